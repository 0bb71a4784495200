"""Keyframe decimation on the four Weber–Penn paper species at 30 m and 130 m.

    python bench/lod_bench.py [--runs 5] [--interpolation linear|step]

Per species and distance (fov 60°, width 1920, i = error_px = 1, exact pixel form, the default
4 s / 30 fps wind on the full LOD0 tree): keys kept (% of dense), max measured error (px), and
decimation seconds (median of --runs, probes included). Target: at 130 m ≤ 10% of keys kept
with max error ≤ 1 px; decimation < 1 s per tree.

Measured (2-core box, LINEAR, --runs 3): keys kept at 30 m / 130 m — aspen 18.0% / 6.1%,
tupelo 25.1% / 8.6%, willow 8.0% / 3.2%, oak 4.6% / 2.0%; max error ≤ 1.000 px everywhere;
decimation 0.26–0.55 s per tree.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from treegen_cli.lod import LodOptions, decimate, measure_error_px
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")
DISTANCES = (30.0, 130.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--interpolation", choices=("linear", "step"), default="linear")
    args = ap.parse_args()
    opts = LodOptions(fov_deg=60.0, width=1920, error_px=1.0, interpolation=args.interpolation.upper())
    print(f"{'species':<16}{'joints':>7}{'dist m':>8}{'keys kept':>18}{'max err px':>12}"
          f"{'decimate s':>12}")
    for name in SPECIES:
        asset, _ = build_asset(load_params(ROOT / "species" / f"{name}.txt"), 0,
                               MakeOptions(lod=None))
        lod = asset.lods[0]
        dense = lod.clips[0]
        for d in DISTANCES:
            seconds = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                clip, rep = decimate(lod.skeleton, lod.primitives, dense, d, opts)
                seconds.append(time.perf_counter() - t0)
            err = measure_error_px(lod.skeleton, lod.primitives, dense, clip, d, opts)
            print(f"{name:<16}{len(lod.skeleton.names):>7}{d:>8g}"
                  f"{rep.keys_kept:>9,} {100 * rep.kept_fraction:>6.1f}%  {err:>10.3f}"
                  f"{statistics.median(seconds):>12.3f}")


if __name__ == "__main__":
    main()
