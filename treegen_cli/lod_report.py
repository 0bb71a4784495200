"""The paper's Table 3 for a tree: per LOD, keys kept, animation bytes, measured error and the
CPU method's leaf-vertex updates per frame (`treegen info --lod`), and the bounded
schedule against the paper's rule at the paper's distances (`bench/lod_bench.py`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .asset import Clip, Lod
from .clip import tracked_keys
from .lod import LOD_DEFAULTS, LodOptions
from .lod_decimate import decimate, measure_error_px
from .lod_probes import probes


def leaf_vertex_joints(lod: Lod) -> np.ndarray:
    """Leaf vertices carried per joint (J,), from the "leaves" primitive's first influence."""
    J = len(lod.skeleton.names)
    counts = np.zeros(J, dtype=np.int64)
    for p in lod.primitives:
        if p.name == "leaves" and len(p.joints):
            counts += np.bincount(np.asarray(p.joints[:, 0], dtype=np.int64), minlength=J)
    return counts


def _keys_per_joint(clip: Clip | None, n_joints: int) -> np.ndarray:
    """Keys each joint's track keeps (J,); zeros without a clip."""
    if clip is None:
        return np.zeros(n_joints, dtype=np.int64)
    K = len(clip.times)
    return np.full(n_joints, K) if clip.keys is None else np.array([len(k) for k in clip.keys])


def leaf_updates(lod: Lod) -> tuple[int, float]:
    """(leaf vertices, leaf-vertex updates per frame on average) of one LOD: the CPU method's
    cost, Σ_j kept keys_j × leaf vertices on joint j / keys; without a clip nothing moves."""
    per_joint = leaf_vertex_joints(lod)
    clip = lod.clips[0] if lod.clips else None
    K = len(clip.times) if clip is not None else 0
    if K == 0:
        return int(per_joint.sum()), 0.0
    kept = _keys_per_joint(clip, len(per_joint))
    return int(per_joint.sum()), float(np.sum(kept * per_joint) / K)


PAPER_DISTANCES = (30.0, 130.0)  # the paper's Table 3


def animation_bytes(clip: Clip | None, n_joints: int) -> int:
    """Bytes the glTF writer stores for the clip's rotation keys: float32 xyzw per kept key
    and joint, plus one float32 time accessor per distinct key set (tracks with the same
    schedule share it); every joint counted as moving."""
    if clip is None:
        return 0
    K = len(clip.times)
    if clip.keys is None:
        return 16 * K * n_joints + 4 * K
    sets = {np.asarray(k, np.int64).tobytes(): len(k) for k in clip.keys}
    return int(16 * sum(len(k) for k in clip.keys) + 4 * sum(sets.values()))


def schedule_rows(lod: Lod, distances=PAPER_DISTANCES, options: LodOptions = LOD_DEFAULTS) -> list[dict]:
    """The paper's Table 3 for one LOD's dense clip: per distance, the bounded schedule and
    the paper's rule side by side — keys kept, animation bytes, measured max error
    (perspective-true, `measure_error_px`) and leaf-vertex updates per frame."""
    dense = replace(lod.clips[0], keys=None)
    pr = probes(lod.skeleton, lod.primitives)
    J = len(lod.skeleton.names)
    rows = []
    for d in distances:
        for schedule in ("bounded", "paper"):
            opts = replace(options, schedule=schedule)
            clip, rep = decimate(lod.skeleton, lod.primitives, dense, d, opts, pr=pr)
            err = measure_error_px(lod.skeleton, lod.primitives, dense, clip, d, opts)
            _, updates = leaf_updates(replace(lod, clips=[clip]))
            rows.append(
                {
                    "distance_m": float(d),
                    "schedule": schedule,
                    "keys_kept": rep.keys_kept,
                    "keys_dense": rep.keys_dense,
                    "keys_kept_pct": round(100.0 * rep.kept_fraction, 2),
                    "animation_bytes": animation_bytes(clip, J),
                    "animation_bytes_dense": animation_bytes(dense, J),
                    "max_error_px": round(err, 4),
                    "leaf_vertex_updates_per_frame": round(updates, 1),
                    "seconds": round(rep.seconds, 4),
                }
            )
    return rows


def lod_table_row(lod: Lod, options: LodOptions = LOD_DEFAULTS) -> dict:
    """One row of the Table-3 analogue: keys kept, max error (measured here, on the LOD's own
    clip against its dense rotations), the CPU method's leaf-vertex updates per frame
    (Σ_j kept keys_j × leaf vertices_j / frames) next to all leaf vertices (the all-GPU
    method's cost per frame), joints, triangles."""
    clip = lod.clips[0] if lod.clips else None
    J = len(lod.skeleton.names)
    K = len(clip.times) if clip is not None else 0
    kept = tracked_keys(clip, lod.skeleton) if clip is not None else 0  # as make counts them
    leaf_vertices, updates = leaf_updates(lod)
    error = 0.0
    if clip is not None and clip.keys is not None:
        dense = replace(clip, keys=None)
        error = measure_error_px(lod.skeleton, lod.primitives, dense, clip, lod.distance, options)
    row = {
        "distance_m": lod.distance,
        "clip": clip.name if clip else None,
        "keys_kept": kept,
        "keys_dense": int(K * J),
        "keys_kept_pct": round(float(100.0 * kept / max(K * J, 1)), 2),
        "animation_bytes": animation_bytes(clip, J),
        "max_error_px": round(error, 4),
        "leaf_vertex_updates_per_frame": round(updates, 1),
        "leaf_vertices": leaf_vertices,
        "joints": J,
        "triangles": int(sum(len(p.indices) // 3 for p in lod.primitives)),
        "screen_coverage": round(float(lod.screen_coverage), 4),
    }
    imp = lod.impostor
    if imp is not None:  # the last LOD: crossed cards showing two of a view atlas's views
        from .impostor import ImpostorOptions

        row["impostor"] = {
            "grid": imp.grid,
            "cell_px": imp.cell,
            "card_view_px": ImpostorOptions(grid=imp.grid, cell=imp.cell).card_cell,
            "atlas_px": imp.grid * imp.cell,
            "card_m": round(2.0 * imp.radius, 3),
            "atlas_bytes": len(imp.albedo.png) + len(imp.normal_depth.png),
        }
    return row
