"""Pool workers run one BLAS thread each (one worker = one core)."""

from __future__ import annotations

import os

from grainforge.workers import THREAD_VARS, ordered_map


def test_pool_workers_get_one_blas_thread():
    """The fork server preloads NumPy once for all workers, so it must start with the thread
    limits: before the fix it started outside them and every worker ran multithreaded BLAS
    (analyse used 2x the CPU per grain on 2 workers)."""
    expect = [os.environ.get(var, "1") for var in THREAD_VARS]
    got = list(ordered_map(os.getenv, list(THREAD_VARS), 2, preload=["numpy"]))
    assert got == expect
