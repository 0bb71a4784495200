"""`treegen batch` vs a loop of `treegen make` (issue 15): a 24-job catalogue, the four paper
species × 6 seeds to GLB (short clips by default so the whole bench takes a few minutes; every
stage still runs). Prints wall seconds for

    loop (processes)   `treegen make` run once per job, as a shell loop does today
    loop (in-process)  api.make per job in one process: the pure build time, no start-up
    batch, N workers   `treegen batch --workers N` (embedded LocalCluster; start-up included)

with the speed-up of each over the process loop, and the scheduler overhead per job: with one
worker the jobs run back to back, so the time between two results arriving at the client, less
the later job's build seconds on the worker, is what Dask and the batch add per job.

    python bench/batch_bench.py [--seeds 6] [--full-clip] [--workers 1,2]

Target on the shared 2-core box: 2 workers ≥ 1.7× faster than the loop, overhead < 50 ms/job.
Measured there (other sessions' load average ~3–4 on the 2 cores, so 2 workers do not get two
free cores; byte-identical outputs checked in every run):

    run                                 wall s  vs loop  notes
    loop (treegen make processes)         40.4    1.00×
    loop (api.make in one process)        20.8    1.94×
    treegen batch --workers 1             21.7    1.86×  19.5 s building on workers; cluster start+stop 0.7 s
    treegen batch --workers 2             16.3    2.48×  28.2 s building on workers
    scheduler overhead per job (1 worker): 2 ms

Again 2026-11-27 (load 0.7-2.4; every job now renders an impostor, so each costs more):

    loop (treegen make processes)        109.5    1.00×
    loop (api.make in one process)        74.0    1.48×
    treegen batch --workers 1             71.8    1.53×  69.3 s building on workers; cluster start+stop 1.0 s
    treegen batch --workers 2             46.7    2.34×  88.6 s building on workers
    scheduler overhead per job (1 worker): 4 ms
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAPER_SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")
ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
ENV.pop("DASK_SCHEDULER_ADDRESS", None)


def catalogue(seeds: int, clip: dict) -> dict:
    return {
        "defaults": {**clip, "seeds": f"1-{seeds}"},
        "entries": [{"species": str(ROOT / "species" / f"{s}.txt")} for s in PAPER_SPECIES],
    }


def jobs(seeds: int) -> list[tuple[str, int]]:
    return [(s, seed) for s in PAPER_SPECIES for seed in range(1, seeds + 1)]


def loop_processes(out: Path, seeds: int, clip_args: list[str]) -> float:
    t0 = time.perf_counter()
    for s, seed in jobs(seeds):
        subprocess.run(
            [
                sys.executable,
                "-m",
                "treegen_cli",
                "make",
                str(ROOT / "species" / f"{s}.txt"),
                "-o",
                str(out / f"{s}_{seed}.glb"),
                "--seed",
                str(seed),
                *clip_args,
                "-q",
            ],
            env=ENV,
            check=True,
        )
    return time.perf_counter() - t0


def loop_in_process(out: Path, seeds: int, clip: dict) -> float:
    sys.path.insert(0, str(ROOT))
    from treegen_cli import api

    t0 = time.perf_counter()
    for s, seed in jobs(seeds):
        api.make(ROOT / "species" / f"{s}.txt", out / f"{s}_{seed}.glb", seed=seed, **clip)
    return time.perf_counter() - t0


def batch(cat: Path, out: Path, workers: int) -> tuple[float, dict, list[tuple[float, float]]]:
    """Wall seconds, the manifest, and per built job (in arrival order): when its result line
    arrived (seconds since start) and how long it built on its worker."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "batch",
            str(cat),
            "-o",
            str(out),
            "--workers",
            str(workers),
            "--json",
        ],
        env=ENV,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    arrived = [
        (time.perf_counter() - t0, json.loads(line)["seconds"])
        for line in proc.stdout
        if '"event": "built"' in line
    ]
    err = proc.stderr.read()
    wall = time.perf_counter() - t0
    if proc.wait() != 0:
        raise SystemExit(f"treegen batch failed:\n{err}")
    return wall, json.loads((out / "manifest.json").read_text()), arrived


def cluster_start_stop(workers: int) -> float:
    """Seconds to start and close an embedded cluster of `workers` processes, in a fresh
    process like the batch's (so imports count the same)."""
    code = (
        "import time; t=time.perf_counter(); from treegen_cli.executor import dask_client\n"
        f"with dask_client(None, {workers}) as c: pass\n"
        "print(time.perf_counter()-t)"
    )
    return float(
        subprocess.run(
            [sys.executable, "-c", code], env=ENV, capture_output=True, text=True, check=True
        ).stdout.split()[-1]
    )


def same_bytes(a: Path, b: Path) -> bool:
    names = sorted(p.name for p in a.glob("*.glb"))
    return names == sorted(p.name for p in b.glob("*.glb")) and all(
        (a / n).read_bytes() == (b / n).read_bytes() for n in names
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=6, help="seeds per species (24 jobs at 6)")
    ap.add_argument("--full-clip", action="store_true", help="the default 4 s, 30 fps clip")
    ap.add_argument("--workers", default="1,2", help="batch worker counts to time")
    args = ap.parse_args()
    clip = {} if args.full_clip else {"duration": 1, "fps": 10}
    clip_args = [a for k, v in clip.items() for a in (f"--{k}", str(v))]
    n = len(jobs(args.seeds))
    rows = []
    with tempfile.TemporaryDirectory(prefix="batch_bench.") as tmp:
        tmp = Path(tmp)
        cat = tmp / "catalogue.json"
        cat.write_text(json.dumps(catalogue(args.seeds, clip)))
        ref = tmp / "loop"
        ref.mkdir()
        t_loop = loop_processes(ref, args.seeds, clip_args)
        rows.append(("loop (treegen make processes)", t_loop, ""))
        inproc = tmp / "inproc"
        inproc.mkdir()
        t_in = loop_in_process(inproc, args.seeds, clip)
        assert same_bytes(ref, inproc), "api.make wrote different bytes from treegen make"
        shutil.rmtree(inproc)
        rows.append(("loop (api.make in one process)", t_in, ""))
        overhead = None
        for w in (int(x) for x in args.workers.split(",")):
            out = tmp / f"batch{w}"
            wall, manifest, arrived = batch(cat, out, w)
            assert same_bytes(ref, out), f"batch with {w} workers wrote different bytes"
            work = sum(r["seconds"] for r in manifest["assets"])
            note = f"{work:.1f} s building on workers"
            if w == 1:
                # One worker runs the jobs one after another, so the gap between two results
                # less the later job's own build seconds is what scheduling, transfer and
                # reporting added per job (the first job also pays the worker's imports).
                gaps = [b - a - s for (a, _), (b, s) in zip(arrived, arrived[1:])]
                overhead = sum(gaps) / len(gaps)
                start = cluster_start_stop(1)
                note += f"; cluster start+stop {start:.1f} s"
            rows.append((f"treegen batch --workers {w}", wall, note))
            shutil.rmtree(out)
    print(
        f"{n} jobs: {', '.join(PAPER_SPECIES)} × {args.seeds} seeds → GLB"
        f"{' (1 s clip at 10 fps)' if clip else ''}; {os.cpu_count()} cores"
    )
    print(f"  {'run':<34}{'wall s':>8}{'vs loop':>9}  notes")
    for name, wall, note in rows:
        print(f"  {name:<34}{wall:>8.1f}{t_loop / wall:>8.2f}×  {note}")
    if overhead is not None:
        print(f"  scheduler overhead per job (1 worker): {overhead * 1000:.0f} ms")


if __name__ == "__main__":
    main()
