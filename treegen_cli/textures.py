"""Generated, deterministic textures: a leaf atlas with alpha and tileable bark albedo + normal,
per species (`species_textures`). Parts: texture_leaf.py (the atlas), texture_bark.py (the bark
maps), texture_color.py (sRGB), texture_png.py (repeatable PNG bytes).

Why: untextured cards read as confetti in an engine. These images are small enough to embed in
every GLB/USD and are drawn from the same LeafShape outlines mesh.py stamps (leafshapes.py), so
the alpha-tested blade on a card matches `Tree.leaf_area` (card area × fill_factor).

Conventions (the glTF ones, so a writer embeds the arrays unchanged):
* UV origin is the top-left of the image, u right, v down (glTF TEXCOORD_0; image row = v·H).
  treegen's own Primitive.uvs have the bottom-left origin (OpenGL/USD) and the glTF writer
  flips them; `card_uvs(..., origin="bottom-left")` gives UVs in that convention.
* Colours passed in are LINEAR RGB (like glTF baseColorFactor / asset.Material.base_color); the
  colour images are sRGB-encoded, as glTF's baseColorTexture requires. A material using them
  should set its base colour factor to white: the mean (in linear light) of the blade texels,
  and of the whole bark albedo, is the colour given, so the tree's average colour is kept.
* Leaf atlas alpha is straight (not premultiplied) coverage; transparent texels carry the colour
  of the nearest solid blade texel so bilinear/mip filtering does not bleed dark halos.
* Normal maps are tangent space, OpenGL/glTF convention: R = +X (u right), G = +Y (up in the
  image, i.e. −v), B = +Z out of the surface; byte = round((n + 1) / 2 · 255).
* Every random choice comes from a numpy Generator seeded from `seed`: same arguments, same
  pixels, and `png_bytes` turns the same pixels into the same bytes.

Default sizes keep a tree's textures to a few hundred KB of PNG: a 512² leaf atlas (four
240-texel leaves) and 256² bark (bark is noise-like and compresses poorly: 512² bark albedo +
normal is ~600 KB, 256² ~190 KB; it tiles around and along every stem anyway).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .texture_bark import bark_textures
from .texture_leaf import LeafAtlas, leaf_atlas
from .texture_png import png_bytes

# Linear RGB (glTF baseColorFactor space). Chosen by eye for each species' real foliage and
# bark; the by-shape and generic entries are the fallbacks.
DEFAULT_LEAF_COLOR: dict[str | int, tuple[float, float, float]] = {
    "default": (0.16, 0.30, 0.06),
    0: (0.16, 0.30, 0.06),  # broadleaf
    1: (0.07, 0.16, 0.05),  # needles
    2: (0.07, 0.17, 0.06),  # narrow needles / willow-like
    3: (0.14, 0.27, 0.06),
    4: (0.15, 0.28, 0.06),
    5: (0.12, 0.17, 0.06),  # seeds, knots, tiny blobs: olive
    6: (0.10, 0.22, 0.05),  # palm fronds
    7: (0.15, 0.29, 0.05),  # palmate
    "balsam_fir": (0.04, 0.11, 0.04),
    "black_tupelo": (0.10, 0.22, 0.04),
    "ca_black_oak": (0.12, 0.20, 0.05),
    "desert_bush": (0.16, 0.18, 0.08),
    "eastern_cottonwood": (0.15, 0.30, 0.06),
    "european_larch": (0.16, 0.34, 0.08),
    "fan_palm": (0.12, 0.24, 0.07),
    "lombardy_poplar": (0.13, 0.28, 0.05),
    "palm": (0.10, 0.22, 0.05),
    "quaking_aspen": (0.20, 0.36, 0.06),
    "rush": (0.20, 0.24, 0.08),
    "sassafras": (0.18, 0.34, 0.06),
    "shave_grass": (0.12, 0.25, 0.07),
    "tamarack": (0.14, 0.30, 0.08),
    "weeping_willow": (0.20, 0.33, 0.07),
}


DEFAULT_BARK_COLOR: dict[str, tuple[float, float, float]] = {
    "default": (0.13, 0.09, 0.06),
    "balsam_fir": (0.17, 0.15, 0.13),  # smooth grey-brown
    "black_tupelo": (0.11, 0.09, 0.08),  # dark, blocky
    "ca_black_oak": (0.08, 0.07, 0.06),  # nearly black furrows
    "desert_bush": (0.20, 0.15, 0.10),
    "eastern_cottonwood": (0.20, 0.19, 0.17),  # ash-grey, deeply furrowed
    "european_larch": (0.17, 0.08, 0.05),  # reddish brown
    "fan_palm": (0.22, 0.17, 0.11),
    "lombardy_poplar": (0.16, 0.15, 0.13),
    "palm": (0.22, 0.17, 0.11),
    "quaking_aspen": (0.45, 0.44, 0.37),  # pale, chalky
    "rush": (0.15, 0.22, 0.07),  # green stems
    "sassafras": (0.17, 0.10, 0.07),  # orange-brown
    "shave_grass": (0.12, 0.22, 0.08),  # green stems
    "tamarack": (0.16, 0.09, 0.07),
    "weeping_willow": (0.14, 0.11, 0.08),
}


# How furrowed each species' bark is (bark_textures' `furrow`): 1 deep plates, 0 smooth.
DEFAULT_BARK_FURROW: dict[str, float] = {
    "default": 1.0,
    "balsam_fir": 0.35,  # smooth with resin blisters until old
    "desert_bush": 0.6,
    "european_larch": 0.8,
    "fan_palm": 0.2,
    "lombardy_poplar": 0.8,
    "palm": 0.2,
    "quaking_aspen": 0.1,  # smooth, chalky, dark lenticels
    "rush": 0.0,  # green culms
    "sassafras": 0.9,
    "shave_grass": 0.0,
    "tamarack": 0.7,
    "weeping_willow": 0.9,
}


def _species_key(params) -> str:
    return str(getattr(params, "name", "")).lower().replace(" ", "_").replace("-", "_")


def species_colors(params) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(leaf, bark) linear RGB for a species: its own LeafColor/BarkColor fields if Params ever
    grows them, else the table by species name, else by leaf shape, else the generic default.
    """
    name = _species_key(params)
    leaf = getattr(params, "leaf_color", None)
    bark = getattr(params, "bark_color", None)
    if leaf is None:
        leaf = DEFAULT_LEAF_COLOR.get(name) or DEFAULT_LEAF_COLOR.get(
            int(getattr(params, "leaf_shape", 0)), DEFAULT_LEAF_COLOR["default"]
        )
    if bark is None:
        bark = DEFAULT_BARK_COLOR.get(name, DEFAULT_BARK_COLOR["default"])
    return tuple(float(c) for c in leaf), tuple(float(c) for c in bark)


@dataclass(frozen=True, eq=False)
class TreeTextures:
    """A species' leaf atlas and bark maps, ready to embed (see `pngs`)."""

    leaf: LeafAtlas
    bark_albedo: np.ndarray  # uint8 (N, N, 3) sRGB
    bark_normal: np.ndarray  # uint8 (N, N, 3) tangent space, OpenGL/glTF convention

    def pngs(self) -> dict[str, bytes]:
        """PNG bytes by role: "leaf" (RGBA), "bark" (RGB), "bark_normal" (RGB)."""
        return {
            "leaf": png_bytes(self.leaf.rgba),
            "bark": png_bytes(self.bark_albedo),
            "bark_normal": png_bytes(self.bark_normal),
        }


def species_textures(
    params, seed: int = 0, leaf_size: int = 512, bark_size: int = 256, variants: int = 4
) -> TreeTextures:
    """Everything a writer needs for one species: its colours, its LeafShape outline, its
    leaf width / length (LeafScaleX) so veins keep their angles on the stretched card, and
    how furrowed its bark is."""
    leaf_rgb, bark_rgb = species_colors(params)
    aspect = float(getattr(params, "leaf_scale_x", 0.5))
    atlas = leaf_atlas(
        int(getattr(params, "leaf_shape", 0)), leaf_rgb, leaf_size, variants, seed, aspect=aspect
    )
    furrow = DEFAULT_BARK_FURROW.get(_species_key(params), DEFAULT_BARK_FURROW["default"])
    albedo, normal = bark_textures(bark_rgb, bark_size, seed, furrow=furrow)
    return TreeTextures(atlas, albedo, normal)
