"""Frond cards for the palms' far LODs, measured before any plumbing (issue 13, item 1).

    python bench/lod_fronds_bench.py [--species palm,fan_palm] [--views -90,-45] [--texel 0.25]
        [--cards 1,1] [--lods 2,3]

The palms miss the IoU target at their far switches (palm 0.81, fan palm 0.80): a far LOD's
few leaflets, each grown to stand for three, read as solid strokes where LOD1's read as a
fine fringe. A frond's leaflets lie near a surface, so here each leafy stem's leaves (all of
LOD0's, not grown) are split into chunks along their order on the stem (along a pinnate
frond; around a fan), each chunk drawn onto one planar card: its plane the chunk's
principal plane (area-weighted corners), its texture the chunk's blades projected onto it
at `--texel` pixels of the LOD's switch (binary alpha from the leaf atlas), shelf-packed into
one atlas per LOD. `--cards f2,f3`: cards per LOD as a share of the leaf triangles LOD k
had, over two (1: the same triangles). The LOD's bark stays as built.

The switches are measured as tests/test_lod_budget.py does (silhouette.compare, 384 px, 6 × 6
samples a pixel) on the test's view and others, enlarged leaves against cards. `--v`: each
chunk split in two by side (a pinnate frond's two rows of leaflets form a V), one card each.

Measured (27 Nov 2026, the test's view −90°, texel 0.25 px, cards in LOD2's and LOD3's leaf
triangles), worst of the view, IoU / cover, enlarged leaves → frond cards (one plane a chunk
→ two, `--v`):
    palm      switch 2 0.812/+4.6 → 0.782/−14.3 → 0.808/−6.0   switch 3 0.859/+1.8 → 0.848/+0.5 → 0.807/−9.1
    fan_palm  switch 2 0.854/−1.7 → 0.783/−13.3 → 0.841/−6.7   switch 3 0.819/−3.8 → 0.800/−12.4 → 0.798/−14.2
The picture is better: the palm's LOD2 drawn with V cards keeps LOD1's fine fringe where the
enlarged leaflets read as solid sticks. The measure is not: the cards lose cover and place it
elsewhere. Against LOD0 itself at switch 2 (palm, V cards): IoU 0.845, cover −5.2 % (LOD1:
0.897, +0.9 %); a texel of 0.125 px: 0.847/−4.1 %; three times the cards (7,316 triangles
for LOD2's 2,444): 0.880/−4.7 %; a third of them: 0.788/−13.6 %. A leaflet 0.6 m long droops
(LeafBend) and stands out of any plane its neighbours share, so a frond seen from the side
near edge-on is thinner as cards than as leaflets, whatever the texel. Not carried further:
curved ribbons would follow the rachis but not the leaflets' droop across it.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from lod_cards_bench import blade_texels, row, scores, shelf_pack, tiles  # noqa: E402

from treegen_cli.api import resolve  # noqa: E402
from treegen_cli.asset import Material, Primitive, Texture  # noqa: E402
from treegen_cli.drawable import decode_image  # noqa: E402
from treegen_cli.lod import LodOptions, pixel_size  # noqa: E402
from treegen_cli.materials import LEAF_VARIANTS  # noqa: E402
from treegen_cli.mesh.leaves import leaf_variants  # noqa: E402
from treegen_cli.params import load_params  # noqa: E402
from treegen_cli.pipeline import build_asset  # noqa: E402
from treegen_cli.texture_leaf import atlas_rects  # noqa: E402
from treegen_cli.texture_png import png_bytes  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TEXTURE = 128  # leaf atlas side, as the test builds


def halves(tree, labels: np.ndarray) -> np.ndarray:
    """`labels` split in two by which side of its chunk's middle a blade points to (along the
    chunk's longest axis): a pinnate frond's two rows of leaflets are two planes (a V)."""
    mid = tree.leaf_middle
    C = int(labels.max()) + 1
    w = np.bincount(labels, minlength=C).astype(float)
    centre = (
        np.stack([np.bincount(labels, weights=mid[:, i], minlength=C) for i in range(3)], 1)
        / np.maximum(w, 1)[:, None]
    )
    rel = mid - centre[labels]
    cov = np.zeros((C, 3, 3))
    np.add.at(cov, labels, np.einsum("li,lj->lij", rel, rel))
    axis = np.linalg.eigh(cov + 1e-12 * np.eye(3))[1][:, :, 2]
    side = np.einsum("li,li->l", rel, axis[labels]) > 0
    _, out = np.unique(2 * labels + side, return_inverse=True)
    return out.reshape(-1)


def chunks(tree, n_cards: int) -> np.ndarray:
    """Card label per leaf (L,): each leafy stem's leaves in their order on it, cut into runs,
    the stem's share of `n_cards` (at least one)."""
    L = tree.n_leaves
    stem = tree.leaf_stem.astype(np.int64)
    order = np.lexsort((np.arange(L), stem))
    count = np.bincount(stem, minlength=tree.n_stems)
    per = np.maximum(1, np.round(n_cards * count / L)).astype(np.int64) * (count > 0)
    start = np.cumsum(count) - count
    rank = np.empty(L, np.int64)
    rank[order] = np.arange(L) - start[stem[order]]
    first = np.cumsum(per) - per
    return first[stem] + rank * per[stem] // np.maximum(count[stem], 1)


def planar_cards(tree, labels, leaf_img, rects, texel: float):
    """(Primitive, RGBA atlas): one card per label, its chunk's blades projected onto it."""
    F, size = tree.leaf_frame, tree.leaf_size
    b, l, a = tree.leaf_pos, F[:, :, 1] * size[:, :1], F[:, :, 0] * size[:, 1:2]  # noqa: E741
    area = size[:, 0] * size[:, 1]
    corner = np.stack([b - 0.5 * a, b + 0.5 * a, b + 0.5 * a + l, b - 0.5 * a + l], 1)  # (L, 4, 3)
    C = int(labels.max()) + 1
    w = np.bincount(labels, weights=area, minlength=C)
    centre = np.stack(
        [np.bincount(labels, weights=area * (b + 0.5 * l)[:, i], minlength=C) for i in range(3)], 1
    )
    centre /= np.maximum(w, 1e-30)[:, None]
    rel = corner - centre[labels][:, None]
    outer = np.einsum("lki,lkj->lij", rel, rel) * (area / 4)[:, None, None]
    cov = np.zeros((C, 3, 3))
    np.add.at(cov, labels, outer)
    _, vec = np.linalg.eigh(cov + 1e-12 * np.eye(3))
    eu, ev, nrm = vec[:, :, 2], vec[:, :, 1], vec[:, :, 0]
    u = np.einsum("lki,li->lk", rel, eu[labels])
    v = np.einsum("lki,li->lk", rel, ev[labels])
    lo_u, lo_v, tw, th = tiles(u, v, labels, C, texel)
    side = 2 ** math.ceil(math.log2(math.sqrt(1.2 * float(((tw + 2) * (th + 2)).sum()))))
    side = max(side, int(tw.max()) + 2)
    x0, y0, used = shelf_pack(tw + 2, th + 2, side)
    cx, cy = x0 + 1, y0 + 1
    height = 2 ** math.ceil(math.log2(max(used, 1)))
    alpha = np.zeros((height, side), np.uint8)
    rgb = np.zeros((height, side, 3), np.uint8)
    H, W = leaf_img.shape[:2]
    # each blade's affine map in its card's plane: point = b' + x a' + y l', x ∈ [-½, ½], y ∈ [0, 1]
    E_u, E_v = eu[labels], ev[labels]
    bu = np.einsum("li,li->l", b - centre[labels], E_u) - lo_u[labels]
    bv = np.einsum("li,li->l", b - centre[labels], E_v) - lo_v[labels]
    au, av = np.einsum("li,li->l", a, E_u), np.einsum("li,li->l", a, E_v)
    lu, lv = np.einsum("li,li->l", l, E_u), np.einsum("li,li->l", l, E_v)
    uu, vv = u - lo_u[labels][:, None], v - lo_v[labels][:, None]
    q, ti, tj, x, y = blade_texels((bu, bv), (au, av), (lu, lv), uu, vv, area, texel)
    r = rects[q]
    px = np.clip(((r[:, 0] + (x + 0.5) * (r[:, 2] - r[:, 0])) * W).astype(np.int64), 0, W - 1)
    py = np.clip(((r[:, 3] - y * (r[:, 3] - r[:, 1])) * H).astype(np.int64), 0, H - 1)
    opaque = leaf_img[py, px, 3] >= 128
    cl = labels[q]
    X = cx[cl] + np.clip(ti, 0, tw[cl] - 1)
    Y = cy[cl] + th[cl] - 1 - np.clip(tj, 0, th[cl] - 1)  # rows top first, v up
    alpha[Y[opaque], X[opaque]] = 255
    rgb[Y[opaque], X[opaque]] = leaf_img[py[opaque], px[opaque], :3]
    u1, v1 = lo_u + tw * texel, lo_v + th * texel
    quad = [(lo_u, lo_v), (u1, lo_v), (lo_u, v1), (u1, v1)]
    P = np.stack([centre + eu * qu[:, None] + ev * qv[:, None] for qu, qv in quad], 1)
    U0, U1 = cx / side, (cx + tw) / side
    V0, V1 = 1 - (cy + th) / height, 1 - cy / height  # bottom-left origin
    UV = np.stack([np.stack(p, 1) for p in ((U0, V0), (U1, V0), (U0, V1), (U1, V1))], 1)
    idx = (np.array([0, 1, 3, 0, 3, 2], np.uint32)[None] + 4 * np.arange(C, dtype=np.uint32)[:, None]).ravel()
    prim = Primitive(
        name="leaves",
        material="fronds",
        positions=P.reshape(-1, 3).astype(np.float32),
        normals=np.repeat(nrm, 4, axis=0).astype(np.float32),
        uvs=UV.reshape(-1, 2).astype(np.float32),
        indices=idx,
        joints=np.zeros((4 * C, 4), np.uint16),  # the masks are drawn at rest
        weights=np.tile(np.float32([1, 0, 0, 0]), (4 * C, 1)),
    )
    return prim, np.dstack([rgb, alpha])


V = False


def with_fronds(asset, tree, lod: LodOptions, texel_px: float, share: dict, lods=(2, 3)):
    """`asset` with the `lods`' leaves replaced by frond cards (share × their leaf triangles / 2)."""
    leaf = next(m for m in asset.materials if m.name == "leaf")
    img = decode_image(leaf.base_texture.png, 4)
    rects = np.asarray(atlas_rects(LEAF_VARIANTS, TEXTURE))[leaf_variants(tree, LEAF_VARIANTS)]
    out, mats = list(asset.lods), list(asset.materials)
    for k in lods:
        n_tris = sum(len(p.indices) // 3 for p in out[k].primitives if p.name == "leaves")
        n = max(1, int(share[k] * n_tris / 2))
        labels = halves(tree, chunks(tree, max(1, n // 2))) if V else chunks(tree, n)
        texel = texel_px * pixel_size(out[k].distance, lod)
        prim, rgba = planar_cards(tree, labels, img, rects, texel)
        name = f"fronds{k}"
        mats.append(Material(name, (1, 1, 1, 1), double_sided=True, alpha_cutoff=0.5,
                             base_texture=Texture(name, png_bytes(rgba), wrap="CLAMP")))  # fmt: skip
        card = replace(prim, material=name)
        out[k] = replace(out[k], primitives=[p for p in out[k].primitives if p.name != "leaves"] + [card])
        print(f"   LOD{k}: {len(card.indices) // 3} card triangles (leaves had {n_tris}), atlas "
              f"{rgba.shape[1]}×{rgba.shape[0]}, {len(mats[-1].base_texture.png) // 1024} KB")  # fmt: skip
    return replace(asset, lods=out, materials=mats)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="palm,fan_palm")
    ap.add_argument("--views", default="-90,-45")
    ap.add_argument("--texel", type=float, default=0.25, help="card texel, in pixels at the switch")
    ap.add_argument("--cards", default="1,1", help="LOD2,LOD3 cards: share of the leaf triangles / 2")
    ap.add_argument("--lods", default="2,3", help="which LODs get cards")
    ap.add_argument("--v", action="store_true", help="two cards a chunk, one per side (a V)")
    args = ap.parse_args()
    global V
    V = args.v
    views = tuple(float(v) for v in args.views.split(","))
    lods = tuple(int(x) for x in args.lods.split(","))
    share = dict(zip((2, 3), (float(x) for x in args.cards.split(","))))
    share.setdefault(1, share[2])
    lod = LodOptions()
    head = "".join(f"{'IoU':>8}{'cover':>8}" for _ in views)
    print(f"views {views}, texel {args.texel} px\n   {'':<26}{head}")
    for name in args.species.split(","):
        job = resolve(dict(no_wind=True, texture_size=TEXTURE))
        asset, tree = build_asset(load_params(ROOT / "species" / f"{name}.txt"), 0, job.options)
        asset = replace(asset, lods=[x for x in asset.lods if x.impostor is None])
        print(name)
        t0 = time.process_time()
        carded = with_fronds(asset, tree, lod, args.texel, share, lods)
        print(f"   cards: {time.process_time() - t0:.2f} CPU-s")
        for k in range(1, len(asset.lods)):
            print(row(f"switch {k}: enlarged leaves", scores(asset, k - 1, k, lod, views)))
            print(row(f"switch {k}: frond cards", scores(carded, k - 1, k, lod, views)))


if __name__ == "__main__":
    main()
