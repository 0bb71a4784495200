"""Generation speed and memory per bundled species (issue 2).

Two figures per species: in-process `generate()` (median of 5, after one warm-up), and the
whole `treegen info` process (median of 3 wall-clock runs, peak RSS from the child's rusage).
Prints a table; run with `make bench` or `python bench/generate_bench.py [species ...]`.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treegen_cli.generate import generate  # noqa: E402
from treegen_cli.params import load_params  # noqa: E402


def whole_process(path: Path) -> tuple[float, float]:
    """Median wall seconds of `treegen info` and the largest peak RSS (MB) over 3 runs."""
    times, peaks = [], []
    for _ in range(3):
        t0 = time.perf_counter()
        child = subprocess.Popen(
            [sys.executable, "-m", "treegen_cli", "info", str(path)], stdout=subprocess.DEVNULL, cwd=ROOT
        )
        _, status, usage = os.wait4(child.pid, 0)
        times.append(time.perf_counter() - t0)
        if status != 0:
            raise SystemExit(f"treegen info {path} failed")
        peaks.append(usage.ru_maxrss / 1024)
    return statistics.median(times), max(peaks)


def main(names: list[str]) -> None:
    files = (
        [ROOT / "species" / f"{n}.txt" for n in names] if names else sorted((ROOT / "species").glob("*.txt"))
    )
    # whole-process runs first: a child inherits its parent's peak RSS at fork on Linux, so the
    # parent must not hold a grown tree yet
    whole = {path: whole_process(path) for path in files}
    print(f"{'species':<20}{'stems':>8}{'leaves':>10}{'gen s':>9}{'info s':>9}{'peak MB':>9}")
    for path in files:
        p = load_params(path)
        tree = generate(p, 0)
        runs = []
        for _ in range(5):
            t0 = time.perf_counter()
            generate(p, 0)
            runs.append(time.perf_counter() - t0)
        wall, peak = whole[path]
        print(
            f"{p.name:<20}{tree.n_stems:>8,}{tree.n_leaves:>10,}{statistics.median(runs):>9.3f}"
            f"{wall:>9.2f}{peak:>9.0f}"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
