"""The switch to the impostor per bundled species: covered area and silhouette IoU of the cards
against the coarsest geometric LOD, and the impostor stage's CPU seconds.

    python bench/impostor_pop_bench.py [--species quaking_aspen,tests/fixtures/arbaro/barley.xml,...]
                                       [--views -90,-45,0,30]

Each species is built as `treegen make` builds it (default options, no wind); the coarsest LOD
and the impostor are rendered at the tree's size on screen at the impostor's distance (fov 60°,
1920 px wide) by treegen_cli.silhouette, from side views: −90° and 0° each face a card,
between them the crossed cards are seen at an angle. Cover: impostor / coarsest LOD; IoU after the silhouette's 3-pixel blur.

Measured 2026-11-26 (load 5-8, four views −90/−45/0/30°; cover at the card views −90° and 0°):
before (atlas of LOD0's leaves thinned to 600 cards of their summed area on the coarsest LOD's
600 widest bark triangles) → after (the coarsest LOD itself; beyond 2,000 leaves every k-th,
enlarged until the card views cover what all do; bark whole up to 40,000 triangles):
    balsam_fir     +47.2/+44.9 % → −0.1/+0.2 %   IoU 0.675/0.688 → 0.860/0.879
    desert_bush    −64.0/−66.2 % → −1.6/+4.5 %   IoU 0.343/0.322 → 0.641/0.725
    ca_black_oak   −16.2/−26.2 % → +10.0/+4.0 %  IoU 0.625/0.617 → 0.715/0.746
    european_larch −42.7/−44.8 % → −6.2/+4.6 %   IoU 0.450/0.466 → 0.591/0.594
    fan_palm       +29.9/+25.8 % → −10.0/−4.0 %  IoU 0.489/0.634 → 0.564/0.764
    rush           −60.5/−66.1 % → −1.5/−9.6 %   IoU 0.308/0.280 → 0.495/0.542
    tamarack       +13.7/+22.0 % → +2.9/+6.7 %   IoU 0.664/0.703 → 0.666/0.745
    weeping_willow +10.4/+8.2 %  → −0.7/+1.8 %   IoU 0.839/0.847 → 0.879/0.898
    quaking_aspen  +4.4/+7.2 %   → +4.1/+3.9 %   IoU 0.842/0.817 → 0.864/0.887
Between the card views (−45°, 30°) the two crossed cards are each seen foreshortened: cover
−18 to +27 % and IoU 0.43-0.81 before and after; only an impostor shader that picks the atlas
cell facing the camera (the atlas and its sidecar are written for that) removes it. The
impostor stage costs more, as it draws all of the coarsest LOD: aspen 0.21 → 0.34 CPU-s,
fir 0.41 → 0.82, willow 0.99.

2026-11-27 (load 2-3, same four views), cover and IoU at the card views −90° and 0°, before
(ca4b97f) → after thin stems are widened within a budget (the rest drawn one in so many) and
the cards' own views are drawn twice as fine as the atlas's cells (CARD_SCALE: a texel spans
0.75 px at the switch, not 1.5); the angled views (−45°, 30°) move by −0.04 to +0.05:
    balsam_fir      +0.5/+2.1 %  → +0.2/+1.7 %   IoU 0.857/0.881 → 0.861/0.877
    black_tupelo    +3.2/+2.5 %  → +2.0/+2.6 %   IoU 0.836/0.865 → 0.855/0.885
    ca_black_oak    +6.2/+3.6 %  → +6.0/+4.0 %   IoU 0.729/0.766 → 0.774/0.833
    desert_bush     −3.8/+8.0 %  → −1.0/+5.6 %   IoU 0.686/0.747 → 0.721/0.828
    eastern_cottonwood +0.9/+1.9 % → +0.6/+1.4 % IoU 0.830/0.888 → 0.857/0.914
    european_larch  +5.0/+4.7 %  → −2.3/−5.6 %   IoU 0.614/0.654 → 0.764/0.774
    fan_palm        −4.6/−7.7 %  → −3.7/+0.0 %   IoU 0.595/0.742 → 0.629/0.882
    lombardy_poplar +3.9/+3.4 %  → +2.9/+4.1 %   IoU 0.790/0.789 → 0.873/0.887
    palm            −7.0/−6.7 %  → −3.2/+1.5 %   IoU 0.678/0.725 → 0.796/0.867
    quaking_aspen   +1.4/+1.0 %  → +0.9/+2.7 %   IoU 0.899/0.896 → 0.922/0.924
    rush            +153/+142 %  → −4.5/+6.9 %   IoU 0.332/0.372 → 0.413/0.569
    sassafras       +2.5/+3.4 %  → +1.0/+2.1 %   IoU 0.834/0.867 → 0.845/0.885
    shave_grass     +5.5/−9.0 %  → +0.2/−2.8 %   IoU 0.654/0.711 → 0.774/0.859
    tamarack        +5.4/+9.8 %  → +3.3/+6.2 %   IoU 0.694/0.772 → 0.742/0.834
    weeping_willow  +0.9/+1.3 %  → −0.2/+1.6 %   IoU 0.888/0.908 → 0.915/0.927

Grasses (2026-11-28; Arbaro's barley and wheat from tests/fixtures/arbaro), cover / IoU at the
card views −90° / 0°: barley −1.0/+1.0 %, 0.354/0.404; wheat +4.5/+6.4 %, 0.472/0.589; rush
−4.5/+6.9 %, 0.413/0.569. Their stalks, under a texel, are widened only below the lowest leaf
(stubs under the ears) and drawn one in so many. Tried, not taken: (1) stalks also widened
above it where no leaf is within two widths: barley 0.190/0.305, rush cover +17.6/+24.8 %
(the one stalk widened whole reads as a thick arc); (2) every thin stalk drawn, each in its
share of its texels (a per-pixel dither in the bark shader) instead of one in so many: barley
0.375/0.473 and wheat 0.527/0.611, but the rush's cards lose half their cover (−50.7/−49.7 %)
once minified to the switch size (a dotted stalk's texels average under the alpha cut-off,
as an engine's mipmaps would average them too).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from treegen_cli import api
from treegen_cli.bundled import resolve_species
from treegen_cli.drawable import from_asset
from treegen_cli.lod import LodOptions
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings, build_asset
from treegen_cli.silhouette import compare, coverage_masks, metres_per_pixel

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="")
    ap.add_argument("--views", default="-90,-45,0,30", help="camera azimuths, degrees")
    ap.add_argument("--max-px", type=int, default=384)
    args = ap.parse_args()
    names = (
        args.species.split(",")
        if args.species
        else sorted(p.stem for p in (ROOT / "treegen_cli" / "species").glob("*.txt"))
    )
    views = tuple(float(v) for v in args.views.split(","))
    job = api.resolve({"no_wind": True})
    print(
        f"{'species':<20}{'dist m':>8}{'px':>5}  {'cover per view':<34}{'IoU per view':<30}impostor s (wall)"
    )
    for given in names:
        path = resolve_species(given)
        name, timings = path.stem, Timings()
        asset, _ = build_asset(load_params(path), 0, job.options, timings)
        k = len(asset.lods) - 1
        d = asset.lods[k].distance
        masks, px = coverage_masks(
            [from_asset(asset, k - 1), from_asset(asset, k)],
            metres_per_pixel(d, LodOptions()),
            views,
            args.max_px,
        )
        scores = [compare(a, b) for a, b in zip(*masks)]
        cover = " ".join(f"{100 * (c - 1):+6.1f}%" for _, c in scores)
        iou = " ".join(f"{i:.3f}" for i, _ in scores)
        print(
            f"{name:<20}{d:>8.0f}{px:>5}  {cover:<34}{iou:<30}{timings.stages.get('impostor', float('nan')):.2f}"
        )


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"({time.perf_counter() - t0:.0f} s)")
