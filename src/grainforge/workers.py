"""Process pools for the local parallel jobs (batch, tray, calibration).

Two habits every pool shares:

- workers fork from a *fork server* that has imported the heavy modules once
  (``spawn`` where there is no fork server), so starting a worker costs
  milliseconds instead of a fresh interpreter's imports, and no state of the
  parent (open files, threads) leaks into them;
- workers run NumPy's BLAS single-threaded (unless the user set the thread
  variables): OpenBLAS otherwise starts one thread per core in *every*
  worker, so N workers would run N × cores busy threads on the cores.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator, Sequence

__all__ = ["process_pool", "single_threaded_children", "THREAD_VARS"]

#: BLAS/OpenMP thread limits given to pool workers (unless the user set them): one worker = one core.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def single_threaded_children() -> Iterator[None]:
    """Set the BLAS thread limits to 1 while worker processes start, then restore them.

    Workers (and the fork server) start when the first tasks are submitted,
    so wrap those submissions.

    Examples
    --------
    >>> import os
    >>> before = os.environ.get("OMP_NUM_THREADS")
    >>> with single_threaded_children():
    ...     inside = os.environ["OMP_NUM_THREADS"]
    >>> inside if before is None else "1"
    '1'
    >>> os.environ.get("OMP_NUM_THREADS") == before
    True
    """
    saved = {k: os.environ.get(k) for k in THREAD_VARS}
    for k, v in saved.items():
        if v is None:
            os.environ[k] = "1"
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)


def process_pool(workers: int, preload: Sequence[str] = ()):
    """A ``ProcessPoolExecutor`` of ``workers`` processes started from a fork server.

    Parameters
    ----------
    workers : int
    preload : sequence of str
        Modules the fork server imports once, before forking the workers.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))
    else:
        ctx = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx)
