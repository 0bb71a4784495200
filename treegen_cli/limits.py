"""Refuse oversized work before allocating it: mesh vertices and joint keys.

The generator already refuses too many stems/leaves from the parameters alone
(generate.estimate_counts, --max-stems/--max-leaves). Once the tree exists its stems, nodes and
leaves are known, so the mesh size follows from the mesh options almost exactly, and the clip's
size is joints × frames. Each refusal names the estimate and the flag that raises the limit.

    check_mesh(tree, MeshOptions(), Limits(max_vertices=1_000_000))   # before build_mesh
    check_keys(n_joints, WindOptions(), Limits())                      # before bake_wind
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import TreegenError

MAX_TREES = 100_000  # trees a forest layout may place (treegen forest --max-trees)


@dataclass(frozen=True)
class Limits:
    """max_vertices: per LOD mesh (bark + leaves); max_keys: joint-keys per clip (joints × keys).
    20M vertices is ~1 GB of float32 attributes in memory; 5M joint-keys ~160 MB while baking."""

    max_vertices: int = 20_000_000
    max_keys: int = 5_000_000


LIMITS_DEFAULTS = Limits()


def _rings_sides(tree, options) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rings each stem's bark emits, its sides, whether it ends in a point, and whether it is
    drawn as crossed ribbons (S,), as mesh.bark makes them."""
    from .mesh.bark import ring_counts
    from .mesh.options import pointed_tips, ribbon_stems, stem_sides

    pointed = pointed_tips(tree, options)
    rings = ring_counts(tree, options) - pointed  # a pointed tip closes on its apex, no ring
    return rings, stem_sides(tree, options), pointed, ribbon_stems(tree, options)


def leaf_outline(tree, options):
    """The outline mesh.build_mesh stamps on every leaf (a card, a triangle card, or the LeafShape)."""
    from .leafshapes import OUTLINES, TRIANGLE_CARD, outline

    if options.leaf_geometry == "triangle":
        return TRIANGLE_CARD
    return OUTLINES[4] if options.leaf_geometry == "card" else outline(tree.params.leaf_shape)


def estimate_vertices(tree, options) -> tuple[int, int]:
    """(bark, leaf) vertex counts mesh.build_mesh will emit for `tree` with MeshOptions
    `options`: exact (flare rings that land on a node's ring merged, as mesh.bark merges them).
    Bark: rings × (sides + 1) per tube plus one apex, 4 a ring per crossed ribbons and 2 at
    their apex where they end in a point; leaves: outline points each."""
    rings, sides, pointed, ribbon = _rings_sides(tree, options)
    bark = int(np.sum(np.where(ribbon, 4 * rings + 2 * pointed, rings * (sides + 1) + 1)))
    leaves = 0
    if options.leaves and tree.n_leaves:
        leaves = tree.n_leaves * len(leaf_outline(tree, options).points)
    return bark, leaves


def bark_triangles(tree, options) -> np.ndarray:
    """Per stem (S,), the bark triangles mesh.build_mesh emits: two per side between
    consecutive rings plus a fan of `sides` to the apex; crossed ribbons four between rings,
    plus two to a pointed tip (its twigs primitive counts as bark)."""
    rings, sides, pointed, ribbon = _rings_sides(tree, options)
    return np.where(ribbon, 4 * (rings - 1) + 2 * pointed, (2 * (rings - 1) + 1) * sides)


def estimate_triangles(tree, options) -> tuple[int, int]:
    """(bark, leaf) triangle counts mesh.build_mesh will emit, exact in the same sense as
    estimate_vertices: bark_triangles summed; the outline's triangles per leaf."""
    bark = int(np.sum(bark_triangles(tree, options)))
    leaves = 0
    if options.leaves and tree.n_leaves:
        leaves = tree.n_leaves * len(leaf_outline(tree, options).triangles)
    return bark, leaves


def frame_count(wind) -> int:
    """Keys per joint track of a baked clip (one per frame plus the closing loop key)."""
    from .clip import loop_times

    if wind is None:
        return 0
    return len(loop_times(wind.duration, wind.fps))


def check_mesh(tree, options, limits: Limits = LIMITS_DEFAULTS) -> int:
    """Raise TreegenError if the mesh would exceed limits.max_vertices; return the estimate."""
    bark, leaves = estimate_vertices(tree, options)
    total = bark + leaves
    if total > limits.max_vertices:
        raise TreegenError(
            f"species '{tree.params.name}' would need about {total:,} mesh vertices "
            f"({bark:,} bark, {leaves:,} leaves), over the limit of {limits.max_vertices:,}; "
            f"raise it with --max-vertices N (or use fewer --sides / lower LeafQuality)"
        )
    return total


def check_keys(n_joints: int, wind, limits: Limits = LIMITS_DEFAULTS) -> int:
    """Raise TreegenError if joints × keys of the clip would exceed limits.max_keys."""
    frames = frame_count(wind)
    total = int(n_joints) * frames
    if total > limits.max_keys:
        raise TreegenError(
            f"the wind clip would hold about {total:,} joint-keys ({n_joints:,} joints × "
            f"{frames:,} keys), over the limit of {limits.max_keys:,}; raise it with "
            f"--max-keys N (or lower --max-joints, --fps or --duration)"
        )
    return total
