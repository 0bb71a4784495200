"""A catalogue file → many `make` jobs → a folder of assets and a manifest, on Dask.

Result: `treegen batch catalogue.json -o DIR` writes every (entry × seed × grid value × format)
asset once, on an embedded LocalCluster or a remote Dask cluster, and DIR/manifest.json +
manifest.csv list them. A rerun builds only what is missing or whose inputs changed.

    cat = load_catalogue("examples/catalogue.json")     # validated; errors name the JSON path,
    plan = plan_jobs(cat, "out")                        #   e.g. entries[1].grid.wind_speed[0]
    summary = run_jobs(cat, plan, "out", workers=2)     # atomic outputs, manifest, resume

Jobs and tasks: a job is one output file (a manifest row). Jobs that differ only in format
share one task (one tree built, written once per format), which halves the work of a
glb + usdc catalogue and changes no byte: each file is what `treegen make -o FILE` writes.

Resume: each job is keyed by a hash of (species file bytes, seed, every make option with its
default filled in, format, treegen version). The worker that writes a file appends its row
to DIR/.manifest.jsonl as soon as the file is in place, so a killed or interrupted run loses
nothing it finished (even a file whose task never returned); a job whose files exist with
the recorded size and key is skipped (`force` rebuilds). The manifest is rewritten at the end
and the journal folded into it. Workers make an output's folder when they write into it.

One module per job: catalogue.py (the file → validated jobs and their identity keys),
plan.py (what to build or skip, each tree's plan for --dry-run, estimates), run.py (the
builds on Dask), manifest.py (the manifest and its journal, read and written).
"""

from __future__ import annotations

from .catalogue import (
    DEFAULT_NAME,
    FORMATS,
    MAX_JOBS,
    SCHEMA_NAME,
    Catalogue,
    Job,
    load_catalogue,
    name_value,
    parse_catalogue,
    parse_seeds,
    render_name,
    schema_text,
)
from .manifest import CSV_COLUMNS, JOURNAL, MANIFEST, MANIFEST_CSV, write_manifest
from .plan import Plan, estimate, for_format, plan_jobs, plan_trees
from .run import build_task, clean_staging, run_jobs, unlisted_files

__all__ = [
    "CSV_COLUMNS",
    "Catalogue",
    "DEFAULT_NAME",
    "FORMATS",
    "JOURNAL",
    "Job",
    "MANIFEST",
    "MANIFEST_CSV",
    "MAX_JOBS",
    "Plan",
    "SCHEMA_NAME",
    "build_task",
    "clean_staging",
    "estimate",
    "for_format",
    "load_catalogue",
    "name_value",
    "parse_catalogue",
    "parse_seeds",
    "plan_jobs",
    "plan_trees",
    "render_name",
    "run_jobs",
    "unlisted_files",
    "schema_text",
    "write_manifest",
]
