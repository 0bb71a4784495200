"""Layout file → validated, expanded placements (scatters become trees). Nothing is built here;
every error names the JSON path, and species files are parsed once, here, so a bad one is
reported at the path that names it before anything is grown or written.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bundled import resolve_species
from ..errors import TreegenError
from ..limits import MAX_TREES
from ..options import MAX_SEED
from ..params import load_params
from .scatter import crossing_edges, polygon_area, scatter_points
from .schema import (
    Camera,
    Defaults,
    WindSpec,
    check_schema,
    layout_schema,  # noqa: F401
    read_json_file,
    show_value,
)

MAX_DENSITY = 10.0  # trees per m² a scatter may hold, by 'density' (the schema's maximum) or by
# 'count' over its area: 100,000 trees in 20 × 20 m took 13 GB to write a 2.6 GB forest


@dataclass(frozen=True)
class Placement:
    """One tree of the layout, before prototypes exist. `source` is its JSON path."""

    species: Path  # resolved species file
    seed: int
    position: tuple[float, float, float]
    rotation_deg: float
    scale: float
    source: str


@dataclass(frozen=True)
class Layout:
    name: str
    path: Path
    camera: Camera | None  # optional: orders the trees; --camera-lod picks LODs by it
    wind: WindSpec
    defaults: Defaults
    placements: list[Placement]
    params: dict = field(default_factory=dict)  # species file → its Params, parsed once
    named: dict = field(default_factory=dict)  # species file → the JSON path first naming it


def _xyz(v) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


def load_layout(path: str | os.PathLike, max_trees: int = MAX_TREES) -> Layout:
    """Read, validate and expand a layout file (scatters become placements)."""
    path = Path(path)
    data = read_json_file(path, "layout")
    try:
        return parse_layout(data, path, max_trees)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None


def _species_file(base: Path, value: str, where: str, checked: dict, named: dict) -> Path:
    """The species file `value` names (a path relative to the layout wins, else a bundled
    name); parsed once per layout so a bad file is reported at the JSON path that names it
    (before anything is built or written); `named`: file → the first JSON path naming it."""
    p = resolve_species(value, base, f"{where}: species file '{show_value(value)[1:-1]}'").resolve()
    named.setdefault(p, where)  # a prototype's build error is reported at this JSON path
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
    camera = None
    if "camera" in data:
        cam = data["camera"]
        camera = Camera(
            _xyz(cam["position"]),
            _xyz(cam["target"]),
            float(cam.get("fov_deg", Camera.fov_deg)),
            int(cam.get("width_px", Camera.width_px)),
        )
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
    named: dict = {}
    for i, inst in enumerate(data.get("instances", [])):
        where = f"instances[{i}]"
        pos = [float(x) for x in inst["position"]] + [0.0] * (3 - len(inst["position"]))
        placements.append(
            Placement(
                species=_species_file(base, inst["species"], f"{where}.species", checked, named),
                seed=int(inst.get("seed", defaults.seed)),
                position=_xyz(pos),
                rotation_deg=float(inst.get("rotation_deg", defaults.rotation_deg)),
                scale=float(inst.get("scale", defaults.scale)),
                source=where,
            )
        )
    for s, sc in enumerate(data.get("scatter", [])):
        placements.extend(  # (a scatter over the limit with the trees before it is refused)
            _scatter_placements(
                sc, f"scatter[{s}]", base, defaults, checked, named, max_trees, len(placements)
            )
        )
    if len(placements) > max_trees:
        raise TreegenError(
            f"instances: the layout places {len(placements):,} trees, over the "
            f"limit of {max_trees:,}; raise it with --max-trees N"
        )
    if not placements:  # (every scatter's count 0: an empty file written with exit 0)
        raise TreegenError("scatter: the layout places no trees (every scatter's count or density gives 0)")
    return Layout(
        name=str(data.get("name") or path.stem),
        path=path,
        camera=camera,
        wind=wind,
        defaults=defaults,
        placements=placements,
        params=checked,
        named=named,
    )


def _scatter_placements(
    sc: dict,
    where: str,
    base: Path,
    defaults: Defaults,
    checked: dict,
    named: dict,
    max_trees: int = MAX_TREES,
    placed: int = 0,
) -> list[Placement]:
    if ("rectangle" in sc) == ("polygon" in sc):
        raise TreegenError(f"{where}: give exactly one of 'rectangle' or 'polygon'")
    if ("count" in sc) == ("density" in sc):
        raise TreegenError(f"{where}: give exactly one of 'count' or 'density'")
    if "rectangle" in sc:
        lo, hi = np.array(sc["rectangle"]["min"], float), np.array(sc["rectangle"]["max"], float)
        if np.any(hi <= lo):
            raise TreegenError(
                f"{where}.rectangle.max: must exceed min in x and y, got min "
                f"[{', '.join(f'{x:g}' for x in lo)}], max [{', '.join(f'{x:g}' for x in hi)}]"
            )
        region, is_poly = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]]), False
        area = float(np.prod(hi - lo))
    else:
        region, is_poly = np.array(sc["polygon"], float), True
        crossing = crossing_edges(region)
        if crossing is not None:
            i, j = crossing
            n = len(region)
            raise TreegenError(
                f"{where}.polygon: edges {i}-{(i + 1) % n} and {j}-{(j + 1) % n} cross; give a "
                "simple polygon, its vertices in order round its outline"
            )
        area = polygon_area(region)
        if area <= 0:
            raise TreegenError(f"{where}.polygon: has zero area")
    for key in ("scale", "rotation_deg"):
        if key in sc and sc[key][1] < sc[key][0]:
            raise TreegenError(f"{where}.{key}: [low, high] with low <= high, got {sc[key]}")
    if "scale" in sc and sc["scale"][0] <= 0:
        raise TreegenError(f"{where}.scale: scales must be > 0, got {sc['scale']}")
    files = [
        _species_file(base, s["file"], f"{where}.species[{i}].file", checked, named)
        for i, s in enumerate(sc["species"])
    ]
    weights = np.array([float(s.get("weight", 1.0)) for s in sc["species"]])
    count = int(sc["count"]) if "count" in sc else sc["density"] * area
    if "count" in sc and count > MAX_DENSITY * area:
        raise TreegenError(
            f"{where}.count: {count:,} trees on {area:,.4g} m² is {count / area:,.4g} per m²; "
            f"allowed at most {MAX_DENSITY:g} per m² (as 'density'): scatter them over more ground"
        )
    if count + placed > max_trees:  # (`placed`: the trees the layout places before these)
        before = f" and {placed:,} placed before" if placed else ""
        raise TreegenError(
            f"{where}: {count:,.0f} trees ({'count' if 'count' in sc else 'density × area'}){before}, "
            f"over the limit of {max_trees:,} trees; raise it with --max-trees N"
        )
    count = int(round(count))
    seed = int(sc.get("seed", defaults.seed))
    n_variants = int(sc.get("variants", 3))
    if seed + n_variants - 1 > MAX_SEED:  # the variants' prototypes are seeds seed, seed + 1, …
        raise TreegenError(
            f"{where}.seed: {seed} with {n_variants} variants reaches seed {seed + n_variants - 1}; "
            f"allowed [0, {MAX_SEED - n_variants + 1}]"
        )
    rng = np.random.default_rng([seed, 0x5CA77E4])
    pts = scatter_points(region, is_poly, count, float(sc.get("min_spacing", 0.0)), rng, where)
    kind = rng.choice(len(files), size=count, p=weights / weights.sum())
    variant = rng.integers(0, n_variants, size=count)
    s_lo, s_hi = (float(x) + 0.0 for x in sc.get("scale", [defaults.scale, defaults.scale]))
    r_lo, r_hi = (float(x) + 0.0 for x in sc.get("rotation_deg", [0.0, 360.0]))  # -0.0 → 0.0
    scale = rng.uniform(s_lo, s_hi, size=count)
    rot = rng.uniform(r_lo, r_hi, size=count)
    z = float(sc.get("z", 0.0))
    return [
        Placement(
            species=files[kind[i]],
            seed=seed + int(variant[i]),
            position=(float(pts[i, 0]), float(pts[i, 1]), z),
            rotation_deg=float(rot[i]),
            scale=float(scale[i]),
            source=f"{where}#{i}",
        )
        for i in range(count)
    ]  # one small record per tree (not per leaf)
