"""Params → the tree's two materials, [bark, leaf], and the leaf atlas layout mesh/leaves.py maps to.

Why a stage of its own: the leaf texture decides how leaf cards are UV-mapped. The generated
atlas holds a few leaf variants side by side, an artist's image is one leaf filling the whole
picture, so the stage returns the layout with the materials (`Materials.leaf_cells`) and
pipeline.py hands it to mesh/ (`MeshOptions.leaf_cells`) before any leaf is stamped.

    mats = build_materials(params, MaterialOptions(texture_size=1024))
    mesh = replace(mesh, leaf_cells=mats.leaf_cells)      # Asset(materials=mats.materials, ...)

Result by options:
* default: generated, deterministic textures (textures.species_textures) from the species'
  colours (LeafColor / BarkColor, else textures.species_colors' defaults), LeafShape and
  LeafScaleX. Leaf: RGBA atlas, CLAMP, alpha-tested (MASK at ALPHA_CUTOFF), double-sided;
  bark: albedo + normal map, REPEAT. Base colour factors are white: the textures' mean is the
  species colour, so the texture alone carries it.
* `textures=False` (--no-textures): colour-only materials in the species colours, the card
  filling one cell (UVs 0..1), as files had before textures.
* `leaf_texture` / `bark_texture` (--leaf-texture / --bark-texture): an artist's PNG embedded
  byte for byte. A custom leaf image is one cell: each card maps to the whole image. A custom
  bark image replaces the generated albedo and drops the generated normal map (its relief would
  not match the artist's picture).

Textures depend on the species only, not on the tree seed: every tree of a species (a forest's
prototypes, other --seed values) gets identical images, so writers can share them, and they
are built once per process per species and size (an LRU cache).
"""

from __future__ import annotations

import io
import re
import zlib
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

from .asset import Material, Texture
from .errors import TreegenError
from .mesh import FULL_CARD_CELL, TWIGS
from .params import Params
from .texture_leaf import atlas_rects
from .textures import species_colors, species_textures

TEXTURE_SIZES = (64, 2048)  # --texture-size range, powers of two (mip chains, old GPUs)
ALPHA_CUTOFF = 0.5  # leaf alpha test: the atlas alpha is anti-aliased coverage
LEAF_VARIANTS = 4  # leaves in the generated atlas (2 × 2 cells)
BARK_ROUGHNESS = 0.92
LEAF_ROUGHNESS = 0.7
WHITE = (1.0, 1.0, 1.0, 1.0)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
Cells = tuple[tuple[float, float, float, float], ...]  # (u0, v0, u1, v1) per leaf variant


@dataclass(frozen=True)
class MaterialOptions:
    textures: bool = True  # False: colour-only materials (--no-textures)
    texture_size: int = 512  # leaf atlas side in texels; bark maps are half of it
    # (bark is noise that tiles around every stem anyway)
    leaf_texture: Path | None = None  # an artist's PNG, used as is (one cell: the whole card)
    bark_texture: Path | None = None  # an artist's PNG bark albedo, used as is, REPEAT
    cut_out: bool = True  # leaves are cards cut out by the image's alpha (not --leaf-geometry
    # shape, whose polygons are the outline): an artist's leaf image needs transparent texels


MATERIAL_DEFAULTS = MaterialOptions()


class Materials:
    """A species' materials: `leaf_cells` at once, `materials` when the textures are made.

    The generated textures (≈ 0.2 s: drawing and PNG-compressing the atlas and bark maps) are
    made on a worker thread started by build_materials, so they overlap growing, skinning and
    baking the tree (numpy and zlib release the GIL); reading `materials` waits for them.
    The layout needs no pixels (textures.atlas_rects), so the mesh never waits.
    """

    def __init__(self, leaf_cells: Cells, make: Callable[[], list[Material]]):
        self.leaf_cells = leaf_cells
        self._future: Future = _run_in_thread(make)

    @property
    def materials(self) -> list[Material]:
        """[bark, leaf], named as Primitive.material says (waits for the textures)."""
        return self._future.result()


def _run_in_thread(fn: Callable[[], list[Material]]) -> Future:
    """fn() on a thread of its own (one per call: safe after a fork, e.g. forest workers)."""
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="treegen-textures")
    try:
        return pool.submit(fn)
    finally:
        pool.shutdown(wait=False)


def check_options(options: MaterialOptions) -> None:
    """Refuse inconsistent options with the flag's name (exit 2 in the CLI)."""
    lo, hi = TEXTURE_SIZES
    n = options.texture_size
    if not (isinstance(n, int) and lo <= n <= hi and n & (n - 1) == 0):
        raise TreegenError(f"--texture-size {n}: must be a power of two in [{lo}, {hi}]")
    if not options.textures:
        for flag, path in (
            ("--leaf-texture", options.leaf_texture),
            ("--bark-texture", options.bark_texture),
        ):
            if path is not None:
                raise TreegenError(f"{flag} {path}: cannot be combined with --no-textures")


# a Python object's repr ("<_io.BytesIO object at 0x7f…>"): its address changes every run
_OBJECT_REPR = re.compile(r"\s*<[^<>]* at 0x[0-9a-fA-F]+>")


def read_png(path: Path, flag: str, cut_out: bool = False) -> bytes:
    """An artist's image as PNG bytes, checked to decode fully; else a one-line TreegenError
    naming the flag and the file (glTF and USD embed PNG, so no other format is taken).
    `cut_out` (a leaf image): it must have texels under ALPHA_CUTOFF, or every leaf is drawn
    as an opaque rectangle (an RGB PNG was embedded so, without a word)."""
    from PIL import Image

    where = f"{flag} {path}"
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise TreegenError(f"{where}: no such file") from None
    except IsADirectoryError:
        raise TreegenError(f"{where}: is a directory, expected a PNG image") from None
    except OSError as exc:
        raise TreegenError(f"{where}: cannot read: {exc.strerror or exc}") from None
    if not data.startswith(PNG_SIGNATURE):
        raise TreegenError(f"{where}: not a PNG image (convert it to PNG first: glTF and USD embed PNG)")
    try:
        with Image.open(io.BytesIO(data)) as img:
            img.load()  # decodes every row: truncation shows here
            w, h = img.size
            low = img.convert("RGBA").getchannel("A").getextrema()[0] if cut_out else 0
            alpha = int(low) if isinstance(low, (int, float)) else 0  # (one band: (min, max))
    except Image.UnidentifiedImageError:  # PIL's text is "cannot identify image file <BytesIO at 0x…>"
        raise TreegenError(
            f"{where}: not a readable PNG image (PNG signature, but no image PIL can decode after it)"
        ) from None
    except Exception as exc:  # PIL raises many types for broken files
        msg = " ".join(_OBJECT_REPR.sub("", str(exc)).split())[:120] or type(exc).__name__
        raise TreegenError(f"{where}: not a readable PNG image ({msg})") from None
    if w < 1 or h < 1:
        raise TreegenError(f"{where}: empty image")
    if alpha >= ALPHA_CUTOFF * 255:
        raise TreegenError(
            f"{where}: no transparent texels (the lowest alpha is {alpha} of 255): leaves are cut out "
            f"where alpha < {round(ALPHA_CUTOFF * 255)}, so each would draw as an opaque rectangle; "
            "save it as RGBA with a transparent background"
        )
    return data


@lru_cache(maxsize=16)
def _generated_pngs(params: Params, size: int) -> tuple[bytes, bytes, bytes]:
    """(leaf atlas, bark albedo, bark normal) PNG bytes of a species: cached, as a forest builds
    many trees of few species. The seed is the species name's CRC (stable across processes),
    so species with the same colours and leaf shape still differ."""
    seed = zlib.crc32(params.name.encode("utf-8"))
    pngs = species_textures(
        params, seed=seed, leaf_size=size, bark_size=size // 2, variants=LEAF_VARIANTS
    ).pngs()
    return pngs["leaf"], pngs["bark"], pngs["bark_normal"]


def _draws_textures(params: Params, options: MaterialOptions) -> bool:
    """Whether build_materials draws generated textures: textures on, and the bark or a leafy
    tree's leaves without an artist's image."""
    return options.textures and (
        options.bark_texture is None or (options.leaf_texture is None and has_leaves(params))
    )


def has_leaves(params: Params) -> bool:
    """Whether the generator can grow leaves for these params (its own rule in generate/grow.py)."""
    return params.levels >= 1 and params.leaves != 0


def leaf_cells(params: Params, options: MaterialOptions = MATERIAL_DEFAULTS) -> Cells:
    """The atlas cells mesh/leaves.py maps leaf cards into (no pixels needed): the generated
    atlas's variants, or the whole card (an artist's image is one leaf; untextured or
    leafless: no atlas). The LOD planner keys triangle cards on it, so a plan without the
    textures (batch --dry-run) must use it too."""
    if not options.textures or options.leaf_texture is not None or not has_leaves(params):
        return FULL_CARD_CELL
    return tuple(
        (float(u0), float(v0), float(u1), float(v1))
        for u0, v0, u1, v1 in atlas_rects(LEAF_VARIANTS, options.texture_size)
    )


def twig_material(bark: Material) -> Material:
    """The crossed ribbons' material (mesh.TWIGS): the bark's colour and texture on both faces
    (a ribbon is seen from either side), without its normal map (the ribbons are flat and
    under a pixel or two wide where they are drawn)."""
    return replace(bark, name=TWIGS, double_sided=True, normal_texture=None)


def build_materials(params: Params, options: MaterialOptions = MATERIAL_DEFAULTS) -> Materials:
    """The [bark, leaf] materials of a species and the leaf cells mesh/leaves.py maps cards into.
    Options and an artist's files are checked here, before anything is grown; generated
    textures are made in the background (see Materials)."""
    check_options(options)
    leaf_rgb, bark_rgb = species_colors(params)
    colour_leaf = Material("leaf", base_color=(*leaf_rgb, 1.0), roughness=LEAF_ROUGHNESS, double_sided=True)
    if not options.textures:
        bark = Material("bark", base_color=(*bark_rgb, 1.0), roughness=BARK_ROUGHNESS)
        return Materials(FULL_CARD_CELL, lambda: [bark, colour_leaf])
    leaf_png = (
        read_png(options.leaf_texture, "--leaf-texture", options.cut_out) if options.leaf_texture else None
    )
    bark_png = read_png(options.bark_texture, "--bark-texture") if options.bark_texture else None
    leafy = has_leaves(params)
    cells = leaf_cells(params, options)

    def make() -> list[Material]:
        png = leaf_png
        if bark_png is not None:
            bark = Material(
                "bark",
                base_color=WHITE,
                roughness=BARK_ROUGHNESS,
                base_texture=Texture("bark", bark_png, wrap="REPEAT"),
            )
        if _draws_textures(params, options):
            atlas, albedo, normal = _generated_pngs(params, options.texture_size)
            if bark_png is None:
                bark = Material(
                    "bark",
                    base_color=WHITE,
                    roughness=BARK_ROUGHNESS,
                    base_texture=Texture("bark", albedo, wrap="REPEAT"),
                    normal_texture=Texture("bark_normal", normal, wrap="REPEAT", srgb=False),
                )
            if leaf_png is None and leafy:
                png = atlas
        if png is None:
            return [bark, colour_leaf]
        return [
            bark,
            Material(
                "leaf",
                base_color=WHITE,
                roughness=LEAF_ROUGHNESS,
                double_sided=True,
                alpha_cutoff=ALPHA_CUTOFF,
                base_texture=Texture("leaf", png, wrap="CLAMP"),
            ),
        ]

    return Materials(cells, make)
