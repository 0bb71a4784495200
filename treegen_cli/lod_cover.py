"""What a tree covers on screen at a LOD switch, estimated without a renderer: the crown's
covered area (m²) seen from the side, pixel by pixel, as the renderer's coverage mask counts it.

Leaf cards (their area thinned by the blade's fill factor, as the renderer's hashed cut-out
covers them from a distance) and stem segments are sampled with points about a pixel apart; each point carries its share of the projected area into a
pixel-size cell, and a cell covers 1 − exp(−area / cell area) of itself (the Boolean model:
what lands in one cell overlaps at random). Blades that clump — leaflets converging on a fan,
needles on a twig — land in the same cells and cover less than their summed area, which a sum
of areas (or cells the size of a leaf) misses; stems thinner than a pixel count for their width.

    grid = Grid.around(tree, px)
    target = grid.cover(tree_area(tree, grid))
    stems, blades = stem_area(lod, grid), Blades(lod, grid.px, 0.25)
    f = solve_factor(lambda f: grid.cover(stems + blades.area(grid, f)), target, 0.25, 8.0)
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from .leafshapes import fill_factor, in_triangle_card, triangle_share
from .tree import Tree

AZIMUTHS = (0.0, 90.0)  # side views, degrees about Z (orthographic: 180° mirrors 0°)
SAMPLES_PER_PX = 1.5  # sample points per pixel of blade or stem extent
STEM_SAMPLES_PER_PX = 3.0  # along and across a stem: a stem wider than a pixel fills the
# cells inside it only if each gets its share of samples whatever the stem's slant
MAX_ALONG = 256  # samples per stem segment, at most
MAX_ACROSS = 64  # samples across a stem, at most
MAX_BLADE = 64  # samples along a blade, at most (and across it)
MAX_SAMPLES = 300_000  # blade samples of a whole crown, about: a crown of many blades is
# measured in cells coarser than a pixel (cell_size)
MAX_CELLS = 1024  # cells across the tree, at most (a near switch is measured coarser)
OPAQUE_EPS = 0.01  # a blade covers at most 1 − this of a cell (keeps the log finite)
LOBE_REACH = 0.85  # a lobed trunk's seen width over its round one, per unit LobeDepth: the
# outline touches a lobe's tip within half a lobe of the side (mean cos over that arc)
FIRST_STEP = math.log(1.25)  # solve_factor: the second try, from the first
MAX_STEP = math.log(2.0)  # solve_factor: the longest secant step (log factor)
MARGIN = 0.25  # the grid reaches this share of the tree's size beyond its bounds


def _axes() -> tuple[np.ndarray, np.ndarray]:
    """Per view: the viewing direction and the screen's horizontal axis, (V, 3) each."""
    a = np.radians(AZIMUTHS)
    view = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    side = np.stack([-np.sin(a), np.cos(a), np.zeros_like(a)], axis=1)
    return view, side


def _project(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V, P) screen coordinates (horizontal, vertical) of (P, 3) points or directions."""
    _, side = _axes()
    return side @ points.T, np.broadcast_to(points[:, 2], (len(AZIMUTHS), points.shape[0]))


def _counts(extent: float, px: float, cap: int) -> int:
    """Samples SAMPLES_PER_PX per pixel over `extent` (a typical size), 1 to `cap`."""
    return int(min(cap, max(1, math.ceil(SAMPLES_PER_PX * extent / max(px, 1e-12)))))


def cell_size(tree: Tree, px: float) -> float:
    """Cell for `tree` at pixels of `px`: the pixel, or coarser where the tree would span more
    than MAX_CELLS of them, or sampling every blade SAMPLES_PER_PX per cell would take more
    than MAX_SAMPLES samples."""
    size = float(np.ptp(tree.node_pos, axis=0).max()) if tree.n_nodes else 0.0
    px = max(px, size / MAX_CELLS)
    if not tree.n_leaves:
        return px
    blade = float(np.median(tree.leaf_size[:, 0] * tree.leaf_size[:, 1]))
    return max(px, SAMPLES_PER_PX * math.sqrt(blade * tree.n_leaves / MAX_SAMPLES))


@dataclass(frozen=True)
class Grid:
    """Pixel cells over the side views of a tree: per view the screen origin (u, w), cells of
    `px` metres, `shape` (nu, nw). Points outside land in the border cells."""

    px: float
    origin: np.ndarray  # (V, 2)
    shape: tuple[int, int]

    @staticmethod
    def around(tree: Tree, px: float) -> "Grid":
        """Cells of `cell_size(tree, px)` over `tree` seen from the side, with a margin."""
        px = cell_size(tree, px)
        pts = np.concatenate([tree.node_pos, tree.leaf_pos]) if tree.n_leaves else tree.node_pos
        u, w = _project(pts)
        lo = np.stack([u.min(1), w.min(1)], 1)
        hi = np.stack([u.max(1), w.max(1)], 1)
        pad = MARGIN * float(np.max(hi - lo)) + 2 * px
        shape = np.ceil(((hi - lo).max(0) + 2 * pad) / px).astype(np.int64) + 1
        return Grid(px, lo - pad, (int(shape[0]), int(shape[1])))

    def cover(self, area: np.ndarray) -> float:
        """Covered area (m²), mean over the views, of per-cell areas (V, cells): Boolean model."""
        a = self.px * self.px
        return float(np.sum(-np.expm1(-area / a))) * a / area.shape[0]


def _segments(tree: Tree, px: float, radius_factor, sides: np.ndarray | None = None):
    """Stem segments (between consecutive nodes of a stem) sampled along and across; a stem
    drawn with `sides` (S,) sides is as wide, in each view, as its polygon turned as the mesh
    turns it (polygon_widths), or round. `radius_factor`: one, or one per segment."""
    seg = tree.segments
    p0, p1 = tree.node_pos[seg], tree.node_pos[seg + 1]
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    width = (tree.node_radius[seg] + tree.node_radius[seg + 1]) * radius_factor  # 2 × mean radius
    lobed = tree.params.lobes > 0 and tree.params.lobe_depth != 0
    if lobed:  # a lobed trunk's outline reaches its lobes' tips
        width = width * np.where(
            tree.stem_level[tree.node_stem[seg]] == 0, 1.0 + LOBE_REACH * abs(tree.params.lobe_depth), 1.0
        )
    view, side = _axes()
    axis = d / np.maximum(length, 1e-12)[:, None]
    sin = np.sqrt(np.maximum(1.0 - (view @ axis.T) ** 2, 0.0))  # (V, seg)
    # across the stem on screen: perpendicular to its projected axis
    au, aw = side @ axis.T, np.broadcast_to(axis[:, 2], sin.shape)
    norm = np.maximum(np.hypot(au, aw), 1e-12)
    width = np.broadcast_to(width, sin.shape)  # (V, seg)
    if sides is not None:
        across3 = (-aw / norm)[:, :, None] * side[:, None, :] + (au / norm)[:, :, None] * np.array(
            [0.0, 0.0, 1.0]
        )
        width = width * polygon_widths(tree.node_frame[seg], sides[tree.node_stem[seg]], across3)
    n = np.clip(np.ceil(STEM_SAMPLES_PER_PX * length / max(px, 1e-12)), 1, MAX_ALONG).astype(np.int64)
    m = np.ceil(STEM_SAMPLES_PER_PX * width.max(axis=0) / max(px, 1e-12))
    m = np.clip(m, 1, MAX_ACROSS).astype(np.int64)
    nm = n * m
    which = np.repeat(np.arange(seg.size), nm)
    k = np.arange(which.size) - np.repeat(np.cumsum(nm) - nm, nm)
    mw = m[which]
    q, r = np.divmod(k, mw)
    along = (q + 0.5) / n[which]
    across = (r + 0.5) / mw - 0.5
    (u0, w0), (du, dw) = _project(p0), _project(d)  # per segment, then along it

    def per_sample(x: np.ndarray) -> np.ndarray:  # (V, seg) → (V, P), a new array
        return np.take(x, which, axis=1)

    # u0 + along·du − off·(aw/norm), summed in place in that order (the same bits, fewer
    # (V, P) temporaries: the stems' samples are most of the cover estimate's memory traffic)
    off = per_sample(width)
    off *= across
    u, w = per_sample(u0), per_sample(w0)
    for out, step, turn in ((u, du, -aw / norm), (w, dw, au / norm)):
        t = per_sample(step)
        t *= along
        out += t
        t = per_sample(turn)  # −aw/norm is −(aw/norm) exactly: u − off·(aw/norm), to the bit
        t *= off
        out += t
    seen = sin * width * length[None, :] / nm[None, :]
    return u, w, per_sample(seen), which


def polygon_widths(frames: np.ndarray, sides: np.ndarray, across: np.ndarray) -> np.ndarray:
    """(V, G) seen width, in diameters, of G regular prisms of `sides` (G,) sides whose ring
    vertices lie at angles 2πj/sides from column 0 of `frames` (G, 3, 3) toward column 1 (as
    mesh.bark draws them), measured along `across` (V, G, 3): a square seen on its face is
    0.71 of its diagonal, so which way a far LOD's few sides face matters per view."""
    out = np.ones(across.shape[:2])
    for n in np.unique(sides):
        g = np.flatnonzero(sides == n)
        t = 2.0 * np.pi * np.arange(n) / n
        radial = (
            np.cos(t)[None, :, None] * frames[g][:, None, :, 0]
            + np.sin(t)[None, :, None] * frames[g][:, None, :, 1]
        )
        proj = np.einsum("gjk,vgk->vgj", radial, across[:, g])
        out[:, g] = 0.5 * (proj.max(axis=2) - proj.min(axis=2))
    return out


def stem_area(
    tree: Tree,
    grid: Grid,
    radius_factor: float = 1.0,
    sides: np.ndarray | None = None,
    girth: np.ndarray | None = None,
) -> np.ndarray:
    """(V, cells) area of `tree`'s stems (radii × `radius_factor`, × `girth` (S,) per stem as
    the mesh widens a LOD's (mesh.girth), drawn with `sides` (S,) sides, or round) per cell of
    `grid`."""
    if tree.n_nodes < 2:
        return np.zeros((len(AZIMUTHS), grid.shape[0] * grid.shape[1]))
    if girth is not None:
        radius_factor = radius_factor * girth[tree.node_stem[tree.segments]]
    u, w, seen, which = _segments(tree, grid.px, radius_factor, sides)
    return _opaque(grid, u, w, seen, which)


class Blades:
    """A tree's leaf blades projected once into the side views, to be binned into a Grid at
    any growth factor (one for all or one per blade) without projecting them again."""

    def __init__(
        self, tree: Tree, px: float, length_share: float, reach: float = 1.0, triangle: bool = False
    ):
        """`px`: the grid's cell (Grid.px); `reach`: a typical growth factor to sample for;
        `triangle`: the blades are drawn as triangle cards (mesh/leaves.py)."""
        F = tree.leaf_frame
        self.length, self.width, self.share = tree.leaf_size[:, 0], tree.leaf_size[:, 1], length_share
        # sample spacing for blades grown by `reach` (a typical factor)
        r = max(reach, 1e-6)
        na = _counts(float(np.median(self.length)) * r**length_share, px, MAX_BLADE)
        nw = _counts(float(np.median(self.width)) * r ** (1 - length_share), px, MAX_BLADE)
        # the card's box, thinned by the fill factor: what the renderer's hashed cut-out
        # covers once a texel spans a pixel or more
        ia, iw = np.divmod(np.arange(na * nw), nw)
        self.s = (ia + 0.5) / na - 0.5  # along the blade, from its middle
        self.t = (iw + 0.5) / nw - 0.5  # across it
        mid = tree.leaf_middle
        view, _ = _axes()
        self.mu, self.mw = _project(mid)
        self.lu, self.lw = _project(F[:, :, 1])
        self.wu, self.ww = _project(F[:, :, 0])
        self.fill = fill_factor(tree.params.leaf_shape)
        drawn = self.fill
        if triangle:  # the samples inside the triangle card carry the blade's share in it
            inside = in_triangle_card(self.t, self.s + 0.5)  # never empty: the middle is in
            self.s, self.t = self.s[inside], self.t[inside]
            drawn = self.fill * triangle_share(int(tree.params.leaf_shape))[0]
        self.seen = np.abs(view @ F[:, :, 2].T) * (self.length * self.width * drawn / self.s.size)

    def area(self, grid: Grid, factor) -> np.ndarray:
        """(V, cells) area of the blades grown by `factor` in area about their middles."""
        f = np.broadcast_to(np.asarray(factor, dtype=np.float64), self.length.shape)
        # in cells: a sample is its blade's middle plus s lengths and t widths, so each view's
        # (L, S) coordinates are one (L, 3) @ (3, S) product (no (V, L, S) temporaries)
        ls = self.length * f**self.share / grid.px
        ws = self.width * f ** (1.0 - self.share) / grid.px
        st = np.stack([np.ones_like(self.s), self.s, self.t])
        cells = []
        for v in range(self.mu.shape[0]):
            u = np.stack([(self.mu[v] - grid.origin[v, 0]) / grid.px, ls * self.lu[v], ws * self.wu[v]], 1)
            w = np.stack([(self.mw[v] - grid.origin[v, 1]) / grid.px, ls * self.lw[v], ws * self.ww[v]], 1)
            cells.append(_cell_index(grid, u @ st, w @ st))
        return _opaque_blades(grid, cells, self.seen * f[None, :])


def _cell_index(grid: Grid, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The flat cell index (u · nw + w, clipped to the grid) of samples at (u, w) in cells
    from the view's origin (overwritten)."""
    nu, nw = grid.shape
    iu = np.floor(u, out=u).astype(np.int64)  # (NaN: the border cell)
    np.clip(iu, 0, nu - 1, out=iu)  # in place: a sample count of int64s less to allocate
    iw = np.floor(w, out=w).astype(np.int64)
    np.clip(iw, 0, nw - 1, out=iw)
    iu *= nw
    iu += iw
    return iu


def _cells(grid: Grid, u: np.ndarray, w: np.ndarray, v: int) -> np.ndarray:
    """The flat cell index (u · nw + w, clipped to the grid) of view `v`'s samples at (u, w)."""
    return _cell_index(grid, (u - grid.origin[v, 0]) / grid.px, (w - grid.origin[v, 1]) / grid.px)


def _effective(c: np.ndarray, a: float) -> np.ndarray:
    """The area −log(1 − c)·a a piece covering the share c of a cell of area `a` enters as
    (see _opaque)."""
    return -np.log1p(-np.minimum(c, 1.0 - OPAQUE_EPS)) * a


def _opaque_blades(grid: Grid, cells: list[np.ndarray], seen: np.ndarray) -> np.ndarray:
    """(V, cells) effective area of blade samples in `cells` (per view, (L, S) flat cell
    indices), each carrying its blade's `seen` (V, L): _opaque with one piece per blade, its
    runs found by sorting each blade's S samples (a sort of all samples at once costs several
    times more)."""
    nu, nw = grid.shape
    a = grid.px * grid.px
    out = np.zeros((len(cells), nu * nw))
    for v, cell in enumerate(cells):
        L, S = cell.shape
        cell.sort(axis=1)  # (L, S): runs of one blade's samples in a cell
        flat = cell.reshape(-1)  # compared as one row (short rows cost per row), then each
        first = np.empty(L * S, dtype=bool)  # blade's first sample starts a run
        np.not_equal(flat[1:], flat[:-1], out=first[1:])
        first[::S] = True
        at = np.flatnonzero(first)
        runs = np.diff(at, append=L * S)
        c = runs * seen[v][at // S] / a
        out[v] = np.bincount(flat[at], weights=_effective(c, a), minlength=nu * nw)
    return out


def _opaque(grid: Grid, u: np.ndarray, w: np.ndarray, seen: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """(V, cells) effective area of samples at (u, w) (V, P) carrying `seen` (V, P), each of
    one opaque `piece` (P,) (a blade, a stem segment). One piece's samples in one cell sum to
    the share c of the cell it covers and enter as −log(1 − c) of the cell's area, so that
    Grid.cover's Boolean model counts a piece filling a cell as covering c of it (a plain sum
    would count 1 − e^−c, a third short for a blade as big as a pixel or a stem a pixel wide);
    specks well under a pixel add as before."""
    V, P = u.shape
    nu, nw = grid.shape
    n = nu * nw
    a = grid.px * grid.px
    out = np.zeros((V, n))
    for v in range(V):
        key = piece.astype(np.int64) * n + _cells(grid, u[v], w[v], v)
        # runs of one piece's samples in a cell; a stable sort (pieces come in order, their
        # samples mostly so) sums each run in the samples' order, as np.unique's inverse did
        order = np.argsort(key, kind="stable")
        key = key[order]
        first = np.ones(P, dtype=bool)
        np.not_equal(key[1:], key[:-1], out=first[1:])
        c = np.bincount(np.cumsum(first) - 1, weights=seen[v][order]) / a
        out[v] = np.bincount(key[first] % n, weights=_effective(c, a), minlength=n)
    return out


def tree_area(
    tree: Tree, grid: Grid, sides: np.ndarray | None = None, stems: np.ndarray | None = None
) -> np.ndarray:
    """(V, cells) area of all of `tree` (blades as they are, stems drawn with `sides`) per
    cell of `grid`; `stems`: its stem_area there, already measured."""
    area = stem_area(tree, grid, sides=sides) if stems is None else stems
    if tree.n_leaves:
        area = area + Blades(tree, grid.px, 0.25).area(grid, 1.0)
    return area


_COVERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # Tree → {grid key: cover}


def tree_cover(tree: Tree, grid: Grid, sides: np.ndarray | None = None) -> float:
    """grid.cover(tree_area(tree, grid, sides)), kept per tree (weakly) and grid: a make's LODs
    measure LOD0 at each switch, and switches whose pixels are under cell_size's floor share
    one grid (the aspen's LOD1 and LOD2: 40 ms again for the same number)."""
    key = (grid.px, grid.shape, grid.origin.tobytes(), None if sides is None else sides.tobytes())
    memo = _COVERS.setdefault(tree, {})
    if key not in memo:
        memo[key] = grid.cover(tree_area(tree, grid, sides))
    return memo[key]


def solve_factor(
    cover_at, target: float, lo: float, hi: float, tol: float = 0.005, steps: int = 10, start: float = 1.0
) -> float:
    """The factor in [lo, hi] at which the increasing `cover_at` meets `target` (within `tol`
    of it), or the clamp it cannot reach past. Secant steps on log(factor) from `start` (a LOD
    usually needs a factor near 1: its per-leaf factors already hold the area it lost), then
    regula falsi (Illinois) once the target is bracketed. Each call of `cover_at` bins every
    blade (lod_cover's main cost in `make`): 1-6 calls over the bundled species, where
    bracketing [lo, hi] first took 4-7."""
    a_lo, a_hi = math.log(lo), math.log(hi)
    x0 = min(max(math.log(start), a_lo), a_hi)
    f0 = cover_at(math.exp(x0)) - target
    if abs(f0) <= tol * target:
        return math.exp(x0)
    below = (x0, f0) if f0 < 0 else None  # the bracket's ends seen so far
    above = (x0, f0) if f0 > 0 else None
    x1 = min(max(x0 + (FIRST_STEP if f0 < 0 else -FIRST_STEP), a_lo), a_hi)
    side = 0
    for _ in range(steps):
        f1 = cover_at(math.exp(x1)) - target
        if abs(f1) <= tol * target:
            return math.exp(x1)
        if f1 < 0:
            if x1 >= a_hi:
                return hi  # out of reach even at the clamp
            if above is not None and side == -1:
                above = (above[0], 0.5 * above[1])
            below, side = (x1, f1), -1
        else:
            if x1 <= a_lo:
                return lo
            if below is not None and side == 1:
                below = (below[0], 0.5 * below[1])
            above, side = (x1, f1), 1
        if below is not None and above is not None:  # regula falsi, Illinois variant
            (a, fa), (b, fb) = below, above
            x2 = (a * fb - b * fa) / (fb - fa)
        else:  # secant through the last two points, at most MAX_STEP on, towards the target
            slope = (f1 - f0) / (x1 - x0) if x1 != x0 else 0.0
            step = -f1 / slope if slope > 0 else (MAX_STEP if f1 < 0 else -MAX_STEP)  # flat: stride
            x2 = x1 + max(-MAX_STEP, min(MAX_STEP, step))
            x2 = min(max(x2, a_lo), a_hi)
        x0, f0, x1 = x1, f1, x2
    # out of steps: the bracket's next point, else the last factor tried (not an untried guess)
    return math.exp(x1 if below is not None and above is not None else x0)
