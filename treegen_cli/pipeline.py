"""The one-way pipeline behind `treegen make`: Params → Tree → Rig → Mesh + Clip → Asset.

Each stage is a function with an options dataclass whose defaults live beside it; this module
only composes them, so a newcomer can read `build_asset` top to bottom and see every step.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

from . import __version__
from .asset import Asset, Lod
from .generate import DEFAULTS as GENERATE_DEFAULTS, GenerateOptions, generate, regrow_leaves
from .exchange.compress import GLTF_DEFAULTS, GltfOptions
from .limits import LIMITS_DEFAULTS, Limits, check_keys, check_mesh
from .lod import LOD_DEFAULTS, LodOptions, decimate, lod_stage_options, match_leaf_area, screen_coverage
from .materials import MATERIAL_DEFAULTS, MaterialOptions, build_materials
from .mesh import MESH_DEFAULTS, MeshOptions, build_mesh
from .params import Params
from .prepare import prepare
from .rig import RIG_DEFAULTS, RigOptions, build_rig
from .tree import Tree, tree_height
from .wind import DEFAULTS as WIND_DEFAULTS, WindOptions, bake_wind

@dataclass(frozen=True)
class MakeOptions:
    """Options of every stage; `wind=None` writes a static (but skinned) tree."""

    generate: GenerateOptions = GENERATE_DEFAULTS
    rig: RigOptions = RIG_DEFAULTS
    mesh: MeshOptions = MESH_DEFAULTS
    wind: WindOptions | None = WIND_DEFAULTS
    lod: LodOptions | None = LOD_DEFAULTS   # None: one LOD with the dense clip
    limits: Limits = LIMITS_DEFAULTS        # refuse oversized meshes / clips before building
    materials: MaterialOptions = MATERIAL_DEFAULTS   # textures (generated or an artist's) or colours
    gltf: GltfOptions = GLTF_DEFAULTS       # --compress: how the glTF writer encodes (not the build)


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


def build_lod(tree: Tree, options: MakeOptions, seed: int, timings: Timings) -> Lod:
    """Rig, skin and animate one grown tree."""
    check_mesh(tree, options.mesh, options.limits)
    rig = timings.run("rig", build_rig, tree, options.rig)
    if options.wind is not None:
        check_keys(len(rig.skeleton.names), options.wind, options.limits)
    primitives = timings.run("mesh", build_mesh, tree, rig, options.mesh)
    clips = []
    if options.wind is not None:
        clip = timings.run("wind", bake_wind, tree, rig, options.wind, seed)
        clips.append(replace(clip, name=clip_name(0)))
    return Lod(primitives=primitives, skeleton=rig.skeleton, clips=clips)


def build_lods(params: Params, tree: Tree, options: MakeOptions, seed: int,
               timings: Timings) -> list[Lod]:
    """One coarser tree per LOD distance (lod.lod_stage_options), each with its own rig, mesh,
    dense wind (same wind options and seed, so the motion matches) and a clip decimated for its
    distance (clip_name(k)). LOD0 reuses `tree`; lower LODs regrow it from the same seed."""
    lo = options.lod
    area = float(tree.leaf_area.sum())
    height = tree_height(tree)
    lods = []
    for k, distance in enumerate(lo.distances):
        p, gen, rig, mesh = lod_stage_options(params, k, options.generate, options.rig,
                                              options.mesh, lo)
        t = tree if gen == options.generate and p == params else \
            timings.run("generate", regrow_leaves, tree, p, gen)
        if gen.levels is not None:
            t = match_leaf_area(t, area)
        lod = build_lod(t, replace(options, rig=rig, mesh=mesh), seed, timings)
        clips = [timings.run("lod", decimate, lod.skeleton, lod.primitives, c, distance, lo,
                             clip_name(k))[0] for c in lod.clips]
        # MSFT_screencoverage: LOD k is shown while the tree covers more than the coverage at
        # which LOD k+1 takes over; the last LOD is never culled.
        coverage = screen_coverage(height, lo.distances[k + 1], lo) if k + 1 < len(lo.distances) else 0.0
        lods.append(replace(lod, clips=clips, distance=float(distance), screen_coverage=coverage))
    return lods


def build_asset(params: Params, seed: int = 0, options: MakeOptions = MakeOptions(),
                timings: Timings | None = None, tree: Tree | None = None) -> tuple[Asset, Tree]:
    """Grow, rig, mesh and animate `params` with `seed`; returns the asset and its tree.
    `tree`: the tree `generate(params, seed, options.generate)` already grew, to reuse."""
    timings = timings if timings is not None else Timings()
    # Materials first: they fix the leaf atlas layout the mesh maps leaves into, and a bad
    # --leaf-texture fails before anything is grown; the textures are drawn meanwhile.
    mats = timings.run("materials", build_materials, params, options.materials)
    options = replace(options, mesh=replace(options.mesh, leaf_cells=mats.leaf_cells))
    if tree is None:
        tree = timings.run("generate", generate, params, seed, options.generate)
    lods = [build_lod(tree, options, seed, timings)] if options.lod is None else \
        build_lods(params, tree, options, seed, timings)
    materials = timings.run("textures", lambda: mats.materials)   # waits only if not done
    asset = Asset(name=params.name, materials=materials, lods=lods,
                  extras={"species": params.name, "seed": seed,
                          "generator": f"treegen {__version__}"})
    return timings.run("prepare", prepare, asset), tree
