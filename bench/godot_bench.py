"""Godot 3.2 import time per bundled species (issue 12: every default GLB imports in under 60 s).

    python bench/godot_bench.py [--repeat 1] [species ...]

Each species' default `treegen make` GLB is imported alone in a fresh Godot project
(tests/clients.py `godot_import`: the headless editor's first scan, then inspect.gd), so the
seconds are one file's whole import as a user's editor would pay it, start-up included. Prints
the import seconds (median of --repeat), the file's MB, skeletons and bones, and whether the
import finished without errors.

Measured at load 12-19 on the shared 2-core box (seconds; all 15 imported clean, 5 skeletons
each: 4 LODs and the impostor): weeping willow 23.6 (256 MB), balsam fir 21.0 (136 MB), CA black oak 6.6, eastern cottonwood
6.5, tamarack 6.2, shave grass 4.7, rush 4.4, palm 4.3, larch 4.2, sassafras 3.4, desert bush 3.0,
black tupelo 2.9, lombardy
poplar 2.7, quaking aspen 2.7, fan palm 2.4. Every one under 60 s.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import clients  # noqa: E402  (tests/clients.py: the real-client harness)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="*", default=sorted(p.stem for p in (ROOT / "species").glob("*.txt")))
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    print(f"Godot {clients.godot_version()} editor import, one file per project, median of {args.repeat}")
    print(f"{'species':<20} {'import s':>9} {'file MB':>8} {'skeletons':>10} {'bones':>16} {'clean':>6}")
    with tempfile.TemporaryDirectory(prefix="godot_bench.") as tmp:
        for name in args.species:
            out = Path(tmp) / f"{name}.glb"
            subprocess.run(
                [sys.executable, "-m", "treegen_cli", "make", name, "-o", str(out), "-q"], check=True, cwd=tmp
            )
            runs = [clients.godot_import(out, timeout=600) for _ in range(args.repeat)]
            r = runs[-1]
            bones = "/".join(str(s["bone_count"]) for s in r.get("skeletons", []))
            clean = r["imported"] and not r["errors"]
            print(
                f"{name:<20} {statistics.median(x['import_seconds'] for x in runs):>9.1f} "
                f"{out.stat().st_size / 1e6:>8.1f} {len(r.get('skeletons', [])):>10} {bones:>16} "
                f"{'yes' if clean else 'NO':>6}",
                flush=True,
            )


if __name__ == "__main__":
    main()
