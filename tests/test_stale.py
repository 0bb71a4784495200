"""A rewrite to the same output leaves only its own files: the textures an earlier write's file
named (USD asset paths, an OBJ's material maps) and this one did not write are removed, with
`make --no-textures` and with a forest whose prototypes changed; files the earlier output did
not name stay, whatever their names (exchange/stale.py; the exact-name leftovers, parts and
sidecars, are tests/test_gltf.py's)."""

from __future__ import annotations

import json
from urllib.parse import unquote
import os

import pytest
from conftest import species_path

from treegen_cli import api

FAST = {"duration": 1.0, "fps": 8, "max_joints": 12}


def _pngs(folder) -> set[str]:
    return {n for n in os.listdir(folder) if n.endswith(".png")}


@pytest.mark.parametrize("suffix", [".usda", ".obj", ".gltf"])
def test_a_rerun_without_textures_removes_the_textures_the_old_file_named(tmp_path, suffix):
    # (an .mtl's map lines are read whole, a .gltf's URIs are percent-encoded: spaces)
    stem = "t" if suffix == ".usda" else "my t"
    out = tmp_path / f"{stem}{suffix}"
    first = api.make(species_path("rush"), out, **({} if suffix == ".obj" else FAST))
    tag = f"{stem}_{suffix[1:]}_"
    textures = {n for n in _pngs(tmp_path) if not n.startswith(tag + "impostor")}
    assert {tag + "leaf.png", tag + "bark.png"} <= textures, first["files"]
    mine = tmp_path / (tag + "mine.png")  # the user's own, named like ours but not the file's
    mine.write_bytes(b"not ours")
    again = api.make(species_path("rush"), out, no_textures=True, **({} if suffix == ".obj" else FAST))
    left = _pngs(tmp_path)
    assert not (textures & left), left  # every texture the old file named, gone
    assert mine.exists()  # never named by the old file: kept
    assert left - {mine.name} <= {os.path.basename(f) for f in again["files"]}  # the rest: this write's


@pytest.mark.parametrize("suffix", [".usdc", ".gltf"])
def test_parts_rewritten_without_textures_keep_only_what_they_wrote(tmp_path, suffix):
    out = tmp_path / f"p{suffix}"
    api.make(species_path("rush"), out, lod_files=True, **FAST)
    tag = suffix[1:]
    assert {f"p_LOD_{tag}_leaf.png", f"p_LOD_{tag}_bark.png"} <= _pngs(tmp_path)
    again = api.make(species_path("rush"), out, lod_files=True, no_textures=True, **FAST)
    assert _pngs(tmp_path) == {os.path.basename(f) for f in again["files"] if f.endswith(".png")}


@pytest.mark.parametrize("suffix", [".usda", ".gltf"])
def test_a_forest_rewritten_with_other_prototypes_drops_their_textures(tmp_path, suffix):
    from click.testing import CliRunner

    from treegen_cli.cli import cli

    def forest(species: list[str]) -> set[str]:
        layout = {
            "wind": {"duration": 1.0, "fps": 8, "seed": 3},
            "defaults": {"max_joints": 12, "lod_distances": [0, 25]},
            "instances": [
                {"species": str(species_path(s)), "position": [6 * k, 0], "seed": 1}
                for k, s in enumerate(species)
            ],
        }
        (tmp_path / "f.json").write_text(json.dumps(layout))
        args = ["forest", str(tmp_path / "f.json"), "-o", str(tmp_path / f"f{suffix}"), "--workers", "1"]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        return _pngs(tmp_path)

    both = forest(["rush", "shave_grass"])
    assert any("rush" in n for n in both) and any("shave_grass" in n for n in both)
    one = forest(["shave_grass"])
    assert one and not any("rush" in n for n in one), one  # the rush's textures went with it
    if suffix == ".gltf":
        named = [unquote(i["uri"]) for i in json.loads((tmp_path / "f.gltf").read_text())["images"]]
    else:
        from pxr import UsdUtils

        _, named, _ = UsdUtils.ExtractExternalReferences(str(tmp_path / "f.usda"))
    assert one == {a.removeprefix("./") for a in named if a.endswith(".png")}
