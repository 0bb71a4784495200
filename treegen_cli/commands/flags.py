"""Every `make` option as a click option, defined once: name → flag spelling, help and metavar.
Type and default come from `options` (DEFAULTS, read from the stage DEFAULTS), so the click
options, `api.make` and catalogues cannot disagree. `use(*names)` turns names into decorators;
the groups `make` and `info` share are `options.GROUPS`.
"""

from __future__ import annotations

from pathlib import Path

import click
from click.core import ParameterSource

from ..errors import TreegenError
from ..executor import scheduler_address
from ..options import (
    CHOICES,
    DEFAULTS,
    MESH_DEFAULTS,
    FLAGS,
    FLOATS,
    GROUPS,
    INTS,
    OPTIONAL_FLOATS,
    OPTIONAL_INTS,
    PATHS,
)

# name → (extra flag spelling or None, help, metavar or None); the type and default are not here
HELP: dict[str, tuple[str | None, str, str | None]] = {
    "seed": (None, "Random seed: the same seed grows the same tree, byte for byte.", None),
    "max_stems": (None, "Refuse trees with more stems than this (estimated before growing).", None),
    "max_leaves": (None, "Refuse trees with more leaves than this (estimated before growing).", None),
    "max_size": (
        None,
        "Refuse trees taller, or with a crown wider, than this many metres: a "
        "plausibility bound that catches a mistyped Scale (the tallest living tree is "
        "about 116 m); raise it for giants on purpose.",
        "METRES",
    ),
    "lod_screen": (
        None,
        "LOD1, LOD2, … take over when the tree's height falls below these "
        "fractions of the screen height (distances per tree from its height and "
        "--fov).",
        "0.5,0.25,0.1",
    ),
    "lod_distances": (
        None,
        "Force the metres from which each LOD is used, from the centre of "
        "the tree's bounds (LOD0 first; at 0 it keeps the dense clip). Replaces "
        "--lod-screen.",
        "0,10,30,130",
    ),
    "fov": (None, "Horizontal field of view, degrees (16:9 screen).", None),
    "width": (None, "Screen width in pixels.", None),
    "error_px": (None, "Allowed on-screen error in pixels (the paper's i); 0 keeps every key.", None),
    "schedule": (
        None,
        "Key schedule per LOD. bounded: slerp between kept keys, every vertex "
        "within --error-px on a perspective screen seen from any direction at the "
        "LOD's switch distance; bounded-step: the same bound with keys held; paper: "
        "the paper's accumulate-and-reset rule as written (P/d > i·tan(fov)/width, "
        "held), unchecked. The held schedules hold LOD0's keys too, as the paper's engine "
        "updates at the clip's rate: the near tree steps at --fps in a faster engine (raise "
        "--fps, or use bounded).",
        None,
    ),
    "max_joints": (
        None,
        "Joint budget of the skeleton (>= 1); chains coarsen and the finest levels lose their joints first.",
        None,
    ),
    "joints": (None, "Joint budget: --max-joints by a shorter name.", "N"),
    "triangles": (
        None,
        "LOD0 triangle budget, met from 10 % under to N by the generator's own "
        "levers (fewer, larger leaves of the same area; fewer sides, segments and stem "
        "levels), or refused naming the fewest the species reaches [default: the "
        "species as is].",
        "N",
    ),
    "profile": (
        None,
        "Preset triangles, joints, texture and impostor sizes, clip length, fps and LOD "
        "distances for a platform (README table); options you give win over it.",
        None,
    ),
    "joint_levels": (None, "Stem levels allowed to own joints [default: all].", "0,1,2"),
    "sides": (
        None,
        "Cross-section sides per stem level, trunk first; the last value repeats; stems under "
        f"{MESH_DEFAULTS.thin_radius * 1000:g} mm in radius get {MESH_DEFAULTS.thin_sides} "
        "whatever their level [default: 16,8,6,4,3].",
        "16,8,6,4,3",
    ),
    "leaf_geometry": (
        None,
        "card: one textured quad per leaf (the leaf outline belongs in the "
        "texture's alpha); shape: the species' LeafShape outline as geometry.",
        None,
    ),
    "texture_size": (
        None,
        "Leaf atlas side in texels, a power of two in [64, 2048]; bark maps are half.",
        None,
    ),
    "impostor_size": (
        None,
        "Impostor atlas side in pixels, a power of two in [128, 2048]: 16 × 16 "
        "views of a sixteenth of it each [default: 2 × --texture-size, at most 1024].",
        "PX",
    ),
    "impostor_distance": (
        None,
        "Metres (from the tree's centre) from which the impostor is used, beyond the "
        "last LOD [default: where the tree is 96 px tall on screen, at least 1.5 × the "
        "last LOD's distance].",
        "M",
    ),
    "leaf_texture": (
        None,
        "Your own leaf image (PNG, alpha = cut-out), embedded as is; each "
        "card maps to the whole image [default: generated from the species].",
        "FILE.png",
    ),
    "bark_texture": (
        None,
        "Your own tileable bark image (PNG), embedded as is, wrapping once "
        "around every stem [default: generated albedo + normal map].",
        "FILE.png",
    ),
    "no_textures": (None, "Colour-only materials (species colours).", None),
    "wind_speed": (None, "Mean wind speed, m/s.", None),
    "wind_dir": (None, "Direction the wind blows towards, degrees (0 = +X, 90 = +Y in Z-up terms).", None),
    "gust": (None, "Gust intensity: σ of the gust process / mean speed.", None),
    "turbulence": (None, "Spatially varying turbulence: σ / mean speed.", None),
    "duration": (None, "Clip length in seconds (the wind loops over it).", None),
    "fps": (None, "Keys per second.", None),
    "stiffness": (
        None,
        "Multiplier on every joint's stiffness and the root plate's: 4 about doubles the "
        "natural frequencies and quarters the lean (see `treegen info --wind`).",
        None,
    ),
    "no_wind": (None, "Write no animation (rest pose only).", None),
    "up_axis": (
        None,
        "Up axis of USD, OBJ and PLY files, metres either way [default: y for "
        ".usdz .obj .ply, z for .usda .usdc]; glTF is always Y up.",
        None,
    ),
    "lod_triangles": (
        None,
        "Triangles of LOD1, LOD2, … as fractions of LOD0's (further LODs step on by "
        "the ratio of the last two, LOD0 counting as 1: 0.3 gives 0.3, 0.09, 0.027); a LOD never has more "
        "than the one before it, and never less than its trunk. Each is cut from "
        "LOD0's tree: fewer sides, stems thinner than half a pixel at its distance "
        "dropped, fewer leaves spread over the whole crown and scaled to cover what "
        "all of them cover.",
        "0.5,0.15,0.05",
    ),
    "no_lod": (None, "Write one LOD with the dense clip.", None),
    "lod_files": (
        None,
        "Write each LOD as its own complete file, NAME_LOD0.glb, NAME_LOD1.glb, "
        "… (for engines that ignore MSFT_lod: Godot, Unity LODGroup, Unreal).",
        None,
    ),
    "impostor": (
        "--no-impostor",
        "End the LODs with an impostor: crossed cards showing two views of a "
        "16×16-view hemi-octahedral atlas (albedo, normals + depth; described in the "
        "file's extras and NAME.glb.impostor.json), swaying with the trunk.",
        None,
    ),
    "compress": (
        None,
        "glTF only: quantize = KHR_mesh_quantization (integer positions, normals, "
        "UVs, rotations); meshopt = that plus EXT_meshopt_compression (needs the "
        "client's meshopt decoder). Both are required extensions; none is read by every "
        "importer.",
        None,
    ),
    "max_vertices": (
        None,
        "Refuse meshes with more vertices than this per LOD (counted from the "
        "grown tree before the mesh is built).",
        None,
    ),
    "max_keys": (None, "Refuse wind clips with more joint-keys (joints × keys) than this.", None),
}

# the order `treegen make --help` lists them in
MAKE = (
    "max_joints",
    "joints",
    "triangles",
    "profile",
    "joint_levels",
    "sides",
    "leaf_geometry",
    "texture_size",
    "leaf_texture",
    "bark_texture",
    "no_textures",
    "wind_speed",
    "wind_dir",
    "gust",
    "turbulence",
    "duration",
    "fps",
    "stiffness",
    "no_wind",
    "up_axis",
    *GROUPS["lod"],
    "lod_triangles",
    "no_lod",
    "lod_files",
    "impostor",
    "impostor_size",
    "impostor_distance",
    "compress",
    "max_vertices",
    "max_keys",
)


def option(name: str, help: str | None = None):
    """The click option of make option `name` (`help` replaces the shared text)."""
    other, text, metavar = HELP[name]
    flag = "--" + name.replace("_", "-")
    default = DEFAULTS[name]
    kw: dict = {"default": default, "help": help or text}
    if metavar:
        kw["metavar"] = metavar
    if name in FLAGS:
        decls = [f"{flag}/{other}"] if other else [flag]
        kw |= {"is_flag": True} if other is None else {"show_default": True}
        return click.option(*decls, **kw)
    if name in CHOICES:
        kw["type"] = click.Choice([c for c in CHOICES[name] if c is not None])
    elif name in INTS or name in OPTIONAL_INTS:
        kw["type"] = int
    elif name in FLOATS or name in OPTIONAL_FLOATS:
        kw["type"] = float
    elif name in PATHS:
        kw["type"] = click.Path(path_type=Path)
    kw["show_default"] = default is not None and name != "lod_distances"
    return click.option(flag, **kw)


def use(*names: str, help: dict[str, str] | None = None):
    """A decorator adding the click options of `names`, listed in that order in --help."""

    def apply(f):
        for name in reversed(names):
            f = option(name, (help or {}).get(name))(f)
        return f

    return apply


def json_flag(help: str):
    return click.option("--json", "as_json", is_flag=True, help=help)


def cluster(workers_help: str, scheduler_help: str):
    """--workers and --scheduler, which `batch` and `forest` share (checked by check_cluster)."""

    def apply(f):
        f = click.option("--scheduler", default=None, metavar="tcp://HOST:8786", help=scheduler_help)(f)
        return click.option("--workers", type=int, default=None, help=workers_help)(f)

    return apply


def check_cluster(workers: int | None, scheduler: str | None) -> None:
    """--workers only makes sense on this machine (not with a cluster), and needs at least one."""
    if workers is not None and workers < 1:
        raise TreegenError(f"--workers {workers}: must be at least 1")
    if workers is not None and scheduler_address(scheduler):
        raise TreegenError(
            f"--workers {workers}: only for workers on this machine; a --scheduler "
            "(or DASK_SCHEDULER_ADDRESS) cluster has its own workers"
        )


def given(values: dict) -> dict:
    """The options the user gave (not click defaults), so a --profile fills only the rest:
    resolve() applies the profile, then the defaults, to what is missing."""
    ctx = click.get_current_context()
    return {
        k: v for k, v in values.items() if ctx.get_parameter_source(k) not in (ParameterSource.DEFAULT, None)
    }
