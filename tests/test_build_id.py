"""build_id: the identity batch keys and cluster checks use changes with any shipped file."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import treegen_cli
from treegen_cli import __version__
from treegen_cli.build_id import build_id, digest

PACKAGE = Path(treegen_cli.__file__).resolve().parent


def test_build_id_is_the_version_and_the_package_digest():
    assert re.fullmatch(re.escape(__version__) + r"\+[0-9a-f]{12}", build_id())
    assert build_id().endswith(digest(PACKAGE)[:12])


def test_digest_follows_code_and_data_but_not_bytecode(tmp_path):
    copy = tmp_path / "treegen_cli"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    base = digest(copy)
    assert base == digest(PACKAGE)  # where the package sits does not matter
    (copy / "__pycache__").mkdir(exist_ok=True)
    (copy / "__pycache__" / "x.cpython-311.pyc").write_bytes(b"\0" * 16)
    assert digest(copy) == base
    species = sorted((copy / "species").glob("*.txt"))[0]
    species.write_text(species.read_text() + "\n")  # a bundled species changed
    assert digest(copy) != base
    species.write_text(species.read_text()[:-1])
    assert digest(copy) == base
    (copy / "lod.py").rename(copy / "lod2.py")  # same bytes under another name
    assert digest(copy) != base


def test_batch_keys_change_with_the_build(monkeypatch, tmp_path):
    """A rerun after treegen's files changed rebuilds (its outputs may differ) even though
    the version string did not."""
    from treegen_cli.batch import catalogue, parse_catalogue

    data = {"entries": [{"species": str(PACKAGE / "species" / "rush.txt"), "seeds": [1]}]}
    first = parse_catalogue(data, tmp_path / "c.json").jobs[0].key
    assert parse_catalogue(data, tmp_path / "c.json").jobs[0].key == first
    monkeypatch.setattr(catalogue, "build_id", lambda: f"{__version__}+000000000000")
    assert parse_catalogue(data, tmp_path / "c.json").jobs[0].key != first
