"""The glTF writer's lean encodings: quantized weights and card UVs that read back exactly (or
within one quantum), a streamed GLB identical to the in-memory one, validator-clean real trees
with leaf cards and with leaf outlines."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from synthetic import MATERIALS, synthetic_asset
from synthetic_tree import synthetic_tree
from treegen_cli.asset import Asset, Lod, Primitive
from treegen_cli.exchange import export as _export
from treegen_cli.prepare import prepare
from treegen_cli.exchange.gltf import build
from treegen_cli.exchange.gltf_buffer import FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT
from treegen_cli.exchange.gltf_container import glb_bytes, read_accessor, read_gltf
from treegen_cli.exchange.validate import summary, validate_gltf
from treegen_cli.mesh import MeshOptions, build_mesh
from treegen_cli.rig import RigOptions, build_rig


def export(asset, path, **opts):
    """Hand-built assets go through the prepare stage, as the pipeline's do."""
    return _export(prepare(asset), path, **opts)


def _raw(gltf, blob, index):
    """An accessor's stored integers, without dequantizing."""
    acc = dict(gltf["accessors"][index])
    acc.pop("normalized", None)
    return read_accessor({**gltf, "accessors": [acc]}, blob, 0)


def _with_prims(asset: Asset, prims: list[Primitive]) -> Asset:
    lod = dataclasses.replace(asset.lods[0], primitives=prims)
    return dataclasses.replace(asset, lods=[lod])


def _random_weights(rng, V):
    """Up to four distinct joints per vertex with random weights; some slots unused."""
    w = rng.random((V, 4)).astype(np.float32)
    w[rng.random((V, 4)) < 0.3] = 0.0
    w[:, 0] += 0.05  # every row has some weight
    w = -np.sort(-w, axis=1)
    w /= w.sum(axis=1, keepdims=True)
    j = np.where(w > 0, np.arange(4), 0).astype(np.uint16)
    return j, w


def test_blended_weights_are_ushort_summing_exactly(tmp_path):
    asset = synthetic_asset(1, with_clip=False)
    bark = asset.lods[0].primitives[0]
    rng = np.random.default_rng(3)
    j, w = _random_weights(rng, len(bark.positions))
    p = tmp_path / "w.glb"
    export(_with_prims(asset, [dataclasses.replace(bark, joints=j, weights=w)]), p)
    gltf, blob = read_gltf(p)
    a = gltf["meshes"][0]["primitives"][0]["attributes"]
    acc = gltf["accessors"][a["WEIGHTS_0"]]
    assert acc["componentType"] == UNSIGNED_SHORT and acc["normalized"] is True
    q = _raw(gltf, blob, a["WEIGHTS_0"]).astype(np.int64)
    assert np.all(q.sum(axis=1) == 65535)  # exact, not approximately
    back = read_accessor(gltf, blob, a["WEIGHTS_0"])
    assert np.abs(back - w).max() <= 2.5 / 65535  # rounding + residual
    joints = read_accessor(gltf, blob, a["JOINTS_0"])
    assert np.all(joints[q == 0] == 0)  # unused slots: (0, 0)
    np.testing.assert_array_equal(joints[q > 0], j[q > 0])


def test_rigid_weights_are_exact_bytes_and_uvs_are_float(tmp_path):
    asset = synthetic_asset(1, with_clip=False)
    p = tmp_path / "r.glb"
    export(asset, p)
    gltf, blob = read_gltf(p)
    bark_p, leaf_p = gltf["meshes"][0]["primitives"]
    src = asset.lods[0].primitives[1]
    acc = gltf["accessors"]
    la = leaf_p["attributes"]
    assert acc[la["WEIGHTS_0"]]["componentType"] == UNSIGNED_BYTE
    q = _raw(gltf, blob, la["WEIGHTS_0"])
    np.testing.assert_array_equal(q, (src.weights * 255).astype(np.uint8))
    # float UVs everywhere: Godot 3.2 reads normalized integer UVs as 0..65535
    assert acc[la["TEXCOORD_0"]]["componentType"] == FLOAT
    assert "normalized" not in acc[la["TEXCOORD_0"]]
    uv = read_accessor(gltf, blob, la["TEXCOORD_0"])
    np.testing.assert_array_equal(uv[:, 0], src.uvs[:, 0])
    np.testing.assert_array_equal(uv[:, 1], 1.0 - src.uvs[:, 1])
    assert acc[bark_p["attributes"]["TEXCOORD_0"]]["componentType"] == FLOAT
    assert acc[bark_p["attributes"]["WEIGHTS_0"]]["componentType"] == UNSIGNED_SHORT


def test_streamed_glb_equals_in_memory_bytes(tmp_path):
    asset = synthetic_asset(3)
    p = tmp_path / "s.glb"
    export(asset, p)
    assert p.read_bytes() == glb_bytes(*build(prepare(asset)))
    gltf, blob = build(prepare(asset))
    assert gltf["buffers"][0]["byteLength"] == len(blob) and len(blob) % 4 == 0


@pytest.mark.parametrize("geometry", ["card", "shape"])
def test_real_mesh_is_validator_clean(tmp_path, geometry):
    """Bark and leaves from mesh/ (5 joints: blended bark, rigid leaves) pass the validator."""
    tree = synthetic_tree()
    rig = build_rig(tree, RigOptions(max_joints=5))
    prims = build_mesh(tree, rig, MeshOptions(leaf_geometry=geometry))
    asset = Asset("t", list(MATERIALS), [Lod(prims, rig.skeleton)])
    p = tmp_path / f"{geometry}.glb"
    export(asset, p)
    report = validate_gltf(p)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, summary(report)
    gltf, blob = read_gltf(p)
    leaves = gltf["meshes"][0]["primitives"][1]["attributes"]
    assert gltf["accessors"][leaves["TEXCOORD_0"]]["componentType"] == FLOAT
    pos = read_accessor(gltf, blob, leaves["POSITION"])
    assert len(pos) == tree.n_leaves * (4 if geometry == "card" else 8)


def test_leaves_always_carry_their_normals(tmp_path):
    """NORMAL is written for flat leaf cards too (Godot computes no normals, Babylon warns and
    regenerates them), and the written normals are the cards' own face normals."""
    tree = synthetic_tree(leaf_shape=6)  # folded palm outline: two planes
    rig = build_rig(tree, RigOptions(max_joints=5))
    for geometry in ("card", "shape"):
        bark, leaves = build_mesh(tree, rig, MeshOptions(leaf_geometry=geometry))
        p = tmp_path / f"{geometry}.glb"
        export(Asset("t", list(MATERIALS), [Lod([bark, leaves], rig.skeleton)]), p)
        gltf, blob = read_gltf(p)
        bark_a, leaf_a = (q["attributes"] for q in gltf["meshes"][0]["primitives"])
        assert "NORMAL" in bark_a and "NORMAL" in leaf_a
        pos = read_accessor(gltf, blob, leaf_a["POSITION"]).astype(np.float64)
        nrm = read_accessor(gltf, blob, leaf_a["NORMAL"]).astype(np.float64)
        tri = read_accessor(gltf, blob, gltf["meshes"][0]["primitives"][1]["indices"])
        t = pos[tri.reshape(-1, 3)]
        face = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        face /= np.linalg.norm(face, axis=1, keepdims=True)
        own = nrm[tri.reshape(-1, 3)]  # (T, 3 corners, 3)
        np.testing.assert_allclose(np.broadcast_to(face[:, None], own.shape), own, atol=1e-4)


def test_y_up_shuffle_of_a_strided_view_is_exact():
    """The writer's Y-up shuffle on a column slice (tangents' xyz) gives the same rows as on a
    contiguous copy (numpy 2.4 mis-reads strided input to negative(out=))."""
    from treegen_cli.exchange.gltf_mesh import y_up32

    t = np.arange(40, dtype=np.float32).reshape(10, 4)
    np.testing.assert_array_equal(y_up32(t[:, :3]), y_up32(t[:, :3].copy()))
    np.testing.assert_array_equal(y_up32(t[:, :3])[:, 2], -t[:, 1])
