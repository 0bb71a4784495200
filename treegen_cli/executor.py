"""Where many builds run: Dask, on a cluster (embedded or remote) or on its local process
scheduler, behind small context managers.

    with dask_client(scheduler=None, workers=2) as (client, where):    # treegen batch
        futures = [client.submit(fn, *args) for ...]
    with process_pool(workers=2) as (run, where):                      # treegen forest
        results = run([(fn, *args), ...], done=bar_step)

dask_client: no scheduler (and no DASK_SCHEDULER_ADDRESS) gives an embedded cluster with one
single-threaded worker process per core (the pipeline is numpy-bound and holds the GIL between
calls, so processes, not threads), started from a fork server; with an address, the same jobs
go to an existing cluster, whose workers must see the same file system paths (outputs are
written by the workers). Closing the block closes the client and, if embedded, the cluster.

process_pool: a handful of tasks whose results come back to this process (the
forest's prototypes) run under Dask's local process scheduler, on processes forked from this
one: no scheduler, comms or imports to start, so a forest builds as fast as the process pool it
had before Dask (bench/forest_bench.py). A forest sent to a cluster uses dask_client.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import pickle
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable

from .cluster_check import SCHEDULER_ENV, address_label, check_workers, reachable
from .errors import TreegenError, signals_held

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
    # one task a worker at a time: with Dask's 1.1 each single-threaded worker holds two, and a
    # task queued behind a long one waits while the other worker idles (the forest's 7
    # prototypes: one worker idle for the last 2.4 s; old pool = 1: 1.22× → 1.11×). Dask
    # queues (and so applies this to) a task group more than twice the cluster's threads.
    "distributed.scheduler.worker-saturation": 1.0,
}


# How the embedded cluster's worker processes start. Spawning (Dask's default) runs a fresh
# interpreter per worker that imports distributed, numpy and then treegen again, and stopping
# it waits ~1 s; a fork server (exec'd once, single-threaded, so no lock is inherited) imports
# them once (PRELOAD) and forks workers that are ready at once and stop at once. Measured on
# the loaded 2-core box, 2 workers, start + first job's imports + close: 7.1 → 3.8 s. The fork
# server is launched first thing (start_fork_server), so its imports overlap the client's.
# Forking the client itself (dask_client(fork=True)) costs neither: the forest's 7 prototypes,
# loaded box, 1.23 × the old process pool's time from the fork server, 1.11 × forked
# (bench/forest_bench.py).
STARTUP = {"distributed.worker.multiprocessing-method": "forkserver"}
PRELOAD = [
    "distributed",
    "treegen_cli.api",
    "treegen_cli.batch.run",
    "treegen_cli.forest.build",
    "treegen_cli.render",
    "treegen_cli.impostor_render",
]


def start_fork_server() -> None:
    """Launch the fork server now, with our preload list (Dask's own dependencies are in it),
    so that its imports (~1 s) run beside the client's own start-up (importing distributed,
    starting the scheduler) rather than after it, when the first nanny would ask for it.
    SIGINT is ignored while it starts, so it and every worker it forks ignore it (see
    dask_client). Idempotent: a running fork server is kept, and Dask's later preload list
    changes nothing."""
    import multiprocessing
    from multiprocessing import forkserver

    multiprocessing.get_context("forkserver").set_forkserver_preload(PRELOAD)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


def can_fork() -> bool:
    """Whether a fork of this process is as safe as the old process pool's were: one Python
    thread (no event-loop, progress or texture thread that may hold a lock the child needs)
    and no OpenGL loaded (a fork of a process with a live llvmpipe context hangs in its first
    framebuffer read)."""
    return hasattr(os, "fork") and threading.active_count() == 1 and "moderngl" not in sys.modules


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """Yield (client, description); the cluster is closed on exit, even on Ctrl-C.

    The embedded cluster's workers start from a fork server (STARTUP): a fork of this process
    once its event loop runs can inherit a held lock and hang."""
    address = scheduler_address(scheduler)
    n = workers or default_workers()
    if not address:
        start_fork_server()  # first: its imports overlap ours below
    import dask
    from distributed import Client

    if address:
        label = address_label(scheduler, address)
        reachable(address, label)  # a mistyped address: at once, not after Dask's timeouts
        try:
            client = Client(address, timeout="10s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as e:
            raise TreegenError(
                f"{label}: cannot connect to a Dask scheduler "
                f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}); "
                "start one with `dask scheduler`"
            ) from None
        try:
            n = check_workers(client, address, label)
            yield client, f"{n} worker(s) at {address}"
        finally:
            client.close()
        return
    config: dict = {
        f"distributed.nanny.pre-spawn-environ.{TRIM}": None,
        **QUIET,
        **STARTUP,
    }
    with dask.config.set(config), contextlib.ExitStack() as stack:
        # The workers come from the fork server, which ignores SIGINT, so a Ctrl-C reaches
        # only this process, which then closes the cluster in order. One while the cluster
        # starts is held until it has (then it can be closed): raised midway, it was lost
        # (SIGINT was ignored here too) or left a half-started cluster to Dask's exit hook,
        # which printed a traceback (a SIGTERM).
        with signals_held():  # acted on once the cluster can be closed, or its start failed
            # (its workers stopped by the same signal, a process group's: that is the news)
            cluster = _local_cluster(n)
            stack.callback(cluster.close)
        client = Client(cluster, set_as_default=False)
        stack.callback(client.close)
        yield client, f"{n} local worker(s)"


def _local_cluster(n: int):
    from distributed import LocalCluster

    # the scheduler's HTTP server (health routes) always starts; on a free port, so a busy
    # 8787 (someone's dashboard) costs no "Port 8787 is already in use" warning
    return LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        silence_logs=logging.CRITICAL,
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
    )


@contextlib.contextmanager
def process_pool(workers: int):
    """Yield (run, description): run(tasks, done) is run_local on `workers` processes, started
    now: forks of this process while can_fork(), as the forest's process pool before Dask was
    (they inherit everything imported here and are ready at once), else children of the fork
    server. They ignore SIGINT (a Ctrl-C reaches only this process, which stops them on the
    way out, as it does when a task fails: the caller writes nothing they return) and exit
    when their parent goes (killed, a CI job cancelled), instead of building on as orphans."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import dask.multiprocessing  # noqa: F401  (before the fork: the workers run its code too)

    if can_fork():
        context = multiprocessing.get_context("fork")
    else:
        start_fork_server()
        context = multiprocessing.get_context("forkserver")
    before = set(multiprocessing.active_children())
    with tempfile.TemporaryDirectory(prefix="treegen-results-") as handoff:
        pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_worker_start)
        try:
            # the first task forks them all (a fork pool starts every process then, before its
            # own thread): now, while this process has no other thread (no progress bar yet)
            pool.submit(int).result()
            yield functools.partial(run_local, pool, workers, handoff), f"{workers} local worker(s)"
        except BaseException:  # Ctrl-C or a failed task: stop the others' builds now
            for process in set(multiprocessing.active_children()) - before:
                process.terminate()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _worker_start() -> None:
    """In each worker: ignore SIGINT, die of SIGTERM (a fork inherits the CLI's handler, which
    would raise in the worker: a traceback, or the next task run while the parent waits), and
    exit once the parent is gone (re-parented)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="treegen-parent-watch", daemon=True).start()


def run_local(
    pool, workers: int, handoff: str, tasks: list[tuple], done: Callable[[int], object] | None = None
) -> list:
    """Run independent tasks [(fn, *args), ...] on `pool` (`workers` processes) under Dask's
    local process scheduler (dask.multiprocessing.get) and return their results in list
    order. Tasks start in list order, one per process at a time (a process takes the next
    when it is free); `done(i)` is called here as task i finishes; a task's exception is
    raised here. Each result comes back as a pickle file in `handoff` whose path is all that
    crosses the pool's shared result pipe: a worker killed while writing a 44 MB prototype into
    that pipe would leave half a message that its reader waits on for ever (a path is one
    atomic write); and the prototype is pickled once, not cloudpickled to bytes by Dask and
    pickled again by the pool."""
    import dask.multiprocessing
    from dask.callbacks import Callback

    keys = [("treegen-task", i) for i in range(len(tasks))]
    out: list = [None] * len(tasks)

    def in_order(_dsk, state) -> None:  # Dask pops its next task from the end of the list
        state["ready"].sort(key=lambda key: -key[1])

    def finished(key, path, _dsk, _state, _worker) -> None:
        with open(path, "rb") as f:
            out[key[1]] = pickle.load(f)
        os.unlink(path)
        if done is not None:
            done(key[1])

    graph = {k: (_to_file, handoff, *task) for k, task in zip(keys, tasks)}
    with Callback(start_state=in_order, posttask=finished), _died_as_error(workers):
        dask.multiprocessing.get(
            graph,
            keys,
            num_workers=workers,
            pool=pool,
            chunksize=1,
            optimize_graph=False,
            func_dumps=_as_is,
            func_loads=_as_is,
        )
    return out


def _to_file(directory: str, fn, *args) -> str:
    """In a worker: fn(*args), pickled into a new file in `directory`; its path."""
    result = fn(*args)
    fd, path = tempfile.mkstemp(dir=directory, suffix=".pickle")
    with os.fdopen(fd, "wb") as f:
        pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
    return path


@contextlib.contextmanager
def _died_as_error(workers: int):
    """A worker process that dies (killed, out of memory) breaks the pool: say so in one line."""
    from concurrent.futures.process import BrokenProcessPool

    try:
        yield
    except BrokenProcessPool:
        raise TreegenError(
            f"a worker process died while building (killed, or out of memory?), or its "
            "result could not be read; "
            f"rerun, with fewer --workers than {workers} if memory is short"
        ) from None


def _as_is(x):
    return x


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
