"""Forest benchmark: the 1,000-tree example (examples/forest_1000.json) to .glb and .usdc.

Three tables:
  1. per LOD mode (every tree with all its LODs, the default; --camera-lod, one LOD per tree)
     and format: seconds (prototypes / write), output MB, and the size against the sum of the
     prototypes' own files (what `treegen make` writes for each; issue 15: all LODs ≤ 1.2 ×);
  2. building the prototypes: the process pool `treegen forest` used before issue 15 (kept
     here only as the reference) against the Dask path it uses now ("dask": Dask's local
     process scheduler on workers forked from the client, executor.process_pool; "dask fs":
     the same with workers from the fork server, as when the client cannot fork safely) and
     against one process; wall and CPU seconds (the whole process tree) as medians of --reps
     interleaved runs, and whether every path's prototypes write the same bytes (they must).
     (Until 2026-11-27 "dask" was an embedded distributed cluster, as `treegen batch` starts;
     the figures below before that date are for it.)
  3. peak MB (this process + its worker processes, ru_maxrss).

    python bench/forest_bench.py [layout.json] [--workers N] [--reps R]

    (run from the repo root with PYTHONPATH=. so the working tree's treegen_cli is used)

Measured 2026-11-23 (2-core box shared with other jobs, load 16-22; 7 prototypes × 4 LODs,
1,000 trees; `PYTHONPATH=. python bench/forest_bench.py --reps 3`):
       LODs format proto_s write_s out_MB own_MB ratio
        all    glb   25.25    6.33  122.4  106.2  1.15
        all   usdc   25.25    4.01   65.3   66.3  0.98
     camera    glb   15.20    0.96   50.6  106.2  0.48
     camera   usdc   15.20    2.45   31.0   66.3  0.47
    prototypes, 2 workers, median of 3: old pool 14.02 s, Dask 18.33 s (1.31×), one process
    11.40 s (0.81×: on a box this loaded two workers gain nothing); same bytes from every path.
    Before the quiet worker settings (executor.QUIET) Dask was 1.53× the old pool.
Measured 2026-11-26, old pool = 1.00, each run in its own process (`--pools-only`):
    load 10-17, median of 3: Dask with spawned workers 1.46× (16.4 / 24.0 s); with workers
    forked from a fork server that preloads treegen (executor.STARTUP, PRELOAD) 1.13×
    (25.5 / 28.9 s), one process 0.92×.
    quiet box (load ~1), median of 5: old pool 3.99 s, Dask 5.15 s (1.29×; 5.64 s with spawned
    workers), one process 5.75 s. What is left is the cluster's start-up, ~1.2 s, which the
    forked pool never paid; building in this process while the cluster starts was tried and
    gained nothing (6.16 s).
    Idle-box figures before issue 15: camera glb 2.8 s / 42 MB, all LODs 3.9 s / 106 MB.
Where the start-up went (load ~8, CPU seconds): the fork server is a fresh interpreter that
    imports distributed and treegen again, 1.2-1.3 s (0.3 s of it compiling treegen's sources:
    this box sets PYTHONDONTWRITEBYTECODE and the checkouts have no __pycache__), and it was
    launched only after the client had imported distributed (0.3-0.5 s) and started the
    scheduler; workers were ready 2.4-3.7 s after the start. Now the forest's workers are forks
    of the client (executor.dask_client(fork=True), while can_fork(): one Python thread, no
    OpenGL), like the old pool's: ready 0.7-1.4 s after the start, nothing imported again. The
    fork server, still used by batch and when the client cannot fork, is launched first thing.
Measured 2026-11-26 after that, three `--pools-only --reps 5` runs (load 4-13; wall median,
    paired = median of each round's ratio to its old pool run, CPU of the process tree):
                   old pool      dask (forked)             dask fs (fork server)   in process
      load  8-11   22.80 s  25.27 s 1.11× p1.05 cpu1.12×  28.06 s 1.23× p1.13 cpu1.23×  1.03×
      load  4-6    22.77 s  26.38 s 1.16× p1.02 cpu1.03×  28.92 s 1.27× p1.12 cpu1.14×  0.96×
      load  5-9    20.05 s  22.49 s 1.12× p1.13 cpu1.10×  24.79 s 1.24× p1.34 cpu1.22×  1.07×
    same bytes from every path. What is left against the old pool is the client's import of
    distributed and the scheduler (~0.8-1 CPU-s in the client).
    quiet box (load 0.1), one `--pools-only --reps 5` run after the impostor and cover changes
    of the same day (prototypes cost more than in the morning's 3.99 s): old pool 6.24 s, Dask
    (forked) 6.43 s 1.03× (paired 1.09×, CPU 1.03×), fork server 7.22 s 1.16×, in process
    8.67 s 1.39×; same bytes from every path.
Where the Dask path's remaining time went (2026-11-26, load 3-9; rusage and /proc per-thread
    CPU of single runs, py-spy): the client imports dask + distributed, 0.25-0.3 CPU-s (0.35-0.5 s
    wall, before the fork, so on the critical path); LocalCluster 0.03-0.06 s, Client 0.05-0.12 s,
    workers registered ~0.1 s later: the first prototype starts ~0.6 s after build_prototypes is
    called (old pool: 0.05 s). Over a run the client's event-loop thread (scheduler, client,
    results) takes 0.34-0.37 CPU-s and its deserialising thread 0.07; each worker's event loop
    0.23; an idle cluster costs 0.012 CPU-s a second in all. The client in total: 1.6-1.9 CPU-s,
    the old pool's 1.0-1.1. Results are not where it goes: the 44 MB sassafras prototype comes
    back through Dask's comms for 0.075 CPU-s of the process tree (relayed by the scheduler or
    gathered directly alike), through the old pool's pipe for 0.17. Each species' textures cost
    0.08-0.11 CPU-s, drawn by every worker building that species (the old pool: 7 draws for 4
    species); the client now draws those of species with more than one prototype before it forks
    (executor.dask_client(warm=)), 4 draws in all. Tried and dropped: largest prototype first,
    one task per free worker (two 4-round A/B runs against main's Dask disagreed in sign); Dask's
    worker-saturation 1.0 (it only queues large task groups; the forest's tasks are placed on
    workers as submitted); LP_NUM_THREADS for llvmpipe (no CPU change resolvable); results
    through shared memory (would save at most ~0.025 CPU-s per 44 MB against Dask's comms).
    `--pools-only --reps 3` (wall median, paired, CPU of the process tree):
                          old pool   dask (forked)                dask fs        in process
      before (main)  load 3.5-7.8  22.90 s  26.29 s 1.15× p1.23 cpu1.14×  1.23× cpu1.19×  1.03×
      after          load 4.6-5.2  13.12 s  12.66 s 0.97× p0.98 cpu0.99×  1.07× cpu1.07×  0.91×
      after, again   load 4.7-6.4  12.11 s  13.77 s 1.14× p1.11 cpu1.19×  1.06× cpu1.20×  0.90×
    same bytes from every path; one process is as fast as two workers on a box this loaded.
    Runs at this load spread by ±10 % (the two `after` rows; the two A/B runs above gave main's
    Dask 1.03× / 0.94× paired and this one 1.10× / 0.88×): the Dask path is not shown slower than
    the old pool, nor faster; the textures drawn once save ~0.27 CPU-s by count, below what
    these runs resolve. A quiet box (load < 1) is needed to settle the last few per cent.

    Nearly quiet box (no helpers; load 1.3-2.5 left over from them), `--pools-only --reps 5`,
    main against the same code with the client-side texture warm-up switched off, run in turn:
                          old pool   dask (forked)                dask fs
      warm-up (main)      6.02 s   7.33 s 1.22× p1.17 cpu1.05×    1.20× cpu1.14×  (first run)
      no warm-up          6.10 s   6.64 s 1.09× p1.07 cpu1.08×    1.25× cpu1.20×
      warm-up (main)      6.20 s   6.89 s 1.11× p1.11 cpu1.04×    1.20× cpu1.17×
      no warm-up          5.94 s   6.74 s 1.13× p1.10 cpu1.09×    1.20× cpu1.14×
    in process 1.36-1.48×; same bytes from every path. The warm-up makes no difference these
    runs resolve (it stays: 3 texture draws fewer). The forked Dask path is ~1.1× the old pool
    (0.6-0.7 s a run): the client's distributed import and scheduler start before the first
    prototype, as measured above. Not "no slower than before" yet.
2026-11-26, late: per-task timelines (a timed build_prototype in each worker) showed two more
    costs. (1) Placement: Dask's worker-saturation 1.1 gives a single-threaded worker two tasks,
    so one worker ran four prototypes (5.4 s) while the other idled its last 2.4 s; now 1.0,
    the prototypes sent in one client.map. (2) Results: a 44 MB prototype reached the client
    0.16-0.32 s after its task ended (Dask's comms, the worker's loop contending with its next
    build for the GIL); pickled to a shared temporary folder it takes 0.04-0.1 s
    (forest.build.build_prototype_to; 0.027 s to pickle, 0.012 s to load). `--pools-only`:
                          old pool   dask (forked)                dask fs    in process
      before (load ~0.3)  5.36 s   6.55 s 1.22× p1.25 cpu1.06×    1.19×      1.35×   (reps 3)
      (1)    (load ~0.6)  5.40 s   6.03 s 1.12× p1.11 cpu1.05×    1.22×      1.42×   (reps 4)
      (1)+(2) (load 1.3)  5.73 s   6.09 s 1.06× p1.09 cpu1.03×    1.41×      1.46×   (reps 5)
    What is left is before the first prototype: the client imports dask and distributed
    (0.21 s), draws the shared textures (0.23 s), starts the scheduler and the workers register
    (0.18 s), all on one core while the other idles; the old pool's first task starts 0.015 s
    after the call. Largest prototype first (priority from generate's expected counts) was
    tried: 5.88 vs 5.80 s (medians of 4), the two sassafras built side by side take 2.4-2.7 s
    each against 2.0-2.2 s beside smaller ones. Dask's own multiprocessing scheduler (no
    cluster) was tried: 5.89 s, its client loads each result before sending the next task.
Measured 2026-11-27: "dask" is now Dask's local process scheduler (dask.multiprocessing.get)
    on a pool forked from the client (executor.process_pool): no distributed import, scheduler
    or comms on the critical path; dask itself is imported before the fork so the workers
    inherit it (imported after, each worker's first task imported it again: 1.04×), and
    results cross once, pickled by the pool (Dask's default cloudpickles them to bytes first).
    Quiet box (load 0.7-2.4), `--pools-only --reps 5`:
        old pool 5.12 s, dask 5.18 s 1.01× (paired 1.01×, CPU 1.00×), dask fs 1.16×,
        in process 1.30×; same bytes from every path. The embedded distributed cluster it
        replaces measured 1.09× (paired, 8 rounds, load 2-3) the same morning.
    After the review's fixes (results as pickle files whose path alone crosses the pool's
    pipe; workers that exit with their parent), load 0.9-2.6, `--pools-only --reps 5`:
        old pool 5.47 s, dask 5.54 s 1.01× (paired 1.01×, CPU 1.02×), dask fs 1.22×,
        in process 1.38×; same bytes from every path.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import resource
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from treegen_cli import executor
from treegen_cli.exchange import export, export_forest
from treegen_cli.forest import build_prototypes, build_scene, load_layout
from treegen_cli.forest.build import build_prototype, make_options

ROOT = Path(__file__).resolve().parent.parent


def _peak_mb() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return own, kids


def old_pool(keys, params, options, workers: int) -> list:
    """The pre-Dask prototype pool (a concurrent.futures process pool), as a reference."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(build_prototype, params[p], s, options) for p, s in keys]
        return [f.result() for f in futures]


def sizes(layout_path: str, workers: int | None, tmp: Path) -> None:
    layout = load_layout(layout_path)
    print(
        f"{'LODs':>7} {'format':>6} {'protos':>6} {'trees':>6} {'proto_s':>8} {'write_s':>8} "
        f"{'out_MB':>8} {'own_MB':>8} {'ratio':>6}"
    )
    own: dict[str, float] = {}
    for all_lods in (True, False):
        scene = build_scene(layout, all_lods=all_lods, workers=workers, progress=False)
        for suffix in (".glb", ".usdc"):
            if suffix not in own:  # the prototypes' own files, as `treegen make` writes them
                own[suffix] = sum(
                    p.stat().st_size
                    for k, a in enumerate(scene.prototypes)
                    for p in export(a, tmp / f"proto{k}{suffix}")
                )
            t0 = time.perf_counter()
            out = sum(p.stat().st_size for p in export_forest(scene, tmp / f"forest{suffix}"))
            write = time.perf_counter() - t0
            print(
                f"{'all' if all_lods else 'camera':>7} {suffix[1:]:>6} {len(scene.prototypes):>6} "
                f"{len(scene.instances):>6} {scene.timings['prototypes_s']:>8.2f} {write:>8.2f} "
                f"{out / 1e6:>8.1f} {own[suffix] / 1e6:>8.1f} {out / own[suffix]:>6.2f}"
            )


METHODS = ("old pool", "dask", "dask fs", "in process")


def one_build(layout_path: str, method: str, workers: int) -> None:
    """`--one METHOD`: build the prototypes once, in this fresh process, and print the
    seconds and a digest of their GLB bytes as JSON. Each run gets its own process because
    the impostor renders with OpenGL, and a fork of a process holding a live llvmpipe context
    hangs in its first framebuffer read: the old pool and the forest's Dask cluster fork
    their parent."""
    layout = load_layout(layout_path)
    keys = sorted({(p.species, p.seed) for p in layout.placements}, key=lambda k: (str(k[0]), k[1]))
    options = make_options(layout)
    t0 = time.perf_counter()
    if method == "dask fs":  # the embedded cluster's other start: workers from the fork server
        executor.can_fork = lambda: False
    if method == "old pool":
        built = old_pool(keys, layout.params, options, workers)
    else:
        built = build_prototypes(
            keys, options, 1 if method == "in process" else workers, False, layout.params
        )
    seconds = time.perf_counter() - t0
    digest = hashlib.sha256()
    with tempfile.TemporaryDirectory() as tmp:
        for k, a in enumerate(built):
            digest.update(export(a, Path(tmp) / f"p{k}.glb")[0].read_bytes())
    print(json.dumps({"seconds": seconds, "sha": digest.hexdigest(), "prototypes": len(keys)}))


def run_one(cmd: list[str]) -> tuple[dict, float]:
    """Run `--one` and return its JSON and the CPU seconds of its whole process tree (the
    fork server's workers are not its children), sampled every 20 ms from here: a thread in
    that process would stop its cluster forking."""
    import psutil

    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    cpu: dict[int, float] = {}
    root = psutil.Process(proc.pid)
    while proc.poll() is None:
        try:
            tree = [root, *root.children(recursive=True)]
        except psutil.Error:
            tree = []
        for p in tree:
            try:
                t = p.cpu_times()
                cpu[p.pid] = t.user + t.system
            except psutil.Error:
                pass
        time.sleep(0.02)
    out, _ = proc.communicate()
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode})")
    return json.loads(out), sum(cpu.values())


def pools(layout_path: str, workers: int, reps: int) -> None:
    runs: dict[str, list[float]] = {m: [] for m in METHODS}
    cpus: dict[str, list[float]] = {m: [] for m in METHODS}
    shas, n = set(), 0
    for _ in range(reps):  # interleaved, so a busy spell hits every method alike
        for method in METHODS:
            cmd = [sys.executable, __file__, layout_path, "--workers", str(workers), "--one", method]
            out, cpu = run_one(cmd)
            runs[method].append(out["seconds"])
            cpus[method].append(cpu)
            shas.add(out["sha"])
            n = out["prototypes"]
    base = statistics.median(runs["old pool"])
    cbase = statistics.median(cpus["old pool"])
    print(
        f"\nprototypes ({n}), {workers} workers, median of {reps} (CPU: the whole process tree, "
        "imports and digest included; paired: median of each round's ratio to that round's "
        "old pool, steadier when the load drifts):"
    )
    for name, ts in runs.items():
        m, c = statistics.median(ts), statistics.median(cpus[name])
        paired = statistics.median(t / b for t, b in zip(ts, runs["old pool"]))
        print(
            f"  {name:>10}  {m:6.2f} s ({m / base:.2f}×, paired {paired:.2f}×)  CPU {c:6.2f} s "
            f"({c / cbase:.2f}×)  runs " + " ".join(f"{t:.2f}" for t in ts)
        )
    print(f"  same bytes from every path: {len(shas) == 1}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("layout", nargs="?", default=str(ROOT / "examples" / "forest_1000.json"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--one", choices=METHODS, help="one timed prototype build (used by the table)")
    ap.add_argument("--pools-only", action="store_true", help="only the prototype-pool table")
    args = ap.parse_args()
    if args.one:
        return one_build(args.layout, args.one, args.workers)
    if not args.pools_only:
        with tempfile.TemporaryDirectory() as tmp:
            sizes(args.layout, args.workers, Path(tmp))
    pools(args.layout, args.workers, args.reps)
    own, kids = _peak_mb()
    print(f"peak MB: main process {own:.0f}, largest worker {kids:.0f}")


if __name__ == "__main__":
    main()
