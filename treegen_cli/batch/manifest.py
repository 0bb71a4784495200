"""DIR/manifest.json and manifest.csv (one row per job) and the journal DIR/.manifest.jsonl
a run appends to as each job finishes, so a killed run loses nothing it finished."""

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
        lods = summary["lods"]
        row |= {
            "files": [Path(f).relative_to(out_dir).as_posix() for f in summary["files"]],
            "bytes": summary["bytes"],
            "triangles": [r["triangles"] for r in lods],
            "joints": [r["joints"] for r in lods],
            "keys": [r["joint_keys"] for r in lods],
            "lod_distances_m": [r["distance_m"] for r in lods],
            "seconds": summary["seconds"],
            "worker": summary.get("worker", ""),
        }
    if error is not None:
        row["error"] = error
    return row


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
