"""MeshOptions, and the per-stem choices they make: sides, girth, pointed tips and ribbons.

Kept apart from the builders because the size estimate (limits.py) must count exactly what
bark.py will emit, from the same rules, before any vertex exists.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import TreegenError

FULL_CARD_CELL = ((0.0, 0.0, 1.0, 1.0),)  # one cell, the whole image: the card fills it


@dataclass(frozen=True)
class MeshOptions:
    """Per-level tuples index by stem level; their last entry repeats for deeper levels."""

    sides: tuple[int, ...] = (16, 8, 6, 4, 3)  # cross-section sides per level (>= 3)
    rings_per_segment: tuple[int, ...] = (2, 1)  # rings per segment per level (>= 1): more rings
    # bend more smoothly under skinning
    flare_rings: int = 4  # extra trunk rings in the flare zone (lowest 1/8 of the trunk)
    thin_radius: float = 0.002  # metres: stems with a thinner base radius get thin_sides
    thin_sides: int = 3
    cap_height: float = 0.5  # tip cap cone height / tip radius
    point_radius: float = 1e-4  # metres: tips thinner than this end in a point, not a cap,
    point_ratio: float = 0.02  # ... and so do tips thinner than this × the stem's base radius
    ribbon_radius: float = 0.0  # metres: branches of at most RIBBON_SIDES sides thinner than
    # this at their base are drawn as two crossed ribbons ("twigs", double-sided), not tubes:
    # 4 triangles a segment where a tube of 3 sides takes 6 (a far LOD's, lod_budget.py)
    leaves: bool = True  # emit the "leaves" primitive
    leaf_geometry: str = "card"  # "card": a textured quad per leaf; "shape": the LeafShape
    # outline as geometry (see leafshapes.py); "triangle": a triangle card (far LODs)
    leaf_cells: tuple[tuple[float, float, float, float], ...] = FULL_CARD_CELL
    # leaf atlas layout: per variant its card rectangle
    # (u0, v0, u1, v1) in glTF UVs (top-left origin), as
    # textures.LeafAtlas.rects; materials.Materials gives it
    match_sides: tuple[int, ...] = ()  # a LOD's: LOD0's sides table; each stem is drawn as
    # wide, on average over the ways it turns, as with those sides (girth)


MESH_DEFAULTS = MeshOptions()
LEAF_GEOMETRIES = ("card", "shape")  # what a user may ask for (--leaf-geometry)
LOD_LEAF_GEOMETRIES = (*LEAF_GEOMETRIES, "triangle")  # and what a far LOD may draw (lod_budget.py)


RIBBON_SIDES = 4  # a branch drawn with more sides than this stays a tube


def per_level(values: tuple, level: np.ndarray) -> np.ndarray:
    """`values[level]` per stem, the last entry repeating for deeper levels."""
    v = np.asarray(values)
    return v[np.minimum(level, len(v) - 1)]


def stem_sides(tree, options: MeshOptions) -> np.ndarray:
    """Cross-section sides per stem (S,): per level, raised on a lobed trunk so the lobes show,
    cut to thin_sides on stems thinner than thin_radius; 4 for a ribbon stem (crossed
    ribbons of half-width r show the outline of a square tube through r)."""
    sides = _tube_sides(tree, options)
    return np.where(_ribbons(tree, options, sides), RIBBON_SIDES, sides)


def _tube_sides(tree, options: MeshOptions) -> np.ndarray:
    level = tree.stem_level.astype(np.int64)
    p = tree.params
    sides = per_level(options.sides, level).astype(np.int64)
    if p.lobes > 0 and p.lobe_depth != 0:
        sides = np.where(level == 0, np.maximum(sides, 4 * p.lobes), sides)
    return np.where(tree.stem_radius < options.thin_radius, np.minimum(sides, options.thin_sides), sides)


def ribbon_stems(tree, options: MeshOptions) -> np.ndarray:
    """Bool (S,): branches drawn as two crossed ribbons instead of a tube (ribbon_radius)."""
    return _ribbons(tree, options, _tube_sides(tree, options))


def _ribbons(tree, options: MeshOptions, sides: np.ndarray) -> np.ndarray:
    if options.ribbon_radius <= 0.0:
        return np.zeros(tree.n_stems, dtype=bool)
    return (tree.stem_level > 0) & (sides <= RIBBON_SIDES) & (tree.stem_radius < options.ribbon_radius)


def girth(tree, options: MeshOptions, sides: np.ndarray | None = None) -> np.ndarray:
    """Radius factor per stem (S,) that draws it, with its sides, as wide on average as with
    options.match_sides (LOD0's): a regular n-gon through the circle is on average
    n·sin(π/n)/π of its diameter wide (a square 0.90, a triangle 0.83, 16 sides 0.994), so a far
    LOD's few-sided trunk would otherwise thin out when it takes over. 1 without match_sides.
    `sides`: stem_sides(tree, options), when the caller has it already."""
    sides = stem_sides(tree, options) if sides is None else sides
    if not options.match_sides:
        return np.ones(sides.shape)
    sides0 = stem_sides(tree, replace(options, sides=options.match_sides))
    return _mean_width(sides0) / _mean_width(sides)


def _mean_width(n: np.ndarray) -> np.ndarray:
    """Mean seen width, in diameters, of a regular n-gon through the circle: perimeter / π."""
    return n * np.sin(np.pi / n) / np.pi


def pointed_tips(tree, options: MeshOptions) -> np.ndarray:
    """Bool (S,): stems whose tip is thin enough to close on an apex instead of a capped ring."""
    tip = tree.stem_node_start.astype(np.int64) + tree.stem_node_count - 1
    return tree.node_radius[tip] < np.maximum(options.point_radius, options.point_ratio * tree.stem_radius)


def check_options(options: MeshOptions) -> None:
    """Refuse options no mesh can be built from, naming the flag."""
    if min(options.sides) < 3 or options.thin_sides < 3:
        raise TreegenError(f"--sides {options.sides}: every level needs at least 3 sides")
    if min(options.rings_per_segment) < 1:
        raise TreegenError(f"rings per segment {options.rings_per_segment}: must be >= 1")
    if options.leaf_geometry not in LOD_LEAF_GEOMETRIES:
        raise TreegenError(
            f"--leaf-geometry '{options.leaf_geometry}': expected one of {', '.join(LEAF_GEOMETRIES)}"
        )
    cells = np.asarray(options.leaf_cells, dtype=np.float64)
    if cells.ndim != 2 or cells.shape[1] != 4 or not len(cells) or not np.all(np.isfinite(cells)):
        raise ValueError(f"leaf_cells must be (u0, v0, u1, v1) rectangles, got {options.leaf_cells!r}")
