"""Hardening: extreme but legal species give a valid, finite file or a clear refusal; a run
killed mid-write leaves the previous output intact; oversized meshes and clips are refused
before they are built; progress and --quiet/--verbose/--json behave when piped."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

from pathlib import Path

import numpy as np
import pytest

from treegen_cli.errors import TreegenError
from treegen_cli.generate import GenerateOptions, generate
from treegen_cli.limits import Limits, check_keys, estimate_vertices, frame_count
from treegen_cli.mesh import MeshOptions, build_mesh
from treegen_cli.params import load_params, parse_params_text
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.rig import RigOptions, build_rig
from treegen_cli.wind import WindOptions

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ROOT / "species"

# A small three-level tree: every extreme case below starts from it and overrides a few keys
# (a fragment: keys it leaves out take Arbaro's defaults).
BASE = """Name base
Shape 7
BaseSize 0.3
Scale 8
ScaleV 1
Levels 3
Ratio 0.02
Lobes 3
LobeDepth 0.1
Flare 0.5
Leaves 6
LeafScale 0.2
AttractionUp 0.5
0CurveRes 4
0Curve 10
0CurveV 20
1DownAngle 60
1DownAngleV -30
1Rotate 140
1Branches 12
1Length 0.4
1CurveRes 3
1Curve -30
1CurveV 40
2DownAngle 45
2Rotate 140
2Branches 6
2Length 0.5
2CurveRes 2
2Curve 20
3Rotate 120
"""

SMALL = MakeOptions(
    generate=GenerateOptions(max_stems=20_000, max_leaves=60_000),
    rig=RigOptions(max_joints=24),
    wind=WindOptions(duration=0.5, fps=6),
    lod=None,
    limits=Limits(max_vertices=2_000_000, max_keys=200_000),
)


def species(overrides: str):
    """BASE with `overrides` ('Key value' lines) replacing or adding keys."""
    lines = dict(line.split(None, 1) for line in BASE.strip().splitlines())
    for line in overrides.strip().splitlines():
        k, v = line.split(None, 1)
        lines[k] = v
    levels = int(lines["Levels"])  # level keys beyond Levels are an error: drop them
    lines = {k: v for k, v in lines.items() if not (k[0].isdigit() and int(k[0]) > levels)}
    text = "\n".join(f"{k} {v}" for k, v in lines.items())
    return parse_params_text(text, "extreme.txt", partial=True)  # the rest: Arbaro's defaults


def float_arrays(asset):
    """(name, array) for every float array in the asset: geometry, skin, skeleton, clips."""
    for k, lod in enumerate(asset.lods):
        for p in lod.primitives:
            for f in ("positions", "normals", "uvs", "weights"):
                yield f"lod{k}.{p.name}.{f}", np.asarray(getattr(p, f))
        s = lod.skeleton
        for f in ("rest_translation", "rest_rotation", "bind_world"):
            yield f"lod{k}.skeleton.{f}", np.asarray(getattr(s, f))
        for c in lod.clips:
            yield f"lod{k}.{c.name}.times", np.asarray(c.times)
            yield f"lod{k}.{c.name}.rotations", np.asarray(c.rotations)


def assert_sound(asset):
    """Finite everywhere, unit normals/quaternions, weights summing to 1, indices in range."""
    for name, a in float_arrays(asset):
        assert np.all(np.isfinite(a)), f"{name} has NaN/inf"
    for lod in asset.lods:
        n_j = len(lod.skeleton.names)
        for p in lod.primitives:
            v = len(p.positions)
            assert v > 0 and len(p.indices) % 3 == 0
            assert p.indices.max() < v
            assert np.allclose(np.linalg.norm(p.normals, axis=1), 1.0, atol=1e-3)
            assert np.allclose(p.weights.sum(axis=1), 1.0, atol=1e-5)
            assert p.joints.max() < n_j
        assert np.allclose(np.linalg.norm(lod.skeleton.rest_rotation, axis=1), 1.0, atol=1e-6)
        for c in lod.clips:
            assert np.allclose(np.linalg.norm(c.rotations, axis=2), 1.0, atol=1e-6)


# Each case: overrides of BASE. All values are inside the parser's legal ranges.
EXTREME = {
    "levels_0": "Levels 0",
    "levels_1": "Levels 1",
    "levels_max_thin": "Levels 9\n3Branches 1\n4Branches 1\n5Branches 1\n6Branches 1\n"
    "7Branches 1\n8Branches 1\n9Branches 1\n2Branches 1\n1Branches 2",
    "zero_branches": "1Branches 0",
    "zero_leaves": "Leaves 0",
    "fan_leaves": "Leaves -8",
    "huge_curve": "0Curve 3600\n1Curve -3600\n2Curve 3600\n1CurveBack 3600",
    "helix": "1CurveV -90\n0CurveV -45",
    "huge_curve_v": "0CurveV 100000\n1CurveV 3600",
    "negative_attraction": "AttractionUp -50",
    "huge_attraction": "AttractionUp 50",
    "scale_v_above_scale": "Scale 2\nScaleV 30",
    "taper_near_3": "0Taper 2.999\n1Taper 2.999\n2Taper 2.5",
    "taper_2": "0Taper 2\n1Taper 2",
    "taper_0": "0Taper 0\n1Taper 0\n2Taper 0",
    "leaf_quality_tiny": "LeafQuality 0.0001",
    "lobes_large": "Lobes 1000\nLobeDepth 5",
    "base_splits_large": "0BaseSplits 1000",
    "base_splits_some": "0BaseSplits 6\n0SplitAngle 180\n0SplitAngleV 180",
    "seg_splits_max": "1SegSplits 10\n1CurveRes 2\n1SplitAngle 180",
    "curve_res_100": "0CurveRes 100\n1CurveRes 100",
    "tiny_tree": "Scale 0.001\nScaleV 0",
    "huge_tree": "Scale 100000\nScaleV 0",
    "zero_lengths": "1Length 0\n2Length 0",
    "ratio_huge": "Ratio 50\nRatioPower 10",
    "ratio_power_negative": "RatioPower -10",
    "flare_min": "Flare -1",
    "flare_huge": "Flare 1000",
    "down_angles_extreme": "1DownAngle 180\n1DownAngleV -180\n2DownAngle -180\n2DownAngleV 180",
    "rotate_extreme": "1Rotate -360\n1RotateV 360\n2Rotate 360",
    "prune_full": "PruneRatio 1\nPruneWidth 0\nPrunePowerLow 0\nPrunePowerHigh 100",
    "prune_wide": "PruneRatio 1\nPruneWidth 100\nPruneWidthPeak 1",
    "envelope_shape_8": "Shape 8\nPruneRatio 1",
    "base_size_1": "BaseSize 1",
    "leaf_huge": "LeafScale 1000\nLeafScaleX 1000\nLeafBend 1",
    "leaf_stem_len_negative": "LeafStemLen -100",
    "branch_dist_extremes": "0BranchDist 1\n1BranchDist 0\n2BranchDist 1",
    "many_trunks": "0Branches 12\n0BranchDist 1\n0DownAngle 80\n0DownAngleV 90",
    "scale0_tiny": "0Scale 0.000001\n0ScaleV 100",
}


@pytest.mark.parametrize("case", sorted(EXTREME))
def test_extreme_parameters_give_a_sound_asset_or_a_clear_refusal(case):
    p = species(EXTREME[case])
    try:
        asset, tree = build_asset(p, 3, SMALL)
    except TreegenError as e:
        msg = str(e)
        assert "--max-" in msg and msg.isprintable(), msg  # refusals name the flag
        return
    assert tree.n_stems >= 1
    assert_sound(asset)


def test_extreme_refusals_happen_where_expected():
    # Levels 9 with the default branching is astronomically many stems: refused up front.
    with pytest.raises(TreegenError, match="--max-stems"):
        build_asset(species("Levels 9"), 0, SMALL)
    # 0BaseSplits 1000 is legal; the generator splits at most 8 ways, and so does the estimate.
    _, tree = build_asset(species("0BaseSplits 1000"), 0, SMALL)
    assert np.count_nonzero(tree.stem_clone & (tree.stem_level == 0)) == 8


@pytest.mark.parametrize(
    "case", ["levels_0", "huge_curve", "scale_v_above_scale", "lobes_large", "zero_leaves"]
)
def test_extreme_parameters_export_readable_files(case, tmp_path):
    from treegen_cli.exchange import export
    from treegen_cli.exchange.gltf_container import read_gltf
    from treegen_cli.exchange.validate import validate_usd

    asset, _ = build_asset(species(EXTREME[case]), 3, SMALL)
    glb, usda = tmp_path / "x.glb", tmp_path / "x.usda"
    export(asset, glb)
    export(asset, usda)
    gltf, _bin = read_gltf(glb)
    assert gltf["skins"] and gltf["meshes"]
    assert validate_usd(usda) == []
    if case in ("huge_curve", "scale_v_above_scale"):
        from treegen_cli.exchange.validate import ValidatorUnavailable, validate_gltf

        try:
            issues = validate_gltf(glb)["issues"]
        except ValidatorUnavailable as e:
            pytest.skip(str(e))
        assert issues["numErrors"] == 0, issues


def test_scale_v_above_scale_never_gives_a_non_positive_tree():
    p = species(EXTREME["scale_v_above_scale"])
    for seed in range(10):
        tree = generate(p, seed, SMALL.generate)
        assert tree.scale > 0 and np.all(np.isfinite(tree.node_pos))
        assert tree.node_pos[:, 2].max() > 0


# ----------------------------------------------------------------------------- atomic writes


def treegen(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT, **kw
    )


def _kill_mid_write(species_file: Path, out: Path, attempts: int = 4) -> list[str]:
    """Start `treegen make`, SIGKILL it while the writer fills its staging folder (the staged
    file exists, the rename has not happened); return the names left in the folder. A run that
    finishes before it is caught is retried (the write window is short on a fast machine),
    after putting the folder back as it was."""
    before = out.read_bytes() if out.exists() else None
    for _ in range(attempts):
        staged = out.parent / "(none)"
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "treegen_cli",
                "make",
                str(species_file),
                "-o",
                str(out),
                "--no-lod",
                "--duration",
                "1",
                "--fps",
                "10",
            ],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            while proc.poll() is None:
                staging = [
                    d
                    for d in out.parent.iterdir()
                    if d.name.startswith(f".{out.name}.") and d.name.endswith(".tmp")
                ]
                if staging:
                    staged = staging[0] / out.name
                    while not staged.exists() and staging[0].exists():
                        pass  # tight: the file appears any moment
                    if staged.exists():
                        os.kill(proc.pid, signal.SIGKILL)
                        break
                time.sleep(0.0005)
            proc.wait(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        # Caught mid-write only if the staged file is still there: the process was not yet
        # past its rename (a loaded machine may deschedule this loop between check and kill).
        if proc.returncode == -signal.SIGKILL and staged.exists():
            return sorted(p.name for p in out.parent.iterdir())
        for d in out.parent.glob(f".{out.name}.*.tmp"):  # a late kill's leftovers
            shutil.rmtree(d)
        if before is None:
            out.unlink(missing_ok=True)
        else:
            out.write_bytes(before)
    pytest.fail(f"the run finished before it could be killed, {attempts} times")


@pytest.mark.parametrize("suffix", [".glb", ".usdc"])
def test_a_run_killed_mid_write_leaves_the_previous_file_intact(tmp_path, suffix):
    out = tmp_path / f"out{suffix}"
    proc = treegen("make", SPECIES / "shave_grass.txt", "-o", out, "--no-lod", "--no-wind")
    assert proc.returncode == 0, proc.stderr
    before = out.read_bytes()
    left = _kill_mid_write(SPECIES / "black_tupelo.txt", out)
    assert out.read_bytes() == before  # byte-identical, not half-written
    # Only the hidden staging folder of the killed run may remain, never a visible partial file.
    assert [n for n in left if not n.startswith(".") and not n.endswith(".png")] == [out.name]
    assert all(
        n.startswith(f".{out.name}.") and n.endswith(".tmp")
        for n in left
        if n != out.name and not n.endswith(".png")
    )
    # A later run is not disturbed by the leftover and replaces the file.
    proc = treegen("make", SPECIES / "shave_grass.txt", "-o", out, "--no-lod", "--duration", "0.5")
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes() != before


def test_ctrl_c_while_files_move_lands_after_the_whole_set(tmp_path, monkeypatch):
    """A SIGINT between two of one asset's moves (its --lod-files parts, sidecars) is acted on
    after the last: the folder holds the new set whole, never old parts beside new ones."""
    from treegen_cli.exchange import staging

    names = ["t_LOD0.glb", "t_LOD1.glb", "t_LOD2.glb"]
    for n in names:
        (tmp_path / n).write_bytes(b"old")
    moved = []
    real = os.replace

    def replace_then_interrupt(src, dst):
        real(src, dst)
        moved.append(Path(dst).name)
        if len(moved) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C right after the first move
            time.sleep(0.05)  # (delivered by now, were it not held)

    monkeypatch.setattr(staging.os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        with staging.staged(tmp_path / names[0]) as tmp:
            for n in names:
                (tmp.parent / n).write_bytes(b"new")
    assert sorted(moved) == names
    assert all((tmp_path / n).read_bytes() == b"new" for n in names)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # handler restored

    # through export_parts: an earlier write's extra part goes before the Ctrl-C acts
    from synthetic import synthetic_asset

    from treegen_cli.exchange import export_parts
    from treegen_cli.prepare import prepare, split_lods

    monkeypatch.setattr(staging.os, "replace", real)
    export_parts(split_lods(prepare(synthetic_asset(3))), tmp_path / "p.glb")
    moved.clear()
    monkeypatch.setattr(staging.os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        export_parts(split_lods(prepare(synthetic_asset(2))), tmp_path / "p.glb")
    assert sorted(p.name for p in tmp_path.glob("p_LOD*")) == ["p_LOD0.glb", "p_LOD1.glb"]


def test_ctrl_c_while_the_cli_loads_is_one_line_and_exit_130():
    """The console script (treegen_cli.entry): a Ctrl-C in the second the CLI's modules take
    to load ends with "treegen: aborted" and exit 130, as during a run, not a traceback."""
    code = (
        "import sys\n"
        "class Stop:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'treegen_cli.cli':\n"
        "            raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Stop())\n"
        "from treegen_cli.entry import main\n"
        "main()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 130 and proc.stderr == "treegen: aborted\n", proc.stderr


def test_a_run_killed_mid_write_leaves_nothing_when_there_was_no_file(tmp_path):
    out = tmp_path / "fresh.glb"
    left = _kill_mid_write(SPECIES / "black_tupelo.txt", out)
    assert not out.exists() and all(n.startswith(".") for n in left)


# ----------------------------------------------------------------------------- limits


@pytest.mark.parametrize("name", ["quaking_aspen", "palm"])
@pytest.mark.parametrize(
    "mesh", [MeshOptions(), MeshOptions(sides=(7, 5), leaf_geometry="shape", rings_per_segment=(3, 2, 1))]
)
def test_vertex_estimate_matches_the_built_mesh(name, mesh):
    tree = generate(load_params(SPECIES / f"{name}.txt"), 1)
    bark, leaves = estimate_vertices(tree, mesh)
    prims = {p.name: p for p in build_mesh(tree, build_rig(tree), mesh)}
    assert bark == len(prims["bark"].positions)
    assert leaves == len(prims["leaves"].positions)


def test_oversized_mesh_and_clip_are_refused_before_building_naming_the_flag():
    p = load_params(SPECIES / "quaking_aspen.txt")
    tree = generate(p, 0)
    need = sum(estimate_vertices(tree, MeshOptions()))
    opts = MakeOptions(lod=None, wind=WindOptions(duration=1, fps=10))
    from dataclasses import replace

    with pytest.raises(TreegenError, match=rf"{need:,} mesh vertices.*--max-vertices"):
        build_asset(p, 0, replace(opts, limits=Limits(max_vertices=need - 1)))
    asset, _ = build_asset(p, 0, replace(opts, limits=Limits(max_vertices=need, max_keys=10**6)))
    joints = len(asset.lods[0].skeleton.names)
    keys = joints * frame_count(opts.wind)
    assert keys == joints * len(asset.lods[0].clips[0].times)
    with pytest.raises(TreegenError, match=rf"{keys:,} joint-keys.*--max-keys"):
        build_asset(p, 0, replace(opts, limits=Limits(max_keys=keys - 1)))
    assert check_keys(joints, None, Limits(max_keys=0)) == 0  # no wind, no keys


def test_cli_refuses_oversized_work_with_exit_2_and_writes_nothing(tmp_path):
    out = tmp_path / "x.glb"
    for flag, needle in (("--max-vertices", "mesh vertices"), ("--max-keys", "joint-keys")):
        proc = treegen("make", SPECIES / "quaking_aspen.txt", "-o", out, flag, "100")
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert needle in proc.stderr and flag in proc.stderr
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- output

FAST = ("--no-lod", "--duration", "0.5", "--fps", "10")


def test_piped_make_prints_no_progress_artefacts(tmp_path):
    proc = treegen("make", SPECIES / "quaking_aspen.txt", "-o", tmp_path / "a.glb", *FAST)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    for stream in (proc.stdout,):
        assert "\x1b" not in stream and "\r" not in stream
    assert proc.stdout.startswith("wrote ")


def test_quiet_prints_nothing_on_success_and_errors_still_show(tmp_path):
    for cmd in (
        ("make", SPECIES / "quaking_aspen.txt", "-o", tmp_path / "a.glb", "-q", *FAST),
        ("info", SPECIES / "quaking_aspen.txt", "--quiet"),
    ):
        proc = treegen(*cmd)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout == "" and proc.stderr == ""
    assert (tmp_path / "a.glb").stat().st_size > 0
    proc = treegen("make", SPECIES / "nope.txt", "-o", tmp_path / "b.glb", "-q")
    assert proc.returncode == 2 and "nope.txt" in proc.stderr and proc.stdout == ""


def test_verbose_reports_each_stage_on_stderr(tmp_path):
    proc = treegen("make", SPECIES / "quaking_aspen.txt", "-o", tmp_path / "a.glb", "-v", *FAST)
    assert proc.returncode == 0, proc.stderr
    stages = [line.split()[0] for line in proc.stderr.splitlines()]
    assert stages == [
        "materials",
        "generate",
        "rig",
        "mesh",
        "wind",
        "textures",
        "prepare",
        "write",
        "counts",
    ]
    assert "nodes" in proc.stderr.splitlines()[-1]
    assert all(line.rstrip().endswith(" s") for line in proc.stderr.splitlines()[:-1])
    assert "\x1b" not in proc.stderr and "\r" not in proc.stderr
    lods = treegen(
        "make", SPECIES / "rush.txt", "-o", tmp_path / "r.glb", "-v", "--duration", "1", "--fps", "5"
    )
    assert lods.returncode == 0, lods.stderr
    names = [line.split()[0] for line in lods.stderr.splitlines()]
    assert len(names) == len(set(names)) and "impostor" in names  # once each, summed over the LODs
    info = treegen("info", SPECIES / "quaking_aspen.txt", "--verbose")
    assert "generate" in info.stderr and "nodes" in info.stderr
    both = treegen("info", SPECIES / "quaking_aspen.txt", "-q", "-v")
    assert both.returncode == 2 and "--quiet" in both.stderr


def test_make_json_summary_parses_and_matches_the_file(tmp_path):
    from treegen_cli.exchange.gltf_container import read_gltf

    out = tmp_path / "a.glb"
    proc = treegen(
        "make", SPECIES / "quaking_aspen.txt", "-o", out, "--json", "--duration", "0.5", "--fps", "10"
    )
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["file"] == str(out) and s["files"] == [str(out), str(out) + ".impostor.json"]
    assert s["bytes"] == sum(Path(f).stat().st_size for f in s["files"])
    assert set(s["stages_s"]) >= {"generate", "rig", "mesh", "wind", "write"}
    # stages are timed inside the whole run: together they cannot exceed it
    assert 0 < sum(s["stages_s"].values()) <= s["seconds"] + 1e-3
    assert s["keys"] == 6 and s["joint_keys"] == s["joints"] * 6  # 0.5 s × 10 fps + 1
    gltf, _ = read_gltf(out)
    assert s["joints"] == len(gltf["skins"][0]["joints"])
    assert len(s["lods"]) == 5 and s["lods"][0]["vertices"] == s["vertices"]  # 4 + the impostor
    assert s["lods"][-1]["triangles"] == 8 and s["lods"][-1]["joints"] == 1
    assert s["triangles"] > 0 and s["vertices"] > s["triangles"] / 2
    # --json output survives --quiet: it was asked for explicitly.
    quiet = treegen("make", SPECIES / "quaking_aspen.txt", "-o", out, "--json", "-q", *FAST)
    assert json.loads(quiet.stdout)["vertices"] == s["vertices"] and quiet.stderr == ""


def test_progress_shows_on_a_terminal_and_is_cleared(tmp_path):
    import pty

    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "make",
            str(SPECIES / "quaking_aspen.txt"),
            "-o",
            str(tmp_path / "a.glb"),
            *FAST,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=slave,
        stdin=subprocess.DEVNULL,
    )
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    out = proc.stdout.read().decode()
    proc.wait()
    os.close(master)
    assert proc.returncode == 0
    assert b"generate" in seen or b"mesh" in seen or b"write" in seen  # the live display
    assert seen.endswith(b"\x1b[2K") or b"\x1b[?25h" in seen  # cleared, cursor back
    assert "\x1b" not in out and out.startswith("wrote ")  # stdout stays clean


BLAS_PROBE = (
    "import sys, treegen_cli, numpy; from threadpoolctl import threadpool_info; "
    "print(sorted({i.get('architecture') for i in threadpool_info() if i['internal_api'] == 'openblas'}))"
)


def test_openblas_kernel_is_pinned_for_cross_machine_bytes():
    """On every AVX2 x86-64 CPU the CLI, its Dask workers and this test process run OpenBLAS's
    Haswell kernel, so a tree built on an AVX-512 node has the bytes of one built elsewhere (the
    wind's eigen solve differs in the last bits between kernels: palm, sassafras, fan_palm)."""
    from threadpoolctl import threadpool_info

    from treegen_cli.blas_kernel import KERNEL, NEEDS, _cpu_flags

    if not NEEDS <= _cpu_flags():
        pytest.skip("this CPU lacks AVX2/FMA: OpenBLAS keeps its own kernel (nothing to pin)")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    child = subprocess.run([sys.executable, "-c", BLAS_PROBE], env=env, capture_output=True, text=True)
    assert child.stdout.strip() == f"['{KERNEL}']", child.stderr
    here = {i.get("architecture") for i in threadpool_info() if i["internal_api"] == "openblas"}
    assert here == {KERNEL}  # conftest imports treegen_cli before numpy, as the CLI does
    mine = dict(env, OPENBLAS_CORETYPE="Sandybridge")  # the user's own choice wins
    child = subprocess.run([sys.executable, "-c", BLAS_PROBE], env=mine, capture_output=True, text=True)
    assert child.stdout.strip() == "['Sandybridge']", child.stderr


# ------------------------------------------------------------------------------ blame


def aspen_with(**keys):
    """The aspen's file with `Key value` lines replaced (`_1Branches` for 1Branches)."""
    import re

    text = (SPECIES / "quaking_aspen.txt").read_text()
    for key, value in keys.items():
        text, n = re.subn(rf"^{key.lstrip('_')}\s.*$", f"{key.lstrip('_')} {value}", text, flags=re.M)
        assert n == 1, key
    return parse_params_text(text, "aspen.txt")


@pytest.mark.parametrize(
    "keys, blamed, line",
    [
        ({"Leaves": 50000}, "Leaves", 30),
        ({"_1Branches": 5_000_000}, "1Branches", 60),
        # Stems are a sum over levels: 2Branches would have to drop further (30 → 0.07) than
        # 1Branches (190000 → 10526), yet the typo is 1Branches: not "most over its bound".
        ({"_1Branches": 190_000}, "1Branches", 60),
        ({"_2Branches": 300_000}, "2Branches", 77),
        ({"_3Branches": 10**9}, None, None),  # the leaf level's Branches grows nothing: fits
    ],
)
def test_a_count_too_large_is_blamed_on_the_mistyped_key_at_its_line(keys, blamed, line):
    from dataclasses import replace

    from treegen_cli.errors import in_file
    from treegen_cli.generate.bounds import DEFAULTS, apply_options, blame, estimate_counts

    p = aspen_with(**keys)
    if blamed is None:
        apply_options(p, DEFAULTS)
        return
    with pytest.raises(TreegenError) as info:
        in_file("aspen.txt", apply_options, p, DEFAULTS)
    msg = str(info.value)
    assert msg.startswith(f"aspen.txt:{line}: {blamed} = ") and "Levels" not in msg, msg
    assert msg.endswith("here (or raise --max-stems N)") or msg.endswith("(or raise --max-leaves N)")
    # the bound it names fits (both limits: a 1Branches that keeps the stems within theirs may
    # still grow too many leaves), and a little more does not
    kind = "leaves" if blamed == "Leaves" else "stems"
    count = estimate_counts(p)[kind == "leaves"]
    fit = blame(kind, count, p, DEFAULTS).max_fit

    def set_(x):
        if blamed == "Leaves":
            return replace(p, leaves=x)
        n = int(blamed[0])
        return replace(p, level=p.level[:n] + (replace(p.level[n], branches=x),) + p.level[n + 1 :])

    apply_options(set_(fit), DEFAULTS)
    with pytest.raises(TreegenError, match="would grow about"):
        apply_options(set_(fit * 1.01 + 1), DEFAULTS)


def test_levels_is_blamed_only_when_no_count_is_a_typo():
    from treegen_cli.generate.bounds import apply_options

    # every count ordinary, the limit small: the tree is too deep, not mistyped
    with pytest.raises(TreegenError, match=r"^Levels = 3 would grow about 951 stems.* at most 2 fits"):
        apply_options(aspen_with(), GenerateOptions(max_stems=500))
    # a mistyped count under --levels 2: the count, never Levels (the override decides it)
    with pytest.raises(TreegenError, match=r"^1Branches = 5000000 would grow"):
        apply_options(aspen_with(_1Branches=5_000_000), GenerateOptions(levels=2))
    # no key alone can fix it, and Levels is not the cause: the count and the flag
    with pytest.raises(TreegenError, match=r"^species 'quaking_aspen' would grow about 1 stems"):
        apply_options(aspen_with(), GenerateOptions(max_stems=0, levels=0))


def test_a_blamed_key_of_an_arbaro_file_names_its_param_line():
    from treegen_cli.errors import in_file

    xml = (
        "<arbaro>\n<species name='x'>\n<param name='Levels' value='2'/>\n"
        "<param name='1Branches' value='20'/>\n<param name='Leaves' value='900000'/>\n</species>\n</arbaro>\n"
    )
    from treegen_cli.params import parse_params_bytes

    q = parse_params_bytes(xml.encode(), "x.xml")
    with pytest.raises(TreegenError, match=r"^x\.xml:5: Leaves = 900000 would grow about 13,500,000 leaves"):
        in_file("x.xml", generate, q, 0)
