"""Pictures: PNG/JPEG stills and looping GIFs (Pillow), for `treegen preview`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image


def write_still(pixels: np.ndarray, path: Path, colors: int = 0) -> None:
    """PNG (optimised; `colors` > 0 quantises to a palette, ~3× smaller) or JPEG."""
    img = Image.fromarray(pixels)
    if path.suffix.lower() == ".png":
        if colors:
            img = img.quantize(
                colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.FLOYDSTEINBERG
            )
        img.save(path, format="PNG", optimize=True)
    else:
        img.save(path, format="JPEG", quality=90)


def write_loop(frames: list[np.ndarray], path: Path, fps: float) -> None:
    """Animated GIF looping forever; one palette for all frames, so equal frames stay equal."""
    stack = np.concatenate(frames[:: max(1, len(frames) // 8)], axis=0)
    palette = Image.fromarray(stack).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=int(round(1000 / fps)),
        loop=0,
        optimize=False,
        disposal=1,
    )
