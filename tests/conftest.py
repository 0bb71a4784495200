"""Shared test fixtures: paths, the bundled species, a grown tree per species (grown once per
test session), and one way to run the CLI in a fresh process."""

from __future__ import annotations

import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import pytest

import treegen_cli  # noqa: F401  (first: pins OpenBLAS's kernel before numpy loads, as the CLI does)

ROOT = Path(__file__).resolve().parent.parent
SPECIES_DIR = ROOT / "species"
SPECIES = sorted(p.stem for p in SPECIES_DIR.glob("*.txt"))
PAPER_SPECIES = ["quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak"]


def species_path(name: str) -> Path:
    return SPECIES_DIR / f"{name}.txt"


@lru_cache(maxsize=None)
def grown(name: str, seed: int = 0):
    """The bundled species `name` grown with `seed`, once per session (trees are immutable)."""
    from treegen_cli.generate import generate
    from treegen_cli.params import load_params

    return generate(load_params(species_path(name)), seed)


def run_treegen(*args, cwd=None) -> subprocess.CompletedProcess:
    """`treegen ARGS` in a fresh interpreter, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "treegen_cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
    )


@pytest.fixture
def treegen_cli_run():
    return run_treegen
