"""The one-way pipeline behind `treegen make`: Params → Tree → Rig → Mesh + Clip → Asset.

Each stage is a function with an options dataclass whose defaults live beside it; this module
only composes them, so a newcomer can read `build_asset` top to bottom and see every step.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import __version__
from .asset import Asset, Lod, triangle_areas
from .budget import DEFAULTS as BUDGET_DEFAULTS, BudgetOptions, plan_budget
from .generate import DEFAULTS as GENERATE_DEFAULTS, GenerateOptions, generate
from .impostor import ImpostorOptions, build_impostor, cards, switch_distance
from .exchange.compress import GLTF_DEFAULTS, GltfOptions
from .limits import LIMITS_DEFAULTS, Limits, check_keys, check_mesh
from .lod import LOD_DEFAULTS, LodOptions, screen_coverage, switch_distances
from .lod_budget import lod_tree
from .lod_decimate import decimate
from .materials import MATERIAL_DEFAULTS, MaterialOptions, build_materials, leaf_cells, twig_material
from .mesh import MESH_DEFAULTS, TWIGS, MeshOptions, build_mesh
from .params import Params
from .prepare import prepare
from .rig import RIG_DEFAULTS, Rig, RigOptions, build_rig, check_joint_levels
from .tree import Tree, tree_height
from .wind import DEFAULTS as WIND_DEFAULTS, WindOptions, bake_wind, bound_bends, one_blas_thread, wind_angles
from .wind_lods import Nearest, lod_angles


@dataclass(frozen=True)
class MakeOptions:
    """Options of every stage; `wind=None` writes a static (but skinned) tree."""

    generate: GenerateOptions = GENERATE_DEFAULTS
    rig: RigOptions = RIG_DEFAULTS
    mesh: MeshOptions = MESH_DEFAULTS
    wind: WindOptions | None = WIND_DEFAULTS
    lod: LodOptions | None = LOD_DEFAULTS  # None: one LOD with the dense clip
    limits: Limits = LIMITS_DEFAULTS  # refuse oversized meshes / clips before building
    materials: MaterialOptions = MATERIAL_DEFAULTS  # textures (generated or an artist's) or colours
    budget: BudgetOptions = BUDGET_DEFAULTS  # LOD0 triangle budget, met before the tree grows
    impostor: ImpostorOptions | None = None  # an impostor after the LODs (needs `lod`; `treegen
    # make` turns it on: api.resolve); None: none
    gltf: GltfOptions = GLTF_DEFAULTS  # --compress: how the glTF writer encodes (not the build)


@dataclass
class Timings:
    """Seconds per stage, for `treegen make`'s report and the benchmarks."""

    stages: dict[str, float] = field(default_factory=dict)

    def run(self, name, fn, *args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.stages[name] = self.stages.get(name, 0.0) + time.perf_counter() - t0
        return out


def clip_name(lod: int) -> str:
    """Engines loop a clip when its name says so (Godot 3 and 4: a "_loop" suffix), so the wind
    is "wind_loop" (LOD0, or a file with one LOD); lower LODs in one MSFT_lod file get
    "wind_lod<k>_loop"."""
    return "wind_loop" if lod == 0 else f"wind_lod{lod}_loop"


@dataclass(frozen=True)
class Sway:
    """LOD0's tree, rig and wind bends: the LODs below sway as it does (wind_lods.lod_angles)."""

    tree: Tree
    rig: Rig
    theta: np.ndarray  # (J, n, 3)
    near: Nearest = field(default_factory=Nearest)  # LOD0's leaf look-up, built once


def build_lod(
    tree: Tree,
    options: MakeOptions,
    seed: int,
    timings: Timings,
    sway: Sway | None = None,
    among: Rig | None = None,
) -> tuple[Lod, Sway | None, Rig]:
    """Rig, skin and animate one grown tree: its own wind, or (`sway`, a LOD cut from it)
    LOD0's motion on its rig, jointed among LOD0's rig `among`'s joints, in their frames
    (rig.build_rig: its skeleton is LOD0's with joints removed). Returns the LOD, the Sway
    the LODs below it follow and its rig."""
    check_mesh(tree, options.mesh, options.limits)
    nodes, frames = (
        (None, None) if among is None else (among.joint_node, among.skeleton.bind_world[:, :3, :3])
    )
    rig = timings.run("rig", build_rig, tree, options.rig, nodes, frames)
    if options.wind is not None:
        check_keys(len(rig.skeleton.names), options.wind, options.limits)
    primitives = timings.run("mesh", build_mesh, tree, rig, options.mesh)
    clips = []
    if options.wind is not None:
        clip, sway = timings.run("wind", _wind, tree, rig, options.wind, seed, sway)
        clips.append(replace(clip, name=clip_name(0)))
    return Lod(primitives=primitives, skeleton=rig.skeleton, clips=clips), sway, rig


def _wind(tree: Tree, rig: Rig, options: WindOptions, seed: int, sway: Sway | None):
    """(clip, Sway): `tree`'s own wind, or `sway`'s (LOD0's) fitted onto `rig` and bounded as
    LOD0's bends are (a LOD joint standing for a chain of LOD0's may sum past the bounds)."""
    if sway is None:
        sway = Sway(tree, rig, wind_angles(tree, rig, options, seed))
        theta = sway.theta
    else:
        fitted = lod_angles(sway.theta, sway.tree, sway.rig, tree, rig, sway.near)
        theta = bound_bends(fitted, np.asarray(rig.skeleton.parent, dtype=np.int64), options)
    return bake_wind(tree, rig, options, seed, theta), sway


def build_lods(params: Params, tree: Tree, options: MakeOptions, seed: int, timings: Timings) -> list[Lod]:
    """One coarser tree per LOD, each with its own rig and mesh, LOD0's wind on that rig
    (wind_lods.lod_angles: the motion changes little at a switch) and a clip decimated for its distance
    (clip_name(k)); distances follow the tree's height on screen (lod.switch_distances).
    LOD0 is `tree`; lower LODs are cut from it within their triangle budgets
    (lod_budget.lod_tree: thin stems dropped, leaves thinned and scaled to keep the cover),
    their joints among LOD0's, named as there (an engine's LODs of one skeleton)."""
    lo = options.lod
    height = tree_height(tree)
    distances = switch_distances(height, lo)
    at = replace(lo, distances=tuple(distances))  # lod_tree sizes stems by the switch distance
    lods: list[Lod] = []
    sway, rig0, leaves = None, None, tree.n_leaves
    for k, distance in enumerate(distances):
        t, rig, mesh = tree, options.rig, options.mesh
        if k > 0:  # (no LOD keeps more leaves than the one before)
            t, rig, mesh = timings.run(
                "generate", lod_tree, tree, k, lods[0], lods[-1], options.rig, options.mesh, at, leaves=leaves
            )
            leaves = t.n_leaves
        lod, sway, built = build_lod(t, replace(options, rig=rig, mesh=mesh), seed, timings, sway, rig0)
        rig0 = built if rig0 is None else rig0
        clips = [
            timings.run("lod", decimate, lod.skeleton, lod.primitives, c, distance, lo, clip_name(k))[0]
            for c in lod.clips
        ]
        # MSFT_screencoverage: LOD k is shown while the tree covers more than the coverage at
        # which LOD k+1 takes over; the last LOD is never culled.
        coverage = screen_coverage(height, distances[k + 1], lo) if k + 1 < len(distances) else 0.0
        lods.append(replace(lod, clips=clips, distance=float(distance), screen_coverage=coverage))
    return lods


CROWN_SHARE = 0.1  # the impostor's source draws at least this share of LOD0's leaf area (the
# bundled species' coarsest LODs draw 0.18 to 14 of it: the fan palm's leaflets overlap where
# they converge, so fewer cover as much; a desert bush's leaves stand in for its dropped twigs)


def _leaf_area(lod: Lod) -> float:
    """Summed area (m²) of the LOD's leaf triangles."""
    return sum(
        float(triangle_areas(p.positions, p.indices).sum()) for p in lod.primitives if p.name == "leaves"
    )


def add_impostor(
    lods: list[Lod], materials: list, tree: Tree, options: MakeOptions
) -> tuple[list[Lod], list]:
    """The impostor appended after the last geometric LOD, which now hands over at the
    impostor's distance; rendered from it, or from the last LOD that still draws CROWN_SHARE of
    LOD0's leaf area where a tiny budget (or many LODs stepping down) left the last ones bare
    trunks or a few leaves: a pole of an impostor would replace a crown."""
    lo, height = options.lod, tree_height(tree)
    distance = switch_distance(height, lods[-1].distance, lo, options.impostor)
    crown = CROWN_SHARE * _leaf_area(lods[0])
    source = next((lod for lod in reversed(lods) if _leaf_area(lod) >= crown), lods[-1])
    imp, material = build_impostor(source, materials, lo, distance, clip_name(len(lods)), options.impostor)
    last = replace(lods[-1], screen_coverage=screen_coverage(height, distance, lo))
    return [*lods[:-1], last, imp], [*materials, material]


@one_blas_thread
def build_asset(
    params: Params,
    seed: int = 0,
    options: MakeOptions = MakeOptions(),
    timings: Timings | None = None,
    tree: Tree | None = None,
) -> tuple[Asset, Tree]:
    """Grow, rig, mesh and animate `params` with `seed`; returns the asset and its tree.
    `tree`: the tree `generate(params, seed, options.generate)` already grew, to reuse.
    BLAS runs on one thread: its products here are small, and idle OpenBLAS threads spin on
    every core (0.3 CPU-s of the aspen's 1.4, no faster), taking it from a batch's workers."""
    timings = timings if timings is not None else Timings()
    check_joint_levels(params.levels, options.rig)
    # Materials first: they fix the leaf atlas layout the mesh maps leaves into, and a bad
    # --leaf-texture fails before anything is grown; the textures are drawn meanwhile.
    mats = timings.run("materials", build_materials, params, options.materials)
    options = replace(options, mesh=replace(options.mesh, leaf_cells=mats.leaf_cells))
    if options.budget.triangles is not None:  # the species and mesh that meet the budget
        plan = timings.run(
            "budget", plan_budget, params, seed, options.mesh, options.budget, options.generate
        )
        params, options, tree = plan.params, replace(options, mesh=plan.mesh), None
    if tree is None:
        tree = timings.run("generate", generate, params, seed, options.generate)
    lods = (
        [build_lod(tree, options, seed, timings)[0]]
        if options.lod is None
        else build_lods(params, tree, options, seed, timings)
    )
    materials = timings.run("textures", lambda: mats.materials)  # waits only if not done
    if any(p.material == TWIGS for lod in lods for p in lod.primitives):  # a far LOD's ribbons
        materials = [*materials, twig_material(next(m for m in materials if m.name == "bark"))]
    if options.lod is not None and options.impostor is not None:
        lods, materials = timings.run("impostor", add_impostor, lods, materials, tree, options)
    asset = Asset(
        name=params.name,
        materials=materials,
        lods=lods,
        extras={"species": params.name, "seed": seed, "generator": f"treegen {__version__}"},
    )
    return timings.run("prepare", prepare, asset), tree


def plan_asset(params: Params, seed: int = 0, options: MakeOptions = MakeOptions()) -> list[dict]:
    """What `build_asset` would build, per LOD: triangles, vertices, joints and the switch
    distance (metres), without its costly stages: the same budget plan, tree, LOD cuts, rigs
    and meshes (exactly the counts the build gets), no wind (it changes no count), textures or
    impostor atlas (the impostor's cards and one joint are counted, not rendered). For
    `treegen batch --dry-run`."""
    plain = replace(options, wind=None)  # the leaf cells the build's mesh maps leaves into
    plain = replace(plain, mesh=replace(plain.mesh, leaf_cells=leaf_cells(params, plain.materials)))
    if plain.budget.triangles is not None:
        plan = plan_budget(params, seed, plain.mesh, plain.budget, plain.generate)
        params, plain = plan.params, replace(plain, mesh=plan.mesh)
    tree = generate(params, seed, plain.generate)
    timings = Timings()
    lods = (
        [build_lod(tree, plain, seed, timings)[0]]
        if plain.lod is None
        else build_lods(params, tree, plain, seed, timings)
    )
    rows = [
        {
            "triangles": sum(len(p.indices) // 3 for p in lod.primitives),
            "vertices": sum(len(p.positions) for p in lod.primitives),
            "joints": len(lod.skeleton.names),
            "distance_m": float(lod.distance),
        }
        for lod in lods
    ]
    if plain.lod is not None and plain.impostor is not None:
        card = cards(np.zeros(3), 1.0, plain.impostor.grid)
        rows.append(
            {
                "triangles": len(card.indices) // 3,
                "vertices": len(card.positions),
                "joints": 1,
                "distance_m": switch_distance(
                    tree_height(tree), lods[-1].distance, plain.lod, plain.impostor
                ),
            }
        )
    return rows
