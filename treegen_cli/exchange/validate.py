"""Run the Khronos glTF-Validator (npm `gltf-validator`, pinned in tools/) on a file.

The validator is JavaScript, so we shell out to `node tools/validate.mjs FILE`, which prints
the validator's JSON report. `make install` runs `cd tools && npm ci` to install it.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

TOOLS_DIR = Path(__file__).resolve().parents[2] / "tools"
SCRIPT = TOOLS_DIR / "validate.mjs"


class ValidatorUnavailable(RuntimeError):
    """node or the npm package is missing: a setup problem, not a bad asset."""


def _node() -> str:
    node = os.environ.get("TREEGEN_NODE") or shutil.which("node")
    if not node:
        raise ValidatorUnavailable(
            "glTF validation needs Node.js: `node` is not on PATH (set TREEGEN_NODE to its path)")
    return node


def validate_gltf(path: str | os.PathLike, max_issues: int = 0) -> dict:
    """Validate a .glb/.gltf file; returns the validator's report (see report['issues']:
    numErrors, numWarnings, numInfos, numHints, messages). max_issues=0: unlimited."""
    if not (TOOLS_DIR / "node_modules" / "gltf-validator").is_dir():
        raise ValidatorUnavailable(
            f"gltf-validator is not installed in {TOOLS_DIR}: run `cd tools && npm ci` "
            "(or `make install`)")
    proc = subprocess.run([_node(), str(SCRIPT), os.fspath(path), "--max-issues", str(max_issues)],
                          capture_output=True, text=True, cwd=TOOLS_DIR)
    if proc.returncode != 0:
        raise RuntimeError(f"glTF validator failed on {path}: {proc.stderr.strip()}")
    return json.loads(proc.stdout)


def summary(report: dict) -> str:
    """One line per message: 'severity CODE pointer: text' (severity 0 error … 3 hint)."""
    names = {0: "error", 1: "warning", 2: "info", 3: "hint"}
    return "\n".join(f"{names.get(m['severity'], m['severity'])} {m['code']} "
                     f"{m.get('pointer', '')}: {m['message']}"
                     for m in report["issues"]["messages"])
