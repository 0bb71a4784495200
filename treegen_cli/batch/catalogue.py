"""A catalogue file → validated, expanded jobs: one per output file, each with the task
(the tree build) it shares with its other formats and the resume key its bytes depend on.
Every error names the catalogue's JSON path (`entries[1].grid.wind_speed[0]`)."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path, PurePosixPath

from ..build_id import build_id
from ..options import MAX_SEED
from ..void_options import check_formats, check_no_effect
from ..errors import TreegenError
from ..forest.schema import check_schema, read_json_file, show_value
from ..generate import check_trunk
from ..rig import check_joint_levels

SCHEMA_NAME = "catalogue.schema.json"
DEFAULT_NAME = "{species}_{seed}.{ext}"
FORMATS = ("glb", "gltf", "usda", "usdc", "usdz", "obj", "ply")
MAX_JOBS = 10_000  # jobs one catalogue may expand to (seed ranges × grid × formats) unless
# `treegen batch --max-jobs` raises it: "1-100000" typed for "1-10" is days of builds
_SEEDS = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


def schema_text() -> str:
    """The published JSON Schema of catalogue files (package data)."""
    return resources.files("treegen_cli").joinpath("schemas", SCHEMA_NAME).read_text("utf-8")


@dataclass(frozen=True)
class Job:
    """One output file. `source`: the JSON path of its entry; `task`: the build it shares
    with its other formats; `key`: what its bytes depend on (the resume key)."""

    index: int
    source: str
    species: Path  # resolved species file
    species_text: str  # as written in the catalogue
    seed: int
    fmt: str
    grid: tuple  # ((option, value), ...) of this grid point
    output: str  # path under DIR, POSIX
    task: str
    key: str


@dataclass
class Catalogue:
    path: Path
    jobs: list[Job]
    params: dict = field(default_factory=dict)  # species file → Params, parsed once
    digests: dict = field(default_factory=dict)  # species file → sha256 of its bytes
    resolved: dict = field(default_factory=dict)  # task → api.Resolved
    labels: dict = field(default_factory=dict)  # task → {option: the JSON path that set it}

    def reword(self, job: Job, message: str) -> str:
        """A build's error in the catalogue's terms: each make option's `--flag` in it
        (`--triangles 5`, from the code `treegen make` shares) that this job's catalogue set
        becomes the JSON path that set it (`entries[0].triangles 5`, `entries[0].seeds`), as
        the checks before a run say; options left to their defaults keep make's flag."""
        labels = self.labels.get(job.task, {})

        def path(m: re.Match) -> str:
            key = m.group(1).replace("-", "_")
            if key in labels:
                return labels[key]
            if key.startswith("no_") and key[3:] in labels:  # --no-impostor: "impostor": false
                return f"{labels[key[3:]]} false"
            return m.group(0)  # an option the catalogue left to its default: make's own words

        return _FLAG.sub(path, message)


# a flag as a word of its own (not inside a path such as /a/--fov/b)
_FLAG = re.compile(r"(?<![^\s(\[`'\"])--([a-z][a-z0-9-]*)")


def load_catalogue(path: str | os.PathLike, max_jobs: int = MAX_JOBS) -> Catalogue:
    """Read, validate and expand a catalogue; every error starts with the file and JSON path."""
    path = Path(path)
    data = read_json_file(path, "catalogue")
    try:
        return parse_catalogue(data, path, max_jobs)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None


def parse_seeds(value, where: str, max_jobs: int = MAX_JOBS) -> list[int]:
    """7, [1, 5, 9] or "1-40" / "1-5,9" → sorted-as-given list of distinct seeds. A bad
    list item is named by its index (`entries[0].seeds[1]`)."""
    allowed = f"allowed [0, {MAX_SEED}]"
    if isinstance(value, bool):
        raise TreegenError(
            f'{where}: expected a seed, a list of seeds or text like "1-40", got {json.dumps(value)}'
        )
    if isinstance(value, (int, float)):
        values, at = [value], [where]
    elif isinstance(value, list) and value:
        values, at = list(value), [f"{where}[{k}]" for k in range(len(value))]
    elif isinstance(value, str):
        values = []
        for part in value.split(","):
            m = _SEEDS.match(part)
            if not m:
                raise TreegenError(f'{where}: \'{value}\' is not a seed range; use e.g. "1-40" or "1-5,9"')
            lo, hi = int(m[1]), int(m[2] if m[2] is not None else m[1])
            if hi < lo:
                raise TreegenError(f"{where}: range '{part.strip()}' runs backwards; use {hi}-{lo}")
            if hi - lo + 1 > max_jobs:
                raise TreegenError(
                    f"{where}: range '{part.strip()}' gives {hi - lo + 1:,} seeds, "
                    f"over the limit of {max_jobs:,} jobs; raise it with --max-jobs N"
                )
            values.extend(range(lo, hi + 1))
        at = [where] * len(values)
    else:
        raise TreegenError(
            f"{where}: expected a seed, a non-empty list of seeds or text like "
            f'"1-40", got {type(value).__name__}'
        )
    for v, w in zip(values, at):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise TreegenError(f"{w}: expected a seed (a whole number), got {show_value(v)}; {allowed}")
        if isinstance(v, float):
            raise TreegenError(f"{w}: {show_value(v)} is not a whole number; {allowed}")
        if not 0 <= v <= MAX_SEED:
            raise TreegenError(f"{w}: seed {v} is out of range; {allowed}")
    seen = set()
    dupes = [(v, w) for v, w in zip(values, at) if v in seen or seen.add(v)]
    if dupes:
        raise TreegenError(f"{dupes[0][1]}: seed {dupes[0][0]} is listed twice")
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
        raise TreegenError(
            f"{where}: unknown field {{{e.args[0]}}} in '{template}'; allowed: "
            "{species}, {seed}, {ext}, {entry} and any make option, e.g. "
            "{wind_speed}"
        ) from None
    except (ValueError, IndexError, AttributeError) as e:
        raise TreegenError(f"{where}: bad name template '{template}' ({e})") from None
    if not name.lower().endswith("." + fmt):
        raise TreegenError(
            f"{where}: '{template}' gives '{name}' for format {fmt}; the name must "
            f"end in .{fmt} (use {{ext}})"
        )
    extra = "".join(f"_{k}-{name_value(v)}" for k, v in grid if k not in used)
    if extra:
        name = name[: -len(fmt) - 1] + extra + name[-len(fmt) - 1 :]
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or not p.name or p.name.startswith("."):
        raise TreegenError(
            f"{where}: '{template}' gives '{name}'; output names must stay inside "
            "the output folder (no absolute paths, '..' or hidden names)"
        )
    return str(p)


def _species(base: Path, value: str, where: str, params: dict) -> tuple[Path, str]:
    """Resolve (a path relative to the catalogue wins, else a bundled name) and parse a
    species file once per catalogue; returns (path, sha256 of bytes)."""
    from ..params import parse_params_bytes

    from ..bundled import resolve_species

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


def short_hash(obj) -> str:
    """The first 16 hex digits of the SHA-256 of `obj` as canonical JSON: a task or resume key."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def parse_catalogue(data, path: Path, max_jobs: int = MAX_JOBS) -> Catalogue:
    """Validate decoded JSON `data` of the catalogue at `path` and expand it into jobs, in
    catalogue order; refuses two jobs with one output before anything runs."""
    from .. import api

    schema = json.loads(schema_text())
    check_schema(data, schema, schema)
    base = path.parent
    defaults = data.get("defaults", {})
    # an option another one in the same place makes void is a mistake (impostor false with
    # impostor_distance); an entry turning off what the defaults set, or a grid, is on purpose
    check_no_effect({k: v for k, v in defaults.items() if k in api.DEFAULTS}, "defaults.{}".format, None)
    loaded: dict = {}
    jobs: list[Job] = []
    resolved: dict = {}
    labels: dict = {}
    seen_images: dict = {}
    outputs: dict[str, str] = {}
    for i, entry in enumerate(data["entries"]):
        where = f"entries[{i}]"
        sp, digest = _species(base, entry["species"], f"{where}.species", loaded)
        check_no_effect({k: v for k, v in entry.items() if k in api.DEFAULTS}, f"{where}.{{}}".format, None)

        def pick(key, fallback):
            if key in entry:
                return entry[key], f"{where}.{key}"
            if key in defaults:
                return defaults[key], f"defaults.{key}"
            return fallback, f"{where}.{key}"

        seeds_given, seeds_where = pick("seeds", 0)
        seeds = parse_seeds(seeds_given, seeds_where, max_jobs)
        formats, fwhere = pick("formats", ["glb"])
        for k, f in enumerate(formats):
            if f not in FORMATS:
                raise TreegenError(
                    f"{fwhere}[{k}]: unknown format {json.dumps(f)}; allowed: {', '.join(FORMATS)}"
                )
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
                base_job = api.resolve(opts, label, void_check=False)
            except TreegenError as e:
                msg = str(e)
                raise TreegenError(
                    msg if msg.startswith(("entries[", "defaults.")) else f"{where}: {msg}"
                ) from None
            base_job, images = _artist_images(base_job, base, label, seen_images)
            if base_job.values["compress"] == "meshopt":
                from ..exchange.compress import check_encoder

                check_encoder()
            check_formats(opts, formats, label, fwhere)  # typed options a format cannot take
            try:  # an implausible Scale is a typo: refused now, not by a worker mid-run
                check_trunk(loaded[sp][0], base_job.options.generate)
            except TreegenError as e:
                raise TreegenError(f"{where}.species: {e}") from None
            try:  # a joint_levels list this species has none of: refused now too
                check_joint_levels(loaded[sp][0].levels, base_job.options.rig, label("joint_levels"))
            except TreegenError as e:
                raise TreegenError(f"{where} ({entry['species']}): {e}") from None
            values = {
                k: v
                for k, v in base_job.values.items()
                if k != "seed" and not (k in api.UNSET_FREE and v is None)
            }
            for seed in seeds:
                identity = {"species": digest, "seed": seed, "options": values, "treegen": build_id()}
                if images:  # an edited PNG rebuilds (only keyed when given: older keys hold)
                    identity["images"] = images
                task = short_hash(identity)
                labels[task] = {**src, "seed": seeds_where}  # the keys this job's file set
                if "joints" in src and "max_joints" not in src:  # `joints` sets --max-joints
                    labels[task]["max_joints"] = src["joints"]
                resolved[task] = api.Resolved(
                    seed=seed, options=base_job.options, values={**base_job.values, "seed": seed}
                )
                fields = {
                    **{k: name_value(v) for k, v in values.items()},
                    "species": sp.stem,
                    "seed": str(seed),
                    "entry": str(i),
                }
                for fmt in formats:
                    name = render_name(template, {**fields, "ext": fmt}, point, fmt, twhere)
                    other = outputs.get(name.casefold())
                    if other is not None:
                        raise TreegenError(
                            f"{where}: output '{name}' (seed {seed}) is also written by {other}; "
                            "put {seed} or the grid keys into the name template, or drop the duplicate"
                        )
                    outputs[name.casefold()] = f"{where} (seed {seed})"
                    jobs.append(
                        Job(
                            index=len(jobs),
                            source=where,
                            species=sp,
                            species_text=entry["species"],
                            seed=seed,
                            fmt=fmt,
                            grid=point,
                            output=name,
                            task=task,
                            key=short_hash({"task": task, "format": fmt}),
                        )
                    )
                    if len(jobs) > max_jobs:
                        raise TreegenError(
                            f"{where}: the catalogue expands to more than "
                            f"{max_jobs:,} jobs; raise the limit with --max-jobs N"
                        )
    return Catalogue(
        path=path,
        jobs=jobs,
        params={p: v[0] for p, v in loaded.items()},
        digests={p: v[1][:16] for p, v in loaded.items()},
        resolved=resolved,
        labels=labels,
    )


def _artist_images(job, base: Path, label, seen: dict):
    """An entry's own leaf and bark PNGs: relative to the catalogue (as species files are),
    read and checked now (a broken file fails before anything runs, not on a worker), and
    with --no-textures refused. Returns the job with absolute paths and {option: sha256 of
    the file} for its key."""
    from dataclasses import replace

    from ..materials import check_options, read_png

    mats = job.options.materials
    fixed, images = {}, {}
    for key in ("leaf_texture", "bark_texture"):
        given = getattr(mats, key)
        if given is None:
            continue
        path = (base / given).resolve()  # (an absolute `given` stays as it is)
        if path not in seen:
            cut = key == "leaf_texture" and mats.cut_out
            seen[path] = hashlib.sha256(read_png(path, label(key), cut)).hexdigest()[:16]
        fixed[key], images[key] = path, seen[path]
    if not fixed:
        return job, images
    try:
        check_options(mats)
    except TreegenError as e:
        raise TreegenError(_FLAG.sub(lambda m: label(m.group(1).replace("-", "_")), str(e))) from None
    materials = replace(mats, **fixed)
    return replace(job, options=replace(job.options, materials=materials)), images


def species_sha(cat: Catalogue, job: Job) -> str:
    return cat.digests[job.species]


def options_sha(values: dict) -> str:
    from .. import api

    return short_hash(
        {k: v for k, v in values.items() if k != "seed" and not (k in api.UNSET_FREE and v is None)}
    )
