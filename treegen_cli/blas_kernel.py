"""The same bytes on every x86-64 machine: pin OpenBLAS's kernel before numpy loads it.

OpenBLAS picks a kernel for the CPU it finds (SkylakeX on AVX-512, Haswell on AVX2, Zen, ...);
their results differ in the last bits, and the wind's eigen solve carries those bits into a few
float32 keys, so a tree built on one node of a cluster would not match the same tree built on
another. Every AVX2 CPU runs the Haswell kernel, so treegen asks for it there. Set
OPENBLAS_CORETYPE yourself to choose otherwise; other architectures are left alone.
"""

from __future__ import annotations

import os
import platform
import sys

KERNEL = "Haswell"
NEEDS = {"avx2", "fma"}  # the instructions the Haswell kernel uses


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin_kernel() -> bool:
    """Set OPENBLAS_CORETYPE for this process and its children (Dask workers, subprocesses);
    True when it takes effect here, i.e. numpy was not loaded yet."""
    if "OPENBLAS_CORETYPE" in os.environ:
        return "numpy" not in sys.modules
    if platform.machine().lower() not in ("x86_64", "amd64") or not NEEDS <= _cpu_flags():
        return False
    os.environ["OPENBLAS_CORETYPE"] = KERNEL
    return "numpy" not in sys.modules
