"""Atomic writes: a writer writes into a hidden staging folder beside the target, then every file
it produced is moved into place with os.replace (siblings first, the main file last), so an
interrupted run never leaves a half-written asset. The folder is named after the target and the
writing process and its host (`.NAME.PID@HOST.XXXX.tmp`); a run into the same folder sweeps away
the staging folders of runs on this host that were killed (their process is gone).
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from ..errors import TreegenError, signals_held

_STAGING = re.compile(r"^\..+\.(\d+)(?:@([A-Za-z0-9-]+))?\.[^.]+\.tmp$")
# The writer's host is part of the name: on a shared folder (treegen batch on a Dask cluster of
# several machines) a process id is only meaningful on its own host, so a run sweeps only the
# folders of its own host's dead processes (names without a host are taken as local).
_HOST = re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname()) or "host"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    # A killed process whose parent died too stays a zombie until init reaps it (late, or
    # never in some containers); os.kill succeeds on it, but it will never write again.
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] not in (b"Z", b"X")
    except (OSError, IndexError):  # no /proc (macOS): trust os.kill
        return True


def sweep(folder: Path) -> list[Path]:
    """Remove staging folders left in `folder` by killed runs; returns what was removed."""
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for e in entries:  # a folder's entries, not vertices
        m = _STAGING.match(e.name)
        if (
            m
            and m.group(2) in (None, _HOST)
            and e.is_dir(follow_symlinks=False)
            and not _alive(int(m.group(1)))
        ):
            shutil.rmtree(e.path, ignore_errors=True)
            removed.append(Path(e.path))
    return removed


@contextmanager
def staged(path: str | os.PathLike, after: Callable[[], object] | None = None) -> Iterator[Path]:
    """Yield a path named like `path` inside a fresh staging folder next to it; on success move
    everything written there into place (main file last), then run `after` (an earlier write's
    stale files removed) with the moves' signals still held; on failure leave nothing behind."""
    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise TreegenError(f"{path}: is a folder; give an output file name such as tree.glb")
    try:
        sweep(folder)
        tmpdir = Path(
            tempfile.mkdtemp(prefix=f".{path.name}.{os.getpid()}@{_HOST}.", suffix=".tmp", dir=folder)
        )
    except FileNotFoundError:
        if folder.is_dir():  # e.g. /proc: there, but creating a file in it fails with ENOENT
            raise TreegenError(
                f"{path}: cannot write into folder '{folder}' (not writable: it refuses new files)"
            ) from None
        raise TreegenError(f"{path}: output folder '{folder}' does not exist") from None
    except OSError as e:
        raise TreegenError(
            f"{path}: cannot write into folder '{folder}' (not writable: {e.strerror})"
        ) from None
    try:
        yield tmpdir / path.name
        produced = sorted(os.listdir(tmpdir), key=lambda n: (n == path.name, n))
        if path.name not in produced:
            raise RuntimeError(f"writer for {path.suffix} did not write {path.name}")
        for name in produced:  # every target checked before any moves: all or nothing
            if (folder / name).is_dir():
                raise TreegenError(f"{folder / name}: is a folder, where {path} writes a file; move it away")
        with signals_held():  # a Ctrl-C between two moves would leave old and new files mixed
            for name in produced:
                os.replace(tmpdir / name, folder / name)
            if after is not None:
                after()
    except OSError as e:
        raise TreegenError(f"{path}: cannot write ({e.strerror or e})") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def written(tmp: Path, path: Path) -> list[Path]:
    """Where the files a writer put beside `tmp` (in its staging folder) land: `path`'s
    folder, main file first (a .gltf also writes its .bin)."""
    names = sorted(  # main file first; a part's files together, its main one first
        os.listdir(tmp.parent),
        key=lambda n: (n != path.name, n.split(".")[0], not n.endswith(path.suffix), n),
    )
    return [path.parent / n for n in names]
