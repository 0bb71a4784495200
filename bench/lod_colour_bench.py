"""Colour at each geometric LOD switch: mean linear RGB of the crown, LOD k against LOD k−1,
both drawn by the preview renderer at the size the tree has on screen when LOD k takes over.

    python bench/lod_colour_bench.py [--species quaking_aspen,...] [--profile web] [--max-px 384]

Each species is built as `treegen make` builds it (default options or a `--profile`, no wind);
switch k is drawn `screen[k−1]` × 1080 px tall (fov 60°, 16:9, the default LOD view), at most
`--max-px`, from the views −90° and −45° (8° up, the preview's sun 50° to the left), over the
pixels both LODs cover (impostor_colour_bench.crown_means). Ratio: LOD k / LOD k−1 per channel;
brightness is the green ratio, hue blue / green.

Measured 2026-11-28 (default options), green ratio / hue per switch 1, 2, 3:
    weeping_willow  0.998/0.978  0.967/1.040  1.027/0.934
    quaking_aspen   0.988/0.945  1.030/0.918  1.061/0.980
    ca_black_oak    1.005/0.918  1.014/0.970  1.036/0.940
    balsam_fir      0.983/0.976  0.992/0.967  1.060/1.000
    sassafras       1.019/0.955  1.011/0.960  1.041/0.961
With `--profile web` the willow's switch 2 brightens most (1.106, hue 0.913: its LOD2's
larger leaves against LOD1's fine hanging ones); the oak's hue falls to 0.862 there. Partly
the measure's: a pixel a leaf covers in part mixes in the sky behind, and fewer, larger
leaves leave fewer such pixels (bluer where there are more).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from impostor_colour_bench import crown_means
from treegen_cli import api
from treegen_cli.bundled import resolve_species
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings, build_asset


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="quaking_aspen,balsam_fir,ca_black_oak,weeping_willow")
    ap.add_argument("--profile", default=None)
    ap.add_argument("--max-px", type=int, default=384)
    args = ap.parse_args()
    given = {"no_wind": True, "impostor": False} | ({"profile": args.profile} if args.profile else {})
    job = api.resolve(given)
    screen = job.options.lod.screen
    print(f"{'species':<20}{'switch':>7}{'px':>5}  {'LOD k / LOD k-1 R G B':<22}{'hue b/g':>8}")
    for given in args.species.split(","):
        path = resolve_species(given)
        asset, _ = build_asset(load_params(path), 0, job.options, Timings())
        for k in range(1, len(asset.lods)):
            size = min(args.max_px, int(round(screen[k - 1] * 1080)))
            geo, new, _, _ = crown_means(asset, size, pair=(k - 1, k))
            ratio = new / np.maximum(geo, 1e-9)
            print(
                f"{path.stem:<20}{k:>7}{size:>5}  {' '.join(f'{x:.3f}' for x in ratio):<22}"
                f"{ratio[2] / max(ratio[1], 1e-9):>8.3f}"
            )


if __name__ == "__main__":
    t0 = time.process_time()
    main()
    print(f"({time.process_time() - t0:.0f} CPU-s)")
