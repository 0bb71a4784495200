"""`--profile mobile|web|desktop|hero`: presets of `make` options for a target platform.

One row per profile; its keys are `make` option names (api.DEFAULTS) and its values what the
option would take. A profile only fills options the user left out: any option given on the
command line (click's parameter source), in the API call or in a catalogue entry wins.

    apply_profile({"profile": "mobile", "fps": 30.0})
    # → {"profile": "mobile", "fps": 30.0, "triangles": 20000, "max_joints": 64, ...}

The README's profile table is `markdown_table()` (tests/test_budget.py keeps them equal).
"""

from __future__ import annotations

from typing import Callable

from .errors import TreegenError

# The options each row sets. lod_screen: the tree's height on screen below which LOD1, LOD2, …
# take over (lod.switch_distances); lod_triangles: their budgets as fractions of LOD0's
# (lod_budget.py); triangles: the LOD0 budget (budget.py); compress: the glTF encoding (web
# pages decode meshopt; game engines' importers mostly read only plain files: README);
# impostor_size: the impostor atlas's side (mobile and web: 32 px views, a third of the bytes;
# 64 px views suffice where the impostor takes over, so hero stays at 1024).
PROFILES: dict[str, dict[str, object]] = {
    "mobile": {
        "triangles": 20_000,
        "max_joints": 64,
        "texture_size": 256,
        "impostor_size": 512,
        "duration": 6.0,
        "fps": 15.0,
        "lod_screen": "0.3,0.1",
        "lod_triangles": "0.4,0.1",
        "compress": "none",
    },
    "web": {
        "triangles": 50_000,
        "max_joints": 128,
        "texture_size": 512,
        "impostor_size": 512,
        "duration": 8.0,
        "fps": 24.0,
        "lod_screen": "0.4,0.2,0.08",
        "lod_triangles": "0.5,0.15,0.05",
        "compress": "meshopt",
    },
    "desktop": {
        "triangles": 150_000,
        "max_joints": 256,
        "texture_size": 1024,
        "impostor_size": 1024,
        "duration": 10.0,
        "fps": 30.0,
        "lod_screen": "0.5,0.25,0.1",
        "lod_triangles": "0.5,0.15,0.05",
        "compress": "none",
    },
    "hero": {
        "triangles": 500_000,
        "max_joints": 512,
        "texture_size": 2048,
        "impostor_size": 1024,
        "duration": 20.0,
        "fps": 30.0,
        "lod_screen": "0.6,0.3,0.12",
        "lod_triangles": "0.5,0.2,0.05",
        "compress": "none",
    },
}
PURPOSE = {
    "mobile": "phones and tablets; many trees on screen",
    "web": "three.js / Babylon.js pages; download size matters",
    "desktop": "PC and console games",
    "hero": "a close-up tree in a cinematic or a foreground",
}
NAMES = tuple(PROFILES)


def apply_profile(options: dict, label: Callable[[str], str] = lambda k: "--" + k.replace("_", "-")) -> dict:
    """`options` with the named profile's values for every option not given in it; without
    a `profile` key (or None), `options` unchanged."""
    name = options.get("profile")
    if name is None:
        return options
    if name not in PROFILES:
        raise TreegenError(f"{label('profile')} {name!r}: use one of {', '.join(NAMES)}")
    return {**PROFILES[name], **options}


def markdown_table() -> str:
    """The README's table: one row per profile, one column per option it sets."""
    keys = list(dict.fromkeys(k for row in PROFILES.values() for k in row))
    head = "| profile | " + " | ".join(f"`--{k.replace('_', '-')}`" for k in keys) + " | for |"
    rule = "|---|" + "---|" * len(keys) + "---|"
    rows = []
    for name, row in PROFILES.items():
        cells = []
        for k in keys:
            v = row.get(k, "")
            cells.append(
                f"{v:,}"
                if isinstance(v, int) and v >= 10_000
                else f"{v:g}"
                if isinstance(v, float)
                else str(v)
            )
        rows.append(f"| `{name}` | " + " | ".join(cells) + f" | {PURPOSE[name]} |")
    return "\n".join([head, rule, *rows])
