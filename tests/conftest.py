"""Shared test fixtures: paths, the bundled species, a grown tree per species (grown once per
test session), and one way to run the CLI in a fresh process."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from contextlib import contextmanager
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


# the environment a Dask worker needs to import this checkout (and no inherited scheduler)
DASK_ENV = {
    **os.environ,
    "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
}
DASK_ENV.pop("DASK_SCHEDULER_ADDRESS", None)


@contextmanager
def dask_cluster(workers=("w1",)):
    """A real `dask scheduler` and one `dask worker` per name, as a studio starts them: separate
    processes, each its own process group (so a worker and its nanny can be killed together).
    Yields (address, {name: worker process}) once every worker has joined."""
    from distributed import Client

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    common = dict(env=DASK_ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    scheduler = ["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
    worker = ["dask", "worker", address, "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1"]
    procs = {"scheduler": subprocess.Popen(scheduler, **common)}
    for name in workers:
        procs[name] = subprocess.Popen([*worker, "--name", name, "--no-dashboard"], **common)
    try:
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(len(workers), timeout=60)
        yield address, {name: procs[name] for name in workers}
    finally:
        for p in procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()
