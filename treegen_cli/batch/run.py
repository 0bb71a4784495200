"""The builds: one Dask task per tree (its formats written by the worker that grew it),
results streamed into the journal and the manifest; Ctrl-C keeps what finished."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ..errors import TreegenError
from .catalogue import Catalogue, Job
from .manifest import JOURNAL, manifest_row, write_manifest
from .plan import Plan, estimate


def build_task(params, species: str, resolved, outputs: list[str]) -> list[dict]:
    """On a worker: grow one tree and write it once per output (each atomically). Returns
    each file's `make --json` summary plus the worker's name."""
    from .. import api
    from ..executor import tune_worker_malloc, worker_name
    from ..pipeline import Timings

    tune_worker_malloc()
    t0 = time.perf_counter()
    timings = Timings()
    asset, tree = api.build(params, species, resolved, timings)
    built = time.perf_counter() - t0
    worker = worker_name()
    results = []
    for out in outputs:
        t1 = time.perf_counter()
        mine = Timings(stages=dict(timings.stages))
        s = api.write(asset, tree, out, mine, t1, resolved)
        s["seconds"] = round(built + s["seconds"], 4)
        s["worker"] = worker
        results.append(s)
    return results


def clean_staging(out_dir: Path, jobs: list[Job]) -> None:
    """Sweep the staging folders (exchange.staging) that killed workers of this host left in
    our output folders; those of live writers, or of other hosts on a shared folder, stay."""
    from ..exchange import sweep

    for folder in sorted({(out_dir / job.output).parent for job in jobs}):
        sweep(folder)


def run_jobs(
    cat: Catalogue, plan: Plan, out_dir: str | os.PathLike, *, scheduler=None, workers=None, on_event=None
) -> dict:
    """Build `plan.build` on Dask, stream each result to `on_event(kind, job, row)` (kind:
    built, failed, skipped, start), write the manifest, and return the totals. Failures do not
    stop the others; Ctrl-C cancels what is queued, closes the cluster and keeps what finished."""
    import contextlib

    from distributed import as_completed

    from ..executor import dask_client

    out_dir = Path(out_dir)
    on_event = on_event or (lambda *a: None)
    rows: dict[str, dict] = {}
    tasks: dict[str, list[Job]] = {}
    for job in plan.build:
        tasks.setdefault(job.task, []).append(job)
    t0 = time.perf_counter()
    where = ""
    journal = None
    started = False
    # Connect first: a cluster that cannot serve us is refused before anything is written.
    cluster = dask_client(scheduler, workers) if tasks else contextlib.nullcontext((None, ""))
    try:
        with cluster as (client, where):
            try:
                for folder in sorted({(out_dir / job.output).parent for job in cat.jobs}):
                    folder.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise TreegenError(
                    f"-o {out_dir}: cannot create folder '{e.filename}' ({e.strerror})"
                ) from None
            started = True
            clean_staging(out_dir, plan.build)
            for job in plan.skip:
                rows[job.output] = {
                    **plan.previous[job.output],
                    **manifest_row(job, out_dir, cat, None, "skipped"),
                }
                on_event("skipped", job, rows[job.output])
            if tasks:
                journal = open(out_dir / JOURNAL, "a", encoding="utf-8")
                on_event("start", None, {"where": where, "tasks": len(tasks)})
                _build_all(cat, plan, out_dir, tasks, client, journal, rows, on_event, as_completed)
    finally:
        # after the cluster is closed, so no worker can start a staging folder behind us
        if journal is not None:
            journal.close()
        if started:
            clean_staging(out_dir, plan.build)
            ordered = [
                rows.get(job.output) or manifest_row(job, out_dir, cat, None, "pending") for job in cat.jobs
            ]
            totals = {
                "jobs": len(cat.jobs),
                **{
                    k: sum(r["status"] == k for r in ordered)
                    for k in ("built", "skipped", "failed", "pending")
                },
                "tasks": len(tasks),
                "seconds": round(time.perf_counter() - t0, 3),
                "cluster": where,
            }
            write_manifest(out_dir, cat, ordered, totals)
    return totals


def _build_all(cat, plan, out_dir, tasks, client, journal, rows, on_event, as_completed) -> None:
    """Submit one Dask task per tree (longest first) and record results as they arrive."""
    run = f"{os.getpid():x}{time.time_ns() & 0xFFFFFF:x}"
    est = estimate(cat, plan)
    futures = {}
    for task, jobs in tasks.items():
        j0 = jobs[0]
        fut = client.submit(
            build_task,
            cat.params[j0.species],
            j0.species_text,
            cat.resolved[task],
            [str(out_dir / j.output) for j in jobs],
            key=f"treegen-{j0.species.stem}-{task}-{run}",
            priority=int(sum(est[j.output][1] for j in jobs) * 1000),
        )
        futures[fut] = jobs
    for fut in as_completed(list(futures), loop=client.loop):
        jobs = futures.pop(fut)
        try:
            results = fut.result()
        except TreegenError as e:
            results, reason = None, str(e)
        except Exception as e:  # worker crash, KilledWorker, a bug
            results, reason = None, f"{type(e).__name__}: {e}"
        for k, job in enumerate(jobs):
            if results is None:
                row = manifest_row(job, out_dir, cat, None, "failed", reason)
            else:
                row = manifest_row(job, out_dir, cat, results[k], "built")
                journal.write(json.dumps(row) + "\n")
                journal.flush()
            rows[job.output] = row
            on_event(row["status"], job, row)
        fut.release()
