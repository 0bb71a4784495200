"""Wind bake benchmark: a 10 s, 30 fps clip for the largest bundled species (weeping willow) at
the default joint budget and at 4×. Prints joints, frames, seconds (median of 5), µs per
joint-frame. Target (issue 4): under 0.5 s at the default budget.

    python bench/wind_bench.py [species/weeping_willow.txt] [--seed N]

Measured (2-core shared box, willow seed 1: 53,850 stems, 582,188 leaves):
     budget  joints  frames  seconds  us/joint-frame
        256     222     301    0.112            1.67
       1024     858     301    0.233            0.90
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from treegen_cli.generate import generate
from treegen_cli.params import load_params
from treegen_cli.rig import RIG_DEFAULTS, RigOptions, build_rig
from treegen_cli.wind import WindOptions, bake_wind

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="?", default=str(ROOT / "species" / "weeping_willow.txt"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    params = load_params(args.species)
    t0 = time.perf_counter()
    tree = generate(params, args.seed)
    print(f"{params.name}: {tree.n_stems} stems, {tree.n_nodes} nodes, {tree.n_leaves} leaves "
          f"(generated in {time.perf_counter() - t0:.2f} s)")
    options = WindOptions(duration=10.0, fps=30.0)
    budget = RIG_DEFAULTS.max_joints
    print(f"{'budget':>7} {'joints':>7} {'frames':>7} {'seconds':>8} {'us/joint-frame':>15}")
    for max_joints in (budget, 4 * budget):
        rig = build_rig(tree, RigOptions(max_joints=max_joints))
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            clip = bake_wind(tree, rig, options, seed=args.seed)
            times.append(time.perf_counter() - t0)
        k, j = clip.rotations.shape[:2]
        sec = statistics.median(times)
        print(f"{max_joints:>7} {j:>7} {k:>7} {sec:>8.3f} {1e6 * sec / (j * k):>15.2f}")


if __name__ == "__main__":
    main()
