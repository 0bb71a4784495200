"""Each option default is defined once, beside its stage (wind.DEFAULTS, lod.LOD_DEFAULTS,
rig/mesh/materials/limits); `make`'s option table, the click options, the layout schema and
the README read or quote it. These fail when a copy drifts."""

from __future__ import annotations

import json
import re
from pathlib import Path

from click.testing import CliRunner

from treegen_cli.cli import cli
from treegen_cli.forest.schema import FOREST_LOOP_S, layout_schema
from treegen_cli.generate import DEFAULTS as GENERATE_DEFAULTS
from treegen_cli.impostor import IMPOSTOR_DEFAULTS
from treegen_cli.limits import LIMITS_DEFAULTS
from treegen_cli.lod import LOD_DEFAULTS
from treegen_cli.materials import MATERIAL_DEFAULTS
from treegen_cli.mesh import MESH_DEFAULTS
from treegen_cli.options import DEFAULTS, resolve
from treegen_cli.rig import RIG_DEFAULTS
from treegen_cli.wind import DEFAULTS as WIND_DEFAULTS

ROOT = Path(__file__).resolve().parents[1]


def test_make_with_no_options_builds_exactly_the_stage_defaults():
    o = resolve({}).options
    assert o.wind == WIND_DEFAULTS and o.lod == LOD_DEFAULTS and o.rig == RIG_DEFAULTS
    assert o.mesh == MESH_DEFAULTS and o.materials == MATERIAL_DEFAULTS
    assert o.limits == LIMITS_DEFAULTS and o.generate == GENERATE_DEFAULTS
    assert o.impostor == IMPOSTOR_DEFAULTS


def test_layout_schema_publishes_the_stage_defaults():
    props = {
        k: v["properties"]
        for k, v in layout_schema()["properties"].items()
        if k in ("camera", "wind", "defaults")
    }
    wind = {k: v.get("default") for k, v in props["wind"].items()}
    assert (wind["speed"], wind["direction_deg"], wind["gust"], wind["turbulence"], wind["fps"]) == (
        WIND_DEFAULTS.speed,
        WIND_DEFAULTS.direction_deg,
        WIND_DEFAULTS.gust,
        WIND_DEFAULTS.turbulence,
        WIND_DEFAULTS.fps,
    )
    assert wind["duration"] == FOREST_LOOP_S  # the forest's own loop, stated once
    assert props["camera"]["fov_deg"]["default"] == LOD_DEFAULTS.fov_deg
    assert props["camera"]["width_px"]["default"] == LOD_DEFAULTS.width
    assert props["defaults"]["error_px"]["default"] == LOD_DEFAULTS.error_px
    printed = json.loads(CliRunner().invoke(cli, ["forest", "--schema"]).output)
    assert printed == layout_schema()


def _g(x) -> str:
    return f"{x:g}"


def test_readme_quotes_the_defaults():
    text = re.sub(r"\s+", " ", (ROOT / "README.md").read_text())
    quotes = [
        f"`--max-joints` ({DEFAULTS['max_joints']})",
        f"a {_g(WIND_DEFAULTS.duration)} s wind loop at {_g(WIND_DEFAULTS.fps)} fps",
        f"`--texture-size`, {DEFAULTS['texture_size']}:",
        f"`--lod-screen {DEFAULTS['lod_screen']}`",
        f"`--fov` ({_g(LOD_DEFAULTS.fov_deg)}°)",
        f"`--lod-triangles` ({DEFAULTS['lod_triangles']}:",
        f"`--error-px` ({_g(LOD_DEFAULTS.error_px)}) pixels",
        f"`--width` {LOD_DEFAULTS.width} px",
    ]
    missing = [q for q in quotes if q not in text]
    assert not missing, f"README no longer quotes these defaults: {missing}"


def test_lod_flags_are_checked_once_in_lod_options_and_worded_as_typed():
    import pytest

    from treegen_cli.errors import TreegenError
    from treegen_cli.lod import LodOptions

    with pytest.raises(TreegenError) as stage:
        LodOptions(screen=(0.5, 0.6))
    with pytest.raises(TreegenError) as cli_msg:
        resolve({"lod_screen": "0.5,0.6"})
    with pytest.raises(TreegenError) as catalogue:
        resolve({"lod_screen": [0.5, 0.6]}, label=lambda k: f"entries[0].{k}")
    assert (
        str(stage.value)
        == str(cli_msg.value)
        == (
            "--lod-screen 0.5,0.6: give descending fractions of the screen height (not "
            "percentages), each in [0.0001, 4], e.g. 0.5,0.25,0.1"
        )
    )
    assert str(catalogue.value).startswith("entries[0].lod_screen 0.5,0.6: give descending")
    with pytest.raises(TreegenError, match=r"^--lod-distances 0,10,10: distances repeat$"):
        resolve({"lod_distances": "0,10,10"})


def test_screen_distance_in_fractions_and_pixels_agree():
    from treegen_cli.lod import screen_distance, switch_distances

    screen_px = LOD_DEFAULTS.width / LOD_DEFAULTS.aspect  # 1080
    d = switch_distances(13.0, LOD_DEFAULTS)
    assert d[1] == screen_distance(13.0, 0.5) and round(d[1], 1) == 40.0  # lod.py's example
    assert abs(screen_distance(13.0, 0.5 * screen_px, of=screen_px) - d[1]) < 1e-9 * d[1]
