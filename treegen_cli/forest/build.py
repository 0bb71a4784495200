"""Layout → Forest: each distinct (species, seed) built once (a prototype, on Dask),
placed many times, each instance with all its prototype's LODs (or, baking a camera, the one
its distance calls for) and the phase variant nearest its time offset; then prepared for the
writers.

Phase variety: an instance's time offset is the travel time of the shared wind field's gusts
from the upwind edge (x·dir / speed: trees downwind sway later, as in a frozen, advected field)
plus a seeded jitter of `phase_jitter` × the loop, wrapped to the loop.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import Progress

from ..asset import Asset, Forest, Instance, Lod, lod_bounds
from ..errors import TreegenError, in_file as _in_file
from ..exchange import FOREST_WRITERS, check_compress, check_suffix, export_forest
from ..limits import MAX_TREES
from ..lod_report import leaf_updates as lod_leaf_updates
from ..params import load_params
from ..pipeline import build_asset
from ..prepare import prepare_forest
from .layout import Layout, WindSpec, load_layout
from .options import gltf_options, make_options


def camera_lods(prototypes, proto, pos, rot, scale, eye) -> tuple[np.ndarray, np.ndarray]:
    """(LOD, distance) of each instance seen from `eye` (Z up): its crown's centre placed,
    per prototype (few), vectorised over its instances."""
    centers = np.array([_crown_center(a) for a in prototypes]).reshape(-1, 3)
    world_center = pos + scale[:, None] * np.einsum("nij,nj->ni", _rotz(rot), centers[proto])
    dist = np.linalg.norm(world_center - np.asarray(eye, float), axis=1)
    lods = np.zeros(len(pos), int)
    for k, asset in enumerate(prototypes):
        sel = proto == k
        lods[sel] = select_lod(dist[sel], [lod.distance for lod in asset.lods], scale[sel])
    return lods, dist


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
    travel = (
        (along - along.min(initial=0.0)) / wind.speed
        if wind.speed > 0
        else rng.random(len(positions)) * wind.duration
    )
    return np.mod(travel + jitter, wind.duration)


def build_prototype(params, seed: int, options) -> Asset:
    """Grow, rig, skin, bake (and decimate) one prototype: a Dask task, or a call here."""
    from ..executor import tune_worker_malloc

    tune_worker_malloc()
    asset, _tree = build_asset(params, seed, options)
    return asset


def build_prototypes(
    keys: list[tuple[Path, int]],
    options,
    workers: int | None = None,
    progress: bool | None = None,
    parsed: dict | None = None,
    scheduler: str | None = None,
    report: dict | None = None,
) -> list[Asset]:
    """Each (species file, seed) built once: on `workers` local processes under Dask's local
    process scheduler (default one per core; executor.process_pool), or on the Dask cluster at
    `scheduler` / $DASK_SCHEDULER_ADDRESS (executor.dask_client), as `treegen batch` builds.
    One worker or one prototype builds in this process. The list is in `keys` order, so the
    bytes never depend on who built what. A rich progress bar on an interactive stderr only.
    `parsed`: species already read (the layout's), so no file is parsed twice.
    `report["cluster"]` is set to where they ran."""
    from ..executor import default_workers, dask_client, process_pool, scheduler_address

    params = dict(parsed or {})
    for path, _seed in keys:
        if path not in params:
            params[path] = load_params(path)
    remote = scheduler_address(scheduler) is not None
    workers = max(1, min(workers or default_workers(), len(keys)))
    if progress is None:
        progress = sys.stderr.isatty()
    tasks = [(functools.partial(_in_file, p, build_prototype), params[p], s, options) for p, s in keys]
    run: Callable[..., list]
    with contextlib.ExitStack() as stack:
        # workers first: the bar's thread would stop them forking
        if remote:
            client, where = stack.enter_context(dask_client(scheduler, workers))
            # the index too: two species files may share a name (a/oak.txt, b/oak.txt)
            names = [f"treegen-forest-{i}-{p.stem}-{s}" for i, (p, s) in enumerate(keys)]
            run = functools.partial(_on_cluster, client, names)
        elif workers > 1:
            run, where = stack.enter_context(process_pool(workers))
        else:
            run, where = _here, "this process"
        if report is not None:
            report["cluster"] = where
        step = None
        if progress:
            bar = Progress(console=Console(stderr=True), transient=True)
            bar.start()
            stack.callback(bar.stop)
            task = bar.add_task("prototypes", total=len(keys))
            step = lambda _i: bar.advance(task)  # noqa: E731
        return run(tasks, done=step)


def _here(tasks: list[tuple], done=None) -> list:
    out = []
    for i, (fn, *args) in enumerate(tasks):
        out.append(fn(*args))
        if done is not None:
            done(i)
    return out


def _on_cluster(client, names: list[str], tasks: list[tuple], done=None) -> list:
    """Run the tasks (Dask keys: `names` and this run's id) on a Dask cluster, in list order
    as its workers free up; `done(i)` as each comes back. A worker's TreegenError (it names
    its species file) is raised here."""
    from distributed import as_completed

    run = f"{os.getpid():x}{time.time_ns() & 0xFFFFFF:x}"
    # one map, not a submit each: the scheduler sees the group whole and queues it (a worker
    # takes its next prototype when free); tasks submitted one by one are placed as they come
    mapped = client.map(_call, tasks, key=[f"{name}-{run}" for name in names])
    index = {fut: i for i, fut in enumerate(mapped)}
    out: list = [None] * len(tasks)
    for fut in as_completed(list(index), loop=client.loop):
        i = index.pop(fut)
        out[i] = fut.result()
        fut.release()
        if done is not None:
            done(i)
    return out


def _call(task: tuple):
    fn, *args = task
    return fn(*args)


def _check_sizes(layout: Layout, prototypes: list[Asset], proto: np.ndarray, scale: np.ndarray, limit: float):
    """Refuse the largest tree an instance's scale makes bigger than `limit` metres (height or
    crown width; defaults.max_size), naming its place in the layout: a scale of 100 on a
    palm built a 2.5 km tree, where `make` refuses anything over 150 m."""
    size = np.array([float(np.ptp(np.stack(lod_bounds(a.lods[0])), axis=0).max()) for a in prototypes])
    big = scale * size[proto]
    if big.size and big.max() > limit:
        i = int(np.argmax(big))
        p = layout.placements[i]
        raise TreegenError(
            f"{layout.path}: {p.source}: scale {scale[i]:g} makes {p.species.stem} {big[i]:,.1f} m "
            f"across ({size[proto[i]]:.1f} m at scale 1); allowed at most {limit:g} m, raise "
            "defaults.max_size for giants on purpose"
        )


def _crown_center(asset: Asset) -> np.ndarray:
    lo, hi = lod_bounds(asset.lods[0])
    return 0.5 * (lo + hi)


def _rotz(deg: np.ndarray) -> np.ndarray:
    a = np.radians(np.asarray(deg, float))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1], m[..., 2, 2] = c, -s, s, c, 1.0
    return m


def build_scene(
    layout: Layout,
    all_lods: bool = True,
    error_px: float | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    scheduler: str | None = None,
    impostor: bool = True,
) -> Forest:
    """Prototypes (built once each, each ending in its impostor unless `impostor` is False)
    and instances with their time offset.

    all_lods (default): every instance carries all its prototype's LODs, for an engine to
    switch as the player walks; the camera, if the layout has one, only orders the instances
    nearest first (what a progressive loader fetches first) and records the LOD it would see.
    all_lods=False bakes the layout's camera: each instance gets only that LOD, in layout order."""
    if not all_lods and layout.camera is None:
        raise TreegenError(
            f'--camera-lod: {layout.path} has no camera; add "camera": '
            '{"position": [x, y, z], "target": [x, y, z]} or drop --camera-lod'
        )
    t0 = time.perf_counter()
    keys = sorted({(p.species, p.seed) for p in layout.placements}, key=lambda k: (str(k[0]), k[1]))
    index = {k: i for i, k in enumerate(keys)}
    options = make_options(layout, error_px, impostor)
    report: dict = {}
    try:
        prototypes = build_prototypes(keys, options, workers, progress, layout.params, scheduler, report)
    except TreegenError as e:  # a layout key refused on one tree: the layout's error, tree named
        species, sep, rest = str(e).partition(": ")
        if sep and rest.startswith(("defaults.", "instances[", "scatter[")):
            raise TreegenError(f"{layout.path}: {rest} (on {species})") from None
        # a species file's own error: also the layout and the JSON path that names the file
        path = next((p for p in layout.named if str(e).startswith(f"{p}:")), None)
        if path is None:
            raise
        raise TreegenError(f"{layout.path}: {layout.named[path]}: {e}") from None
    t1 = time.perf_counter()
    placements = layout.placements
    proto = np.array([index[(p.species, p.seed)] for p in placements], int)
    pos = np.array([p.position for p in placements], float).reshape(-1, 3)
    scale = np.array([p.scale for p in placements], float)
    _check_sizes(layout, prototypes, proto, scale, options.generate.max_size)
    rot = np.array([p.rotation_deg for p in placements], float)
    lods = np.zeros(len(placements), int)
    dist = np.zeros(len(placements))
    order = np.arange(len(placements))
    if layout.camera is not None:
        lods, dist = camera_lods(prototypes, proto, pos, rot, scale, layout.camera.position)
        if all_lods:
            order = np.argsort(dist / scale, kind="stable")  # nearest (on screen) first
    animated = layout.wind.enabled
    offsets = time_offsets(pos, layout.wind) if animated else np.zeros(len(placements))
    loop = layout.wind.duration if animated else 0.0
    V = max(1, layout.defaults.phase_variants)
    variant = np.round(offsets / loop * V).astype(int) % V if loop > 0 else np.zeros(len(placements), int)
    instances = [
        Instance(
            int(proto[i]),
            tuple(pos[i]),
            float(rot[i]),
            float(scale[i]),
            int(lods[i]),
            float(offsets[i]),
            float(dist[i]),
            placements[i].source,
            int(variant[i]),
        )
        for i in order
    ]
    forest = prepare_forest(
        Forest(
            name=layout.name,
            prototypes=prototypes,
            instances=instances,
            all_lods=all_lods,
            phase_variants=layout.defaults.phase_variants,
            loop=loop,
            cluster=report.get("cluster", ""),
        )
    )
    forest.timings.update(prototypes_s=t1 - t0, place_s=time.perf_counter() - t1)
    return forest


def leaf_updates(lod: Lod) -> tuple[int, float]:
    """(leaf vertices, leaf-vertex updates per frame on average) of one LOD, counted like
    `treegen info --lod`. A joint's schedule already follows its world-space movement (parents'
    motion included), which is the paper's per-branch accumulate-and-reset rule."""

    return lod_leaf_updates(lod)


def summary(scene: Forest, written: list[Path], seconds: float, camera: bool = True) -> dict:
    """The paper's comparison for the whole scene: leaf-vertex updates per frame with the LODs
    the camera sees (without a camera: LOD0 everywhere, what the engine starts from) versus
    every leaf vertex of LOD0 every frame (no LOD)."""
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
        "camera": camera,
        "cluster": scene.cluster,
        "files": [str(p) for p in written],
        "bytes": int(sum(p.stat().st_size for p in written)),
        "seconds": round(seconds, 3),
        "leaf_vertex_updates_per_frame": round(with_lod),
        "leaf_vertex_updates_per_frame_without_lod": round(without),
        **{k: round(v, 3) for k, v in scene.timings.items()},
    }


def run_forest(
    layout_path,
    output,
    all_lods: bool = True,
    error_px: float | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    max_trees: int = MAX_TREES,
    scheduler: str | None = None,
    compress: str = "none",
    impostor: bool = True,
    profile: str | None = None,
) -> dict:
    """The whole command: validate (nothing written on error), build, write, summarise.
    `compress`: glTF's --compress (quantize, meshopt; a USD output refuses it); `impostor`:
    end each prototype's LODs with its impostor; `profile`: instead of the layout's."""
    t0 = time.perf_counter()
    output = check_suffix(output, FOREST_WRITERS, flag="-o")
    check_compress(output, compress)
    if error_px is not None and not (math.isfinite(error_px) and 0 <= error_px <= 100):
        raise TreegenError(f"--error-px {error_px}: allowed range 0..100 pixels")
    layout = load_layout(layout_path, max_trees)
    if profile is not None:
        layout = replace(layout, defaults=replace(layout.defaults, profile=profile))
    scene = build_scene(layout, all_lods, error_px, workers, progress, scheduler, impostor)
    t1 = time.perf_counter()
    written = export_forest(scene, output, gltf_options(layout, compress, error_px))
    scene.timings["write_s"] = time.perf_counter() - t1
    _details(scene)
    return summary(scene, written, time.perf_counter() - t0, layout.camera is not None)


def _details(scene: Forest) -> None:
    """With -v: a line per prototype (triangles per LOD, joints) and the forest's stages."""
    from ..progress import current_reporter

    rep = current_reporter()
    for a in scene.prototypes:
        tris = " / ".join(f"{sum(len(p.indices) // 3 for p in lod.primitives):,}" for lod in a.lods)
        rep.detail(
            f"  prototype {a.extras.get('species', a.name)} seed {a.extras.get('seed', 0)}: "
            f"{tris} triangles per LOD, {len(a.lods[0].skeleton.names)} joints"
        )
    rep.stage_totals({name: scene.timings.get(name + "_s", 0.0) for name in ("prototypes", "place", "write")})
