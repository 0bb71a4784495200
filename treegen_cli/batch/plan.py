"""What a run will do: the jobs to build and those up to date (resume), each tree's plan
(--dry-run: LODs, triangles, joints as the build makes them) and size/time estimates."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import TreegenError
from ..exchange import STATIC
from .catalogue import Catalogue, Job, options_sha, species_sha
from .manifest import journal_rows


def up_to_date(out_dir: Path, job: Job, row: dict | None) -> bool:
    """Whether `row` (an earlier run's) is `job`'s, and its files are on disk at the size
    recorded: the resume test (written atomically, a file there is a whole file)."""
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
    previous: dict[str, dict]  # output path → earlier row


def plan_jobs(cat: Catalogue, out_dir: str | os.PathLike, force: bool = False) -> Plan:
    out_dir = Path(out_dir)
    previous = journal_rows(out_dir) if out_dir.is_dir() else {}
    build, skip = [], []
    for job in cat.jobs:
        (skip if not force and up_to_date(out_dir, job, previous.get(job.output)) else build).append(job)
    return Plan(build=build, skip=skip, previous=previous)


def plan_trees(
    cat: Catalogue, jobs: list[Job], seconds: dict[str, float] | None = None, reporter=None
) -> dict[str, list[dict] | str]:
    """Per task of `jobs`: what its build will have per LOD (pipeline.plan_asset: triangles,
    vertices, joints, switch distance; budgets, profiles and joint limits applied as the build
    applies them), or the one-line error the build would fail with. Grown here, one tree at a
    time, without wind, textures or the impostor atlas; `seconds`, if given, gets each task's
    CPU seconds of that (the build repeats them: estimate() counts them); `reporter` (a
    progress.Reporter) shows a bar over the trees and, verbose, a line per tree."""
    from ..pipeline import plan_asset

    out: dict[str, list[dict] | str] = {}
    total = len({job.task for job in jobs})
    for job in jobs:
        if job.task in out:
            continue
        r = cat.resolved[job.task]
        if reporter is not None:
            reporter.stage_started("planning", total)
        t0 = time.process_time()
        try:
            out[job.task] = plan_asset(cat.params[job.species], r.seed, r.options)
        except TreegenError as e:
            out[job.task] = cat.reword(job, str(e))
        spent = time.process_time() - t0
        if seconds is not None:
            seconds[job.task] = spent
        if reporter is not None:
            reporter.stage_done("planning", spent)
            reporter.detail(f"  planned {len(out)}/{total}: {job.source} seed {r.seed} ({spent:.2f} s)")
    return out


def for_format(fmt: str, shape):
    """A task's planned LODs (plan_trees) as the file of format `fmt` holds them: a static one
    (.obj .ply) LOD0's rest pose alone, no joints (the manifest's row for it says so)."""
    if isinstance(shape, list) and f".{fmt}" in STATIC:
        return [{**shape[0], "joints": 0, "distance_m": 0.0}]
    return shape


# bytes per vertex (float32 position, normal, UV; joints, weights, tangents on bark) and per
# triangle (indices), and the share of that --compress keeps (README: ~60 %, ~a fifth)
_VERTEX_BYTES, _TRIANGLE_BYTES = 48, 8
_COMPRESSED = {"none": 1.0, "quantize": 0.6, "meshopt": 0.2}
# the static formats' own (vertex, triangle) bytes: an OBJ's v/vt/vn lines and an `f a/a/a …`
# line (a dry run read LOD0's 48 + 8 and was 2.3× low on the aspen, 11× under --profile web);
# a PLY's float32 position and normal, and a uchar count + three int32 (measured to the byte)
_STATIC_BYTES = {"obj": (77, 60), "ply": (24, 13)}
# USD's meshes and keys against the glTF model: crate packs them tighter, text spells them out
# (the aspen, textures aside: .usdc 7.7 MB, .usda 32.1 MB for the .glb's 12.4 MB)
_USD_SCALE = {"usdc": 0.62, "usdz": 0.62, "usda": 2.6}
# PNG bytes per texel: the leaf atlas and bark maps (N² + 2 (N/2)² texels; 0.67-0.95 measured),
# the impostor's albedo + normal atlases (side² each pair; 0.49 for a sparse small tree to 1.46
# for the aspen at --profile web: a full crown compresses less)
_MATERIAL_PNG, _IMPOSTOR_PNG = 0.9, 0.9


def _texture_bytes(fmt: str, options, impostor: bool) -> float:
    """What a file's textures add: its materials' PNGs (none in a PLY, or without textures) and
    the impostor atlases (the LOD formats only)."""
    if fmt == "ply" or not options.materials.textures:
        return 0.0
    n = options.materials.texture_size
    size = _MATERIAL_PNG * 1.5 * n * n
    if impostor and f".{fmt}" not in STATIC:  # the atlas as resolved (--impostor-size, or 2N)
        size += _IMPOSTOR_PNG * (options.impostor.grid * options.impostor.cell) ** 2
    return size


# CPU seconds of a build beyond what plan_asset does (fitted on 7 builds, bench/estimate_bench.py):
# per joint and frame of every LOD's clip (wind), the impostor, per MB written; and, with no
# plan, per vertex of every LOD (growing, rigging, meshing, planning the LODs)
_S_JOINT_FRAME, _S_IMPOSTOR, _S_MB, _S_VERTEX = 3.1e-6, 0.18, 0.014, 3.0e-6


def estimate(
    cat: Catalogue,
    plan: Plan,
    shapes: dict[str, list[dict] | str] | None = None,
    seconds: dict[str, float] | None = None,
) -> dict[str, tuple[float, float, str]]:
    """Per output path: (bytes, seconds, how). Measured when an earlier run built the same
    species, format and options (any seed); otherwise the planned LODs (`shapes` and the
    planning's own `seconds`, plan_trees: "plan") or the leaf and stem counts the species
    predicts (generate.estimate_counts: "model"), plus a model of the clip, the impostor and
    the bytes written."""
    from ..generate import estimate_counts

    measured: dict[tuple, list] = {}
    for row in plan.previous.values():
        measured.setdefault((row.get("species_sha"), row.get("format"), row.get("options_sha")), []).append(
            (row.get("bytes", 0), row.get("seconds", 0.0))
        )
    out = {}
    for job in cat.jobs:
        r = cat.resolved[job.task]
        sha = species_sha(cat, job)
        opt = options_sha(r.values)
        m = measured.get((sha, job.fmt, opt))
        if m:
            out[job.output] = (sum(b for b, _ in m) / len(m), sum(s for _, s in m) / len(m), "measured")
            continue
        frames = 0 if r.options.wind is None else r.options.wind.duration * r.options.wind.fps + 1
        shape = for_format(job.fmt, shapes.get(job.task)) if shapes is not None else None
        if isinstance(shape, list):
            lods = len(shape)
            joints = sum(row["joints"] for row in shape)
            per_v, per_t = _STATIC_BYTES.get(job.fmt, (_VERTEX_BYTES, _TRIANGLE_BYTES))
            # --compress (a profile's too) encodes glTF only
            packed = _COMPRESSED[r.values["compress"]] if job.fmt in ("glb", "gltf") else 1.0
            size = _USD_SCALE.get(job.fmt, 1.0) * (
                packed * sum(row["vertices"] * per_v + row["triangles"] * per_t for row in shape)
                + shape[0]["joints"] * frames * 16 * min(lods, 2)
            )
            grow = (seconds or {}).get(job.task, _S_VERTEX * sum(row["vertices"] for row in shape))
            how = "plan"
        else:
            stems, leaves = estimate_counts(cat.params[job.species])
            lods = 1 if r.options.lod is None else r.options.lod.count
            verts = leaves * 4 + stems * 60
            if r.options.budget.triangles:  # LOD0 grown to the budget (~1.45 vertices a triangle)
                verts = min(verts, 1.45 * r.options.budget.triangles)
            verts *= 1.0 if lods == 1 else 1.9
            joints = r.options.rig.max_joints * (1.0 if lods == 1 else 1.9)
            size = verts * 27 + r.options.rig.max_joints * frames * 16 * min(lods, 2)
            grow = _S_VERTEX * verts
            how = "model"
        impostor = lods > 1 and r.options.impostor is not None
        size += _texture_bytes(job.fmt, r.options, impostor)
        secs = grow + _S_JOINT_FRAME * joints * frames + _S_IMPOSTOR * impostor + _S_MB * size / 1e6
        out[job.output] = (size, secs, how)
    return out
