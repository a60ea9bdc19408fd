"""DPA timings: aggregation, union surface, full grains, calibration.

Run: ``.venv/bin/python benchmarks/bench_dpa.py [--quick]``.  Prints wall-clock
figures (best of several repeats, one core unless stated); asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

CPU: list[float] = []  # CPU seconds (time.process_time) of the best run of each best() call


def best(fn, repeats):
    times = []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        fn()
        times.append((time.perf_counter() - t, time.process_time() - c))
    wall, cpu = min(times)
    CPU.append(cpu)
    return wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repeats, skip the calibration run")
    args = ap.parse_args()
    reps = 2 if args.quick else 5

    import grainforge
    from grainforge.methods.dpa import aggregation as D
    from grainforge.methods.dpa.calibration import calibrate

    print(f"load average: {os.getloadavg()}")
    D.aggregate("octahedron", 20, exponent=1.0, rng=np.random.default_rng(0))  # imports, caches
    grainforge.dpa(primaries=20, rng=0)

    print("\n300 octahedra (face-cancellation union, contact rules; seeds 0, 1; wall s / CPU s, one run each)")
    for eps in (1.0, 3.0):
        for seed in (0, 1):
            t0, c0 = time.perf_counter(), time.process_time()
            agg = D.aggregate("octahedron", 300, exponent=eps, rng=np.random.default_rng(seed))
            t1, c1 = time.perf_counter(), time.process_time()
            D.union_surface(agg)
            t2, c2 = time.perf_counter(), time.process_time()
            grainforge.dpa(primitive="octahedron", exponent=eps, primaries=300, rng=seed)
            t3, c3 = time.perf_counter(), time.process_time()
            print(f"ε = {eps:g}, seed {seed}: aggregate {t1 - t0:.3f} / {c1 - c0:.3f}, surface {t2 - t1:.3f} / "
                  f"{c2 - c1:.3f}, grain {t3 - t2:.3f} / {c3 - c2:.3f}")

    print("\n1,000 primaries (seeds 0..; best of repeats)")
    print(f"{'primitive':22s} {'ε':>5s} {'aggregate s':>12s} {'surface s':>10s} {'grain s':>9s}   (CPU s: aggregate, surface, grain)")
    for name in ("cube", "octahedron", "tetrahedron", "dodecahedron", "icosahedron", "truncated-octahedron"):
        for eps in ((0.3, 1.0, 10.0) if name in ("cube", "octahedron") else (1.0,)):
            r = reps if name in ("cube", "octahedron") else 2
            t_agg = best(lambda: D.aggregate(name, 1000, exponent=eps, rng=np.random.default_rng(1)), r)
            agg = D.aggregate(name, 1000, exponent=eps, rng=np.random.default_rng(1))
            if agg.cells is not None:
                t_surf = best(lambda: D.lattice_surface(agg.cells), r)
            else:
                t_surf = best(lambda: D.union_surface(agg), max(1, r // 2))
            t_grain = best(lambda: grainforge.dpa(primitive=name, exponent=eps, primaries=1000, rng=1),
                           max(1, r // 2))
            print(f"{name:22s} {eps:5g} {t_agg:12.3f} {t_surf:10.3f} {t_grain:9.3f}   "
                  f"({CPU[-3]:.3f}, {CPU[-2]:.3f}, {CPU[-1]:.3f})")

    if not args.quick:
        t = time.perf_counter()
        calibrate("cube", 200, exponents=np.linspace(0.5, 10.0, 20), repeats=20, rng=0, workers=2)
        print(f"\ncalibration, cubes N = 200, 20 ε × 20 repeats, 2 workers: {time.perf_counter() - t:.1f} s")
    print(f"load average: {os.getloadavg()}")


if __name__ == "__main__":
    main()
