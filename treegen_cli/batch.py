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
default filled in, format, treegen version). The client appends a line to DIR/.manifest.jsonl
as each job finishes, so a killed run loses nothing it finished; a job whose files exist with
the recorded size and key is skipped (`force` rebuilds). The manifest is rewritten at the end
and the journal folded into it.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import os
import re
import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path, PurePosixPath

from . import __version__
from .errors import TreegenError
from .generate import check_trunk
from .forest.schema import check_schema, read_json_file

SCHEMA_NAME = "catalogue.schema.json"
DEFAULT_NAME = "{species}_{seed}.{ext}"
FORMATS = ("glb", "gltf", "usda", "usdc", "usdz", "obj", "ply")
MANIFEST, MANIFEST_CSV, JOURNAL = "manifest.json", "manifest.csv", ".manifest.jsonl"
MAX_JOBS = 100_000        # jobs one catalogue may expand to (seed ranges × grid × formats)
_SEEDS = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


def schema_text() -> str:
    """The published JSON Schema of catalogue files (package data)."""
    return resources.files("treegen_cli").joinpath("schemas", SCHEMA_NAME).read_text("utf-8")


# ----------------------------------------------------------------------------- catalogue

@dataclass(frozen=True)
class Job:
    """One output file. `source`: the JSON path of its entry; `task`: the build it shares
    with its other formats; `key`: what its bytes depend on (the resume key)."""

    index: int
    source: str
    species: Path              # resolved species file
    species_text: str          # as written in the catalogue
    seed: int
    fmt: str
    grid: tuple                # ((option, value), ...) of this grid point
    output: str                # path under DIR, POSIX
    task: str
    key: str


@dataclass
class Catalogue:
    path: Path
    jobs: list[Job]
    params: dict = field(default_factory=dict)     # species file → Params, parsed once
    digests: dict = field(default_factory=dict)    # species file → sha256 of its bytes
    resolved: dict = field(default_factory=dict)   # task → api.Resolved


def load_catalogue(path: str | os.PathLike, max_jobs: int = MAX_JOBS) -> Catalogue:
    """Read, validate and expand a catalogue; every error starts with the file and JSON path."""
    path = Path(path)
    data = read_json_file(path, "catalogue")
    try:
        return parse_catalogue(data, path, max_jobs)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None


def parse_seeds(value, where: str, max_jobs: int = MAX_JOBS) -> list[int]:
    """7, [1, 5, 9] or "1-40" / "1-5,9" → sorted-as-given list of distinct seeds."""
    if isinstance(value, bool):
        raise TreegenError(f"{where}: expected a seed, a list of seeds or text like \"1-40\", got {json.dumps(value)}")
    if isinstance(value, int):
        values = [value]
    elif isinstance(value, list) and value and all(isinstance(v, int) and not isinstance(v, bool)
                                                   for v in value):
        values = list(value)
    elif isinstance(value, str):
        values = []
        for part in value.split(","):
            m = _SEEDS.match(part)
            if not m:
                raise TreegenError(f"{where}: '{value}' is not a seed range; use e.g. \"1-40\" or \"1-5,9\"")
            lo, hi = int(m[1]), int(m[2] if m[2] is not None else m[1])
            if hi < lo:
                raise TreegenError(f"{where}: range '{part.strip()}' runs backwards; use {hi}-{lo}")
            if hi - lo + 1 > max_jobs:
                raise TreegenError(f"{where}: range '{part.strip()}' gives {hi - lo + 1:,} seeds, "
                                   f"over the limit of {max_jobs:,} jobs")
            values.extend(range(lo, hi + 1))
    else:
        raise TreegenError(f"{where}: expected a seed, a non-empty list of seeds or text like "
                           f"\"1-40\", got {type(value).__name__}")
    for v in values:
        if not 0 <= v <= 2**32 - 1:
            raise TreegenError(f"{where}: seed {v} is out of range; allowed [0, 4294967295]")
    seen = set()
    dupes = [v for v in values if v in seen or seen.add(v)]
    if dupes:
        raise TreegenError(f"{where}: seed {dupes[0]} is listed twice")
    return values


def name_value(value) -> str:
    """An option value as it appears in file names: 8.0 → 8, [0, 15] → 0,15, True → true."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return ",".join(name_value(v) for v in value)
    return str(value)


def render_name(template: str, fields: dict, grid: tuple, fmt: str, where: str) -> str:
    """The output path under DIR. Grid keys the template does not mention are appended
    before the extension (`_wind_speed-8`), so two grid points never share a file."""
    from string import Formatter

    try:
        used = {f for _, f, _, _ in Formatter().parse(template) if f is not None}
        name = template.format_map(fields)
    except KeyError as e:
        raise TreegenError(f"{where}: unknown field {{{e.args[0]}}} in '{template}'; allowed: "
                           "{species}, {seed}, {ext}, {entry} and any make option, e.g. "
                           "{wind_speed}") from None
    except (ValueError, IndexError, AttributeError) as e:
        raise TreegenError(f"{where}: bad name template '{template}' ({e})") from None
    if not name.lower().endswith("." + fmt):
        raise TreegenError(f"{where}: '{template}' gives '{name}' for format {fmt}; the name must "
                           f"end in .{fmt} (use {{ext}})")
    extra = "".join(f"_{k}-{name_value(v)}" for k, v in grid if k not in used)
    if extra:
        name = name[:-len(fmt) - 1] + extra + name[-len(fmt) - 1:]
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or not p.name or p.name.startswith("."):
        raise TreegenError(f"{where}: '{template}' gives '{name}'; output names must stay inside "
                           "the output folder (no absolute paths, '..' or hidden names)")
    return str(p)


def _species(base: Path, value: str, where: str, params: dict) -> tuple[Path, str]:
    """Resolve (a path relative to the catalogue wins, else a bundled name) and parse a
    species file once per catalogue; returns (path, sha256 of bytes)."""
    from .params import parse_params_bytes

    from .bundled import resolve_species

    p = resolve_species(value, base, f"{where}: species file '{value}'").resolve()
    if p not in params:
        try:
            data = p.read_bytes()
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
            raise TreegenError(f"{where}: species file '{value}' not found") from None
        except OSError as e:
            raise TreegenError(f"{where}: cannot read species file '{value}' ({e.strerror})") from None
        try:
            params[p] = (parse_params_bytes(data, str(p)), hashlib.sha256(data).hexdigest())
        except TreegenError as e:
            raise TreegenError(f"{where}: {e}") from None
    return p, params[p][1]


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def parse_catalogue(data, path: Path, max_jobs: int = MAX_JOBS) -> Catalogue:
    """Validate decoded JSON `data` of the catalogue at `path` and expand it into jobs, in
    catalogue order; refuses two jobs with one output before anything runs."""
    from . import api
    schema = json.loads(schema_text())
    check_schema(data, schema, schema)
    base = path.parent
    defaults = data.get("defaults", {})
    loaded: dict = {}
    jobs: list[Job] = []
    resolved: dict = {}
    outputs: dict[str, str] = {}
    for i, entry in enumerate(data["entries"]):
        where = f"entries[{i}]"
        sp, digest = _species(base, entry["species"], f"{where}.species", loaded)

        def pick(key, fallback):
            if key in entry:
                return entry[key], f"{where}.{key}"
            if key in defaults:
                return defaults[key], f"defaults.{key}"
            return fallback, f"{where}.{key}"

        seeds = parse_seeds(*pick("seeds", 0), max_jobs)
        formats, fwhere = pick("formats", ["glb"])
        for k, f in enumerate(formats):
            if f not in FORMATS:
                raise TreegenError(f"{fwhere}[{k}]: unknown format {json.dumps(f)}; allowed: {', '.join(FORMATS)}")
        template, _ = pick("name", data.get("name"))
        twhere = f"{where}.name" if "name" in entry else "name"
        template = template or DEFAULT_NAME
        options, sources = {}, {}
        for scope, src in ((defaults, "defaults"), (entry, where)):
            for k, v in scope.items():
                if k in api.DEFAULTS:
                    options[k], sources[k] = v, f"{src}.{k}"
        grid = entry.get("grid", {})
        for k in grid:
            if k in entry:
                raise TreegenError(f"{where}.grid.{k}: also set as {where}.{k}; give one of them")
        keys = list(grid)
        for combo in itertools.product(*(list(enumerate(grid[k])) for k in keys)):
            opts = dict(options)
            src = dict(sources)
            for k, (j, v) in zip(keys, combo):
                opts[k], src[k] = v, f"{where}.grid.{k}[{j}]"
            point = tuple((k, v) for k, (_, v) in zip(keys, combo))

            def label(key, src=src):
                return src.get(key, f"{where}.{key}")

            try:
                base_job = api.resolve(opts, label)
            except TreegenError as e:
                msg = str(e)
                raise TreegenError(msg if msg.startswith(("entries[", "defaults."))
                                   else f"{where}: {msg}") from None
            if base_job.values["compress"] == "meshopt":
                from .exchange.compress import check_encoder
                check_encoder()
            if base_job.values["compress"] != "none":
                for k, f in enumerate(formats):
                    if f not in ("glb", "gltf"):
                        raise TreegenError(
                            f"{label('compress')}: {base_job.values['compress']} is for glb/gltf "
                            f"only, but {fwhere}[{k}] is {json.dumps(f)} (USD has no such encoding)")
            try:        # an implausible Scale is a typo: refused now, not by a worker mid-run
                check_trunk(loaded[sp][0], base_job.options.generate)
            except TreegenError as e:
                raise TreegenError(f"{where}.species: {e}") from None
            values = {k: v for k, v in base_job.values.items() if k != "seed"
                      and not (k in api.UNSET_FREE and v is None)}
            for seed in seeds:
                task = _digest({"species": digest, "seed": seed, "options": values,
                                "treegen": __version__})
                resolved[task] = api.Resolved(seed=seed, options=base_job.options,
                                              values={**base_job.values, "seed": seed})
                fields = {**{k: name_value(v) for k, v in values.items()},
                          "species": sp.stem, "seed": str(seed), "entry": str(i)}
                for fmt in formats:
                    name = render_name(template, {**fields, "ext": fmt}, point, fmt, twhere)
                    other = outputs.get(name.casefold())
                    if other is not None:
                        raise TreegenError(
                            f"{where}: output '{name}' (seed {seed}) is also written by {other}; "
                            "put {seed} or the grid keys into the name template, or drop the duplicate")
                    outputs[name.casefold()] = f"{where} (seed {seed})"
                    jobs.append(Job(index=len(jobs), source=where, species=sp,
                                    species_text=entry["species"], seed=seed, fmt=fmt, grid=point,
                                    output=name, task=task,
                                    key=_digest({"task": task, "format": fmt})))
                    if len(jobs) > max_jobs:
                        raise TreegenError(f"{where}: the catalogue expands to more than "
                                           f"{max_jobs:,} jobs; split it into several files")
    return Catalogue(path=path, jobs=jobs, params={p: v[0] for p, v in loaded.items()},
                     digests={p: v[1][:16] for p, v in loaded.items()}, resolved=resolved)


# ----------------------------------------------------------------------------- plan

def _journal_rows(out_dir: Path) -> dict[str, dict]:
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


def _up_to_date(out_dir: Path, job: Job, row: dict | None) -> bool:
    if row is None or row.get("options_hash") != job.key:
        return False
    files = [out_dir / f for f in row.get("files", [job.output])]
    try:
        return sum(f.stat().st_size for f in files) == row.get("bytes")
    except OSError:
        return False


@dataclass
class Plan:
    build: list[Job]
    skip: list[Job]
    previous: dict[str, dict]          # output path → earlier row


def plan_jobs(cat: Catalogue, out_dir: str | os.PathLike, force: bool = False) -> Plan:
    out_dir = Path(out_dir)
    previous = _journal_rows(out_dir) if out_dir.is_dir() else {}
    build, skip = [], []
    for job in cat.jobs:
        (skip if not force and _up_to_date(out_dir, job, previous.get(job.output)) else build).append(job)
    return Plan(build=build, skip=skip, previous=previous)


def plan_trees(cat: Catalogue, jobs: list[Job]) -> dict[str, list[dict] | str]:
    """Per task of `jobs`: what its build will have per LOD (pipeline.plan_asset: triangles,
    vertices, joints, switch distance; budgets, profiles and joint limits applied as the build
    applies them), or the one-line error the build would fail with. Grown here, one tree at a
    time, without wind, textures or the impostor atlas."""
    from .pipeline import plan_asset

    out: dict[str, list[dict] | str] = {}
    for job in jobs:
        if job.task in out:
            continue
        r = cat.resolved[job.task]
        try:
            out[job.task] = plan_asset(cat.params[job.species], r.seed, r.options)
        except TreegenError as e:
            out[job.task] = str(e)
    return out


# bytes per vertex (float32 position, normal, UV; joints, weights, tangents on bark) and per
# triangle (indices), and the share of that --compress keeps (README: ~60 %, ~a fifth)
_VERTEX_BYTES, _TRIANGLE_BYTES = 48, 8
_COMPRESSED = {"none": 1.0, "quantize": 0.6, "meshopt": 0.2}


def estimate(cat: Catalogue, plan: Plan,
             shapes: dict[str, list[dict] | str] | None = None) -> dict[str, tuple[float, float, str]]:
    """Per output path: (bytes, seconds, how). Measured when an earlier run built the same
    species, format and options (any seed); otherwise a model of the clip length and either
    the planned LODs (`shapes`, plan_trees: "plan") or the leaf and stem counts the species
    predicts (generate.estimate_counts: "model")."""
    from .generate import estimate_counts

    measured: dict[tuple, list] = {}
    for row in plan.previous.values():
        measured.setdefault((row.get("species_sha"), row.get("format"), row.get("options_sha")),
                            []).append((row.get("bytes", 0), row.get("seconds", 0.0)))
    out = {}
    for job in cat.jobs:
        r = cat.resolved[job.task]
        sha = _sha_of(cat, job)
        opt = _options_sha(r.values)
        m = measured.get((sha, job.fmt, opt))
        if m:
            out[job.output] = (sum(b for b, _ in m) / len(m), sum(s for _, s in m) / len(m), "measured")
            continue
        frames = 0 if r.options.wind is None else r.options.wind.duration * r.options.wind.fps + 1
        shape = shapes.get(job.task) if shapes is not None else None
        if isinstance(shape, list):
            lods = len(shape)
            verts = sum(row["vertices"] for row in shape)
            size = _COMPRESSED[r.values["compress"]] * sum(
                row["vertices"] * _VERTEX_BYTES + row["triangles"] * _TRIANGLE_BYTES
                for row in shape) + shape[0]["joints"] * frames * 16 * min(lods, 2)
            how = "plan"
        else:
            stems, leaves = estimate_counts(cat.params[job.species])
            lods = 1 if r.options.lod is None else r.options.lod.count
            verts = (leaves * 4 + stems * 60) * (1.0 if lods == 1 else 1.9)
            size = verts * 27 + r.options.rig.max_joints * frames * 16 * min(lods, 2)
            how = "model"
        secs = 0.03 + verts * 0.9e-6 + (lods > 1) * 0.1 + frames * 5e-4
        out[job.output] = (size, secs, how)
    return out


def _sha_of(cat: Catalogue, job: Job) -> str:
    return cat.digests[job.species]


def _options_sha(values: dict) -> str:
    from . import api
    return _digest({k: v for k, v in values.items() if k != "seed"
                    and not (k in api.UNSET_FREE and v is None)})


# ----------------------------------------------------------------------------- run

def build_task(params, species: str, resolved, outputs: list[str]) -> list[dict]:
    """On a worker: grow one tree and write it once per output (each atomically). Returns
    each file's `make --json` summary plus the worker's name."""
    from . import api
    from .executor import tune_worker_malloc, worker_name
    from .pipeline import Timings

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


def _row(job: Job, out_dir: Path, cat: Catalogue, summary: dict | None, status: str,
         error: str | None = None) -> dict:
    r = cat.resolved[job.task]
    row = {"entry": job.source, "species": job.species_text, "seed": job.seed,
           "format": job.fmt, "grid": dict(job.grid), "path": job.output,
           "options_hash": job.key, "species_sha": _sha_of(cat, job),
           "options_sha": _options_sha(r.values), "status": status}
    if summary is not None:
        lods = summary["lods"]
        row |= {"files": [Path(f).relative_to(out_dir).as_posix() for f in summary["files"]],
                "bytes": summary["bytes"],
                "triangles": [r["triangles"] for r in lods], "joints": [r["joints"] for r in lods],
                "keys": [r["joint_keys"] for r in lods], "lod_distances_m": [r["distance_m"] for r in lods],
                "seconds": summary["seconds"], "worker": summary.get("worker", "")}
    if error is not None:
        row["error"] = error
    return row


CSV_COLUMNS = ("entry", "species", "seed", "format", "path", "options_hash", "status", "bytes",
               "triangles", "joints", "keys", "seconds", "worker", "error")


def write_manifest(out_dir: Path, cat: Catalogue, rows: list[dict], totals: dict) -> None:
    """DIR/manifest.json and manifest.csv (one row per job, catalogue order), each replaced
    atomically; then the journal they now contain is removed."""
    doc = {"catalogue": str(cat.path), "treegen": __version__, **totals, "assets": rows}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for row in rows:
        w.writerow([";".join(map(str, row[c])) if isinstance(row.get(c), list) else row.get(c, "")
                    for c in CSV_COLUMNS])
    for name, text in ((MANIFEST, json.dumps(doc, indent=1) + "\n"), (MANIFEST_CSV, buf.getvalue())):
        tmp = out_dir / f".{name}.tmp"
        tmp.write_text(text, "utf-8")
        os.replace(tmp, out_dir / name)
    (out_dir / JOURNAL).unlink(missing_ok=True)


def clean_staging(out_dir: Path, jobs: list[Job]) -> None:
    """Sweep the staging folders (exchange.staging) that killed workers of this host left in
    our output folders; those of live writers, or of other hosts on a shared folder, stay."""
    from .exchange import sweep

    for folder in sorted({(out_dir / job.output).parent for job in jobs}):
        sweep(folder)


def run_jobs(cat: Catalogue, plan: Plan, out_dir: str | os.PathLike, *, scheduler=None,
             workers=None, on_event=None) -> dict:
    """Build `plan.build` on Dask, stream each result to `on_event(kind, job, row)` (kind:
    built, failed, skipped, start), write the manifest, and return the totals. Failures do not
    stop the others; Ctrl-C cancels what is queued, closes the cluster and keeps what finished."""
    import contextlib

    from distributed import as_completed

    from .executor import dask_client

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
                raise TreegenError(f"-o {out_dir}: cannot create folder '{e.filename}' "
                                   f"({e.strerror})") from None
            started = True
            clean_staging(out_dir, plan.build)
            for job in plan.skip:
                rows[job.output] = {**plan.previous[job.output],
                                    **_row(job, out_dir, cat, None, "skipped")}
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
            ordered = [rows.get(job.output) or _row(job, out_dir, cat, None, "pending")
                       for job in cat.jobs]
            totals = {"jobs": len(cat.jobs),
                      **{k: sum(r["status"] == k for r in ordered)
                         for k in ("built", "skipped", "failed", "pending")},
                      "tasks": len(tasks), "seconds": round(time.perf_counter() - t0, 3),
                      "cluster": where}
            write_manifest(out_dir, cat, ordered, totals)
    return totals


def _build_all(cat, plan, out_dir, tasks, client, journal, rows, on_event, as_completed) -> None:
    """Submit one Dask task per tree (longest first) and record results as they arrive."""
    run = f"{os.getpid():x}{time.time_ns() & 0xFFFFFF:x}"
    est = estimate(cat, plan)
    futures = {}
    for task, jobs in tasks.items():
        j0 = jobs[0]
        fut = client.submit(build_task, cat.params[j0.species], j0.species_text,
                            cat.resolved[task], [str(out_dir / j.output) for j in jobs],
                            key=f"treegen-{j0.species.stem}-{task}-{run}",
                            priority=int(sum(est[j.output][1] for j in jobs) * 1000))
        futures[fut] = jobs
    for fut in as_completed(list(futures), loop=client.loop):
        jobs = futures.pop(fut)
        try:
            results = fut.result()
        except TreegenError as e:
            results, reason = None, str(e)
        except Exception as e:             # worker crash, KilledWorker, a bug
            results, reason = None, f"{type(e).__name__}: {e}"
        for k, job in enumerate(jobs):
            if results is None:
                row = _row(job, out_dir, cat, None, "failed", reason)
            else:
                row = _row(job, out_dir, cat, results[k], "built")
                journal.write(json.dumps(row) + "\n")
                journal.flush()
            rows[job.output] = row
            on_event(row["status"], job, row)
        fut.release()
