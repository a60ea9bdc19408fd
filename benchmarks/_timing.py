"""Timing helpers shared by the benchmark scripts (``from _timing import ...``).

Benchmarks run as scripts (``.venv/bin/python benchmarks/bench_x.py``), so this folder is on
``sys.path``. On a shared machine the process is time-sliced: the CPU time of this process is
then the better estimate of the one-core cost, and the load average says how shared it was.
"""

from __future__ import annotations

import os
import time

# NumPy is imported inside the functions: ``one_core()`` must run before NumPy loads its BLAS.

__all__ = ["one_core", "samples", "load"]


def one_core() -> None:
    """Limit BLAS/OpenMP to one thread (call before importing NumPy's users' heavy modules)."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def samples(fn, repeat: int, number: int = 1, warmup: bool = True):
    """Per-call wall and CPU seconds (two NumPy arrays) of ``repeat`` runs of ``number`` calls of ``fn``.

    One call is made first (and not timed) if ``warmup``.
    """
    import numpy as np

    if warmup:
        fn()
    wall, cpu = [], []
    for _ in range(int(repeat)):
        t, c = time.perf_counter(), time.process_time()
        for _ in range(int(number)):
            fn()
        wall.append((time.perf_counter() - t) / number)
        cpu.append((time.process_time() - c) / number)
    return np.array(wall), np.array(cpu)


def load() -> str:
    """``"load average a, b, c"`` of this machine now."""
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg())
