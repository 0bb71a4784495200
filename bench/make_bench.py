"""Whole-process `treegen make` benchmark (issue 3): the four Weber–Penn paper species to GLB,
each run as its own `treegen make` process (python -c ... cli.main()) (imports, generation, LODs, writing and
interpreter exit all count). Prints seconds (median of --repeat runs), peak resident MB (the
child's ru_maxrss, median) and the file size. Target: weeping willow under 4 s and under 1 GB.

    python bench/make_bench.py [--repeat 3] [--seed 0] [--root DIR] [--against=OPTIONS] [species ...]
                               [-- make options]

e.g. `python bench/make_bench.py weeping_willow -- --no-lod --leaf-geometry shape`.

Measured on the shared 2-core box, seed 0, median of 3 (seconds / peak MB / file MB). "before" is
commit 6b90909 (one LOD, 8-vertex leaf outlines, float32 weights, joined in-memory buffers),
run with --root on a `git archive` of it; "no LOD" is today's code with --no-lod (the same
single-LOD tree as before); "default" adds the 4 LODs that `make` now writes by default.

    species          before                 no LOD                default (4 LODs)
    quaking_aspen    0.87 s  127 MB  13 MB   0.63 s   91 MB   5 MB   1.15 s  103 MB   8 MB
    black_tupelo     1.10 s  191 MB  28 MB   0.71 s  121 MB  13 MB   1.42 s  149 MB  27 MB
    weeping_willow   6.66 s 1267 MB 331 MB   2.50 s  499 MB  96 MB   4.55 s  661 MB 187 MB
    ca_black_oak     1.24 s  246 MB  42 MB   0.95 s  128 MB  15 MB   1.28 s  153 MB  27 MB

Textures' cost (issue 12: at most +20 %), `--against=--no-textures`, median of 3, CPU seconds of
the whole process (user + system; the box ran at load 15-19, so wall seconds mean little):

    species          textures  --no-textures  ratio   file MB (ratio)
    quaking_aspen      2.21       2.12        1.04    13.83 / 13.37 (1.03)
    black_tupelo       2.72       2.36        1.15    33.77 / 33.31 (1.01)
    weeping_willow    15.06      14.89        1.01   256.19 / 255.67 (1.00)
    ca_black_oak       2.71       2.54        1.07    40.97 / 40.71 (1.01)
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAPER_SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")


def run_once(
    species: Path, out: Path, seed: int, extra: list[str], root: Path = ROOT
) -> tuple[float, float, str, float]:
    """(wall seconds, peak RSS MB, stdout, CPU seconds) of one whole `treegen make` process.
    The child is reaped with os.wait4 for its own rusage (RUSAGE_CHILDREN would be a max over
    all runs). CPU seconds (user + system, all threads) hold up on a loaded box; wall does not."""
    cmd = [
        sys.executable,
        "-c",
        "from treegen_cli.cli import main; main()",
        "make",
        str(species),
        "-o",
        str(out),
        "--seed",
        str(seed),
        *extra,
    ]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with tempfile.TemporaryFile() as log, tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=log, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0), err.seek(0)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed:\n{err.read().decode()}")
        cpu = usage.ru_utime + usage.ru_stime
        return seconds, usage.ru_maxrss / 1024.0, log.read().decode(), cpu  # Linux: KiB


def main() -> None:
    argv = sys.argv[1:]
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1 :]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "species", nargs="*", default=list(PAPER_SPECIES), help="species names (species/<name>.txt) or paths"
    )
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--root",
        type=Path,
        default=ROOT,
        help="treegen checkout to run (e.g. an older `git archive` for before/after)",
    )
    ap.add_argument(
        "--against",
        default=None,
        metavar="OPTIONS",
        help="also run each species with these make options (e.g. --against=--no-textures) "
        "and print the default's CPU time and size as ratios to them",
    )
    args = ap.parse_args(argv)
    if args.against is not None:
        compare(args, extra)
        return

    print(
        f"treegen make, whole process, median of {args.repeat}"
        + (f"; options: {' '.join(extra)}" if extra else "")
    )
    print(f"{'species':<18} {'seconds':>8} {'peak MB':>8} {'file MB':>8} {'vertices':>10} {'triangles':>10}")
    with tempfile.TemporaryDirectory(prefix="make_bench.") as tmp:
        for name in args.species:
            species = Path(name) if name.endswith((".txt", ".xml")) else ROOT / "species" / f"{name}.txt"
            out = Path(tmp) / f"{species.stem}.glb"
            runs = [run_once(species, out, args.seed, extra, args.root) for _ in range(args.repeat)]
            m = re.search(r"([\d,]+) vertices, ([\d,]+) triangles", runs[-1][2])
            verts, tris = (m.group(1), m.group(2)) if m else ("?", "?")
            print(
                f"{species.stem:<18} {statistics.median(r[0] for r in runs):>8.2f} "
                f"{statistics.median(r[1] for r in runs):>8.0f} "
                f"{out.stat().st_size / 1e6:>8.1f} {verts:>10} {tris:>10}",
                flush=True,
            )


def compare(args, extra: list[str]) -> None:
    """Each species made with `extra` and with `extra` + --against; medians and ratios."""
    other = args.against.split()
    print(
        f"treegen make, whole process, median of {args.repeat}; A = {' '.join(extra) or 'defaults'}"
        f", B = A + {args.against}"
    )
    print(
        f"{'species':<18} {'A cpu s':>8} {'B cpu s':>8} {'A/B':>6} {'A wall':>7} {'B wall':>7} "
        f"{'A MB':>7} {'B MB':>7} {'A/B':>6}"
    )
    with tempfile.TemporaryDirectory(prefix="make_bench.") as tmp:
        for name in args.species:
            species = Path(name) if name.endswith((".txt", ".xml")) else ROOT / "species" / f"{name}.txt"
            a_out, b_out = Path(tmp) / f"{species.stem}_a.glb", Path(tmp) / f"{species.stem}_b.glb"
            a, b = [], []
            for _ in range(args.repeat):  # interleaved: load drifts hit both alike
                a.append(run_once(species, a_out, args.seed, extra, args.root))
                b.append(run_once(species, b_out, args.seed, extra + other, args.root))
            ac, bc = (statistics.median(r[3] for r in x) for x in (a, b))
            aw, bw = (statistics.median(r[0] for r in x) for x in (a, b))
            am, bm = a_out.stat().st_size / 1e6, b_out.stat().st_size / 1e6
            print(
                f"{species.stem:<18} {ac:>8.2f} {bc:>8.2f} {ac / bc:>6.2f} {aw:>7.2f} {bw:>7.2f} "
                f"{am:>7.2f} {bm:>7.2f} {am / bm:>6.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
