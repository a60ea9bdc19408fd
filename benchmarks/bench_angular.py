"""Angular-grain timings: one grain at subdivisions 5 (10,242 vertices), by stage and as a whole.

Target: one angular grain at 10,242 vertices **with roughness** in ≤ 60 ms on one
core.  Prints best-of-repeats wall and CPU times (the machine is shared: the load average is
printed before and after); asserts nothing.  One core: BLAS/OpenMP threads are limited to 1.

Run: ``.venv/bin/python benchmarks/bench_angular.py [--repeat 9]``.
"""

from __future__ import annotations

from _timing import load, one_core, samples

one_core()

import argparse  # noqa: E402

import numpy as np  # noqa: E402


def best(fn, repeat):
    """Smallest wall time, smallest and median CPU time (ms) of ``repeat`` calls after a warm-up."""
    wall, cpu = samples(fn, repeat)
    return 1e3 * wall.min(), 1e3 * cpu.min(), 1e3 * float(np.median(cpu))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    a = ap.parse_args(argv)

    from grainforge.geometry.geodesic import icosphere
    from grainforge.geometry.solid import require_solid, volume_centroid
    from grainforge.methods import angular, generate

    print(load())
    unit, _ = icosphere(5)
    print(f"one angular grain, subdivisions 5 ({len(unit)} vertices), best of {a.repeat} (ms; one core)\n")
    print("| setting | core (planes + rounding geometry) | radius function | roughness (FSO overlay) "
          "| build | solid check + centring | `generate` wall | `generate` CPU best | CPU median |")
    print("|---|---|---|---|---|---|---|---|---|")
    settings = [
        ("sharp, smooth (rounding 0)", angular.Params(rounding=0.0)),
        ("default rounding 0.1, roughness 0.02", angular.Params(roughness=0.02)),
        ("rounding 0.4, roughness 0.02, 4 dents", angular.Params(rounding=0.4, roughness=0.02, dents=4)),
        ("rounding 0.9, roughness 0.02", angular.Params(rounding=0.9, roughness=0.02)),
        ("60 facets, rounding 0.2, roughness 0.05", angular.Params(facets=60, rounding=0.2, roughness=0.05)),
    ]
    for label, p in settings:
        c = angular.core(p, np.random.default_rng(0))
        t_core = best(lambda: angular.core(p, np.random.default_rng(0)), a.repeat)[1]
        t_rad = best(lambda: angular.radius(unit, c), a.repeat)[1]
        t_rough = best(lambda: angular._roughness_factor(unit, p, np.random.default_rng(0)), a.repeat)[1]
        t_build = best(lambda: angular.build(p, np.random.default_rng(0)), a.repeat)[1]
        v, f, _ = angular.build(p, np.random.default_rng(0))
        t_check = best(lambda: (require_solid(v, f, "x", star_centre=np.zeros(3)), volume_centroid(v, f)), a.repeat)[1]
        wall, cpu, med = best(lambda: generate("angular", p, 0), a.repeat)
        print(f"| {label} | {t_core:.1f} | {t_rad:.1f} | {t_rough:.1f} | {t_build:.1f} | {t_check:.1f} "
              f"| {wall:.1f} | **{cpu:.1f}** | {med:.1f} |", flush=True)
    print("\n" + load())


if __name__ == "__main__":
    main()
