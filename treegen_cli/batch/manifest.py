"""DIR/manifest.json and manifest.csv (one row per job) and the journal DIR/.manifest.jsonl
the workers append to as each file lands, so a killed or interrupted run loses nothing it
finished."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

from ..build_id import build_id
from .catalogue import Catalogue, Job, options_sha, species_sha

MANIFEST, MANIFEST_CSV, JOURNAL = "manifest.json", "manifest.csv", ".manifest.jsonl"


def journal_rows(out_dir: Path) -> dict[str, dict]:
    """What earlier runs recorded, by output path: the manifest, then the journal's lines
    (later wins; a line cut off by a kill is ignored)."""
    rows: dict[str, dict] = {}
    try:
        for row in json.loads((out_dir / MANIFEST).read_text("utf-8")).get("assets", []):
            if row.get("status") in ("built", "skipped"):
                rows[row["path"]] = row
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        pass
    try:
        lines = (out_dir / JOURNAL).read_text("utf-8").splitlines()
    except OSError:
        lines = []
    for line in lines:
        try:
            row = json.loads(line)
            rows[row["path"]] = row
        except (ValueError, KeyError, TypeError):
            continue
    return rows


def manifest_row(
    job: Job, out_dir: Path, cat: Catalogue, summary: dict | None, status: str, error: str | None = None
) -> dict:
    r = cat.resolved[job.task]
    row = {
        "entry": job.source,
        "species": job.species_text,
        "seed": job.seed,
        "format": job.fmt,
        "grid": dict(job.grid),
        "path": job.output,
        "options_hash": job.key,
        "species_sha": species_sha(cat, job),
        "options_sha": options_sha(r.values),
        "status": status,
    }
    if summary is not None:
        row |= summary_fields(summary, out_dir)
    if error is not None:
        row["error"] = error
    return row


def summary_fields(summary: dict, out_dir: str | os.PathLike) -> dict:
    """A built row's part from a file's `make --json` summary (a worker adds it to the row
    the client gave it, for the journal; the client the same, for the manifest)."""
    lods = summary["lods"]
    return {
        "files": [Path(f).relative_to(out_dir).as_posix() for f in summary["files"]],
        "bytes": summary["bytes"],
        "triangles": [r["triangles"] for r in lods],
        "joints": [r["joints"] for r in lods],
        "keys": [r["joint_keys"] for r in lods],
        "lod_distances_m": [r["distance_m"] for r in lods],
        "seconds": summary["seconds"],
        "worker": summary.get("worker", ""),
    }


def append_journal(path: str | os.PathLike, row: dict) -> None:
    """Append `row` as one line with one O_APPEND write: the workers of a run share the
    journal, and a line is never interleaved with another's (a torn one, after a kill, is
    skipped by journal_rows: that job is simply built again)."""
    data = (json.dumps(row) + "\n").encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)


def journal_since(out_dir: Path, offset: int) -> list[dict]:
    """The journal's rows from byte `offset` on (what this run's workers appended)."""
    try:
        with open(out_dir / JOURNAL, "rb") as f:
            f.seek(offset)
            lines = f.read().decode("utf-8", "replace").splitlines()
    except OSError:
        return []
    rows = []
    for line in lines:
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and "path" in row:
            rows.append(row)
    return rows


CSV_COLUMNS = (
    "entry",
    "species",
    "seed",
    "format",
    "path",
    "options_hash",
    "status",
    "bytes",
    "triangles",
    "joints",
    "keys",
    "seconds",
    "worker",
    "error",
)


def write_manifest(out_dir: Path, cat: Catalogue, rows: list[dict], totals: dict) -> None:
    """DIR/manifest.json and manifest.csv (one row per job, catalogue order), each replaced
    atomically; then the journal they now contain is removed."""
    doc = {"catalogue": str(cat.path), "treegen": build_id(), **totals, "assets": rows}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for row in rows:
        w.writerow(
            [
                ";".join(map(str, row[c])) if isinstance(row.get(c), list) else row.get(c, "")
                for c in CSV_COLUMNS
            ]
        )
    for name, text in ((MANIFEST, json.dumps(doc, indent=1) + "\n"), (MANIFEST_CSV, buf.getvalue())):
        tmp = out_dir / f".{name}.tmp"
        tmp.write_text(text, "utf-8")
        os.replace(tmp, out_dir / name)
    (out_dir / JOURNAL).unlink(missing_ok=True)
