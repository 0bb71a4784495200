"""Leaf blade outlines, one per LeafShape code (the codes params/keys.py's table names).

A blade lives in card space: x across the blade (−0.5..0.5 of the leaf width), y along it
(0 = base at the petiole, 1 = tip, in units of the leaf length), z along the blade normal.
Each outline is a tiny triangle list drawn once at import. By default mesh/leaves.py draws every leaf
as a plain length × width card (the "rectangle" below) and the outline belongs in the leaf
texture's alpha, at the same UVs (u = x + 0.5, v = y); with `leaf_geometry="shape"` it stamps
the outline itself with one broadcast. `fill_factor` is the exact area of the outline's
triangles, so `Tree.leaf_area` (what the wind model pushes on) is the physical blade area:
equal to the drawn area for shape geometry, and card area × fill_factor for cards.

| code | params/keys.py    | outline here                                        | verts | tris |
|------|-------------------|-----------------------------------------------------|-------|------|
| 0    | disc, oval, …     | elliptic 8-gon                                      | 8     | 6    |
| 1    | disc1             | triangle inscribed in the ellipse                   | 3     | 1    |
| 2    | disc2             | diamond inscribed in the ellipse                    | 4     | 2    |
| 3    | disc3             | pentagon inscribed in the ellipse                   | 5     | 3    |
| 4    | square, rectangle | the full card                                       | 4     | 2    |
| 5    | sphere            | round 8-gon (a card: seen from the side it is thin) | 8     | 6    |
| 6    | palm              | two elliptic halves folded up 30° along the midrib  | 16    | 12   |
| 7    | star              | five-lobed (palmate) star fanned from its centre    | 11    | 10   |
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .asset import triangle_areas
from .errors import TreegenError


@dataclass(frozen=True, eq=False)
class LeafOutline:
    """One blade in card space; triangles counter-clockwise seen from +normal."""

    name: str
    points: np.ndarray  # float64 (P, 3): x (width units), y (length units), z (normal)
    normals: np.ndarray  # float64 (P, 3), unit
    uvs: np.ndarray  # float64 (P, 2), 0..1 across the card
    triangles: np.ndarray  # int32 (T, 3)
    area: float  # true area of the triangles for a 1 × 1 card


def _rows(rows: list[tuple[float, float, float]]):
    """Triangulate a y-monotone blade given as rows (y, x_left, x_right), base to tip.

    A row with x_left == x_right is a single point (base or tip); consecutive rows are joined
    by one or two triangles, all counter-clockwise in the x–y plane.
    """
    pts: list[tuple[float, float]] = []
    row_idx: list[tuple[int, int]] = []  # (left vertex, right vertex); equal for a point
    for y, xl, xr in rows:
        if xl == xr:
            pts.append((xl, y))
            row_idx.append((len(pts) - 1, len(pts) - 1))
        else:
            pts.append((xl, y))
            pts.append((xr, y))
            row_idx.append((len(pts) - 2, len(pts) - 1))
    tris: list[tuple[int, int, int]] = []
    for (l0, r0), (l1, r1) in zip(row_idx[:-1], row_idx[1:]):
        if l0 != r0:
            tris.append((l0, r0, r1))
        if l1 != r1:
            tris.append((l0, r1, l1))
    return np.array(pts, dtype=np.float64), np.array(tris, dtype=np.int32)


def _inscribed(n: int) -> list[tuple[float, float, float]]:
    """Rows of an n-gon inscribed in the card's ellipse with a vertex at the base."""
    rows = []
    for k in range(n // 2 + 1):
        phi = 2.0 * math.pi * k / n
        y = 0.5 - 0.5 * math.cos(phi)
        w = 0.5 * math.sin(phi)
        if w < 1e-12 or (n % 2 == 0 and k == n // 2):
            rows.append((y, 0.0, 0.0))
        else:
            rows.append((y, -w, w))
    return rows


def _outline(
    name: str,
    p2: np.ndarray,
    tris: np.ndarray,
    z: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> LeafOutline:
    pts = np.zeros((len(p2), 3))
    pts[:, :2] = p2
    uvs = np.column_stack([p2[:, 0] + 0.5, p2[:, 1]])
    if z is not None:
        pts = z
    if normals is None:
        normals = np.tile([0.0, 0.0, 1.0], (len(p2), 1))
    return LeafOutline(name, pts, normals, uvs, tris, float(triangle_areas(pts, tris).sum()))


def _flat(name: str, rows) -> LeafOutline:
    p2, tris = _rows(rows)
    return _outline(name, p2, tris)


def _palm(fold_deg: float = 30.0) -> LeafOutline:
    """Two elliptic halves, each tilted up by fold_deg about the midrib (y axis)."""
    ell = _inscribed(8)
    halves = [
        [(y, xl, 0.0) for y, xl, _ in ell],  # left half: x ≤ 0
        [(y, 0.0, xr) for y, _, xr in ell],
    ]  # right half: x ≥ 0
    a = math.radians(fold_deg)
    all_p2, all_p3, all_n, all_t = [], [], [], []
    base = 0
    for side, rows in zip((-1.0, 1.0), halves):
        p2, tris = _rows(rows)
        p3 = np.column_stack([p2[:, 0] * math.cos(a), p2[:, 1], np.abs(p2[:, 0]) * math.sin(a)])
        n = np.tile([-side * math.sin(a), 0.0, math.cos(a)], (len(p2), 1))
        all_p2.append(p2), all_p3.append(p3), all_n.append(n), all_t.append(tris + base)
        base += len(p2)
    return _outline("palm", np.vstack(all_p2), np.vstack(all_t), np.vstack(all_p3), np.vstack(all_n))


def _star(lobes: int = 5, inner: float = 0.45) -> LeafOutline:
    """A palmate star around the card centre, fanned from a centre vertex (not y-monotone)."""
    k = np.arange(2 * lobes)
    ang = math.pi / 2 + math.pi * k / lobes  # a lobe points to the tip
    rad = np.where(k % 2 == 0, 0.5, 0.5 * inner)
    ring = np.column_stack([rad * np.cos(ang), 0.5 + rad * np.sin(ang)])
    p2 = np.vstack([[0.0, 0.5], ring])
    i = np.arange(2 * lobes)
    tris = np.column_stack([np.zeros_like(i), 1 + i, 1 + (i + 1) % (2 * lobes)]).astype(np.int32)
    return _outline("star", p2, tris)


OUTLINES: dict[int, LeafOutline] = {
    0: _flat("elliptic", _inscribed(8)),
    1: _flat("triangle", _inscribed(3)),
    2: _flat("diamond", _inscribed(4)),
    3: _flat("pentagon", _inscribed(5)),
    4: _flat("rectangle", [(0.0, -0.5, 0.5), (1.0, -0.5, 0.5)]),
    5: _flat("round", _inscribed(8)),
    6: _palm(),
    7: _star(),
}


# A triangle card for far LODs whose blades are a few pixels long: the card's base edge and
# its tip's middle, one triangle a leaf instead of two, so a LOD's budget holds twice the
# leaves. It cuts the blade's upper sides off (the rest, `triangle_share`, is drawn larger);
# symmetric about the midrib, so what shows keeps the blade's footprint. UVs stay in the
# card's atlas cell.
TRIANGLE_CARD = LeafOutline(
    "triangle card",
    np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    np.tile([0.0, 0.0, 1.0], (3, 1)),
    np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]]),
    np.array([[0, 1, 2]], dtype=np.int32),
    0.5,
)


def card_corners(n_vertices: int, n_indices: int) -> int:
    """Vertices a leaf of a primitive stamped as cards (4: two triangles a leaf) or triangle
    cards (3: one), told by vertices per triangle; 0 when it is neither (the LeafShape
    outlines with those counts, the diamond and the triangle, read as cards alike)."""
    T = n_indices // 3
    return 4 if T and n_vertices == 2 * T else 3 if T and n_vertices == 3 * T else 0


def in_triangle_card(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether card points (x across −½..½, y base 0 to tip 1) lie in TRIANGLE_CARD."""
    return (y >= 0.0) & (np.abs(x) <= 0.5 * (1.0 - y))


@functools.lru_cache(maxsize=None)
def triangle_share(leaf_shape: int, n: int = 256) -> tuple[float, float]:
    """(share of the blade's area inside TRIANGLE_CARD, height of that part's centroid
    minus the blade's, in lengths): measured on an n × n grid of the outline."""
    o = outline(leaf_shape)
    x, y = np.meshgrid((np.arange(n) + 0.5) / n - 0.5, (np.arange(n) + 0.5) / n)
    p = o.points[:, :2] if o.name != "palm" else np.column_stack([o.uvs[:, 0] - 0.5, o.uvs[:, 1]])
    blade = np.zeros(x.shape, dtype=bool)
    for t in o.triangles:
        a, b, c = p[t]
        d = [(q[0] - r[0]) * (y - r[1]) - (q[1] - r[1]) * (x - r[0]) for r, q in ((a, b), (b, c), (c, a))]
        blade |= (d[0] >= 0) & (d[1] >= 0) & (d[2] >= 0)  # counter-clockwise triangles
    cut = blade & in_triangle_card(x, y)
    return float(cut.sum() / max(blade.sum(), 1)), float(y[cut].mean() - y[blade].mean())


def outline(leaf_shape: int) -> LeafOutline:
    """The outline drawn for a LeafShape code; unknown codes are a user error."""
    try:
        return OUTLINES[int(leaf_shape)]
    except KeyError:
        raise TreegenError(
            f"LeafShape {leaf_shape}: no such leaf shape (allowed 0..{max(OUTLINES)})"
        ) from None


def fill_factor(leaf_shape: int) -> float:
    """Blade area / (length × width) for the outline `leaf_shape` draws."""
    return outline(leaf_shape).area
