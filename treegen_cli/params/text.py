"""The Weber–Penn text format, both ways: `Key value` or `Key = value` lines, `#` comments.

`parse_params_text` reads it (lines numbered for the errors); `format_params_text` writes
Params back so that reading the result gives the same Params (`params_dict` is its key order).
"""

from __future__ import annotations

from .assemble import Builder, clip, default_name
from .colors import COLOR_FORMAT, linear_to_srgb_hex
from .keys import LEAF_SHAPE_NAMES, LEVEL_KEYS, TOP_KEYS, lookup, suggest
from .record import MAX_LEVELS, Params


def parse_params_text(text: str, source: str = "<string>", partial: bool = False) -> Params:
    """Parse the plain text species format: `Key value` or `Key = value`, `#` comments.

    A file lists every parameter (keys.required_keys) and one missing any is refused, so a
    forgotten or deleted line is not silently Arbaro's default; `partial` accepts a fragment
    (a few keys over the defaults, as tests and snippets write them)."""
    b = Builder(source)
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
            raise b.fail(lineno, f"expected 'Key value' or 'Key = value', got {clip(raw.strip())!r}")
        if key.lower() in ("name", "species"):
            b.set_name(value, lineno, key)
            continue
        found = lookup(key)
        if found is None and key.endswith(":") and lookup(key[:-1]) is not None:
            raise b.fail(
                lineno,
                f"'{clip(key)} {clip(value)}': write {key[:-1]} {clip(value)} or {key[:-1]} = {clip(value)}",
            )
        if found is None:
            raise b.fail(lineno, f"unknown key {clip(key)}{suggest(key)}")
        if not value:
            if found[0].kind is str:
                raise b.fail(
                    lineno,
                    f"{key} has no value ({COLOR_FORMAT}; write it without '#', which starts a comment)",
                )
            raise b.fail(lineno, f"{key} has no value (allowed range {found[0].range_text()})")
        if len(value.split()) > 1:
            raise b.fail(lineno, f"{key} = {clip(value)!r}: expected one value, got {len(value.split())}")
        b.add(key, value, lineno)
    return b.build(default_name(source), complete=not partial)


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
    name = d.pop("Name")
    # a line holding "=" is read as `Key = value` (split at its first "="): so is such a name
    lines.append(f"Name = {name}" if "=" in name else f"Name {name}")
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
