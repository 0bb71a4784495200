"""LOD pops in motion: how far the crown's top moves differently in LOD k than in LOD k−1 at
k's switch, through the whole wind clip (the rest-pose silhouettes of lod_pop_bench.py do not
see it), and how far each LOD leans downwind against LOD0.

    python bench/lod_motion_bench.py [--species quaking_aspen,...] [--wind-speed 6]

Per species (default `make` options, impostor left out, texture 128): the crown's top fifth of
leaf vertices (by height), its mean displacement from rest at 24 poses through the clip, as the
file plays it (the decimated keys); `jump px` is the largest difference between consecutive
LODs over the clip, in pixels of the default view (fov 60°, 1920 px) at the switch distance;
`lean` is each LOD's clip-mean displacement over LOD0's (1 = leans as far).

Measured 2026-11-26, wind 6 m/s (`--species quaking_aspen,black_tupelo,ca_black_oak`; "before"
is commit 9c96ff8 run with this script, each LOD baked from its own thinned leaves and pruned
rig; "after", wind_lods.lod_angles fits LOD0's bends onto each LOD's rig), switches 1 / 2 / 3:
                  jump px before      jump px after       lean before         lean after
    quaking_aspen 5.68 / 3.65 / 0.84  0.81 / 0.39 / 0.76  0.70 / 1.12 / 1.10  0.97 / 0.97 / 0.93
    black_tupelo  2.61 / 4.39 / 0.79  0.43 / 0.52 / 0.43  0.90 / 1.42 / 1.26  1.00 / 1.00 / 1.04
    ca_black_oak  0.40 / 0.33 / 0.26  0.40 / 0.28 / 0.20  0.87 / 0.76 / 0.36  0.98 / 0.87 / 0.65
    shave_grass   (leafless: its twigs)   0.53 / 0.45 / 0.52                      0.98 / 1.02 / 1.17
(The oak's LOD3 leans 0.65 × at 0.20 px: its top fifth is other leaves, and it barely moves at
that distance. tests/test_wind_lods.py asserts ≤ 1.5 px and lean within 20 % for the aspen and
the tupelo.)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from lbs import skin_frames  # noqa: E402

from treegen_cli.api import resolve  # noqa: E402
from treegen_cli.drawable import from_asset  # noqa: E402
from treegen_cli.lod import LodOptions  # noqa: E402
from treegen_cli.params import load_params  # noqa: E402
from treegen_cli.pipeline import build_asset  # noqa: E402
from treegen_cli.silhouette import metres_per_pixel  # noqa: E402

SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")
POSES = 24


def crown_top_motion(asset, k: int, t: np.ndarray) -> np.ndarray:
    """(T, 3) mean displacement from rest of LOD k's leaf vertices (a leafless tree's bark)
    in the crown's top fifth."""
    d = from_asset(asset, k)
    leaves = [p for p in d.parts if p.double_sided and len(p.positions)]
    leaves = leaves or [p for p in d.parts if len(p.positions)]  # leafless: its twigs
    rest = np.concatenate([p.positions for p in leaves]).astype(np.float64)
    skin = d.pose(t)
    top = rest[:, 1] > np.quantile(rest[:, 1], 0.8)  # drawables are Y up
    moved = np.concatenate([skin_frames(skin, p.positions, p.joints, p.weights) for p in leaves], axis=1)
    return (moved[:, top] - rest[top]).mean(axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default=",".join(SPECIES))
    ap.add_argument("--wind-speed", type=float, default=6.0)
    args = ap.parse_args()
    print(f"{'species':<16}{'switch':>7}{'distance m':>12}{'jump px':>9}{'lean':>7}")
    for name in args.species.split(","):
        job = resolve(dict(texture_size=128, wind_speed=args.wind_speed, impostor=False))
        asset, _ = build_asset(load_params(ROOT / "species" / f"{name}.txt"), 0, job.options)
        t = np.linspace(0.0, from_asset(asset, 0).duration, POSES, endpoint=False)
        motion = [crown_top_motion(asset, k, t) for k in range(len(asset.lods))]
        lean0 = np.linalg.norm(motion[0].mean(axis=0))
        for k in range(1, len(asset.lods)):
            px = metres_per_pixel(asset.lods[k].distance, LodOptions())
            jump = np.linalg.norm(motion[k] - motion[k - 1], axis=1).max() / px
            lean = np.linalg.norm(motion[k].mean(axis=0)) / max(lean0, 1e-12)
            print(f"{name:<16}{k:>7}{asset.lods[k].distance:>12.1f}{jump:>9.2f}{lean:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
