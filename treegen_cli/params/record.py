"""The immutable `Params` record of one species, and Arbaro's defaults for absent keys.

Field names follow the paper in snake_case (`down_angle`, `curve_res`, `shape_ratio`); the
file keys (keys.py) are the Weber–Penn / Arbaro names (`1DownAngle`, `0CurveRes`, `Shape`).
This is the shared contract of the readers and the generator; nothing else here reads files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_LEVELS = 9  # Levels may be 0..MAX_LEVELS
LEVEL_SLOTS = MAX_LEVELS + 1  # per-level values exist for levels 0..MAX_LEVELS


@dataclass(frozen=True)
class LevelParams:
    """Per-level values (the `n` prefix of the Weber–Penn names)."""

    length: float = 0.5  # nLength
    length_v: float = 0.0  # nLengthV
    taper: float = 1.0  # nTaper, [0, 3)
    seg_splits: float = 0.0  # nSegSplits (0BaseSplits is Params.base_splits)
    split_angle: float = 0.0  # nSplitAngle, degrees
    split_angle_v: float = 0.0  # nSplitAngleV
    curve_res: int = 3  # nCurveRes, segments per stem
    curve: float = 0.0  # nCurve, degrees
    curve_back: float = 0.0  # nCurveBack
    curve_v: float = 0.0  # nCurveV (negative: helix)
    down_angle: float = 0.0  # nDownAngle, degrees
    down_angle_v: float = 0.0  # nDownAngleV (negative: varies along the parent)
    rotate: float = 0.0  # nRotate (negative: alternating / whorled)
    rotate_v: float = 0.0  # nRotateV
    branches: float = 0.0  # nBranches
    branch_dist: float = 0.0  # nBranchDist (Arbaro; 0 = evenly spread)


@dataclass(frozen=True)
class Params:
    """One species, validated. `level[n]` holds the `n`-prefixed values for level n."""

    name: str = "tree"
    shape: int = 0  # Shape, 0..8
    base_size: float = 0.25  # BaseSize, fraction of the trunk without branches
    scale: float = 10.0  # Scale, metres
    scale_v: float = 0.0  # ScaleV
    levels: int = 3  # Levels: stem levels (trunk = 0); leaves grow on the last
    ratio: float = 0.05  # Ratio: trunk radius / length
    ratio_power: float = 1.0  # RatioPower
    lobes: int = 0  # Lobes
    lobe_depth: float = 0.0  # LobeDepth
    flare: float = 0.5  # Flare
    scale0: float = 1.0  # 0Scale: trunk radius scale
    scale0_v: float = 0.0  # 0ScaleV
    base_splits: int = 0  # 0BaseSplits
    leaves: float = 0.0  # Leaves per stem (negative: a fan at the stem tip)
    leaf_shape: int = 0  # LeafShape (see leafshapes.py)
    leaf_scale: float = 0.2  # LeafScale, metres
    leaf_scale_x: float = 0.5  # LeafScaleX, width / length
    leaf_quality: float = 1.0  # LeafQuality, (0, 1]
    leaf_bend: float = 0.3  # LeafBend (Arbaro), 0..1
    leaf_distrib: int = 4  # LeafDistrib (Arbaro): shape used for leaf counts along a stem
    leaf_stem_len: float = 0.5  # LeafStemLen (Arbaro): petiole length / leaf length
    attraction_up: float = 0.0  # AttractionUp
    prune_ratio: float = 0.0  # PruneRatio, 0..1
    prune_width: float = 0.5  # PruneWidth
    prune_width_peak: float = 0.5  # PruneWidthPeak
    prune_power_low: float = 0.5  # PrunePowerLow
    prune_power_high: float = 0.5  # PrunePowerHigh
    smooth: float = 0.5  # Smooth (Arbaro mesh smoothness), 0..1
    leaf_color: tuple[float, float, float] | None = None  # LeafColor rrggbb (sRGB in the file),
    bark_color: tuple[float, float, float] | None = None  # BarkColor; stored as linear RGB like
    # Material.base_color; None: the
    # species default (textures.species_colors)
    level: tuple[LevelParams, ...] = field(
        default_factory=lambda: tuple(LevelParams() for _ in range(LEVEL_SLOTS))
    )
    # (canonical key, line) of each key the file set: lets a refusal made later (an oversized
    # tree) name the line to edit. Not part of the species: equal Params may differ here.
    key_lines: tuple[tuple[str, int], ...] = field(default=(), compare=False, repr=False)

    def line_of(self, key: str) -> int | None:
        """The line of the species file that set `key` (canonical spelling), or None."""
        return dict(self.key_lines).get(key)


# Arbaro's per-level defaults for levels 0..3 (its LevelParams); level n > 3 repeats level 3,
# as Arbaro uses level 3's values for every deeper level.
_ARBARO_LEVEL_DEFAULTS: dict[str, tuple] = {
    "length": (1.0, 0.5, 0.5, 0.5),
    "curve_res": (3, 3, 1, 1),
    "down_angle": (0.0, 30.0, 30.0, 30.0),
    "rotate": (0.0, 120.0, 120.0, 120.0),
    "branches": (1.0, 10.0, 5.0, 5.0),
    "branch_dist": (0.0, 1.0, 1.0, 1.0),
}
_ARBARO_LEVEL_CONST = {
    "length_v": 0.0,
    "taper": 1.0,
    "seg_splits": 0.0,
    "split_angle": 0.0,
    "split_angle_v": 0.0,
    "curve": 0.0,
    "curve_back": 0.0,
    "curve_v": 0.0,
    "down_angle_v": 0.0,
    "rotate_v": 0.0,
}


def arbaro_level_defaults(n: int) -> LevelParams:
    """Values a level gets when the file says nothing about it (Arbaro's defaults)."""
    i = min(n, 3)
    return LevelParams(**{f: v[i] for f, v in _ARBARO_LEVEL_DEFAULTS.items()}, **_ARBARO_LEVEL_CONST)


def default_params(name: str = "tree") -> Params:
    """The Params a file with no keys would give: Arbaro's defaults for every key."""
    return Params(name=name, level=tuple(arbaro_level_defaults(n) for n in range(LEVEL_SLOTS)))
