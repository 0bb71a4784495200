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


def gif_delays(n: int, duration: float) -> list[int]:
    """Per-frame delays (ms) of `n` equal steps over `duration` s. GIF stores delays in 10 ms
    units, so one rounded delay drifts (15 fps: 60 ms × 150 = 9.0 s for a 10 s loop); rounding
    each frame's start time instead spreads the error (60/70/70 ms) and the delays sum to the
    loop's length within 5 ms."""
    starts = np.round(np.arange(n + 1) * (100.0 * duration / n)).astype(np.int64)  # centiseconds
    return [int(d) * 10 for d in np.diff(starts)]


def write_loop(frames: list[np.ndarray], path: Path, duration: float) -> None:
    """Animated GIF looping forever over `duration` s; one palette for all frames, so equal
    frames stay equal. `frames` are evenly spaced and exclude the closing pose (the GIF wraps
    back to the first)."""
    stack = np.concatenate(frames[:: max(1, len(frames) // 8)], axis=0)
    palette = Image.fromarray(stack).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=gif_delays(len(images), duration),
        loop=0,
        optimize=False,
        disposal=1,
    )
