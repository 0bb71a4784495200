"""Wind bake benchmark: per species, the natural frequencies (lowest modes, and the crown's sway:
its motion's spectral peak at 4 m/s, wind.sway), the bake time of a 10 s, 30 fps clip at the default joint budget (wall and CPU seconds,
medians; on a shared machine the CPU time is the one to compare), and the amplitudes at 4 and
12 m/s (tree top's lean and RMS sway, largest joint turn, median leaf movement).
Target (issue 14): bake under 0.5 s at the default budget, the willow ≤ 1 s.

    python bench/wind_bench.py [species ...] [--seed N] [--repeat N]
    python bench/wind_bench.py weeping_willow --joints 128,256,512,900
    (default: the paper's four species; OPENBLAS_NUM_THREADS=1 is faster on a busy machine;
    --joints: the median leaf movement at 4 m/s per joint budget instead)

Measured 2026-11-26 07:50 (load 8-11; read the cpu column), before the rig spent the whole
joint budget: joints 256 / 210 / 222 / 238, sway (the mode carrying the trunk top's static
deflection) 0.565 / 0.393 / 0.201 / 0.511 Hz, cpu 0.168 / 0.099 / 0.306 / 0.133 s for the aspen,
tupelo, willow and oak; the willow's largest joint turn 11.1° / 33.5° at 4 / 12 m/s. Before the
willow's sag stiffness its sway mode was 0.535 Hz and its median leaf moved 2.1 / 13.8 cm.
Measured 2026-11-26 23:30 (quiet box, same command) after the rig spends the whole joint budget
(rig.py: every species now has 256 joints) and `sway Hz` became the crown's spectral peak (it was
the mode carrying the trunk top's static deflection, which on the finer rig was one heavy willow
limb's 0.11 Hz pendulum):
species          joints              modes Hz  sway Hz  bake s  cpu s    m/s     ζ  lean m  sway m  max ° leaf cm
quaking_aspen       256      0.56, 0.56, 0.85    0.550   0.143  0.143      4  0.22    0.10    0.03    5.9    14.5
                                                                          12  0.28    0.56    0.24   19.5    93.7
black_tupelo        256      0.39, 0.39, 0.69    0.300   0.136  0.136      4  0.23    0.23    0.07    5.4    18.8
                                                                          12  0.30    1.28    0.49   20.7   118.7
weeping_willow      256      0.11, 0.11, 0.19    0.158   0.303  0.303      4  0.21    0.03    0.01   24.4     7.8
                                                                          12  0.25    0.15    0.04   38.4    43.5
ca_black_oak        256      0.51, 0.51, 0.87    0.458   0.142  0.142      4  0.16    0.03    0.01    2.1     1.9
                                                                          12  0.17    0.14    0.07   11.1    14.5
(At 4 m/s the tupelo's and the oak's crowns follow the gusts below their first mode: 0.30 and
0.46 Hz against 0.39 and 0.51.)
--joints on the willow before the sag stiffness (median leaf cm at 4 m/s): 2.07 / 2.07 / 2.16 at
256 / 512 / 900 joints.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from treegen_cli.generate import generate
from treegen_cli.params import load_params
from treegen_cli.rig import RigOptions, build_rig
from treegen_cli.skeleton import pose_world
from treegen_cli.wind import WindOptions, bake_wind, wind_report

ROOT = Path(__file__).resolve().parent.parent
PAPER = ["quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak"]


def median_leaf_motion(tree, rig, clip, every: int = 29) -> float:
    """Median over leaves of the largest distance a leaf base moves from rest in the loop (m)."""
    j = rig.leaf_joint[::every].astype(int)
    local = np.einsum(
        "lab,lb->la",
        np.linalg.inv(rig.skeleton.bind_world[j]),
        np.c_[tree.leaf_pos[::every], np.ones(len(j))],
    )
    x = np.einsum("klab,lb->kla", pose_world(rig.skeleton, clip.rotations)[:, j], local)[..., :3]
    return float(np.median(np.linalg.norm(x - tree.leaf_pos[::every][None], axis=2).max(axis=0)))


def species_path(name: str) -> str:
    """A species file, or a bundled species by its name."""
    return name if Path(name).suffix else str(ROOT / "species" / f"{name}.txt")


def leaf_motion_by_budget(paths: list[str], budgets: list[int], seed: int) -> None:
    """Median leaf movement at 4 m/s per joint budget: does the budget limit it?"""
    print(f"{'species':<16}{'budget':>7}{'joints':>7}{'bake s':>8}{'leaf cm':>8}")
    for path in paths:
        params = load_params(path)
        tree = generate(params, seed)
        for budget in budgets:
            rig = build_rig(tree, RigOptions(max_joints=budget))
            t0 = time.perf_counter()
            clip = bake_wind(tree, rig, WindOptions(), seed=seed)
            wall = time.perf_counter() - t0
            print(
                f"{params.name:<16}{budget:>7}{len(rig.joint_node):>7}{wall:>8.2f}"
                f"{100 * median_leaf_motion(tree, rig, clip):>8.2f}",
                flush=True,
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="*", default=PAPER)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--joints", help="comma-separated joint budgets: leaf movement per budget")
    args = ap.parse_args()
    paths = [species_path(s) for s in args.species]
    if args.joints:
        leaf_motion_by_budget(paths, [int(b) for b in args.joints.split(",")], args.seed)
        return

    print(
        f"{'species':<16}{'joints':>7}{'modes Hz':>22}{'sway Hz':>9}{'bake s':>8}{'cpu s':>7}"
        f"{'':>3}{'m/s':>4}{'ζ':>6}{'lean m':>8}{'sway m':>8}{'max °':>7}{'leaf cm':>8}"
    )
    for path in paths:
        params = load_params(path)
        tree = generate(params, args.seed)
        rig = build_rig(tree)
        options = WindOptions(duration=10.0, fps=30.0)
        times, cpu = [], []
        for _ in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            bake_wind(tree, rig, options, seed=args.seed)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        for k, speed in enumerate((4.0, 12.0)):
            o = WindOptions(speed=speed, duration=10.0, fps=30.0)
            rep = wind_report(tree, rig, o, args.seed)
            leaf = (
                f"{100 * median_leaf_motion(tree, rig, bake_wind(tree, rig, o, seed=args.seed)):>8.1f}"
                if tree.n_leaves
                else f"{'-':>8}"
            )
            modes = ", ".join(f"{m['hz']:.2f}" for m in rep["modes"][:3])
            head = (
                (
                    f"{params.name:<16}{len(rig.joint_node):>7}{modes:>22}{rep['sway_hz']:>9.3f}"
                    f"{statistics.median(times):>8.3f}{statistics.median(cpu):>7.3f}"
                )
                if k == 0
                else " " * 69
            )
            print(
                f"{head}{'':>3}{speed:>4g}{rep['sway_damping']:>6.2f}{rep['top_lean_m']:>8.2f}"
                f"{rep['top_sway_rms_m']:>8.2f}{rep['max_joint_deg']:>7.1f}{leaf}",
                flush=True,
            )


if __name__ == "__main__":
    main()
