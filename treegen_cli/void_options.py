"""Options the rest of a `make` request makes void (`--wind-speed` with `--no-wind`, an
impostor size with `--no-impostor`, `--impostor` with `--no-lod`, LOD options for a static
format): refused by name, not
silently ignored. Called before a profile fills its own values: those are defaults, not
requests.

    check_no_effect({"no_wind": True, "error_px": 3}, cli_name, "a.glb")
    # Result: TreegenError "--error-px: has no effect, --no-wind builds no clip; leave it out"
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from .errors import TreegenError
from .exchange import STATIC

# options that shape only the clip, only the LODs, only the impostor
WIND_ONLY = ("wind_speed", "wind_dir", "gust", "turbulence", "duration", "fps", "stiffness")
IMPOSTOR_ONLY = ("impostor_size", "impostor_distance")
KEYS_ONLY = ("schedule", "error_px")  # the LODs' key schedule: void without a clip
SKIN_ONLY = ("max_joints", "joints", "joint_levels")  # the rig: void for a static format
TEXTURE_ONLY = ("texture_size", "leaf_texture", "bark_texture")  # void where nothing is textured
LOD_ONLY = ("lod_screen", "lod_distances", "lod_triangles", "lod_files", *KEYS_ONLY, *IMPOSTOR_ONLY)


def static_format(output) -> bool:
    """Whether `output` is a static format (.obj .ply): no wind or LODs."""
    return output is not None and Path(output).suffix.lower() in STATIC


def typed_name(k: str, value, label: Callable[[str], str]) -> str:
    """Option `k` as the user typed it: its label, `--no-impostor` for `--impostor` given off."""
    name = label(k)
    return "--no-impostor" if name == "--impostor" and value is False else name


def _given(options: dict, keys) -> list[str]:
    """The `keys` the user gave: a flag when set, a value when given at all (0 included)."""
    return [k for k in keys if options.get(k) is not None and options.get(k) is not False]


def check_no_effect(options: dict, label: Callable[[str], str], output) -> None:
    """Refuse an option the user gave that the rest of the request makes void (called before
    a profile fills its own: those are defaults, not requests), as _given counts them."""
    static = static_format(output)
    given = _given(options, (*WIND_ONLY, *LOD_ONLY))
    for k in given:
        if static:
            why = f"a {Path(output).suffix.lower()} file holds no wind or LODs (static format)"
        elif (k in WIND_ONLY or k in KEYS_ONLY) and options.get("no_wind"):
            why = f"{label('no_wind')} builds no clip"
        elif k in LOD_ONLY and options.get("no_lod"):
            why = f"{label('no_lod')} builds one LOD"
        elif k in IMPOSTOR_ONLY and options.get("impostor") is False:
            off = "--no-impostor" if label("impostor") == "--impostor" else f"{label('impostor')} false"
            why = f"{off} builds no impostor"
        else:
            continue
        raise TreegenError(f"{label(k)}: has no effect, {why}; leave it out")
    if options.get("impostor") is not None and (static or options.get("no_lod")):  # either way
        why = (
            f"a {Path(output).suffix.lower()} file holds no LODs (static format)"
            if static
            else f"{label('no_lod')} builds one LOD, never an impostor"
        )
        raise TreegenError(
            f"{typed_name('impostor', options['impostor'], label)}: has no effect, {why}; leave it out"
        )
    suffix = Path(output).suffix.lower() if output is not None else ""
    for k in (*SKIN_ONLY, *TEXTURE_ONLY):
        if options.get(k) is None:
            continue
        if static and k in SKIN_ONLY:
            why = f"a {suffix} file holds no skin (static format)"
        elif suffix == ".ply" and k in TEXTURE_ONLY:
            why = "a .ply file holds no textures (one mesh, no materials)"
        else:
            continue
        raise TreegenError(f"{label(k)}: has no effect, {why}; leave it out")
    if options.get("lod_distances") is not None and options.get("lod_screen") is not None:
        raise TreegenError(
            f"{label('lod_screen')}: has no effect, {label('lod_distances')} replaces it; give one of them"
        )


def check_formats(options: dict, formats: list, label: Callable[[str], str], where: str) -> None:
    """Refuse, for a catalogue entry written as `formats` (its JSON path `where`), an option
    typed in it that one of those formats cannot take: `compress` on a non-glTF format (a
    profile's is for glTF only, and dropped there), `lod_files` on a static one, which holds
    LOD0 alone, a wind or LOD option where every format is static (make refuses them all; a
    batch must not write what make would not)."""
    import json

    if formats and all(static_format(f"x.{f}") for f in formats):  # as make refuses for x.obj
        typed = _given(options, (*WIND_ONLY, *LOD_ONLY, *SKIN_ONLY))
        typed += ["impostor"] if options.get("impostor") is not None else []  # either way
        typed = [k for k in typed if not label(k).startswith("defaults.")]  # (those serve others)
        if typed:
            raise TreegenError(
                f"{label(typed[0])}: has no effect, {where} {json.dumps(formats)} holds no wind, "
                "LODs or skin (static formats); leave it out"
            )
    for k, f in enumerate(formats):
        if options.get("compress") not in (None, "none") and f not in ("glb", "gltf"):
            raise TreegenError(
                f"{label('compress')}: {options['compress']} is for glb/gltf only, but "
                f"{where}[{k}] is {json.dumps(f)} (no other format has such an encoding)"
            )
        if options.get("lod_files") and static_format(f"x.{f}"):
            raise TreegenError(
                f"{label('lod_files')}: has no effect on {where}[{k}] {json.dumps(f)}, a static format "
                "holds no wind or LODs; give that format an entry of its own"
            )
