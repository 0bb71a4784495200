"""Weber–Penn species parameters: the `Params` record, its defaults, and the file readers.

A text file lists every parameter (keys.required_keys: the paper's table for the levels it
grows); keys beyond the paper, and any key of an Arbaro XML file, may be absent and take
Arbaro's defaults. The file's own values always win.
`load_params(path)` is the front door (load.py); its parts, one module each:

- record.py — `Params` / `LevelParams` (the paper's names in snake_case) and Arbaro's defaults
- keys.py — the parameter table: file key → field, type, legal range; LeafShape names
- colors.py — LeafColor / BarkColor: sRGB hex in the file, linear RGB in Params
- assemble.py — validation: entries from either reader → Params, or a one-line error
- text.py — the Weber–Penn text format, read and written
- arbaro_xml.py — Arbaro's XML species files
"""

from __future__ import annotations

from .arbaro_xml import parse_params_xml
from .colors import COLOR_FORMAT, linear_to_srgb_hex, srgb_hex_to_linear
from .keys import (
    LEAF_SHAPE_NAMES,
    LEAF_SHAPES,
    LEVEL_ALIASES,
    LEVEL_KEYS,
    MAX_LEAF_SHAPE,
    NAME_KEYS,
    TOP_KEYS,
    KeySpec,
)
from .load import load_params, parse_params_bytes
from .record import LEVEL_SLOTS, MAX_LEVELS, LevelParams, Params, arbaro_level_defaults, default_params
from .text import format_params_text, params_dict, parse_params_text

__all__ = [
    "COLOR_FORMAT",
    "LEAF_SHAPES",
    "LEAF_SHAPE_NAMES",
    "LEVEL_ALIASES",
    "LEVEL_KEYS",
    "LEVEL_SLOTS",
    "MAX_LEAF_SHAPE",
    "MAX_LEVELS",
    "NAME_KEYS",
    "TOP_KEYS",
    "KeySpec",
    "LevelParams",
    "Params",
    "arbaro_level_defaults",
    "default_params",
    "format_params_text",
    "linear_to_srgb_hex",
    "load_params",
    "params_dict",
    "parse_params_bytes",
    "parse_params_text",
    "parse_params_xml",
    "srgb_hex_to_linear",
]
