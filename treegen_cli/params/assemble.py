"""Validation: the (key, value, line) entries either reader collected → a validated `Params`.

Every problem is a one-line TreegenError naming file, line, key and allowed range; all
entries are checked at once, after reading, so both formats share one set of rules.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import TreegenError
from .colors import COLOR_FORMAT, srgb_hex_to_linear
from .keys import LEAF_SHAPES, KeySpec, lookup, required_keys, suggest
from .record import LEVEL_SLOTS, MAX_LEVELS, LevelParams, Params, arbaro_level_defaults, default_params

# A number as Arbaro and the paper write one (ASCII digits, optional sign, fraction and
# exponent); nan and inf are read so that the message says they are not finite
NUMBER = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$|^(?i:[+-]?(?:nan|inf|infinity))$", re.ASCII)


@dataclass
class Entry:
    """One key and value as a reader found them, with its line for the errors."""

    key: str  # as written in the file
    value: str  # as written in the file
    line: int | None  # 1-based, None if unknown


def printable(text: str) -> str:
    """Escape control characters so an error stays one readable terminal line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def clip(text: str, limit: int = 40) -> str:
    """Shorten file text quoted in an error message."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Builder:
    """Collects entries from either reader, then validates all of them at once."""

    def __init__(self, source: str):
        self.source = source
        self.name: str | None = None
        self.name_line: int | None = None
        self.name_key = "Name"
        self.entries: list[Entry] = []

    def where(self, line: int | None) -> str:
        return f"{self.source}:{line}" if line is not None else self.source

    def fail(self, line: int | None, msg: str) -> TreegenError:
        return TreegenError(f"{self.where(line)}: {printable(msg)}")

    def set_name(self, value: str, line: int | None, key: str = "Name") -> None:
        value = value.strip()
        if self.name is not None:
            same = (
                "" if self.name_key == key else f" as {self.name_key}: {key} and {self.name_key} are one key"
            )
            raise self.fail(line, f"duplicate key {key} (first set on line {self.name_line}{same})")
        if not value or not value.isprintable() or "#" in value:
            raise self.fail(
                line,
                f"{key} = {clip(value)!r} must be a non-empty one-line name "
                f"without '#' (the text format's comment sign)",
            )
        self.name, self.name_line, self.name_key = value, line, key

    def add(self, key: str, value: str, line: int | None) -> None:
        if key.lower() in ("name", "species"):
            self.set_name(value, line, key)
        else:
            self.entries.append(Entry(key, value, line))

    def _number(self, spec: KeySpec, canon: str, e: Entry) -> int | float | tuple:
        raw = e.value.strip()
        shown = clip(raw)
        if spec.kind is str:
            try:
                return srgb_hex_to_linear(raw)
            except ValueError:
                raise self.fail(e.line, f"{canon} = {shown!r} is not a colour ({COLOR_FORMAT})") from None
        if spec.field == "leaf_shape" and raw.lower() in LEAF_SHAPES:
            return LEAF_SHAPES[raw.lower()]
        rng = spec.range_text()
        try:
            if not NUMBER.match(raw):  # float() also takes 13_0, full-width digits, "infinity"
                raise ValueError(raw)
            v = float(raw)
        except ValueError:
            if "\u2212" in raw or "\u2013" in raw:
                raise self.fail(
                    e.line,
                    f"{canon} = {shown!r} is not a number: type the minus sign as '-' (allowed range {rng})",
                ) from None
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

    def build(self, default_name: str, complete: bool = False) -> Params:
        """Validate every entry into Params; `complete`: refuse a file missing a key the
        text format requires (keys.required_keys)."""
        if not self.entries and self.name is None:
            raise self.fail(1, "empty species file: no parameters found")
        top: dict[str, int | float] = {}
        per_level: list[dict[str, int | float]] = [{} for _ in range(LEVEL_SLOTS)]
        seen: dict[tuple[str, int | None], Entry] = {}
        level_refs: list[tuple[int, str, Entry]] = []
        lines_seen: list[tuple[tuple[str, int | None], str, Entry]] = []
        for e in self.entries:
            found = lookup(e.key)
            if found is None:
                raise self.fail(e.line, f"unknown key {clip(e.key)}{suggest(e.key)}")
            spec, n, canon = found
            ident = (spec.key, n)
            if ident in seen:
                first = seen[ident]
                was = f" as {first.key}" if first.key != e.key else ""
                at = f"line {first.line}" if first.line is not None else "earlier"
                raise self.fail(e.line, f"duplicate key {e.key}: {canon} already set on {at}{was}")
            seen[ident] = e
            lines_seen.append((ident, canon, e))
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
        if complete:
            leaves = top.get("leaves", Params.leaves)
            missing = [
                k for k in required_keys(levels, leaves) if (lookup(k)[0].key, lookup(k)[1]) not in seen
            ]
            if missing:
                more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
                listed = {n for _, n in seen}
                bare = sorted({n for n in (lookup(k)[1] for k in missing) if n and n not in listed})
                deep = ""
                if bare and ("Levels", None) in seen:  # likely a Levels typo: say so
                    where = seen[("Levels", None)].line
                    at = f" (line {where})" if where is not None else ""
                    span = f"{bare[0]}..{bare[-1]}" if len(bare) > 1 else f"{bare[0]}"
                    deep = f"; Levels = {levels}{at} needs level{'s' if len(bare) > 1 else ''} {span}, which the file has no keys for"
                raise self.fail(
                    None,
                    f"missing {', '.join(missing[:5])}{more}{deep}; a species file lists every "
                    f"parameter (start from a bundled one, e.g. quaking_aspen.txt: `treegen species` "
                    f"lists them)",
                )
        slots: list[LevelParams] = []
        for n in range(LEVEL_SLOTS):
            base = arbaro_level_defaults(n) if n <= 3 else slots[n - 1]
            slots.append(replace(base, **per_level[n]))
        name = self.name if self.name is not None else default_name
        lines = tuple((canon, e.line) for _, canon, e in lines_seen if e.line is not None)
        return replace(default_params(name), **top, level=tuple(slots), key_lines=lines)


def default_name(source: str) -> str:
    if source.startswith("<"):
        return "tree"
    return Path(source).stem or "tree"
