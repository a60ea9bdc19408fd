"""The per-item costs behind the up-front estimates of ``fit`` and ``simulate``, measured beside their models.

``grainforge fit`` refuses a search estimated beyond a day with a per-grain
cost of ``FIT_GRAIN_SECONDS + FIT_MAKE_SECONDS[method] + FIT_VOXEL_SECONDS·(voxels across / 69)³``
(:func:`grainforge.fit.measured_grain_seconds`, :func:`grainforge.fit.check_fit_size`); ``grainforge simulate`` counts
``TEMPLATE_SECONDS + TEMPLATE_SPHERE_SECONDS·spheres`` per clump template
(:func:`grainforge.simulate.check_size`; its Yade part comes from the runs
of docs/simulate.md and ``benchmarks/bench_simulate.py``).  This prints, per
case, the measured CPU seconds (best and median of ``--repeat`` grains) and
the model's figure.  The models are meant to be rough and on the safe side
(tell a two-hour job from a two-year one).  Usage:
``OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_estimates.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def cpu_seconds(fn, repeat):
    out = []
    for k in range(repeat):
        c = time.process_time()
        fn(k)
        out.append(time.process_time() - c)
    return min(out), float(np.median(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from grainforge import fit
    from grainforge.analysis.atlas import atlas_descriptors
    from grainforge.dem.template import prepare
    from grainforge.methods import generate, get
    from grainforge.simulate import settings

    params = get("rf").Params(subdivisions=5)  # the fitted rf grains' resolution
    print("fit: one rf grain (subdivisions 5) made and measured the Atlas way, CPU s")
    print(f"{'voxels across':>14} {'best':>8} {'median':>8} {'model':>8}")
    for across in (20, 69, 150):
        def one(k, across=across):
            g = generate("rf", params, k)
            atlas_descriptors(g, voxels_across=across, rotation=np.random.default_rng(k))

        best, med = cpu_seconds(one, args.repeat)
        model = fit.measured_grain_seconds("rf", across)
        print(f"{across:>14} {best:8.3f} {med:8.3f} {model:8.3f}")

    print("\nfit: making one grain of each fitted method at its fit resolution, CPU s")
    print(f"{'method':>14} {'best':>8} {'median':>8} {'model':>8}")
    for m, mf in fit.FITS.items():
        values = {"sphericity": 0.85, "convexity": 0.95, "flatness": 0.8, "elongation": 0.8,
                  **{s.name: (s.low + s.high) / 2 for s in mf.settings}}
        mp = get(m).Params(**{**mf.fixed, **mf.params(values)})
        best, med = cpu_seconds(lambda k, m=m, mp=mp: generate(m, mp, k), max(args.repeat, 5))
        print(f"{m:>14} {best:8.3f} {med:8.3f} {fit.FIT_MAKE_SECONDS.get(m, float('nan')):8.3f}")

    g = generate("angular", get("angular").Params(subdivisions=3), 0)
    v, f = np.asarray(g.vertices) * 2.0, np.asarray(g.faces)
    print("\nsimulate: one clump template of an angular grain (subdivisions 3), CPU s")
    print(f"{'spheres':>14} {'best':>8} {'median':>8} {'model':>8}")
    for spheres in (1, 10, 50, 200):
        best, med = cpu_seconds(lambda k, s=spheres: prepare(v, f, name="g", unit=1e-3, density=1180.0, spheres=s,
                                                             source="bench", rng=k), args.repeat)
        model = settings.TEMPLATE_SECONDS + settings.TEMPLATE_SPHERE_SECONDS * spheres
        print(f"{spheres:>14} {best:8.3f} {med:8.3f} {model:8.3f}")


if __name__ == "__main__":
    main()
