"""FSO timings: the Weierstrass–Mandelbrot kernel, one whole grain, and a 100-grain CLI run.

Targets: one FSO grain at subdivisions 5 (10,242 vertices, M = n_max = 40)
in ≤ 60 ms on one core, ≥ 10× faster than the straightforward float64 NumPy
evaluation of the same double sum (``wm_sum_reference``) in the same run, with
radii within 1e-4·R0 of it; ``grainforge generate fso --count 100 --subdivisions 4``
in under 15 s wall time.

Prints figures (best of several repeats; the machine is shared, so the load
average is printed before and after); asserts nothing.  One core: BLAS/OpenMP
threads are limited to 1 here and in the CLI subprocess.

Run: ``.venv/bin/python benchmarks/bench_fso.py [--quick]``.
"""

from __future__ import annotations

import os

from _timing import load, one_core, samples

one_core()

import argparse  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402


def best(fn, repeat):
    """Smallest wall time and smallest CPU time of ``repeat`` calls (after one warm-up call).

    On a loaded machine the process is time-sliced: the CPU time (this
    process, one thread) is then the better estimate of the one-core cost.
    """
    wall, cpu = samples(fn, repeat)
    return float(wall.min()), float(cpu.min())


def bench_kernel(levels, quick):
    import grainforge
    from grainforge.geometry.geodesic import icosphere
    from grainforge.methods import fso

    p = fso.Params()  # M = n_max = 40, D = 2.4, L/R0 = 7, γ = 1.5, amplitude 0.1
    print("FSO double sum, M = n_max = 40 (best of repeats, one core):")
    print(
        f"{'s':>2} {'vertices':>9} {'terms':>11} {'wm_sum ms':>10} {'(CPU)':>6} {'ns/term':>8}"
        f" {'reference ms':>13} {'(CPU)':>6} {'speed-up':>9} {'(CPU)':>6} {'max |ΔR|/R0':>12}"
        f" {'fso() ms':>9} {'(CPU)':>6}"
    )
    rows = []
    for s in levels:
        unit, _ = icosphere(s)
        field = fso.draw_field(fso.Params(subdivisions=s), np.random.default_rng(s))
        terms = len(unit) * field.psi.size
        t_fast, c_fast = best(lambda: fso.wm_sum(unit, field), repeat=3 if quick else 11)
        t_ref, c_ref = best(lambda: fso.wm_sum_reference(unit, field), repeat=1 if (quick or s >= 6) else 3)
        # radius difference with the K the generator would use (amplitude 0.1 on the level-3 sphere)
        _, _, info = fso.build(fso.Params(subdivisions=s), np.random.default_rng(s))
        diff = info["K"] * float(np.abs(fso.wm_sum(unit, field) - fso.wm_sum_reference(unit, field)).max())
        seeds = iter(range(10**6))
        t_grain, c_grain = best(lambda: grainforge.fso(subdivisions=s, rng=next(seeds)), repeat=3 if quick else 9)
        rows.append((s, len(unit), terms, t_fast, c_fast, t_ref, c_ref, diff, t_grain, c_grain))
        print(
            f"{s:>2} {len(unit):>9} {terms:>11,} {t_fast * 1e3:>10.1f} {c_fast * 1e3:>6.1f}"
            f" {t_fast / terms * 1e9:>8.2f} {t_ref * 1e3:>13.0f} {c_ref * 1e3:>6.0f} {t_ref / t_fast:>8.1f}×"
            f" {c_ref / c_fast:>5.1f}× {diff:>12.1e}"
            f" {t_grain * 1e3:>9.1f} {c_grain * 1e3:>6.1f}"
        )
    print("  wm_sum = the fast kernel (wall, and CPU time of this process); ns/term from the wall time;")
    print("  reference = wm_sum_reference (float64 NumPy, same sum, same run); speed-up = reference / wm_sum")
    print("  (best wall / best wall, and CPU / CPU);")
    print("  max |ΔR|/R0 = K·max|S_fast − S_reference| with the grain's K (amplitude 0.1);")
    print("  fso() = one whole grain: field, kernel, amplitude, solid check, centring (grainforge.fso).")
    return rows, p


def bench_cli(count, subdivisions):
    exe = Path(sys.executable).with_name("grainforge")
    cmd = [str(exe), "generate", "fso", "--count", str(count), "--subdivisions", str(subdivisions), "--out"]
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        res = subprocess.run(cmd + [str(Path(tmp) / "run")], capture_output=True, text=True)
        wall = time.perf_counter() - t
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        n_files = len(list((Path(tmp) / "run").glob("*.stl"))) if res.returncode == 0 else 0
    if res.returncode != 0:
        print(f"CLI run failed ({res.returncode}): {res.stderr.strip()}")
        return None
    print(f"`grainforge generate fso --count {count} --subdivisions {subdivisions}`: {wall:.2f} s wall, "
          f"{cpu:.2f} s CPU "
          f"({n_files} STL files + manifest; includes interpreter start-up, scaling, descriptors, export)")
    return wall


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, levels 3–5 only")
    args = ap.parse_args(argv)
    print(f"numpy {np.__version__}, {os.cpu_count()} CPUs, {load()}")
    levels = (3, 4, 5) if args.quick else (3, 4, 5, 6)
    rows, _ = bench_kernel(levels, args.quick)
    for s, _, _, t_fast, c_fast, t_ref, c_ref, diff, t_grain, c_grain in rows:
        if s == 5:
            print(
                f"Targets at s = 5: kernel {t_fast * 1e3:.1f} ms wall / {c_fast * 1e3:.1f} ms CPU (≤ 60), "
                f"whole grain {t_grain * 1e3:.1f} ms wall / {c_grain * 1e3:.1f} ms CPU, "
                f"speed-up {t_ref / t_fast:.1f}× wall / {c_ref / c_fast:.1f}× CPU (≥ 10), "
                f"max |ΔR| {diff:.1e}·R0 (≤ 1e-4)"
            )
    bench_cli(100, 4)
    print(load())


if __name__ == "__main__":
    main()
