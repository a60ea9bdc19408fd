"""Can a per-grain seed search twin the synthetic angular sand with ``--method angular``? (docs/fit.md)

``angular`` grains are shaped by their seed more than by their settings, so a twin of a sand
grain would need its seed chosen along with its settings.  This measures the simplest such
search: every 5th row of ``tests/data/synthetic-angular-sand.csv`` (30 grains) gets the inverse
model's settings (the design of ``benchmarks/fit_recovery.py``: 200 grains at 10–40 voxels across,
cached under ``benchmarks/out/fit-recovery-cache``) and is made with ``--seeds`` different seeds;
the script prints, for the best of the first k seeds, the share of grains whose twin is within 0.03
on every descriptor and the median miss.  Usage::

    nice .venv/bin/python benchmarks/fit_seed_search.py [--seeds 20] [--workers 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    from grainforge.fit import FITS, TWIN_TOL, _Pool, design, grain_seed, measured_across, read_sand, resolve_cap
    from grainforge.twins import invert

    sand = read_sand(ROOT / "tests" / "data" / "synthetic-angular-sand.csv")
    spec = FITS["angular"]
    rows = np.arange(0, sand.count, 5)
    targets = sand.table()[rows]
    across = measured_across(sand, resolve_cap("angular", "method"))[rows]
    t, k = time.perf_counter(), args.seeds
    with _Pool(args.workers) as pool:
        model = design("angular", pool, high=40.0, grains=200,
                       cache=ROOT / "benchmarks" / "out" / "fit-recovery-cache").model()
        u, _ = invert(model, targets, across, scale=np.full(4, 0.012))
        jobs = [(spec.grain_params(u[i]), grain_seed(7, 1000 * i + j), float(across[i]))
                for i in range(len(rows)) for j in range(k)]
        y = pool.run("angular", spec.fixed, jobs, None).reshape(len(rows), k, 4)
        cpu = pool.cpu
    err = np.max(np.abs(y - targets[:, None, :]), axis=2)
    print(f"{len(rows)} grains of the synthetic angular sand, {k} seeds each at the model's settings "
          f"({len(jobs)} grains measured, {cpu:.0f} s of CPU, {time.perf_counter() - t:.0f} s wall)")
    print("| seeds tried | twins within 0.03 (best seed) | median miss of the best seed |\n|---|---|---|")
    for n in sorted({1, 2, 4, 8, k // 2, k}):
        best = np.nanmin(err[:, :n], axis=1)
        print(f"| {n} | {np.mean(best <= TWIN_TOL):.1%} | {np.median(best):.3f} |")


if __name__ == "__main__":
    main()
