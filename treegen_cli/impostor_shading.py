"""What the impostor's leaves look like in its views, computed per vertex in numpy so the
atlas's leaf program stays lean (impostor_render.py): each leaf's tint (the preview's hash),
the crown's sky occlusion (the bark shader's formula) and the shade of a crown's leaves.

    shade = leaf_shading(part, centre, radius, crown_centre, crown_radius)
    # Result: (V, 3) float32, colour × tint × LEAF_SHADE × occlusion
"""

from __future__ import annotations

import numpy as np

# A card faces the light as one surface; a crown's leaves face every way and shade each other.
# Leaves' albedo is scaled by this so the cards, lit by an engine through their normal map
# (impostor.card_textures), match the coarsest LOD's colour at the switch (the aspen's cards
# came out 2.1× brighter than its LOD3 without it). Per channel: the crown's self-shadowing
# dims the warm sun more than the blue sky, so one grey left the cards yellower (blue/green
# 0.85-0.91× LOD3's on aspen, fir, oak and willow); these balance the hue over those four at
# the switch size (impostor_colour_bench --size 96: blue/green 0.92-1.08×), green the mean
# brightness (0.92-1.21×, mean 1.05; per species, mostly from the bark inside the crown).
LEAF_SHADE = np.array([0.372, 0.403, 0.589])


def _occlusion(rel: np.ndarray, crown_centre: np.ndarray, crown_radius: np.ndarray) -> np.ndarray:
    """The bark shader's sky occlusion at points `rel` ((p − centre) / radius), in numpy."""
    r = np.linalg.norm((rel - crown_centre) / crown_radius, axis=1)
    t = np.clip((r - 0.1) / 0.9, 0.0, 1.0)
    return 0.45 + 0.55 * (t * t * (3.0 - 2.0 * t))


def leaf_ids(indices: np.ndarray, n_vertices: int) -> np.ndarray:
    """Per vertex, the index of its leaf (connected triangles; numbered by first vertex, so the
    k-th card of a card primitive is leaf k)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    tri = np.asarray(indices, np.int64).reshape(-1, 3)
    rows, cols = np.concatenate([tri[:, 0], tri[:, 1]]), np.concatenate([tri[:, 1], tri[:, 2]])
    graph = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(n_vertices, n_vertices))
    return connected_components(graph, directed=False)[1]


def leaf_tint(leaf: np.ndarray) -> np.ndarray:
    """Each leaf its own tint, as the preview gives it: a hash of its index (uint32 arithmetic,
    float32 like the GPU's) → (n, 3) factors around 1."""
    x = np.asarray(leaf, np.uint32).copy()
    x ^= x >> np.uint32(16)
    x *= np.uint32(0x7FEB352D)
    x ^= x >> np.uint32(15)
    x *= np.uint32(0x846CA68B)
    x ^= x >> np.uint32(16)
    h = x.astype(np.float32) / np.float32(4294967295.0)
    return np.float32(1.0) + np.float32(0.5) * (
        h[:, None] * np.array([0.3, 0.4, 0.2], np.float32) - np.array([0.15, 0.2, 0.2], np.float32)
    )


def leaf_shading(
    p, centre: np.ndarray, radius: float, crown_centre: np.ndarray, crown_radius: np.ndarray
) -> np.ndarray:
    """(V, 3) float32 `in_shade` of a leaf part: colour × tint × LEAF_SHADE × occlusion."""
    rel = (np.asarray(p.positions, np.float64) - centre) / radius
    tint = leaf_tint(leaf_ids(p.indices, len(p.positions)))
    ao = _occlusion(rel, crown_centre, crown_radius)
    color = np.asarray(p.color, np.float64)
    return (tint * ao[:, None] * LEAF_SHADE * color).astype(np.float32)
