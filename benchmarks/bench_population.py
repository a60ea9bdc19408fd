"""Population runner: throughput with 1 and 2 local workers, and the runner's per-grain overhead.

Prints figures; asserts nothing about time.  Run on an otherwise idle machine:

    .venv/bin/python benchmarks/bench_population.py [--count 64] [--subdivisions 5]

- generation time: ``make_grain`` called in a plain loop (draw, generate, scale to size, measure,
  encode), i.e. what any loop over grains must do;
- runner overhead: in an in-process batch (files written atomically, SHA-256, sidecar journal,
  manifest; report excluded), the batch's wall time minus the time spent inside ``make_grain``
  during that same batch, per grain and as a fraction of the generation time;
- throughput: grains/s of ``run_batch`` with a pool of 1 and of 2 worker processes (pool start-up
  included), and the speed-up.

BLAS is limited to one thread in this process too (set before NumPy loads), as in pool workers, so
that "one worker" means one core everywhere.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import shutil
import tempfile
import time
from pathlib import Path

import grainforge.population.batch as runner  # noqa: E402  (run_batch looks make_grain up here)
from grainforge.population import make_grain, parse_recipe, run_batch  # noqa: E402

RECIPE = """\
method = "fso"
count = {count}
seed = 7
[params]
fractal_dimension = {{ distribution = "uniform", low = 2.2, high = 2.6 }}
subdivisions = {subdivisions}
[size]
definition = "equivalent"
distribution = "lognormal"
median_mm = 5.0
sigma = 0.2
"""


def _burn(n: int) -> int:
    s = 0
    for i in range(n):
        s += i * i
    return s


def machine_parallelism() -> float:
    """Control: speed-up of a pure-Python CPU burn with 2 processes vs 1 (about 2 on an idle 2-core machine)."""
    from concurrent.futures import ProcessPoolExecutor

    times = []
    for w in (1, 2):
        with ProcessPoolExecutor(w) as ex:
            list(ex.map(_burn, [10] * w))
            t = time.perf_counter()
            list(ex.map(_burn, [2_000_000] * 8))
            times.append(time.perf_counter() - t)
    return times[0] / times[1]


def runner_overhead(recipe, tmp: Path) -> tuple[float, float]:
    """(batch wall time, time inside make_grain) of one in-process batch."""
    spent = []

    def timed(r, i):
        t = time.perf_counter()
        res = make_grain(r, i)
        spent.append(time.perf_counter() - t)
        return res

    runner.make_grain = timed
    try:
        total = timed_batch(recipe, 1, tmp, True)
    finally:
        runner.make_grain = make_grain
    return total, sum(spent)


def timed_batch(recipe, workers: int, tmp: Path, in_process: bool) -> float:
    out = tmp / f"w{workers}-{in_process}"
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    run_batch(recipe, out, workers=workers, report=False, in_process=in_process)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=64)
    ap.add_argument("--subdivisions", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    recipe = parse_recipe(RECIPE.format(count=a.count, subdivisions=a.subdivisions))
    print(f"FSO population: {a.count} grains, subdivisions {a.subdivisions}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f} at start")
    make_grain(recipe, 0)  # warm imports and caches
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        # start the fork server (once per process) before timing
        timed_batch(parse_recipe(RECIPE.format(count=2, subdivisions=a.subdivisions)), 2, tmp, False)
        loop, over, one, two = [], [], [], []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            for i in range(recipe.count):
                make_grain(recipe, i)
            loop.append(time.perf_counter() - t0)
            total, inside = runner_overhead(recipe, tmp)
            over.append((total - inside) / inside)
            one.append(timed_batch(recipe, 1, tmp, False))
            two.append(timed_batch(recipe, 2, tmp, False))
        t_loop, t1, t2 = min(loop), min(one), min(two)
        t0 = time.perf_counter()
        from grainforge.population.report import population_report

        rows = run_batch(recipe, tmp / "w1-True", resume=True, report=False)["rows"]
        population_report(recipe, rows, tmp / "w1-True")
        t_report = time.perf_counter() - t0
    n = recipe.count
    gen = t_loop / n
    over = min(over)
    over_pool = (t1 - t_loop) / n
    print(f"generation (plain loop):     {1e3 * gen:8.1f} ms/grain")
    print(f"runner overhead, in-process: {1e3 * over * gen:8.1f} ms/grain = {100 * over:5.1f} % of generation")
    print(f"1-process pool vs plain loop: {1e3 * over_pool:+7.1f} ms/grain = {100 * over_pool / gen:+5.1f} % "
          "(IPC, start-up; difference of two timings, noisy)")
    print(f"batch, 1 worker (pool):      {n / t1:8.2f} grains/s ({t1:.2f} s)")
    print(f"batch, 2 workers:            {n / t2:8.2f} grains/s ({t2:.2f} s, pool start-up included)")
    print(f"speed-up 2 vs 1 worker:      {t1 / t2:8.2f}x")
    print(f"control: CPU burn 2 vs 1 process {machine_parallelism():5.2f}x (what the machine allows now)")
    print(f"resume check + report (once): {t_report:6.2f} s")
    print(f"load average at end {os.getloadavg()[0]:.2f} (best of {a.repeats} repeats)")


if __name__ == "__main__":
    main()
