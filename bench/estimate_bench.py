"""`treegen batch --dry-run`'s time estimate against the builds it estimates.

    python bench/estimate_bench.py

For a few bundled species and option sets: the dry run's estimate (batch.plan.estimate with
the planning's own CPU seconds, "plan"; and without a plan, "model", the ETA of a run) and
the CPU seconds of the build it stands for (pipeline.build_asset plus writing the GLB, in this
process: the work a worker does), with the ratios; and the dry run's planning itself
(seconds, share of the build). CPU seconds, not wall: the box is shared. The model's
constants (batch/plan.py) were fitted on these same builds: the ratios say how well the
model fits them, not how it does on other trees.

Measured 2026-11-26 (2-core box, helpers running; CPU s). Before, the dry run's model was
0.03 s + 0.9 µs a vertex + 0.1 s for LODs + 0.5 ms a frame: it read 0.48 s for a default
aspen that took 2.6 s of wall time in a loaded worker (a new user's trial: ~4× low), and without a
plan it took every species whole, budgets ignored (fir mobile: 22× high). Now:

    species          options                 build   plan  ratio  model  ratio planning  share
    quaking_aspen    {}                       1.33   1.41   1.06   1.47   1.10     0.61   0.46
    black_tupelo     {}                       2.43   2.33   0.96   4.36   1.80     1.29   0.53
    ca_black_oak     {}                       3.08   2.15   0.70   3.49   1.13     1.07   0.35
    weeping_willow   {"profile": "web"}       1.44   1.19   0.82   0.80   0.56     0.88   0.61
    palm             {"profile": "mobile"}    0.44   0.38   0.85   0.39   0.87     0.14   0.31
    balsam_fir       {"profile": "mobile"}    0.49   0.41   0.85   0.40   0.83     0.17   0.34
    lombardy_poplar  {"no_lod": true}         0.24   0.32   1.35   0.50   2.10     0.02   0.09
    median estimate / build: plan 0.85 (range 0.70-1.35), model 1.10 (range 0.56-2.10)

(with a CI run on the box; an earlier quieter run of the same builds: plan 0.99, 0.83-1.15).
A worker's start (imports, ~0.5-1 s once per worker) is not in either.
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treegen_cli.batch import estimate, load_catalogue, plan_jobs, plan_trees  # noqa: E402
from treegen_cli.exchange import export  # noqa: E402
from treegen_cli.pipeline import build_asset  # noqa: E402

JOBS = [
    ("quaking_aspen", {}),
    ("black_tupelo", {}),
    ("ca_black_oak", {}),
    ("weeping_willow", {"profile": "web"}),
    ("palm", {"profile": "mobile"}),
    ("balsam_fir", {"profile": "mobile"}),
    ("lombardy_poplar", {"no_lod": True}),
]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        entries = [
            {"species": str(ROOT / "species" / f"{name}.txt"), "seeds": [1], **opts} for name, opts in JOBS
        ]
        (tmp / "cat.json").write_text(json.dumps({"defaults": {"formats": ["glb"]}, "entries": entries}))
        cat = load_catalogue(tmp / "cat.json")
        plan = plan_jobs(cat, tmp / "out")
        spent: dict[str, float] = {}
        shapes = plan_trees(cat, plan.build, spent)
        with_plan = estimate(cat, plan, shapes, spent)
        model = estimate(cat, plan)
        print(
            f"{'species':16} {'options':22} {'build':>6} {'plan':>6} {'ratio':>6} {'model':>6} {'ratio':>6} "
            f"{'planning':>8} {'share':>6}"
        )
        ratios_p, ratios_m = [], []
        for (name, opts), job in zip(JOBS, plan.build):
            r = cat.resolved[job.task]
            t0 = time.process_time()
            asset, _ = build_asset(cat.params[job.species], r.seed, r.options)
            export(asset, tmp / f"{name}.glb")
            built = time.process_time() - t0
            p, m = with_plan[job.output][1], model[job.output][1]
            ratios_p.append(p / built)
            ratios_m.append(m / built)
            planning = spent[job.task]
            print(
                f"{name:16} {json.dumps(opts):22} {built:6.2f} {p:6.2f} {p / built:6.2f} {m:6.2f} {m / built:6.2f} "
                f"{planning:8.2f} {planning / built:6.2f}",
                flush=True,
            )
        print(
            f"median estimate / build: plan {statistics.median(ratios_p):.2f} "
            f"(range {min(ratios_p):.2f}-{max(ratios_p):.2f}), model {statistics.median(ratios_m):.2f} "
            f"(range {min(ratios_m):.2f}-{max(ratios_m):.2f})"
        )


if __name__ == "__main__":
    main()
