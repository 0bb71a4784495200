"""Leaf trios for the far LODs, measured before any plumbing (issue 13, item 1).

    python bench/lod_trios_bench.py [--species ca_black_oak,lombardy_poplar] [--more 3]
        [--group greedy|morton] [--blob 0.17]
    python bench/lod_trios_bench.py --pairs [--more 2]

The near-miss species (oak, cottonwood, larch, poplar: worst switch IoU 0.88-0.90) pass when
their triangle-card LODs (LOD2, LOD3) keep `--more` times the leaves, over budget (the upper
bound, printed as "more"; 3 × at texture 256 in bench/lod_pop_bench.py: larch 0.907 / 0.910,
cottonwood 0.938 / 0.929 at switches 2 / 3). A trio is a try at that within the budget: one triangle carrying
three leaf blobs, each where one of three neighbouring kept leaves is. The triangle's corners
are the three leaves' middles pushed out from their centroid (a blob at barycentric
(0.6, 0.2, 0.2) sits on its leaf when the push is 1 / (0.6 − 0.2) = 2.5); the push is then set
per trio so that the blobs (discs of radius `--blob` in a 1 × 1 UV triangle) carry the three
leaves' cut-out area, and one factor over all trios, fitted on the render in three steps,
brings the cover to the LOD before's. Leaves are grouped by nearest unassigned neighbours
along a Morton order (`greedy`) or three by three along it (`morton`). Masks and scores are
tests/test_lod_budget.py's (silhouette.compare, the −90° view, 384 px, 6 × 6 samples a pixel).

Measured (27 Nov 2026), IoU / cover at switches 2 and 3; now (in budget) → `--more 3` (over
budget: LOD2 0.24, LOD3 0.10 of LOD0's triangles for the oak) → trios of those leaves (in
budget, greedy):
    ca_black_oak     0.899/+0.3  0.902/+2.1 → 0.929/−0.0  0.926/+1.6 → 0.883/+3.0  0.892/+2.4
    lombardy_poplar  0.887/+2.3  0.882/−0.2 → 0.940/+1.5  0.905/+0.8 → 0.817/+2.0  0.864/+1.7
(morton groups: oak 0.854, 0.874; poplar 0.777, 0.853.) Trios lose to the leaves they
replace. The push that carries a trio's area varies 0.4-1.5× the one that puts the blobs on
their leaves (10th-90th percentile), so blobs sit off their leaves, and a trio's plane,
set by where its leaves are, is edge-on to the view as often as a leaf is, for three leaves
at once. Not carried into `make`: the lever is more leaves, which trios do not give.

Leaf pairs (`--pairs`, 28 Nov 2026): mutual nearest kept leaves (of `--more 2` × the leaves)
share one triangle whose texture holds two elliptic blobs, each exactly on its leaf's middle
with its leaf's cut-out area (an atlas of PAIR_BINS cells by blob radius over spacing; the
plane holds the pair's axis, turned to the leaves' mean normal); the few left unpaired stay
triangle cards. Poplar, switches 2 / 3, IoU / cover: now 0.887/+2.3 0.882/−0.2; `--more 2`
0.940/+1.5 0.899/−0.1; pairs 0.858/+0.5 0.873/+0.6 (LOD2 then draws 4,687 triangles of its
6,795). The pairs against the very leaves they carry ("self"): 0.860 and 0.885, and 0.873 /
0.879 with every pair's plane facing the camera, so the shared plane is not what loses. A
pair's triangle is two or three pixels at the switch: its texture is read at a mip where
the blobs and the empty texels between them average into one alpha over the triangle, so
the pair draws as its triangle's footprint, thinned, not as two leaves. The same holds for
trios and the cluster cards (bench/lod_cards_bench.py, which needed texels of a third of a
pixel): at these sizes a triangle's shape is its leaf's shape, and one triangle is one leaf.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import treegen_cli.lod_budget as lod_budget
from treegen_cli.bundled import resolve_species
from treegen_cli.drawable import from_asset
from treegen_cli.leafshapes import card_corners
from treegen_cli.lod import LodOptions
from treegen_cli.materials import MaterialOptions
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.silhouette import compare, coverage_masks, metres_per_pixel

ROOT = Path(__file__).resolve().parent.parent
ALPHA, BETA = 0.6, 0.2  # a blob's barycentric centre at its own corner
UV = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]])  # the trio's texture triangle
TEX = 256  # its texture's side


def trio_texture(r: float) -> np.ndarray:
    """RGBA (TEX, TEX, 4), top row first: three opaque discs of radius `r` in UV, one a corner."""
    v = (np.arange(TEX) + 0.5) / TEX
    x, y = np.meshgrid(v, 1.0 - v)
    inside = np.zeros((TEX, TEX), dtype=bool)
    for i in range(3):
        b = np.full(3, BETA)
        b[i] = ALPHA
        cx, cy = b @ UV
        inside |= (x - cx) ** 2 + (y - cy) ** 2 <= r * r
    img = np.zeros((TEX, TEX, 4), dtype=np.uint8)
    img[..., 1] = 120
    img[..., 3] = np.where(inside, 255, 0)
    return img


def morton(p: np.ndarray, bits: int = 10) -> np.ndarray:
    """Indices of points (n, 3) along a Morton curve over their box."""
    lo, hi = p.min(0), p.max(0)
    q = ((p - lo) / np.maximum(hi - lo, 1e-12) * (2**bits - 1)).astype(np.uint64)
    code = np.zeros(len(p), dtype=np.uint64)
    for b in range(bits):
        for d in range(3):
            code |= ((q[:, d] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + d)
    return np.argsort(code, kind="stable")


def greedy_triples(p: np.ndarray) -> np.ndarray:
    """(T, 3) indices: along a Morton order, each unassigned point with its two nearest
    unassigned neighbours (a bench: a Python loop over trios)."""
    from scipy.spatial import cKDTree

    n, used, out, tree = len(p), np.zeros(len(p), dtype=bool), [], cKDTree(p)
    for i in morton(p):
        if used[i]:
            continue
        k = 8
        while True:
            near = [j for j in np.atleast_1d(tree.query(p[i], k=min(k, n))[1]) if not used[j] and j != i]
            if len(near) >= 2 or k >= n:
                break
            k *= 4
        group = [i] + near[:2]
        used[group] = True
        if len(group) == 3:
            out.append(group)
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def card_fill(part) -> float:
    """Share of a triangle card's area its blade's cut-out covers (sampled in its atlas cell)."""
    alpha = part.texture[..., 3].astype(np.float64) / 255.0
    uv = part.uvs.reshape(-1, 3, 2)[0]
    u = np.random.default_rng(0).random((20000, 2))
    flip = u.sum(1) > 1
    u[flip] = 1 - u[flip]
    pt = uv[0] + u[:, :1] * (uv[1] - uv[0]) + u[:, 1:] * (uv[2] - uv[0])
    H, W = alpha.shape
    a = alpha[
        np.clip(((1 - pt[:, 1]) * H).astype(int), 0, H - 1), np.clip((pt[:, 0] * W).astype(int), 0, W - 1)
    ]
    return float((a >= (part.alpha_cutoff or 0.5)).mean())


def trio_part(part, fill: float, group: str, blob: float, factor: float):
    """The triangle cards of `part` as trios carrying `factor` × their cut-out area."""
    V = part.positions.reshape(-1, 3, 3).astype(np.float64)
    centre = V.mean(1)
    area = 0.5 * np.linalg.norm(np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0]), axis=1)
    if group == "greedy":
        g = greedy_triples(centre)
    else:
        o = morton(centre)
        g = o[: len(o) // 3 * 3].reshape(-1, 3)
    m = centre[g]
    c = m.mean(1, keepdims=True)
    hull = 0.5 * np.linalg.norm(np.cross(m[:, 1] - m[:, 0], m[:, 2] - m[:, 0]), axis=1)
    phi = 3 * np.pi * blob * blob / 0.5  # the blobs' share of the UV triangle
    s0 = 1.0 / (ALPHA - BETA)
    push = np.sqrt((area * fill * factor)[g].sum(1) / (phi * np.maximum(hull, 1e-30)))
    push = np.clip(push, 0.25 * s0, 4.0 * s0)
    W = c + push[:, None, None] * (m - c)
    T = len(W)
    n = np.cross(W[:, 1] - W[:, 0], W[:, 2] - W[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    trio = replace(
        part,
        positions=W.reshape(-1, 3).astype(np.float32),
        normals=np.repeat(n, 3, 0).astype(np.float32),
        indices=np.arange(3 * T, dtype=np.uint32),
        joints=np.zeros((3 * T, 4), dtype=part.joints.dtype),
        weights=np.tile(np.array([1, 0, 0, 0], np.float32), (3 * T, 1)),
        uvs=np.tile(UV.astype(np.float32), (T, 1)),
        texture=trio_texture(blob),
        normal_map=None,
        wrap=("CLAMP", "CLAMP"),
    )
    return trio, np.percentile(push / s0, [10, 90])


PAIR_AT = (0.45, 0.85)  # the blobs' centres along the pair's texture triangle (apex 0, base 1)
PAIR_HALF = 0.2  # a blob's half-width across it, in UV
PAIR_BINS = np.array([0.08, 0.12, 0.18, 0.26, 0.36, 0.5, 0.7, 1.0])  # blob radius / spacing
PAIR_CELL = (128, 256)  # texels of one bin's cell (wide, tall)


def pair_texture() -> np.ndarray:
    """RGBA, top row first: one cell per PAIR_BINS, each an isosceles triangle (apex at v 0)
    holding two opaque ellipses on its axis at PAIR_AT."""
    cw, ch = PAIR_CELL
    k_n = len(PAIR_BINS)
    u, v = np.meshgrid((np.arange(cw * k_n) + 0.5) / (cw * k_n), 1.0 - (np.arange(ch) + 0.5) / ch)
    k = np.minimum((u * k_n).astype(int), k_n - 1)
    across, along = (u * k_n - k - 0.5) / PAIR_HALF, 0.4 * PAIR_BINS[k]
    inside = np.zeros(u.shape, dtype=bool)
    for at in PAIR_AT:
        inside |= across**2 + ((v - at) / along) ** 2 <= 1.0
    img = np.zeros((ch, cw * k_n, 4), dtype=np.uint8)
    img[..., 1] = 120
    img[..., 3] = np.where(inside, 255, 0)
    return img


def mutual_pairs(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((P, 2) pairs of mutual nearest neighbours among `p`, found again among the unpaired
    a few times; indices left unpaired)."""
    from scipy.spatial import cKDTree

    free, pairs = np.ones(len(p), dtype=bool), [np.zeros((0, 2), dtype=np.int64)]
    for _ in range(12):
        idx = np.flatnonzero(free)
        if len(idx) < 2:
            break
        nn = cKDTree(p[idx]).query(p[idx], k=2)[1][:, 1]
        a = np.flatnonzero((nn[nn] == np.arange(len(idx))) & (np.arange(len(idx)) < nn))
        pairs.append(np.stack([idx[a], idx[nn[a]]], 1))
        free[idx[a]] = free[idx[nn[a]]] = False
    return np.concatenate(pairs), np.flatnonzero(free)


def pair_part(part, fill: float, factor: float):
    """(pairs, singles): `part`'s triangle cards two to a triangle carrying `factor` × their
    cut-out area, and the unpaired ones as they were, grown alike."""
    V = part.positions.reshape(-1, 3, 3).astype(np.float64)
    c = V.mean(1)
    n = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.maximum(2.0 * area[:, None], 1e-30)
    P, single = mutual_pairs(c)
    A, B = c[P[:, 0]], c[P[:, 1]]
    d = np.linalg.norm(B - A, axis=1)
    e = (B - A) / np.maximum(d, 1e-30)[:, None]
    na, nb = n[P[:, 0]], n[P[:, 1]]
    m = na + nb * np.sign(np.sum(na * nb, 1, keepdims=True) + 1e-12)
    m -= np.sum(m * e, 1, keepdims=True) * e
    flat = np.linalg.norm(m, axis=1) < 1e-6
    m[flat] = np.cross(e[flat], [0.0, 0.0, 1.0]) + 1e-3
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    side = np.cross(m, e)
    r = np.sqrt(factor * fill * 0.5 * (area[P[:, 0]] + area[P[:, 1]]) / np.pi)
    rho = r / np.maximum(d, 1e-30)
    k = np.clip(np.searchsorted(0.5 * (PAIR_BINS[1:] + PAIR_BINS[:-1]), rho), 0, len(PAIR_BINS) - 1)
    length = d / (PAIR_AT[1] - PAIR_AT[0])
    width = r * rho / PAIR_BINS[k] / PAIR_HALF  # the binned blob's length, its area kept in width
    apex = A - e * (PAIR_AT[0] * length)[:, None]
    base = apex + e * length[:, None]
    W = np.stack([apex, base - side * (0.5 * width)[:, None], base + side * (0.5 * width)[:, None]], 1)
    k_n, zero, one = len(PAIR_BINS), np.zeros(len(k)), np.ones(len(k))
    uv = np.stack(
        [
            np.stack([(k + 0.5) / k_n, zero], 1),
            np.stack([k / k_n, one], 1),
            np.stack([(k + 1) / k_n, one], 1),
        ],
        1,
    )
    Vs = V[single]
    Vs = Vs.mean(1, keepdims=True) + np.sqrt(factor) * (Vs - Vs.mean(1, keepdims=True))
    pairs = _triangles(
        part,
        W,
        np.repeat(m, 3, 0),
        uv.reshape(-1, 2),
        texture=pair_texture(),
        normal_map=None,
        wrap=("CLAMP", "CLAMP"),
    )
    singles = _triangles(
        part, Vs, np.repeat(n[single], 3, 0), part.uvs.reshape(-1, 3, 2)[single].reshape(-1, 2)
    )
    return pairs, singles


def _triangles(part, W: np.ndarray, normals: np.ndarray, uvs: np.ndarray, **more):
    """`part` drawing the triangles W (T, 3, 3), unskinned."""
    T = len(W)
    return replace(
        part,
        positions=W.reshape(-1, 3).astype(np.float32),
        normals=normals.astype(np.float32),
        indices=np.arange(3 * T, dtype=np.uint32),
        joints=np.zeros((3 * T, 4), dtype=part.joints.dtype),
        weights=np.tile(np.array([1, 0, 0, 0], np.float32), (3 * T, 1)),
        uvs=uvs.astype(np.float32),
        **more,
    )


def score(a, b, distance: float, opts) -> tuple[float, float]:
    masks, _ = coverage_masks([a, b], metres_per_pixel(distance, opts), (-90.0,), 384)
    return compare(masks[0][0], masks[1][0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="ca_black_oak,lombardy_poplar")
    ap.add_argument("--more", type=float, default=3.0)
    ap.add_argument("--group", choices=("greedy", "morton"), default="greedy")
    ap.add_argument("--blob", type=float, default=0.17)
    ap.add_argument("--pairs", action="store_true", help="leaf pairs instead of trios")
    args = ap.parse_args()
    opts = LodOptions()
    make = MakeOptions(wind=None, lod=opts, materials=MaterialOptions(texture_size=128))
    real = lod_budget.plan_lod

    def more(tree, bark0, leaf0, budget, mesh, px, mesh0=None, triangle_cards=False, max_leaves=None):
        if triangle_cards:  # the leaves' part of the budget × --more
            share = bark0 / (bark0 + leaf0)
            budget, max_leaves = budget * (share + (1 - share) * args.more), None
        return real(tree, bark0, leaf0, budget, mesh, px, mesh0, triangle_cards, max_leaves)

    shape, last = ("pairs", "self (pairs vs more)") if args.pairs else ("trios", "push 10-90 %")
    print(f"{'species':<20}{'switch':>7}{'now':>14}{'more':>14}{shape:>14}   {last}")
    for name in args.species.split(","):
        params = load_params(resolve_species(name))
        now, _ = build_asset(params, 0, make)
        lod_budget.plan_lod = more
        try:
            big, _ = build_asset(params, 0, make)
        finally:
            lod_budget.plan_lod = real
        geo = [k for k, lod in enumerate(now.lods) if lod.impostor is None]
        prev_now, prev_big, prev_trio = (from_asset(now, 1),) * 3
        for k in geo[2:]:
            d = now.lods[k].distance
            cur_now, cur_big = from_asset(now, k), from_asset(big, k)
            i = next(
                i
                for i, p in enumerate(cur_big.parts)
                if p.name == "leaves" and card_corners(len(p.positions), len(p.indices)) == 3
            )
            fill, factor, spread = card_fill(cur_big.parts[i]), 1.0, ""
            for _ in range(4 if args.pairs else 3):  # the cover fitted to the LOD before's on the render
                if args.pairs:
                    new = list(pair_part(cur_big.parts[i], fill, factor))
                else:
                    trio, push = trio_part(cur_big.parts[i], fill, args.group, args.blob, factor)
                    new, spread = [trio], f"{push[0]:.2f}-{push[1]:.2f}"
                cur_trio = replace(cur_big, parts=[p for j, p in enumerate(cur_big.parts) if j != i] + new)
                t_iou, t_cov = score(prev_trio, cur_trio, d, opts)
                factor /= t_cov**1.2
            if args.pairs:
                s_iou, s_cov = score(cur_big, cur_trio, d, opts)
                spread = f"{s_iou:.3f}/{100 * (s_cov - 1):+.1f}%"
            n_iou, n_cov = score(prev_now, cur_now, d, opts)
            b_iou, b_cov = score(prev_big, cur_big, d, opts)
            print(
                f"{name:<20}{k:>7}{n_iou:>8.3f}{100 * (n_cov - 1):>+5.1f}%{b_iou:>8.3f}{100 * (b_cov - 1):>+5.1f}%"
                f"{t_iou:>8.3f}{100 * (t_cov - 1):>+5.1f}%   {spread}",
                flush=True,
            )
            prev_now, prev_big, prev_trio = cur_now, cur_big, cur_trio


if __name__ == "__main__":
    main()
