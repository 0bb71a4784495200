"""The builds: one Dask task per tree (its formats written by the worker that grew it, each
file journaled by that worker as it lands), results streamed into the manifest; Ctrl-C keeps
every file that was completely written, and leaves no folder a job never wrote into."""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

from ..errors import TreegenError
from .catalogue import Catalogue, Job
from .manifest import JOURNAL, append_journal, journal_since, manifest_row, summary_fields, write_manifest
from .plan import Plan, estimate, up_to_date


def build_task(
    params, species: str, resolved, outputs: list[str], rows: list[dict], out_dir: str, journal: str
) -> list[dict]:
    """On a worker: grow one tree and write it once per output (each atomically, into a
    folder made now: none is made for a job that never runs). Each file's manifest row
    (`rows[k]` and its summary) goes into the journal as soon as the file is in place, so a
    file written just before a Ctrl-C is known as built though its result never reaches the
    client. Returns each file's `make --json` summary plus the worker's name."""
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
    for out, row in zip(outputs, rows):
        t1 = time.perf_counter()
        mine = Timings(stages=dict(timings.stages))
        folder = Path(out).parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise TreegenError(f"{out}: cannot create folder '{folder}' ({e.strerror or e})") from None
        s = api.write(asset, tree, out, mine, t1, resolved)
        s["seconds"] = round(built + s["seconds"], 4)
        s["worker"] = worker
        with contextlib.suppress(OSError):  # a safety net: the result still reaches the client
            append_journal(journal, {**row, **summary_fields(s, out_dir)})
        results.append(s)
    return results


def output_folders(out_dir: Path, jobs: list[Job]) -> list[Path]:
    """The folders under `out_dir` the jobs write into, with their parents up to it (not
    `out_dir` itself), deepest first."""
    folders: set[Path] = set()
    for job in jobs:
        folder = (out_dir / job.output).parent
        while folder != out_dir and out_dir in folder.parents:
            folders.add(folder)
            folder = folder.parent
    return sorted(folders, key=lambda f: (-len(f.parts), str(f)))


def check_folders(out_dir: Path, folders: list[Path]) -> None:
    """Refuse, before anything runs, an output folder a file stands in the way of (the
    workers make the folders only when they write into them)."""
    for folder in folders:
        if folder.exists() and not folder.is_dir():
            raise TreegenError(
                f"-o {out_dir}: cannot create folder '{folder}' (a file of that name is there)"
            )


def remove_empty(folders: list[Path]) -> None:
    """Remove those of `folders` (deepest first) that are empty: made by a job that was then
    stopped before its file landed."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


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
    stop the others; Ctrl-C cancels what is queued, closes the cluster and keeps what finished:
    a job whose file a worker put in place (journaled) is built even if its result was lost."""
    from distributed import as_completed

    from ..executor import dask_client

    out_dir = Path(out_dir)
    on_event = on_event or (lambda *a: None)
    rows: dict[str, dict] = {}
    tasks: dict[str, list[Job]] = {}
    for job in plan.build:
        tasks.setdefault(job.task, []).append(job)
    folders = output_folders(out_dir, cat.jobs)
    check_folders(out_dir, folders)
    made = [f for f in folders if not f.exists()]  # removed at the end if still empty
    t0 = time.perf_counter()
    where = ""
    offset = 0
    started = False
    # Connect first: a cluster that cannot serve us is refused before anything is written.
    cluster = dask_client(scheduler, workers) if tasks else contextlib.nullcontext((None, ""))
    try:
        with cluster as (client, where):
            try:
                out_dir.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise TreegenError(
                    f"-o {out_dir}: cannot create folder '{e.filename}' ({e.strerror})"
                ) from None
            started = True
            with contextlib.suppress(OSError):
                offset = (out_dir / JOURNAL).stat().st_size
            clean_staging(out_dir, plan.build)
            for job in plan.skip:
                rows[job.output] = {
                    **plan.previous[job.output],
                    **manifest_row(job, out_dir, cat, None, "skipped"),
                }
                on_event("skipped", job, rows[job.output])
            if tasks:
                on_event("start", None, {"where": where, "tasks": len(tasks)})
                _build_all(cat, plan, out_dir, tasks, client, rows, on_event, as_completed)
    finally:
        # after the cluster is closed, so no worker can start a staging folder behind us
        if started:
            clean_staging(out_dir, plan.build)
            _journaled(plan, out_dir, offset, rows, on_event)
            remove_empty(made)
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
                "removed": remove_unlisted(out_dir, cat, plan, ordered),
            }
            write_manifest(out_dir, cat, ordered, totals)
    return totals


def unlisted_files(out_dir: Path, cat: Catalogue, plan: Plan, rows: list[dict] = ()) -> list[str]:
    """Files an earlier run into `out_dir` recorded for assets the catalogue no longer lists
    (an entry, seed or format edited away) and no asset of this run writes: an engine that
    imports the folder would take them. Only names the earlier manifest recorded, inside the
    folder."""
    listed = {job.output for job in cat.jobs}
    keep = {f for row in rows for f in row.get("files", [row.get("path")])} | listed
    root = out_dir.resolve()
    out = set()
    for path, row in plan.previous.items():
        if path in listed:
            continue
        for f in row.get("files", [path]):
            target = (out_dir / str(f)).resolve()
            if f not in keep and target.is_relative_to(root) and target.is_file():
                out.add(str(f))
    return sorted(out)


def remove_unlisted(out_dir: Path, cat: Catalogue, plan: Plan, rows: list[dict]) -> int:
    """Remove unlisted_files (and folders they leave empty); returns how many went."""
    gone = 0
    for f in unlisted_files(out_dir, cat, plan, rows):
        with contextlib.suppress(OSError):
            (out_dir / f).unlink()
            gone += 1
            remove_empty([p for p in (out_dir / f).parents if p != out_dir and out_dir in p.parents])
    return gone


def _journaled(plan: Plan, out_dir: Path, offset: int, rows: dict, on_event) -> None:
    """Jobs with no result (a Ctrl-C came first) whose file a worker of this run journaled
    and which is on disk as recorded: built (reported as such)."""
    mine = {row["path"]: row for row in journal_since(out_dir, offset)}
    for job in plan.build:
        row = mine.get(job.output)
        if job.output not in rows and row is not None and up_to_date(out_dir, job, row):
            rows[job.output] = row
            on_event("built", job, row)


def _build_all(cat, plan, out_dir, tasks, client, rows, on_event, as_completed) -> None:
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
            [manifest_row(j, out_dir, cat, None, "built") for j in jobs],
            str(out_dir),
            str(out_dir / JOURNAL),
            key=f"treegen-{j0.species.stem}-{task}-{run}",
            priority=int(sum(est[j.output][1] for j in jobs) * 1000),
        )
        futures[fut] = jobs
    for fut in as_completed(list(futures), loop=client.loop):
        jobs = futures.pop(fut)
        try:
            results = fut.result()
        except TreegenError as e:
            results, reason = None, cat.reword(jobs[0], str(e))
        except Exception as e:  # worker crash, KilledWorker, a bug
            results, reason = None, f"{type(e).__name__}: {e}"
        for k, job in enumerate(jobs):
            if results is None:
                row = manifest_row(job, out_dir, cat, None, "failed", reason)
            else:
                row = manifest_row(job, out_dir, cat, results[k], "built")
            rows[job.output] = row
            on_event(row["status"], job, row)
        fut.release()
