"""Species colours (LeafColor, BarkColor): sRGB hex in the file, linear RGB in Params."""

from __future__ import annotations

import re

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
