"""Linear blend skinning of many frames at once, the tests' reference for what a client plays.

    skinned = skin_frames(skinning, points, joints, weights)
    # Result: (K, V, 3) float64, Σ_s w_s · S[k, j_s] · (p, 1) for every frame k and vertex

One sparse (V, 4J) × dense (4J, 3K) product: gathering each vertex's four matrices per frame
would be K × V × 16 floats (gigabytes for a willow's leaves over a 10 s clip)."""

from __future__ import annotations

import numpy as np
from scipy import sparse


def skin_frames(
    skinning: np.ndarray, points: np.ndarray, joints: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """`skinning`: (K, J, 4, 4) world · inverse bind per frame; points (V, 3); joints and
    weights (V, S) influences."""
    (k, j), v = skinning.shape[:2], len(points)
    s = joints.shape[1]
    hom = np.c_[np.asarray(points, np.float64), np.ones(v)]  # (V, 4)
    cols = (np.asarray(joints, np.int64)[:, :, None] * 4 + np.arange(4)).ravel()  # joint's 4 rows
    vals = (np.asarray(weights, np.float64)[:, :, None] * hom[:, None, :]).ravel()
    q = sparse.csr_matrix((vals, (np.repeat(np.arange(v), 4 * s), cols)), shape=(v, 4 * j))
    m = np.asarray(skinning, np.float64)[:, :, :3, :].transpose(1, 3, 0, 2).reshape(4 * j, 3 * k)
    return np.ascontiguousarray((q @ m).reshape(v, k, 3).transpose(1, 0, 2))
