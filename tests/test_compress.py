"""`--compress quantize|meshopt`: what the integers decode to, against the float file.

One real tree (quaking aspen, a short clip) is built once and written three ways. quantize is
decoded here (grid positions through the skin's inverse bind matrices, int8 normals, uint16
UVs through KHR_texture_transform, int16 rotations); meshopt is decoded by three.js's own
MeshoptDecoder (tests/clients.py), the only reader of it we trust.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

import clients
from conftest import run_treegen, species_path
from treegen_cli import api
from treegen_cli.exchange import GltfOptions, export, export_parts
from treegen_cli.exchange.gltf_container import read_accessor, read_gltf
from treegen_cli.exchange.read_gltf import read_strided
from treegen_cli.exchange.validate import summary, validate_gltf
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings
from treegen_cli.prepare import split_lods

SPECIES = "quaking_aspen"
CLIP = {"duration": 2.0, "fps": 10.0}
MM = 1e-3


def _job(compress: str) -> api.Resolved:
    return api.resolve({**CLIP, "compress": compress}, output="x.glb")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """{compress: path} for none / quantize / meshopt of one built aspen, plus the asset."""
    d = tmp_path_factory.mktemp("compress")
    job = _job("none")
    asset, _ = api.build(load_params(species_path(SPECIES)), SPECIES, job, Timings())
    out = {"asset": asset}
    for c in ("none", "quantize", "meshopt"):
        out[c] = d / f"{c}.glb"
        export(asset, out[c], _job(c).options.gltf)
    return out


@pytest.fixture(scope="module")
def plans(files):
    """{meshopt: key_plan.plan} of the aspen's LOD0 clip, for quantize (False) and meshopt."""
    from treegen_cli import key_plan

    lod = files["asset"].lods[0]
    return {meshopt: key_plan.plan(lod, lod.clips[0], meshopt) for meshopt in (False, True)}


def _mesh_node(gltf: dict, lod: int) -> dict:
    root = gltf["nodes"][gltf["scenes"][0]["nodes"][0]]
    ids = [gltf["scenes"][0]["nodes"][0], *root.get("extensions", {}).get("MSFT_lod", {}).get("ids", [])]
    return gltf["nodes"][ids[lod]]


def _dequantize(none, quant, lod: int) -> tuple[np.ndarray, np.ndarray]:
    """(D, spread): the grid's dequantization recovered per joint as IBM_none⁻¹ · IBM_quant
    (their median) and how far the joints disagree (one grid per skin: float32 rounding only)."""
    (g0, b0), (g1, b1) = none, quant
    s0, s1 = (g["skins"][_mesh_node(g, lod)["skin"]] for g in (g0, g1))
    ibm0 = read_accessor(g0, b0, s0["inverseBindMatrices"]).astype(np.float64)
    ibm1 = read_accessor(g1, b1, s1["inverseBindMatrices"]).astype(np.float64)
    d = np.linalg.inv(ibm0) @ ibm1
    return np.median(d, axis=0), float(np.abs(d - np.median(d, axis=0)).max())


def test_extensions_declared_and_required(files):
    for c, extra in (("quantize", set()), ("meshopt", {"EXT_meshopt_compression"})):
        gltf, _ = read_gltf(files[c])
        need = {"KHR_mesh_quantization", "KHR_texture_transform"} | extra
        assert set(gltf["extensionsRequired"]) == need
        assert need | {"MSFT_lod"} == set(gltf["extensionsUsed"])
    assert "extensionsRequired" not in read_gltf(files["none"])[0]


def test_compressed_views_are_pooled(files):
    """One view per kind of element (target, type, filter), as gltfpack writes them, instead
    of one per vertex attribute and track: a few views, vertex ones with their byteStride."""
    for c in ("quantize", "meshopt"):
        gltf, _ = read_gltf(files[c])
        images = {i["bufferView"] for i in gltf.get("images", [])}
        views = [v for i, v in enumerate(gltf["bufferViews"]) if i not in images]
        assert len(views) <= 10, len(views)
        assert all("byteStride" in v for v in views if v.get("target") == 34962)
    none, _ = read_gltf(files["none"])
    assert len(none["bufferViews"]) > 30


@pytest.mark.parametrize("compress", ["quantize", "meshopt"])
def test_validator_clean(files, compress):
    report = validate_gltf(files[compress])
    assert report["issues"]["numErrors"] == 0, summary(report)
    assert report["issues"]["numWarnings"] == 0, summary(report)


def test_quantized_geometry_decodes_within_tolerance(files):
    """LOD0 positions within 1 mm (16-bit grid: ≤ extent/131070 per axis), every LOD within
    its grid's half step; normals within 1°, tangents' handedness kept, UVs through the
    texture transform within half a step of the material's range, weights rows summing to 1."""
    none, quant = read_gltf(files["none"]), read_gltf(files["quantize"])
    for lod in range(len(files["asset"].lods)):
        d, spread = _dequantize(none, quant, lod)
        step = d[0, 0]
        assert np.allclose(d[:3, :3], np.eye(3) * step, atol=1e-9) and spread < 1e-5
        prims0 = none[0]["meshes"][_mesh_node(none[0], lod)["mesh"]]["primitives"]
        prims1 = quant[0]["meshes"][_mesh_node(quant[0], lod)["mesh"]]["primitives"]
        for p0, p1 in zip(prims0, prims1):
            a0, a1 = p0["attributes"], p1["attributes"]
            pos = read_accessor(*none, a0["POSITION"]).astype(np.float64)
            q = read_strided(*quant, a1["POSITION"]).astype(np.float64)
            assert quant[0]["accessors"][a1["POSITION"]]["componentType"] == 5123  # uint16
            err = np.linalg.norm(q @ d[:3, :3].T + d[:3, 3] - pos, axis=1).max()
            assert err <= np.sqrt(3) * step / 2 * 1.001
            if lod == 0:
                assert err <= 1 * MM
            n0 = read_accessor(*none, a0["NORMAL"]).astype(np.float64)
            n1 = read_strided(*quant, a1["NORMAL"])
            n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
            assert np.degrees(np.arccos(np.clip((n0 * n1).sum(1), -1, 1))).max() < 1.0
            if "TANGENT" in a0:
                t0 = read_accessor(*none, a0["TANGENT"])
                t1 = read_strided(*quant, a1["TANGENT"])
                assert np.array_equal(np.sign(t0[:, 3]), t1[:, 3])
            material = quant[0]["materials"][p1["material"]]
            ref = material["pbrMetallicRoughness"].get("baseColorTexture", {})
            tt = ref.get("extensions", {}).get("KHR_texture_transform", {})
            scale, offset = np.array(tt.get("scale", [1, 1])), np.array(tt.get("offset", [0, 0]))
            uv0 = read_accessor(*none, a0["TEXCOORD_0"]).astype(np.float64)
            uv1 = read_strided(*quant, a1["TEXCOORD_0"]) * scale + offset
            assert np.abs(uv1 - uv0).max() <= scale.max() / 65535 / 2 * 1.001
            w = read_strided(*quant, a1["WEIGHTS_0"])
            assert quant[0]["accessors"][a1["WEIGHTS_0"]]["componentType"] == 5121
            assert np.allclose(w.sum(1), 1.0, atol=1e-6)
    bark = next(m for m in quant[0]["materials"] if m["name"] == "bark")
    assert "KHR_texture_transform" in bark["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]


def test_quantized_rotations_are_the_planned_keys_within_one_step(files):
    """Each compressed key is its plan's key at the same time (key_plan.py): int16 within half
    a step, the long levers' float32 (`wide` joints) as they are. LOD0 keeps a subset of its
    keys, each aimed through its parent's played rotation (the float key corrected by the
    parent's rounding and dropped keys: within 1e-3 of it); lower LODs keep the float file's
    keys, and leave out only tracks the float file holds constant (key_plan.still)."""
    from treegen_cli import key_plan
    from treegen_cli.axes import quat_to_y_up

    none = read_gltf(files["none"])
    quant = read_gltf(files["quantize"])
    planned = key_plan.with_key_plans(files["asset"], meshopt=False)
    kinds, left_out = set(), 0
    for k, (a0, a1) in enumerate(zip(none[0]["animations"], quant[0]["animations"])):
        clip = planned.lods[k].clips[0]
        want = quat_to_y_up(np.asarray(clip.plan.clip.rotations, dtype=np.float64))
        joint_of = {
            int(ch["target"]["node"]): j for j, ch in zip(np.flatnonzero(clip.animated), a0["channels"])
        }
        ch0 = {ch["target"]["node"]: a0["samplers"][ch["sampler"]] for ch in a0["channels"]}
        ch1 = {ch["target"]["node"]: a1["samplers"][ch["sampler"]] for ch in a1["channels"]}
        assert set(ch1) <= set(ch0) and len(ch1) > 0
        for node, s0 in ch0.items():
            t0, r0 = read_accessor(*none, s0["input"]), read_accessor(*none, s0["output"])
            if node not in ch1:  # left out: constant in the float file
                assert k > 0 and np.abs(r0 - r0[:1]).max() == 0.0
                left_out += 1
                continue
            s1 = ch1[node]
            t1 = read_accessor(*quant, s1["input"])
            at = np.searchsorted(t0, t1)
            assert np.array_equal(t0[at], t1)
            kind = quant[0]["accessors"][s1["output"]]["componentType"]
            kinds.add((k, kind))
            r1 = read_strided(*quant, s1["output"])
            aim = want[np.searchsorted(np.asarray(clip.times, np.float32), t1), joint_of[node]]
            aim *= np.where((aim * r1).sum(axis=1) < 0, -1.0, 1.0)[:, None]  # sign-continuous
            assert np.abs(r1 - aim).max() <= (0.5 / 32767 + 1e-7 if kind == 5122 else 1e-7)
            assert np.abs(r1 - r0[at]).max() <= 1e-3
            if k > 0 and len(t1) > 1:
                assert len(t1) == len(t0)
    assert (0, 5122) in kinds and all(kind == 5122 for k, kind in kinds if k > 0)
    assert left_out > 0


def test_compressed_lod0_animation_within_one_millimetre(files, plans, monkeypatch):
    """key_plan's measure (every skinned vertex's hull corner on every frame, played from the
    stored keys) keeps LOD0 within 1 mm of the dense float clip in both settings, while every
    key rounded to 16 bits on its own would not (the 19 m aspen's trunk carries its crown):
    keys aimed through their parents' played rotations (key_plan.aimed) take a parent's
    rounding out instead of passing it down the chain; no more than some joints keep float32
    keys; meshopt keeps every key (quantize drops keys when that is cheaper: on this short
    10 fps clip it is not)."""
    from treegen_cli import key_plan
    from treegen_cli.quat import unit

    lod = files["asset"].lods[0]
    dense = lod.clips[0]
    J = len(lod.skeleton.names)
    every = [np.arange(len(dense.times))] * J
    naive = key_plan.KeyPlan(replace(dense, keys=every), np.zeros(J, bool))
    assert key_plan.error(lod, dense, naive) > 1 * MM
    rot = unit(np.asarray(dense.rotations, dtype=np.float64))
    check = key_plan._Check(lod, rot, exact=False)
    targets, _ = key_plan.aimed(check, rot, np.ones(rot.shape[:2], bool), np.zeros(J, bool))
    aimed = key_plan.KeyPlan(replace(dense, rotations=targets, keys=every), np.zeros(J, bool))
    assert key_plan.error(lod, dense, aimed) < 0.75 * key_plan.error(lod, dense, naive)
    for meshopt, kp in plans.items():
        assert key_plan.error(lod, dense, kp) <= 1 * MM  # meshopt: either decoder
        assert kp.wide.sum() < J
        kept = sum(len(k) for k in kp.clip.keys)
        assert kept == J * len(dense.times) if meshopt else kept <= J * len(dense.times)
    monkeypatch.setattr(key_plan, "QUANT_SHARES", (0.3e-3,))  # rounding 0.3 mm, keys 0.65
    kp = key_plan.plan(lod, dense)
    assert sum(len(k) for k in kp.clip.keys) < J * len(dense.times)
    assert key_plan.error(lod, dense, kp) <= 1 * MM


def test_written_files_play_lod0_within_one_millimetre(files, plans):
    """Read back from the files' bytes (exchange.read_clip: the stored keys as a client slerps
    them; meshopt through both of meshoptimizer's decoders, SIMD and scalar), LOD0's clip
    keeps every skinned vertex within 1 mm of the dense float clip in the quantize and meshopt
    files, as their plans measured (the writer stores what was planned); the float file plays
    it to float32 precision. size_bench measures gltfpack's files so."""
    from treegen_cli import key_plan
    from treegen_cli.exchange.read_clip import played_error

    lod = files["asset"].lods[0]
    assert played_error(lod, files["none"]) < 0.01 * MM
    for compress in ("quantize", "meshopt"):
        err = played_error(lod, files[compress])
        planned = key_plan.error(lod, lod.clips[0], plans[compress == "meshopt"])
        assert err <= 1 * MM
        assert abs(err - planned) < 0.01 * MM


def test_compressed_joint_nodes_are_the_float_rest_pose(files):
    """Joint nodes' rest TRS in a compressed file are the float file's to float32 precision,
    arithmetic noise (a 1e-17 m component beside a 2 m one) written as 0, not as digits."""
    none, _ = read_gltf(files["none"])
    for c in ("quantize", "meshopt"):
        gltf, _ = read_gltf(files[c])
        assert len(gltf["nodes"]) == len(none["nodes"])
        tiny = 0
        for n0, n1 in zip(none["nodes"], gltf["nodes"]):
            for key, default in (("translation", [0, 0, 0]), ("rotation", [0, 0, 0, 1])):
                v0 = np.asarray(n0.get(key, default), dtype=np.float64)
                v1 = np.asarray(n1.get(key, default), dtype=np.float64)
                scale = np.abs(v0).max()
                assert np.abs(v1 - v0).max() <= scale * 2.0**-23
                assert not np.any((v1 != 0) & (np.abs(v1) < scale * 2.0**-25))
                tiny += int(np.sum((v0 != 0) & (v1 == 0)))
        assert tiny > 0  # the aspen's rig has such noise


def test_compressed_previews_match_the_float_one(files):
    """`treegen preview` reads quantize (dequantized in numpy) and meshopt (meshoptimizer's
    own decoder, tools/meshopt_decode.mjs) files. quantize keeps the triangle order: its
    picture matches the float file's pixel for pixel to a grey level on average. meshopt's
    encoder reorders triangles, and the renderer's hashed cut-out of tiny leaves is seeded by
    the card's index, so its speckle moves while coverage does not: 8×8-pixel means agree
    within a grey level on average, 24 at worst. Skinned mid-clip, meshopt's vertices are
    within 2 mm of the float file's: ≤ 1 mm of position grid plus ≤ 1 mm from 16-bit keys;
    quantize's (0.25 mm grid) within 1 mm, vertex for vertex."""
    from treegen_cli.exchange import read_drawable
    from treegen_cli.preview import PreviewOptions, load_scene, render_still

    opts = PreviewOptions(width=160, height=160)
    base = render_still(load_scene(files["none"], opts), opts).astype(np.float64)
    assert (np.abs(base - base[0, 0]).max(axis=2) > 40).mean() > 0.05  # a tree is drawn

    def blocks(img, k=8):
        return img.reshape(160 // k, k, 160 // k, k, 3).mean(axis=(1, 3))

    quant = render_still(load_scene(files["quantize"], opts), opts).astype(np.float64)
    assert np.abs(quant - base).max(axis=2).mean() < 0.5
    mesh = render_still(load_scene(files["meshopt"], opts), opts).astype(np.float64)
    d = np.abs(blocks(mesh) - blocks(base)).max(axis=2)
    assert d.mean() < 1.5 and d.max() < 24, (d.mean(), d.max())
    a, q, b = (read_drawable(files[c]) for c in ("none", "quantize", "meshopt"))
    assert len(a.parts) == len(q.parts) == len(b.parts) == 2
    for pa, pq, pb in zip(a.parts, q.parts, b.parts):
        assert len(pa.positions) == len(pb.positions)
        assert np.linalg.norm(_skinned(a, pa) - _skinned(q, pq), axis=1).max() <= 1 * MM
        assert cKDTree(_skinned(a, pa)).query(_skinned(b, pb))[0].max() <= 2 * MM


def _skinned(drawable, part, t=0.7):
    s = drawable.pose(t)[0]
    p = np.column_stack([part.positions, np.ones(len(part.positions))])
    m = np.einsum("vk,vkij->vij", part.weights, s[part.joints])
    return np.einsum("vij,vj->vi", m, p)[:, :3]


def _three(path, **kw):
    try:
        return clients.three_load(path, timeout=300, **kw)
    except clients.ClientMissing as exc:
        pytest.skip(str(exc))


def test_meshopt_decodes_to_the_grid(files):
    """three.js's MeshoptDecoder gives back exactly the grid coordinates of the float file's
    positions, on a grid of ≤ 1.15 mm at LOD0: every position within 1 mm."""
    r = _three(files["meshopt"], positions=True)
    assert r["loaded"], r.get("error")
    none = read_gltf(files["none"])
    skin = none[0]["skins"][_mesh_node(none[0], 0)["skin"]]
    ibm0 = read_accessor(*none, skin["inverseBindMatrices"])[0].astype(np.float64)
    ibm1 = np.asarray(r["skeletons"][0]["bone_inverse_0"], dtype=np.float64).reshape(4, 4).T
    d = np.linalg.inv(ibm0) @ ibm1
    step = d[0, 0]
    assert np.allclose(d[:3, :3], np.eye(3) * step, atol=1e-9)
    assert np.sqrt(3) * step / 2 <= 1 * MM
    prims = none[0]["meshes"][_mesh_node(none[0], 0)["mesh"]]["primitives"]
    for prim, mesh in zip(prims, r["meshes"]):
        pos = read_accessor(*none, prim["attributes"]["POSITION"]).astype(np.float64)
        got = np.asarray(mesh["positions"], dtype=np.float64).reshape(-1, 3) * step + d[:3, 3]
        assert len(got) == len(pos)
        # every decoded vertex is within 1 mm of a float one and every float one of a decoded
        # one (the encoder reordered them)
        assert cKDTree(pos).query(got)[0].max() <= 1 * MM
        assert cKDTree(got).query(pos)[0].max() <= 1 * MM


def test_animation_error_within_the_lod_bound(files):
    """Every node's world position over each clip, three.js playing each file: int16 rotations
    (quantize; meshopt's 16-bit quaternion filter) keep them within 1 mm of the float file
    for LOD0's clip on a 19 m tree, and within a quarter pixel at each lower LOD's distance
    (default 60°, 1920 px view), on top of the LOD's own error_px."""
    from treegen_cli.lod import pixel_size

    base = _three(files["none"], poses=8)
    bound = [max(1 * MM, pixel_size(lod.distance) / 4) for lod in files["asset"].lods]
    for c in ("quantize", "meshopt"):
        r = _three(files[c], poses=8)
        assert r["loaded"] and not r["warnings"], (r.get("error"), r["warnings"])
        for k, (a0, a1) in enumerate(zip(base["animations"], r["animations"])):
            # int16 quaternions are unit only to ~1e-5 and three.js normalizes them on some
            # paths only: first and last frame agree to a fraction of a millimetre, not 1e-4
            assert (
                a1["loop_max_diff"] <= 0.5 * MM
                and abs(a1["bones_moved"] - a0["bones_moved"]) <= 0.05 * a0["bones_moved"]
            )
            err = np.abs(np.asarray(a1["poses"]) - np.asarray(a0["poses"])).max()
            assert err <= bound[k], (c, a0["name"], err)


def test_meshopt_is_deterministic_and_smaller(files, tmp_path):
    again = tmp_path / "again.glb"
    export(files["asset"], again, _job("meshopt").options.gltf)
    assert again.read_bytes() == files["meshopt"].read_bytes()
    sizes = [_geometry_bytes(files[c]) for c in ("none", "quantize", "meshopt")]
    assert sizes[0] > 1.5 * sizes[1] > 1.5 * 2 * sizes[2], sizes


def _geometry_bytes(path) -> int:
    """The file's bytes less its embedded images (textures and the impostor atlas, PNGs that
    every setting stores alike)."""
    gltf, _ = read_gltf(path)
    views = gltf["bufferViews"]
    return path.stat().st_size - sum(
        views[i["bufferView"]]["byteLength"] for i in gltf.get("images", []) if "bufferView" in i
    )


def test_lod_files_compress_each_part(files, tmp_path):
    parts = export_parts(split_lods(files["asset"]), tmp_path / "t.glb", _job("meshopt").options.gltf)
    n = len(files["asset"].lods)
    assert [p.name for p in parts] == [f"t_LOD{k}.glb" for k in range(n)] + [
        f"t_LOD{n - 1}.glb.impostor.json"
    ]
    for p in parts[:n]:
        gltf, _ = read_gltf(p)
        assert "EXT_meshopt_compression" in gltf["extensionsRequired"]
        assert validate_gltf(p)["issues"]["numErrors"] == 0


# ---- refusals: one line, exit 2, nothing written ----


@pytest.mark.parametrize("suffix", [".usdc", ".usdz", ".obj"])
def test_compress_refused_outside_gltf(tmp_path, suffix):
    out = tmp_path / f"t{suffix}"
    proc = run_treegen("make", species_path("rush"), "-o", out, "--compress", "quantize")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "--compress quantize is for .glb/.gltf only" in proc.stderr
    assert not any(tmp_path.iterdir())


def test_meshopt_without_node_is_one_line(tmp_path):
    out = tmp_path / "t.glb"
    env = {**os.environ, "TREEGEN_NODE": str(tmp_path / "no-node")}
    import subprocess
    import sys

    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "make",
            str(species_path("rush")),
            "-o",
            str(out),
            "--compress",
            "meshopt",
            "--no-lod",
            "--no-wind",
        ],
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "needs Node.js" in proc.stderr
    assert not any(tmp_path.iterdir())


def test_catalogue_compress_refuses_usd_formats(tmp_path):
    from treegen_cli.batch import load_catalogue
    from treegen_cli.errors import TreegenError

    cat = tmp_path / "c.json"
    cat.write_text(
        json.dumps(
            {
                "entries": [
                    {"species": str(species_path("rush")), "formats": ["glb", "usdc"], "compress": "meshopt"}
                ]
            }
        )
    )
    with pytest.raises(
        TreegenError,
        match=r"entries\[0\]\.compress: meshopt is for glb/gltf only, "
        r"but entries\[0\]\.formats\[1\] is \"usdc\"",
    ):
        load_catalogue(cat)
    cat.write_text(json.dumps({"entries": [{"species": str(species_path("rush")), "compress": "zip"}]}))
    with pytest.raises(
        TreegenError, match=r"entries\[0\]\.compress: \"zip\"; expected one of none, quantize, meshopt"
    ):
        load_catalogue(cat)


def test_default_options_leave_the_writer_alone():
    assert _job("none").options.gltf == GltfOptions()
    assert replace(_job("meshopt").options.gltf, compress="none", pixel_size=0.0) == GltfOptions()


@pytest.mark.parametrize("bits", [18, 20])
def test_exponential_filter_model_matches_meshoptimizer(bits):
    """key_codec.exp_filter (the wide joints' keys under meshopt) gives, to the bit, what
    meshoptimizer's EXPONENTIAL filter (one exponent per vector) gives back from the writer's
    float32 source: steps of 2^(1 − bits) for a unit quaternion, 2^(2 − bits) only where a
    component is ±1 (a model at the coarser step everywhere took a file past 1 mm)."""
    from treegen_cli import key_codec
    from treegen_cli.axes import quat_to_y_up
    from treegen_cli.exchange import compress
    from treegen_cli.quat import unit

    rng = np.random.default_rng(2)
    n = 4096
    q = rng.normal(size=(n, 4))
    q[: n // 2, :3] *= 0.05
    q[0] = [0.0, 0.0, 0.0, 1.0]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    source = unit(quat_to_y_up(q)).astype(np.float32)
    view = compress.MeshoptView("ATTRIBUTES", 16, n, "EXPONENTIAL", source, bits)
    try:
        (encoded,) = compress.encode([(view, memoryview(source).cast("B"))])
        ext = {"mode": "ATTRIBUTES", "filter": "EXPONENTIAL", "byteStride": 16, "count": n}
        (decoded,) = compress.decode([(ext, encoded)], "test")
    except Exception as exc:  # no node or tools: the clients' tests skip alike
        pytest.skip(str(exc))
    got = np.frombuffer(decoded, dtype="<f4").reshape(n, 4)
    want = quat_to_y_up(key_codec.exp_filter(q[:, None], np.array([bits]))[:, 0])
    assert np.array_equal(got, want)


@pytest.mark.parametrize("simd", [True, False])
@pytest.mark.parametrize("bits", [12, 13, 14, 15, 16])
def test_quaternion_filter_model_matches_meshoptimizer(bits, simd):
    """key_codec.quat_filter (what the 1 mm check plays) gives, to the bit, what meshoptimizer's
    own encoder and each of its decoders (the SIMD build and the scalar one a client without
    WebAssembly SIMD runs) give back for the QUATERNION filter at `bits` from the writer's
    source (Y up, float32): their float32 arithmetic included (a float64 model missed by one
    int16 step on ~1 key in 1,000, enough to take a file past 1 mm), near-rest rotations
    (wind's) as well as any; and the two decoders do differ on some keys."""
    from treegen_cli import key_codec
    from treegen_cli.axes import quat_to_y_up
    from treegen_cli.exchange import compress
    from treegen_cli.quat import unit

    rng = np.random.default_rng(1)
    n = 4096
    q = rng.normal(size=(n, 4))
    q[: n // 2, :3] *= 0.05
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    source = unit(quat_to_y_up(q)).astype(np.float32)
    view = compress.MeshoptView("ATTRIBUTES", 8, n, "QUATERNION", source, bits)
    data = compress.snorm16(source.astype(np.float64))
    try:
        (encoded,) = compress.encode([(view, memoryview(data).cast("B"))])
        ext = {"mode": "ATTRIBUTES", "filter": "QUATERNION", "byteStride": 8, "count": n}
        (decoded,) = compress.decode([(ext, encoded)], "test", simd=simd)
    except Exception as exc:  # no node or tools: the clients' tests skip alike
        pytest.skip(str(exc))
    got = np.frombuffer(decoded, dtype="<i2").reshape(n, 4)

    def model(simd: bool) -> np.ndarray:
        return np.rint(quat_to_y_up(key_codec.quat_filter(q[:, None], np.array([bits]), simd)[:, 0]) * 32767)

    assert np.array_equal(got, model(simd))
    assert not np.array_equal(model(True), model(False))
