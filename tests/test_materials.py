"""Materials stage: generated textures, colour-only materials, an artist's PNGs, the leaf atlas
layout the mesh maps leaves into, and the CLI flags."""

from __future__ import annotations

import dataclasses
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from treegen_cli.errors import TreegenError
from treegen_cli.materials import (
    ALPHA_CUTOFF,
    LEAF_VARIANTS,
    MATERIAL_DEFAULTS,
    MaterialOptions,
    build_materials,
)
from treegen_cli.mesh import FULL_CARD_CELL
from treegen_cli.params import load_params, parse_params_text
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.texture_color import srgb8_to_linear
from treegen_cli.texture_leaf import atlas_rects
from treegen_cli.textures import species_colors

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ROOT / "species"
PALM = SPECIES / "fan_palm.txt"  # 28 stems, 2,160 leaves: quick to grow
QUICK = MakeOptions(wind=None, lod=None)


def species(name):
    return load_params(SPECIES / f"{name}.txt")


def image(texture) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(texture.png)))


def write_png(path, size=(32, 64), mode="RGBA") -> Path:
    img = Image.new(mode, size, (200, 120, 40, 255)[: len(mode)])
    if "A" in mode:  # a leaf's cut-out: a transparent corner (an opaque leaf image is refused)
        img.putpixel((0, 0), (0,) * len(mode))
    img.save(path)
    return path


# ------------------------------------------------------------------------------ generated


@pytest.fixture(scope="module")
def aspen():
    return species("quaking_aspen")


def test_default_materials_are_textured_leaf_and_bark(aspen):
    m = build_materials(aspen)
    bark, leaf = m.materials
    assert (bark.name, leaf.name) == ("bark", "leaf")
    # Leaf: RGBA atlas, clamped, alpha-tested, double-sided, colour from the texture alone.
    assert leaf.base_color == (1.0, 1.0, 1.0, 1.0) and leaf.double_sided
    assert leaf.alpha_cutoff == ALPHA_CUTOFF
    t = leaf.base_texture
    assert (t.name, t.wrap, t.srgb) == ("leaf", "CLAMP", True)
    rgba = image(t)
    assert rgba.shape == (512, 512, 4) and 0 < rgba[..., 3].mean() < 255
    # Bark: albedo (sRGB) + normal map (raw data), both repeating, half the leaf size.
    assert bark.base_color == (1.0, 1.0, 1.0, 1.0) and not bark.double_sided
    assert bark.alpha_cutoff is None
    assert (bark.base_texture.name, bark.base_texture.wrap, bark.base_texture.srgb) == (
        "bark",
        "REPEAT",
        True,
    )
    n = bark.normal_texture
    assert (n.name, n.wrap, n.srgb) == ("bark_normal", "REPEAT", False)
    assert image(bark.base_texture).shape == image(n).shape == (256, 256, 3)
    sizes = [len(t.png) for t in (leaf.base_texture, bark.base_texture, n)]
    assert sum(sizes) < 600_000  # a few hundred KB per tree


def test_leaf_cells_are_the_drawn_atlas_layout(aspen):
    m = build_materials(aspen)
    assert m.leaf_cells == tuple(map(tuple, atlas_rects(LEAF_VARIANTS, 512).tolist()))
    assert len(m.leaf_cells) == LEAF_VARIANTS
    alpha = image(m.materials[1].base_texture)[..., 3]
    inside = np.zeros(alpha.shape, dtype=bool)
    for u0, v0, u1, v1 in m.leaf_cells:  # glTF UVs: row = v · H
        inside[round(v0 * 512) : round(v1 * 512), round(u0 * 512) : round(u1 * 512)] = True
        assert alpha[round(v0 * 512) : round(v1 * 512), round(u0 * 512) : round(u1 * 512)].any()
    assert not alpha[~inside].any()


def test_textures_are_deterministic_per_species_and_carry_its_colours(aspen):
    a = build_materials(aspen).materials
    b = build_materials(dataclasses.replace(aspen)).materials  # equal params, cached or not
    assert [m.base_texture.png for m in a] == [m.base_texture.png for m in b]
    # The species file's LeafColor is the blade's mean colour (opaque texels, linear light).
    leaf_rgb, bark_rgb = species_colors(aspen)
    assert leaf_rgb == pytest.approx(aspen.leaf_color)
    rgba = image(a[1].base_texture)
    blade = rgba[..., 3] == 255
    np.testing.assert_allclose(srgb8_to_linear(rgba[blade][:, :3]).mean(0), leaf_rgb, rtol=0.06)
    albedo = image(a[0].base_texture)
    np.testing.assert_allclose(srgb8_to_linear(albedo).reshape(-1, 3).mean(0), bark_rgb, rtol=0.06)
    # Another colour, another texture; another species, another atlas.
    red = dataclasses.replace(aspen, leaf_color=(0.5, 0.1, 0.1))
    assert build_materials(red).materials[1].base_texture.png != a[1].base_texture.png
    tupelo = build_materials(species("black_tupelo")).materials
    assert tupelo[1].base_texture.png != a[1].base_texture.png


def test_texture_size_scales_both_maps_and_is_checked(aspen):
    m = build_materials(aspen, MaterialOptions(texture_size=128)).materials
    assert image(m[1].base_texture).shape == (128, 128, 4)
    assert image(m[0].base_texture).shape == (64, 64, 3)
    for bad in (32, 100, 4096, 0, -64):
        with pytest.raises(TreegenError, match=rf"--texture-size {bad}: must be a power of two"):
            build_materials(aspen, MaterialOptions(texture_size=bad))


def test_no_textures_gives_colour_only_materials(aspen):
    m = build_materials(aspen, MaterialOptions(textures=False))
    bark, leaf = m.materials
    leaf_rgb, bark_rgb = species_colors(aspen)
    assert bark.base_color == (*bark_rgb, 1.0) and leaf.base_color == (*leaf_rgb, 1.0)
    assert all(x.base_texture is None and x.normal_texture is None for x in (bark, leaf))
    assert leaf.alpha_cutoff is None and leaf.double_sided
    assert m.leaf_cells == FULL_CARD_CELL


def test_leafless_species_gets_no_leaf_atlas():
    m = build_materials(species("shave_grass"))
    bark, leaf = m.materials
    assert bark.base_texture is not None and leaf.base_texture is None
    assert m.leaf_cells == FULL_CARD_CELL


# ------------------------------------------------------------------------------ artist's images


def test_custom_textures_are_embedded_as_they_are(aspen, tmp_path):
    leaf_png = write_png(tmp_path / "leaf.png", (48, 96))
    bark_png = write_png(tmp_path / "bark.png", (64, 64), "RGB")
    m = build_materials(aspen, MaterialOptions(leaf_texture=leaf_png, bark_texture=bark_png))
    bark, leaf = m.materials
    assert leaf.base_texture.png == leaf_png.read_bytes()
    assert bark.base_texture.png == bark_png.read_bytes()
    assert bark.normal_texture is None  # ours would not match their picture
    assert leaf.alpha_cutoff == ALPHA_CUTOFF and leaf.base_texture.wrap == "CLAMP"
    assert m.leaf_cells == FULL_CARD_CELL  # one leaf, the whole image
    # Only the bark replaced: the generated atlas stays, with its cells.
    only_bark = build_materials(aspen, MaterialOptions(bark_texture=bark_png))
    assert len(only_bark.leaf_cells) == LEAF_VARIANTS
    assert only_bark.materials[1].base_texture.png == build_materials(aspen).materials[1].base_texture.png


def test_bad_custom_textures_name_the_flag_and_the_file(aspen, tmp_path):
    good = write_png(tmp_path / "good.png")
    jpeg = tmp_path / "photo.png"
    Image.new("RGB", (8, 8)).save(jpeg, format="JPEG")
    cut = tmp_path / "cut.png"
    cut.write_bytes(write_png(tmp_path / "big.png", (256, 256), "RGB").read_bytes()[:200])
    fake = tmp_path / "fake.png"  # the PNG signature, then no IHDR: PIL cannot identify it
    fake.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\x0dABCD" + b"A" * 100)
    cases = [
        (tmp_path / "missing.png", "no such file"),
        (jpeg, "not a PNG image"),
        (cut, "not a readable PNG image"),
        (fake, "not a readable PNG image"),
        (tmp_path, "is a directory"),
    ]
    for flag, field in (("--leaf-texture", "leaf_texture"), ("--bark-texture", "bark_texture")):
        for path, why in cases:
            with pytest.raises(TreegenError) as info:
                build_materials(aspen, MaterialOptions(**{field: path}))
            msg = str(info.value)
            assert msg.startswith(f"{flag} {path}: ") and why in msg and "\n" not in msg
            assert " at 0x" not in msg and "BytesIO" not in msg  # no Python object reprs
        with pytest.raises(TreegenError, match=f"{flag} .*cannot be combined with --no-textures"):
            build_materials(aspen, MaterialOptions(textures=False, **{field: good}))


# ------------------------------------------------------------------------------ pipeline


def leaf_prim(asset, lod=0):
    return next(p for p in asset.lods[lod].primitives if p.name == "leaves")


def test_pipeline_maps_leaves_into_the_atlas_and_uses_the_materials():
    params = load_params(PALM)
    asset, tree = build_asset(params, 0, QUICK)
    assert [m.name for m in asset.materials] == ["bark", "leaf"]
    assert asset.materials[1].base_texture is not None
    cells = np.asarray(atlas_rects(LEAF_VARIANTS, 512), dtype=np.float64)
    uv = leaf_prim(asset).uvs.astype(np.float64).reshape(tree.n_leaves, -1, 2)
    lo = np.column_stack([cells[:, 0], 1 - cells[:, 3]])  # bottom-left cell bounds
    hi = np.column_stack([cells[:, 2], 1 - cells[:, 1]])
    inside = np.all(
        (uv[:, None] >= lo[None, :, None] - 1e-6) & (uv[:, None] <= hi[None, :, None] + 1e-6), axis=(2, 3)
    )
    assert np.all(inside.sum(axis=1) == 1)
    assert len(np.unique(inside.argmax(axis=1))) == LEAF_VARIANTS
    # Same seed, same file; the textures do not depend on the tree seed (shared by a forest).
    again, _ = build_asset(params, 0, QUICK)
    np.testing.assert_array_equal(leaf_prim(again).uvs, leaf_prim(asset).uvs)
    other, _ = build_asset(params, 5, QUICK)
    assert other.materials[1].base_texture == asset.materials[1].base_texture


def test_pipeline_without_textures_or_with_a_custom_leaf_maps_whole_cards(tmp_path):
    params = load_params(PALM)
    plain, tree = build_asset(
        params, 0, dataclasses.replace(QUICK, materials=MaterialOptions(textures=False))
    )
    assert all(m.base_texture is None for m in plain.materials)
    custom, _ = build_asset(
        params,
        0,
        dataclasses.replace(QUICK, materials=MaterialOptions(leaf_texture=write_png(tmp_path / "l.png"))),
    )
    for asset in (plain, custom):
        uv = leaf_prim(asset).uvs.reshape(tree.n_leaves, -1, 2)
        assert uv.min() == 0.0 and uv.max() == 1.0
        np.testing.assert_array_equal(uv, np.broadcast_to(uv[:1], uv.shape))


def test_species_file_leaf_colour_reaches_the_colour_only_material():
    text = PALM.read_text() + "\nLeafColor ff0000\n"
    params = parse_params_text(text, "red_palm.txt")
    m = build_materials(params, MaterialOptions(textures=False)).materials
    assert m[1].base_color == (1.0, 0.0, 0.0, 1.0)


# ------------------------------------------------------------------------------ CLI


def treegen(*args):
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT
    )


def test_cli_texture_flags(tmp_path):
    out = tmp_path / "palm.glb"
    fast = ["--no-wind", "--no-lod"]
    proc = treegen(
        "make",
        PALM,
        "-o",
        out,
        *fast,
        "--texture-size",
        "64",
        "--leaf-texture",
        write_png(tmp_path / "leaf.png"),
    )
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_size > 0
    proc = treegen("make", PALM, "-o", tmp_path / "plain.glb", *fast, "--no-textures")
    assert proc.returncode == 0, proc.stderr
    help_text = treegen("make", "--help").stdout
    for flag in ("--texture-size", "--leaf-texture", "--bark-texture", "--no-textures"):
        assert flag in help_text


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--leaf-texture", "nope.png"], ["--leaf-texture nope.png", "no such file"]),
        (
            ["--leaf-texture", "{opaque}"],
            ["opaque.png: no transparent texels (the lowest alpha is 255", "RGBA"],
        ),
        (["--bark-texture", "species/fan_palm.txt"], ["--bark-texture species/fan_palm.txt", "not a PNG"]),
        (["--texture-size", "300"], ["--texture-size 300", "power of two in [64, 2048]"]),
    ],
)
def test_cli_bad_texture_flags_exit_2_and_write_nothing(tmp_path_factory, tmp_path, args, needles):
    opaque = tmp_path_factory.mktemp("images") / "opaque.png"  # an RGBA leaf with no cut-out
    Image.new("RGBA", (8, 8), (40, 160, 40, 255)).save(opaque)
    args = [a.format(opaque=opaque) for a in args]
    out = tmp_path / "x.glb"
    proc = treegen("make", PALM, "-o", out, "--no-wind", "--no-lod", *args)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for n in needles:
        assert n in lines[0], lines[0]
    assert not out.exists() and not list(tmp_path.iterdir())


def test_an_opaque_leaf_image_is_fine_for_shaped_leaves(tmp_path):
    """--leaf-geometry shape draws the outline as polygons: an image with no cut-out is what
    the artist wants there (refused for cards, where each leaf would be a rectangle)."""
    from treegen_cli import api

    opaque = tmp_path / "opaque.png"
    Image.new("RGB", (16, 16), (40, 160, 40)).save(opaque)
    fast = dict(no_wind=True, no_lod=True, leaf_texture=str(opaque))
    api.make(PALM, tmp_path / "shape.glb", leaf_geometry="shape", **fast)
    with pytest.raises(TreegenError, match="no transparent texels"):
        api.make(PALM, tmp_path / "card.glb", **fast)


def test_defaults_are_documented_beside_the_options():
    assert MATERIAL_DEFAULTS == MaterialOptions()
    assert MATERIAL_DEFAULTS.textures and MATERIAL_DEFAULTS.texture_size == 512
