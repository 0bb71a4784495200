"""Leaf-cluster cards for the far LODs, measured before any plumbing (issue 13, item 1).

    python bench/lod_cards_bench.py [--species quaking_aspen,...] [--views -90,-45]
        [--texel 1.0] [--measure-ss 2] [--stems] [--nest] [--keep 1,1] [--planes 2]
        [--area 1,1] [--floor]

LOD2 and LOD3's leaves are replaced by cluster cards in memory and the switches are measured as
tests/test_lod_budget.py does (silhouette.compare, 384 px), on the test's view and others:
  * clusters: LOD0's leaves (and, with the twigs the LOD drops, their bark segments) grouped
    in voxels sized so that the clusters' crossed cards (two vertical quads, a seeded azimuth
    per cluster, 4 triangles; `--planes 3`: three at 60°) use the triangles LOD k's leaves had;
  * each card's texture is its cluster projected along the card's normal, point-sampled at
    `--texel` pixels of the switch distance (binary alpha from the leaf atlas; bark opaque),
    shelf-packed into one atlas per LOD.
`--floor` prints the measure's own noise: LOD0 against itself moved by 0.1 and 0.25 pixel.

Measured (26 Nov 2026, this box; texel 1 px, leaves only, views −90° and −45°, the test's
2×2 samples a pixel; IoU the worse view, cover the one farther from 1, then in brackets the
measure's floor: LOD0 against itself moved 0.1 px):

                      switch 2 (LOD1→2): leaves → cards         switch 3 (LOD2→3): leaves → cards
  balsam_fir          0.941 +1.2% → 0.952 +0.7%  (0.983)        0.938 −1.1% → 0.942  +3.1%  (0.970)
  black_tupelo        0.877 +2.1% → 0.894 +1.3%  (0.959)        0.885 +1.4% → 0.873  +7.3%  (0.941)
  ca_black_oak        0.835 +2.0% → 0.859 −5.3%  (0.944)        0.851 +0.8% → 0.831  −2.2%  (0.916)
  desert_bush         0.877 −1.5% → 0.888 −8.4%  (0.969)        0.814 −4.3% → 0.840 −12.8%  (0.943)
  eastern_cottonwood  0.824 −1.0% → 0.860 +1.6%  (0.966)        0.846 +3.0% → 0.863  +2.1%  (0.944)
  european_larch      0.813 +6.0% → 0.793 −3.3%  (0.756)        0.776 −3.7% → 0.745  −9.5%  (0.735)
  fan_palm            0.832 −4.6% → 0.759 +3.8%  (0.981)        0.761 −4.9% → 0.776 −10.9%  (0.963)
  lombardy_poplar     0.782 +2.7% → 0.821 −2.4%  (0.928)        0.783 +2.6% → 0.779 +15.0%  (0.892)
  palm                0.783 +3.6% → 0.776 +8.6%  (0.909)        0.762 +3.6% → 0.716  +3.0%  (0.854)
  quaking_aspen       0.888 +0.6% → 0.906 +2.1%  (0.976)        0.879 −2.0% → 0.911  +1.8%  (0.957)
  rush                0.949 +0.9% → 0.927 −5.0%  (0.918)        0.886 −2.3% → 0.893  −8.5%  (0.867)
  sassafras           0.880 +0.6% → 0.906 +1.2%  (0.965)        0.882 −0.5% → 0.889  +5.4%  (0.946)
  tamarack            0.862 +1.4% → 0.851 +5.7%  (0.925)        0.855 −1.2% → 0.829  +7.6%  (0.890)
  weeping_willow      0.950 +0.5% → 0.948 +0.9%  (0.967)        0.948 +1.4% → 0.936  +3.2%  (0.956)
  (shave_grass: leafless.) Cards CPU (clusters, rasterising, PNG): aspen 0.34–0.46 s, oak 0.8–1.4 s,
  willow 15 s; aspen atlases 1024² (LOD2, 360 KB) and 512×256 (LOD3, 48 KB).

Variants (same measure unless said):
  --stems (dropped twigs' bark drawn into the cards) fixes the lost cover: desert_bush switch 2/3
    0.908 −1.4% / 0.848 −1.3%, rush 0.931 / 0.894 −4.0%, oak 0.863 +1.3% / 0.848 +3.5%,
    fan_palm 0.767 +7.5% / 0.790 −6.3%.
  --nest (LOD3's clusters unions of LOD2's, same card azimuths): no gain (oak switch 3 0.831,
    sassafras 0.890, aspen 0.909).
  --keep 1,0.93 --nest (thin LOD3's texels): cover +5.3 → +2.8 % (sassafras), IoU 0.890 → 0.891.
  --texel 0.35 --stems with 8×8 samples: oak 0.891 / 0.919, palm 0.824 / 0.848; the oak's LOD2
    atlas is then 4096 × 2048 (2.4 MB PNG). Cards all facing the view (one azimuth, −90°):
    oak 0.925 / 0.939; the rest is a cluster projected on a card seen from another side.
  --planes 3 (three cards at 60°, fewer and larger clusters): switch 3 rises (aspen 0.924,
    sassafras 0.909, tupelo 0.899, oak 0.841) but a leaf on three cards over-covers LOD2 by +5
    to +11 % (switch 2 aspen 0.902, sassafras 0.898, tupelo 0.881); thinning the texels back
    (--keep 0.88,0.95) moves cover 3 % for 12 % of the texels and costs IoU; shrinking the
    blades drawn into the cards (--area 0.85,0.93) moves it 3 % too, switch 3 sassafras 0.892
    (+6.7 %), tupelo 0.881 (+8.6 %), aspen 0.912.
  8×8 samples a pixel (silhouette.SUPERSAMPLE = 8) raises the floor (0.1 px: oak LOD3 0.916 →
    0.979, poplar 0.892 → 0.967, palm 0.854 → 0.952) but not the LODs' own scores (oak LOD2→3
    0.858 → 0.875, poplar 0.790 → 0.805, palm 0.762 → 0.795): their gap is real.

What was learned: cluster cards reach 0.9 at both far switches for the aspen only (sassafras
0.906 / 0.889, tupelo 0.894 / 0.873), at a texture cost (aspen +410 KB of PNG) and 0.3–0.5 CPU-s,
and lose cover where the LOD drops twigs (desert bush, rush, fan palm) or over-cover where
clusters are sparse (a leaf is on both crossed cards: poplar, tamarack +6 to +15 %). And the
test's measure cannot hold every species to 0.9: with 2×2 samples a pixel the crown's sub-pixel
leaves are point-sampled, and the same LOD0 moved by a tenth of a pixel scores 0.735–0.756
(larch), 0.854 (palm), 0.867 (rush), 0.890 (tamarack) and 0.892 (poplar) at their far switches.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import treegen_cli.silhouette as silhouette
from treegen_cli.asset import Material, Primitive, Texture
from treegen_cli.drawable import decode_image, from_asset
from treegen_cli.lod import LodOptions, pixel_size, switch_distances
from treegen_cli.lod_budget import lod_tree
from treegen_cli.lod_leaves import grow_leaves
from treegen_cli.materials import LEAF_VARIANTS, MaterialOptions
from treegen_cli.mesh.leaves import leaf_variants
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.texture_leaf import atlas_rects
from treegen_cli.texture_png import png_bytes
from treegen_cli.tree import tree_height

ROOT = Path(__file__).resolve().parent.parent
TEXTURE = 256  # leaf atlas side the assets are built with
BARK_RGB = (90, 70, 50)


def voxel_clusters(points: np.ndarray, n_target: int) -> np.ndarray:
    """Cluster label per point (P,): cubic voxels, side bisected until about n_target occupied."""
    lo, ext = points.min(0), float(np.ptp(points, axis=0).max())
    a, b = ext / 4000, ext
    labels = np.zeros(len(points), dtype=np.int64)
    for _ in range(40):
        s = math.sqrt(a * b)
        _, inv = np.unique(np.floor((points - lo) / s).astype(np.int64), axis=0, return_inverse=True)
        labels, n = inv.reshape(-1), int(inv.max()) + 1
        if abs(n - n_target) <= 0.01 * n_target:
            break
        a, b = (s, b) if n > n_target else (a, s)
    return labels


def shelf_pack(w: np.ndarray, h: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(x, y, height) of tiles w × h in rows of at most `side` texels, tallest first."""
    order = np.lexsort((np.arange(len(h)), -h))
    room = side - int(w.max())
    row = np.cumsum(w[order]) // max(room, 1)
    start = np.r_[0, np.flatnonzero(np.diff(row)) + 1]
    first = np.repeat(start, np.diff(np.r_[start, len(order)]))
    ends = np.cumsum(w[order])
    x = ends - w[order] - np.r_[0, ends][first]
    row_h = h[order][start]  # tallest of each row comes first
    y_row = np.r_[0, np.cumsum(row_h)[:-1]]
    y = y_row[np.searchsorted(start, np.arange(len(order)), side="right") - 1]
    X, Y = np.empty_like(x), np.empty_like(y)
    X[order], Y[order] = x, y
    return X, Y, int(row_h.sum())


def tiles(u, v, labels, C: int, texel: float):
    """(lo_u, lo_v, columns, rows) of each of C cards' texel tiles: the bounds of its items'
    corners (N, 4) `u`, `v` in its plane."""
    lo_u, hi_u = np.full(C, np.inf), np.full(C, -np.inf)
    lo_v, hi_v = np.full(C, np.inf), np.full(C, -np.inf)
    np.minimum.at(lo_u, labels, u.min(1)), np.maximum.at(hi_u, labels, u.max(1))
    np.minimum.at(lo_v, labels, v.min(1)), np.maximum.at(hi_v, labels, v.max(1))
    tw = np.maximum(1, np.ceil((hi_u - lo_u) / texel)).astype(np.int64)
    th = np.maximum(1, np.ceil((hi_v - lo_v) / texel)).astype(np.int64)
    return lo_u, lo_v, tw, th


def blade_texels(b, a, l, uu, vv, area, texel):  # noqa: E741
    """(item, texel column, row, x, y) of every texel centre inside a blade, in card-plane
    coordinates: each item's blade is b + x a + y l (x in [-1/2, 1/2], y in [0, 1]; each a
    pair of (N,) arrays u, v), its corners' coordinates (N, 4) `uu`, `vv` bound the texels
    tried; a blade seen edge-on in the plane (a degenerate map) gives none."""
    (bu, bv), (au, av), (lu, lv) = b, a, l
    i0, i1 = np.floor(uu.min(1) / texel).astype(np.int64), np.ceil(uu.max(1) / texel).astype(np.int64)
    j0, j1 = np.floor(vv.min(1) / texel).astype(np.int64), np.ceil(vv.max(1) / texel).astype(np.int64)
    det = au * lv - lu * av
    ok = np.abs(det) > 1e-9 * (area + 1e-30)
    ni, nj = (i1 - i0) * ok, (j1 - j0) * ok
    n = ni * nj
    q = np.repeat(np.arange(len(bu)), n)
    k = np.arange(q.size) - np.repeat(np.cumsum(n) - n, n)
    ti, tj = i0[q] + k // np.maximum(nj[q], 1), j0[q] + k % np.maximum(nj[q], 1)
    pu, pv = (ti + 0.5) * texel - bu[q], (tj + 0.5) * texel - bv[q]
    x = (lv[q] * pu - lu[q] * pv) / det[q]
    y = (-av[q] * pu + au[q] * pv) / det[q]
    inside = (np.abs(x) <= 0.5) & (y >= 0) & (y <= 1)
    return q[inside], ti[inside], tj[inside], x[inside], y[inside]


def cluster_cards(
    items: dict, labels: np.ndarray, leaf_img: np.ndarray, texel: float, seed: int, phi=None, planes: int = 2
):
    """(Primitive, RGBA atlas) of crossed cards, one pair per cluster `labels` (N,) of `items`
    (b, l: base and along of each quad, a: its across vector or None for a stem of radius r,
    rect: leaf atlas cell or None for bark)."""
    b, l, area, stem = items["b"], items["l"], items["area"], items["stem"]  # noqa: E741
    C = int(labels.max()) + 1
    mid = b + 0.5 * l
    wsum = np.bincount(labels, weights=area, minlength=C)
    centre = np.stack([np.bincount(labels, weights=area * mid[:, i], minlength=C) for i in range(3)], 1)
    centre /= np.maximum(wsum, 1e-30)[:, None]
    phi0 = np.random.default_rng([seed, 0xCA7D]).uniform(0.0, np.pi, C) if phi is None else phi
    cards = []
    for phi in [phi0 + j * np.pi / planes for j in range(planes)]:
        nrm = np.stack([np.cos(phi), np.sin(phi), np.zeros(C)], 1)
        eu = np.stack([-np.sin(phi), np.cos(phi), np.zeros(C)], 1)
        a = items["a"].copy()
        w = np.cross(nrm[labels][stem], l[stem])  # a stem's band: 2r across its axis on screen
        a[stem] = 2 * items["r"][:, None] * w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12)
        rel = (
            np.stack([b - 0.5 * a, b + 0.5 * a, b - 0.5 * a + l, b + 0.5 * a + l], 1)
            - centre[labels][:, None]
        )
        u, v = np.einsum("nkj,nj->nk", rel, eu[labels]), rel[:, :, 2]
        lo_u, lo_v, tw, th = tiles(u, v, labels, C, texel)
        cards.append(dict(a=a, nrm=nrm, eu=eu, lo_u=lo_u, lo_v=lo_v, tw=tw, th=th, u=u, v=v))
    tw = np.concatenate([c["tw"] for c in cards]) + 2
    th = np.concatenate([c["th"] for c in cards]) + 2  # one clear texel round each tile
    side = 2 ** math.ceil(math.log2(math.sqrt(1.2 * float((tw * th).sum()))))
    x0, y0, used = shelf_pack(tw, th, side)
    height = 2 ** math.ceil(math.log2(max(used, 1)))
    alpha = np.zeros((height, side), np.uint8)
    rgb = np.zeros((height, side, 3), np.uint8)
    H, W = leaf_img.shape[:2]
    pos, uvs = [], []
    for ci, c in enumerate(cards):
        cx, cy = x0[ci * C : (ci + 1) * C] + 1, y0[ci * C : (ci + 1) * C] + 1
        eu, a = c["eu"][labels], c["a"]
        au, lu = np.einsum("ij,ij->i", a, eu), np.einsum("ij,ij->i", l, eu)
        av, lv = a[:, 2], l[:, 2]
        bu = np.einsum("ij,ij->i", b - centre[labels], eu) - c["lo_u"][labels]
        bv = b[:, 2] - centre[labels, 2] - c["lo_v"][labels]
        uu, vv = c["u"] - c["lo_u"][labels][:, None], c["v"] - c["lo_v"][labels][:, None]
        q, ti, tj, x, y = blade_texels((bu, bv), (au, av), (lu, lv), uu, vv, area, texel)
        r = items["rect"][q]
        px = np.clip(((r[:, 0] + (x + 0.5) * (r[:, 2] - r[:, 0])) * W).astype(np.int64), 0, W - 1)
        py = np.clip(((r[:, 3] - y * (r[:, 3] - r[:, 1])) * H).astype(np.int64), 0, H - 1)
        opaque = stem[q] | (leaf_img[py, px, 3] >= 128)
        cl = labels[q]
        X = cx[cl] + np.clip(ti, 0, c["tw"][cl] - 1)
        Y = cy[cl] + c["th"][cl] - 1 - np.clip(tj, 0, c["th"][cl] - 1)  # rows top first, v up
        col = np.where(stem[q][:, None], np.uint8(BARK_RGB), leaf_img[py, px, :3])
        depth = np.einsum("ij,ij->i", mid[q], c["nrm"][cl])
        o = np.lexsort((depth,))[opaque[np.lexsort((depth,))]]  # nearest to the card's front last
        alpha[Y[o], X[o]] = 255
        rgb[Y[o], X[o]] = col[o]
        u1, v1 = c["lo_u"] + c["tw"] * texel, c["lo_v"] + c["th"] * texel
        z = np.array([0.0, 0.0, 1.0])
        E = c["eu"]
        corner = [(c["lo_u"], c["lo_v"]), (u1, c["lo_v"]), (c["lo_u"], v1), (u1, v1)]
        pos.append(np.stack([centre + E * cu[:, None] + z * cv[:, None] for cu, cv in corner], 1))
        U0, U1 = cx / side, (cx + c["tw"]) / side
        V0, V1 = 1 - (cy + c["th"]) / height, 1 - cy / height  # bottom-left origin
        uvs.append(np.stack([np.stack(p, 1) for p in ((U0, V0), (U1, V0), (U0, V1), (U1, V1))], 1))
    P = np.concatenate(pos).reshape(-1, 3).astype(np.float32)
    n_cards = len(P) // 4
    idx = (
        np.array([0, 1, 3, 0, 3, 2], np.uint32)[None] + 4 * np.arange(n_cards, dtype=np.uint32)[:, None]
    ).ravel()
    prim = Primitive(
        name="leaves",
        material="cards",
        positions=P,
        normals=np.concatenate([np.repeat(c["nrm"], 4, axis=0) for c in cards]).astype(np.float32),
        uvs=np.concatenate(uvs).reshape(-1, 2).astype(np.float32),
        indices=idx,
        joints=np.zeros((len(P), 4), np.uint16),  # the masks are drawn at rest
        weights=np.tile(np.float32([1, 0, 0, 0]), (len(P), 1)),
    )
    return prim, np.dstack([rgb, alpha])


def dropped_stems(asset, tree, k: int, lod: LodOptions) -> np.ndarray:
    """(S,) LOD0 stems that LOD k drops (matched by length and offset, which a cut keeps)."""
    at = replace(lod, distances=tuple(switch_distances(tree_height(tree), lod)))
    cells = tuple(tuple(float(x) for x in r) for r in atlas_rects(LEAF_VARIANTS, TEXTURE))
    o = MakeOptions()
    t, _, _ = lod_tree(
        tree, k, asset.lods[0], asset.lods[k - 1], o.rig, replace(o.mesh, leaf_cells=cells), at
    )
    kept = set(zip(np.round(t.stem_length, 9), np.round(t.stem_offset, 9)))
    return np.array(
        [key not in kept for key in zip(np.round(tree.stem_length, 9), np.round(tree.stem_offset, 9))]
    )


def items_of(tree, drop: np.ndarray | None) -> dict:
    """Leaf quads (and dropped stem segments) of LOD0's `tree` as the card rasteriser's items."""
    F = tree.leaf_frame
    rect = atlas_rects(LEAF_VARIANTS, TEXTURE)[leaf_variants(tree, LEAF_VARIANTS)]
    it = dict(
        b=tree.leaf_pos,
        l=F[:, :, 1] * tree.leaf_size[:, :1],
        a=F[:, :, 0] * tree.leaf_size[:, 1:2],
        area=tree.leaf_size[:, 0] * tree.leaf_size[:, 1],
        rect=rect,
        r=np.zeros(0),
    )
    if drop is None or not drop.any():
        return {**it, "stem": np.zeros(tree.n_leaves, bool)}
    seg = tree.segments
    seg = seg[drop[tree.node_stem[seg]]]
    p0, d = tree.node_pos[seg], tree.node_pos[seg + 1] - tree.node_pos[seg]
    r = 0.5 * (tree.node_radius[seg] + tree.node_radius[seg + 1])
    n = len(seg)
    return dict(
        b=np.concatenate([it["b"], p0]),
        l=np.concatenate([it["l"], d]),
        a=np.concatenate([it["a"], np.zeros((n, 3))]),
        area=np.concatenate([it["area"], 2 * r * np.linalg.norm(d, axis=1)]),
        rect=np.concatenate([rect, np.zeros((n, 4), np.float32)]),
        r=r,
        stem=np.r_[np.zeros(tree.n_leaves, bool), np.ones(n, bool)],
    )


def nested(points: np.ndarray, n2: int, n3: int, seed: int):
    """(LOD2 labels, LOD2 azimuths, LOD3 labels, LOD3 azimuths): LOD3's clusters are unions of
    LOD2's, whose cards share their parent's azimuth (the far switch swaps like for like)."""
    lab2 = voxel_clusters(points, n2)
    c2 = np.stack([np.bincount(lab2, weights=points[:, i]) for i in range(3)], 1) / np.bincount(lab2)[:, None]
    parent = voxel_clusters(c2, n3)
    phi3 = np.random.default_rng([seed, 0xCA7D]).uniform(0.0, np.pi, int(parent.max()) + 1)
    return lab2, phi3[parent], parent[lab2], phi3


def with_cards(
    asset,
    tree,
    lod: LodOptions,
    texel_px: float,
    stems: bool,
    keep=(1.0, 1.0),
    nest=False,
    planes=2,
    area=(1.0, 1.0),
):
    """`asset` with LOD2 and LOD3's leaves replaced by cluster cards in the same triangles."""
    leaf = next(m for m in asset.materials if m.name == "leaf")
    img = decode_image(leaf.base_texture.png, 4)
    lods, mats = list(asset.lods), list(asset.materials)
    n = {k: sum(len(p.indices) // 3 for p in lods[k].primitives if p.name == "leaves") for k in (2, 3)}
    plan = {}
    if nest:
        it = items_of(tree, None)
        l2, p2, l3, p3 = nested(
            it["b"] + 0.5 * it["l"], n[2] // (2 * planes), n[3] // (2 * planes), tree.seed
        )
        plan = {2: (l2, p2), 3: (l3, p3)}
    for k in (2, 3):
        prims = lods[k].primitives
        n_tris = n[k]
        grown = grow_leaves(tree, area[k - 2])  # about each blade's middle: clusters stay
        items = items_of(grown, dropped_stems(asset, tree, k, lod) if stems else None)
        labels, phi = plan.get(k) or (
            voxel_clusters(items["b"] + 0.5 * items["l"], n_tris // (2 * planes)),
            None,
        )
        texel = texel_px * pixel_size(lods[k].distance, lod)
        prim, rgba = cluster_cards(items, labels, img, texel, k, phi, planes)
        if keep[k - 2] < 1.0:  # a leaf is on both crossed cards: seen obliquely, sparse ones double
            rgba[..., 3] *= np.random.default_rng([k, 0x7A1]).random(rgba.shape[:2]) < keep[k - 2]
        name = f"cards{k}"
        mats.append(Material(name, (1, 1, 1, 1), double_sided=True, alpha_cutoff=0.5,
                             base_texture=Texture(name, png_bytes(rgba), wrap="CLAMP")))  # fmt: skip
        card = replace(prim, material=name)
        lods[k] = replace(lods[k], primitives=[p for p in prims if p.name != "leaves"] + [card])
        print(f"   LOD{k}: {len(card.indices) // 3} card triangles (leaves had {n_tris}), atlas "
              f"{rgba.shape[1]}×{rgba.shape[0]}, {len(mats[-1].base_texture.png) // 1024} KB")  # fmt: skip
    return replace(asset, lods=lods, materials=mats)


def scores(asset, a: int, b: int, lod, views, shift: float = 0.0, at: int | None = None):
    """Per view (IoU, cover) of LOD a vs LOD b (moved by `shift` px) at LOD `at`'s switch (b's)."""
    mpp = silhouette.metres_per_pixel(asset.lods[b if at is None else at].distance, lod)
    other = asset.lods[b]
    if shift:
        moved = [
            replace(p, positions=p.positions + np.float32([shift * mpp, 0, 0])) for p in other.primitives
        ]
        other = replace(other, primitives=moved)
    pair = replace(asset, lods=[asset.lods[a], other])
    masks, _ = silhouette.coverage_masks([from_asset(pair, 0), from_asset(pair, 1)], mpp, views, 384)
    return [silhouette.compare(x, y) for x, y in zip(*masks)]


def row(label: str, s) -> str:
    return f"   {label:<26}" + "".join(f"{i:>8.3f}{100 * (c - 1):>+7.1f}%" for i, c in s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="")
    ap.add_argument("--views", default="-90,-45")
    ap.add_argument("--texel", type=float, default=1.0, help="card texel, in pixels at the switch")
    ap.add_argument("--measure-ss", type=int, default=silhouette.SUPERSAMPLE)
    ap.add_argument("--stems", action="store_true", help="draw the dropped twigs' bark into the cards")
    ap.add_argument("--area", default="1,1", help="LOD2,LOD3: leaves' area factor as drawn into the cards")
    ap.add_argument("--planes", type=int, default=2, help="vertical cards per cluster (2: crossed)")
    ap.add_argument("--nest", action="store_true", help="LOD3's clusters are unions of LOD2's")
    ap.add_argument("--keep", default="1,1", help="LOD2,LOD3: share of the cards' texels kept (thinning)")
    ap.add_argument("--floor", action="store_true", help="also LOD0 against itself moved 0.1 / 0.25 px")
    args = ap.parse_args()
    silhouette.SUPERSAMPLE = args.measure_ss
    views = tuple(float(v) for v in args.views.split(","))
    lod = LodOptions()
    head = "".join(f"{'IoU':>8}{'cover':>8}" for _ in views)
    print(
        f"views {views}, {args.measure_ss}×{args.measure_ss} samples a pixel, texel {args.texel} px\n   {'':<26}{head}"
    )
    names = (
        args.species.split(",") if args.species else sorted(p.stem for p in (ROOT / "species").glob("*.txt"))
    )
    for name in names:
        asset, tree = build_asset(
            load_params(ROOT / "species" / f"{name}.txt"),
            0,
            MakeOptions(wind=None, lod=lod, materials=MaterialOptions(texture_size=TEXTURE)),
        )
        asset = replace(asset, lods=[x for x in asset.lods if x.impostor is None])
        print(name)
        if not tree.n_leaves:
            print("   leafless: no cards")
            continue
        t0 = time.process_time()
        if args.nest and args.stems:
            ap.error("--nest draws leaves only (no --stems)")
        carded = with_cards(
            asset,
            tree,
            lod,
            args.texel,
            args.stems,
            tuple(float(x) for x in args.keep.split(",")),
            args.nest,
            args.planes,
            tuple(float(x) for x in args.area.split(",")),
        )
        print(f"   cards: {time.process_time() - t0:.2f} CPU-s")
        for k in (2, 3):
            print(row(f"switch {k}: enlarged leaves", scores(asset, k - 1, k, lod, views)))
            print(row(f"switch {k}: cards", scores(carded, k - 1, k, lod, views)))
            if args.floor:
                for shift in (0.1, 0.25):
                    print(row(f"LOD0 moved {shift} px", scores(asset, 0, 0, lod, views, shift, k)))


if __name__ == "__main__":
    main()
