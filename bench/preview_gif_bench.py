"""`treegen preview --animate`: how long the GIF plays against the wind clip it shows.

Renders fan_palm's default 10 s loop at a few --fps (64 px, so it is quick), reads each GIF back
with Pillow and prints its frame count and summed frame delays next to the clip's length. GIF
delays are whole 10 ms units: one rounded delay per frame (the old writer: 60 ms at 15 fps,
plus the closing key drawn again) played 151 frames in 9.06 s; per-frame delays that round each
frame's start time play the clip's 150 distinct poses in its 10.00 s.

    python bench/preview_gif_bench.py [--fps 2,3,7,15,24,30]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ROOT / "species" / "fan_palm.txt"


def gif_timing(path: Path) -> tuple[int, int, bool]:
    """(frames, summed delays in ms, first frame == last frame) of a GIF."""
    with Image.open(path) as im:
        delays, first, last = [], None, None
        for i in range(im.n_frames):
            im.seek(i)
            delays.append(im.info["duration"])
            rgb = im.convert("RGB").tobytes()
            first = rgb if first is None else first
            last = rgb
    return len(delays), sum(delays), first == last


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fps", default="2,3,7,15,24,30")
    args = ap.parse_args()
    print(f"{'fps':>5} {'frames':>7} {'played s':>9} {'clip s':>7} {'error ms':>9}  seam repeats a pose")
    with tempfile.TemporaryDirectory() as tmp:
        for fps in (float(f) for f in args.fps.split(",")):
            gif = Path(tmp) / f"{fps:g}.gif"
            cmd = [sys.executable, "-m", "treegen_cli", "preview", str(SPECIES), "--animate", str(gif)]
            cmd += ["--size", "64", "--fps", f"{fps:g}", "-q"]
            subprocess.run(cmd, check=True, cwd=ROOT)
            n, ms, same = gif_timing(gif)
            print(f"{fps:5g} {n:7d} {ms / 1000:9.2f} {10.0:7.2f} {ms - 10_000:9d}  {'yes' if same else 'no'}")


if __name__ == "__main__":
    main()
