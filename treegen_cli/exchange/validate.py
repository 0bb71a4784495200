"""Validators for what we write: the Khronos glTF-Validator (npm `gltf-validator`, pinned in
tools/) and USD's own (pxr.UsdValidation, `validate_usd`).

The glTF validator is JavaScript, so we shell out to `node tools/validate.mjs FILE`, which
prints the validator's JSON report. `make install` runs `cd tools && npm ci` to install it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

NEEDED = Path("node_modules") / "gltf-validator"


def tools_dir() -> Path:
    """The folder holding validate.mjs and node_modules/gltf-validator: $TREEGEN_TOOLS, else
    the first `tools/` with the validator installed above this package or the working folder
    (a source checkout, editable or not)."""
    env = os.environ.get("TREEGEN_TOOLS")
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for base in [*here.parents, *Path.cwd().resolve().parents, Path.cwd().resolve()]:
        if (base / "tools" / NEEDED).is_dir() and (base / "tools" / "validate.mjs").is_file():
            return base / "tools"
    raise ValidatorUnavailable(
        "gltf-validator is not installed: run `make install` (npm ci in tools/) in a treegen "
        "checkout, or set TREEGEN_TOOLS to a folder holding validate.mjs and node_modules/"
    )


class ValidatorUnavailable(RuntimeError):
    """node or the npm package is missing: a setup problem, not a bad asset."""


def _node() -> str:
    node = os.environ.get("TREEGEN_NODE") or shutil.which("node")
    if not node:
        raise ValidatorUnavailable(
            "glTF validation needs Node.js: `node` is not on PATH (set TREEGEN_NODE to its path)"
        )
    return node


def validate_gltf(path: str | os.PathLike, max_issues: int = 0) -> dict:
    """Validate a .glb/.gltf file; returns the validator's report (see report['issues']:
    numErrors, numWarnings, numInfos, numHints, messages). max_issues=0: unlimited."""
    tools = tools_dir()
    if not (tools / NEEDED).is_dir():
        raise ValidatorUnavailable(
            f"gltf-validator is not installed in {tools}: run `cd tools && npm ci` (or `make install`)"
        )
    proc = subprocess.run(
        [_node(), str(tools / "validate.mjs"), os.path.abspath(path), "--max-issues", str(max_issues)],
        capture_output=True,
        text=True,
        cwd=tools,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"glTF validator failed on {path}: {proc.stderr.strip()}")
    return json.loads(proc.stdout)


def summary(report: dict) -> str:
    """One line per message: 'severity CODE pointer: text' (severity 0 error … 3 hint)."""
    names = {0: "error", 1: "warning", 2: "info", 3: "hint"}
    return "\n".join(
        f"{names.get(m['severity'], m['severity'])} {m['code']} {m.get('pointer', '')}: {m['message']}"
        for m in report["issues"]["messages"]
    )


def validate_usd(path, all_variants: bool = True) -> list[str]:
    """Run every validator registered with pxr.UsdValidation (core, geom, shade, skel, usdz
    utils, ...) over the stage at `path`; return their messages (empty list = clean).

    all_variants: also validate the stage under every selection of every variant set (our
    "LOD" set), set in the session layer, so non-default LODs are checked too.
    """
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"{path}: cannot be opened as a USD stage"]
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    messages: list[str] = []

    def run(label: str) -> None:
        for e in context.Validate(stage):
            if not e.HasNoError():
                msg = e.GetErrorAsString() + label
                if msg not in messages:
                    messages.append(msg)

    run("")
    if all_variants:
        sets = [
            (prim.GetPath(), name, prim.GetVariantSets().GetVariantSet(name).GetVariantNames())
            for prim in stage.Traverse()
            for name in prim.GetVariantSets().GetNames()
        ]
        with Usd.EditContext(stage, stage.GetSessionLayer()):
            for prim_path, name, variants in sets:
                vset = stage.GetPrimAtPath(prim_path).GetVariantSets().GetVariantSet(name)
                for variant in variants:
                    vset.SetVariantSelection(variant)
                    run(f" [variant {prim_path}{{{name}={variant}}}]")
                vset.ClearVariantSelection()
    return messages
