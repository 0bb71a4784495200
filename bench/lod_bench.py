"""LOD keys and cost on the four Weber–Penn paper species (the paper's Table 3, honestly).

    python bench/lod_bench.py [--durations 4,10,30] [--species quaking_aspen,...] [--tables 1,2]
                              [--repeat 1]

Table 1, per species at the paper's 30 m and 130 m (fov 60°, width 1920, i = error_px = 1, the
full LOD0 tree and its default 10 s / 30 fps wind): the default bounded schedule and the
paper's rule side by side — keys kept (% of dense), animation bytes (% of dense), max error
measured perspective-true (any camera at that distance from the centre of the tree's bounds;
`lod_decimate.measure_error_px`), leaf-vertex updates per frame, decimation seconds.

Table 2, per species and clip length: the default `treegen make` (GLB, in-process through
`api.make`): whole make seconds and the process's CPU seconds over it (every thread: the
texture thread, llvmpipe's for the impostor), LOD stage seconds and its share, LOD seconds per
clip second (flat = linear in clip length), switch distances (from the tree's height on screen)
and triangles per LOD; medians of `--repeat` runs after one warm-up make. Seconds are measured
on a shared box: read ratios, not absolutes.

Measured 2026-11-27 (table 2, the aspen's default make, 10 s clip, `--repeat 7`, each checkout
by PYTHONPATH; load about 1): cd1e81e 1.36 s wall / 1.67 CPU-s → 1.14 s / 1.27 CPU-s after the
cover estimator's faster binning, one BLAS thread in build_asset (idle OpenBLAS threads spun),
the PNG on a second thread and the decimation reusing every other frame's poses. An in-process
A/B of 18 makes each, alternating checkouts (load 0.5-1.6): 1.13-1.25 → 1.03-1.05 s wall
(paired 0.85-0.90×), 1.43-1.56 → 1.14-1.17 CPU-s. Still above the issue's 1.0 s.

Measured again 2026-11-27 (the same run, e8c7316 → a47705d alternating, eight runs each, the
first four at 8d3cf63; a parallel render kept the load at 1.5-4): medians 1.13 → 1.03 s
wall, 1.17 → 1.07 CPU-s, LOD stage 0.21 → 0.195 s (runs 1.05-1.26 → 0.94-1.18 s). Two warm
processes alternating make by make (30 makes each): 1.15 → 1.00 s wall (paired median
0.87×), 1.20 → 1.06 CPU-s (0.89×), LOD stage 0.215 → 0.190 s (0.89×); generate 0.29 →
0.20 s, wind 0.23 → 0.21 s. From LOD0's cover measured once per grid, the stratified leaf
order kept across LODs, in-place stem sampling, the playback check re-slerping only what a
key changes, the wind's per-joint axis sums written out (not np.einsum) and calibration
draws clearing only their cells. Left as they are, since any change moves output bits: the
impostor's GL draw (about 0.2 s of llvmpipe) and the 512² eigensolve (about 50 ms with its
triangular solves).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from treegen_cli import api
from treegen_cli.lod import LOD_DEFAULTS
from treegen_cli.lod_report import PAPER_DISTANCES, schedule_rows
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--durations", default="4,10,30")
    ap.add_argument("--species", default=",".join(SPECIES))
    ap.add_argument("--tables", default="1,2", help="which tables to print")
    ap.add_argument("--repeat", type=int, default=1, help="table 2: median of this many makes")
    args = ap.parse_args()
    tables = args.tables.split(",")
    species = args.species.split(",")
    durations = [float(x) for x in args.durations.split(",")]

    if "1" in tables:
        schedules(species)
    if "2" in tables:
        stage_seconds(species, durations, args.repeat)


def schedules(species: list[str]) -> None:
    print(
        f"{'species':<16}{'dist m':>7}  {'schedule':<9}{'keys kept':>17}{'anim bytes':>19}"
        f"{'max err px':>11}{'updates/frame':>15}{'seconds':>9}"
    )
    for name in species:
        asset, _ = build_asset(load_params(ROOT / "species" / f"{name}.txt"), 0, MakeOptions(lod=None))
        for r in schedule_rows(asset.lods[0], PAPER_DISTANCES, LOD_DEFAULTS):
            pct = 100.0 * r["animation_bytes"] / r["animation_bytes_dense"]
            print(
                f"{name:<16}{r['distance_m']:>7g}  {r['schedule']:<9}{r['keys_kept']:>9,} "
                f"{r['keys_kept_pct']:>6.1f}%{r['animation_bytes']:>11,} {pct:>6.1f}%"
                f"{r['max_error_px']:>11.3f}{r['leaf_vertex_updates_per_frame']:>15,.0f}"
                f"{r['seconds']:>9.2f}"
            )
    print()


def stage_seconds(species: list[str], durations: list[float], repeat: int = 1) -> None:
    print(
        f"{'species':<16}{'clip s':>7}{'make s':>8}{'cpu s':>7}{'lod s':>7}{'lod/make':>9}"
        f"{'lod s/clip s':>13}  switch m / triangles per LOD"
    )
    with tempfile.TemporaryDirectory() as tmp:
        api.make(ROOT / "species" / "quaking_aspen.txt", Path(tmp) / "warm.glb")  # imports, GL
        for name in species:
            for duration in durations:
                runs = []
                for _ in range(max(repeat, 1)):
                    cpu = time.process_time()
                    s = api.make(
                        ROOT / "species" / f"{name}.txt", Path(tmp) / f"{name}.glb", duration=duration
                    )
                    runs.append((s["seconds"], time.process_time() - cpu, s["stages_s"].get("lod", 0.0)))
                wall, cpu_s, lod_s = (statistics.median(r[i] for r in runs) for i in range(3))
                lods = " ".join(f"{r['distance_m']:.0f}:{r['triangles']:,}" for r in s["lods"])
                print(
                    f"{name:<16}{duration:>7g}{wall:>8.2f}{cpu_s:>7.2f}{lod_s:>7.2f}"
                    f"{lod_s / wall:>9.2f}{lod_s / duration:>13.3f}  {lods}"
                )


if __name__ == "__main__":
    main()
