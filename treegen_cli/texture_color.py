"""What the generated textures share: linear colour → sRGB bytes and back, the check of a
colour argument, and the C¹ ramp their masks are shaped with (textures.py's conventions)."""

from __future__ import annotations

import numpy as np

_SRGB_LUT = np.round(
    255.0
    * np.where(
        np.linspace(0.0, 1.0, 4096) <= 0.0031308,
        12.92 * np.linspace(0.0, 1.0, 4096),
        1.055 * np.power(np.linspace(0.0, 1.0, 4096), 1 / 2.4) - 0.055,
    )
).astype(np.uint8)


def to_srgb8(lin: np.ndarray) -> np.ndarray:
    """Linear 0..1 floats → sRGB-encoded uint8 through a 4096-entry table (fast, exact enough)."""
    idx = np.clip(lin, 0.0, 1.0).astype(np.float32)
    idx *= np.float32(4095.0)
    idx += np.float32(0.5)
    return _SRGB_LUT.take(idx.astype(np.int32))


def srgb8_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB uint8 → linear float64 0..1 (what a renderer samples from the colour images)."""
    x = np.asarray(c, dtype=np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def check_color(name: str, color) -> np.ndarray:
    c = np.asarray(color, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 1:
        raise ValueError(f"{name} must be 3 linear floats in 0..1, got {color!r}")
    return c


def smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    """0 below e0, 1 above e1, a C¹ ramp between (float32 in, float32 out, few temporaries)."""
    t = np.subtract(x, np.float32(e0), dtype=np.float32)
    t *= np.float32(1.0 / (e1 - e0))
    np.clip(t, 0.0, 1.0, out=t)
    return t * t * (np.float32(3.0) - np.float32(2.0) * t)
