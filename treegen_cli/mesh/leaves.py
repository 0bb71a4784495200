"""Leaves: a card (or the LeafShape outline) stamped on every leaf frame, rigid on its joint.

Cards by default: one length × width quad per leaf (4 vertices, 2 triangles, UVs 0..1) meant
for an alpha-tested texture that carries the LeafShape outline — half the vertices of the
8-point ellipse on the willow's 630k leaves. `leaf_geometry="shape"` stamps the outline itself
as geometry instead. Either way `Tree.leaf_area` stays the physical blade area (length × width
× fill_factor): a card draws length × width, the texture's alpha cuts it back to the blade.
`"triangle"` (far LODs only, lod_budget.py) draws leafshapes.TRIANGLE_CARD, one triangle a
leaf: a blade a few pixels long shows its cover, not its outline, and the LOD holds twice the
leaves for its triangles.

UVs (origin bottom-left): each leaf draws one cell of the leaf atlas (`MeshOptions.leaf_cells`,
the layout the materials stage made the texture with), chosen by a generator seeded from the
tree seed, and the card (or outline) fills that cell as textures.card_uvs maps it.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..asset import Primitive
from ..leafshapes import OUTLINES, TRIANGLE_CARD, outline
from ..texture_leaf import card_uvs
from .options import FULL_CARD_CELL

CARD = OUTLINES[4]  # the full length × width rectangle, UVs 0..1


def leaf_variants(tree, n_cells: int) -> np.ndarray:
    """Atlas cell per leaf (L,), seeded from the tree seed: the same tree, the same leaves."""
    if n_cells <= 1:
        return np.zeros(tree.n_leaves, dtype=np.int64)
    rng = np.random.default_rng([int(tree.seed), 0x1EAF, 0xA71A5])
    return rng.integers(0, n_cells, tree.n_leaves)


def _faces_flat(o) -> bool:
    """Whether every outline vertex normal is the face normal of its triangles, also after the
    stamp's anisotropic length × width scaling (checked at two aspect ratios)."""
    for aspect in (1.0, 3.0):
        p = o.points * [1.0, aspect, 1.0]
        a, b, c = (p[o.triangles[:, k]] for k in range(3))
        fn = np.cross(b - a, c - a)
        fn /= np.linalg.norm(fn, axis=1, keepdims=True)
        if not np.allclose(o.normals[o.triangles], fn[:, None, :], atol=1e-9):
            return False
    return True


def _leaf_uvs(tree, o, cells) -> np.ndarray:
    """(L·P, 2) bottom-left UVs: each leaf's outline points in its seeded atlas cell. card_uvs
    maps the P points into each of the few cells once; leaves then index that small table."""
    K, P = len(cells), len(o.points)
    table = card_uvs(
        np.tile(o.uvs, (K, 1)),
        np.repeat(np.arange(K), P),
        SimpleNamespace(rects=np.asarray(cells, dtype=np.float32)),  # reads .rects
        origin="bottom-left",
    )
    pick = leaf_variants(tree, K)[:, None] * P + np.arange(P)[None, :]
    return table[pick.ravel()]


def stamp_leaves(tree, rig, geometry: str = "card", cells: tuple = FULL_CARD_CELL) -> Primitive:
    """Stamp a card, a triangle card or the LeafShape outline on every leaf frame (float32
    broadcasts)."""
    o = outline(tree.params.leaf_shape)  # validates the code even for cards
    if geometry != "shape":
        o = CARD if geometry == "card" else TRIANGLE_CARD
    L, P = tree.n_leaves, len(o.points)
    F = tree.leaf_frame.astype(np.float32)
    size = tree.leaf_size.astype(np.float32)
    length, width = size[:, 0:1], size[:, 1:2]  # (L, 1)
    pts = o.points.astype(np.float32)
    base = tree.leaf_pos.astype(np.float32)
    # Blade axes scaled once, then one (L, 3) pass per outline point (P ≤ 16, not per leaf).
    across, along = F[:, :, 0] * width, F[:, :, 1] * length
    up = F[:, :, 2] * width if np.any(pts[:, 2]) else None  # folded blades (palm)
    pos = np.empty((L, P, 3), dtype=np.float32)
    for k, (x, y, z) in enumerate(pts):
        out = pos[:, k]
        np.multiply(across, x, out=out)
        out += base
        if y:
            out += y * along
        if z and up is not None:
            out += z * up
    nl = o.normals.astype(np.float32)
    if np.all(nl == [0.0, 0.0, 1.0]):  # flat blade: the frame normal
        n = F[:, :, 2]
        n = n / np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
        nrm = np.repeat(n, P, axis=0)
    else:
        nrm = (
            nl[None, :, 0, None] * F[:, None, :, 0]
            + nl[None, :, 1, None] * F[:, None, :, 1]
            + nl[None, :, 2, None] * F[:, None, :, 2]
        )
        nrm = (nrm / np.linalg.norm(nrm, axis=2, keepdims=True)).reshape(-1, 3)
    idx = (
        o.triangles.astype(np.uint32)[None, :, :]
        + (np.uint32(P) * np.arange(L, dtype=np.uint32))[:, None, None]
    )
    joints = np.zeros((L * P, 4), dtype=np.uint16)
    joints[:, 0] = np.repeat(rig.leaf_joint, P)
    weights = np.zeros((L * P, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return Primitive(
        name="leaves",
        material="leaf",
        positions=pos.reshape(-1, 3),
        normals=nrm,
        uvs=_leaf_uvs(tree, o, cells),
        indices=idx.ravel(),
        joints=joints,
        weights=weights,
        flat_normals=_faces_flat(o),  # frames are rotations: flat stays flat
    )
