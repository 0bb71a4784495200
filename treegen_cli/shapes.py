"""Weber–Penn ShapeRatio, stem taper and trunk flare — pure functions on numpy arrays.

Kept apart from the generator because the mesh builder evaluates the same radius profile
between nodes.
"""

from __future__ import annotations

import numpy as np

CONICAL, SPHERICAL, HEMISPHERICAL, CYLINDRICAL = 0, 1, 2, 3
TAPERED_CYLINDRICAL, FLAME, INVERSE_CONICAL, TEND_FLAME, ENVELOPE = 4, 5, 6, 7, 8


def shape_ratio(
    shape: int, r, prune_width_peak: float = 0.5, prune_power_low: float = 0.5, prune_power_high: float = 0.5
) -> np.ndarray:
    """The paper's ShapeRatio(shape, r) for r in [0, 1], elementwise.

    Shape 8 is the pruning envelope. It uses the continuous form (dividing by PruneWidthPeak
    on the upper side), which equals the paper's at PruneWidthPeak = 0.5 and does not jump
    anywhere else.
    """
    r = np.asarray(r, dtype=np.float64)
    if shape == CONICAL:
        return 0.2 + 0.8 * r
    if shape == SPHERICAL:
        return 0.2 + 0.8 * np.sin(np.pi * r)
    if shape == HEMISPHERICAL:
        return 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    if shape == CYLINDRICAL:
        return np.ones_like(r)
    if shape == TAPERED_CYLINDRICAL:
        return 0.5 + 0.5 * r
    if shape == FLAME:
        return np.where(r <= 0.7, r / 0.7, (1.0 - r) / 0.3)
    if shape == INVERSE_CONICAL:
        return 1.0 - 0.8 * r
    if shape == TEND_FLAME:
        return np.where(r <= 0.7, 0.5 + 0.5 * r / 0.7, 0.5 + 0.5 * (1.0 - r) / 0.3)
    if shape == ENVELOPE:
        peak = min(max(prune_width_peak, 1e-6), 1.0 - 1e-6)
        low = np.clip(r / (1.0 - peak), 0.0, None) ** prune_power_high
        high = np.clip((1.0 - r) / peak, 0.0, None) ** prune_power_low
        out = np.where(r < 1.0 - peak, low, high)
        return np.where((r < 0.0) | (r > 1.0), 0.0, out)
    raise ValueError(f"shape {shape} is not 0..8")


def taper_radius(r0, length, taper, z) -> np.ndarray:
    """Radius at distance z along a stem of base radius r0 (the paper's nTaper profile).

    taper in [0, 1): cone to cylinder; [1, 2): spherical end; [2, 3): periodic (beads).
    """
    r0, length, taper, z = np.broadcast_arrays(
        np.asarray(r0, float), np.asarray(length, float), np.asarray(taper, float), np.asarray(z, float)
    )
    Z = np.clip(z / np.maximum(length, 1e-12), 0.0, 1.0)
    unit = np.where(taper < 1.0, taper, np.where(taper < 2.0, 2.0 - taper, 0.0))
    taper_z = r0 * (1.0 - unit * Z)
    Z2 = (1.0 - Z) * length
    depth = np.where((taper < 2.0) | (Z2 < taper_z), 1.0, taper - 2.0)
    period = np.maximum(2.0 * taper_z, 1e-12)
    Z3 = np.where(taper < 2.0, Z2, np.abs(Z2 - period * np.floor(Z2 / period + 0.5)))
    sphere = np.sqrt(np.clip(taper_z**2 - (Z3 - taper_z) ** 2, 0.0, None))
    rounded = np.where((taper < 2.0) & (Z3 >= taper_z), taper_z, (1.0 - depth) * taper_z + depth * sphere)
    out = np.where(taper < 1.0, taper_z, rounded)
    # A stem never ends in a zero-width point: keep a sliver so radii stay positive.
    return np.maximum(out, 1e-3 * r0)


def flare_factor(flare: float, Z) -> np.ndarray:
    """Trunk flare multiplier at relative height Z: 1 + Flare·(100^y − 1)/100, y = max(0, 1 − 8Z)."""
    y = np.clip(1.0 - 8.0 * np.asarray(Z, float), 0.0, None)
    return 1.0 + flare * (np.power(100.0, y) - 1.0) / 100.0
