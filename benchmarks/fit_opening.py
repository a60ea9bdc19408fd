"""Would a fifth descriptor pin down a sand's mean edge rounding?  An experiment (docs/fit.md).

An Atlas table gives four shape descriptors a grain, and from their means the synthetic angular sand's mean
rounding is known to ±15 % at best at 300 grains (``benchmarks/fit_information.py``).  A μCT study also has
the grains' voxel images.  This script measures, on them, one candidate descriptor that responds to edge
rounding directly: the **opening fraction** (:func:`grainforge.analysis.atlas.opening_fraction`) — the share
of a grain's voxels that a ball of radius ``r`` (here a fraction of the grain's d_eq) reaches while staying
inside it; sharp edges and corners are what it cannot.

At the known settings of ``tests/data/synthetic-angular-sand-settings.csv`` (each grain at its row's
resolution, about 30 voxels across), as ``fit_information.py`` does:

- the **slope** of each mean descriptor with each setting: every grain remade with the setting raised and
  lowered by ``--step`` under the same seed;
- the **seed scatter**: the sd of a descriptor between two seeds at the same settings, over √2;
- the **least standard error** of each mean setting from the means of a set of descriptors,
  (Jᵀ Σ⁻¹ J)⁻¹ / n (J the slopes, Σ the descriptors' covariance over the grains made with the sand's own
  seeds, which are the sand's rows; with four descriptors this is ``fit_information.py``'s J⁻¹ Σ J⁻ᵀ / n),
  for the four Atlas descriptors alone and with each opening fraction added;
- grain by grain, over the grains made with the sand's own seeds (its rows), the share of each setting's
  variance that a linear least-squares fit of the setting to the descriptors predicts on grains it was not
  fitted to (5-fold cross-validated R²): how far a grain's descriptors say its own settings.

With ``--curve``, instead: the mean opening fraction at each radius (and the mean sphericity) of the first
``--grains`` grains remade at their own seeds and other settings with every grain's rounding set to each of
0.05 … 0.6: how far the response is from linear.

It is not a fit: grainforge does not measure opening fractions of a sand (the Sand Atlas's tables do not
have them).  Usage::

    nice .venv/bin/python benchmarks/fit_opening.py [--grains 300] [--step 0.04] [--workers 2] [--curve]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

#: opening radii as fractions of the grain's d_eq (1, 1.5, 2 and 3 voxels at 30 voxels across)
RADII = (1 / 30, 1.5 / 30, 2 / 30, 3 / 30)


def _grain(job):
    """(own parameters, fixed parameters, seed, voxels across) -> the four descriptors and the opening fractions."""
    import numpy as np

    from grainforge.analysis.atlas import opening_fraction, voxel_descriptors, voxel_image
    from grainforge.fit import DESCRIPTORS
    from grainforge.methods import generate, get
    from grainforge.params import ParameterError

    own, fixed, seed, across = job
    try:
        grain = generate("angular", get("angular").Params(**{**fixed, **own}), seed)
    except (ParameterError, ValueError):
        return [float("nan")] * (len(DESCRIPTORS) + len(RADII))
    mask, h, _ = voxel_image(grain, voxels_across=across, rotation=np.random.default_rng([seed, 1]))
    d = voxel_descriptors(mask, h)
    return [float(d[k]) for k in DESCRIPTORS] + [opening_fraction(mask, r * across) for r in RADII]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grains", type=int, default=300)
    ap.add_argument("--step", type=float, default=0.04)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--curve", action="store_true", help="the response to rounding over 0.05-0.6 instead")
    args = ap.parse_args()
    import numpy as np
    from fit_information import known_angular_sand  # this folder's

    from grainforge.fit import DESCRIPTORS, grain_seed

    sand, spec, names, known, rows, across = known_angular_sand(args.grains)
    t0 = time.perf_counter()
    cols = [*DESCRIPTORS, *(f"opening {r * 30:g}/30" for r in RADII)]
    print(f"{args.grains} grains at the synthetic angular sand's known settings, {across.mean():.0f} voxels across; "
          f"slopes by ±{args.step:g} with the same seeds; opening radii {', '.join(f'{r:.3f}' for r in RADII)} d_eq")

    if args.curve:
        roundings = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6)
        k = names.index("rounding")
        print("\n| rounding | " + " | ".join(f"mean {c}" for c in cols if c != "flatness" and c != "elongation")
              + " |\n" + "|---" * (len(cols) - 1) + "|")
        with ProcessPoolExecutor(args.workers) as pool:
            for r in roundings:
                jobs = [(spec.params({**dict(zip(names, known[j])), names[k]: r}), dict(spec.fixed),
                         grain_seed(41, i), float(across[i])) for i, j in enumerate(rows)]
                y = np.array(list(pool.map(_grain, jobs, chunksize=8)))
                mean = np.nanmean(y, axis=0)
                print(f"| {r:g} | " + " | ".join(f"{mean[c]:.4f}" for c in range(len(cols))
                                                 if cols[c] not in ("flatness", "elongation")) + " |")
        print(f"\n{time.perf_counter() - t0:.0f} s wall clock")
        return
    with ProcessPoolExecutor(args.workers) as pool:
        def run(delta, root):
            jobs = [(spec.params(dict(zip(names, known[j] + delta))), dict(spec.fixed), grain_seed(root, i),
                     float(across[i])) for i, j in enumerate(rows)]
            return np.array(list(pool.map(_grain, jobs, chunksize=8)))

        base, other = run(np.zeros(len(names)), 41), run(np.zeros(len(names)), 7)  # 41: the sand's own seeds
        slopes = []
        for k in range(len(names)):
            step = np.zeros(len(names))
            step[k] = args.step
            up, down = run(step, 41), run(-step, 41)
            ok = np.all(np.isfinite(up), axis=1) & np.all(np.isfinite(down), axis=1)
            slopes.append((up - down)[ok].mean(axis=0) / (2 * args.step))
    jac = np.array(slopes).T  # (descriptors, settings)
    ok = np.all(np.isfinite(base), axis=1) & np.all(np.isfinite(other), axis=1)
    scatter = np.std(base[ok] - other[ok], axis=0) / np.sqrt(2)
    cov = np.cov(base[ok].T)
    four = list(range(len(DESCRIPTORS)))
    print("\n| descriptor | " + " | ".join(f"slope with {n}" for n in names) + " | seed scatter (sd) |")
    print("|---" * (len(names) + 2) + "|")
    for d, c in enumerate(cols):
        print(f"| {c} | " + " | ".join(f"{jac[d, k]:+.4f}" for k in range(len(names))) + f" | {scatter[d]:.4f} |")
    mean = known.mean(axis=0)
    print("\n| descriptors' means used | " + " | ".join(f"least s.e. of mean {n} ({mean[k]:.3f})"
                                                     for k, n in enumerate(names)) + " |")
    print("|---" * (len(names) + 1) + "|")
    for label, use in [("the four", four)] + [(f"the four + {cols[j]}", four + [j]) for j in
                                              range(len(DESCRIPTORS), len(cols))] + [("all", list(range(len(cols))))]:
        j = jac[use]
        se = np.sqrt(np.diag(np.linalg.inv(j.T @ np.linalg.solve(cov[np.ix_(use, use)], j))) / args.grains)
        print(f"| {label} | " + " | ".join(f"±{se[k]:.4f} ({se[k] / mean[k]:.1%})" for k in range(len(names))) + " |")
    print("\n| grain by grain, from | " + " | ".join(f"R² of {n}" for n in names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for label, use in [("the four", four), (f"the four + {cols[5]}", four + [5]), ("all", list(range(len(cols))))]:
        print(f"| {label} | " + " | ".join(f"{_cv_r2(base[ok][:, use], known[rows][ok, k]):.2f}"
                                           for k in range(len(names))) + " |")
    print(f"\n{time.perf_counter() - t0:.0f} s wall clock")


def _cv_r2(x, y, folds: int = 5) -> float:
    """5-fold cross-validated R² of a linear least-squares fit of ``y`` to the columns of ``x``."""
    import numpy as np

    a = np.column_stack([np.ones(len(y)), x])
    pred = np.empty(len(y))
    for f in range(folds):
        test = np.arange(len(y)) % folds == f
        coef, *_ = np.linalg.lstsq(a[~test], y[~test], rcond=None)
        pred[test] = a[test] @ coef
    return float(1 - np.mean((pred - y) ** 2) / np.var(y))


if __name__ == "__main__":
    main()
