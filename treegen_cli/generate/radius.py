"""Stem radii (the paper's "stem radius" and "taper"): at the base, then along the stem.

A trunk's base radius is its length × Ratio × 0Scale; a child's is its parent's scaled by
(length / parent length)^RatioPower, never thicker than the parent where it attaches. Along a
stem the radius follows nTaper (shapes.taper_radius), and the trunk also flares at its foot.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shapes import flare_factor, taper_radius
from .draws import vary


def trunk_radius(p: Params, rng: np.random.Generator, length: np.ndarray) -> np.ndarray:
    """Base radius of each trunk: length × Ratio × (0Scale ± 0ScaleV)."""
    return length * p.ratio * vary(rng, p.scale0, p.scale0_v, length.shape[0])


def child_radius(
    p: Params, parent_radius: np.ndarray, length: np.ndarray, parent_length: np.ndarray, at_attach
) -> np.ndarray:
    """Base radius of child stems: the parent's × (length / parent length)^RatioPower, at most
    the parent's radius `at_attach` where the child starts."""
    radius = parent_radius * (length / np.maximum(parent_length, 1e-12)) ** p.ratio_power
    return np.minimum(radius, at_attach)


def node_radius(p: Params, level: int, radius: np.ndarray, length: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Radius at distance z along stems of base `radius` and `length`: nTaper, and on the
    trunk (level 0) Flare."""
    r = taper_radius(radius, length, p.level[level].taper, z)
    if level == 0:
        r = r * flare_factor(p.flare, z / np.maximum(length, 1e-12))
    return r
