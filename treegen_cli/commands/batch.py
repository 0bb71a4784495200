"""`treegen batch CATALOGUE -o DIR`: many `make` jobs on Dask (batch.py plans and runs them).

Output policy: one stdout line at the end (or, with --json, one JSON line per finished job
and a closing {"event": "done", ...} line, for machines that want results as they stream);
every failed job is one stderr line naming its entry's JSON path, seed and reason; a progress
bar (done / failed / skipped, ETA) on a terminal; -v adds one stderr line per finished job.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path

import click

from ..batch import (
    MAX_JOBS,
    estimate,
    for_format,
    load_catalogue,
    plan_jobs,
    plan_trees,
    run_jobs,
    schema_text,
    unlisted_files,
)
from ..errors import Terminated, TreegenError
from ..executor import default_workers, scheduler_address
from ..progress import current_reporter
from . import flags


@click.command()
@click.argument("catalogue", type=click.Path(path_type=Path), required=False)
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(path_type=Path),
    metavar="DIR",
    help="Output folder (created if missing); assets, manifest.json and manifest.csv go here.",
)
@flags.cluster(
    "Worker processes of the embedded Dask cluster [default: one per core].",
    "Run the jobs on this Dask scheduler's workers instead [default: "
    "$DASK_SCHEDULER_ADDRESS, else an embedded cluster]. Workers must see DIR "
    "at the same path.",
)
@click.option("--force", is_flag=True, help="Rebuild every job, even those already up to date.")
@click.option(
    "--dry-run",
    is_flag=True,
    help="Print the job table with each tree's plan (LODs, triangles, joints, as the build "
    "will make them) and a size/time estimate; build and write nothing.",
)
@click.option(
    "--max-jobs",
    type=click.IntRange(min=1),
    default=MAX_JOBS,
    show_default=True,
    help="Refuse catalogues that expand to more jobs than this (checked before building).",
)
@click.option("--schema", is_flag=True, help="Print the catalogue's JSON Schema and exit.")
@flags.json_flag("One JSON line per finished job, then a summary line.")
def batch(catalogue, out_dir, workers, scheduler, force, dry_run, max_jobs, schema, as_json):
    """Build every asset CATALOGUE (JSON; see --schema) lists — species × seeds × grid ×
    formats — in parallel on Dask, into DIR with a manifest. Reruns skip what is up to date."""
    if schema:
        click.echo(schema_text().rstrip())
        return
    if catalogue is None:
        raise TreegenError("batch: give a CATALOGUE file (or --schema)")
    if out_dir is None:
        raise TreegenError("batch: give an output folder with -o, e.g. -o assets")
    if out_dir.exists() and not out_dir.is_dir():
        raise TreegenError(f"-o {out_dir}: is a file; give a folder")
    base = next(p for p in (out_dir.absolute(), *out_dir.absolute().parents) if p.exists())
    if not base.is_dir() or not os.access(base, os.W_OK | os.X_OK):
        raise TreegenError(f"-o {out_dir}: cannot write into '{base}'")
    flags.check_cluster(workers, scheduler)
    cat = load_catalogue(catalogue, max_jobs)
    plan = plan_jobs(cat, out_dir, force)
    if dry_run:
        _dry_run(cat, plan, out_dir, workers, scheduler, as_json)
        return
    _run(cat, plan, out_dir, workers, scheduler, as_json)


def _dry_run(cat, plan, out_dir, workers, scheduler, as_json) -> None:
    """The job table with each tree's plan (LODs, triangles and joints per LOD, as the build
    will make them) and a size/time estimate; exit 1 when a job would fail, as the run would."""
    spent: dict[str, float] = {}
    with current_reporter().live():  # a tree a second or so: a large catalogue shows progress
        shapes = plan_trees(cat, plan.build, spent, current_reporter())
    for j in plan.skip:  # up to date: what the manifest recorded when it was built
        row = plan.previous[j.output]
        shapes.setdefault(
            j.task,
            [
                {"triangles": t, "joints": n, "distance_m": d}
                for t, n, d in zip(row["triangles"], row["joints"], row["lod_distances_m"])
            ],
        )
    est = estimate(cat, plan, shapes, spent)
    failing = [j for j in plan.build if isinstance(shapes[j.task], str)]
    todo = {j.output for j in plan.build}
    per_task: dict[str, float] = {}
    for j in plan.build:
        per_task[j.task] = max(per_task.get(j.task, 0.0), est[j.output][1])
    size = sum(est[j.output][0] for j in plan.build)
    work = sum(per_task.values())
    n = None if scheduler_address(scheduler) else (workers or default_workers())
    how = sorted({est[j.output][2] for j in plan.build}) or ["-"]
    if as_json:
        click.echo(
            json.dumps(
                {
                    "jobs": [
                        {
                            "entry": j.source,
                            "species": j.species_text,
                            "seed": j.seed,
                            "format": j.fmt,
                            "grid": dict(j.grid),
                            "path": j.output,
                            "options_hash": j.key,
                            "action": "build" if j.output in todo else "skip",
                            "estimated_bytes": round(est[j.output][0]),
                            "estimated_seconds": round(est[j.output][1], 3),
                            **_shape(for_format(j.fmt, shapes[j.task])),
                        }
                        for j in cat.jobs
                    ],
                    "build": len(plan.build),
                    "skip": len(plan.skip),
                    "trees": len(per_task),
                    "estimated_bytes": round(size),
                    "estimated_work_seconds": round(work, 2),
                    "workers": n,
                    "estimate": "+".join(how),
                    "failing": len(failing),
                    "would_remove": unlisted_files(Path(out_dir), cat, plan),
                },
                indent=1,
            )
        )
        _fail(failing, shapes)
        return
    width = max([len(j.output) for j in cat.jobs] + [6])
    click.echo(
        f"{'#':>4}  {'entry':<12}{'seed':>6}  {'format':<7}{'output':<{width}}  "
        f"{'action':<7}{'LODs':>5}{'LOD0 tris':>11}{'joints':>8}{'est MB':>8}{'est s':>8}"
    )
    for j in cat.jobs:
        b, s, _ = est[j.output]
        shape = for_format(j.fmt, shapes[j.task])
        lods = (
            f"{len(shape):>5}{shape[0]['triangles']:>11,}{shape[0]['joints']:>8}"
            if isinstance(shape, list)
            else f"{'fails':>5}{'-':>11}{'-':>8}"
        )
        click.echo(
            f"{j.index:>4}  {j.source:<12}{j.seed:>6}  {j.fmt:<7}{j.output:<{width}}  "
            f"{'build' if j.output in todo else 'skip':<7}{lods}{b / 1e6:>8.1f}{s:>8.2f}"
        )
    unlisted = unlisted_files(Path(out_dir), cat, plan)
    if unlisted:
        click.echo(
            f"would remove {len(unlisted)} file(s) of assets the catalogue no longer lists: {', '.join(unlisted[:5])}"
            + (" …" if len(unlisted) > 5 else "")
        )
    if not plan.build:
        click.echo(f"{len(cat.jobs)} jobs, all up to date: nothing to build")
        return
    wall = f", ~{work / n:.0f} s on {n} worker(s)" if n else ""
    click.echo(
        f"{len(cat.jobs)} jobs: {len(plan.build)} to build ({len(per_task)} trees), "
        f"{len(plan.skip)} up to date; about {size / 1e6:.0f} MB and {work:.0f} s of "
        f"work{wall} ({' + '.join(how)} estimate)"
    )
    _fail(failing, shapes)


def _shape(shape) -> dict:
    """A job's planned LODs in the manifest's own fields (or the error it would fail with)."""
    if isinstance(shape, str):
        return {"error": shape}
    return {
        "triangles": [r["triangles"] for r in shape],
        "joints": [r["joints"] for r in shape],
        "lod_distances_m": [r["distance_m"] for r in shape],
    }


def _fail(failing, shapes) -> None:
    """One stderr line per job the run would fail, as the run reports it; then exit 1."""
    for j in failing:
        click.echo(f"treegen: would fail: {j.source} seed {j.seed} ({j.output}): {shapes[j.task]}", err=True)
    if failing:
        sys.exit(1)


def _run(cat, plan, out_dir, workers, scheduler, as_json) -> None:
    rep = current_reporter()
    counts = {"built": 0, "failed": 0, "skipped": 0}
    with _progress(rep, len(plan.build)) as bar:

        def say(message: str) -> None:
            if bar is not None:
                bar.console.print(message, markup=False, highlight=False)
            else:
                click.echo(message, err=True)

        def on_event(kind, job, row):
            if kind == "start":
                if rep.verbose:
                    say(f"  cluster   {row['where']}; {row['tasks']} tree(s) to build")
                return
            counts[kind] += 1
            if as_json:
                click.echo(json.dumps({"event": kind, **row}))
            if kind == "failed":
                say(f"treegen: failed: {job.source} seed {job.seed} ({job.output}): {row['error']}")
            elif rep.verbose and not rep.quiet:
                extra = (
                    f"{row.get('bytes', 0) / 1e6:7.2f} MB {row.get('seconds', 0):7.2f} s  "
                    f"{row.get('worker', '')}"
                    if kind == "built"
                    else "up to date"
                )
                say(f"  {kind:<8}{job.output}  {extra}")
            if bar is not None and kind != "skipped":
                bar.advance(bar.task_ids[0])
            if bar is not None:
                bar.update(
                    bar.task_ids[0],
                    stats=f"done {counts['built']}  failed {counts['failed']}  skipped {counts['skipped']}",
                )

        try:
            totals = run_jobs(cat, plan, out_dir, scheduler=scheduler, workers=workers, on_event=on_event)
        except KeyboardInterrupt as e:  # Ctrl-C, or a SIGTERM (errors.Terminated)
            # run_jobs has closed the cluster, removed staging folders and written the manifest
            term = isinstance(e, Terminated)
            click.echo(
                f"treegen: {'terminated' if term else 'interrupted'}: {counts['built']} built, "
                f"{counts['failed']} failed, {len(plan.build) - counts['built'] - counts['failed']} "
                "not done; rerun the same command to finish",
                err=True,
            )
            sys.exit(143 if term else 130)
    manifest = Path(out_dir) / "manifest.json"
    if as_json:
        click.echo(json.dumps({"event": "done", **totals, "manifest": str(manifest)}))
    else:
        where = f" on {totals['cluster']}" if totals["cluster"] else ""
        gone = (
            f"; removed {totals['removed']} file(s) of assets the catalogue no longer lists"
            if totals["removed"]
            else ""
        )
        click.echo(
            f"built {totals['built']}, skipped {totals['skipped']}, failed "
            f"{totals['failed']} of {totals['jobs']} assets in {totals['seconds']:.1f} s"
            f"{where}{gone}; manifest: {manifest}"
        )
    if totals["failed"]:
        sys.exit(1)  # some jobs failed (each reported above); the rest are built


@contextlib.contextmanager
def _progress(rep, total: int):
    """A rich bar with done/failed/skipped and the ETA, on a terminal only; else None."""
    if not rep.show_progress or total == 0:
        yield None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        SpinnerColumn(),
        TextColumn("batch"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[stats]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=Console(file=sys.stderr),
        transient=True,
    ) as prog:
        prog.add_task("batch", total=total, stats="starting the cluster")
        yield prog
