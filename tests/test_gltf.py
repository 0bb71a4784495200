"""glTF writer and export registry: validator-clean output, real readers, exact re-reads."""

from __future__ import annotations

import os
import subprocess
import sys
import dataclasses

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from synthetic import bark, chain_skeleton, leaves, synthetic_asset, MATERIALS
from treegen_cli import __version__
from treegen_cli.asset import Asset, Lod
from treegen_cli.errors import TreegenError
from treegen_cli.exchange import WRITERS, export as _export, supported_suffixes
from treegen_cli.prepare import prepare
from treegen_cli.axes import quat_to_y_up, to_y_up
from treegen_cli.exchange.gltf_buffer import UNSIGNED_BYTE, UNSIGNED_INT, UNSIGNED_SHORT
from treegen_cli.exchange.gltf_container import read_accessor, read_gltf
from treegen_cli.exchange.validate import summary, validate_gltf


def export(asset, path, **opts):
    """Hand-built assets go through the prepare stage, as the pipeline's do."""
    return _export(prepare(asset), path, **opts)


def _clean(path) -> dict:
    report = validate_gltf(path)
    issues = report["issues"]
    print(f"{path.name}: {issues['numInfos']} infos, {issues['numHints']} hints\n{summary(report)}")
    assert issues["numErrors"] == 0, summary(report)
    assert issues["numWarnings"] == 0, summary(report)
    return report


def _trs_world(gltf: dict, root: int) -> dict[int, np.ndarray]:
    """World matrices of `root` and its descendants from node TRS (glTF space)."""
    out = {}

    def walk(i, parent):
        n = gltf["nodes"][i]
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(n.get("rotation", [0, 0, 0, 1])).as_matrix()
        m[:3, 3] = n.get("translation", [0, 0, 0])
        out[i] = parent @ m
        for c in n.get("children", []):
            walk(c, out[i])

    walk(root, np.eye(4))
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The synthetic asset (1, 2 and 3 LODs) written once as GLB and as .gltf + .bin."""
    d = tmp_path_factory.mktemp("gltf")
    out = {}
    for lods in (1, 2, 3):
        asset = synthetic_asset(lods)
        for suffix in (".glb", ".gltf"):
            p = d / f"tree{lods}{suffix}"
            export(asset, p)
            out[lods, suffix] = (asset, p)
    return out


@pytest.mark.parametrize("key", [(1, ".glb"), (2, ".glb"), (2, ".gltf"), (3, ".glb")])
def test_validator_clean(written, key):
    _clean(written[key][1])


def test_validator_clean_without_clip(tmp_path):
    p = tmp_path / "still.glb"
    export(synthetic_asset(2, with_clip=False), p)
    _clean(p)
    assert "animations" not in read_gltf(p)[0]


def test_trimesh_counts(written):
    asset, p = written[2, ".glb"]
    scene = trimesh.load(p, force="scene")
    shown = [scene.geometry[scene.graph[n][1]] for n in scene.graph.nodes_geometry]
    lod0 = asset.lods[0].primitives
    # only LOD0 is in the scene; the lower LOD reaches engines through MSFT_lod
    assert sum(len(g.vertices) for g in shown) == sum(len(p.positions) for p in lod0) == 32
    assert sum(len(g.faces) for g in shown) == sum(len(p.indices) // 3 for p in lod0) == 40


def test_gltf_and_glb_carry_the_same_data(written):
    g1, b1 = read_gltf(written[2, ".glb"][1])
    g2, b2 = read_gltf(written[2, ".gltf"][1])
    assert b1 == b2
    assert g2["buffers"][0]["uri"] == "tree2.bin"
    g2["buffers"][0].pop("uri")
    assert g1 == g2


def test_skin_joints_and_inverse_bind(written):
    asset, p = written[2, ".glb"]
    gltf, blob = read_gltf(p)
    assert len(gltf["skins"]) == len(asset.lods)
    for k, (lod, skin) in enumerate(zip(asset.lods, gltf["skins"])):
        J = len(lod.skeleton.names)
        assert len(skin["joints"]) == J
        assert [gltf["nodes"][j]["name"] for j in skin["joints"]] == lod.skeleton.names
        mesh_node = gltf["nodes"][gltf["nodes"].index(next(n for n in gltf["nodes"] if n.get("skin") == k))]
        assert "translation" not in mesh_node and "rotation" not in mesh_node
        world = _trs_world(gltf, skin["skeleton"])
        ibm = read_accessor(gltf, blob, skin["inverseBindMatrices"])
        for j, node in enumerate(skin["joints"]):
            np.testing.assert_allclose(ibm[j] @ world[node], np.eye(4), atol=1e-5)


def test_y_up_conversion(written):
    asset, p = written[1, ".glb"]
    gltf, blob = read_gltf(p)
    for prim, src in zip(gltf["meshes"][0]["primitives"], asset.lods[0].primitives):
        pos = read_accessor(gltf, blob, prim["attributes"]["POSITION"])
        gen = src.positions
        np.testing.assert_array_equal(pos[:, 0], gen[:, 0])
        np.testing.assert_array_equal(pos[:, 1], gen[:, 2])  # generator z=5 → glTF y=5
        np.testing.assert_array_equal(pos[:, 2], -gen[:, 1])
        acc = gltf["accessors"][prim["attributes"]["POSITION"]]
        assert acc["min"] == pos.min(axis=0).tolist() and acc["max"] == pos.max(axis=0).tolist()
        nrm = read_accessor(gltf, blob, prim["attributes"]["NORMAL"])
        np.testing.assert_allclose(nrm, to_y_up(src.normals), atol=1e-6)
    tip = gltf["nodes"][gltf["skins"][0]["joints"][-1]]
    assert np.allclose(to_y_up([0, 0, 1]), [0, 1, 0])
    # joints climb in +y in glTF as they climb in +z in the generator
    world = _trs_world(gltf, gltf["skins"][0]["skeleton"])
    top = world[gltf["skins"][0]["joints"][-1]][:3, 3]
    np.testing.assert_allclose(top, to_y_up(asset.lods[0].skeleton.bind_world[-1][:3, 3]), atol=1e-6)
    assert tip["name"] == "j2"


def test_vertex_attributes(written):
    asset, p = written[1, ".glb"]
    gltf, blob = read_gltf(p)
    J = len(asset.lods[0].skeleton.names)
    for prim, src in zip(gltf["meshes"][0]["primitives"], asset.lods[0].primitives):
        a = prim["attributes"]
        w = read_accessor(gltf, blob, a["WEIGHTS_0"])
        j = read_accessor(gltf, blob, a["JOINTS_0"])
        np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-7)
        assert j.max() < J and np.all(j[w == 0] == 0)
        assert gltf["accessors"][a["JOINTS_0"]]["componentType"] == UNSIGNED_BYTE
        assert gltf["accessors"][prim["indices"]]["componentType"] == UNSIGNED_SHORT
        np.testing.assert_array_equal(read_accessor(gltf, blob, prim["indices"]), src.indices)
        uv = read_accessor(gltf, blob, a["TEXCOORD_0"])
        np.testing.assert_allclose(uv[:, 1], 1.0 - src.uvs[:, 1])  # glTF's v runs down
    views = gltf["bufferViews"]
    assert all(v["byteOffset"] % 4 == 0 for v in views)
    targets = {
        gltf["accessors"][i]["bufferView"]: t
        for prim in gltf["meshes"][0]["primitives"]
        for i, t in [*((x, 34962) for x in prim["attributes"].values()), (prim["indices"], 34963)]
    }
    for i, v in enumerate(views):
        assert v.get("target") == targets.get(i)  # no target on IBM / animation views


def test_materials(written):
    gltf, _ = read_gltf(written[1, ".glb"][1])
    mats = {m["name"]: m for m in gltf["materials"]}
    assert mats["leaf"]["doubleSided"] is True
    assert mats["leaf"]["alphaMode"] == "MASK" and mats["leaf"]["alphaCutoff"] == 0.5
    assert "alphaMode" not in mats["bark"] and "doubleSided" not in mats["bark"]
    pbr = mats["bark"]["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"] == list(MATERIALS[0].base_color)
    assert pbr["roughnessFactor"] == 0.9 and pbr["metallicFactor"] == 0.0


def test_asset_header(written):
    asset, p = written[1, ".glb"]
    gltf, _ = read_gltf(p)
    assert gltf["asset"]["generator"] == f"treegen {__version__}"
    assert gltf["asset"]["extras"] == asset.extras
    assert len(gltf["scenes"]) == 1 and gltf["scene"] == 0


def test_animation_channels_and_sparse_keys(written):
    asset, p = written[2, ".glb"]
    gltf, blob = read_gltf(p)
    anims = {a["name"]: a for a in gltf["animations"]}
    assert sorted(anims) == ["wind_lod0", "wind_lod1"]
    for k, lod in enumerate(asset.lods):
        clip = lod.clips[0]
        anim = anims[clip.name]
        joints = gltf["skins"][k]["joints"]
        J = len(joints)
        # the root never leaves rest, so it gets no channel
        assert len(anim["channels"]) == J - 1
        inputs = set()
        for ch in anim["channels"]:
            j = joints.index(ch["target"]["node"])
            assert ch["target"]["path"] == "rotation" and j > 0
            s = anim["samplers"][ch["sampler"]]
            assert s["interpolation"] == clip.interpolation
            keys = np.arange(len(clip.times)) if clip.keys is None else clip.keys[j]
            t = read_accessor(gltf, blob, s["input"])
            np.testing.assert_array_equal(t, clip.times[keys].astype(np.float32))
            acc = gltf["accessors"][s["input"]]
            assert acc["min"] == [float(t[0])] and acc["max"] == [float(t[-1])]
            q = read_accessor(gltf, blob, s["output"])
            want = quat_to_y_up(clip.rotations[keys, j])
            np.testing.assert_allclose(np.abs(np.einsum("ki,ki->k", q, want)), 1.0, atol=1e-6)
            assert np.all(np.einsum("ki,ki->k", q[1:], q[:-1]) >= 0)  # no long-way slerp
            inputs.add(s["input"])
        # LOD0's non-root joints share one key set, LOD1 is dense: one input accessor each
        assert len(inputs) == 1
    sparse = asset.lods[0].clips[0].keys[1]
    assert len(sparse) < len(asset.lods[0].clips[0].times)


def _skin(gltf, blob, mesh_index, skin_index, rotations: dict[int, np.ndarray]):
    """Skinned positions of a mesh in glTF space with some joint rotations overridden."""
    skin = gltf["skins"][skin_index]
    nodes = gltf["nodes"]
    saved = {n: nodes[n].get("rotation") for n in rotations}
    for n, q in rotations.items():
        nodes[n]["rotation"] = list(q)
    world = _trs_world(gltf, skin["skeleton"])
    for n, q in saved.items():
        nodes[n]["rotation"] = q if q is not None else [0, 0, 0, 1]
    ibm = read_accessor(gltf, blob, skin["inverseBindMatrices"])
    mats = np.stack([world[n] @ ibm[j] for j, n in enumerate(skin["joints"])])
    out = []
    for prim in gltf["meshes"][mesh_index]["primitives"]:
        a = prim["attributes"]
        pos = read_accessor(gltf, blob, a["POSITION"]).astype(np.float64)
        jj = read_accessor(gltf, blob, a["JOINTS_0"]).astype(np.int64)
        ww = read_accessor(gltf, blob, a["WEIGHTS_0"]).astype(np.float64)
        m = np.einsum("vk,vkij->vij", ww, mats[jj])
        out.append(np.einsum("vij,vj->vi", m[:, :3, :3], pos) + m[:, :3, 3])
    return np.concatenate(out)


def test_posed_mesh_matches_generator_space(written):
    """Pose key 2 in glTF (node TRS + IBM + weights) equals the generator-space pose rotated
    to Y up: checks translations, rotations, IBMs and animation quaternions together."""
    asset, p = written[1, ".glb"]
    gltf, blob = read_gltf(p)
    lod = asset.lods[0]
    sk, clip, key = lod.skeleton, lod.clips[0], 2
    anim = gltf["animations"][0]
    pose = {}
    for ch in anim["channels"]:
        s = anim["samplers"][ch["sampler"]]
        t = read_accessor(gltf, blob, s["input"])
        q = read_accessor(gltf, blob, s["output"])
        pose[ch["target"]["node"]] = q[np.flatnonzero(t == np.float32(clip.times[key]))[0]]
    got = _skin(gltf, blob, 0, 0, pose)
    # generator space: compose the keyed local rotations, skin with inv(bind_world)
    J = len(sk.names)
    world = np.empty((J, 4, 4))
    for j in range(J):
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(clip.rotations[key, j]).as_matrix()
        m[:3, 3] = sk.rest_translation[j]
        world[j] = m if sk.parent[j] < 0 else world[sk.parent[j]] @ m
    mats = world @ np.linalg.inv(sk.bind_world)
    want = []
    for prim in lod.primitives:
        m = np.einsum("vk,vkij->vij", prim.weights.astype(np.float64), mats[prim.joints])
        want.append(np.einsum("vij,vj->vi", m[:, :3, :3], prim.positions) + m[:, :3, 3])
    want = to_y_up(np.concatenate(want))
    np.testing.assert_allclose(got, want, atol=1e-5)
    rest = _skin(gltf, blob, 0, 0, {})
    assert np.abs(got - rest).max() > 0.05  # the key really moves the tree


def test_msft_lod_and_node_layout(written):
    """LOD0's mesh node and one rig node per LOD are the scene roots; a skinned mesh node
    never parents a joint (Godot 3 hangs on that); lower LODs' meshes only through MSFT_lod."""
    asset, p = written[3, ".glb"]
    gltf, _ = read_gltf(p)
    nodes = gltf["nodes"]
    roots = gltf["scenes"][0]["nodes"]
    meshes = [r for r in roots if "mesh" in nodes[r]]
    rigs = [r for r in roots if "mesh" not in nodes[r]]
    assert len(meshes) == 1 and len(rigs) == len(asset.lods)
    top = nodes[meshes[0]]
    ids = top["extensions"]["MSFT_lod"]["ids"]
    assert len(ids) == 2 and not set(ids) & set(roots)
    assert [nodes[i]["mesh"] for i in ids] == [1, 2]
    assert [nodes[i]["skin"] for i in ids] == [1, 2]
    assert [nodes[i]["name"] for i in [meshes[0], *ids]] == [f"synthetic_LOD{k}" for k in range(3)]
    cover = top["extras"]["MSFT_screencoverage"]
    assert cover == [lod.screen_coverage for lod in asset.lods]
    assert all(a > b for a, b in zip(cover, cover[1:]))
    for k, i in enumerate([meshes[0], *ids]):
        assert nodes[i]["extras"]["treegen_lod"]["index"] == k
        assert nodes[i]["extras"]["treegen_lod"]["distance_m"] == asset.lods[k].distance
        assert "children" not in nodes[i]
        assert nodes[rigs[k]]["children"] == [gltf["skins"][k]["skeleton"]]
    assert gltf["extensionsUsed"] == ["MSFT_lod"] and "extensionsRequired" not in gltf
    single, _ = read_gltf(written[1, ".glb"][1])
    assert "extensionsUsed" not in single and "extensions" not in single["nodes"][0]


def test_deterministic_bytes(tmp_path):
    for suffix in (".glb", ".gltf"):
        a, b = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
        export(synthetic_asset(2), a)
        export(synthetic_asset(2), b)
        assert a.read_bytes().replace(b"a.bin", b"b.bin") == b.read_bytes()
    assert (tmp_path / "a.bin").read_bytes() == (tmp_path / "b.bin").read_bytes()


def test_large_indices_and_joints(tmp_path):
    """300 joints → UNSIGNED_SHORT joints; ≥ 65535 vertices → UNSIGNED_INT indices."""
    sk = chain_skeleton(300)
    asset = Asset("big", list(MATERIALS), [Lod([bark(sk, 220), leaves(sk, 4)], sk)])
    assert len(asset.lods[0].primitives[0].positions) >= 65535
    p = tmp_path / "big.glb"
    export(asset, p)
    _clean(p)
    gltf, _ = read_gltf(p)
    bark_prim, leaf_prim = gltf["meshes"][0]["primitives"]
    acc = gltf["accessors"]
    assert acc[bark_prim["attributes"]["JOINTS_0"]]["componentType"] == UNSIGNED_SHORT
    assert acc[bark_prim["indices"]]["componentType"] == UNSIGNED_INT
    assert acc[leaf_prim["indices"]]["componentType"] == UNSIGNED_SHORT
    # weights: blended bark as normalized UNSIGNED_SHORT, rigid leaves as UNSIGNED_BYTE
    assert acc[bark_prim["attributes"]["WEIGHTS_0"]]["componentType"] == UNSIGNED_SHORT
    assert acc[leaf_prim["attributes"]["WEIGHTS_0"]]["componentType"] == UNSIGNED_BYTE
    assert acc[bark_prim["attributes"]["WEIGHTS_0"]]["normalized"] is True


def test_step_and_explicit_animated(tmp_path):
    asset = synthetic_asset(1)
    clip = dataclasses.replace(
        asset.lods[0].clips[0], interpolation="STEP", animated=np.array([False, False, True]), keys=None
    )
    asset = dataclasses.replace(asset, lods=[dataclasses.replace(asset.lods[0], clips=[clip])])
    p = tmp_path / "step.glb"
    _export(prepare(asset), p)
    _clean(p)
    gltf, _ = read_gltf(p)
    anim = gltf["animations"][0]
    assert len(anim["channels"]) == 1 and anim["samplers"][0]["interpolation"] == "STEP"
    assert gltf["nodes"][anim["channels"][0]["target"]["node"]]["name"] == "j2"


def test_unknown_suffix(tmp_path):
    with pytest.raises(TreegenError) as e:
        export(synthetic_asset(), tmp_path / "tree.fbx")
    assert ".glb" in str(e.value) and ".usdc" in str(e.value) and ".fbx" in str(e.value)
    assert os.listdir(tmp_path) == []
    assert {".glb", ".gltf", ".usda", ".usdc", ".usdz", ".obj", ".ply"} <= set(supported_suffixes())


def test_missing_folder(tmp_path):
    with pytest.raises(TreegenError, match="does not exist"):
        export(synthetic_asset(), tmp_path / "nope" / "tree.glb")


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs Linux's /proc")
def test_existing_folder_that_refuses_files_is_not_called_missing():
    """/proc exists but refuses new files (ENOENT, even for root): say it is not writable."""
    with pytest.raises(TreegenError) as e:
        export(synthetic_asset(), "/proc/tree.glb")
    msg = str(e.value)
    assert msg.startswith("/proc/tree.glb: cannot write into folder '/proc' (not writable")
    assert "does not exist" not in msg


def test_gltf_buffer_uri_is_percent_encoded(tmp_path):
    """A .gltf's buffer is referenced by a URI: a name with a space or '#' is percent-encoded,
    or a URL-based loader (three.js in a browser) reads '#1.bin' as a fragment."""
    from urllib.parse import urljoin

    path = tmp_path / "my tree#1.gltf"
    export(synthetic_asset(), path)
    gltf, blob = read_gltf(path)
    uri = gltf["buffers"][0]["uri"]
    assert uri == "my%20tree%231.bin" and len(blob) == gltf["buffers"][0]["byteLength"]
    # as a browser resolves it against the .gltf's URL: the .bin beside it, no fragment
    resolved = urljoin(path.as_uri(), uri)
    assert "#" not in resolved and resolved == (tmp_path / "my tree#1.bin").as_uri()


def test_a_gltf_writes_its_textures_as_png_files_beside_it(tmp_path):
    """A .gltf's images are PNG files beside it (`NAME_gltf_leaf.png`, the USD/OBJ naming),
    named by percent-encoded URIs, byte for byte the images a .glb of the same tree embeds;
    the validator resolves them clean, and the file reads back with the same textures."""
    from urllib.parse import unquote

    from treegen_cli import api
    from treegen_cli.exchange import read_drawable

    from conftest import species_path

    fast = {"duration": 1.0, "fps": 8, "max_joints": 12}
    path = tmp_path / "my tree#1.gltf"
    made = api.make(species_path("rush"), path, **fast)
    api.make(species_path("rush"), tmp_path / "t.glb", **fast)
    gltf, _ = read_gltf(path)
    glb, glb_blob = read_gltf(tmp_path / "t.glb")
    images = gltf["images"]
    assert len(images) == len(glb["images"]) and all("bufferView" not in i for i in images)
    names = [unquote(i["uri"]) for i in images]
    assert all(n.startswith("my tree#1_gltf_") and "%" not in n for n in names)
    assert {"my tree#1_gltf_leaf.png", "my tree#1_gltf_bark.png"} <= set(names)
    assert all(i["uri"].startswith("my%20tree%231_gltf_") for i in images)
    # sub-delimiters stay as they are (Godot 3.2 reads URIs undecoded)
    api.make(species_path("rush"), tmp_path / "r(1)+x.gltf", **fast)
    doc, _ = read_gltf(tmp_path / "r(1)+x.gltf")
    assert doc["buffers"][0]["uri"] == "r(1)+x.bin" and doc["images"][0]["uri"].startswith("r(1)+x_gltf_")
    assert {os.path.basename(f) for f in made["files"]} >= set(names)
    for name, embedded in zip(names, glb["images"]):
        view = glb["bufferViews"][embedded["bufferView"]]
        start = view.get("byteOffset", 0)
        assert (tmp_path / name).read_bytes() == glb_blob[start : start + view["byteLength"]], name
    # the buffer holds no PNG: every view is an accessor's
    used = {a["bufferView"] for a in gltf["accessors"] if "bufferView" in a}
    assert used == set(range(len(gltf["bufferViews"])))
    _clean(path)
    a, b = read_drawable(path), read_drawable(tmp_path / "t.glb")
    for pa, pb in zip(a.parts, b.parts):
        for key in ("texture", "normal_map"):
            x, y = getattr(pa, key), getattr(pb, key)
            assert (x is None) == (y is None) and (x is None or np.array_equal(x, y)), (pa.name, key)
    # the impostor's atlas indices name images of the file, now files beside it
    meta = gltf["asset"]["extras"]["treegen_impostor"]
    assert all((tmp_path / names[i]).is_file() for i in meta["images"].values())


def test_atomic_write_leaves_no_temp_files(tmp_path, monkeypatch):
    export(synthetic_asset(), tmp_path / "t.gltf")
    export(synthetic_asset(), tmp_path / "t.glb")
    assert sorted(os.listdir(tmp_path)) == ["t.bin", "t.glb", "t.gltf"]
    old = (tmp_path / "t.glb").read_bytes()

    def broken(asset, path, **opts):
        path.write_bytes(b"half a file")
        raise RuntimeError("interrupted")

    monkeypatch.setitem(WRITERS, ".glb", broken)
    with pytest.raises(RuntimeError):
        export(synthetic_asset(), tmp_path / "t.glb")
    assert sorted(os.listdir(tmp_path)) == ["t.bin", "t.glb", "t.gltf"]
    assert (tmp_path / "t.glb").read_bytes() == old  # the previous file is untouched


def test_a_folder_where_a_side_file_goes_is_named_and_nothing_lands(tmp_path):
    """A .gltf writes its .bin beside it: a folder of that name is refused by its own path,
    before any file is moved into place (it was blamed on the .gltf, and the files moved
    before it stayed)."""
    (tmp_path / "t.bin").mkdir()
    with pytest.raises(TreegenError, match=r"t\.bin: is a folder, where .*t\.gltf writes a file"):
        export(synthetic_asset(), tmp_path / "t.gltf")
    assert sorted(os.listdir(tmp_path)) == ["t.bin"] and not os.listdir(tmp_path / "t.bin")


def test_a_new_write_removes_what_an_earlier_write_to_the_same_output_left(tmp_path):
    """Engines import `--lod-files` parts by name: a run with fewer LODs left NAME_LOD2.glb
    beside the new parts, and a run without an impostor left its sidecar and atlas PNGs.
    A write removes exactly its own output's leftovers: never the other form's (the single
    file and the parts are separate outputs), another format's (.bin of .gltf parts), nor
    another output's whose name merely starts the same (`a_usdc.usdc`'s textures)."""
    from treegen_cli.exchange import export_parts
    from treegen_cli.exchange.stale import stale_files
    from treegen_cli.prepare import split_lods

    export_parts(split_lods(prepare(synthetic_asset(3))), tmp_path / "p.glb")
    export(synthetic_asset(1), tmp_path / "p.glb")  # the single file beside the parts
    for n in (
        "p_LOD2.glb.impostor.json",
        "p.glb.impostor.json",
        "other_LOD5.glb",
        "p_LOD7.bin",
        "p_LOD7.gltf",
    ):
        (tmp_path / n).write_text("not this output's" if "other" in n or "LOD7" in n else "{}")
    export_parts(split_lods(prepare(synthetic_asset(2))), tmp_path / "p.glb")
    assert sorted(os.listdir(tmp_path)) == [
        "other_LOD5.glb",
        "p.glb",
        "p.glb.impostor.json",
        "p_LOD0.glb",
        "p_LOD1.glb",
        "p_LOD7.bin",
        "p_LOD7.gltf",
    ]
    export(synthetic_asset(1), tmp_path / "p.glb")  # no impostor now: its sidecar goes
    assert "p.glb.impostor.json" not in os.listdir(tmp_path)
    names = ["a.usdc", "a_usdc_leaf.png", "a_usdc_impostor_albedo.png", "a.usdc.impostor.json"]
    names += ["a_LOD0.usdc", "a_LOD1.usdc", "a_LOD1.usdc.impostor.json", "a_LOD_usdc_impostor_cards.png"]
    names += ["a_usdc_usdc_impostor_albedo.png", "a_usdc.usdc", "a_LOD_usdc_leaf.png"]
    for n in names:
        (tmp_path / n).write_text("")
    wrote = [tmp_path / n for n in ("a.usdc", "a_usdc_leaf.png")]
    assert [p.name for p in stale_files(tmp_path / "a.usdc", wrote)] == [
        "a.usdc.impostor.json",
        "a_usdc_impostor_albedo.png",
    ]
    wrote = [tmp_path / n for n in ("a_LOD0.usdc", "a_LOD_usdc_leaf.png")]
    assert [p.name for p in stale_files(tmp_path / "a.usdc", wrote, parts=1)] == [
        "a_LOD1.usdc",
        "a_LOD1.usdc.impostor.json",
        "a_LOD_usdc_impostor_cards.png",
    ]


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_static_exports(tmp_path, suffix):
    asset = synthetic_asset(2)
    p = tmp_path / f"tree{suffix}"
    assert export(asset, p)[0] == p  # an .obj also writes its .mtl
    mesh = trimesh.load(p, force="mesh", process=False)
    lod0 = asset.lods[0].primitives
    assert len(mesh.faces) == sum(len(q.indices) // 3 for q in lod0)
    assert len(mesh.vertices) == sum(len(q.positions) for q in lod0)
    gen = np.concatenate([q.positions for q in lod0])
    # Y up (sorted: trimesh concatenates an .obj's material groups in its own order)
    np.testing.assert_allclose(np.sort(mesh.vertices[:, 1]), np.sort(gen[:, 2]), atol=1e-5)


@pytest.mark.parametrize("suffix", [".usda", ".usdz"])
def test_registry_dispatches_usd_lazily(tmp_path, suffix):
    p = tmp_path / f"tree{suffix}"
    assert export(synthetic_asset(2), p) == [p]
    assert os.listdir(tmp_path) == [p.name] and p.stat().st_size > 0


def test_validator_missing_is_a_clear_error(tmp_path, monkeypatch):
    from treegen_cli.exchange import validate

    monkeypatch.setenv("TREEGEN_TOOLS", str(tmp_path))
    with pytest.raises(validate.ValidatorUnavailable, match="npm ci"):
        validate.validate_gltf(tmp_path / "x.glb")
    monkeypatch.undo()
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("TREEGEN_NODE", raising=False)
    with pytest.raises(validate.ValidatorUnavailable, match="Node.js"):
        validate.validate_gltf(tmp_path / "x.glb")


def test_validator_found_from_another_working_folder(tmp_path, monkeypatch):
    """The tools folder is looked up, not assumed at a fixed depth below the package."""
    from treegen_cli.exchange import validate

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("TREEGEN_TOOLS", raising=False)
    assert (validate.tools_dir() / "validate.mjs").is_file()
    p = tmp_path / "x.glb"
    export(synthetic_asset(1), p)
    assert validate.validate_gltf("x.glb")["issues"]["numErrors"] == 0


def test_a_killed_runs_staging_folder_is_swept_by_the_next_run(tmp_path):
    """A staging folder whose writer process is gone is removed by the next write there; one
    of a live process is left alone."""
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    ).stdout.strip()
    stale = tmp_path / f".tree.glb.{dead}.abcd1234.tmp"
    stale.mkdir()
    (stale / "tree.glb").write_bytes(b"half")
    live = tmp_path / f".other.glb.{os.getpid()}.abcd1234.tmp"
    live.mkdir()
    export(synthetic_asset(1), tmp_path / "a.glb")
    assert not stale.exists() and live.exists()
    assert sorted(os.listdir(tmp_path)) == sorted(["a.glb", live.name])
