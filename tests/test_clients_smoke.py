"""Smoke tests with real glTF clients (tests/clients.py): three.js, Babylon.js, Godot 3.2.

One small tree (fan palm, one LOD, ~250 joints, < 1 MB) goes through each client. Only what holds
today and should keep holding is asserted: the file loads, every skeleton has at most 256 bones,
there is a wind animation and playing it moves bones. Godot 3.2 does not import today's files (the
import hangs: the skinned mesh node is the parent of its skeleton's root joint); that test is a
strict xfail so it fails loudly, as an XPASS, the day the writer's layout is fixed. The sibling
layout test is the harness's own control: the same file with the mesh node and the root joint
made siblings (tests/clients.sibling_layout) does import, so the harness itself works.
A client that is not installed skips its test, naming the install command.
"""
import subprocess
import sys
from pathlib import Path

import pytest

import clients

REPO = Path(__file__).resolve().parent.parent
MAX_BONES = 256
GODOT_TIMEOUT = 20  # a small tree imports in ~2 s; today's layout never finishes


@pytest.fixture(scope="module")
def small_glb(tmp_path_factory):
    out = tmp_path_factory.mktemp("clients") / "fan_palm.glb"
    subprocess.run([sys.executable, "-m", "treegen_cli", "make", "species/fan_palm.txt", "--no-lod",
                    "-o", str(out), "-q"], cwd=REPO, check=True)
    return out


def _client(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except clients.ClientMissing as exc:
        pytest.skip(str(exc))


def _check_web_client(r):
    assert r["loaded"], r.get("error")
    assert "error" not in r, r["error"]
    assert r["skeletons"], "no skeleton"
    assert all(0 < s["bones"] <= MAX_BONES for s in r["skeletons"]), r["skeletons"]
    assert any(m["skinned"] for m in r["meshes"])
    assert r["animations"], "no animation"
    for a in r["animations"]:
        assert a["duration"] > 0
        assert a["bones_moved"] > 0, a


def test_three_js(small_glb):
    _check_web_client(_client(clients.three_load, small_glb))


def test_babylon_js(small_glb):
    _check_web_client(_client(clients.babylon_load, small_glb))


def _check_godot(r):
    assert r["imported"], r["reason"]
    assert r["skeletons"], "no Skeleton node"
    assert all(0 < s["bone_count"] <= MAX_BONES for s in r["skeletons"]), r["skeletons"]
    anims = [a for p in r["animation_players"] for a in p["animations"]]
    assert anims, "no animation"
    assert all(a["length"] > 0 and a["bones_moved"] > 0 for a in anims), anims


@pytest.mark.xfail(strict=True, reason="Godot 3.2 hangs importing a skinned mesh node that is the "
                   "parent of its own skeleton root joint (treegen writes lod0 -> j0 today)")
def test_godot_imports_our_file(small_glb):
    _check_godot(_client(clients.godot_import, small_glb, timeout=GODOT_TIMEOUT))


def test_godot_imports_sibling_layout(small_glb, tmp_path):
    fixed = tmp_path / "siblings.glb"
    clients.sibling_layout(small_glb, fixed)
    _check_godot(_client(clients.godot_import, fixed, timeout=GODOT_TIMEOUT))
