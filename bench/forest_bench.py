"""Forest benchmark: the 1,000-tree example (examples/forest_1000.json) to .glb and .usdc.
Prints seconds (prototypes / write / total), peak MB (this process + its worker processes,
ru_maxrss), output MB, prototypes, instances per LOD, and leaf-vertex updates per frame with
LOD vs without. Target (issue 6): under 60 s on the 2-core box, output ∝ prototypes.

    python bench/forest_bench.py [layout.json] [--all-lods] [--workers N]

    (run from the repo root with PYTHONPATH=. so the working tree's treegen_cli is used)

Measured (2-core shared box, 7 prototypes × 4 LODs, 1,000 trees, 32 joints, 4 s at 15 fps):
    format  total_s  out_MB  leaf-vertex updates/frame LOD vs no LOD   per LOD
       glb     2.8     42.2          4,258,436 vs 109,765,268      lod1 19, lod2 232, lod3 749
      usdc     2.5     27.0          (same)
    --all-lods: glb 3.9 s / 106 MB, usdc 3.1 s / 59 MB; peak 551 MB main, 320 MB per worker.
"""
from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

from treegen_cli.forest import run_forest

ROOT = Path(__file__).resolve().parent.parent


def _peak_mb() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return own, kids


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("layout", nargs="?", default=str(ROOT / "examples" / "forest_1000.json"))
    ap.add_argument("--all-lods", action="store_true")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    print(f"{'format':>6} {'protos':>6} {'trees':>6} {'proto_s':>8} {'write_s':>8} {'total_s':>8} "
          f"{'out_MB':>8} {'upd/frame LOD':>14} {'no LOD':>12}  per LOD")
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in (".glb", ".usdc"):
            t0 = time.perf_counter()
            s = run_forest(args.layout, Path(tmp) / f"forest{suffix}", all_lods=args.all_lods,
                           workers=args.workers, progress=False)
            total = time.perf_counter() - t0
            print(f"{suffix[1:]:>6} {s['prototypes']:>6} {s['instances']:>6} {s['prototypes_s']:>8.2f} "
                  f"{s['write_s']:>8.2f} {total:>8.2f} {s['bytes'] / 1e6:>8.1f} "
                  f"{s['leaf_vertex_updates_per_frame']:>14,} "
                  f"{s['leaf_vertex_updates_per_frame_without_lod']:>12,}  {s['instances_per_lod']}")
    own, kids = _peak_mb()
    print(f"peak MB: main process {own:.0f}, largest worker {kids:.0f}")


if __name__ == "__main__":
    main()
