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
from treegen_cli.drawable import Part, from_asset as scene_from_asset
from treegen_cli.exchange.read_gltf import read_drawable as scene_from_gltf
from treegen_cli.exchange.read_usd import read_drawable as scene_from_usd
from treegen_cli.preview import PreviewOptions, camera_for, load_scene, sun_angles
from treegen_cli.render import Renderer
from treegen_cli.render_gl import egl_available
from treegen_cli.render_view import skin_points
from treegen_cli.species_list import describe, species_dir, species_files

ROOT = Path(__file__).resolve().parent.parent
SMALL = ROOT / "species" / "fan_palm.txt"  # 28 stems, 2 160 leaves: quick to grow

needs_egl = pytest.mark.skipif(
    not egl_available(), reason="no headless OpenGL 3.3 context (EGL) on this machine"
)


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
    rest = dataclasses.replace(scene, skinning=None)  # stills show the rest pose, no wind
    t0 = np.zeros(1)
    with Renderer(scene, 96, 128) as r:
        args = (camera_for(rest, options, t0), rest.pose(t0)[0], *sun_angles(options))
        tree, background = r.render(*args), r.render(*args, draw_tree=False)
    assert np.array_equal(tree, img)  # the command draws exactly this
    mask = np.abs(tree.astype(int) - background.astype(int)).sum(-1) > 24
    assert 0.03 < mask.mean() < 0.8
    ys, xs = np.nonzero(mask)
    assert abs(xs.mean() / 96 - 0.5) < 0.2 and abs(ys.mean() / 128 - 0.5) < 0.25  # framed
    r_, g_, b_ = (tree[..., c].astype(int) for c in range(3))
    leafy = mask & (g_ > 1.15 * r_) & (g_ > 1.3 * b_)  # leaf base colour (0.26, 0.46, 0.13)
    barky = mask & (r_ > 1.05 * g_) & (g_ > 1.05 * b_)  # bark base colour (0.36, 0.27, 0.19)
    assert leafy.sum() > 30 and barky.sum() > 30


def _tree_mask(scene, options) -> tuple[np.ndarray, np.ndarray]:
    """Pixels where the tree itself (not its shadow) is drawn, as the command frames it, and
    the picture without the tree."""
    rest = dataclasses.replace(scene, skinning=None)
    t0 = np.zeros(1)
    with Renderer(scene, options.width, options.height) as r:
        args = (camera_for(rest, options, t0), rest.pose(t0)[0], *sun_angles(options))
        tree, background = r.render(*args), r.render(*args, draw_tree=False)
    return np.abs(tree.astype(int) - background.astype(int)).sum(-1) > 24, background


@needs_egl
@pytest.mark.parametrize("elevation", [8.0, 60.0])
def test_framing_fits_the_width_and_the_height_of_any_aspect(elevation):
    # the fan palm's crown is as wide as the tree is tall: a portrait view must fit its width
    # (fitted to the height alone it ran off both sides), a landscape one its height
    scene = load_scene(SMALL)
    for width, height in ((60, 180), (180, 60)):
        options = PreviewOptions(width=width, height=height, elevation=elevation)
        mask, background = _tree_mask(scene, options)
        ys, xs = np.nonzero(mask)
        assert not (mask[:, 0].any() or mask[:, -1].any() or mask[0].any() or mask[-1].any())
        # the fit is tight on the binding side: the 8 % margin, not a tree shrunk to a dot
        fill = max((np.ptp(xs) + 1) / width, (np.ptp(ys) + 1) / height)
        assert fill > 0.85, (width, height, fill)
        # the view reaches far below the tree's foot: ground there (olive, green over blue),
        # not sky showing through a near plane that cut the ground off
        g_, b_ = (background[-1, :, c].astype(int) for c in (1, 2))
        assert (g_ > b_).all()


@needs_egl
def test_preview_of_written_glb_and_usd_matches_in_process_render(written, tmp_path, capsys):
    # the species itself too: grown in-process at LOD 0 it skips the LOD chain (preview.py),
    # and must still be the tree `make` wrote
    for name, src in (
        ("palm.glb", written / "palm.glb"),
        ("palm.usdc", written / "palm.usdc"),
        ("species", SMALL),
    ):
        code, out, err = run(
            [
                "preview",
                src,
                "-o",
                tmp_path / f"{name}.png",
                "--size",
                "64",
                "--azimuth",
                "30",
                "--elevation",
                "20",
            ],
            capsys,
        )
        assert code == 0, err
    a, b = _rgb(tmp_path / "palm.glb.png"), _rgb(tmp_path / "palm.usdc.png")
    c = _rgb(tmp_path / "species.png")
    assert a.shape == (64, 64, 3)
    # float32 files, one skinning path: the pictures agree but for a few edge pixels
    assert (np.abs(a.astype(int) - b.astype(int)).sum(-1) > 30).mean() < 0.02
    assert (np.abs(a.astype(int) - c.astype(int)).sum(-1) > 30).mean() < 0.02


@needs_egl
def test_gif_loops_seamlessly_at_the_clips_speed_and_moves(tmp_path, capsys):
    from PIL import Image, ImageSequence

    # 3 fps over the default 10 s loop: 333.3 ms a frame, not a whole number of GIF 10 ms units
    gifs = [tmp_path / "a.gif", tmp_path / "b.gif"]
    for gif in gifs:
        code, out, err = run(["preview", SMALL, "--animate", gif, "--size", "64", "--fps", "3"], capsys)
        assert code == 0, err
    assert gifs[0].read_bytes() == gifs[1].read_bytes()  # deterministic
    frames, delays = [], []
    with Image.open(gifs[0]) as im:
        for f in ImageSequence.Iterator(im):  # one image object, seeked: read each frame now
            frames.append(np.asarray(f.convert("RGB")))
            delays.append(f.info["duration"])
    # the clip's 31 keys less the closing one, which repeats the first pose
    assert len(frames) == round(10.0 * 3)
    assert all(f.shape == (64, 64, 3) for f in frames)
    assert abs(sum(delays) - 10_000) <= 10  # plays as long as the clip
    assert set(delays) == {330, 340}  # the 10 ms rounding spread over the frames
    # every step moves the tree, the wrap from the last frame to the first too: no pose held
    assert all(not np.array_equal(a, b) for a, b in zip(frames, frames[1:] + frames[:1]))


def test_gif_delays_sum_to_the_loop():
    from treegen_cli.exchange.image import gif_delays

    d = gif_delays(150, 10.0)  # 15 fps
    assert d[:3] == [70, 60, 70] and sum(d) == 10_000
    for n, duration in ((7, 1.3), (600, 10.0), (1, 4.0), (29, 9.97)):
        d = gif_delays(n, duration)
        assert len(d) == n and all(x % 10 == 0 and x > 0 for x in d)
        assert abs(sum(d) - 1000 * duration) <= 5


def _impostor_scenes(path: Path):
    """(coarsest geometric LOD, impostor LOD) of a written tree, the impostor's index read
    from the file's sidecar description (exchange/impostor_meta.py)."""
    k = json.loads(Path(f"{path}.impostor.json").read_text())["lod_index"]
    return [load_scene(path, PreviewOptions(lod=lod)) for lod in (k - 1, k)]


@pytest.mark.parametrize("name", ["palm.glb", "palm.usdc"])
def test_impostor_is_framed_like_the_lod_it_replaces(written, name):
    """The impostor's camera fits what its cards show (their opaque texels), as the coarsest
    geometric LOD's fits its vertices, so --lod 3 and --lod 4 side by side frame the tree alike.
    Fitted to the cards' corners (squares around the tree's sphere) it stood 44 % and 80 %
    farther off here."""
    geo_scene, imp_scene = _impostor_scenes(written / name)
    assert [p.impostor for p in imp_scene.parts] == [True]
    assert not any(p.impostor for p in geo_scene.parts)
    t0 = np.zeros(1)
    for azimuth, elevation in ((-90.0, 8.0), (0.0, 30.0)):
        options = PreviewOptions(azimuth=azimuth, elevation=elevation)
        geo, imp = camera_for(geo_scene, options, t0), camera_for(imp_scene, options, t0)
        dist = np.linalg.norm(geo.eye - geo.target)
        assert np.linalg.norm(imp.eye - imp.target) == pytest.approx(dist, rel=0.08)
        assert np.linalg.norm(imp.target - geo.target) < 0.05 * dist


@needs_egl
def test_impostor_still_shows_the_tree_as_tall_as_the_lod_it_replaces(written):
    """Rendered, the tree is as many pixels tall at the impostor LOD as at the one before
    (rows with 2+ tree pixels: a card seen edge-on draws a 1-pixel line beyond the crown).
    Framed by the cards' corners the palm was 32 % shorter."""
    heights = []
    options = PreviewOptions(width=128, height=128)
    t0 = np.zeros(1)
    for scene in _impostor_scenes(written / "palm.glb"):
        rest = dataclasses.replace(scene, skinning=None)
        with Renderer(scene, 128, 128) as r:
            args = (camera_for(rest, options, t0), rest.pose(t0)[0], *sun_angles(options))
            tree, background = r.render(*args), r.render(*args, draw_tree=False)
        mask = np.abs(tree.astype(int) - background.astype(int)).sum(-1) > 24
        rows = np.flatnonzero(mask.sum(1) >= 2)
        heights.append(rows[-1] - rows[0] + 1)
    assert heights[0] > 64  # framed: the tree fills most of the picture's height
    assert heights[1] == pytest.approx(heights[0], rel=0.06)


# ------------------------------------------------------------------------------ loaders


def test_skinning_agrees_across_asset_gltf_and_usd(written):
    """The three loaders pose the same skeleton: S_j(t) = W_j(t)·B_j⁻¹ agree in Y-up space."""
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import build_asset

    asset, _ = build_asset(load_params(SMALL), 0)
    t = np.array([0.0, 0.37, 1.5, 2.0, 4.0])
    for lod in range(len(asset.lods)):
        ref_scene = scene_from_asset(asset, lod)
        ref = ref_scene.pose(t)
        for scene in (scene_from_gltf(written / "palm.glb", lod), scene_from_usd(written / "palm.usdc", lod)):
            assert scene.n_joints == ref.shape[1]
            assert np.allclose(scene.pose(t), ref, atol=1e-4)
            # leaves lit as leaves; far LODs' crossed twig ribbons, double-sided too, as bark
            assert [p.double_sided for p in scene.parts] == [p.double_sided for p in ref_scene.parts]
    twigs = [p for p in scene_from_gltf(written / "palm.glb", 3).parts if p.name == "twigs"]
    assert twigs and not twigs[0].double_sided
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
    mats[:, :3, 3] = (1.0, 2.0, 3.0)  # every joint moved alike
    assert np.allclose(skin_points(p, joints, w, mats), p + (1.0, 2.0, 3.0))


def test_sample_track_hits_keys_and_holds_ends():
    times = np.array([0.0, 1.0, 3.0])
    q = np.array([[0, 0, 0, 1], [0, 0, np.sin(0.2), np.cos(0.2)], [0, 0, np.sin(0.6), np.cos(0.6)]])
    v = q[:, None, :]
    out = sample_track(times, v, np.array([-1.0, 0.0, 1.0, 2.0, 3.0, 9.0]))
    assert np.allclose(out[[1, 2, 4], 0], q)
    assert np.allclose(out[0, 0], q[0]) and np.allclose(out[5, 0], q[2])
    assert np.allclose(out[3, 0], [0, 0, np.sin(0.4), np.cos(0.4)])  # slerp halfway
    step = sample_track(times, v, np.array([0.5, 2.9]), "STEP")
    assert np.allclose(step[:, 0], q[:2])


# ------------------------------------------------------------------------------ errors


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["preview", "nope/missing.txt", "-o", "{d}/x.png"], "no such file"),
        (["preview", "{d}/tree.obj", "-o", "{d}/x.png"], "unknown input extension"),
        (["preview", str(SMALL), "-o", "{d}/x.bmp"], "unknown image extension"),
        (["preview", str(SMALL), "--animate", "{d}/x.mp4"], "unknown animation extension"),
        (["preview", str(SMALL)], "give an image"),
        (["preview", str(SMALL), "-o", "{d}/x.png", "--size", "big"], "--size"),
        (["preview", str(SMALL), "-o", "{d}/x.png", "--lod", "99"], "out of range"),
        (["preview", "{d}/palm.glb", "-o", "{d}/x.png", "--lod", "7"], "out of range"),
        (["preview", "{d}/broken.glb", "-o", "{d}/x.png"], "not a whole GLB file (its header says"),
        (["preview", "{d}/broken2.glb", "-o", "{d}/x.png"], "not a readable glTF"),
        (["preview", "{d}/oak.species", "-o", "{d}/x.png"], "oak.species:1: unknown key"),  # read
        (["preview", str(SMALL), "-o", "{d}/x.png", "--sun", "nan"], "--sun nan: give a bearing"),
        (["preview", "{d}/palm.glb", "-o", "{d}/x.png", "--seed", "3"], "is a written tree"),
        (["preview", "{d}/palm.glb", "-o", "{d}/x.png", "--seed", "0"], "is a written tree"),
        (["preview", str(SMALL), "-o", "{d}/x.png", "--seed", "-1"], "--seed -1: allowed range 0.."),
    ],
)
def test_bad_input_is_one_line_exit_2(argv, needle, written, capsys):
    (written / "tree.obj").write_text("v 0 0 0\n")
    (written / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    (written / "broken2.glb").write_bytes(b"glTF\x02\x00\x00\x00\x20\x00\x00\x00" + b"\x00" * 20)
    (written / "oak.species").write_text("Lvels 2\n")  # any name: read as make reads it
    code, out, err = run([a.format(d=written) for a in argv], capsys)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("treegen: error:") and needle in err
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def forest_files(tmp_path_factory):
    """Two instances of one small palm written by `treegen forest` as GLB and USDA."""
    d = tmp_path_factory.mktemp("forest")
    layout = {
        "wind": {"duration": 1.0, "fps": 8, "seed": 3},
        "defaults": {"max_joints": 12, "lod_distances": [0, 25]},
        "instances": [
            {"species": str(ROOT / "species" / "palm.txt"), "position": [0, 0], "seed": 1},
            {
                "species": str(ROOT / "species" / "palm.txt"),
                "position": [6, 3],
                "seed": 1,
                "rotation_deg": 90,
            },
        ],
    }
    (d / "layout.json").write_text(json.dumps(layout))
    for name in ("f.glb", "f.usda"):
        with pytest.raises(SystemExit) as e:
            main(
                [
                    "forest",
                    str(d / "layout.json"),
                    "-o",
                    str(d / name),
                    "--workers",
                    "1",
                    "--no-impostor",
                    "-q",
                ]
            )
        assert e.value.code == 0
    return d


@pytest.mark.parametrize("name", ["f.glb", "f.usda"])
def test_preview_of_a_forest_is_refused_in_one_line(forest_files, name, tmp_path, capsys):
    # the GLB drew its first tree alone (exit 0), the USD said it had no UsdSkel SkelRoot
    png, gif = tmp_path / "f.png", tmp_path / "f.gif"
    code, out, err = run(["preview", forest_files / name, "-o", png, "--animate", gif], capsys)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("treegen: error:") and "Traceback" not in err
    assert f"{name}: a forest (2 instances); preview draws single trees" in err
    assert "treegen make" in err
    assert not png.exists() and not gif.exists()
    # other readers of a forest GLB still get its first tree (test_forest relies on it)
    if name == "f.glb":
        assert scene_from_gltf(forest_files / name).parts


def test_a_species_preview_reaches_the_impostor_as_make_writes_it():
    """`preview SPECIES --lod K` builds the LODs as `make` does: the last is the impostor
    (its cards, 8 triangles), as in the written file (it was refused: no impostor)."""
    from treegen_cli.preview import PreviewOptions, load_scene

    scene = load_scene("quaking_aspen", PreviewOptions(lod=4))
    assert sum(len(p.indices) // 3 for p in scene.parts) == 8


def test_lod_out_of_range_raises_treegen_error(written):
    with pytest.raises(TreegenError, match="only LOD 0|LODs 0"):
        scene_from_gltf(written / "palm.glb", lod=50)


# ------------------------------------------------------------------------------ species


def test_species_lists_every_bundled_file_with_counts(capsys):
    from treegen_cli.generate import generate
    from treegen_cli.params import load_params

    files = species_files()
    # package data; the repository's species/ is a link to it (README commands)
    assert species_dir() == ROOT / "treegen_cli" / "species" and len(files) >= 10
    assert (ROOT / "species").resolve() == species_dir()
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


def test_sun_bearing_is_fixed_by_sun(written, capsys):
    """--sun fixes where the light comes from (the default turns with the camera, 50° to its
    left): the default's bearing given explicitly draws the same bytes; from the other side
    the crown's lit half moves across."""
    from PIL import Image

    images = {}
    for name, extra in {"default": [], "same": ["--sun", "-140"], "other": ["--sun", "-40"]}.items():
        out = written / f"sun_{name}.png"
        code, _out, err = run(
            ["preview", str(written / "palm.glb"), "-o", str(out), "--size", "96", *extra], capsys
        )
        assert code == 0, err
        images[name] = np.asarray(Image.open(out).convert("RGB")).astype(float)
    assert np.array_equal(images["default"], images["same"])
    sky = images["default"][2, 2]
    crown = np.abs(images["default"] - sky).sum(-1) > 60
    crown[60:] = False  # the palm's fronds, not its trunk's foot or the ground
    mid = int(np.median(np.nonzero(crown)[1]))
    lum = {k: v.mean(-1) for k, v in images.items()}
    left = {k: v[:, :mid][crown[:, :mid]].mean() / v[:, mid:][crown[:, mid:]].mean() for k, v in lum.items()}
    assert left["default"] > left["other"], left


def test_preview_json_summary(tmp_path):
    """--json prints what was written, machine-readable."""
    import json as _json
    import subprocess
    import sys

    from treegen_cli.render_gl import egl_available

    if not egl_available():
        pytest.skip("no EGL context on this machine")
    out = tmp_path / "p.png"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "preview",
            str(Path(__file__).resolve().parent.parent / "species" / "palm.txt"),
            "-o",
            str(out),
            "--size",
            "64",
            "--json",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    summary = _json.loads(proc.stdout)
    assert summary["image"] == str(out) and summary["width"] == 64 and out.exists()


# ------------------------------------------------------------------------------ textures


def _card(uvs=None, **material) -> "Part":
    """A 1 m × 2 m vertical card facing +Z (towards a camera at azimuth −90°, elevation 0)."""
    from treegen_cli.drawable import Part

    pos = np.float32([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 2, 0], [-0.5, 2, 0]])
    uv = np.float32([[0, 0], [1, 0], [1, 1], [0, 1]]) if uvs is None else np.float32(uvs)
    return Part(
        name="card",
        positions=pos,
        normals=np.tile(np.float32([0, 0, 1]), (4, 1)),
        indices=np.uint32([0, 1, 2, 0, 2, 3]),
        joints=np.zeros((4, 4), np.int64),
        weights=np.tile(np.float32([1, 0, 0, 0]), (4, 1)),
        uvs=uv,
        **material,
    )


def _shoot(part, size=96, sun=(-140.0, 50.0)):
    """(tree, background) renders of one part, framed from the front; background keeps the
    part's shadow."""
    from treegen_cli.drawable import Drawable
    from treegen_cli.render_view import frame_points

    scene = Drawable(parts=[part], n_joints=1)
    cam = frame_points(part.positions, -90.0, 0.0, margin=0.3)
    with Renderer(scene, size, size) as r:
        return r.render(cam, None, *sun), r.render(cam, None, *sun, draw_tree=False)


def _leaf_rgba(size=128):
    """One-variant oval leaf (LeafShape 0) and the card UVs (bottom-left) that fill the card."""
    from treegen_cli.texture_leaf import card_uvs, leaf_atlas

    atlas = leaf_atlas(0, (0.16, 0.30, 0.06), size=size, variants=1)
    card = np.float32([[0, 0], [1, 0], [1, 1], [0, 1]])
    return atlas.rgba, card_uvs(card, np.zeros(4, int), atlas, origin="bottom-left")


def _covered(tree, background):
    return np.abs(tree.astype(int) - background.astype(int)).sum(-1) > 24


@needs_egl
def test_cut_out_leaf_covers_less_of_the_card_and_of_its_shadow():
    rgba, uv = _leaf_rgba(100)  # 100 → 50 → 25 → 12: odd levels too
    flat = _card(uv, color=(0.3, 0.5, 0.1), double_sided=True)
    leaf = _card(
        uv, color=(1, 1, 1), double_sided=True, texture=rgba, alpha_cutoff=0.5, wrap=("CLAMP", "CLAMP")
    )
    (ft, fb), (lt, lb) = _shoot(flat), _shoot(leaf)
    full, cut = _covered(ft, fb).sum(), _covered(lt, lb).sum()
    assert full > 500
    assert 0.35 * full < cut < 0.85 * full  # an oval blade on its card: ~ π/4 of it
    # the shadow pass tests alpha too: the card's shadow on the ground shrinks alike
    shade_flat = (fb.astype(int).sum(-1) < lb.astype(int).sum(-1) - 24).sum()
    assert shade_flat > 50
    # no alpha test without a cutoff (OPAQUE): the whole card again
    opaque = _card(uv, color=(1, 1, 1), double_sided=True, texture=rgba)
    assert _covered(*_shoot(opaque)).sum() >= 0.97 * full


@needs_egl
def test_bark_texture_shows_and_normal_map_follows_the_opengl_convention():
    from treegen_cli.texture_bark import bark_textures

    albedo, normal = bark_textures((0.2, 0.19, 0.17), size=64, seed=1)
    rgba = np.concatenate([albedo, np.full((64, 64, 1), 255, np.uint8)], axis=2)
    tiles = [[0, 0], [2, 0], [2, 4], [0, 4]]  # REPEAT: two tiles across, four up
    flat_t, flat_b = _shoot(_card(tiles, color=(0.2, 0.19, 0.17)))
    bark_t, bark_b = _shoot(_card(tiles, color=(1, 1, 1), texture=rgba, normal_map=normal))
    m = _covered(flat_t, flat_b) & _covered(bark_t, bark_b)
    m = m[:, 1:] & m[:, :-1]

    def grain(img):  # pixel-to-pixel change across the card (not shading)
        lum = img.astype(float).sum(-1)
        return np.abs(np.diff(lum, axis=1))[m].mean()

    assert grain(bark_t) > 5 * grain(flat_t) + 5

    # a constant normal map leaning towards +u is lit by a sun on the +u (+X) side, and the
    # one leaning to −u is not: T = +u, and G = +v (up), the glTF / OpenGL convention
    def lit(r, g):
        nm = np.zeros((4, 4, 3), np.uint8)
        nm[...] = (r, g, 200)
        t, b = _shoot(_card(color=(0.5, 0.5, 0.5), normal_map=nm), sun=(0.0, 20.0))
        return t.astype(float)[_covered(t, b)].mean()

    assert lit(230, 128) > lit(25, 128) + 20

    def up(g):
        card = _card(color=(0.5, 0.5, 0.5), normal_map=np.full((4, 4, 3), (128, g, 200), np.uint8))
        return _shoot(card, sun=(-90.0, 80.0))[0].astype(float).mean()

    assert up(230) > up(25)  # sun overhead: +v leans to it


def test_mips_average_in_linear_light_weighted_by_alpha():
    from treegen_cli.render_gl import mip_chain

    rng = np.random.default_rng(0)
    rgba = np.zeros((128, 96, 4), np.uint8)
    rgba[..., :3] = (40, 90, 20)
    rgba[..., 3] = np.where(rng.random((128, 96)) < 0.3, 255, 0)
    rgba[rgba[..., 3] == 0, :3] = 0  # black where transparent: no fringe
    levels = mip_chain(rgba, True)
    assert [lv.shape[:2] for lv in levels] == [
        (128, 96),
        (64, 48),
        (32, 24),
        (16, 12),
        (8, 6),
        (4, 3),
        (2, 1),
        (1, 1),
    ]  # GL: floor(n / 2)
    odd = mip_chain(np.zeros((45, 63, 3), np.uint8), False)
    assert [lv.shape[:2] for lv in odd] == [(45, 63), (22, 31), (11, 15), (5, 7), (2, 3), (1, 1)]
    # alpha is the plain mean (coverage); colour the mean of the opaque texels only
    assert abs(levels[3][..., 3].mean() / 255 - (rgba[..., 3] > 0).mean()) < 0.01
    assert np.abs(levels[3][..., :3].astype(int) - (40, 90, 20)).max() <= 1
    # sRGB is averaged as light: black and white make 0.5 linear = 188 in sRGB, not 128
    bw = np.zeros((2, 2, 3), np.uint8)
    bw[0] = 255
    assert mip_chain(bw, True)[1][0, 0, 0] == 188 and mip_chain(bw, False)[1][0, 0, 0] == 128


@needs_egl
def test_tiny_cut_out_leaves_keep_their_share_of_coverage(monkeypatch):
    """Leaves far smaller than a pixel: a fixed cutoff on their blurred alpha keeps all or none
    of them; the hashed test keeps about the blade's share of the card."""
    from treegen_cli import render
    from treegen_cli.drawable import Part

    rgba, uv = _leaf_rgba(128)
    n = 60  # 60 × 60 cards of 1.5 × 3 cm in 2 m
    gx, gy = np.meshgrid(np.linspace(-1, 1, n), np.linspace(0.1, 2.1, n))
    corner = np.float32([[-0.0075, 0], [0.0075, 0], [0.0075, 0.03], [-0.0075, 0.03]])
    pos = np.zeros((n * n, 4, 3), np.float32)
    pos[..., :2] = np.stack([gx, gy], -1).reshape(-1, 1, 2) + corner
    idx = (np.uint32([0, 1, 2, 0, 2, 3]) + 4 * np.arange(n * n, dtype=np.uint32)[:, None]).ravel()
    V = 4 * n * n

    def field(**material):
        return Part(
            name="leaves",
            positions=pos.reshape(-1, 3),
            indices=idx,
            normals=np.tile(np.float32([0, 0, 1]), (V, 1)),
            joints=np.zeros((V, 4), np.int64),
            weights=np.tile(np.float32([1, 0, 0, 0]), (V, 1)),
            uvs=np.tile(uv, (n * n, 1)),
            double_sided=True,
            **material,
        )

    def darkening(part):
        t, b = _shoot(part, size=64)
        return np.abs(t.astype(float) - b.astype(float)).sum(-1).mean()

    flat = darkening(field(color=(0.16, 0.30, 0.06)))  # the atlas's mean colour
    cut = dict(color=(1, 1, 1), texture=rgba, alpha_cutoff=0.5, wrap=("CLAMP", "CLAMP"))
    hashed = darkening(field(**cut))
    blade = float((rgba[..., 3] >= 128).mean()) / float(np.prod(np.ptp(uv, 0)))  # ≈ π/4
    assert 0.5 * blade < hashed / flat < 1.3 * blade
    monkeypatch.setattr(render, "HASH_LOD", 99.0)  # a fixed cutoff all the way down
    assert abs(darkening(field(**cut)) / flat - blade) > abs(hashed / flat - blade)


def _tiny_asset(material, uvs):
    """A one-card Asset (one joint) with `material` on it."""
    from treegen_cli.asset import Asset, Lod, Primitive, Skeleton

    pos = np.float32([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 2], [-0.5, 0, 2]])  # Z up, faces −Y
    prim = Primitive(
        name="leaves",
        material=material.name,
        positions=pos,
        normals=np.tile(np.float32([0, -1, 0]), (4, 1)),
        uvs=np.float32(uvs),
        indices=np.uint32([0, 1, 2, 0, 2, 3]),
        joints=np.zeros((4, 4), np.uint16),
        weights=np.tile(np.float32([1, 0, 0, 0]), (4, 1)),
    )
    sk = Skeleton(
        names=["j0"],
        parent=np.int32([-1]),
        rest_translation=np.zeros((1, 3)),
        rest_rotation=np.float64([[0, 0, 0, 1]]),
        bind_world=np.eye(4)[None],
    )
    return Asset(name="card", materials=[material], lods=[Lod([prim], sk)])


@needs_egl
def test_asset_textures_decode_into_parts_and_render_deterministically():
    from treegen_cli.asset import Material, Texture
    from treegen_cli.texture_png import png_bytes

    rgba, uv = _leaf_rgba()
    mat = Material(
        "leaf",
        (1, 1, 1, 1),
        double_sided=True,
        alpha_cutoff=0.5,
        base_texture=Texture("leaf", png_bytes(rgba), wrap="CLAMP"),
    )
    scene = scene_from_asset(_tiny_asset(mat, uv))
    part = scene.parts[0]
    assert part.textured and np.array_equal(part.texture, rgba)
    assert np.allclose(part.uvs, uv) and part.alpha_cutoff == 0.5
    assert part.wrap == ("CLAMP", "CLAMP") and part.normal_map is None
    options = PreviewOptions(width=64, height=64)
    from treegen_cli.preview import render_still

    a, b = render_still(scene, options), render_still(scene_from_asset(_tiny_asset(mat, uv)), options)
    assert np.array_equal(a, b)


def _glb(doc: dict, blob: bytes) -> bytes:
    """A GLB container around a JSON document and its binary chunk (both padded to 4)."""
    import struct

    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    return (
        struct.pack("<4sII", b"glTF", 2, total)
        + struct.pack("<I4s", len(js), b"JSON")
        + js
        + struct.pack("<I4s", len(blob), b"BIN\0")
        + blob
    )


def _textured_gltf(rgba, uv_bl, normal, interleaved=False, image_uri=None):
    """(JSON, binary) of a one-card glTF with a MASK leaf material, written by hand to the glTF
    2.0 spec the way other exporters do: TEXCOORD_0 as normalized shorts (glTF's v down), or
    interleaved floats (byteStride); images in bufferViews or behind a URI."""
    from treegen_cli.texture_png import png_bytes

    pos = np.float32([[-0.5, 0, 0], [0.5, 0, 0], [0.5, 2, 0], [-0.5, 2, 0]])
    uv = np.column_stack([uv_bl[:, 0], 1.0 - uv_bl[:, 1]])  # glTF: origin top-left
    chunks, views, accessors = [], [], []

    def view(data: bytes, **extra) -> int:
        off = sum(len(c) for c in chunks)
        chunks.append(data + b"\0" * (-len(data) % 4))
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(data), **extra})
        return len(views) - 1

    if interleaved:
        v = view(np.hstack([pos, uv.astype(np.float32)]).astype("<f4").tobytes(), byteStride=20)
        accessors += [
            {
                "bufferView": v,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [-0.5, 0, 0],
                "max": [0.5, 2, 0],
            },
            {"bufferView": v, "byteOffset": 12, "componentType": 5126, "count": 4, "type": "VEC2"},
        ]
    else:
        accessors += [
            {
                "bufferView": view(pos.tobytes()),
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [-0.5, 0, 0],
                "max": [0.5, 2, 0],
            },
            {
                "bufferView": view(np.round(uv * 65535).astype("<u2").tobytes()),
                "componentType": 5123,
                "normalized": True,
                "count": 4,
                "type": "VEC2",
            },
        ]
    accessors.append(
        {
            "bufferView": view(np.uint16([0, 1, 2, 0, 2, 3]).tobytes()),
            "componentType": 5123,
            "count": 6,
            "type": "SCALAR",
        }
    )
    images = [
        {"uri": image_uri} if image_uri else {"bufferView": view(png_bytes(rgba)), "mimeType": "image/png"},
        {"bufferView": view(png_bytes(normal)), "mimeType": "image/png"},
    ]
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}
        ],
        "materials": [
            {
                "name": "leaf",
                "doubleSided": True,
                "alphaMode": "MASK",
                "alphaCutoff": 0.4,
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
                "normalTexture": {"index": 1, "scale": 0.7},
            }
        ],
        "samplers": [{"wrapS": 33071, "wrapT": 33071}, {"wrapS": 33648}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1, "sampler": 1}],
        "images": images,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": sum(len(c) for c in chunks)}],
    }
    return doc, b"".join(chunks)


def test_gltf_reader_reads_uvs_textures_and_cut_out_of_a_hand_built_file(tmp_path):
    rgba, uv = _leaf_rgba(64)
    normal = np.zeros((8, 8, 3), np.uint8)
    normal[...] = (128, 128, 255)
    normal[0, 0] = (200, 90, 220)  # not symmetric: orientation shows
    doc, blob = _textured_gltf(rgba, uv, normal)
    (tmp_path / "card.glb").write_bytes(_glb(doc, blob))
    # the same card as .gltf + .bin, floats interleaved with positions, the atlas a PNG file
    from treegen_cli.texture_png import png_bytes

    doc2, blob2 = _textured_gltf(rgba, uv, normal, interleaved=True, image_uri="leaf%20atlas.png")
    doc2["buffers"][0]["uri"] = "card.bin"
    (tmp_path / "card.bin").write_bytes(blob2)
    (tmp_path / "leaf atlas.png").write_bytes(png_bytes(rgba))
    (tmp_path / "card.gltf").write_text(json.dumps(doc2))

    for name, tol in (("card.glb", 1e-4), ("card.gltf", 1e-6)):
        part = scene_from_gltf(tmp_path / name).parts[0]
        assert np.allclose(part.uvs, uv, atol=tol), name  # back to bottom-left
        assert np.array_equal(part.texture, rgba) and np.array_equal(part.normal_map, normal)
        assert part.alpha_cutoff == pytest.approx(0.4) and part.double_sided
        assert part.wrap == ("CLAMP", "CLAMP") and part.normal_wrap == ("MIRROR", "REPEAT")
        assert part.normal_scale == pytest.approx(0.7) and part.color == (1.0, 1.0, 1.0)

    (tmp_path / "leaf atlas.png").unlink()
    with pytest.raises(TreegenError, match="not found"):
        scene_from_gltf(tmp_path / "card.gltf")


@needs_egl
def test_preview_of_a_textured_glb_shows_the_cut_out(tmp_path, capsys):
    rgba, uv = _leaf_rgba(64)
    doc, blob = _textured_gltf(rgba, uv, np.full((4, 4, 3), (128, 128, 255), np.uint8))
    (tmp_path / "cut.glb").write_bytes(_glb(doc, blob))
    doc["materials"][0]["alphaMode"] = "OPAQUE"
    (tmp_path / "full.glb").write_bytes(_glb(doc, blob))
    covered = {}
    for name in ("cut", "full"):
        code, out, err = run(
            [
                "preview",
                tmp_path / f"{name}.glb",
                "-o",
                tmp_path / f"{name}.png",
                "--size",
                "64",
                "--elevation",
                "0",
            ],
            capsys,
        )
        assert code == 0, err
        img = _rgb(tmp_path / f"{name}.png").astype(int)
        covered[name] = (img[..., 1] > img[..., 2] + 45).sum()  # leaf green, not sky or ground
    assert 0.3 * covered["full"] < covered["cut"] < 0.85 * covered["full"]


def _textured_usd(path, rgba, uv_bl, normal, face_varying=False):
    """A one-card UsdSkel stage with a UsdPreviewSurface leaf written by hand to the spec:
    diffuseColor and opacity from one UsdUVTexture (rgb, a), opacityThreshold, a normal map
    (scale 2, bias −1), st through a UsdPrimvarReader_float2 whose varname comes from a
    material interface input; textures in textures/ beside the layer."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

    from treegen_cli.texture_png import png_bytes

    (path.parent / "textures").mkdir(exist_ok=True)
    (path.parent / "textures" / "leaf.png").write_bytes(png_bytes(rgba))
    (path.parent / "textures" / "leaf_normal.png").write_bytes(png_bytes(normal))
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdSkel.Root.Define(stage, "/Card")
    skel = UsdSkel.Skeleton.Define(stage, "/Card/Skel")
    skel.CreateJointsAttr(["j0"])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    mesh = UsdGeom.Mesh.Define(stage, "/Card/Mesh")
    mesh.CreatePointsAttr([(-0.5, 0, 0), (0.5, 0, 0), (0.5, 2, 0), (-0.5, 2, 0)])
    mesh.CreateFaceVertexCountsAttr([4])
    order = [1, 2, 3, 0] if face_varying else [0, 1, 2, 3]  # corners ≠ points
    mesh.CreateFaceVertexIndicesAttr(order)
    mesh.CreateDoubleSidedAttr(True)
    interp = UsdGeom.Tokens.faceVarying if face_varying else UsdGeom.Tokens.vertex
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("uvmap", Sdf.ValueTypeNames.TexCoord2fArray, interp)
    st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uv_bl[order], np.float32)))
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(True, 1).Set([0])
    binding.CreateJointWeightsPrimvar(True, 1).Set([1.0])
    UsdSkel.BindingAPI.Apply(root.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])

    mat = UsdShade.Material.Define(stage, "/Card/Looks/leaf")
    var = mat.CreateInput("frame:stPrimvarName", Sdf.ValueTypeNames.Token)
    var.Set("uvmap")
    surf = UsdShade.Shader.Define(stage, "/Card/Looks/leaf/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.4)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    reader = UsdShade.Shader.Define(stage, "/Card/Looks/leaf/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).ConnectToSource(var)
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    for name, file, outputs in (
        ("tex", "leaf.png", (("rgb", "diffuseColor"), ("a", "opacity"))),
        ("nrm", "leaf_normal.png", (("rgb", "normal"),)),
    ):
        t = UsdShade.Shader.Define(stage, f"/Card/Looks/leaf/{name}")
        t.CreateIdAttr("UsdUVTexture")
        t.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./textures/{file}")
        t.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        t.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp" if name == "tex" else "mirror")
        if name == "nrm":
            t.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(1.4, 1.4, 1.4, 1))
            t.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(-0.7, -0.7, -0.7, 0))
            t.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        for out, inp in outputs:
            kind = (
                Sdf.ValueTypeNames.Float
                if out == "a"
                else (Sdf.ValueTypeNames.Normal3f if inp == "normal" else Sdf.ValueTypeNames.Color3f)
            )
            o = t.CreateOutput(out, Sdf.ValueTypeNames.Float if out == "a" else Sdf.ValueTypeNames.Float3)
            surf.CreateInput(inp, kind).ConnectToSource(o)
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()


def test_usd_reader_reads_st_and_preview_surface_textures(tmp_path):
    from pxr import UsdUtils

    rgba, uv = _leaf_rgba(64)
    normal = np.zeros((8, 8, 3), np.uint8)
    normal[...] = (128, 128, 255)
    normal[0, 0] = (200, 90, 220)
    _textured_usd(tmp_path / "card.usda", rgba, uv, normal)
    (tmp_path / "fv").mkdir()
    _textured_usd(tmp_path / "fv" / "card.usda", rgba, uv, normal, face_varying=True)
    assert UsdUtils.CreateNewUsdzPackage(str(tmp_path / "card.usda"), str(tmp_path / "card.usdz"))
    for f in ("card.usda", "fv/card.usda", "card.usdz"):
        part = scene_from_usd(tmp_path / f).parts[0]
        assert len(part.indices) == 6
        # each drawn corner carries the UV of its point (points: x = ±0.5, y = 0 or 2)
        p = part.positions[part.indices]
        point = (p[:, 0] > 0).astype(int) + 2 * (p[:, 1] > 1) * 1
        want = uv[np.array([0, 1, 3, 2])[point]]
        assert np.allclose(part.uvs[part.indices], want), f
        assert np.array_equal(part.texture, rgba) and np.array_equal(part.normal_map, normal)
        assert part.alpha_cutoff == pytest.approx(0.4) and part.double_sided
        assert part.wrap == ("CLAMP", "REPEAT") and part.normal_wrap == ("MIRROR", "REPEAT")
        assert part.normal_scale == pytest.approx(0.7) and part.color == (1.0, 1.0, 1.0)
    (tmp_path / "textures" / "leaf.png").unlink()
    with pytest.raises(TreegenError, match="not found"):
        scene_from_usd(tmp_path / "card.usda")
    assert scene_from_usd(tmp_path / "card.usdz").parts[0].textured  # packaged: still there


def test_only_treegens_own_forest_mark_makes_a_forest():
    """Another tool's glTF with several skinned roots (a body and its clothes) previews as
    before; a treegen forest file says so in its asset extras."""
    from treegen_cli.exchange.read_gltf import forest_instances

    nodes = [{"mesh": 0, "skin": 0}, {"mesh": 1, "skin": 0}]
    two_skinned = {"asset": {"version": "2.0"}, "nodes": nodes, "scenes": [{"nodes": [0, 1]}]}
    assert forest_instances(two_skinned) == 0
    marked = {**two_skinned, "asset": {"version": "2.0", "extras": {"forest": "f", "instances": 2}}}
    assert forest_instances(marked) == 2
