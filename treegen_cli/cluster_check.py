"""What a remote Dask cluster must be before a job goes to it: reachable at a well-formed
address, with workers that run this very treegen (the same files) on the same OpenBLAS kernel,
so every asset it builds is byte-identical to `treegen make` here.

    reachable("tcp://10.0.0.5:8786", "--scheduler tcp://10.0.0.5:8786")
    n = check_workers(client, address, label)   # Result: 4 (workers), or a TreegenError

The kernel matters because `dask worker` loads numpy before treegen can pin OpenBLAS's kernel
(blas_kernel.py): an AVX-512 node then runs SkylakeX, whose last bits differ from the Haswell
kernel treegen asks for, and one float32 key in a fan palm's trunk came out one step apart.
"""

from __future__ import annotations

import re
import socket

from .errors import TreegenError

SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[^\]]+\]|[^:/\s]+):(?P<port>\d{1,5})$")


def address_label(scheduler: str | None, address: str) -> str:
    """How an error names the address: the flag, or the variable it came from."""
    return f"--scheduler {address}" if scheduler else f"{SCHEDULER_ENV}={address}"


def reachable(address: str, label: str, timeout_s: float = 5.0) -> None:
    """Refuse an address that is not [SCHEME://]HOST:PORT, or a TCP one nothing listens at,
    in one line and at once (Dask would retry for 20 s and print a traceback on the way out)."""
    m = _ADDRESS.match(address.strip())
    if m is None or not 0 < int(m["port"]) < 65536:
        raise TreegenError(
            f"{label}: not a scheduler address; give tcp://HOST:PORT (`dask scheduler` listens on 8786)"
        )
    if (m["scheme"] or "tcp") != "tcp":
        return  # tls://, ucx://, ...: Dask knows how to reach those
    try:
        socket.create_connection((m["host"].strip("[]"), int(m["port"])), timeout=timeout_s).close()
    except OSError as e:
        raise TreegenError(
            f"{label}: cannot connect to a Dask scheduler ({e.strerror or type(e).__name__}); "
            "start one with `dask scheduler`"
        ) from None


def treegen_version() -> str:
    """Run on each worker by check_workers (by reference: it fails where treegen_cli is
    not importable, which is the point)."""
    from .build_id import build_id

    return build_id()


def blas_kernels() -> str:
    """The OpenBLAS kernels this process's numpy and scipy run (as threadpoolctl found them when
    treegen's wind module loaded), e.g. "Haswell"; run on each worker by check_workers."""
    from .wind import _BLAS

    found = {str(c.architecture) for c in _BLAS.lib_controllers if c.internal_api == "openblas"}
    return "/".join(sorted(found)) or "none"


def check_workers(client, address: str, label: str = "", wait_s: float = 30.0) -> int:
    """Refuse a cluster whose workers cannot run our jobs, before any is sent: no worker
    (after `wait_s`), a worker without treegen_cli, one with another treegen version (whose
    bytes could differ from `treegen make` here: same version and same package files,
    build_id) or on another OpenBLAS kernel. Returns the number of workers."""
    from . import __version__
    from .build_id import build_id

    label = label or f"--scheduler {address}"
    here = build_id()
    try:
        client.wait_for_workers(1, timeout=wait_s)
    except TimeoutError:
        raise TreegenError(
            f"{label}: no worker joined within {wait_s:g} s; start some with `dask worker {address}`"
        ) from None
    found = client.run(treegen_version, on_error="return")
    for worker, v in sorted(found.items()):
        if isinstance(v, BaseException):
            raise TreegenError(
                f"{label}: worker {worker} cannot run treegen ({type(v).__name__}: {v}); "
                f"install treegen {__version__} on every worker"
            ) from None
        if v != here:
            raise TreegenError(
                f"{label}: worker {worker} has treegen {v}, this is {here}; install the same "
                "version (the same files) on every worker"
            )
    check_kernels(client.run(blas_kernels, on_error="return"), blas_kernels(), address, label)
    return len(found)


def check_kernels(kernels: dict, here: str, address: str, label: str) -> None:
    """Refuse workers whose OpenBLAS kernels (`kernels`: worker → blas_kernels()) would give
    other bits: a worker without OpenBLAS, workers that disagree, or (this process running
    OpenBLAS on x86-64, as the workers do) a kernel other than `here`'s, so a batch's assets
    are `treegen make`'s here. A client on another architecture (a laptop on ARM) only needs
    its workers to agree."""
    import platform

    from .blas_kernel import KERNEL

    pin = here.split("/")[0] if here != "none" else KERNEL
    start = f"start every worker with `OPENBLAS_CORETYPE={pin} dask worker {address} ...`"
    for worker, k in sorted(kernels.items()):
        if isinstance(k, BaseException) or k == "none":
            raise TreegenError(
                f"{label}: worker {worker} runs no OpenBLAS (a numpy built on another BLAS): its "
                "trees would differ in the last bits; install numpy's PyPI wheels there"
            )
    seen = sorted(set(kernels.values()))
    if len(seen) > 1:
        a, b = (next(w for w, k in sorted(kernels.items()) if k == x) for x in seen[:2])
        raise TreegenError(
            f"{label}: worker {a} runs OpenBLAS's {kernels[a]} kernel, worker {b} {kernels[b]}: "
            f"their trees would differ in the last bits; {start}"
        )
    x86 = platform.machine().lower() in ("x86_64", "amd64")
    if seen and here != "none" and x86 and seen[0] != here:
        worker = sorted(kernels)[0]
        raise TreegenError(
            f"{label}: worker {worker} runs OpenBLAS's {seen[0]} kernel, this process {here}: "
            f"their trees would differ in the last bits; {start}"
        )
