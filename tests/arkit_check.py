"""AR Quick Look–style check of a .usdz: usd-core's `UsdUtils.ComplianceChecker(arkit=True)`.

usd-core 26 dropped the ComplianceChecker (usdchecker moved to UsdValidation, which has no
ARKit rules), so it runs from usd-core 24.11 installed on the side (tools/usd-compliance, by
`make install` → `python tests/arkit_check.py --install`), in a subprocess. The 24.11 wheel
ships without the UsdPreviewSurface shader definitions its shader rule looks up, so the
install copies them from the project's usd-core (the definitions are the same).

    python tests/arkit_check.py --install      # once
    python tests/arkit_check.py FILE.usdz      # prints the checker's errors / failed checks
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET = Path(os.environ.get("TREEGEN_USD_COMPLIANCE", ROOT / "tools" / "usd-compliance"))
VERSION = "24.11"


def available() -> bool:
    return (TARGET / "pxr" / "UsdUtils" / "complianceChecker.py").is_file()


def install() -> None:
    """pip-install usd-core 24.11 into TARGET and give its usdHydra plugin the shader defs."""
    if not available():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "pip",
                "install",
                "--quiet",
                "--no-deps",
                "--target",
                str(TARGET),
                f"usd-core=={VERSION}",
            ],
            check=True,
        )
    import pxr  # the project's usd-core: it has the definitions

    src = Path(pxr.__file__).parent / "pluginfo" / "usdShaders" / "resources" / "shaders"
    dst = TARGET / "pxr" / "pluginfo" / "usdHydra" / "resources" / "shaders"
    dst.mkdir(parents=True, exist_ok=True)
    for f in src.iterdir():
        shutil.copy2(f, dst / f.name)


def check(path) -> dict[str, list[str]]:
    """{"errors": [...], "failed": [...], "warnings": [...]} from ComplianceChecker(arkit=True)
    run under usd-core 24.11 (call only when available())."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PXR_PLUGINPATH_NAME")}
    env["PYTHONPATH"] = str(TARGET)
    proc = subprocess.run(
        [sys.executable, "-c", _RUN, str(Path(path).resolve())],  # (it runs from TARGET)
        capture_output=True,
        text=True,
        env=env,
        cwd=str(TARGET),
        timeout=300,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"ComplianceChecker failed to run: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


_RUN = """
import json, sys
from pxr import UsdUtils
c = UsdUtils.ComplianceChecker(arkit=True)
c.CheckCompliance(sys.argv[1])
print(json.dumps({"errors": c.GetErrors(), "failed": c.GetFailedChecks(),
                  "warnings": c.GetWarnings()}))
"""


if __name__ == "__main__":
    if sys.argv[1:] == ["--install"]:
        install()
        print(f"usd-core {VERSION} ComplianceChecker in {TARGET}")
    elif sys.argv[1:] and not sys.argv[1].startswith("-"):
        if not available():
            sys.exit(f"not installed: python {sys.argv[0]} --install")
        bad = False
        for f in sys.argv[1:]:
            r = check(f)
            bad |= bool(r["errors"] or r["failed"])
            print(f, json.dumps(r, indent=1))
        sys.exit(1 if bad else 0)
    else:
        sys.exit("usage: python tests/arkit_check.py --install | FILE.usdz ...")
