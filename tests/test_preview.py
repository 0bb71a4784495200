"""treegen preview and treegen species: real renders (EGL), real files, real readers."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from treegen_cli.cli import main
from treegen_cli.errors import TreegenError
from treegen_cli.clip import sample_track
from treegen_cli.drawable import from_asset as scene_from_asset
from treegen_cli.exchange.read_gltf import read_drawable as scene_from_gltf
from treegen_cli.exchange.read_usd import read_drawable as scene_from_usd
from treegen_cli.preview import PreviewOptions, camera_for, load_scene, sun_angles
from treegen_cli.render import Renderer, egl_available, skin_points
from treegen_cli.species_list import describe, species_dir, species_files

ROOT = Path(__file__).resolve().parent.parent
SMALL = ROOT / "species" / "fan_palm.txt"          # 28 stems, 2 160 leaves: quick to grow

needs_egl = pytest.mark.skipif(not egl_available(),
                               reason="no headless OpenGL 3.3 context (EGL) on this machine")


def run(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        main([str(a) for a in argv])
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """fan_palm written by `treegen make` as GLB and USDC (same seed, same asset)."""
    d = tmp_path_factory.mktemp("made")
    for name in ("palm.glb", "palm.usdc"):
        with pytest.raises(SystemExit) as e:
            main(["make", str(SMALL), "-o", str(d / name), "-q"])
        assert e.value.code == 0
    return d


def _rgb(path) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(path).convert("RGB"))


# ------------------------------------------------------------------------------ stills

@needs_egl
def test_still_has_tree_pixels_with_bark_and_leaf_colours(tmp_path, capsys):
    code, out, err = run(["preview", SMALL, "-o", tmp_path / "p.png", "--size", "96x128"], capsys)
    assert code == 0, err
    img = _rgb(tmp_path / "p.png")
    assert img.shape == (128, 96, 3)

    # the same view without the tree is the background; the tree is what differs from it
    options = PreviewOptions(width=96, height=128)
    scene = load_scene(SMALL, options)
    rest = dataclasses.replace(scene, skinning=None)       # stills show the rest pose, no wind
    t0 = np.zeros(1)
    with Renderer(scene, 96, 128) as r:
        args = (camera_for(rest, options, t0), rest.pose(t0)[0], *sun_angles(options))
        tree, background = r.render(*args), r.render(*args, draw_tree=False)
    assert np.array_equal(tree, img)                       # the command draws exactly this
    mask = np.abs(tree.astype(int) - background.astype(int)).sum(-1) > 24
    assert 0.03 < mask.mean() < 0.8
    ys, xs = np.nonzero(mask)
    assert abs(xs.mean() / 96 - 0.5) < 0.2 and abs(ys.mean() / 128 - 0.5) < 0.25   # framed
    r_, g_, b_ = (tree[..., c].astype(int) for c in range(3))
    leafy = mask & (g_ > 1.15 * r_) & (g_ > 1.3 * b_)      # leaf base colour (0.26, 0.46, 0.13)
    barky = mask & (r_ > 1.05 * g_) & (g_ > 1.05 * b_)     # bark base colour (0.36, 0.27, 0.19)
    assert leafy.sum() > 30 and barky.sum() > 30


@needs_egl
def test_preview_of_written_glb_and_usd_matches_in_process_render(written, tmp_path, capsys):
    for name in ("palm.glb", "palm.usdc"):
        code, out, err = run(["preview", written / name, "-o", tmp_path / f"{name}.png",
                              "--size", "64", "--azimuth", "30", "--elevation", "20"], capsys)
        assert code == 0, err
    a, b = _rgb(tmp_path / "palm.glb.png"), _rgb(tmp_path / "palm.usdc.png")
    assert a.shape == (64, 64, 3)
    # float32 files, one skinning path: the pictures agree but for a few edge pixels
    assert (np.abs(a.astype(int) - b.astype(int)).sum(-1) > 30).mean() < 0.02


@needs_egl
def test_gif_loops_and_moves(tmp_path, capsys):
    from PIL import Image, ImageSequence

    gif = tmp_path / "wind.gif"
    code, out, err = run(["preview", SMALL, "--animate", gif, "--size", "96", "--fps", "2"], capsys)
    assert code == 0, err
    frames = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(Image.open(gif))]
    assert len(frames) == round(10.0 * 2) + 1                # default 10 s loop, both ends
    assert all(f.shape == (96, 96, 3) for f in frames)
    assert np.array_equal(frames[0], frames[-1])             # the loop closes
    assert all(not np.array_equal(a, b) for a, b in zip(frames, frames[1:]))   # the tree moves


# ------------------------------------------------------------------------------ loaders

def test_skinning_agrees_across_asset_gltf_and_usd(written):
    """The three loaders pose the same skeleton: S_j(t) = W_j(t)·B_j⁻¹ agree in Y-up space."""
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import build_asset

    asset, _ = build_asset(load_params(SMALL), 0)
    t = np.array([0.0, 0.37, 1.5, 2.0, 4.0])
    for lod in range(len(asset.lods)):
        ref = scene_from_asset(asset, lod).pose(t)
        for scene in (scene_from_gltf(written / "palm.glb", lod),
                      scene_from_usd(written / "palm.usdc", lod)):
            assert scene.n_joints == ref.shape[1]
            assert np.allclose(scene.pose(t), ref, atol=1e-4)
    # the clip loops: end pose == start pose
    s = scene_from_gltf(written / "palm.glb")
    assert np.array_equal(s.pose([0.0]), s.pose([s.duration]))
    # rest-pose geometry survives the file (float32)
    g = scene_from_gltf(written / "palm.glb")
    a = scene_from_asset(asset)
    for pa, pg in zip(a.parts, g.parts):
        assert np.allclose(pa.positions, pg.positions, atol=1e-5)
        assert np.array_equal(pa.indices, pg.indices)


def test_skin_points_identity_and_translation():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(50, 3))
    joints = rng.integers(0, 3, size=(50, 4))
    w = rng.random((50, 4))
    w /= w.sum(1, keepdims=True)
    mats = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    assert np.allclose(skin_points(p, joints, w, mats), p)
    mats[:, :3, 3] = (1.0, 2.0, 3.0)                       # every joint moved alike
    assert np.allclose(skin_points(p, joints, w, mats), p + (1.0, 2.0, 3.0))


def test_sample_track_hits_keys_and_holds_ends():
    times = np.array([0.0, 1.0, 3.0])
    q = np.array([[0, 0, 0, 1], [0, 0, np.sin(0.2), np.cos(0.2)], [0, 0, np.sin(0.6), np.cos(0.6)]])
    v = q[:, None, :]
    out = sample_track(times, v, np.array([-1.0, 0.0, 1.0, 2.0, 3.0, 9.0]))
    assert np.allclose(out[[1, 2, 4], 0], q)
    assert np.allclose(out[0, 0], q[0]) and np.allclose(out[5, 0], q[2])
    assert np.allclose(out[3, 0], [0, 0, np.sin(0.4), np.cos(0.4)])     # slerp halfway
    step = sample_track(times, v, np.array([0.5, 2.9]), "STEP")
    assert np.allclose(step[:, 0], q[:2])


# ------------------------------------------------------------------------------ errors

@pytest.mark.parametrize("argv, needle", [
    (["preview", "nope/missing.txt", "-o", "{d}/x.png"], "no such file"),
    (["preview", "{d}/tree.obj", "-o", "{d}/x.png"], "unknown input extension"),
    (["preview", str(SMALL), "-o", "{d}/x.bmp"], "unknown image extension"),
    (["preview", str(SMALL), "--animate", "{d}/x.mp4"], "unknown animation extension"),
    (["preview", str(SMALL)], "give an image"),
    (["preview", str(SMALL), "-o", "{d}/x.png", "--size", "big"], "--size"),
    (["preview", str(SMALL), "-o", "{d}/x.png", "--lod", "99"], "out of range"),
    (["preview", "{d}/palm.glb", "-o", "{d}/x.png", "--lod", "7"], "out of range"),
    (["preview", "{d}/broken.glb", "-o", "{d}/x.png"], "not a readable glTF"),
])
def test_bad_input_is_one_line_exit_2(argv, needle, written, capsys):
    (written / "tree.obj").write_text("v 0 0 0\n")
    (written / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    code, out, err = run([a.format(d=written) for a in argv], capsys)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("treegen: error:") and needle in err
    assert "Traceback" not in err


def test_lod_out_of_range_raises_treegen_error(written):
    with pytest.raises(TreegenError, match="only LOD 0|LODs 0"):
        scene_from_gltf(written / "palm.glb", lod=50)


# ------------------------------------------------------------------------------ species

def test_species_lists_every_bundled_file_with_counts(capsys):
    from treegen_cli.generate import generate
    from treegen_cli.params import load_params

    files = species_files()
    assert species_dir() == ROOT / "species" and len(files) >= 10
    code, out, err = run(["species", "--json"], capsys)
    assert code == 0, err
    rows = json.loads(out)
    assert [r["name"] for r in rows] == [p.stem for p in files]
    assert all(r["description"] and "\n" not in r["description"] for r in rows)
    palm = next(r for r in rows if r["name"] == "fan_palm")
    tree = generate(load_params(SMALL), 0)
    assert (palm["stems"], palm["leaves"]) == (tree.n_stems, tree.n_leaves)
    assert describe(ROOT / "species" / "quaking_aspen.txt").startswith("Quaking Aspen (Populus")
    assert describe(SMALL) == "Fan palm — Arbaro trees/fanpalm.xml"


def test_preview_json_summary(tmp_path):
    """--json prints what was written, machine-readable."""
    import json as _json
    import subprocess
    import sys

    from treegen_cli.render import egl_available

    if not egl_available():
        pytest.skip("no EGL context on this machine")
    out = tmp_path / "p.png"
    proc = subprocess.run([sys.executable, "-m", "treegen_cli", "preview",
                           str(Path(__file__).resolve().parent.parent / "species" / "palm.txt"),
                           "-o", str(out), "--size", "64", "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    summary = _json.loads(proc.stdout)
    assert summary["image"] == str(out) and summary["width"] == 64 and out.exists()
