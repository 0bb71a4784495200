"""What thinning leaves can reach at a LOD switch: silhouette IoU, at each switch, of two
random nested thinnings of LOD0's leaf cards to the shares of LOD0's leaves the two LODs keep,
each card grown by the inverse share in area about its middle (so the covered area stays),
next to what the LODs themselves reach. Rendered as treegen_cli.silhouette renders a switch
(one view, −90°, at most 384 px: the test's).

    python bench/lod_floor_bench.py [--species eastern_cottonwood,...]

Columns: `jitter`, LOD0 against itself with every card moved by a quarter of its size (how
small a change the metric already counts at that scale); `model`, the random nested
thinning; `LOD`, the LODs; `leaves`, the LODs' leaves on LOD k−1's bark (the share of the pop
that is the leaves').

Measured 2026-11-27:
    species             switch   px  jitter  share k-1 -> k  model    LOD  leaves
    eastern_cottonwood       1  376   0.915     1.00 -> 0.52  0.883  0.890   0.891
    eastern_cottonwood       2  273   0.936     0.52 -> 0.32  0.902  0.891   0.896
    eastern_cottonwood       3  109   0.971     0.32 -> 0.10  0.887  0.897   0.900
    lombardy_poplar          1  376   0.882     1.00 -> 1.00  1.000  0.943   0.945
    lombardy_poplar          2  271   0.918     1.00 -> 0.75  0.907  0.887   0.891
    lombardy_poplar          3  108   0.959     0.75 -> 0.22  0.881  0.881   0.880
    ca_black_oak             1  376   0.953     1.00 -> 0.70  0.945  0.926   0.929
    ca_black_oak             2  316   0.960     0.70 -> 0.33  0.917  0.899   0.906
    ca_black_oak             3  126   0.976     0.33 -> 0.10  0.924  0.902   0.904
    european_larch           1  376   0.957     1.00 -> 0.79  0.965  0.918   0.956
    european_larch           2  270   0.957     0.79 -> 0.34  0.959  0.903   0.945
    european_larch           3  108   0.954     0.34 -> 0.10  0.954  0.894   0.921
Random thinning, nested and grown as the LODs are, stays under 0.9 at one switch or more of
the cottonwood and the poplar: at the default budgets (50 / 15 / 5 % of the triangles) their
leaves must thin this far, and the LODs' picks (stratified, gathered to the leaves they stand
for) are within 0.02 of chance. The oak and the larch lose 0.02-0.06 more than the model: the
larch in its bark (its leaves alone pass; bark is 88 % of its covered area at switch 1), the
oak in its leaves (from LOD2 on drawn as triangle cards, which the model does not). Keeping
more of the larch's thin twigs (lod_budget.STEM_WORTH 0.5, 0.25) moved it by ≤ 0.003.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from treegen_cli.api import resolve
from treegen_cli.drawable import from_asset
from treegen_cli.lod import LodOptions
from treegen_cli.params import load_params
from treegen_cli.pipeline import build_asset
from treegen_cli.silhouette import compare, coverage_masks, metres_per_pixel

ROOT = Path(__file__).resolve().parent.parent
SPECIES = "eastern_cottonwood,lombardy_poplar,ca_black_oak,european_larch"


def leaf_cards(lod) -> int:
    """Leaf cards a LOD draws: quads (6 indices on 4 vertices) or triangle cards (3 on 3)."""
    p = next((p for p in lod.primitives if p.name == "leaves"), None)
    if p is None:
        return 0
    return len(p.positions) // (4 if len(p.indices) * 4 == len(p.positions) * 6 else 3)


def thinned(scene, leaf: int, order: np.ndarray, share: float, rng, jitter: float = 0.0):
    """`scene` with the first `share` of its quad leaf cards in `order` (nested: a smaller
    share keeps a subset), each scaled to 1/share its area about its middle and moved by
    `jitter` × its size in a random direction."""
    part = scene.parts[leaf]
    cards = np.sort(order[: max(1, int(round(share * order.size)))])
    v = (cards[:, None] * 4 + np.arange(4)).reshape(-1)
    pos = part.positions[v].reshape(-1, 4, 3).astype(np.float64)
    mid = pos.mean(axis=1, keepdims=True)
    pos = mid + (pos - mid) * share**-0.5
    if jitter:
        size = np.linalg.norm(pos[:, 0] - pos[:, 2], axis=1)[:, None, None]
        pos = pos + jitter * size * rng.normal(size=(len(pos), 1, 3))
    pattern = part.indices[:6].astype(np.int64) - int(part.indices[:6].min())
    idx = (np.arange(cards.size)[:, None] * 4 + pattern).reshape(-1).astype(np.uint32)
    new = replace(
        part,
        positions=pos.reshape(-1, 3).astype(np.float32),
        normals=part.normals[v],
        indices=idx,
        joints=part.joints[v],
        weights=part.weights[v],
        uvs=None if part.uvs is None else part.uvs[v],
    )
    parts = list(scene.parts)
    parts[leaf] = new
    return replace(scene, parts=parts)


def _parts(scene, name: str) -> list:
    return [p for p in scene.parts if p.name == name]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default=SPECIES)
    args = ap.parse_args()
    job = resolve({"no_wind": True, "texture_size": 128, "impostor": False})
    lod_options = LodOptions()
    print(
        f"{'species':<20}{'switch':>6}{'px':>5}{'jitter':>8}{'share k-1 -> k':>16}{'model':>7}{'LOD':>7}"
        f"{'leaves':>8}"
    )
    for name in args.species.split(","):
        asset, _ = build_asset(load_params(ROOT / "species" / f"{name}.txt"), 0, job.options)
        scene = from_asset(asset, 0)
        leaf = next(i for i, p in enumerate(scene.parts) if p.name == "leaves")
        rng = np.random.default_rng(1)
        order = rng.permutation(len(scene.parts[leaf].positions) // 4)
        share = [min(leaf_cards(lod) / max(leaf_cards(asset.lods[0]), 1), 1.0) for lod in asset.lods]
        for k in range(1, len(asset.lods)):
            mpp = metres_per_pixel(asset.lods[k].distance, lod_options)
            a, b = from_asset(asset, k - 1), from_asset(asset, k)
            drawn = [
                scene,
                thinned(scene, leaf, order, 1.0, rng, jitter=0.25),
                thinned(scene, leaf, order, share[k - 1], rng),
                thinned(scene, leaf, order, share[k], rng),
                a,
                b,
                replace(a, parts=_parts(a, "bark") + _parts(b, "leaves")),
            ]
            masks, px = coverage_masks(drawn, mpp, (-90.0,), 384)
            m = [x[0] for x in masks]
            jitter, model = compare(m[0], m[1])[0], compare(m[2], m[3])[0]
            lod, leaves = compare(m[4], m[5])[0], compare(m[4], m[6])[0]
            print(
                f"{name:<20}{k:>6}{px:>5}{jitter:>8.3f}{share[k - 1]:>9.2f} -> {share[k]:.2f}"
                f"{model:>7.3f}{lod:>7.3f}{leaves:>8.3f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
