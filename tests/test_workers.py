"""Pool workers: one BLAS thread each (one worker = one core), and no private pool internals."""

from __future__ import annotations

import os

from grainforge.runtime.workers import THREAD_VARS, ordered_map


def test_pool_workers_get_one_blas_thread():
    """The fork server preloads NumPy once for all workers, so it must start with the thread
    limits: before the fix it started outside them and every worker ran multithreaded BLAS
    (analyse used 2x the CPU per grain on 2 workers)."""
    expect = [os.environ.get(var, "1") for var in THREAD_VARS]
    got = list(ordered_map(os.getenv, list(THREAD_VARS), workers=2, preload=["numpy"]))
    assert got == expect


#: private names of the standard library workers.py may use, by the top-level function using them
#: (``os._exit`` is public API)
ALLOWED_PRIVATE = {"*": {"_exit"}, "_unblock_result_reader": {"_result_queue", "_writer"}}


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


def test_private_standard_library_internals_stay_in_one_documented_place():
    """workers.py stops pools through public API; the one private attribute it still needs (the
    pool's result pipe) is read in ``_unblock_result_reader`` only."""
    import inspect

    import grainforge.runtime.workers as workers

    assert private_names(inspect.getsource(workers)) == []
    # the detector sees what the pools used to read
    old = "def close_pool(pool):\n    ps = pool._processes\n    w = getattr(pool._result_queue, '_writer')\n"
    assert sorted(private_names(old)) == [("close_pool", "_processes"), ("close_pool", "_result_queue"),
                                  ("close_pool", "_writer")]
