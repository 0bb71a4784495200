"""Static formats: .obj keeps UVs, groups and materials (an .mtl with the same textures as the
skinned formats), .ply the rest-pose geometry; both Y up by default, metres."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from synthetic import synthetic_asset, synthetic_textures, textured_asset
from treegen_cli.axes import to_y_up
from treegen_cli.exchange import export
from treegen_cli.prepare import prepare

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def obj(tmp_path_factory):
    d = tmp_path_factory.mktemp("obj")
    return export(prepare(textured_asset()), d / "tree.obj")


def parse_mtl(path):
    """{material: {key: rest of line}} of a .mtl."""
    out, cur = {}, None
    for line in path.read_text().splitlines():
        key, _, rest = line.strip().partition(" ")
        if key == "newmtl":
            cur = out.setdefault(rest, {})
        elif cur is not None and key:
            cur[key] = rest
    return out


def test_obj_files_and_names(obj):
    assert [f.name for f in obj] == [
        "tree.obj",
        "tree.mtl",
        "tree_obj_bark.png",
        "tree_obj_bark_normal.png",
        "tree_obj_leaf.png",
    ]
    tex = synthetic_textures()
    for name, t in tex.items():
        assert (obj[0].parent / f"tree_obj_{name}.png").read_bytes() == t.png


def test_mtl_has_both_materials_with_existing_textures(obj):
    mtl = parse_mtl(obj[0].parent / "tree.mtl")
    assert set(mtl) == {"bark", "leaf"}
    for m in mtl.values():
        assert (obj[0].parent / m["map_Kd"]).is_file()
    assert mtl["leaf"]["map_d"] == mtl["leaf"]["map_Kd"] == "tree_obj_leaf.png"  # alpha cut-out
    assert mtl["bark"]["map_Bump"].split()[-1] == "tree_obj_bark_normal.png"
    assert "map_d" not in mtl["bark"]
    np.testing.assert_allclose(
        [float(v) for v in mtl["bark"]["Kd"].split()], textured_asset().materials[0].base_color[:3]
    )


def test_trimesh_loads_groups_with_uvs_and_textures(obj):
    """trimesh (group_material) gives one mesh per material, each with its UVs and image."""
    asset = textured_asset()
    scene = trimesh.load(obj[0])
    assert set(scene.geometry) == {"bark", "leaf"}
    for prim in asset.lods[0].primitives:
        g = scene.geometry[prim.material]
        assert g.visual.kind == "texture"
        assert g.visual.material.image is not None
        assert g.visual.material.image.size == (32, 32)
        # trimesh may reorder vertices: compare as sets of (position, uv) rows
        want = np.c_[to_y_up(prim.positions.astype(np.float64)), prim.uvs]
        got = np.c_[g.vertices, g.visual.uv]
        assert len(got) == len(want)
        np.testing.assert_allclose(
            np.unique(got.round(5), axis=0), np.unique(want.round(5), axis=0), atol=2e-5
        )


def test_obj_plain_parse_groups_and_indices(obj):
    lines = obj[0].read_text().splitlines()
    asset = textured_asset()
    prims = asset.lods[0].primitives
    n = sum(len(p.positions) for p in prims)
    assert sum(ln.startswith("v ") for ln in lines) == n
    assert sum(ln.startswith("vt ") for ln in lines) == n
    assert sum(ln.startswith("vn ") for ln in lines) == n
    assert [ln for ln in lines if ln.startswith(("g ", "usemtl "))] == [
        "g bark",
        "usemtl bark",
        "g leaves",
        "usemtl leaf",
    ]
    faces = [ln for ln in lines if ln.startswith("f ")]
    assert len(faces) == sum(len(p.indices) // 3 for p in prims)
    idx = np.array([[int(c.split("/")[0]) for c in f.split()[1:]] for f in faces])
    assert idx.min() == 1 and idx.max() == n


def test_up_axis_z_keeps_generator_space_and_metres(tmp_path):
    asset = synthetic_asset()
    export(prepare(dataclasses.replace(asset, up_axis="z")), tmp_path / "z.obj")
    export(prepare(asset), tmp_path / "y.obj")

    def verts(p):
        return np.array(
            [[float(v) for v in ln.split()[1:]] for ln in p.read_text().splitlines() if ln.startswith("v ")]
        )

    vz, vy = verts(tmp_path / "z.obj"), verts(tmp_path / "y.obj")
    np.testing.assert_allclose(vy, to_y_up(vz), atol=1e-6)
    assert vz[:, 2].max() > 4.0 and vy[:, 1].max() > 4.0  # the same height, up either way


def test_untextured_obj_writes_colours_only(tmp_path):
    files = export(prepare(synthetic_asset()), tmp_path / "plain.obj")
    assert [f.name for f in files] == ["plain.obj", "plain.mtl"]
    mtl = parse_mtl(tmp_path / "plain.mtl")
    assert set(mtl) == {"bark", "leaf"} and not any(k.startswith("map_") for m in mtl.values() for k in m)


def test_obj_same_asset_same_bytes(tmp_path):
    out = []
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        out.append([f.read_bytes() for f in export(prepare(textured_asset()), tmp_path / sub / "t.obj")])
    assert out[0] == out[1]


def test_ply_rest_pose(tmp_path):
    asset = synthetic_asset()
    (path,) = export(prepare(asset), tmp_path / "t.ply")
    mesh = trimesh.load(path, process=False)
    n = sum(len(p.positions) for p in asset.lods[0].primitives)
    assert len(mesh.vertices) == n
    np.testing.assert_allclose(
        mesh.vertices[: len(asset.lods[0].primitives[0].positions)],
        to_y_up(asset.lods[0].primitives[0].positions),
        atol=1e-5,
    )


# --------------------------------------------------------------------------- command line

import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PALM = ROOT / "species" / "fan_palm.txt"


def treegen(*args):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT
    )


def test_cli_static_format_implies_no_wind(tmp_path):
    """No clip or LOD work for a file that cannot hold them, and the summary says so (and
    counts no joints or keys, which the file does not have)."""
    proc = treegen("make", PALM, "-o", tmp_path / "palm.obj")
    assert proc.returncode == 0, proc.stderr
    assert "static format: no wind or LODs" in proc.stdout
    assert "joints" not in proc.stdout and "keys" not in proc.stdout  # none are in the file
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "palm.mtl",
        "palm.obj",
        "palm_obj_bark.png",
        "palm_obj_bark_normal.png",
        "palm_obj_leaf.png",
    ]
    s = json.loads(treegen("make", PALM, "-o", tmp_path / "palm.ply", "--json").stdout)
    assert s["keys"] == 0 and len(s["lods"]) == 1
    assert s["joints"] == s["lods"][0]["joints"] == 0  # no skin in the file
    assert "wind" not in s["stages_s"] and "lod" not in s["stages_s"]


def test_cli_up_axis_z_for_gltf_is_a_user_error(tmp_path):
    proc = treegen("make", PALM, "-o", tmp_path / "palm.glb", "--up-axis", "z")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert [ln for ln in proc.stderr.splitlines() if ln.strip()] == [
        f"treegen: error: {tmp_path / 'palm.glb'}: glTF is always Y up; up axis z needs one of "
        ".obj .ply .usda .usdc .usdz"
    ]
    assert not list(tmp_path.iterdir())


def test_cli_up_axis_reaches_the_usd_writer(tmp_path):
    from pxr import Usd, UsdGeom

    for name, args, up in (
        ("a.usdz", [], "Y"),
        ("b.usdz", ["--up-axis", "z"], "Z"),
        ("c.usdc", [], "Z"),
        ("d.usda", ["--up-axis", "y"], "Y"),
    ):
        proc = treegen("make", PALM, "-o", tmp_path / name, "--duration", "1", "--fps", "5", *args)
        assert proc.returncode == 0, proc.stderr
        assert UsdGeom.GetStageUpAxis(Usd.Stage.Open(str(tmp_path / name))) == up, name
