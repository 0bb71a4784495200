"""The parameter table: every file key, the Params field it sets, its type and legal range.

Both readers look keys up here (case-insensitively, with the seed paper's aliases), and an
unknown key gets the closest real name as a suggestion; the writer walks the same table.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass

from .colors import COLOR_FORMAT
from .record import LEVEL_SLOTS, MAX_LEVELS

INF = math.inf

# LeafShape codes. Arbaro's files name shapes ("disc1", "sphere", "palm"); treegen stores an
# integer code and leafshapes.py draws the outline for each code.
#
# | code | names accepted            | outline (drawn by leafshapes.py)                       |
# |------|---------------------------|--------------------------------------------------------|
# | 0    | 0, disc, oval, ellipse,   | elliptic blade, the Weber–Penn / Arbaro default        |
# |      | disc4 … disc9             | (Arbaro's disc4+ are finer ovals: same outline here)   |
# | 1    | disc1                     | 1 triangle: cheapest needle (Arbaro's european_larch)  |
# | 2    | disc2                     | 2 triangles, a thin diamond (Arbaro's weeping_willow)  |
# | 3    | disc3                     | 3 triangles (coarse oval)                              |
# | 4    | square, rectangle         | full rectangle (the leaf card itself)                  |
# | 5    | sphere                    | a small closed blob: seeds, knots, needles seen all-round |
# | 6    | palm                      | two half-discs folded along the midrib (palm fronds)   |
# | 7    | star                      | star-shaped (palmate) outline                          |
LEAF_SHAPES: dict[str, int] = {
    "disc": 0,
    "oval": 0,
    "ellipse": 0,
    "disc1": 1,
    "disc2": 2,
    "disc3": 3,
    "disc4": 0,
    "disc5": 0,
    "disc6": 0,
    "disc7": 0,
    "disc8": 0,
    "disc9": 0,
    "square": 4,
    "rectangle": 4,
    "sphere": 5,
    "palm": 6,
    "star": 7,
}
LEAF_SHAPE_NAMES: dict[int, str] = {
    0: "disc",
    1: "disc1",
    2: "disc2",
    3: "disc3",
    4: "square",
    5: "sphere",
    6: "palm",
    7: "star",
}
MAX_LEAF_SHAPE = 7


@dataclass(frozen=True)
class KeySpec:
    """One file key: where it goes in Params, its type and its legal range."""

    key: str  # canonical spelling; per-level keys without the digit ("DownAngle")
    field: str  # Params / LevelParams attribute
    kind: type  # int or float
    lo: float = -INF
    hi: float = INF
    lo_open: bool = False
    hi_open: bool = False
    per_level: bool = False  # kind str: a colour (6 hex digits, see _color)

    def contains(self, v: float) -> bool:
        if v < self.lo or (self.lo_open and v == self.lo):
            return False
        if v > self.hi or (self.hi_open and v == self.hi):
            return False
        return True

    def range_text(self) -> str:
        """The legal range in interval notation, e.g. '[-180, 180]', '(0, 1]', '[0, inf)'."""
        if self.kind is str:
            return COLOR_FORMAT

        def num(x: float) -> str:
            if math.isinf(x):
                return "inf" if x > 0 else "-inf"
            return str(int(x)) if float(x).is_integer() else repr(float(x))

        left = "(" if self.lo_open or math.isinf(self.lo) else "["
        right = ")" if self.hi_open or math.isinf(self.hi) else "]"
        return f"{left}{num(self.lo)}, {num(self.hi)}{right}"


def _k(key, field_, kind, lo=-INF, hi=INF, lo_open=False, hi_open=False):
    return KeySpec(key, field_, kind, lo, hi, lo_open, hi_open, per_level=False)


def _c(key, field_):
    """A colour key: 6 hex digits of sRGB in the file, linear RGB in Params."""
    return KeySpec(key, field_, str)


def _n(key, field_, kind, lo=-INF, hi=INF, lo_open=False, hi_open=False):
    return KeySpec(key, field_, kind, lo, hi, lo_open, hi_open, per_level=True)


# Ranges: Arbaro's own limits where it has them, widened where real files or the paper need
# it (nLength 0 on the paper's leaf level, PruneWidth > 1 for crowns wider than tall).
# Angles in degrees. Infinite bounds still require a finite number.
TOP_KEYS: tuple[KeySpec, ...] = (
    _k("Shape", "shape", int, 0, 8),
    _k("BaseSize", "base_size", float, 0, 1),
    _k("Scale", "scale", float, 0, INF, lo_open=True),
    _k("ScaleV", "scale_v", float, 0, INF),
    _k("Levels", "levels", int, 0, MAX_LEVELS),
    _k("Ratio", "ratio", float, 0, INF, lo_open=True),
    _k("RatioPower", "ratio_power", float),
    _k("Lobes", "lobes", int, 0, 1000),
    _k("LobeDepth", "lobe_depth", float, 0, INF),
    _k("Flare", "flare", float, -1, INF),
    _k("0Scale", "scale0", float, 0, INF, lo_open=True),
    _k("0ScaleV", "scale0_v", float, 0, INF),
    _k("0BaseSplits", "base_splits", int, 0, 1000),
    _k("Leaves", "leaves", float),  # negative: a fan at the stem tip
    _k("LeafShape", "leaf_shape", int, 0, MAX_LEAF_SHAPE),
    _k("LeafScale", "leaf_scale", float, 0, INF, lo_open=True),
    _k("LeafScaleX", "leaf_scale_x", float, 0, INF, lo_open=True),
    _k("LeafQuality", "leaf_quality", float, 0, 1, lo_open=True),
    _k("LeafBend", "leaf_bend", float, 0, 1),
    _k("LeafDistrib", "leaf_distrib", int, 0, 8),
    _k("LeafStemLen", "leaf_stem_len", float),  # Arbaro allows negative
    _k("AttractionUp", "attraction_up", float),  # negative: droop (willow)
    _k("PruneRatio", "prune_ratio", float, 0, 1),
    _k("PruneWidth", "prune_width", float, 0, INF),
    _k("PruneWidthPeak", "prune_width_peak", float, 0, 1),
    _k("PrunePowerLow", "prune_power_low", float, 0, INF),
    _k("PrunePowerHigh", "prune_power_high", float, 0, INF),
    _k("Smooth", "smooth", float, 0, 1),
    _c("LeafColor", "leaf_color"),
    _c("BarkColor", "bark_color"),
)

LEVEL_KEYS: tuple[KeySpec, ...] = (
    _n("Length", "length", float, 0, INF),
    _n("LengthV", "length_v", float, 0, INF),
    _n("Taper", "taper", float, 0, 3, hi_open=True),
    _n("SegSplits", "seg_splits", float, 0, 10),
    _n("SplitAngle", "split_angle", float, 0, 180),
    _n("SplitAngleV", "split_angle_v", float, 0, 180),
    _n("CurveRes", "curve_res", int, 1, 100),
    _n("Curve", "curve", float),
    _n("CurveBack", "curve_back", float),
    _n("CurveV", "curve_v", float, -90, INF),  # negative: helix
    _n("DownAngle", "down_angle", float, -180, 180),
    _n("DownAngleV", "down_angle_v", float, -180, 180),  # negative: varies along the parent
    _n("Rotate", "rotate", float, -360, 360),  # negative: alternating / whorled
    _n("RotateV", "rotate_v", float, -360, 360),
    _n("Branches", "branches", float, 0, INF),
    _n("BranchDist", "branch_dist", float, 0, 1),
)

# What a Weber–Penn text file must list (params/assemble.py refuses a file missing any): the
# paper's own parameter table, for the levels the tree grows. Optional, as keys beyond the paper:
# Arbaro's LeafQuality, LeafBend, LeafDistrib, LeafStemLen, Smooth and nBranchDist, Arbaro's
# level-0 DownAngle/Rotate/Branches (several trunks), and treegen's LeafColor/BarkColor; a file
# leaving them out gets Arbaro's (or the species') defaults. Arbaro XML files stay partial.
OPTIONAL_TOP = frozenset(
    {"LeafQuality", "LeafBend", "LeafDistrib", "LeafStemLen", "Smooth", "LeafColor", "BarkColor"}
)
TRUNK_KEYS = (
    "Length",
    "LengthV",
    "Taper",
    "SegSplits",
    "SplitAngle",
    "SplitAngleV",
    "CurveRes",
    "Curve",
    "CurveBack",
    "CurveV",
)
LEAF_LEVEL_KEYS = ("DownAngle", "DownAngleV", "Rotate", "RotateV")  # orient the leaves


def required_keys(levels: int, leaves: float) -> list[str]:
    """The keys a text file must list for a tree of `levels` stem levels and `leaves` Leaves, in
    the writer's order: top-level keys, the trunk's, every key of stem levels 1..levels-1, and
    the leaf level's angles when there are leaves (level `levels`; no leaves grow at Levels 0)."""
    keys = [s.key for s in TOP_KEYS if s.key not in OPTIONAL_TOP]
    keys += [f"0{k}" for k in TRUNK_KEYS]
    for n in range(1, levels):
        keys += [f"{n}{s.key}" for s in LEVEL_KEYS if s.key != "BranchDist"]
    if levels >= 1 and leaves != 0:
        keys += [f"{levels}{k}" for k in LEAF_LEVEL_KEYS]
    return keys


# The seed paper's (Kondo et al.) spellings of per-level keys.
LEVEL_ALIASES: dict[str, str] = {
    "CurveResolution": "CurveRes",
    "BranchLength": "Length",
    "AngleDown": "DownAngle",
    "AngleRotate": "Rotate",
}
NAME_KEYS = ("Name", "Species")

_TOP_BY_LOWER = {s.key.lower(): s for s in TOP_KEYS}
_LEVEL_BY_LOWER = {s.key.lower(): s for s in LEVEL_KEYS}
_LEVEL_BY_LOWER.update({a.lower(): _LEVEL_BY_LOWER[k.lower()] for a, k in LEVEL_ALIASES.items()})
_LEVEL_RE = re.compile(r"^(\d+)([A-Za-z]+)$")


def _all_key_names() -> list[str]:
    names = [s.key for s in TOP_KEYS] + list(NAME_KEYS)
    for n in range(LEVEL_SLOTS):
        names += [f"{n}{s.key}" for s in LEVEL_KEYS]
        names += [f"{n}{a}" for a in LEVEL_ALIASES]
    return names


_ALL_KEYS = _all_key_names()
_ALL_KEYS_LOWER = {k.lower(): k for k in _ALL_KEYS}


def suggest(key: str) -> str:
    """' (did you mean X?)' for the closest real key name, or ''."""
    if len(key) > 40:
        return ""
    low = key.lower()
    m = _LEVEL_RE.match(key)
    if m is None and low in _LEVEL_BY_LOWER:
        return f" (per-level keys need a level digit, e.g. 1{_LEVEL_BY_LOWER[low].key})"
    pool = list(_ALL_KEYS_LOWER)
    if m is not None and m.group(1).isdigit() and len(m.group(1)) == 1:
        # Prefer names on the same level, then anything.
        pool = [k for k in pool if k.startswith(m.group(1))] + pool
    hit = difflib.get_close_matches(low, pool, n=1, cutoff=0.6)
    return f" (did you mean {_ALL_KEYS_LOWER[hit[0]]}?)" if hit else ""


def lookup(key: str) -> tuple[KeySpec, int | None, str] | None:
    """(spec, level or None, canonical key) for a file key, case-insensitively; None if unknown."""
    low = key.lower()
    if low in _TOP_BY_LOWER:
        s = _TOP_BY_LOWER[low]
        return s, None, s.key
    m = _LEVEL_RE.match(key)
    if m is not None and m.group(2).lower() in _LEVEL_BY_LOWER:
        s = _LEVEL_BY_LOWER[m.group(2).lower()]
        n = int(m.group(1))
        return s, n, f"{n}{s.key}"
    return None
