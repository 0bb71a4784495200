"""Quaternion helpers on numpy arrays, xyzw order (scipy's), broadcasting over leading axes.

One home for the few operations every stage needs (wind composes, LOD and the writers slerp),
kept in plain numpy because scipy's Rotation is ~10× slower on hundreds of thousands of pairs.
"""
from __future__ import annotations

import numpy as np


def unit(q: np.ndarray) -> np.ndarray:
    """q scaled to length 1 along the last axis."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ∘ b (apply b, then a)."""
    av, aw = a[..., :3], a[..., 3:]
    bv, bw = b[..., :3], b[..., 3:]
    return np.concatenate([aw * bv + bw * av + np.cross(av, bv),
                           aw * bw - np.sum(av * bv, axis=-1, keepdims=True)], axis=-1)


def continuous(q: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 so consecutive keys have a non-negative dot: the same
    rotations, but no importer that lerps or slerps takes the long way round."""
    if len(q) < 2:
        return q
    dot = np.einsum("k...i,k...i->k...", q[1:], q[:-1])
    flips = np.concatenate([np.ones((1,) + dot.shape[1:]), np.where(dot < 0, -1.0, 1.0)])
    return q * np.cumprod(flips, axis=0)[..., None]


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Shortest-path slerp of unit quaternions (..., 4) at fractions t (...): what glTF's
    LINEAR rotation sampler plays between two keys."""
    dot = np.sum(a * b, axis=-1)
    b = np.where((dot < 0)[..., None], -b, b)
    theta = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-9
    safe = np.where(small, 1.0, s)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(small, t, np.sin(t * theta) / safe)
    return unit(wa[..., None] * a + wb[..., None] * b)
