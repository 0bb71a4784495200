"""Weber–Penn species parameters: the immutable `Params` record, its defaults, and the readers.

Field names follow the paper in snake_case (`down_angle`, `curve_res`, `shape_ratio`); the
file keys are the Weber–Penn / Arbaro names (`1DownAngle`, `0CurveRes`, `Shape`).
Defaults for absent keys follow Arbaro; the file's own values always win.
"""
from __future__ import annotations

from dataclasses import dataclass, field

MAX_LEVELS = 9          # Levels may be 0..MAX_LEVELS
LEVEL_SLOTS = MAX_LEVELS + 1  # per-level values exist for levels 0..MAX_LEVELS


@dataclass(frozen=True)
class LevelParams:
    """Per-level values (the `n` prefix of the Weber–Penn names)."""

    length: float = 0.5          # nLength
    length_v: float = 0.0        # nLengthV
    taper: float = 1.0           # nTaper, [0, 3)
    seg_splits: float = 0.0      # nSegSplits (0BaseSplits is Params.base_splits)
    split_angle: float = 0.0     # nSplitAngle, degrees
    split_angle_v: float = 0.0   # nSplitAngleV
    curve_res: int = 3           # nCurveRes, segments per stem
    curve: float = 0.0           # nCurve, degrees
    curve_back: float = 0.0      # nCurveBack
    curve_v: float = 0.0         # nCurveV (negative: helix)
    down_angle: float = 0.0      # nDownAngle, degrees
    down_angle_v: float = 0.0    # nDownAngleV (negative: varies along the parent)
    rotate: float = 0.0          # nRotate (negative: alternating / whorled)
    rotate_v: float = 0.0        # nRotateV
    branches: float = 0.0        # nBranches
    branch_dist: float = 0.0     # nBranchDist (Arbaro; 0 = evenly spread)


@dataclass(frozen=True)
class Params:
    """One species, validated. `level[n]` holds the `n`-prefixed values for level n."""

    name: str = "tree"
    shape: int = 0               # Shape, 0..8
    base_size: float = 0.25      # BaseSize, fraction of the trunk without branches
    scale: float = 10.0          # Scale, metres
    scale_v: float = 0.0         # ScaleV
    levels: int = 3              # Levels: stem levels (trunk = 0); leaves grow on the last
    ratio: float = 0.05          # Ratio: trunk radius / length
    ratio_power: float = 1.0     # RatioPower
    lobes: int = 0               # Lobes
    lobe_depth: float = 0.0      # LobeDepth
    flare: float = 0.5           # Flare
    scale0: float = 1.0          # 0Scale: trunk radius scale
    scale0_v: float = 0.0        # 0ScaleV
    base_splits: int = 0         # 0BaseSplits
    leaves: float = 0.0          # Leaves per stem (negative: a fan at the stem tip)
    leaf_shape: int = 0          # LeafShape (see leafshapes.py)
    leaf_scale: float = 0.2      # LeafScale, metres
    leaf_scale_x: float = 0.5    # LeafScaleX, width / length
    leaf_quality: float = 1.0    # LeafQuality, (0, 1]
    leaf_bend: float = 0.3       # LeafBend (Arbaro), 0..1
    leaf_distrib: int = 4        # LeafDistrib (Arbaro): shape used for leaf counts along a stem
    leaf_stem_len: float = 0.5   # LeafStemLen (Arbaro): petiole length / leaf length
    attraction_up: float = 0.0   # AttractionUp
    prune_ratio: float = 0.0     # PruneRatio, 0..1
    prune_width: float = 0.5     # PruneWidth
    prune_width_peak: float = 0.5  # PruneWidthPeak
    prune_power_low: float = 0.5   # PrunePowerLow
    prune_power_high: float = 0.5  # PrunePowerHigh
    smooth: float = 0.5          # Smooth (Arbaro mesh smoothness), 0..1
    level: tuple[LevelParams, ...] = field(
        default_factory=lambda: tuple(LevelParams() for _ in range(LEVEL_SLOTS))
    )
