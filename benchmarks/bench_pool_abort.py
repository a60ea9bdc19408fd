"""Stopping a process pool while its workers send large results: does the stop return, and how fast?

The evidence behind ``grainforge.runtime.workers``' own pool (docs/design/architecture.md, "Worker pools").
Each run makes a pool of 2 workers whose tasks return 4 MB each (so a result takes a while to cross the
pipe), lets it work for 50-250 ms (seeded), stops it from a helper thread and waits up to 5 s for the stop
to return:

- ``--pool grainforge``: :func:`grainforge.runtime.workers.process_pool`, stopped with ``close_pool(pool,
  abort=True)`` (what leaving its ``with`` block on Ctrl-C does);
- ``--pool stdlib``: ``multiprocessing.Pool`` on the same fork server context, stopped with its documented
  ``terminate()``.  A worker stopped while it sends a result leaves the pool's result handler reading the
  rest of the message for ever (this process holds the write end of the shared result pipe too), and
  ``terminate()`` joins that thread: such a run is counted as hung.

Usage: ``python benchmarks/bench_pool_abort.py --pool stdlib --runs 300`` (about 2 min on 2 cores; a hung
run's threads are left behind, and the script ends with ``os._exit``).
"""

from __future__ import annotations

import argparse
import os
import random
import threading
import time


def big_result(i: int) -> bytes:
    time.sleep(random.random() * 0.004)
    return bytes(4_000_000)


def one_run(kind: str, seed: int) -> float | None:
    """Seconds the stop took, or None if it had not returned after 5 s."""
    random.seed(seed)
    if kind == "stdlib":
        import multiprocessing

        pool = multiprocessing.get_context("forkserver").Pool(2)
        for i in range(400):
            pool.apply_async(big_result, (i,))
        stop = pool.terminate
    else:
        from grainforge.runtime.workers import close_pool, process_pool

        pool = process_pool(2)
        for i in range(400):
            pool.submit(big_result, i)

        def stop():
            close_pool(pool, abort=True)

    time.sleep(0.05 + random.random() * 0.2)
    thread = threading.Thread(target=stop, daemon=True)
    start = time.monotonic()
    thread.start()
    thread.join(5.0)
    return None if thread.is_alive() else time.monotonic() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pool", choices=["grainforge", "stdlib"], default="grainforge")
    parser.add_argument("--runs", type=int, default=100)
    args = parser.parse_args()
    times, hung = [], []
    for seed in range(args.runs):
        took = one_run(args.pool, seed)
        if took is None:
            hung.append(seed)
        else:
            times.append(took)
    times.sort()
    print(f"{args.pool}: {len(hung)}/{args.runs} stops hung (> 5 s){f', runs {hung}' if hung else ''}; "
          f"the others took median {times[len(times) // 2] * 1000:.0f} ms, slowest {times[-1] * 1000:.0f} ms")
    os._exit(0)  # a hung run's threads would keep the interpreter from exiting


if __name__ == "__main__":
    main()
