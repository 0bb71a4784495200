"""Stem frames: the rotations every growth step applies, as batched 3×3 matrices.

A stem's frame is a rotation matrix whose z column is its direction; curving, splitting,
placing children and turning leaves are all products with these, one (n, 3, 3) batch per step.
"""

from __future__ import annotations

import numpy as np

UP = np.array([0.0, 0.0, 1.0])


def rot_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) about unit axes (n, 3) by angles (n,) radians (Rodrigues)."""
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    m = np.empty(axis.shape[:1] + (3, 3))
    m[:, 0, 0] = t * x * x + c
    m[:, 0, 1] = t * x * y - s * z
    m[:, 0, 2] = t * x * z + s * y
    m[:, 1, 0] = t * x * y + s * z
    m[:, 1, 1] = t * y * y + c
    m[:, 1, 2] = t * y * z - s * x
    m[:, 2, 0] = t * x * z - s * y
    m[:, 2, 1] = t * y * z + s * x
    m[:, 2, 2] = t * z * z + c
    return m


def rot_x(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1], m[..., 1, 2] = c, -s
    m[..., 2, 1], m[..., 2, 2] = s, c
    return m


def rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    m[..., 0, 0], m[..., 0, 1] = c, -s
    m[..., 1, 0], m[..., 1, 1] = s, c
    m[..., 2, 2] = 1.0
    return m


def unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    n = np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]
    out = v / np.maximum(n, 1e-12)
    if fallback is not None:
        out = np.where(n > 1e-9, out, fallback)
    return out


def declination(direction: np.ndarray) -> np.ndarray:
    """Angle (radians) between a direction and world up."""
    return np.arccos(np.clip(direction[..., 2], -1.0, 1.0))
