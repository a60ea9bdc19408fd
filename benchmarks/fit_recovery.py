"""Settings recovery: twin-fit a synthetic sand whose grains' settings are known, compare (docs/fit.md).

A synthetic sand (``benchmarks/make_synthetic_sand.py``: grains of one
generator, each made with known settings, measured the Atlas way into an
Atlas CSV, the settings in a ``...-settings.csv`` beside it) is fitted by
:func:`grainforge.fit.fit_sand` with every row twinned once, and the script
prints the fit's criteria, then per setting (those the fitted method shares with the sand's
generator) the mean of the known settings
(of the rows twinned), the mean of the fitted ones and their relative
difference, and the Spearman correlation between each grain's known and
fitted setting: a setting is *identifiable* when the fitted values follow the
known ones grain by grain (their means then agree); two settings that trade
(the same descriptors from different settings) show as a weak per-grain
correlation and means that move in opposite directions.  Beside them, the
design's cross-validated R² of each setting predicted from a grain's four
descriptors (:func:`grainforge.fit.setting_identifiability`): the most any
inverse of the descriptors can know of it.  Last, the fit's estimate of the
sand's *mean* settings (:func:`grainforge.fit.population_settings`: from the
descriptors' means, where the seed's share averages out) against the known
means of all rows, in per cent, in its own standard errors and in those and its stated sensitivity
to the settings' spread (``Population.spread``) added in quadrature.  Usage::

    nice .venv/bin/python benchmarks/fit_recovery.py [--sand tests/data/synthetic-angular-sand.csv]
        [--method angular] [--design-grains 200] [--max-across 40] [--refine 4] [--reseed 6]
        [--population-grains 300] [--population-slopes auto] [--workers 1] [--seed 2024]
        [--measured-slopes | --known-spread]

How the mean settings' error falls with the sand's size: a 20,000-grain synthetic angular sand (its first 300
rows are the suite's) with every row remade in the estimate::

    nice .venv/bin/python benchmarks/make_synthetic_sand.py --grains 20000 --out benchmarks/out/big-angular \
        --workers 2
    nice .venv/bin/python benchmarks/fit_recovery.py --sand benchmarks/out/big-angular/synthetic-angular-sand.csv \
        --refine 0 --reseed 0 --population-grains 20000 --workers 2 [--population-slopes model] [--known-spread]

The same with the opening-fraction column (``synthetic-angular-sand-opening.csv`` beside it, with
``--max-across 48``, its largest grain) is the estimate as a study with the images would run it.

``--measured-slopes`` is a diagnostic: the estimate's Newton steps go through slopes measured on the grains at
the sand's known settings (which a real sand does not give) instead of the design model's.
``--known-spread`` is another: the population the estimate shifts carries the sand's known settings about the
same starting mean, so that only the spread of its settings differs from a fit's.

The design is measured into a fresh cache under ``benchmarks/out`` (its
resolution range is the sand's, 10 to ``--max-across`` voxels across).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sand", type=Path, default=ROOT / "tests" / "data" / "synthetic-angular-sand.csv")
    ap.add_argument("--method", default="angular")
    ap.add_argument("--design-grains", type=int, default=200)
    ap.add_argument("--max-across", type=float, default=40.0)
    ap.add_argument("--refine", type=int, default=4)
    ap.add_argument("--reseed", type=int, default=None, help="[default: the fit's]")
    ap.add_argument("--population-grains", type=int, default=None,
                    help="twins remade per round of the mean-settings estimate [default: the fit's, 300]")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=2024, help="the fit's seed (its twins' seeds)")
    ap.add_argument("--population-slopes", default="auto", choices=["auto", "measured", "model"],
                    help="the slopes the mean-settings estimate steps through (fit --population-slopes)")
    ap.add_argument("--measured-slopes", action="store_true",
                    help="a diagnostic: the mean-settings estimate steps through slopes measured on the grains at "
                         "the sand's known settings (each of 300 grains remade with a setting raised and lowered by "
                         "0.04 and its own seed), not the design model's; uses the truth, so not a fit")
    ap.add_argument("--known-spread", action="store_true",
                    help="a diagnostic: the mean-settings estimate shifts the grains' known settings (recentred on "
                         "the shrunk twins' mean) instead of the shrunk twins: the made population's spread of "
                         "settings is then the sand's; uses the truth, so not a fit")
    args = ap.parse_args()
    import numpy as np
    from scipy.stats import spearmanr

    from grainforge.fit import POPULATION_GRAINS, RESEED, fit_sand, read_sand

    sand = read_sand(args.sand)
    known_path = args.sand.with_name(args.sand.stem.removesuffix("-opening") + "-settings.csv")
    with open(known_path, encoding="utf-8", newline="") as fh:
        known = list(csv.DictReader(fh))
    if args.measured_slopes:
        import grainforge.fit.mean_settings as estimate

        slopes = measured_slopes(args.method, sand, known, args.max_across, args.workers)
        print("measured slopes of the mean descriptors per unit-box setting (rows: descriptors):\n"
              + np.array2string(slopes, precision=4), flush=True)
        estimate._mean_jacobian = lambda model, u, across, h=1e-3: slopes  # looked up by population_settings
    if args.known_spread:
        import grainforge.fit.run as run  # fit_sand looks population_settings up in its own module

        run.population_settings = known_spread(run.population_settings, known)
    t, cpu = time.perf_counter(), time.process_time()
    result = fit_sand(sand, args.method, count=None, refine=args.refine, rng=args.seed,
                      design_grains=args.design_grains,
                      reseed=RESEED if args.reseed is None else args.reseed,
                      population_grains=args.population_grains or POPULATION_GRAINS,
                      # the diagnostic's slopes replace the model's: the estimate must step through the "model"
                      population_slopes="model" if args.measured_slopes else args.population_slopes,
                      max_across=args.max_across, workers=args.workers,
                      cache=ROOT / "benchmarks" / "out" / "fit-recovery-cache", log=lambda s: print(s, flush=True))
    print(f"{sand.name}: {result.method}, {len(result.generated)} twins, {result.grains_measured} grains measured, "
          f"{result.cpu_seconds:.0f} s of measuring CPU ({time.process_time() - cpu:.0f} s in this process), "
          f"{time.perf_counter() - t:.0f} s wall clock")
    st = result.stats
    print("| criterion | sand | twins | difference |\n|---|---|---|---|")
    for k, p in st["per"].items():
        print(f"| {k} mean; KS | {p['sand_mean']:.3f} | {p['gen_mean']:.3f} | {p['mean_diff']:+.3f}; KS {p['ks']:.3f} |")
    for pair, (a, b) in st["corr"].items():
        print(f"| Spearman {pair} | {a:+.3f} | {b:+.3f} | {b - a:+.3f} |")
    print(f"| twins within 0.03 (of the reachable) | | {st['twin_within']:.1%} | |")
    print(f"| unreachable | | {1 - st['reachable']:.1%} | |")
    print(f"passes: {st['pass']}\n")
    rows = result.sand_rows
    print("| setting | known mean | fitted mean | difference | Spearman known vs fitted, per grain | "
          "design: R² of the setting from a grain's descriptors (rms error) |")
    print("|---|---|---|---|---|---|")
    for k in known[0]:
        if k not in result.settings[0]:  # the row number, or a setting of another generator than the fitted one
            continue
        a = np.array([float(known[j][k]) for j in rows])
        b = np.array([s[k] for s in result.settings])
        r2, err = result.identifiable[k]
        print(f"| {k} | {a.mean():.4f} | {b.mean():.4f} | {(b.mean() - a.mean()) / a.mean():+.1%} | "
              f"{spearmanr(a, b)[0]:+.2f} | {r2:.2f} (±{err:.3g}) |")
    print("(a setting is identifiable when R² >= 0.9: the descriptors then determine it grain by grain)\n")
    pop = result.population
    print(f"The sand's mean settings from its descriptors' means ({pop.grains} grains remade per round):\n")
    print("| setting | known mean (all rows) | estimated mean ± standard error | ± spread | difference | "
          "in standard errors | in both added | determined by the means |")
    print("|---|---|---|---|---|---|---|---|")
    for k in known[0]:
        if k not in pop.mean:
            continue
        a = float(np.mean([float(r[k]) for r in known]))
        both = float(np.hypot(pop.se[k], pop.spread.get(k, 0.0)))
        print(f"| {k} | {a:.4f} | {pop.mean[k]:.4f} ± {pop.se[k]:.4f} | {pop.spread.get(k, 0.0):.4f} | "
              f"{(pop.mean[k] - a) / a:+.1%} | {(pop.mean[k] - a) / pop.se[k]:+.1f} | {(pop.mean[k] - a) / both:+.1f} | "
              f"{pop.determined[k]:.2f} |")


def known_spread(population_settings, known: list[dict]):
    """``population_settings`` started from the sand's known settings of the rows remade, recentred on the mean
    of the start it would have used (the twins shrunk by what the descriptors know of each setting): the same
    starting mean, the sand's own spread."""
    import numpy as np

    def wrapped(spec, sand, *, u0, grains, shrink=None, **kw):
        names = [s.name for s in spec.all_settings]
        low = np.array([s.low for s in spec.all_settings])
        width = np.array([s.high - s.low for s in spec.all_settings])
        m = min(len(u0), int(grains))  # the fit twins every row once: twin i is row i
        truth = (np.array([[float(known[j][k]) for k in names] for j in range(m)]) - low) / width
        u = np.asarray(u0[:m], np.float64)
        centre = u.mean(axis=0)  # shrinking about the mean keeps it
        print("known-spread start: settings' sd (unit box) " + ", ".join(
            f"{k} {a:.3f} (shrunk twins {b:.3f})" for k, a, b in
            zip(names, truth.std(axis=0), (u - centre).std(axis=0) * np.asarray(shrink or np.ones(len(names))))),
            flush=True)
        return population_settings(spec, sand, u0=u0, shrink=shrink, grains=grains,
                                   start=truth - truth.mean(axis=0) + centre, **kw)

    return wrapped


def measured_slopes(method: str, sand, known: list[dict], max_across: float, workers: int, step: float = 0.04):
    """(4, p) slopes of the mean descriptors per unit-box setting, measured at the known settings of the sand's
    first rows (:func:`grainforge.fit.mean_settings._measured_mean_jacobian`, the fit's own measurement, with a step of
    ``step`` in each setting's units and the seeds of ``fit_information.py``)."""
    import numpy as np

    from grainforge.fit import FITS, SLOPE_GRAINS, MeasurePool, grain_seed
    from grainforge.fit.mean_settings import _measured_mean_jacobian

    spec = FITS[method]
    names = [s.name for s in spec.all_settings]
    low = np.array([s.low for s in spec.all_settings])
    width = np.array([s.high - s.low for s in spec.all_settings])
    rows = np.arange(min(SLOPE_GRAINS, len(known)))
    u = (np.array([[float(known[j][k]) for k in names] for j in rows]) - low) / width
    across = np.minimum(sand.equivalent_diameter[rows] / sand.voxel_size, max_across)
    with MeasurePool(workers) as pool:
        return _measured_mean_jacobian(spec, pool, u, [grain_seed(99, i) for i in rows], across, step=step / width)


if __name__ == "__main__":
    main()
