"""Every bundled species through the whole pipeline into both formats, checked by the real
validators (Khronos glTF-Validator, pxr.UsdValidation) and read back by trimesh and pxr."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from treegen_cli.exchange import export
from treegen_cli.exchange.validate import validate_usd
from treegen_cli.exchange.validate import summary, validate_gltf
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.wind import WindOptions

SPECIES = sorted((Path(__file__).parent.parent / "species").glob("*.txt"))
# a short clip keeps the files small; the geometry and skeleton are the defaults
SHORT = MakeOptions(wind=WindOptions(duration=1.0, fps=10.0))


@pytest.fixture(scope="module", params=[s.stem for s in SPECIES])
def built(request, tmp_path_factory):
    p = load_params(SPECIES[0].parent / f"{request.param}.txt")
    asset, tree = build_asset(p, seed=0, options=SHORT)
    return request.param, asset, tree, tmp_path_factory.mktemp(request.param)


def test_glb_is_validator_clean(built):
    name, asset, tree, folder = built
    out = folder / f"{name}.glb"
    export(asset, out)
    report = validate_gltf(out, max_issues=50)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, summary(report)


def test_usdc_is_validator_clean(built):
    name, asset, tree, folder = built
    out = folder / f"{name}.usdc"
    export(asset, out)
    assert validate_usd(out) == []


def test_every_vertex_bound_and_budget_kept(built):
    _, asset, tree, _ = built
    lod = asset.lods[0]
    n_joints = len(lod.skeleton.names)
    assert 1 <= n_joints <= 256
    parent = lod.skeleton.parent
    assert parent[0] == -1 and np.all(parent[1:] < np.arange(1, n_joints)) and np.all(parent[1:] >= 0)
    for prim in lod.primitives:
        assert np.allclose(prim.weights.sum(axis=1), 1.0, atol=1e-6)
        assert prim.joints.max() < n_joints
        assert np.all(np.isfinite(prim.positions)) and np.all(np.isfinite(prim.normals))
    for clip in lod.clips:
        assert np.all(np.isfinite(clip.rotations))
        assert np.allclose(clip.rotations[0], clip.rotations[-1])


def test_trimesh_reads_back_the_counts(built):
    import trimesh

    name, asset, tree, folder = built
    out = folder / f"{name}_static.glb"
    export(asset, out)
    scene = trimesh.load(out, force="scene", process=False)
    verts = sum(len(g.vertices) for g in scene.geometry.values())
    tris = sum(len(g.faces) for g in scene.geometry.values())
    prims = [p for lod in asset.lods for p in lod.primitives]  # trimesh loads every LOD's mesh
    assert verts == sum(len(p.positions) for p in prims)
    assert tris == sum(len(p.indices) // 3 for p in prims)


def test_uvs_fit_half_floats_and_leaves_fill_atlas_cells(built):
    """Engines store UVs as half floats: every UV of every LOD within ±64, in the asset's
    convention and after glTF's 1 − v; leaf UVs inside the atlas (0..1)."""
    _, asset, _, _ = built
    for lod in asset.lods:
        for prim in lod.primitives:
            uv = prim.uvs.astype(np.float64)
            assert np.abs(uv).max() <= 64 and np.abs(1.0 - uv[:, 1]).max() <= 64, prim.name
            if prim.name == "leaves":
                assert uv.min() >= 0.0 and uv.max() <= 1.0
