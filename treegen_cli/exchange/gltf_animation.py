"""glTF animation: a Clip's rotation tracks as samplers and channels, each track with only the
keys its LOD's schedule kept (tracks with the same key set share one input accessor)."""

from __future__ import annotations

import numpy as np

from ..asset import Clip, KeyPlan, Skeleton
from ..axes import quat_to_y_up
from ..quat import continuous
from .compress import snorm16
from .gltf_buffer import Buffer
from .gltf_mesh import unit


def tracked_joints(clip: Clip) -> np.ndarray:
    """Joints that get a channel, as prepare marked them in Clip.animated: the moving ones, or
    the root's alone in a still clip."""
    if clip.animated is None:
        raise ValueError(f"clip {clip.name!r} is not prepared (prepare.prepare before export)")
    return np.flatnonzero(clip.animated)


def rotation_samplers(
    buf: Buffer,
    clip: Clip,
    joints: np.ndarray,
    inputs: dict,
    quantized: bool = False,
    wide: np.ndarray | None = None,
    bits: np.ndarray | None = None,
) -> list[tuple[int, dict]]:
    """[(joint, sampler)] for the rotation tracks of `joints`, each with only its kept keys
    (Y up, sign-continuous). `inputs` caches input accessors by (times, key set), so tracks
    with the same schedule share one. `quantized`: outputs as normalized int16 (core glTF),
    QUATERNION-filtered under meshopt (at `bits` per joint when given), but float32 for the
    `wide` joints (key_plan.py); a track whose stored keys are all equal is stored as its
    first key (the first track keeps its span, so the clip keeps its length)."""
    K = len(clip.times)
    rot = unit(quat_to_y_up(clip.rotations))
    times = np.asarray(clip.times, dtype=np.float32)
    out = []
    for j in joints:  # loop over joints (a few hundred), not keys or vertices
        keys = np.arange(K) if clip.keys is None else np.asarray(clip.keys[j], dtype=np.int64)
        q = continuous(rot[keys, j])
        if not quantized:
            values, fields = q.astype(np.float32), {}
        elif wide is not None and wide[j]:  # meshopt: EXPONENTIAL-filtered
            values = q.astype(np.float32)
            fields = {"filter": "EXPONENTIAL", "source": values}
            if bits is not None:
                fields["bits"] = int(bits[j])
        else:
            values = snorm16(q)
            fields = {"normalized": True, "filter": "QUATERNION", "source": q.astype(np.float32)}
            if bits is not None:
                fields["bits"] = int(bits[j])
        if quantized and out and len(keys) > 1 and not np.any(values != values[:1]):
            keys, values = keys[:1], values[:1]
            if "source" in fields:
                fields["source"] = fields["source"][:1]
        ident = (times.tobytes(), keys.tobytes())
        if ident not in inputs:
            inputs[ident] = buf.accessor(times[keys], bounds=True)
        sampler = {"input": inputs[ident], "output": buf.accessor(values, **fields)}
        if not (quantized and clip.interpolation == "LINEAR"):  # (LINEAR is glTF's default)
            sampler["interpolation"] = clip.interpolation
        out.append((int(j), sampler))
    return out


def animation_dict(
    buf: Buffer,
    clip: Clip,
    skeleton: Skeleton,
    joint_nodes: np.ndarray,
    quantized: bool = False,
    plan: KeyPlan | None = None,
) -> dict:
    """The clip as one glTF animation: a rotation channel per moving joint, on its node in
    `joint_nodes`; when no joint moves (`--wind-speed 0`), the root's track, a still loop, as
    USD keys its timeline: engines that play `wind_loop` by name find it. `plan`: a compressed
    LOD0's keys, bits and float32 joints (key_plan.py)."""
    if plan is not None:  # (its clip may leave still tracks out: key_plan.still)
        clip = plan.clip
    joints = tracked_joints(clip)
    wide, bits = (plan.wide, plan.bits) if plan is not None else (None, None)
    samplers, channels = [], []
    for j, sampler in rotation_samplers(buf, clip, joints, {}, quantized, wide, bits):
        samplers.append(sampler)
        channels.append(
            {"sampler": len(samplers) - 1, "target": {"node": int(joint_nodes[j]), "path": "rotation"}}
        )
    return {"name": clip.name, "samplers": samplers, "channels": channels}
