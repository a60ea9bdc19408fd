"""CPU seconds of the test suite, per test file and per test.

Runs pytest (any arguments after ``--``) with this file loaded as a plugin that
records, for every test, the CPU time of the pytest process and of the child
processes it waited for (commands, engines, ``mpirun``), and the wall time;
then prints the per-file table (tests, CPU s, wall s) and the costliest tests.

CPU seconds are the figure to compare on a shared machine: wall time grows with
the load, CPU time hardly does.  Not counted: the collection and import time of
each pytest process, and processes nobody waits for.

Usage::

    .venv/bin/python benchmarks/suite_cpu.py [--top 30] [--markdown] -- -n 2 -m "not slow"
    .venv/bin/python benchmarks/suite_cpu.py -- -n 0 tests/cli/test_cli_contract.py
"""

from __future__ import annotations

import os
import time

_ROWS: list[tuple[str, float, float]] = []


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _hookwrapper(fn):
    import pytest

    return pytest.hookimpl(hookwrapper=True)(fn)


try:  # the plugin side (loaded by pytest with -p suite_cpu)
    import pytest as _pytest  # noqa: F401

    @_hookwrapper
    def pytest_runtest_protocol(item, nextitem):
        c0, w0 = _cpu(), time.perf_counter()
        yield
        _ROWS.append((item.nodeid, _cpu() - c0, time.perf_counter() - w0))

    def pytest_sessionfinish(session):
        out = os.environ.get("SUITE_CPU_OUT")
        if not out:
            return
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        with open(os.path.join(out, f"{worker}.tsv"), "w", encoding="utf-8") as f:
            for name, cpu, wall in _ROWS:
                f.write(f"{name}\t{cpu:.3f}\t{wall:.3f}\n")
except ImportError:  # pragma: no cover - pytest is a test extra
    pass


def summarise(folder: str) -> tuple[dict[str, list[float]], list[tuple[str, float, float]]]:
    """Per-file ``[tests, cpu, wall]`` and every ``(test, cpu, wall)`` from the workers' files."""
    rows = []
    for name in sorted(os.listdir(folder)):
        with open(os.path.join(folder, name), encoding="utf-8") as f:
            for line in f:
                test, cpu, wall = line.rstrip("\n").split("\t")
                rows.append((test, float(cpu), float(wall)))
    files: dict[str, list[float]] = {}
    for test, cpu, wall in rows:
        agg = files.setdefault(test.split("::")[0], [0, 0.0, 0.0])
        agg[0] += 1
        agg[1] += cpu
        agg[2] += wall
    return files, rows


def main(argv: list[str] | None = None) -> int:
    import argparse
    import subprocess
    import sys
    import tempfile

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--top", type=int, default=30, help="costliest tests to list")
    ap.add_argument("--markdown", action="store_true", help="print the file table as Markdown")
    ap.add_argument("pytest_args", nargs="*", help="arguments for pytest (after --)")
    args = ap.parse_args(argv)
    here = os.path.dirname(os.path.abspath(__file__))
    with tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, SUITE_CPU_OUT=out,
                   PYTHONPATH=os.pathsep.join(filter(None, [here, os.environ.get("PYTHONPATH")])))
        t0, c0 = time.perf_counter(), _cpu()
        code = subprocess.call([sys.executable, "-m", "pytest", "-p", "suite_cpu", *args.pytest_args], env=env)
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
        files, rows = summarise(out)
    sep = "|" if args.markdown else "\t"
    print()
    if args.markdown:
        print("| file | tests | CPU s | wall s |\n|---|---:|---:|---:|")
    else:
        print("file\ttests\tCPU s\twall s")
    for name, (n, c, w) in sorted(files.items(), key=lambda kv: -kv[1][1]):
        cells = [name, str(n), f"{c:.1f}", f"{w:.1f}"]
        print(f"| {' | '.join(cells)} |" if args.markdown else sep.join(cells))
    print(f"\n{len(rows)} tests: {sum(r[1] for r in rows):.1f} CPU s in the tests; the whole run "
          f"{cpu:.1f} CPU s (with collection) in {wall:.1f} s wall, pytest exit {code}")
    print(f"\ncostliest {args.top} tests (CPU s, wall s):")
    for test, c, w in sorted(rows, key=lambda r: -r[1])[: args.top]:
        print(f"{c:7.1f} {w:7.1f}  {test}")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
