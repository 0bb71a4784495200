"""Random draws and whole counts, shared by every growth step.

Randomness: one `numpy.random.Generator` per (seed, level, purpose), the purposes below, so
pruning can regrow a level with exactly the same random draws and nothing touches the global RNG.
"""

from __future__ import annotations

import numpy as np

# the purposes of the random streams: np.random.default_rng([seed, level, purpose])
GROW, CHILDREN, LEAVES, TREE = 1, 2, 3, 4


def error_diffuse(values: np.ndarray) -> np.ndarray:
    """Whole counts whose running sum tracks the running sum of fractional `values`.

    Result: (0.4, 0.4, 0.4, 0.4, 0.4) → (0, 1, 0, 1, 0). One accumulator, in array order.
    """
    values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    total = np.floor(np.cumsum(values) + 0.5)
    return np.diff(total, prepend=0.0).astype(np.int64)


def vary(rng: np.random.Generator, value: float, variation: float, n: int) -> np.ndarray:
    """A size drawn from value ± variation that stays positive: when the variation exceeds the
    value (ScaleV > Scale is legal), draws below a tenth of the value are folded up to it."""
    lo = max(value - abs(variation), 0.1 * value)
    hi = max(value + abs(variation), lo)
    return rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo)


def deviation(rng: np.random.Generator, n, variation) -> np.ndarray:
    """value ± variation: a uniform draw in [−variation, variation] per element."""
    return rng.uniform(-1.0, 1.0, n) * variation
