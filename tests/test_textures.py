"""Generated leaf atlas and bark textures: coverage, layout, UVs, tiling, normals, PNG bytes."""

from __future__ import annotations

import hashlib
import io
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from treegen_cli import texture_bark as B, texture_color as C, texture_leaf as L, texture_png as P
from treegen_cli import textures as T
from treegen_cli.errors import TreegenError
from treegen_cli.leafshapes import OUTLINES, fill_factor, outline
from treegen_cli.params import default_params

GREEN = (0.16, 0.30, 0.06)
BARK = (0.13, 0.09, 0.06)


@pytest.fixture(scope="module")
def atlases():
    """One 256² atlas per LeafShape (aspects as the shipped species use them)."""
    aspect = {1: 0.2, 5: 1.0, 6: 0.06, 7: 1.0}
    return {s: L.leaf_atlas(s, GREEN, size=256, seed=3, aspect=aspect.get(s, 0.5)) for s in OUTLINES}


@pytest.fixture(scope="module")
def bark():
    return B.bark_textures(BARK, size=128, seed=5)


def cell_pixels(atlas, k):
    """Texel bounds (x0, y0, x1, y1) of variant k's card rectangle."""
    h, w = atlas.rgba.shape[:2]
    u0, v0, u1, v1 = atlas.rects[k]
    return (int(round(u0 * w)), int(round(v0 * h)), int(round(u1 * w)), int(round(v1 * h)))


def outline_centroid(shape):
    """Area-weighted centroid of the outline's triangles in card UVs (u = x + .5, v = y)."""
    o = outline(shape)
    tri = o.uvs[o.triangles]  # (T, 3, 2)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    a = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return (tri.mean(axis=1) * a[:, None]).sum(axis=0) / a.sum()


# ------------------------------------------------------------------------------ leaf atlas


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_alpha_coverage_matches_fill_factor(atlases, shape):
    at = atlases[shape]
    for k in range(at.variants):
        x0, y0, x1, y1 = cell_pixels(at, k)
        cov = at.rgba[y0:y1, x0:x1, 3].astype(np.float64).mean() / 255.0
        assert cov == pytest.approx(fill_factor(shape), abs=0.02)


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_alpha_lies_only_inside_the_card_rectangles(atlases, shape):
    at = atlases[shape]
    inside = np.zeros(at.rgba.shape[:2], dtype=bool)
    for k in range(at.variants):
        x0, y0, x1, y1 = cell_pixels(at, k)
        inside[y0:y1, x0:x1] = True
    assert not at.rgba[..., 3][~inside].any()


@pytest.mark.parametrize("shape", sorted(OUTLINES))
def test_outline_centroid_maps_onto_the_blade(atlases, shape):
    """The outline's centroid through card_uvs lands in its cell, on opaque texels, and the
    alpha-weighted centre of the cell is there too (catches a flipped v: triangles, stars)."""
    at = atlases[shape]
    h, w = at.rgba.shape[:2]
    c = outline_centroid(shape)
    for k in range(at.variants):
        uv = L.card_uvs(c[None, :], np.array([k]), at)[0]
        u0, v0, u1, v1 = at.rects[k]
        assert u0 < uv[0] < u1 and v0 < uv[1] < v1
        x0, y0, x1, y1 = cell_pixels(at, k)
        a = at.rgba[y0:y1, x0:x1, 3].astype(np.float64)
        assert at.rgba[int(uv[1] * h), int(uv[0] * w), 3] > 200  # on the blade
        ys, xs = np.mgrid[y0:y1, x0:x1] + 0.5
        cu, cv = (a * xs).sum() / a.sum() / w, (a * ys).sum() / a.sum() / h
        assert cu == pytest.approx(uv[0], abs=1.5 / w)
        assert cv == pytest.approx(uv[1], abs=1.5 / h)


@pytest.mark.parametrize("variants", [1, 2, 3, 4, 6, 9])
def test_rects_inside_unit_square_padded_and_disjoint(variants):
    at = L.leaf_atlas(0, GREEN, size=256, variants=variants)
    r = at.rects.astype(np.float64)
    assert r.shape == (variants, 4)
    assert np.all(r >= 0) and np.all(r <= 1)
    assert np.all(r[:, 0] < r[:, 2]) and np.all(r[:, 1] < r[:, 3])
    assert np.all(r[:, :2] * 256 >= 2) and np.all(r[:, 2:] * 256 <= 254)  # padded from edges
    for i in range(variants):
        for j in range(i + 1, variants):
            gap_u = max(r[j, 0] - r[i, 2], r[i, 0] - r[j, 2])
            gap_v = max(r[j, 1] - r[i, 3], r[i, 1] - r[j, 3])
            assert max(gap_u, gap_v) * 256 >= 4  # two padding bands between cards


def test_card_uvs_map_card_corners_to_rect_corners(atlases):
    at = atlases[0]
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.float32)
    for k in range(at.variants):
        u0, v0, u1, v1 = at.rects[k]
        got = L.card_uvs(corners, np.full(4, k), at)
        assert got.dtype == np.float32 and got.shape == (4, 2)
        # base (v_card = 0) at the bottom edge v1, tip (v_card = 1) at the top edge v0
        np.testing.assert_allclose(got, [[u0, v1], [u1, v1], [u0, v0], [u1, v0]], atol=1e-7)


def test_card_uvs_in_the_asset_convention_round_trip_through_the_gltf_flip(atlases):
    """Primitive.uvs are bottom-left; exchange/gltf_mesh.py writes 1 − v. The texels sampled must be
    the ones atlas.rects name in glTF UVs."""
    at = atlases[1]
    rng = np.random.default_rng(1)
    uv = rng.uniform(0, 1, (200, 2)).astype(np.float32)
    var = rng.integers(0, at.variants, 200)
    gltf = L.card_uvs(uv, var, at)
    asset = L.card_uvs(uv, var, at, origin="bottom-left")
    flipped = np.float32(1.0) - asset[:, 1]  # what gltf_mesh.py writes
    np.testing.assert_allclose(flipped, gltf[:, 1], atol=1e-6)
    np.testing.assert_array_equal(asset[:, 0], gltf[:, 0])
    with pytest.raises(ValueError):
        L.card_uvs(uv, var, at, origin="centre")


def test_card_uvs_vectorised_over_mixed_variants(atlases):
    at = atlases[3]
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 1, (1000, 2))
    var = rng.integers(0, at.variants, 1000)
    got = L.card_uvs(uv, var, at)
    r = at.rects[var]
    assert np.all((got[:, 0] >= r[:, 0] - 1e-6) & (got[:, 0] <= r[:, 2] + 1e-6))
    assert np.all((got[:, 1] >= r[:, 1] - 1e-6) & (got[:, 1] <= r[:, 3] + 1e-6))


def test_card_uvs_on_the_mesh_card_uvs():
    """mesh/leaves.py's cards carry the outline's uvs; mapped, every vertex stays in its cell."""
    from treegen_cli.mesh import CARD

    at = L.leaf_atlas(2, GREEN, size=128)
    uv = np.tile(CARD.uvs, (3, 1))
    var = np.repeat([0, 1, 3], len(CARD.uvs))
    got = L.card_uvs(uv, var, at)
    assert np.allclose(got[0], [at.rects[0, 0], at.rects[0, 3]])  # first CARD point: base left


def rgb_key(px):
    """One integer per texel colour, for set membership."""
    px = px[..., :3].astype(np.int64)
    return px[..., 0] << 16 | px[..., 1] << 8 | px[..., 2]


def test_transparent_texels_carry_blade_colour(atlases):
    """Colour dilation: every alpha-0 texel repeats the colour of a solid texel of its own cell,
    so bilinear and mip filtering never pull in black or white."""
    for shape, at in atlases.items():
        w = at.rgba.shape[1]
        cw = w // 2  # 4 variants: a 2 × 2 grid
        for k in range(at.variants):
            x0, y0, x1, y1 = cell_pixels(at, k)
            pad = x0 % cw
            cell = at.rgba[y0 - pad : y1 + pad, x0 - pad : x1 + pad]
            solid = cell[..., 3] >= 128
            clear = cell[..., 3] == 0
            assert clear.any() or shape == 4
            assert np.isin(rgb_key(cell[clear]), rgb_key(cell[solid])).all()
    # and nothing dark anywhere: the padding round the card is leaf colour too
    lin = C.srgb8_to_linear(atlases[0].rgba[..., :3])
    assert lin.min() > 0.25 * min(GREEN)


def test_blade_mean_colour_is_the_colour_given(atlases):
    for shape, at in atlases.items():
        solid = at.rgba[..., 3] >= 128
        mean = C.srgb8_to_linear(at.rgba[..., :3][solid]).mean(axis=0)
        np.testing.assert_allclose(mean, GREEN, rtol=0.04)


def test_variants_differ_and_carry_veins(atlases):
    for shape in (0, 4, 7):
        at = atlases[shape]
        cells = []
        for k in range(at.variants):
            x0, y0, x1, y1 = cell_pixels(at, k)
            cells.append(C.srgb8_to_linear(at.rgba[y0:y1, x0:x1, :3]))
        means = np.array([c[at.rgba[y0:y1, x0:x1, 3] >= 128].mean(axis=0) for c in cells])
        assert np.ptp(means, axis=0).max() > 0.005  # colour jitter between variants
        lum = cells[0][..., 1][at.rgba[y0:y1, x0:x1, 3] >= 128]
        assert lum.std() > 0.03 * lum.mean()  # not a flat fill (veins, shading)


def test_midrib_is_lighter_than_the_blade_beside_it():
    at = L.leaf_atlas(4, GREEN, size=256, variants=1)
    x0, y0, x1, y1 = cell_pixels(at, 0)
    g = C.srgb8_to_linear(at.rgba[y0:y1, x0:x1, 1])
    mid = (x1 - x0) // 2
    rows = slice((y1 - y0) // 4, (y1 - y0) // 2)
    assert g[rows, mid - 1 : mid + 1].mean() > 1.1 * g[rows, mid - 25 : mid - 15].mean()


def test_square_leaf_is_a_full_card():
    at = L.leaf_atlas(4, GREEN, size=128)
    x0, y0, x1, y1 = cell_pixels(at, 0)
    assert (at.rgba[y0:y1, x0:x1, 3] == 255).all()


def test_atlas_size_not_a_multiple_of_the_grid():
    at = L.leaf_atlas(0, GREEN, size=200, variants=3)
    assert at.rgba.shape == (200, 200, 4)
    assert C.srgb8_to_linear(at.rgba[..., :3]).min() > 0.25 * min(GREEN)


def test_leaf_atlas_rejects_bad_input():
    with pytest.raises(TreegenError):
        L.leaf_atlas(8, GREEN)
    with pytest.raises(ValueError):
        L.leaf_atlas(0, (1.2, 0.5, 0.1))
    with pytest.raises(ValueError):
        L.leaf_atlas(0, GREEN, variants=0)
    with pytest.raises(ValueError):
        L.leaf_atlas(0, GREEN, size=16, variants=16)


# ------------------------------------------------------------------------------ bark


def seam_stats(img, axis):
    """(wrap-around seam difference, median and max of the interior neighbour differences),
    each a mean |difference| over one pair of adjacent lines across `axis`."""
    a = np.moveaxis(img.astype(np.float64), axis, 0)
    pairs = np.abs(np.diff(a, axis=0)).reshape(a.shape[0] - 1, -1).mean(axis=1)
    return np.abs(a[0] - a[-1]).mean(), np.median(pairs), pairs.max()


def tiles(img, axis):
    """The seam pair looks like any interior pair: within the interior's range (a periodic
    texture's seam is just one more pair, so allow it to be the largest by a little) and
    not far above the typical pair."""
    seam, median, most = seam_stats(img, axis)
    return seam <= 1.15 * most and seam <= 2.5 * median


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bark_albedo_and_normal_tile_in_both_directions(seed):
    for img in B.bark_textures(BARK, size=128, seed=seed):
        assert tiles(img, 0) and tiles(img, 1)


@pytest.mark.parametrize("furrow", [0.0, 0.3])
def test_smooth_bark_tiles_and_is_smoother(furrow):
    for img in B.bark_textures(BARK, size=128, seed=0, furrow=furrow):
        assert tiles(img, 0) and tiles(img, 1)
    rough = np.abs(np.diff(B.bark_height(128, 0, 1.0), axis=1)).mean()
    assert np.abs(np.diff(B.bark_height(128, 0, furrow), axis=1)).mean() < 0.8 * rough
    with pytest.raises(ValueError):
        B.bark_textures(BARK, furrow=1.5)


def test_tiling_check_catches_a_texture_that_does_not_tile():
    """Control: a corner crop of a bigger bark is not periodic and the check says so."""
    albedo, normal = B.bark_textures(BARK, size=256, seed=0)
    assert not tiles(albedo[:128, :128], 0)
    assert not tiles(normal[:128, :128], 0)


def test_bark_tiles_at_512_too():
    """512 runs the Voronoi pass at half resolution and upsamples it on the torus."""
    for img in B.bark_textures(BARK, size=512, seed=0):
        assert tiles(img, 0) and tiles(img, 1)


def test_bark_furrows_run_along_v():
    """Bark runs along the stem: the height changes faster across (u) than along (v)."""
    h = B.bark_height(256, seed=1).astype(np.float64)
    across = np.abs(np.diff(h, axis=1)).mean()
    along = np.abs(np.diff(h, axis=0)).mean()
    assert across > 1.3 * along


def test_normal_map_decodes_to_unit_vectors_facing_out(bark):
    n = bark[1].astype(np.float64) / 127.5 - 1.0
    length = np.linalg.norm(n, axis=-1)
    assert np.abs(length - 1.0).max() < 0.02
    assert n[..., 2].min() > 0.0
    assert n[..., 2].mean() > 0.8  # mostly facing out, not noise


def test_normal_map_is_opengl_convention():
    """glTF: R = +X right (u), G = +Y up (toward row 0). A texel whose height rises to the right
    tilts left (R < 128); one whose height rises toward the top row tilts down (G < 128)."""
    size, seed = 128, 2
    h = B.bark_height(size, seed).astype(np.float64)
    _, nm = B.bark_textures(BARK, size, seed)
    n = nm.astype(np.float64) / 127.5 - 1.0
    dh_right = np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)
    dh_up = np.roll(h, 1, axis=0) - np.roll(h, -1, axis=0)
    assert np.corrcoef(n[..., 0].ravel(), -dh_right.ravel())[0, 1] > 0.95
    assert np.corrcoef(n[..., 1].ravel(), -dh_up.ravel())[0, 1] > 0.95


def test_bark_albedo_mean_is_the_tint_and_furrows_are_dark():
    size = 128
    albedo, _ = B.bark_textures(BARK, size, seed=4)
    lin = C.srgb8_to_linear(albedo)
    np.testing.assert_allclose(lin.reshape(-1, 3).mean(axis=0), BARK, rtol=0.03)
    h = B.bark_height(size, seed=4)
    assert lin[h < 0.2].mean() < 0.6 * lin[h > 0.6].mean()


def test_bark_shapes_and_types(bark):
    albedo, normal = bark
    assert albedo.shape == normal.shape == (128, 128, 3)
    assert albedo.dtype == normal.dtype == np.uint8


def test_bark_same_pattern_at_every_resolution():
    """The noise is drawn per frequency, not per texel: 256² is the 512² picture, downsampled."""
    a = B.bark_height(256, seed=9).astype(np.float64)
    b = B.bark_height(512, seed=9).astype(np.float64)
    b = b.reshape(256, 2, 256, 2).mean(axis=(1, 3))
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.8


# ------------------------------------------------------------------------------ PNG bytes


def test_png_bytes_deterministic_and_seeded():
    a1 = P.png_bytes(L.leaf_atlas(0, GREEN, 128, seed=1).rgba)
    a2 = P.png_bytes(L.leaf_atlas(0, GREEN, 128, seed=1).rgba)
    a3 = P.png_bytes(L.leaf_atlas(0, GREEN, 128, seed=2).rgba)
    assert a1 == a2 and a1 != a3
    b1 = [P.png_bytes(x) for x in B.bark_textures(BARK, 64, seed=1)]
    b2 = [P.png_bytes(x) for x in B.bark_textures(BARK, 64, seed=1)]
    b3 = [P.png_bytes(x) for x in B.bark_textures(BARK, 64, seed=2)]
    assert b1 == b2 and b1[0] != b3[0] and b1[1] != b3[1]


@pytest.mark.parametrize("channels,mode", [(3, "RGB"), (4, "RGBA")])
def test_png_bytes_round_trip_without_metadata(channels, mode):
    arr = np.random.default_rng(0).integers(0, 256, (17, 23, channels), dtype=np.uint8)
    data = P.png_bytes(arr)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    for chunk in (b"tEXt", b"zTXt", b"iTXt", b"tIME", b"pHYs", b"eXIf"):
        assert chunk not in data
    img = Image.open(io.BytesIO(data))
    assert img.mode == mode
    np.testing.assert_array_equal(np.asarray(img), arr)


def test_png_bytes_rejects_other_arrays():
    with pytest.raises(ValueError):
        P.png_bytes(np.zeros((4, 4), dtype=np.uint8))
    with pytest.raises(ValueError):
        P.png_bytes(np.zeros((4, 4, 3), dtype=np.float32))


# ------------------------------------------------------------------------------ colours


def test_species_colors_by_name_then_shape_then_default():
    leaf, bark = T.species_colors(replace(default_params("quaking_aspen"), leaf_shape=0))
    assert leaf == T.DEFAULT_LEAF_COLOR["quaking_aspen"]
    assert bark == T.DEFAULT_BARK_COLOR["quaking_aspen"]
    leaf, bark = T.species_colors(replace(default_params("my tree"), leaf_shape=1))
    assert leaf == T.DEFAULT_LEAF_COLOR[1]
    assert bark == T.DEFAULT_BARK_COLOR["default"]


def test_default_colours_are_valid_linear_rgb():
    for table in (T.DEFAULT_LEAF_COLOR, T.DEFAULT_BARK_COLOR):
        for c in table.values():
            assert len(c) == 3 and all(0.0 <= x <= 1.0 for x in c)
    for s in OUTLINES:
        assert s in T.DEFAULT_LEAF_COLOR


def test_species_textures_bundle():
    p = replace(default_params("weeping_willow"), leaf_shape=0, leaf_scale_x=0.2)
    tex = T.species_textures(p, seed=1, leaf_size=128, bark_size=64, variants=2)
    assert tex.leaf.variants == 2 and tex.leaf.rgba.shape == (128, 128, 4)
    assert tex.bark_albedo.shape == tex.bark_normal.shape == (64, 64, 3)
    pngs = tex.pngs()
    assert set(pngs) == {"leaf", "bark", "bark_normal"}
    assert pngs == T.species_textures(p, seed=1, leaf_size=128, bark_size=64, variants=2).pngs()
    solid = tex.leaf.rgba[..., 3] >= 128
    np.testing.assert_allclose(
        C.srgb8_to_linear(tex.leaf.rgba[..., :3][solid]).mean(axis=0),
        T.DEFAULT_LEAF_COLOR["weeping_willow"],
        rtol=0.04,
    )


def test_png_bytes_identical_in_a_fresh_interpreter():
    """Same bytes from another process (other hash seed, fresh imports): nothing depends on
    interpreter state."""
    code = (
        "import hashlib\n"
        "from treegen_cli import textures as T\n"
        "from treegen_cli.params import default_params\n"
        "t = T.species_textures(default_params('oak'), 3, 128, 64)\n"
        "print(hashlib.sha256(b''.join(t.pngs().values())).hexdigest())\n"
    )
    env = dict(os.environ, PYTHONHASHSEED="12345")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.strip()
    here = T.species_textures(default_params("oak"), 3, 128, 64)
    assert out == hashlib.sha256(b"".join(here.pngs().values())).hexdigest()


@pytest.mark.parametrize("variants,size", [(1, 64), (4, 512), (4, 500), (5, 256), (9, 300)])
def test_atlas_rects_is_the_layout_leaf_atlas_draws(variants, size):
    """The layout alone (for UV mapping before the pixels exist) is exactly the atlas's."""
    np.testing.assert_array_equal(
        L.atlas_rects(variants, size), L.leaf_atlas(0, GREEN, size, variants, seed=1).rects
    )
