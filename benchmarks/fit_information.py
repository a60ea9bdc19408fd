"""How much a sand's table can say about its generator's settings: slopes, seed scatter, least error (docs/fit.md).

For the fit's ``angular`` method, at the known settings of the synthetic angular sand
(``tests/data/synthetic-angular-sand-settings.csv``: every row's settings, at its grain's resolution, each
grain with a seed of its own), and for each way the aspect enters the grain (``--aspect-by``: ``inertia``, the
fit's, and ``facets``, the generator's default), the script measures

- the **slope** of each mean descriptor with each setting: every grain remade with the setting raised and
  lowered by ``--step`` and the same seed (so the difference is the setting's, not the seed's);
- the **seed scatter**: the sd of a descriptor between the same settings made with two seeds, over √2;
- the **least standard error** of the sand's *mean* settings estimated from its descriptors' means, for a
  table of ``--sand-grains`` grains: J⁻¹ Σ J⁻ᵀ / n with J the slopes and Σ the sand's covariance (for a sand
  whose descriptors scatter as a Gaussian about a linear response, no estimator from the table does better);
  and the grains a table would need for each mean to be known within 5 % (one standard error).

Usage::

    nice .venv/bin/python benchmarks/fit_information.py [--grains 300] [--step 0.04] [--sand-grains 300]
        [--workers 2]
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAND = ROOT / "tests" / "data" / "synthetic-angular-sand.csv"


def known_angular_sand(grains: int):
    """The synthetic angular sand, the fit's angular method, its settings' names, the known settings of each row,
    and the rows and voxels across of ``grains`` grains (the sand's rows in turn)."""
    import numpy as np

    from grainforge.fit import FITS, read_sand

    sand = read_sand(SAND)
    spec = FITS["angular"]
    names = [s.name for s in spec.all_settings]
    with open(SAND.with_name("synthetic-angular-sand-settings.csv"), encoding="utf-8", newline="") as fh:
        known = np.array([[float(r[k]) for k in names] for r in csv.DictReader(fh)])
    rows = np.arange(grains) % len(known)
    return sand, spec, names, known, rows, sand.equivalent_diameter[rows] / sand.voxel_size


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grains", type=int, default=300)
    ap.add_argument("--step", type=float, default=0.04)
    ap.add_argument("--sand-grains", type=int, default=300)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    import numpy as np

    from grainforge.fit import DESCRIPTORS, MeasurePool, grain_seed

    sand, spec, names, known, rows, across = known_angular_sand(args.grains)
    cov = np.cov(sand.table().T)
    t0, cpu = time.perf_counter(), 0.0
    print(f"{args.grains} grains at the synthetic angular sand's known settings, {across.mean():.0f} voxels across; "
          f"slopes by ±{args.step:g} with the same seeds\n")
    for mode in ("inertia", "facets"):
        fixed = {**spec.fixed, "aspect_by": mode}
        with MeasurePool(args.workers) as pool:
            def run(delta, root=99):
                jobs = [(spec.params(dict(zip(names, known[j] + delta))), grain_seed(root, i), float(across[i]))
                        for i, j in enumerate(rows)]
                return pool.run("angular", fixed, jobs)

            base, other = run(np.zeros(len(names))), run(np.zeros(len(names)), root=7)
            slopes = []
            for k in range(len(names)):
                step = np.zeros(len(names))
                step[k] = args.step
                up, down = run(step), run(-step)
                ok = np.all(np.isfinite(up), axis=1) & np.all(np.isfinite(down), axis=1)
                slopes.append((up - down)[ok].mean(axis=0) / (2 * args.step))
            cpu += pool.cpu
        jac = np.array(slopes).T  # (descriptors, settings)
        ok = np.all(np.isfinite(base), axis=1) & np.all(np.isfinite(other), axis=1)
        scatter = np.std(base[ok] - other[ok], axis=0) / np.sqrt(2)
        inv = np.linalg.inv(jac)
        se = np.sqrt(np.diag(inv @ cov @ inv.T) / args.sand_grains)
        mean = known.mean(axis=0)
        need = args.sand_grains * (se / (0.05 * mean)) ** 2
        print(f"### aspect by {mode}\n")
        print("| setting (known mean) | " + " | ".join(f"slope of mean {d}" for d in DESCRIPTORS)
              + f" | least s.e. of its mean, {args.sand_grains} grains | grains for 5 % |")
        print("|---" * (len(DESCRIPTORS) + 3) + "|")
        for k, n in enumerate(names):
            print(f"| {n} ({mean[k]:.3f}) | " + " | ".join(f"{jac[d, k]:+.3f}" for d in range(len(DESCRIPTORS)))
                  + f" | ±{se[k]:.4f} ({se[k] / mean[k]:.1%}) | {need[k]:,.0f} |")
        print("| seed scatter (sd at fixed settings) | " + " | ".join(f"{s:.4f}" for s in scatter) + " | | |\n")
    print(f"{time.perf_counter() - t0:.0f} s wall clock, {cpu:.0f} s of measuring CPU")


if __name__ == "__main__":
    main()
