"""Golden outputs: SHA-256 digests of what the CLI writes for every bundled species (GLB; USDC
for five), the example forests (a baked camera view in GLB, every LOD in GLB and USDA), a
static OBJ and a preview PNG.

A refactor must leave these bytes alone; a change that means to alter the output updates them
on purpose, in its own commit, with `python tests/golden.py --update` (the diff of
tests/fixtures/golden.json then shows exactly which outputs moved).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DIGESTS = ROOT / "tests" / "fixtures" / "golden.json"
# short clips keep the suite quick; every stage (LODs, decimation, UsdSkel) still runs
CLIP = ["--duration", "1", "--fps", "10"]
# run from a temporary folder, `python -m treegen_cli` would import the installed package (an
# editable install may point at another worktree): put this checkout first
ENV = {
    **os.environ,
    "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
}


# USDC for species that reach the USD writer's distinct paths (broad leaves, leaves that are
# whole fronds, no leaves at all); every species' GLB already guards the asset itself
USDC = {"quaking_aspen", "black_tupelo", "ca_black_oak", "fan_palm", "shave_grass"}


def cases() -> dict[str, list[str]]:
    """name → treegen arguments; `{out}` is replaced by the output path."""
    out: dict[str, list[str]] = {}
    for sp in sorted((ROOT / "species").glob("*.txt")):
        for ext in ("glb", "usdc") if sp.stem in USDC else ("glb",):
            out[f"{sp.stem}.{ext}"] = ["make", str(sp), "-o", "{out}", *CLIP]
    for ex in sorted((ROOT / "examples").glob("forest_*.json")):
        if ex.stem != "forest_1000":
            out[f"{ex.stem}.glb"] = ["forest", str(ex), "-o", "{out}", "--camera-lod"]
    # the default: every tree with all its LODs
    for ext in ("glb", "usda"):
        out[f"forest_30m_walk.{ext}"] = ["forest", str(ROOT / "examples" / "forest_30m.json"), "-o", "{out}"]
    out["palm.obj"] = ["make", str(ROOT / "species" / "palm.txt"), "-o", "{out}", "--no-wind"]
    out["quaking_aspen.png"] = [
        "preview",
        str(ROOT / "species" / "quaking_aspen.txt"),
        "-o",
        "{out}",
        "--size",
        "96",
    ]
    return out


def digest(name: str, args: list[str]) -> str:
    """Run treegen in a fresh process and hash the main file plus any sibling files."""
    with tempfile.TemporaryDirectory() as tmp:
        target = Path(tmp) / name
        argv = [a.replace("{out}", str(target)) for a in args]
        proc = subprocess.run(  # this checkout's treegen_cli, not whatever is installed
            [sys.executable, "-m", "treegen_cli", *argv, "-q"],
            capture_output=True,
            text=True,
            cwd=tmp,
            env=ENV,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"treegen {' '.join(argv)} failed: {proc.stderr}")
        h = hashlib.sha256()
        for f in sorted(Path(tmp).iterdir()):
            h.update(f.name.encode() + b"\0" + f.read_bytes())
        return h.hexdigest()


def compute(names: list[str] | None = None, jobs: int = 2) -> dict[str, str]:
    table = cases()
    names = names or list(table)
    with ThreadPoolExecutor(jobs) as pool:
        return dict(zip(names, pool.map(lambda n: digest(n, table[n]), names)))


if __name__ == "__main__":
    if sys.argv[1:] != ["--update"]:
        sys.exit("usage: python tests/golden.py --update")
    DIGESTS.write_text(json.dumps(compute(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {DIGESTS}")
