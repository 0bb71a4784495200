"""Skinning influences: up to 4 (joint, weight) slots per vertex, as glTF and UsdSkel take them."""

from __future__ import annotations

import numpy as np


def merge_influences(joints: np.ndarray, weights: np.ndarray):
    """(K, n ≤ 4) joint/weight slots → (K, 4): duplicates merged, sorted by weight, normalised,
    unused slots (0, 0.0).   Result: ([3, 5, 3, 0], [.2, .3, .5, 0]) → ([3, 5, 0, 0], [.7, .3, 0, 0])"""
    K, n = joints.shape
    J = np.zeros((K, 4), dtype=np.int64)
    W = np.zeros((K, 4), dtype=np.float64)
    J[:, :n] = joints
    W[:, :n] = weights
    for j in range(1, 4):
        for i in range(j):
            dup = (J[:, j] == J[:, i]) & (W[:, i] > 0)
            W[dup, i] += W[dup, j]
            W[dup, j] = 0.0
    order = np.argsort(-W, axis=1, kind="stable")
    W = np.take_along_axis(W, order, axis=1)
    J = np.take_along_axis(J, order, axis=1)
    J[W <= 0] = 0
    W[W < 0] = 0.0
    W /= W.sum(axis=1, keepdims=True)
    return J.astype(np.uint16), W.astype(np.float32)
