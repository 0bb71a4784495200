"""Axis conventions: the generator works Z up (metres, right-handed, like the Weber–Penn paper);
glTF, OBJ and the preview are Y up. One change of axes C, used by every format that needs it.
"""

from __future__ import annotations

import numpy as np

# generator (Z up) → Y up: (x, y, z) → (x, z, −y)
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def to_y_up(v: np.ndarray) -> np.ndarray:
    """Vectors (..., 3): (x, y, z) → (x, z, −y)."""
    v = np.asarray(v)
    return np.stack([v[..., 0], v[..., 2], -v[..., 1]], axis=-1)


def quat_to_y_up(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) xyzw: C is a proper rotation, so the vector part maps like a vector."""
    q = np.asarray(q, dtype=np.float64)
    return np.concatenate([to_y_up(q[..., :3]), q[..., 3:]], axis=-1)


def quat_from_y_up(q: np.ndarray) -> np.ndarray:
    """The inverse of quat_to_y_up: vector part (x, y, z) → (x, −z, y)."""
    q = np.asarray(q, dtype=np.float64)
    return np.stack([q[..., 0], -q[..., 2], q[..., 1], q[..., 3]], axis=-1)


def matrix_to_y_up(m: np.ndarray) -> np.ndarray:
    """4×4 matrices (..., 4, 4): C·M·Cᵀ."""
    c = np.eye(4)
    c[:3, :3] = Z_UP_TO_Y_UP
    return c @ np.asarray(m, dtype=np.float64) @ c.T
