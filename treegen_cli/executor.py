"""Where many builds run: a Dask cluster, embedded or remote, behind one context manager.

    with dask_client(scheduler=None, workers=2) as (client, where):
        futures = [client.submit(fn, *args) for ...]

No scheduler (and no DASK_SCHEDULER_ADDRESS): an embedded cluster with one single-threaded
worker process per core (the pipeline is numpy-bound and holds the GIL between calls, so
processes, not threads), started from a fork server, or (`fork=True`, the forest) forked
from this process while that is safe (can_fork). With an address: the same jobs go to an
existing cluster, whose workers must see the same file system paths (outputs are written by
the workers).
Closing the block closes the client and, if embedded, the cluster and its processes.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable

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
def dask_client(
    scheduler: str | None = None,
    workers: int | None = None,
    fork: bool = False,
    warm: Callable[[], object] | None = None,
):
    """Yield (client, description); the cluster is closed on exit, even on Ctrl-C.

    The embedded cluster's workers start from a fork server (STARTUP): a fork of this process
    once its event loop runs can inherit a held lock and hang. With `fork` (the forest) and
    while can_fork(), they are forked from this process instead, before the scheduler's loop
    starts: they inherit everything imported here and are ready at once, where the fork
    server is a fresh interpreter importing it all again (~1 s of CPU). Such workers have no
    nanny (not restarted if they die: their tasks go to the others). `warm`, called just
    before they are forked (and only then), does work each of them would otherwise repeat
    (the forest: species textures); they inherit its result."""
    address = scheduler_address(scheduler)
    n = workers or default_workers()
    forked = fork and not address and can_fork()
    if not address and not forked:
        start_fork_server()  # first: its imports overlap ours below
    import dask
    from distributed import Client

    if forked and warm is not None:
        warm()
    if forked and not can_fork():  # the imports (or warm) started a thread after all
        forked = False
        start_fork_server()
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
    config: dict = {
        f"distributed.nanny.pre-spawn-environ.{TRIM}": None,
        **QUIET,
        **STARTUP,
    }
    if forked:  # no nanny restarts them: should all die, their tasks fail instead of waiting
        config["distributed.scheduler.no-workers-timeout"] = "60s"
    with dask.config.set(config), contextlib.ExitStack() as stack:
        # Worker processes inherit an ignored SIGINT (Python keeps SIG_IGN across fork and
        # exec), so a Ctrl-C reaches only this process, which then closes the cluster in
        # order; without this every worker prints its own KeyboardInterrupt traceback.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            send_address = stack.enter_context(forked_workers(n)) if forked else None
            cluster = _local_cluster(0 if forked else n)
        finally:
            signal.signal(signal.SIGINT, previous)
        stack.callback(cluster.close)
        if send_address is not None:
            send_address(cluster.scheduler_address)
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
def forked_workers(n: int):
    """Fork `n` processes that each wait for the scheduler's address on a pipe and then run
    one single-threaded Dask worker until the scheduler closes it (or this process goes: the
    pipe's end then closes and they exit); yields `send(address)`, which tells them all. On
    exit, wait for them (then kill stragglers)."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    pipes = [ctx.Pipe(duplex=False) for _ in range(n)]
    mine = [w for _r, w in pipes]
    processes = []
    try:
        for k, (r, _w) in enumerate(pipes):
            p = ctx.Process(
                target=_worker_main, args=(r, mine, n, k), name=f"treegen-worker-{k}", daemon=True
            )
            p.start()
            processes.append(p)
        for r, _w in pipes:
            r.close()

        def send(address: str) -> None:
            for pipe in mine:
                pipe.send(address)

        yield send
    finally:
        for w in mine:
            w.close()
        for p in processes:
            p.join(10)
            if p.exitcode is None:
                p.kill()
                p.join()


def _worker_main(pipe, parents, n: int, k: int) -> None:
    """In a forked process: wait for the scheduler's address, then serve as a Dask worker."""
    import asyncio

    for w in parents:  # this process keeps no write end: EOF then means the client is gone
        w.close()
    logging.getLogger("distributed").setLevel(logging.CRITICAL)  # as the nannies' workers
    try:
        address = pipe.recv()
    except EOFError:
        return

    def watch() -> None:
        try:
            pipe.recv()
        except (EOFError, OSError):
            pass
        os._exit(0)

    threading.Thread(target=watch, name="treegen-parent-watch", daemon=True).start()

    async def serve() -> None:
        from distributed import Worker

        async with Worker(
            address,
            nthreads=1,
            host="127.0.0.1",
            dashboard=False,
            memory_limit=1.0 / n,
            name=f"forked-{k}",
            silence_logs=logging.CRITICAL,
        ) as worker:
            await worker.finished()

    asyncio.run(serve())


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
