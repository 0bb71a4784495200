"""Leaf trios for the far LODs, measured before any plumbing (issue 13, item 1).

    python bench/lod_trios_bench.py [--species ca_black_oak,lombardy_poplar] [--more 3]
        [--group greedy|morton] [--blob 0.17]

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
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

import treegen_cli.lod_budget as lod_budget
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


def score(a, b, distance: float, opts) -> tuple[float, float]:
    masks, _ = coverage_masks([a, b], metres_per_pixel(distance, opts), (-90.0,), 384)
    return compare(masks[0][0], masks[1][0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="ca_black_oak,lombardy_poplar")
    ap.add_argument("--more", type=float, default=3.0)
    ap.add_argument("--group", choices=("greedy", "morton"), default="greedy")
    ap.add_argument("--blob", type=float, default=0.17)
    args = ap.parse_args()
    opts = LodOptions()
    make = MakeOptions(wind=None, lod=opts, materials=MaterialOptions(texture_size=128))
    real = lod_budget.plan_lod

    def more(tree, bark0, leaf0, budget, mesh, px, mesh0=None, triangle_cards=False, max_leaves=None):
        if triangle_cards:  # the leaves' part of the budget × --more
            share = bark0 / (bark0 + leaf0)
            budget, max_leaves = budget * (share + (1 - share) * args.more), None
        return real(tree, bark0, leaf0, budget, mesh, px, mesh0, triangle_cards, max_leaves)

    print(f"{'species':<20}{'switch':>7}{'now':>14}{'more':>14}{'trios':>14}   push 10-90 %")
    for name in args.species.split(","):
        params = load_params(ROOT / "species" / f"{name}.txt")
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
            fill, factor = card_fill(cur_big.parts[i]), 1.0
            for _ in range(3):  # the trios' cover fitted to the LOD before's on the render
                trio, spread = trio_part(cur_big.parts[i], fill, args.group, args.blob, factor)
                cur_trio = replace(
                    cur_big, parts=[trio if j == i else p for j, p in enumerate(cur_big.parts)]
                )
                t_iou, t_cov = score(prev_trio, cur_trio, d, opts)
                factor /= t_cov**1.2
            n_iou, n_cov = score(prev_now, cur_now, d, opts)
            b_iou, b_cov = score(prev_big, cur_big, d, opts)
            print(
                f"{name:<20}{k:>7}{n_iou:>8.3f}{100 * (n_cov - 1):>+5.1f}%{b_iou:>8.3f}{100 * (b_cov - 1):>+5.1f}%"
                f"{t_iou:>8.3f}{100 * (t_cov - 1):>+5.1f}%   {spread[0]:.2f}-{spread[1]:.2f}",
                flush=True,
            )
            prev_now, prev_big, prev_trio = cur_now, cur_big, cur_trio


if __name__ == "__main__":
    main()
