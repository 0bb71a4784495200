"""Weber–Penn species parameters: the immutable `Params` record, its defaults, and the readers.

Field names follow the paper in snake_case (`down_angle`, `curve_res`, `shape_ratio`); the
file keys are the Weber–Penn / Arbaro names (`1DownAngle`, `0CurveRes`, `Shape`).
Defaults for absent keys follow Arbaro; the file's own values always win.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from xml.parsers import expat

from .errors import TreegenError

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


# ---------------------------------------------------------------------------------------------
# Readers: key table, text format, Arbaro XML, writer.
#
# Everything below turns a species file into a validated `Params` or a one-line TreegenError
# naming file, line, key and allowed range. The dataclasses above are the shared contract;
# nothing below changes their meaning.
# ---------------------------------------------------------------------------------------------

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

# Colours: what artists copy from an image editor (sRGB bytes), without '#', which starts a
# comment in the text format (Arbaro XML values may keep it). Params holds linear RGB, the
# space textures and materials compute in; the exact sRGB curve makes the writer round-trip.
COLOR_FORMAT = "6 hex digits rrggbb, sRGB, e.g. 5a7a2e"
_HEX_RE = re.compile(r"^#?([0-9A-Fa-f]{6})$")


def srgb_hex_to_linear(text: str) -> tuple[float, float, float]:
    """'5a7a2e' → linear RGB floats (the sRGB transfer curve, exactly)."""
    m = _HEX_RE.match(text.strip())
    if m is None:
        raise ValueError(f"{text!r} is not {COLOR_FORMAT}")
    out = []
    for i in range(0, 6, 2):
        x = int(m.group(1)[i : i + 2], 16) / 255.0
        out.append(x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4)
    return tuple(out)


def linear_to_srgb_hex(rgb) -> str:
    """Linear RGB floats → 'rrggbb' (inverse of srgb_hex_to_linear on its outputs)."""
    out = ""
    for c in rgb:
        c = min(max(float(c), 0.0), 1.0)
        x = 12.92 * c if c <= 0.0031308 else 1.055 * c ** (1 / 2.4) - 0.055
        out += f"{int(round(x * 255.0)):02x}"
    return out


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


# ------------------------------------------------------------------------------ key lookup


def _all_key_names() -> list[str]:
    names = [s.key for s in TOP_KEYS] + list(NAME_KEYS)
    for n in range(LEVEL_SLOTS):
        names += [f"{n}{s.key}" for s in LEVEL_KEYS]
        names += [f"{n}{a}" for a in LEVEL_ALIASES]
    return names


_ALL_KEYS = _all_key_names()
_ALL_KEYS_LOWER = {k.lower(): k for k in _ALL_KEYS}


def _suggest(key: str) -> str:
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


def _lookup(key: str) -> tuple[KeySpec, int | None, str] | None:
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


# ------------------------------------------------------------------------------ assembling


@dataclass
class _Entry:
    key: str  # as written in the file
    value: str  # as written in the file
    line: int | None  # 1-based, None if unknown


def _printable(text: str) -> str:
    """Escape control characters so an error stays one readable terminal line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _clip(text: str, limit: int = 40) -> str:
    """Shorten file text quoted in an error message."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Builder:
    """Collects entries from either reader, then validates all of them at once."""

    def __init__(self, source: str):
        self.source = source
        self.name: str | None = None
        self.name_line: int | None = None
        self.entries: list[_Entry] = []

    def where(self, line: int | None) -> str:
        return f"{self.source}:{line}" if line is not None else self.source

    def fail(self, line: int | None, msg: str) -> TreegenError:
        return TreegenError(f"{self.where(line)}: {_printable(msg)}")

    def set_name(self, value: str, line: int | None, key: str = "Name") -> None:
        value = value.strip()
        if self.name is not None:
            raise self.fail(line, f"duplicate key {key} (first set on line {self.name_line})")
        if not value or not value.isprintable() or "#" in value:
            raise self.fail(
                line,
                f"{key} = {_clip(value)!r} must be a non-empty one-line name "
                f"without '#' (the text format's comment sign)",
            )
        self.name, self.name_line = value, line

    def add(self, key: str, value: str, line: int | None) -> None:
        if key.lower() in ("name", "species"):
            self.set_name(value, line, key)
        else:
            self.entries.append(_Entry(key, value, line))

    def _number(self, spec: KeySpec, canon: str, e: _Entry) -> int | float | tuple:
        raw = e.value.strip()
        shown = _clip(raw)
        if spec.kind is str:
            try:
                return srgb_hex_to_linear(raw)
            except ValueError:
                raise self.fail(e.line, f"{canon} = {shown!r} is not a colour ({COLOR_FORMAT})") from None
        if spec.field == "leaf_shape" and raw.lower() in LEAF_SHAPES:
            return LEAF_SHAPES[raw.lower()]
        rng = spec.range_text()
        try:
            v = float(raw)
        except ValueError:
            if spec.field == "leaf_shape":
                allowed = ", ".join(sorted(set(LEAF_SHAPES) - {f"disc{i}" for i in range(4, 10)}))
                raise self.fail(
                    e.line, f"{canon} = {shown!r} is not a leaf shape (a code in {rng} or one of: {allowed})"
                ) from None
            raise self.fail(e.line, f"{canon} = {shown!r} is not a number (allowed range {rng})") from None
        if not math.isfinite(v):
            raise self.fail(e.line, f"{canon} = {shown} is not a finite number (allowed range {rng})")
        if not spec.contains(v):
            raise self.fail(e.line, f"{canon} = {shown} is out of range {rng}")
        if spec.kind is int:
            if not v.is_integer():
                raise self.fail(e.line, f"{canon} = {shown} must be a whole number in {rng}")
            return int(v)
        return v

    def build(self, default_name: str) -> Params:
        if not self.entries and self.name is None:
            raise self.fail(1, "empty species file: no parameters found")
        top: dict[str, int | float] = {}
        per_level: list[dict[str, int | float]] = [{} for _ in range(LEVEL_SLOTS)]
        seen: dict[tuple[str, int | None], _Entry] = {}
        level_refs: list[tuple[int, str, _Entry]] = []
        for e in self.entries:
            found = _lookup(e.key)
            if found is None:
                raise self.fail(e.line, f"unknown key {_clip(e.key)}{_suggest(e.key)}")
            spec, n, canon = found
            ident = (spec.key, n)
            if ident in seen:
                first = seen[ident]
                was = f" as {first.key}" if first.key != e.key else ""
                at = f"line {first.line}" if first.line is not None else "earlier"
                raise self.fail(e.line, f"duplicate key {e.key}: {canon} already set on {at}{was}")
            seen[ident] = e
            if n is not None and n > MAX_LEVELS:
                raise self.fail(
                    e.line,
                    f"{canon}: level {n} is beyond the last level "
                    f"{MAX_LEVELS} (Levels is at most {MAX_LEVELS})",
                )
            value = self._number(spec, canon, e)
            if n is None:
                top[spec.field] = value
            else:
                per_level[n][spec.field] = value
                level_refs.append((n, canon, e))
        levels = int(top.get("levels", Params.levels))
        for n, canon, e in level_refs:
            if n > levels:
                raise self.fail(
                    e.line,
                    f"{canon}: level {n} is beyond Levels = {levels} "
                    f"(level keys may use 0..{levels}; level {levels} "
                    f"holds the leaves' DownAngle/Rotate)",
                )
        slots: list[LevelParams] = []
        for n in range(LEVEL_SLOTS):
            base = arbaro_level_defaults(n) if n <= 3 else slots[n - 1]
            slots.append(replace(base, **per_level[n]))
        name = self.name if self.name is not None else default_name
        return replace(default_params(name), **top, level=tuple(slots))


def _default_name(source: str) -> str:
    if source.startswith("<"):
        return "tree"
    return Path(source).stem or "tree"


# ------------------------------------------------------------------------------ text format


def parse_params_text(text: str, source: str = "<string>") -> Params:
    """Parse the plain text species format: `Key value` or `Key = value`, `#` comments."""
    b = _Builder(source)
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise b.fail(line, "binary data (NUL byte): not a species text file")
    # Lines are counted by "\n" only, as editors do (str.splitlines also splits on \f, \v, ...).
    for lineno, raw in enumerate(text.split("\n"), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if "=" in line:
            key, _, value = line.partition("=")
        else:
            key, value = (line.split(None, 1) + [""])[:2]
        key, value = key.strip(), value.strip()
        if not key or any(c.isspace() for c in key):
            raise b.fail(lineno, f"expected 'Key value' or 'Key = value', got {_clip(raw.strip())!r}")
        if key.lower() in ("name", "species"):
            b.set_name(value, lineno, key)
            continue
        found = _lookup(key)
        if found is None:
            raise b.fail(lineno, f"unknown key {_clip(key)}{_suggest(key)}")
        if not value:
            if found[0].kind is str:
                raise b.fail(
                    lineno,
                    f"{key} has no value ({COLOR_FORMAT}; write it without '#', which starts a comment)",
                )
            raise b.fail(lineno, f"{key} has no value (allowed range {found[0].range_text()})")
        if len(value.split()) > 1:
            raise b.fail(lineno, f"{key} = {_clip(value)!r}: expected one value, got {len(value.split())}")
        b.add(key, value, lineno)
    return b.build(_default_name(source))


# ------------------------------------------------------------------------------ Arbaro XML


class _Refused(Exception):
    """Raised inside expat callbacks; turned into a TreegenError by the caller."""


def parse_params_xml(data: str | bytes, source: str = "<string>") -> Params:
    """Read an Arbaro species file (`<arbaro><species name=..><param name=.. value=../>`).

    Uses expat directly (as ElementTree does) to keep each param's line number. DOCTYPE and
    ENTITY declarations are refused outright: no entity expansion, no external resources.
    """
    b = _Builder(source)
    p = expat.ParserCreate()
    p.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[str] = []
    species_count = 0

    def refuse(msg: str):
        raise _Refused(f"{b.where(p.CurrentLineNumber)}: {_printable(_clip(msg, 200))}")

    def start(tag: str, attrs: dict[str, str]):
        nonlocal species_count
        line = p.CurrentLineNumber
        if not stack and tag != "arbaro":
            refuse(f"root element is <{tag}>, expected <arbaro> (an Arbaro species file)")
        if tag == "species":
            species_count += 1
            if species_count > 1:
                refuse("more than one <species>; treegen reads one species per file")
            if "name" in attrs:
                b.set_name(attrs["name"], line, "species name")
        elif tag == "param":
            if "species" not in stack:
                refuse("<param> outside <species>")
            if "name" not in attrs or "value" not in attrs:
                missing = "name" if "name" not in attrs else "value"
                what = attrs.get("name", "")
                refuse(f"<param{' ' + what if what else ''}> has no {missing}= attribute")
            b.add(attrs["name"], attrs["value"], line)
        stack.append(tag)

    def end(tag: str):
        stack.pop()

    def doctype(*_args):
        refuse("DOCTYPE declarations are not allowed in species files (entity expansion risk)")

    def entity(*_args):
        refuse("ENTITY declarations are not allowed in species files")

    p.StartElementHandler = start
    p.EndElementHandler = end
    p.StartDoctypeDeclHandler = doctype
    p.EntityDeclHandler = entity
    p.ExternalEntityRefHandler = lambda *a: refuse("external entities are not allowed")
    try:
        p.Parse(data, True)
    except _Refused as exc:
        raise TreegenError(str(exc)) from None
    except expat.ExpatError as exc:
        raise TreegenError(
            f"{source}:{exc.lineno}:{exc.offset + 1}: malformed XML: {expat.ErrorString(exc.code)}"
        ) from None
    except TreegenError:
        raise
    except (ValueError, UnicodeError, LookupError) as exc:  # e.g. unknown encoding declaration
        raise TreegenError(f"{source}: unreadable XML: {_printable(_clip(str(exc), 200))}") from None
    if species_count == 0:
        raise b.fail(None, "no <species> element: not an Arbaro species file")
    return b.build(_default_name(source))


# ------------------------------------------------------------------------------ dispatch


def _looks_xml(text: str) -> bool:
    return text.lstrip("\ufeff \t\r\n").startswith("<")


def parse_params_bytes(data: bytes, source: str = "<string>") -> Params:
    """Parse a species file's raw bytes: Arbaro XML if it starts with '<', else text."""
    if b"\x00" in data:
        line = data.count(b"\n", 0, data.index(b"\x00")) + 1
        raise TreegenError(f"{source}:{line}: binary data (NUL byte): not a species file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if data.lstrip().startswith(b"<?xml") and b"encoding" in data[:200]:
            return parse_params_xml(data, source)  # declared non-UTF-8 encoding: expat decodes
        line = data.count(b"\n", 0, exc.start) + 1
        raise TreegenError(
            f"{source}:{line}: not UTF-8 text (byte 0x{data[exc.start]:02x} "
            f"at offset {exc.start}): binary file?"
        ) from None
    if not text.strip():
        raise TreegenError(f"{source}:1: empty species file: no parameters found")
    if _looks_xml(text):
        return parse_params_xml(data, source)
    return parse_params_text(text, source)


def load_params(path: str | Path) -> Params:
    """Read and validate one species file (text or Arbaro XML, decided by content)."""
    p = Path(path)
    source = str(path)
    if p.is_dir():
        raise TreegenError(f"{source}: is a directory, expected a species file")
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise TreegenError(f"{source}: no such species file") from None
    except OSError as exc:
        raise TreegenError(f"{source}: cannot read species file: {exc.strerror or exc}") from None
    return parse_params_bytes(data, source)


# ------------------------------------------------------------------------------ output


def _fmt(v: int | float | str) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        raise TypeError("bool is not a parameter value")
    if isinstance(v, int):
        return str(v)
    return repr(float(v))  # shortest text that reads back to the same float


def params_dict(params: Params) -> dict[str, object]:
    """Canonical `{key: value}` of a Params: Name, top-level keys, then level keys 0..Levels.

    Levels above `Levels` are left out: no file can set them (they repeat Arbaro's defaults
    or level 3). Colours are 'rrggbb' text, None when unset (the species default applies).
    Used by `treegen info --json` and by the writer.
    """
    out: dict[str, object] = {"Name": params.name}
    for s in TOP_KEYS:
        v = getattr(params, s.field)
        out[s.key] = linear_to_srgb_hex(v) if s.kind is str and v is not None else v
    for n in range(min(params.levels, MAX_LEVELS) + 1):
        lp = params.level[n]
        for s in LEVEL_KEYS:
            out[f"{n}{s.key}"] = getattr(lp, s.field)
    return out


def format_params_text(params: Params, header: str | None = None) -> str:
    """Write Params in the text format; `parse_params_text` of the result gives them back."""
    d = params_dict(params)
    lines = [f"# {ln}" if ln else "#" for ln in (header or "").splitlines()]
    lines.append(f"Name {d.pop('Name')}")
    width = max(len(k) for k in d)
    current = None
    for key, value in d.items():
        if value is None:  # an unset colour: the species default
            continue
        group = key[0] if key[0].isdigit() and key not in ("0Scale", "0ScaleV", "0BaseSplits") else ""
        if group != current:
            lines.append("")
            lines.append(f"# level {group}" if group else "# tree")
            current = group
        text = _fmt(value)
        if key == "LeafShape":
            text += f"    # {LEAF_SHAPE_NAMES.get(int(value), '?')}"
        lines.append(f"{key:<{width}} {text}")
    return "\n".join(lines) + "\n"
