"""Pool workers: one BLAS thread each (one worker = one core), no private pool internals, results in order,
errors raised for their item, and a pool stopped at once, whenever it is stopped, leaving no process."""

from __future__ import annotations

import os
import signal
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest

from grainforge.params import ParameterError
from grainforge.runtime.children import THREAD_VARS, pid_alive
from grainforge.runtime.workers import RemoteTraceback, ordered_map, process_pool


def test_pool_workers_get_one_blas_thread():
    """The fork server preloads NumPy once for all workers, so it must start with the thread
    limits: before the fix it started outside them and every worker ran multithreaded BLAS
    (analyse used 2x the CPU per grain on 2 workers)."""
    expect = [os.environ.get(var, "1") for var in THREAD_VARS]
    got = list(ordered_map(os.getenv, list(THREAD_VARS), workers=2, preload=["numpy"]))
    assert got == expect


#: private names of the standard library workers.py may use, by the top-level function using them
#: (``os._exit`` is public API): none
ALLOWED_PRIVATE = {"*": {"_exit"}}


def private_names(source: str) -> list[tuple[str, str]]:
    """(top-level definition, name) of every ``obj._name`` and ``getattr(obj, "_name")`` not allowed."""
    import ast

    found = []
    for top in ast.parse(source).body:
        where = getattr(top, "name", "<module>")
        allowed = ALLOWED_PRIVATE["*"] | ALLOWED_PRIVATE.get(where, set())
        for node in ast.walk(top):
            names = [node.attr] if isinstance(node, ast.Attribute) else []
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "getattr" and len(node.args) > 1 \
                    and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str):
                names.append(node.args[1].value)
            found += [(where, n) for n in names if n.startswith("_") and not n.startswith("__") and n not in allowed]
    return found


def test_workers_use_no_private_standard_library_internals():
    """workers.py makes and stops pools through documented calls only: no ``obj._name`` anywhere (it used to
    read a ``ProcessPoolExecutor``'s result pipe, ``pool._result_queue._writer``)."""
    import inspect

    import grainforge.runtime.children as children
    import grainforge.runtime.workers as workers

    assert private_names(inspect.getsource(workers)) == []
    assert private_names(inspect.getsource(children)) == []
    # the detector sees what the pools used to read
    old = "def close_pool(pool):\n    ps = pool._processes\n    w = getattr(pool._result_queue, '_writer')\n"
    assert sorted(private_names(old)) == [("close_pool", "_processes"), ("close_pool", "_result_queue"),
                                  ("close_pool", "_writer")]


# --------------------------------------------------------------------------- the pool's contract

#: seconds a stopped pool may take to be gone: the contract says 2 (measured: tens of ms), the margin is for a
#: machine loaded by other jobs, as in tests/cli/test_cli_signals.py
STOP_WITHIN = 5.0


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise ParameterError("x", "three is refused")
    return x * x


def test_results_come_in_order_and_an_error_is_raised_for_its_item():
    """The squares in input order on 2 workers (the same as in this process), then the worker's own exception,
    with its message and the worker's traceback as its cause; the workers are gone after either."""
    assert list(ordered_map(_fail_on_three, [5, 1, 4, 2], workers=2)) == [25, 1, 16, 4]
    got = []
    with pytest.raises(ParameterError, match="three is refused") as info:
        for y in ordered_map(_fail_on_three, range(10), workers=2):
            got.append(y)
    assert got == [0, 1, 4]
    assert isinstance(info.value.__cause__, RemoteTraceback) and "_fail_on_three" in str(info.value.__cause__)
    with process_pool(2) as pool:
        assert list(pool.map(_fail_on_three, [6, 7, 8, 9, 10], chunksize=2)) == [36, 49, 64, 81, 100]
        procs = pool.processes()
    assert len(procs) == 2 and all(p.exitcode == 0 for p in procs)


def test_an_interrupt_stops_busy_workers_at_once():
    """Ctrl-C inside the pool's block while both workers run 30 s tasks: the block is left at once, both workers
    are gone, the queued tasks are cancelled and the running ones fail."""
    with pytest.raises(KeyboardInterrupt):
        with process_pool(2) as pool:
            futures = [pool.submit(time.sleep, 30) for _ in range(4)]
            deadline = time.monotonic() + 60
            while sum(f.running() for f in futures) < 2 and time.monotonic() < deadline:
                time.sleep(0.01)
            procs = pool.processes()
            sent = time.monotonic()
            raise KeyboardInterrupt
    took = time.monotonic() - sent
    assert took < STOP_WITHIN, f"the pool took {took:.1f} s to stop"
    assert len(procs) == 2 and not any(pid_alive(p.pid) for p in procs)
    assert [f.cancelled() for f in futures] == [False, False, True, True]
    assert all(isinstance(f.exception(), BrokenProcessPool) for f in futures[:2])


def _die_mid_answer():
    """Write the start of an answer of 1 MiB on the worker's pipe, then die: a worker killed while sending."""
    import gc
    import multiprocessing.connection
    import struct

    (conn,) = [o for o in gc.get_objects()
               if isinstance(o, multiprocessing.connection.Connection) and not o.closed and o.writable]
    os.write(conn.fileno(), struct.pack("!i", 1 << 20) + bytes(1000))
    os._exit(1)


def test_a_worker_that_dies_while_it_answers_breaks_the_pool_without_a_hang():
    """The reason the pool keeps no copy of a worker's pipe end: a worker that dies after sending part of its
    answer must end the read here (a standard pool waited for the rest for ever, and the interpreter at exit).
    Its task and the queued ones raise BrokenProcessPool; closing the pool returns at once."""
    pool = process_pool(2)
    with pytest.raises(BrokenProcessPool, match=r"exit code 1"):
        with pool:
            slow = pool.submit(time.sleep, 30)
            pool.submit(_die_mid_answer).result(timeout=60)
    assert isinstance(slow.exception(timeout=STOP_WITHIN), BrokenProcessPool)
    with pytest.raises(BrokenProcessPool):
        pool.submit(abs, -1)
    assert not any(pid_alive(p.pid) for p in pool.processes())


_CUT_SHORT = """
import os, sys, time
sys.path.insert(0, {folder!r})
from grainforge.runtime.workers import process_pool
try:
    with process_pool(2, ["slow_to_import"]) as pool:  # the fork server imports it for 30 s
        futures = [pool.submit(abs, -k) for k in range(4)]
        time.sleep(1.0)
        print(len(pool.processes()), flush=True)  # 0: the first worker is still on its way
        raise KeyboardInterrupt
except KeyboardInterrupt:
    print("stopped", flush=True)
"""


def test_a_pool_stopped_while_its_fork_server_imports_leaves_no_process(tmp_path):
    """Ctrl-C while the fork server still imports its preload (a first worker asked for, not started): the pool
    is left at once, and the fork server and the worker on its way are gone, none adopted by init; the
    program's exit prints nothing else."""
    import subprocess
    import sys

    from _processes import session_processes

    (tmp_path / "slow_to_import.py").write_text("import time\ntime.sleep(30)\n")
    proc = subprocess.Popen([sys.executable, "-c", _CUT_SHORT.format(folder=str(tmp_path))], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert proc.stdout.readline() == "0\n"
        assert proc.stdout.readline() == "stopped\n"
        stopped = time.monotonic()
        out, err = proc.communicate(timeout=60)  # until every process holding its pipes is gone
        took = time.monotonic() - stopped
        assert (proc.returncode, out, err) == (0, "", ""), (out, err)
        assert took < STOP_WITHIN, f"processes held the program's pipes {took:.1f} s after the pool stopped"
        while session_processes(proc.pid) and time.monotonic() - stopped < STOP_WITHIN:
            time.sleep(0.05)  # multiprocessing's resource tracker leaves as it sees the program gone
        left = {pid: Path(f"/proc/{pid}/cmdline").read_bytes() for pid in session_processes(proc.pid)}
        assert left == {}
    finally:
        for pid in session_processes(proc.pid):
            os.kill(pid, signal.SIGKILL)
