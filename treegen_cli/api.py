"""treegen as a library: `make(species, out, **options)` is `treegen make` without a shell.

    from treegen_cli import api
    summary = api.make("species/quaking_aspen.txt", "aspen.glb", seed=3, wind_speed=6,
                       lod_distances=[0, 15, 60])
    summary["triangles"], summary["lods"][1]["joint_keys"]

Options go by their CLI names with underscores (`--wind-speed` → `wind_speed`); list options
(`lod_distances`, `sides`, `joint_levels`) take a list or the CLI's "0,10,30" text. The CLI's
`make`, this function and `treegen batch` all turn options into stage options through
`options.resolve()`, so they share defaults, validation and error messages, and one set of
options always writes the same bytes whichever door it came in by.

`treegen make` in one read: commands/make.py hands the flags it was given to `plan_make`
(output name checked, `options.resolve` → stage options, species file parsed), then
`run_make`: `pipeline.build_asset` (grow, rig, mesh, wind, LODs, impostor, `prepare`) →
`exchange.export` (the writer the suffix picks, staged and renamed atomically) →
`make_summary`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

from .budget import BudgetOptions, plan_budget
from .bundled import resolve_species
from .clip import tracked_keys
from .errors import TreegenError, in_file
from .exchange import FIXED_UP_AXIS, GLTF_DEFAULTS, STATIC, check_suffix, check_up_axis, export, export_parts
from .forest import run_forest, schema_text as forest_schema_text  # noqa: F401  (the forest door)
from .generate import generate
from .limits import MAX_TREES, estimate_triangles  # noqa: F401  (MAX_TREES: forest's default)
from .lod_report import PAPER_DISTANCES, lod_table_row, schedule_rows
from .mesh import MESH_DEFAULTS

# re-exported: api is the one door (api.DEFAULTS, api.resolve, ...)
from .options import DEFAULTS, GROUPS, INFO_LOD_BUILD, UNSET_FREE, Resolved, cli_name, resolve  # noqa: F401
from .void_options import typed_name
from .params import Params, load_params
from .pipeline import Timings, build_asset
from .prepare import split_lods
from .profiles import apply_profile
from .progress import current_reporter
from .rig import build_rig
from .tree import tree_stats
from .wind import wind_report


def check_output(output: str | os.PathLike, up_axis: str | None = None, flag: str | None = None) -> Path:
    """Refuse an output name whose suffix no writer handles (or a folder), or an up axis its
    format cannot carry, before any work is done; `flag` ("-o") names the option in messages."""
    path = check_suffix(output, flag=flag)
    check_up_axis(path, up_axis)
    return path


def build(params, species, job: Resolved, timings=None):
    """Grow, rig, mesh and animate one tree; user errors are reported against `species`."""
    return in_file(
        species, build_asset, params, job.seed, job.options, timings if timings is not None else Timings()
    )


def write(asset, tree, output, timings, t0: float, job: Resolved | None = None) -> dict:
    """Export `asset` atomically to `output` (as per-LOD files with lod_files) and return the
    `make --json` summary."""
    values = job.values if job is not None else DEFAULTS
    gltf = job.options.gltf if job is not None else GLTF_DEFAULTS
    if Path(output).suffix.lower() not in FIXED_UP_AXIS:  # a profile's glTF encoding: not USD's
        gltf = GLTF_DEFAULTS  # (a typed --compress was refused for it before anything was built)
    asset = replace(asset, up_axis=values["up_axis"])
    static = Path(output).suffix.lower() in STATIC
    if static:  # what the file holds, and its summary: LOD0's rest pose (a batch task's job
        # has the LODs and clips its other formats take)
        asset = replace(asset, lods=[replace(asset.lods[0], clips=[])])
    written = (
        timings.run("write", export_parts, split_lods(asset), output, gltf)
        if values["lod_files"] and not static
        else timings.run("write", export, asset, output, gltf)
    )
    lod_options = job.options.lod if job is not None else None
    return make_summary(asset, tree, written, timings.stages, time.perf_counter() - t0, lod_options)


# ------------------------------------------------------------------------------------- make


@dataclass(frozen=True)
class MakeJob:
    """One checked `make` request, nothing built yet: what `run_make` needs."""

    species: str | os.PathLike  # as given: user errors in the species file name it
    output: Path
    params: Params
    job: Resolved
    t0: float  # when the request arrived (the summary's seconds)

    @property
    def static(self) -> bool:
        """.obj/.ply: no wind or LODs (the format cannot hold them)."""
        return self.output.suffix.lower() in STATIC

    @property
    def stage_runs(self) -> int:
        """Stage runs to expect, for a progress bar: per LOD generate, rig, mesh (, wind,
        lod), then materials, textures, prepare, write (, impostor)."""
        o = self.job.options
        per_lod = 3 if o.wind is None else 5
        if o.lod is None:
            return per_lod + 4
        return o.lod.count * per_lod + 4 + (o.impostor is not None)


def plan_make(
    species: str | os.PathLike, output: str | os.PathLike, options: dict, flag: str | None = None
) -> MakeJob:
    """Check the output name, resolve `options` (missing ones: a --profile, then DEFAULTS)
    and parse the species file; every refusal comes before any work."""
    t0 = time.perf_counter()
    path = check_output(output, options.get("up_axis"), flag=flag)
    job = resolve(options, output=path)
    return MakeJob(species, path, load_params(resolve_species(species)), job, t0)


def run_make(make_job: MakeJob, timings=None) -> dict:
    """Build the asset and write it; returns the `make --json` summary."""
    timings = timings if timings is not None else Timings()
    asset, tree = build(make_job.params, make_job.species, make_job.job, timings)
    summary = write(asset, tree, make_job.output, timings, make_job.t0, make_job.job)
    current_reporter().stage_totals(timings.stages)
    current_reporter().detail(
        f"  counts    stems per level {tree_stats(tree)['stems_per_level']}, "
        f"{tree.n_nodes:,} nodes, {tree.n_leaves:,} leaves, {len(asset.lods)} LOD(s)"
    )
    return summary


def make(species: str | os.PathLike, output: str | os.PathLike, **options) -> dict:
    """Grow `species` (a file, or a bundled name such as "quaking_aspen") and write it to
    `output` (format from the suffix), as `treegen make` does with the same options; returns
    what `treegen make --json` prints."""
    return run_make(plan_make(species, output, options))


def make_summary(asset, tree, written, stages: dict, seconds: float, lod_options=None) -> dict:
    """`treegen make --json`: what was written and how big, per LOD, and seconds per stage
    (a static file has no skin: no joints). With `lod_options`, each geometric LOD below LOD0
    has its triangle budget (lod_budget.lod_budget): a LOD never draws less than its trunks,
    so a tiny `--lod-triangles` fraction is exceeded, and the summary says so."""
    static = Path(written[0]).suffix.lower() in STATIC

    def lod_row(lod):
        clip = lod.clips[0] if lod.clips else None
        keys = 0 if clip is None else len(clip.times)
        joint_keys = 0 if clip is None else tracked_keys(clip, lod.skeleton)
        return {
            "distance_m": lod.distance,
            "vertices": sum(len(p.positions) for p in lod.primitives),
            "triangles": sum(len(p.indices) // 3 for p in lod.primitives),
            "joints": 0 if static else len(lod.skeleton.names),
            "keys": keys,
            "joint_keys": joint_keys,
            "decimated": clip is not None and clip.keys is not None,
            # None where unbounded too (the paper's walk with a camera that can be inside the
            # tree): JSON has no Infinity
            "max_error_px": None
            if clip is None or clip.error_px is None or not math.isfinite(clip.error_px)
            else round(clip.error_px, 3),
            "impostor": lod.impostor is not None,
        }

    lods = [lod_row(lod) for lod in asset.lods]
    if lod_options is not None and not static:
        from .lod_budget import lod_budget

        for k, r in enumerate(lods[1:], 1):
            r["budget"] = (
                None if r["impostor"] else int(lod_budget(k, asset.lods[0], asset.lods[k - 1], lod_options))
            )
    return {
        "file": str(written[0]),
        "files": [str(p) for p in written],
        "bytes": sum(p.stat().st_size for p in written),
        "species": asset.name,
        "seed": tree.seed,
        "stems": tree.n_stems,
        "leaves": tree.n_leaves,
        **{k: lods[0][k] for k in ("vertices", "triangles", "joints", "keys", "joint_keys")},
        "lods": lods,
        "seconds": round(seconds, 4),
        "stages_s": {k: round(v, 4) for k, v in stages.items()},
    }


# ------------------------------------------------------------------------------------- info


def info(
    species: str | os.PathLike, lod: bool = False, wind: bool = False, triangles: int | None = None, **options
) -> dict:
    """`treegen info --json`: grow `species` and report stems, leaves, sizes and LOD0
    triangles; with `triangles` the budget plan `make --triangles` would build; with `lod` a
    row per LOD and the paper's Table 3 side by side; with `wind` the wind model's numbers.
    An option no requested report uses is refused by name, as `make` refuses void ones."""

    def given(group: str) -> dict:
        return {k: v for k, v in options.items() if k in GROUPS[group]}

    for k in options:  # ("profile" also sets the budget the plain report plans)
        if not lod and k != "profile" and (k in GROUPS["lod"] or k in INFO_LOD_BUILD):
            flag = typed_name(k, options[k], cli_name)
            raise TreegenError(f"{flag}: has no effect without --lod (it shapes the LODs); add --lod")
        if not (lod or wind) and k in GROUPS["wind"]:
            raise TreegenError(
                f"{cli_name(k)}: has no effect without --wind or --lod (it shapes the wind); add --wind"
            )

    typed = triangles is not None
    if not typed and options.get("profile") is not None:  # its LOD0 budget (a ceiling), as make's
        triangles = apply_profile({"profile": options["profile"]}).get("triangles")

    unknown = {k: v for k, v in options.items() if k not in DEFAULTS}
    generate_job = resolve(given("generate") | unknown)
    generate_options, seed = generate_job.options.generate, generate_job.seed
    path = resolve_species(species)
    params = load_params(path)
    t0 = time.perf_counter()
    tree = in_file(path, generate, params, seed, generate_options)
    seconds = time.perf_counter() - t0
    current_reporter().detail(
        f"  generate  {seconds:8.3f} s  ({tree.n_stems:,} stems, "
        f"{tree.n_nodes:,} nodes, {tree.n_leaves:,} leaves)"
    )
    stats = tree_stats(tree) | {"generate_s": round(seconds, 4), "file": str(path)}
    stats["triangles"] = _triangle_rows(path, params, seed, tree, triangles, generate_options, not typed)
    if lod:
        from .render_gl import egl_available  # lazy: GL only when the impostor is drawn

        build = given("lod") | given("wind") | {k: v for k, v in options.items() if k in INFO_LOD_BUILD}
        if typed:  # (a profile's budget comes with "profile", as a ceiling)
            build["triangles"] = triangles
        job = resolve(given("generate") | build)  # the LODs `make` builds with these options
        lod_options = job.options.lod
        assert lod_options is not None  # no_lod is not an info option
        make_options = replace(job.options, impostor=job.options.impostor if egl_available() else None)
        reuse = tree if make_options.budget.triangles is None else None  # a budget regrows it
        asset, _tree = in_file(path, build_asset, params, seed, make_options, Timings(), reuse)
        stats["lods"] = [lod_table_row(level, lod_options) for level in asset.lods]
        stats["schedules"] = schedule_rows(asset.lods[0], PAPER_DISTANCES, lod_options)
    if wind:
        wind_options = resolve(given("wind")).options.wind
        stats["wind"] = wind_report(tree, build_rig(tree), wind_options, seed)
    return stats


def _triangle_rows(species, params, seed, tree, triangles, generate_options, ceiling=False) -> dict:
    """LOD0 triangles as `make` builds the grown tree (exact, from its stems and leaves), and
    with a budget the plan `make --triangles` would build (`ceiling`: a profile's, which a
    species already under it keeps as it is)."""
    bark, leaves = estimate_triangles(tree, MESH_DEFAULTS)
    out: dict = {"lod0": bark + leaves, "bark": bark, "leaves": leaves}
    if triangles is not None:
        plan = in_file(
            species,
            plan_budget,
            params,
            seed,
            MESH_DEFAULTS,
            BudgetOptions(triangles=triangles, ceiling=ceiling),
            generate_options,
        )
        out["budget"] = {
            "target": triangles,
            "triangles": plan.triangles,
            "bark": plan.bark,
            "leaves": plan.leaves,
            "levels": plan.levels,
            "curve_scale": plan.curve_scale,
            "sides": list(plan.mesh.sides),
            "rings_per_segment": list(plan.mesh.rings_per_segment),
            "leaf_quality_factor": round(plan.leaf_factor, 6),
            "minimum": None if plan.under is not None else plan.minimum,  # (none searched)
            "maximum": None if plan.under is not None else plan.maximum,
            "as_is": plan.under is not None,  # a profile's ceiling the species was under
            "plan": plan.describe(),
        }
    return out


__all__ = [
    "DEFAULTS",
    "MAX_TREES",
    "MakeJob",
    "Resolved",
    "TreegenError",
    "build",
    "check_output",
    "cli_name",
    "forest_schema_text",
    "info",
    "make",
    "make_summary",
    "plan_make",
    "resolve",
    "run_forest",
    "run_make",
    "write",
]
