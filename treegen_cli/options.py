"""`make` options: one table of every option a user can give (`DEFAULTS`, read from the stage
DEFAULTS beside each stage), their types, and `resolve()`, which validates them and builds the
stage options. The CLI's `make`/`info`, `api.make` and `treegen batch` catalogues all come
through here, so they share defaults, validation and error messages.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from .budget import BudgetOptions
from .errors import OptionError, TreegenError
from .exchange import COMPRESS, FIXED_UP_AXIS, GLTF_DEFAULTS, GltfOptions, check_compress
from .generate import DEFAULTS as GENERATE_DEFAULTS, GenerateOptions
from .impostor import IMPOSTOR_SIZES, atlas_side, placed
from .limits import LIMITS_DEFAULTS, Limits
from .lod import LOD_DEFAULTS, SCHEDULES, LodOptions, pixel_size
from .materials import MATERIAL_DEFAULTS, TEXTURE_SIZES, MaterialOptions
from .mesh import MESH_DEFAULTS
from .params import MAX_LEVELS
from .pipeline import MakeOptions
from .profiles import NAMES as PROFILE_NAMES, apply_profile
from .rig import MAX_JOINTS, RIG_DEFAULTS, RigOptions
from .wind import DEFAULTS as WIND_DEFAULTS, WindOptions
from .void_options import IMPOSTOR_ONLY, WIND_ONLY, check_no_effect, static_format


def _text(value) -> str:
    if isinstance(value, (list, tuple)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    return str(value)


# Every `make` option (CLI name with underscores) and its default, read from the stage that owns
# it: the click options, the catalogue schema (tests/test_batch.py) and the README read these.
DEFAULTS: dict[str, object] = {
    "seed": 0,
    "max_stems": GENERATE_DEFAULTS.max_stems,
    "max_leaves": GENERATE_DEFAULTS.max_leaves,
    "max_size": GENERATE_DEFAULTS.max_size,
    "max_joints": RIG_DEFAULTS.max_joints,
    "joint_levels": RIG_DEFAULTS.joint_levels,
    "sides": None,  # None: MESH_DEFAULTS.sides (budgets may cut)
    "leaf_geometry": MESH_DEFAULTS.leaf_geometry,
    "texture_size": MATERIAL_DEFAULTS.texture_size,
    "impostor_size": None,  # None: impostor.atlas_side(texture_size)
    "impostor_distance": None,  # None: where the tree is switch_px tall (impostor.switch_distance)
    "leaf_texture": MATERIAL_DEFAULTS.leaf_texture,
    "bark_texture": MATERIAL_DEFAULTS.bark_texture,
    "no_textures": not MATERIAL_DEFAULTS.textures,
    "wind_speed": WIND_DEFAULTS.speed,
    "wind_dir": WIND_DEFAULTS.direction_deg,
    "gust": WIND_DEFAULTS.gust,
    "turbulence": WIND_DEFAULTS.turbulence,
    "duration": WIND_DEFAULTS.duration,
    "fps": WIND_DEFAULTS.fps,
    "stiffness": WIND_DEFAULTS.stiffness,
    "no_wind": False,
    "lod_screen": _text(LOD_DEFAULTS.screen),
    "lod_distances": LOD_DEFAULTS.distances,
    "fov": LOD_DEFAULTS.fov_deg,
    "width": LOD_DEFAULTS.width,
    "error_px": LOD_DEFAULTS.error_px,
    "schedule": LOD_DEFAULTS.schedule,
    "lod_triangles": _text(LOD_DEFAULTS.triangles[1:]),  # LOD0 is always 1.0
    "no_lod": False,
    "lod_files": False,
    "impostor": True,
    "up_axis": None,  # None: the format's own (exchange/)
    "compress": GLTF_DEFAULTS.compress,
    "max_vertices": LIMITS_DEFAULTS.max_vertices,
    "max_keys": LIMITS_DEFAULTS.max_keys,
    "triangles": None,
    "joints": None,
    "profile": None,
}
# Options `make` shares with `info` (commands/flags.py turns each group into click options)
GROUPS: dict[str, tuple[str, ...]] = {
    "generate": ("seed", "max_stems", "max_leaves", "max_size"),
    "lod": ("lod_screen", "lod_distances", "fov", "width", "error_px", "schedule"),
    "wind": ("wind_speed", "wind_dir", "gust", "turbulence", "duration", "fps", "stiffness"),
}
INTS = ("seed", "max_stems", "max_leaves", "max_joints", "width", "max_vertices", "max_keys", "texture_size")
# None: no budget; --max-joints decides; 2 × --texture-size (impostor.atlas_side)
OPTIONAL_INTS = ("triangles", "joints", "impostor_size")
# Options added after assets were first keyed: left out of identity hashes while unset, so a
# catalogue built before they existed keeps its keys (batch/catalogue.py).
UNSET_FREE = ("triangles", "joints", "profile", "impostor_size", "impostor_distance")
OPTIONAL_FLOATS = ("impostor_distance",)
PATHS = ("leaf_texture", "bark_texture")
# What else `info --lod` builds the LODs with, as `make` would (a profile's LODs and impostor)
INFO_LOD_BUILD = ("lod_triangles", "max_joints", "joints", "profile", "impostor", *IMPOSTOR_ONLY)
FLOATS = ("max_size", "fov", "error_px", *WIND_ONLY)
FLAGS = ("no_wind", "no_lod", "lod_files", "no_textures", "impostor")
CHOICES = {
    "leaf_geometry": ("card", "shape"),
    "schedule": SCHEDULES,
    "up_axis": (None, "y", "z"),
    "profile": (None, *PROFILE_NAMES),
    "compress": COMPRESS,
}
LISTS = ("joint_levels", "sides", "lod_screen", "lod_distances", "lod_triangles")
# list option → (what its values are, an example) for messages about a malformed list
LIST_EXAMPLES = {
    "joint_levels": ("whole numbers", "0,1,2"),
    "sides": ("whole numbers", "16,8,6,4,3"),
    "lod_screen": ("fractions", "0.5,0.25,0.1"),
    "lod_distances": ("metres", "0,10,30,130"),
    "lod_triangles": ("fractions", "0.5,0.15,0.05"),
}
# stage option fields (WindOptions, LodOptions) → the make option a user typed for them
STAGE_FIELDS = {
    "speed": "wind_speed",
    "direction_deg": "wind_dir",
    "distances": "lod_distances",
    "fov_deg": "fov",
    "screen": "lod_screen",
}


def cli_name(key: str) -> str:
    """How the CLI spells an option in messages: `wind_speed` → `--wind-speed`."""
    return "--" + key.replace("_", "-")


@dataclass(frozen=True)
class Resolved:
    """One validated set of make options: the seed, the stage options, and the canonical
    option values (defaults filled in, lists as numbers) that identify the output."""

    seed: int
    options: MakeOptions
    values: dict


def _number_list(key: str, value, kind: type, label: Callable[[str], str]) -> tuple | None:
    """A list option from a list/tuple of numbers or from the CLI's comma-separated text."""
    if value is None:
        return None
    if isinstance(value, str):
        items = value.split(",") if value.strip() else []
        try:  # an empty value between commas ("0.5,,0.1") is refused too
            values = tuple(kind(v) for v in items)
        except ValueError:
            what, example = LIST_EXAMPLES[key]
            empty = "an empty value between commas; " if any(not v.strip() for v in items) else ""
            raise TreegenError(
                f"{label(key)} '{value}': {empty}expected comma-separated {what}, e.g. {example}"
            ) from None
    elif isinstance(value, (list, tuple)) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and (kind is float or float(v).is_integer())
        for v in value
    ):
        values = tuple(kind(v) for v in value)
    else:
        what, example = LIST_EXAMPLES[key]
        raise TreegenError(f"{label(key)} {value!r}: expected a list of {what} or text like {example}")
    if not values and kind is int:
        raise TreegenError(f"{label(key)} '{_text(value)}': give at least one value")
    return values


def _scalar(key: str, value, label: Callable[[str], str]):
    """Type-check one scalar option (click did this for the CLI; the API and catalogues need it)."""
    if key in FLAGS:
        if not isinstance(value, bool):
            raise TreegenError(f"{label(key)} {value!r}: expected true or false")
        return value
    if key in (*OPTIONAL_INTS, *OPTIONAL_FLOATS) and value is None:
        return None
    if key in INTS or key in OPTIONAL_INTS:
        if isinstance(value, bool) or not isinstance(value, int):
            raise TreegenError(f"{label(key)} {value!r}: expected a whole number")
        return value
    if key in FLOATS or key in OPTIONAL_FLOATS:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise TreegenError(f"{label(key)} {value!r}: expected a finite number")
        return float(value)
    if key in PATHS:
        if value is not None and not isinstance(value, (str, os.PathLike)):
            raise TreegenError(f"{label(key)} {value!r}: expected a PNG file name")
        return None if value is None else Path(value)
    if key in CHOICES:
        if value not in CHOICES[key]:
            raise TreegenError(
                f"{label(key)} {value!r}: use one of {', '.join(str(c).lower() for c in CHOICES[key])}"
            )
        return value
    return value


def _power_of_two(flag: str, n: int, bounds: tuple[int, int], rule: str) -> None:
    """Image sides: a power of two within `bounds` (`rule` words the message, {lo}/{hi})."""
    lo, hi = bounds
    if not (lo <= n <= hi and n & (n - 1) == 0):
        raise TreegenError(f"{flag} {n}: " + rule.format(lo=lo, hi=hi))


MAX_SEED = 2**63 - 1  # every seed (make, batch, forest layouts): numpy's int64


def resolve(
    options: dict,
    label: Callable[[str], str] = cli_name,
    output: str | os.PathLike | None = None,
    void_check: bool = True,
) -> Resolved:
    """Validate `make` options (missing ones take DEFAULTS) and build the stage options.
    For a static `output` format (.obj .ply) no wind or LODs are built: it cannot hold them.

    `label(key)` names an option in messages: `--max-joints` for the CLI and the API, a JSON
    path for a catalogue entry. Every refusal is a TreegenError naming the option and range.
    `void_check`: refuse an option the rest of the request makes void (--wind-speed with
    --no-wind); a catalogue turns it off, its defaults and grids combine options on purpose."""
    unknown = sorted(set(options) - set(DEFAULTS))
    if unknown:
        raise TreegenError(f"unknown make option '{unknown[0]}'; allowed: {', '.join(DEFAULTS)}")
    typed = _typed_as_joints(label) if options.get("joints") is not None else label
    options = _joints_alias(options, label)
    label = typed  # the joint budget's messages name the spelling the user gave
    if void_check:  # (a catalogue's grids and defaults combine options on purpose)
        check_no_effect(options, label, output)
    given = options
    options = apply_profile(options, label) if options.get("profile") is not None else options
    if (
        given.get("compress") is None
        and output is not None
        and Path(output).suffix.lower() not in FIXED_UP_AXIS
    ):
        options = {**options, "compress": "none"}  # a profile's glTF encoding: not for USD, OBJ
    v = {k: _scalar(k, options.get(k, d), label) for k, d in DEFAULTS.items()}
    v["joint_levels"] = _number_list("joint_levels", v["joint_levels"], int, label)
    v["sides"] = _number_list("sides", v["sides"], int, label)
    v["lod_distances"] = _number_list("lod_distances", v["lod_distances"], float, label)
    v["lod_triangles"] = _number_list("lod_triangles", v["lod_triangles"], float, label)
    v["lod_screen"] = _number_list("lod_screen", v["lod_screen"], float, label)

    if not v["no_lod"]:
        t = v["lod_triangles"]
        if not t or any(not (math.isfinite(x) and 0 < x <= 1) for x in t) or list(t) != sorted(t)[::-1]:
            raise TreegenError(
                f"{label('lod_triangles')} '{_text(t)}': give LOD1, LOD2, … triangles as fractions of "
                "LOD0's, each in (0, 1] and none above the one before, e.g. 0.5,0.15,0.05"
            )
    if v["triangles"] is not None and not 1 <= v["triangles"] <= 100_000_000:
        raise TreegenError(
            f"{label('triangles')} {v['triangles']}: the LOD0 triangle budget must be in [1, 100000000]"
        )
    if v["max_joints"] < 1:
        raise TreegenError(f"{label('max_joints')} {v['max_joints']}: the joint budget must be at least 1")
    mesh = replace(MESH_DEFAULTS, leaf_geometry=v["leaf_geometry"])
    if v["sides"] is not None:
        if min(v["sides"]) < 3 or max(v["sides"]) > 64:
            raise TreegenError(
                f"{label('sides')} '{_text(options.get('sides'))}': each value must be in [3, 64]"
            )
        mesh = replace(mesh, sides=v["sides"])
    if not 0 <= v["seed"] <= MAX_SEED:
        raise TreegenError(f"{label('seed')} {v['seed']}: allowed range 0..{MAX_SEED}")
    for key in ("max_stems", "max_leaves", "max_vertices", "max_keys"):
        if v[key] < 1:
            raise TreegenError(f"{label(key)} {v[key]}: the limit must be at least 1")
    for key, what in (("max_size", "the bound"), ("impostor_distance", "the distance")):
        if v[key] is not None and not v[key] > 0:
            raise TreegenError(f"{label(key)} {v[key]:g}: {what} must be > 0 metres")
    if v["joint_levels"] is not None and not all(0 <= n <= MAX_LEVELS for n in v["joint_levels"]):
        raise TreegenError(
            f"{label('joint_levels')} '{_text(v['joint_levels'])}': each stem "
            f"level must be in 0..{MAX_LEVELS}"
        )
    if v["max_joints"] > MAX_JOINTS:
        raise TreegenError(
            f"{label('max_joints')} {v['max_joints']}: the joint budget must be in 1..{MAX_JOINTS}"
        )
    n = v["texture_size"]
    _power_of_two(label("texture_size"), n, TEXTURE_SIZES, "must be a power of two in [{lo}, {hi}]")
    side = v["impostor_size"]
    if side is not None:
        _power_of_two(
            label("impostor_size"),
            side,
            IMPOSTOR_SIZES,
            "the atlas side must be a power of two in [{lo}, {hi}] px",
        )
    static = static_format(output)
    if output is not None:
        check_compress(output, v["compress"], label("compress"))
    try:  # a stage's range check names its own field: say what the user typed instead
        wind = (
            None
            if v["no_wind"] or static
            else WindOptions(
                speed=v["wind_speed"],
                direction_deg=v["wind_dir"],
                gust=v["gust"],
                turbulence=v["turbulence"],
                duration=v["duration"],
                fps=v["fps"],
                stiffness=v["stiffness"],
            )
        )
        # LodOptions checks --lod-screen/--lod-distances (also for a static format, which
        # then drops the LODs)
        lod = (
            None
            if v["no_lod"]
            else LodOptions(
                distances=v["lod_distances"],
                screen=v["lod_screen"],
                fov_deg=v["fov"],
                width=v["width"],
                error_px=v["error_px"],
                schedule=v["schedule"],
                triangles=(1.0, *v["lod_triangles"]),
            )
        )
    except OptionError as e:
        raise TreegenError(e.worded(label(STAGE_FIELDS.get(e.field, e.field)))) from None
    lod = None if static else lod

    make_options = MakeOptions(
        impostor=placed(side or atlas_side(n), v["impostor_distance"], label("impostor_distance"), lod)
        if v["impostor"] and lod is not None
        else None,
        generate=GenerateOptions(
            max_stems=v["max_stems"], max_leaves=v["max_leaves"], max_size=v["max_size"]
        ),
        rig=RigOptions(max_joints=v["max_joints"], joint_levels=v["joint_levels"]),
        mesh=mesh,
        wind=wind,
        lod=lod,
        limits=Limits(max_vertices=v["max_vertices"], max_keys=v["max_keys"]),
        materials=MaterialOptions(
            textures=not v["no_textures"],
            texture_size=v["texture_size"],
            leaf_texture=v["leaf_texture"],
            bark_texture=v["bark_texture"],
            cut_out=v["leaf_geometry"] != "shape",
        ),
        budget=BudgetOptions(
            triangles=v["triangles"],
            fixed_sides=v["sides"] is not None,
            ceiling=given.get("triangles") is None,  # a profile's budget: a ceiling
        ),
        gltf=GltfOptions(
            compress=v["compress"],
            pixel_size=pixel_size(1.0, lod) if lod is not None and v["compress"] == "meshopt" else 0.0,
        ),
    )

    values = {
        k: list(x) if isinstance(x, tuple) else str(x) if isinstance(x, Path) else x for k, x in v.items()
    }
    return Resolved(seed=v["seed"], options=make_options, values=values)


def _typed_as_joints(label: Callable[[str], str]) -> Callable[[str], str]:
    """`label` naming the joint budget `joints` (`--joints`), as the user gave it."""
    return lambda key: label("joints" if key == "max_joints" else key)


def _joints_alias(options: dict, label: Callable[[str], str]) -> dict:
    """`joints` is `max_joints` by a shorter name: merged into it (both given must agree)."""
    joints = _scalar("joints", options.get("joints"), label)
    if joints is None:
        return options
    if options.get("max_joints", joints) != joints:
        raise TreegenError(
            f"{label('joints')} {joints} and {label('max_joints')} "
            f"{options['max_joints']}: the same joint budget; give one of them"
        )
    return {**{k: x for k, x in options.items() if k != "joints"}, "max_joints": joints}
