"""Colour at each geometric LOD switch: mean linear RGB of the crown, LOD k against LOD k−1,
both drawn by the preview renderer at the size the tree has on screen when LOD k takes over.

    python bench/lod_colour_bench.py [--species quaking_aspen,...] [--profile web] [--max-px 384]

Each species is built as `treegen make` builds it (default options or a `--profile`, no wind);
switch k is drawn `screen[k−1]` × 1080 px tall (fov 60°, 16:9, the default LOD view), at most
`--max-px`, from the views −90° and −45° (8° up, the preview's sun 50° to the left), over the
pixels both LODs cover (impostor_colour_bench.crown_means). Ratio: LOD k / LOD k−1 per channel;
brightness is the green ratio, hue blue / green.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from impostor_colour_bench import crown_means
from treegen_cli import api
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings, build_asset

ROOT = Path(__file__).resolve().parent.parent


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
    for given_name in args.species.split(","):
        path = (
            Path(given_name)
            if given_name.endswith((".txt", ".xml"))
            else ROOT / "treegen_cli" / "species" / f"{given_name}.txt"
        )
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
