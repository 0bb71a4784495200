"""The one-way pipeline behind `treegen make`: Params → Tree → Rig → Mesh + Clip → Asset.

Each stage is a function with an options dataclass whose defaults live beside it; this module
only composes them, so a newcomer can read `build_asset` top to bottom and see every step.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

from . import __version__
from .asset import Asset, Lod, Material
from .generate import DEFAULTS as GENERATE_DEFAULTS, GenerateOptions, generate
from .mesh import MESH_DEFAULTS, MeshOptions, build_mesh
from .params import Params
from .rig import RIG_DEFAULTS, RigOptions, build_rig
from .tree import Tree
from .wind import DEFAULTS as WIND_DEFAULTS, WindOptions, bake_wind

BARK = Material("bark", base_color=(0.36, 0.27, 0.19, 1.0), roughness=0.92)
LEAF = Material("leaf", base_color=(0.26, 0.46, 0.13, 1.0), roughness=0.7, double_sided=True)


@dataclass(frozen=True)
class MakeOptions:
    """Options of every stage; `wind=None` writes a static (but skinned) tree."""

    generate: GenerateOptions = GENERATE_DEFAULTS
    rig: RigOptions = RIG_DEFAULTS
    mesh: MeshOptions = MESH_DEFAULTS
    wind: WindOptions | None = WIND_DEFAULTS


@dataclass
class Timings:
    """Seconds per stage, for `treegen make`'s report and the benchmarks."""

    stages: dict[str, float] = field(default_factory=dict)

    def run(self, name, fn, *args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.stages[name] = self.stages.get(name, 0.0) + time.perf_counter() - t0
        return out


def build_lod(tree: Tree, options: MakeOptions, seed: int, timings: Timings) -> Lod:
    """Rig, skin and animate one grown tree."""
    rig = timings.run("rig", build_rig, tree, options.rig)
    primitives = timings.run("mesh", build_mesh, tree, rig, options.mesh)
    clips = []
    if options.wind is not None:
        clips.append(timings.run("wind", bake_wind, tree, rig, options.wind, seed))
    return Lod(primitives=primitives, skeleton=rig.skeleton, clips=clips)


def build_asset(params: Params, seed: int = 0, options: MakeOptions = MakeOptions(),
                timings: Timings | None = None) -> tuple[Asset, Tree]:
    """Grow, rig, mesh and animate `params` with `seed`; returns the asset and its tree."""
    timings = timings if timings is not None else Timings()
    tree = timings.run("generate", generate, params, seed, options.generate)
    lod0 = build_lod(tree, options, seed, timings)
    asset = Asset(name=params.name, materials=[BARK, LEAF], lods=[lod0],
                  extras={"species": params.name, "seed": seed,
                          "generator": f"treegen {__version__}"})
    return asset, tree
