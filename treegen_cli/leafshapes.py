"""Leaf blade outlines (LeafShape) — placeholder contract, replaced by mesh work."""
from __future__ import annotations


def fill_factor(leaf_shape: int) -> float:
    """Blade area / (length × width) for the outline `leaf_shape` draws."""
    return 1.0
