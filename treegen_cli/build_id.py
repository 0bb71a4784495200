"""Which treegen built an asset: the version plus a digest of the installed package's files.

    build_id()   # Result: "0.1.0+3f9c1a2b7d4e"

The version string alone does not change when the code that writes the bytes does (a checkout
between releases, a patched install), so a batch resume keyed on it would keep stale outputs
and a cluster mixing two builds would write different bytes under one key. The digest covers
every file the package ships (code, bundled species, schemas), so any change to what `make`
can write gives a new id; docstring edits do too, which only costs a rebuild.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

from . import __version__

SKIP_DIRS = {"__pycache__"}
SKIP_SUFFIXES = {".pyc", ".pyo"}


def package_files(root: Path) -> list[Path]:
    """The files under `root` that make up the package, in a fixed (sorted path) order."""
    files = [
        p
        for p in root.rglob("*")
        if p.is_file()
        and p.suffix not in SKIP_SUFFIXES
        and not SKIP_DIRS.intersection(p.relative_to(root).parts)
    ]
    return sorted(files, key=lambda p: p.relative_to(root).as_posix())


def digest(root: Path) -> str:
    """SHA-256 (hex) of each package file's path (relative to `root`) and bytes."""
    h = hashlib.sha256()
    for p in package_files(root):
        name = p.relative_to(root).as_posix().encode()
        data = p.read_bytes()
        h.update(len(name).to_bytes(4, "little") + name + len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


@lru_cache(maxsize=1)
def build_id() -> str:
    """`<version>+<12 hex digits>` of this installed package (read once per process)."""
    return f"{__version__}+{digest(Path(__file__).resolve().parent)[:12]}"
