"""The command line as a user meets it: real processes, exit codes, one-line errors, no
partial output, byte-identical reruns."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
ASPEN = ROOT / "species" / "quaking_aspen.txt"


def treegen(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
    )


def assert_user_error(proc, *needles):
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    for n in needles:
        assert n in lines[0], lines[0]


def test_info_json_reports_the_tree():
    proc = treegen("info", ASPEN, "--json", "--seed", "3")
    assert proc.returncode == 0, proc.stderr
    stats = json.loads(proc.stdout)
    assert stats["species"] == "quaking_aspen" and stats["seed"] == 3
    assert sum(stats["stems_per_level"]) == stats["stems"]
    assert stats["leaves"] > 0 and stats["leaf_area_m2"] > 0
    assert 0 < stats["height_m"] < 40 and 0 < stats["crown_width_m"] < stats["height_m"] * 2
    assert stats["nodes"] >= 2 * stats["stems"]
    text = treegen("info", ASPEN, "--seed", "3").stdout
    assert f"{stats['leaves']:,}" in text and "generation" in text


def test_info_bad_species_files(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("Shape 7\nLevles 3\n")
    assert_user_error(treegen("info", bad), "bad.txt", "2", "Levles", "Levels")
    assert_user_error(treegen("info", tmp_path / "missing.txt"), "missing.txt")
    big = tmp_path / "big.txt"
    big.write_text((ROOT / "species" / "weeping_willow.txt").read_text())
    assert_user_error(treegen("info", big, "--max-leaves", "1000"), "big.txt", "--max-leaves")


def test_make_writes_a_valid_glb_and_the_same_bytes_twice(tmp_path):
    from treegen_cli.exchange.validate import validate_gltf

    a, b = tmp_path / "a.glb", tmp_path / "b.glb"
    for out in (a, b):
        proc = treegen("make", ASPEN, "-o", out, "--duration", "1", "--fps", "10")
        assert proc.returncode == 0, proc.stderr
        assert "joints" in proc.stdout and "vertices" in proc.stdout
        assert "; impostor from " in proc.stdout and "1 joint" in proc.stdout  # the last LOD, named
    assert a.read_bytes() == b.read_bytes()
    issues = validate_gltf(a)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [  # no temp files left
        "a.glb",
        "a.glb.impostor.json",
        "b.glb",
        "b.glb.impostor.json",
    ]


def test_make_usdc_twice_is_byte_identical(tmp_path):
    """Same name in two folders (a .usdc names its sibling texture files after itself)."""
    a, b = tmp_path / "1" / "t.usdc", tmp_path / "2" / "t.usdc"
    for out in (a, b):
        out.parent.mkdir()
        assert treegen("make", ASPEN, "-o", out, "--duration", "1", "--fps", "10").returncode == 0
    assert a.read_bytes() == b.read_bytes()
    assert sorted(p.name for p in a.parent.iterdir()) == sorted(p.name for p in b.parent.iterdir())
    for p in a.parent.iterdir():
        assert p.read_bytes() == (b.parent / p.name).read_bytes(), p.name


def test_make_refuses_bad_requests_and_writes_nothing(tmp_path):
    assert_user_error(treegen("make", ASPEN, "-o", tmp_path / "x.fbx"), "x.fbx", ".glb")
    assert_user_error(treegen("make", ASPEN, "-o", tmp_path / "x.glb", "--max-joints", "0"), "--max-joints")
    assert_user_error(treegen("make", ASPEN, "-o", tmp_path / "nowhere" / "x.glb"), "nowhere")
    assert_user_error(treegen("make", ASPEN, "-o", tmp_path / "x.glb", "--sides", "2,1"), "--sides")
    assert_user_error(treegen("make", ASPEN, "-o", tmp_path / "x.glb", "--wind-speed", "-3"), "speed")
    assert list(tmp_path.iterdir()) == []


def test_make_respects_the_joint_budget(tmp_path):
    from treegen_cli.exchange.gltf_container import read_gltf

    out = tmp_path / "small.glb"
    proc = treegen("make", ASPEN, "-o", out, "--max-joints", "12", "--no-wind")
    assert proc.returncode == 0, proc.stderr
    gltf, _ = read_gltf(out)
    assert all(len(s["joints"]) <= 12 for s in gltf["skins"])
    assert "animations" not in gltf or not gltf["animations"]


def test_help_documents_units_and_defaults():
    text = treegen("make", "--help").stdout
    for needle in ("m/s", "degrees", "seconds", "default: 256", "--max-joints", "--no-wind"):
        assert needle in text, needle
