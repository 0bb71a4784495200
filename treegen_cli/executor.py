"""Where many builds run: a Dask cluster, embedded or remote, behind one context manager.

    with dask_client(scheduler=None, workers=2) as (client, where):
        futures = [client.submit(fn, *args) for ...]

No scheduler (and no DASK_SCHEDULER_ADDRESS): an embedded LocalCluster with one single-threaded
worker process per core (the pipeline is numpy-bound and holds the GIL between calls, so
processes, not threads). With an address: the same jobs go to an existing cluster, whose
workers must see the same file system paths (outputs are written by the workers).
Closing the block closes the client and, if embedded, the cluster and its processes.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal

from .errors import TreegenError

SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
TRIM = "MALLOC_TRIM_THRESHOLD_"
_tuned = False


def scheduler_address(scheduler: str | None) -> str | None:
    """--scheduler, else $DASK_SCHEDULER_ADDRESS, else None (embedded cluster)."""
    return scheduler or os.environ.get(SCHEDULER_ENV) or None


def default_workers() -> int:
    return os.cpu_count() or 1


# Monitors of the embedded cluster that we never read (no dashboard), slowed down or off:
# each wakes a worker's event-loop thread, which must take the GIL from the building thread
# (profiler: every 10 ms; loop tick: 20 ms; memory monitor: 100 ms). On a busy machine the
# loop thread is then often preempted holding the GIL and the build waits (measured: 8
# prototypes of forest_130m, 2 workers on a loaded 2-core box, 33-38 s → 28-29 s).
QUIET = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.memory.monitor-interval": "2s",
}


# How the embedded cluster's worker processes start. Spawning (Dask's default) runs a fresh
# interpreter per worker that imports distributed, numpy and then treegen again, and stopping
# it waits ~1 s; a fork server (exec'd once, single-threaded, so no lock is inherited) imports
# them once (PRELOAD) and forks workers that are ready at once and stop at once. Measured on
# the loaded 2-core box, 2 workers, start + first job's imports + close: 7.1 → 3.8 s.
STARTUP = {"distributed.worker.multiprocessing-method": "forkserver"}
PRELOAD = [
    "distributed",
    "treegen_cli.api",
    "treegen_cli.batch.run",
    "treegen_cli.forest.build",
    "treegen_cli.render",
    "treegen_cli.impostor_render",
]


def _preload_fork_server() -> None:
    """Replace Dask's preload list (its own dependencies) with ours, which imports them too.
    Only before the fork server's first start; later calls change nothing."""
    from distributed.utils import get_mp_context

    get_mp_context().set_forkserver_preload(PRELOAD)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """Yield (client, description); the cluster is closed on exit, even on Ctrl-C. The embedded
    cluster starts its workers from a fork server (STARTUP): a fork of this process, whose
    threads are running, can inherit a held lock and hang."""
    import dask
    from distributed import Client, LocalCluster

    address = scheduler_address(scheduler)
    if address:
        try:
            client = Client(address, timeout="10s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as e:
            raise TreegenError(
                f"--scheduler {address}: cannot connect to a Dask scheduler "
                f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}); "
                "start one with `dask scheduler`"
            ) from None
        try:
            n = check_workers(client, address)
            yield client, f"{n} worker(s) at {address}"
        finally:
            client.close()
        return
    n = workers or default_workers()
    # Worker processes inherit an ignored SIGINT (Python keeps SIG_IGN across exec), so a
    # Ctrl-C reaches only this process, which then closes the cluster in order; without
    # this every worker prints its own KeyboardInterrupt traceback.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        config: dict = {f"distributed.nanny.pre-spawn-environ.{TRIM}": None, **QUIET, **STARTUP}
        with dask.config.set(config):
            _preload_fork_server()
            # the scheduler's HTTP server (health routes) always starts; on a free port, so a
            # busy 8787 (someone's dashboard) costs no "Port 8787 is already in use" warning
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            )
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client, f"{n} local worker(s)"
        finally:
            client.close()
    finally:
        cluster.close()


def treegen_version() -> str:
    """Run on each worker by check_workers (by reference: it fails where treegen_cli is
    not importable, which is the point)."""
    from .build_id import build_id

    return build_id()


def check_workers(client, address: str, wait_s: float = 30.0) -> int:
    """Refuse a cluster whose workers cannot run our jobs, before any is sent: no worker
    (after `wait_s`), a worker without treegen_cli, or one with another treegen version
    (whose bytes could differ from `treegen make` here): same version and same package files
    (build_id). Returns the number of workers."""
    from . import __version__
    from .build_id import build_id

    here = build_id()

    try:
        client.wait_for_workers(1, timeout=wait_s)
    except TimeoutError:
        raise TreegenError(
            f"--scheduler {address}: no worker joined within {wait_s:g} s; start "
            f"some with `dask worker {address}`"
        ) from None
    found = client.run(treegen_version, on_error="return")
    for worker, v in sorted(found.items()):
        if isinstance(v, BaseException):
            raise TreegenError(
                f"--scheduler {address}: worker {worker} cannot run treegen "
                f"({type(v).__name__}: {v}); install treegen {__version__} "
                "on every worker"
            ) from None
        if v != here:
            raise TreegenError(
                f"--scheduler {address}: worker {worker} has treegen {v}, this "
                f"is {here}; install the same version (the same files) on every worker"
            )
    return len(found)


def worker_name() -> str:
    """The Dask worker running this task (its address), or 'local' outside one."""
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


def tune_worker_malloc() -> None:
    """Undo, once per worker process, the slowdown Dask's nannies cause by default.

    A nanny starts its worker with MALLOC_TRIM_THRESHOLD_=65536, and glibc then stops adapting
    its mmap threshold: every numpy array over 128 KiB is a fresh mmap, zero-filled page by
    page, and a tree builds 2–3× slower than in a plain process (measured: black_tupelo 1.8 s
    vs 0.6 s). Raising the mmap and trim thresholds restores plain-process speed. Our embedded
    cluster does not set the variable at all; this covers `dask worker` clusters started with
    the default configuration. No-op off glibc or when the variable is not set."""
    global _tuned
    if _tuned or TRIM not in os.environ:
        return
    _tuned = True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 32 * 1024 * 1024)  # M_MMAP_THRESHOLD: glibc's own upper bound
        libc.mallopt(-1, 64 * 1024 * 1024)  # M_TRIM_THRESHOLD: twice it, as glibc adapts
    except (OSError, AttributeError):
        pass
