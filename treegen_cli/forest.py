"""Layout file → placed instances → shared prototypes → one animated, LOD-selected scene.

Result: `treegen forest layout.json -o forest.glb` writes every distinct (species, seed) tree
once (a prototype, with whatever LODs the pipeline gives it) and places it many times; each
instance gets the LOD its distance to the camera calls for, or all of them with `--all-lods`.

    layout = load_layout("examples/forest_30m.json")      # validated; TreegenError names the
    scene = build_scene(layout)                           #   JSON path, e.g. instances[12].species
    export_forest(scene, "forest.glb")                    # atomic (exchange)

Validation is by hand, by a small interpreter of the subset of JSON Schema that
schemas/layout.schema.json uses (type, properties, required, additionalProperties, items,
min/maxItems, minimum/maximum, exclusive bounds, minLength, $ref), so the published schema and
the checks cannot drift apart; what a schema cannot say (files exist, one of rectangle/polygon,
a feasible scatter) is checked after it.

Phase variety: an instance's time offset is the travel time of the shared wind field's gusts
from the upwind edge (x·dir / speed: trees downwind sway later, as in a frozen, advected field)
plus a seeded jitter of `phase_jitter` × the loop, wrapped to the loop.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from .asset import Asset, Forest, Instance, Lod, lod_bounds
from .limits import MAX_TREES
from .prepare import prepare_forest
from .errors import TreegenError, in_file as _in_file
from .exchange import FOREST_WRITERS, check_suffix, export_forest

SCHEMA_NAME = "layout.schema.json"
HEX_PACKING = 2.0 / math.sqrt(3.0)    # most disks of diameter s per s² of area (hexagonal)


# ----------------------------------------------------------------------------- schema

def schema_text() -> str:
    """The published JSON Schema of layout files (package data)."""
    return resources.files("treegen_cli").joinpath("schemas", SCHEMA_NAME).read_text("utf-8")


def layout_schema() -> dict:
    return json.loads(schema_text())


_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and _finite(v),
}


def _finite(v) -> bool:
    try:
        return math.isfinite(float(v))
    except OverflowError:          # an integer too large for a float
        return False


def _show(value) -> str:
    text = json.dumps(value) if not isinstance(value, (dict, list)) else type(value).__name__
    return text if len(text) <= 40 else text[:37] + "..."


def _join(path: str, key) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def check_schema(value, schema: dict, root: dict, path: str = "") -> None:
    """Raise TreegenError '<json path>: <reason>' at the first place `value` breaks `schema`."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        schema = {**root["$defs"][name], **{k: v for k, v in schema.items() if k != "$ref"}}
    where = path or "(top level)"
    kind = schema.get("type")
    if kind and not _TYPES[kind](value):
        shown = _show(value)
        article = "an" if kind[0] in "aeiou" else "a"
        extra = " (finite)" if kind == "number" else ""
        raise TreegenError(f"{where}: expected {article} {kind}{extra}, got {shown}")
    if kind == "number" or kind == "integer":
        lo, hi = schema.get("minimum"), schema.get("maximum")
        xlo, xhi = schema.get("exclusiveMinimum"), schema.get("exclusiveMaximum")
        if (lo is not None and value < lo) or (hi is not None and value > hi) \
                or (xlo is not None and value <= xlo) or (xhi is not None and value >= xhi):
            left = f"[{lo:g}" if lo is not None else (f"({xlo:g}" if xlo is not None else "(-inf")
            right = f"{hi:g}]" if hi is not None else (f"{xhi:g})" if xhi is not None else "inf)")
            raise TreegenError(f"{where}: {_show(value)} is out of range; allowed {left}, {right}")
    if kind == "string" and len(value) < schema.get("minLength", 0):
        raise TreegenError(f"{where}: must not be empty")
    if kind == "array":
        n_min, n_max = schema.get("minItems"), schema.get("maxItems")
        if (n_min is not None and len(value) < n_min) or (n_max is not None and len(value) > n_max):
            want = (f"{n_min}" if n_min == n_max else
                    f"{n_min or 0}..{n_max if n_max is not None else 'any'}")
            raise TreegenError(f"{where}: expected {want} items, got {len(value)}")
        if "items" in schema:
            for i, item in enumerate(value):
                check_schema(item, schema["items"], root, _join(path, i))
    if kind == "object":
        props = schema.get("properties", {})
        for key in schema.get("required", []):
            if key not in value:
                raise TreegenError(f"{_join(path, key)}: required")
        for key, item in value.items():
            if key in props:
                check_schema(item, props[key], root, _join(path, key))
            elif schema.get("additionalProperties", True) is False:
                raise TreegenError(f"{_join(path, key)}: unknown key; allowed: {', '.join(sorted(props))}")


# ----------------------------------------------------------------------------- layout

@dataclass(frozen=True)
class Camera:
    position: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_deg: float = 60.0
    width_px: int = 1920


@dataclass(frozen=True)
class WindSpec:
    speed: float = 4.0
    direction_deg: float = 0.0
    gust: float = 0.35
    turbulence: float = 0.3
    duration: float = 4.0
    fps: float = 30.0
    seed: int = 0
    phase_jitter: float = 0.25
    enabled: bool = True


@dataclass(frozen=True)
class Defaults:
    seed: int = 0
    scale: float = 1.0
    rotation_deg: float = 0.0
    max_joints: int = 48
    lod_distances: tuple[float, ...] | None = None
    error_px: float = 1.0
    phase_variants: int = 4


@dataclass(frozen=True)
class Placement:
    """One tree of the layout, before prototypes exist. `source` is its JSON path."""

    species: Path                 # resolved species file
    seed: int
    position: tuple[float, float, float]
    rotation_deg: float
    scale: float
    source: str


@dataclass(frozen=True)
class Layout:
    name: str
    path: Path
    camera: Camera
    wind: WindSpec
    defaults: Defaults
    placements: list[Placement]
    params: dict = field(default_factory=dict)   # species file → its Params, parsed once


def load_layout(path: str | os.PathLike, max_trees: int = MAX_TREES) -> Layout:
    """Read, validate and expand a layout file (scatters become placements)."""
    path = Path(path)
    try:
        text = path.read_text("utf-8")
    except FileNotFoundError:
        raise TreegenError(f"{path}: no such layout file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise TreegenError(f"{path}: cannot read the layout ({e})") from None
    try:
        data = json.loads(text, parse_constant=lambda c: float("nan"))
    except json.JSONDecodeError as e:
        raise TreegenError(f"{path}: line {e.lineno} column {e.colno}: invalid JSON ({e.msg})") from None
    try:
        return parse_layout(data, path, max_trees)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None


def _species_file(base: Path, value: str, where: str, checked: dict) -> Path:
    """The resolved species file; parsed once per layout so a bad file is reported at the
    JSON path that names it (before anything is built or written)."""
    from .params import load_params

    try:
        p = (base / value).resolve()
        ok = p.is_file()
    except (OSError, ValueError):
        ok = False
    if not ok:
        raise TreegenError(f"{where}: species file '{_show(value)[1:-1]}' not found")
    if p not in checked:
        try:
            checked[p] = load_params(p)
        except TreegenError as e:
            raise TreegenError(f"{where}: {e}") from None
    return p


def parse_layout(data, path: Path, max_trees: int = MAX_TREES) -> Layout:
    """Validate decoded JSON `data` of the layout at `path`; messages start with the JSON path."""
    schema = layout_schema()
    check_schema(data, schema, schema)
    base = path.parent
    cam = data["camera"]
    camera = Camera(tuple(map(float, cam["position"])), tuple(map(float, cam["target"])),
                    float(cam.get("fov_deg", 60.0)), int(cam.get("width_px", 1920)))
    if np.allclose(camera.position, camera.target):
        raise TreegenError("camera.target: must differ from camera.position")
    wind = WindSpec(**data.get("wind", {}))
    d = dict(data.get("defaults", {}))
    if "lod_distances" in d:
        ld = d["lod_distances"]
        if any(b <= a for a, b in zip(ld, ld[1:])):
            raise TreegenError(f"defaults.lod_distances: must increase strictly, got {ld}")
        d["lod_distances"] = tuple(float(x) for x in ld)
    defaults = Defaults(**d)
    if not data.get("instances") and not data.get("scatter"):
        raise TreegenError("instances: the layout places no trees (give 'instances' or 'scatter')")

    placements: list[Placement] = []
    checked: dict = {}
    for i, inst in enumerate(data.get("instances", [])):
        where = f"instances[{i}]"
        pos = [float(x) for x in inst["position"]] + [0.0] * (3 - len(inst["position"]))
        placements.append(Placement(
            species=_species_file(base, inst["species"], f"{where}.species", checked),
            seed=int(inst.get("seed", defaults.seed)), position=tuple(pos),
            rotation_deg=float(inst.get("rotation_deg", defaults.rotation_deg)),
            scale=float(inst.get("scale", defaults.scale)), source=where))
    for s, sc in enumerate(data.get("scatter", [])):
        placements.extend(_scatter_placements(sc, f"scatter[{s}]", base, defaults, checked,
                                              max_trees - len(placements)))
        if len(placements) > max_trees:
            raise TreegenError(f"scatter[{s}]: the layout places {len(placements):,} trees, over "
                               f"the limit of {max_trees:,}; raise it with --max-trees N")
    if len(placements) > max_trees:
        raise TreegenError(f"instances: the layout places {len(placements):,} trees, over the "
                           f"limit of {max_trees:,}; raise it with --max-trees N")
    return Layout(name=str(data.get("name") or path.stem), path=path, camera=camera, wind=wind,
                  defaults=defaults, placements=placements, params=checked)


# ----------------------------------------------------------------------------- scatter

def polygon_area(poly: np.ndarray) -> float:
    """Shoelace area (absolute) of a simple polygon (N, 2)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def inside_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised over points × edges: bool (P,)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    px, py = points[:, 0:1], points[:, 1:2]
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    dy = np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1])
    x_at = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / dy[None, :]
    return (np.count_nonzero(crosses & (px < x_at), axis=1) % 2) == 1


def scatter_points(region: np.ndarray, is_polygon: bool, count: int, min_spacing: float,
                   rng: np.random.Generator, where: str = "scatter") -> np.ndarray:
    """`count` points (count, 2) uniformly in the region, pairwise ≥ min_spacing apart.

    Dart throwing in vectorised batches: a candidate survives if it keeps the spacing to every
    accepted point and to every earlier candidate of its batch (a conservative rule that needs
    no sequential pass). Impossible requests (more disks than hexagonal packing holds) fail at
    once; hard ones fail after a bounded number of fruitless batches, naming the count reached.
    """
    from scipy.spatial import cKDTree

    lo, hi = region.min(axis=0), region.max(axis=0)
    area = polygon_area(region) if is_polygon else float(np.prod(hi - lo))
    if count == 0:
        return np.zeros((0, 2))
    if area <= 0:
        raise TreegenError(f"{where}: the region has zero area")
    if min_spacing > 0:
        # disks of radius s/2 around each point lie in the region grown by s/2
        per = np.sum(np.linalg.norm(np.roll(region, -1, 0) - region, axis=1)) if is_polygon \
            else 2 * float(np.sum(hi - lo))
        grown = area + per * min_spacing / 2 + math.pi * min_spacing ** 2 / 4
        most = int(HEX_PACKING * grown / min_spacing ** 2)
        if count > most:
            raise TreegenError(
                f"{where}: impossible scatter: {count} trees at min_spacing {min_spacing:g} m need "
                f"about {count * min_spacing ** 2 / HEX_PACKING:.0f} m², the region has {area:.0f} m² "
                f"(at most ~{most} fit); lower count/density or min_spacing")
    accepted = np.zeros((0, 2))
    stale = 0
    while len(accepted) < count and stale < 60:
        need = count - len(accepted)
        cand = lo + rng.random((max(4 * need, 64), 2)) * (hi - lo)
        if is_polygon:
            cand = cand[inside_polygon(cand, region)]
        if min_spacing > 0 and len(cand):
            if len(accepted):
                d, _ = cKDTree(accepted).query(cand, k=1)
                cand = cand[d >= min_spacing]
            pairs = cKDTree(cand).query_pairs(min_spacing, output_type="ndarray")
            keep = np.ones(len(cand), bool)
            keep[pairs.max(axis=1) if len(pairs) else []] = False
            cand = cand[keep]
        cand = cand[:need]
        stale = stale + 1 if len(cand) == 0 else 0
        accepted = np.concatenate([accepted, cand])
    if len(accepted) < count:
        raise TreegenError(f"{where}: could not place {count} trees at min_spacing {min_spacing:g} m "
                           f"(placed {len(accepted)}); lower count/density or min_spacing")
    return accepted


def _scatter_placements(sc: dict, where: str, base: Path, defaults: Defaults,
                        checked: dict, max_trees: int = MAX_TREES) -> list[Placement]:
    if ("rectangle" in sc) == ("polygon" in sc):
        raise TreegenError(f"{where}: give exactly one of 'rectangle' or 'polygon'")
    if ("count" in sc) == ("density" in sc):
        raise TreegenError(f"{where}: give exactly one of 'count' or 'density'")
    if "rectangle" in sc:
        lo, hi = np.array(sc["rectangle"]["min"], float), np.array(sc["rectangle"]["max"], float)
        if np.any(hi <= lo):
            raise TreegenError(f"{where}.rectangle.max: must exceed min in x and y, got {sc['rectangle']}")
        region, is_poly = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]]), False
        area = float(np.prod(hi - lo))
    else:
        region, is_poly = np.array(sc["polygon"], float), True
        area = polygon_area(region)
        if area <= 0:
            raise TreegenError(f"{where}.polygon: has zero area")
    for key in ("scale", "rotation_deg"):
        if key in sc and sc[key][1] < sc[key][0]:
            raise TreegenError(f"{where}.{key}: [low, high] with low <= high, got {sc[key]}")
    if "scale" in sc and sc["scale"][0] <= 0:
        raise TreegenError(f"{where}.scale: scales must be > 0, got {sc['scale']}")
    files = [_species_file(base, s["file"], f"{where}.species[{i}].file", checked)
             for i, s in enumerate(sc["species"])]
    weights = np.array([float(s.get("weight", 1.0)) for s in sc["species"]])
    count = int(sc["count"]) if "count" in sc else sc["density"] * area
    if count > max_trees:
        raise TreegenError(f"{where}: {count:,.0f} trees (density × area), over the limit of "
                           f"{max(max_trees, 0):,}; raise it with --max-trees N")
    count = int(round(count))
    seed = int(sc.get("seed", defaults.seed))
    rng = np.random.default_rng([seed, 0x5CA77E4])
    pts = scatter_points(region, is_poly, count, float(sc.get("min_spacing", 0.0)), rng, where)
    kind = rng.choice(len(files), size=count, p=weights / weights.sum())
    variant = rng.integers(0, int(sc.get("variants", 3)), size=count)
    s_lo, s_hi = (float(x) + 0.0 for x in sc.get("scale", [defaults.scale, defaults.scale]))
    r_lo, r_hi = (float(x) + 0.0 for x in sc.get("rotation_deg", [0.0, 360.0]))   # -0.0 → 0.0
    scale = rng.uniform(s_lo, s_hi, size=count)
    rot = rng.uniform(r_lo, r_hi, size=count)
    z = float(sc.get("z", 0.0))
    return [Placement(species=files[kind[i]], seed=seed + int(variant[i]),
                      position=(float(pts[i, 0]), float(pts[i, 1]), z),
                      rotation_deg=float(rot[i]), scale=float(scale[i]), source=f"{where}#{i}")
            for i in range(count)]   # one small record per tree (not per leaf)


# ----------------------------------------------------------------------------- scene

def select_lod(distance: np.ndarray, lod_distances, scale: np.ndarray | float = 1.0) -> np.ndarray:
    """LOD index per instance: the last LOD whose `distance` ≤ the instance's effective
    distance (camera distance / scale: a tree twice as big looks like one twice as near)."""
    d = np.asarray(distance, float) / np.asarray(scale, float)
    starts = np.asarray(lod_distances, float)
    return np.clip(np.searchsorted(starts, d, side="right") - 1, 0, len(starts) - 1)


def time_offsets(positions: np.ndarray, wind: WindSpec, seed: int = 0) -> np.ndarray:
    """Seconds in [0, duration): gust travel time downwind + seeded jitter, wrapped."""
    positions = np.asarray(positions, float).reshape(-1, 3)
    phi = math.radians(wind.direction_deg)
    along = positions[:, :2] @ np.array([math.cos(phi), math.sin(phi)])
    rng = np.random.default_rng([wind.seed, seed, 0x0FF5E7])
    jitter = rng.random(len(positions)) * wind.phase_jitter * wind.duration
    travel = (along - along.min(initial=0.0)) / wind.speed if wind.speed > 0 else \
        rng.random(len(positions)) * wind.duration
    return np.mod(travel + jitter, wind.duration)


def make_options(layout: Layout, error_px: float | None = None):
    """MakeOptions for every prototype: the layout's joint budget, the shared-field wind, and
    LOD schedules for the layout's camera (fov, width) and error bound."""
    from .lod import LOD_DEFAULTS
    from .pipeline import MakeOptions
    from .rig import RigOptions
    from .wind import WindOptions

    w = layout.wind
    wind = WindOptions(speed=w.speed, direction_deg=w.direction_deg, gust=w.gust,
                       turbulence=w.turbulence, duration=w.duration, fps=w.fps,
                       field_seed=w.seed) if w.enabled else None
    cam = layout.camera
    lod = replace(LOD_DEFAULTS, fov_deg=cam.fov_deg, width=cam.width_px,
                  error_px=layout.defaults.error_px if error_px is None else error_px,
                  distances=layout.defaults.lod_distances or LOD_DEFAULTS.distances)
    return MakeOptions(rig=RigOptions(max_joints=layout.defaults.max_joints), wind=wind, lod=lod)


def _build_one(params, seed: int, options) -> Asset:
    """Worker: grow, rig, skin, bake (and decimate) one prototype."""
    from .pipeline import build_asset
    asset, _tree = build_asset(params, seed, options)
    return asset


def build_prototypes(keys: list[tuple[Path, int]], options, workers: int | None = None,
                     progress: bool | None = None, parsed: dict | None = None) -> list[Asset]:
    """Each (species file, seed) built once, in a process pool on all cores (workers=1: in
    this process). A rich progress bar on an interactive stderr only. `parsed`: species
    already read (the layout's), so no file is parsed twice."""
    from .params import load_params

    params = dict(parsed or {})
    for path, _seed in keys:
        if path not in params:
            params[path] = load_params(path)
    workers = workers or os.cpu_count() or 1
    workers = max(1, min(workers, len(keys)))
    if progress is None:
        progress = sys.stderr.isatty()
    out: list[Asset | None] = [None] * len(keys)
    bar = None
    if progress:
        from rich.console import Console
        from rich.progress import Progress
        bar = Progress(console=Console(stderr=True), transient=True)
        bar.start()
        task = bar.add_task("prototypes", total=len(keys))
    try:
        if workers == 1:
            for i, (path, seed) in enumerate(keys):
                out[i] = _in_file(path, _build_one, params[path], seed, options)
                if bar:
                    bar.advance(task)
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futures = {pool.submit(_build_one, params[p], s, options): i
                           for i, (p, s) in enumerate(keys)}
                for fut in as_completed(futures):
                    i = futures[fut]
                    out[i] = _in_file(keys[i][0], fut.result)
                    if bar:
                        bar.advance(task)
    finally:
        if bar:
            bar.stop()
    return out  # type: ignore[return-value]


def _crown_center(asset: Asset) -> np.ndarray:
    lo, hi = lod_bounds(asset.lods[0])
    return 0.5 * (lo + hi)


def _rotz(deg: np.ndarray) -> np.ndarray:
    a = np.radians(np.asarray(deg, float))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1], m[..., 2, 2] = c, -s, s, c, 1.0
    return m


def build_scene(layout: Layout, all_lods: bool = False, error_px: float | None = None,
                workers: int | None = None, progress: bool | None = None) -> Forest:
    """Prototypes (built once each) and instances with their LOD and time offset."""
    t0 = time.perf_counter()
    keys = sorted({(p.species, p.seed) for p in layout.placements}, key=lambda k: (str(k[0]), k[1]))
    index = {k: i for i, k in enumerate(keys)}
    options = make_options(layout, error_px)
    prototypes = build_prototypes(keys, options, workers, progress, layout.params)
    t1 = time.perf_counter()
    placements = layout.placements
    proto = np.array([index[(p.species, p.seed)] for p in placements], int)
    pos = np.array([p.position for p in placements], float).reshape(-1, 3)
    scale = np.array([p.scale for p in placements], float)
    rot = np.array([p.rotation_deg for p in placements], float)
    centers = np.array([_crown_center(a) for a in prototypes]).reshape(-1, 3)
    world_center = pos + scale[:, None] * np.einsum("nij,nj->ni", _rotz(rot), centers[proto])
    dist = np.linalg.norm(world_center - np.asarray(layout.camera.position), axis=1)
    lods = np.zeros(len(placements), int)
    for k, asset in enumerate(prototypes):     # per prototype (few), vectorised over instances
        sel = proto == k
        lods[sel] = select_lod(dist[sel], [l.distance for l in asset.lods], scale[sel])
    animated = layout.wind.enabled
    offsets = time_offsets(pos, layout.wind) if animated else np.zeros(len(placements))
    loop = layout.wind.duration if animated else 0.0
    V = max(1, layout.defaults.phase_variants)
    variant = np.round(offsets / loop * V).astype(int) % V if loop > 0 else np.zeros(len(placements), int)
    instances = [Instance(int(proto[i]), tuple(pos[i]), float(rot[i]), float(scale[i]), int(lods[i]),
                          float(offsets[i]), float(dist[i]), placements[i].source, int(variant[i]))
                 for i in range(len(placements))]
    forest = prepare_forest(Forest(name=layout.name, prototypes=prototypes, instances=instances,
                                   all_lods=all_lods, phase_variants=layout.defaults.phase_variants,
                                   loop=loop))
    forest.timings.update(prototypes_s=t1 - t0, place_s=time.perf_counter() - t1)
    return forest


# ----------------------------------------------------------------------------- clips

# ----------------------------------------------------------------------------- summary

def leaf_updates(lod: Lod) -> tuple[int, float]:
    """(leaf vertices, leaf-vertex updates per frame on average) of one LOD, counted like
    `treegen info --lod`. A joint's schedule already follows its world-space movement (parents'
    motion included), which is the paper's per-branch accumulate-and-reset rule."""
    from .lod import leaf_updates as lod_leaf_updates

    return lod_leaf_updates(lod)


def summary(scene: Forest, written: list[Path], seconds: float) -> dict:
    """The paper's comparison for the whole scene: leaf-vertex updates per frame with the
    chosen LODs versus every leaf vertex of LOD0 every frame (no LOD)."""
    per = [[leaf_updates(lod) for lod in a.lods] for a in scene.prototypes]
    per_lod: dict[int, int] = {}
    with_lod = without = 0.0
    for inst in scene.instances:
        per_lod[inst.lod] = per_lod.get(inst.lod, 0) + 1
        with_lod += per[inst.prototype][inst.lod][1]
        without += per[inst.prototype][0][0] if scene.loop > 0 else 0.0
    return {
        "scene": scene.name,
        "prototypes": len(scene.prototypes),
        "instances": len(scene.instances),
        "instances_per_lod": {f"lod{k}": v for k, v in sorted(per_lod.items())},
        "all_lods": scene.all_lods,
        "files": [str(p) for p in written],
        "bytes": int(sum(p.stat().st_size for p in written)),
        "seconds": round(seconds, 3),
        "leaf_vertex_updates_per_frame": round(with_lod),
        "leaf_vertex_updates_per_frame_without_lod": round(without),
        **{k: round(v, 3) for k, v in scene.timings.items()},
    }


# ----------------------------------------------------------------------------- writing

def run_forest(layout_path, output, all_lods: bool = False, error_px: float | None = None,
               workers: int | None = None, progress: bool | None = None,
               max_trees: int = MAX_TREES) -> dict:
    """The whole command: validate (nothing written on error), build, write, summarise."""
    t0 = time.perf_counter()
    output = check_suffix(output, FOREST_WRITERS)
    if error_px is not None and not (math.isfinite(error_px) and 0 <= error_px <= 100):
        raise TreegenError(f"--error-px {error_px}: allowed range 0..100 pixels")
    layout = load_layout(layout_path, max_trees)
    scene = build_scene(layout, all_lods, error_px, workers, progress)
    t1 = time.perf_counter()
    written = export_forest(scene, output)
    scene.timings["write_s"] = time.perf_counter() - t1
    return summary(scene, written, time.perf_counter() - t0)
