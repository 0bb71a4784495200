"""Hardening: extreme but legal species give a valid, finite file or a clear refusal; a run
killed mid-write leaves the previous output intact; oversized meshes and clips are refused
before they are built; progress and --quiet/--verbose/--json behave when piped."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import fields
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

# A small three-level tree: every extreme case below starts from it and overrides a few keys.
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
    limits=Limits(max_vertices=2_000_000, max_keys=200_000))


def species(overrides: str):
    """BASE with `overrides` ('Key value' lines) replacing or adding keys."""
    lines = dict(l.split(None, 1) for l in BASE.strip().splitlines())
    for line in overrides.strip().splitlines():
        k, v = line.split(None, 1)
        lines[k] = v
    levels = int(lines["Levels"])         # level keys beyond Levels are an error: drop them
    lines = {k: v for k, v in lines.items() if not (k[0].isdigit() and int(k[0]) > levels)}
    return parse_params_text("\n".join(f"{k} {v}" for k, v in lines.items()), "extreme.txt")


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
        assert "--max-" in msg and msg.isprintable(), msg     # refusals name the flag
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


@pytest.mark.parametrize("case", ["levels_0", "huge_curve", "scale_v_above_scale",
                                  "lobes_large", "zero_leaves"])
def test_extreme_parameters_export_readable_files(case, tmp_path):
    from treegen_cli.exchange import export
    from treegen_cli.exchange.gltf import read_gltf
    from treegen_cli.exchange.usd import validate_usd

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
