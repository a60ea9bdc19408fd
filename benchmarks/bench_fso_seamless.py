"""Seamless vs paper FSO surface: time of the overlay and of a whole grain.

Target: the seamless surface at subdivisions 5 (10,242 vertices), M = n_max = 40, in at most
1.5× the paper form's time.  Both forms run the same rank-4 phase product, float32 cosine
and weighted sum (``fso.wm_sum``); the seamless one skips the hemisphere bookkeeping and the
Chebyshev first term.  Prints best-of-N wall and CPU times (one BLAS thread) and the load
average; asserts nothing.

Run: ``.venv/bin/python benchmarks/bench_fso_seamless.py [--repeat 7]``.
"""

from __future__ import annotations

import os

from _timing import one_core, samples

one_core()

import argparse  # noqa: E402

import numpy as np  # noqa: E402


def best(fn, repeat):
    """Smallest wall and CPU seconds of ``repeat`` calls after a warm-up call."""
    wall, cpu = samples(fn, repeat)
    return float(wall.min()), float(cpu.min())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)

    import grainforge
    from grainforge.geometry.geodesic import icosphere
    from grainforge.methods import fso

    print(f"load average before: {os.getloadavg()}")
    unit, _ = icosphere(5)
    rows = {}
    for surface in fso.SURFACES:
        p = fso.Params(surface=surface)
        f = fso.draw_field(p, np.random.default_rng(0))
        rows[(surface, "wm_sum")] = best(lambda: fso.wm_sum(unit, f), args.repeat)
        rows[(surface, "grain")] = best(lambda: grainforge.fso(surface=surface, rng=0), args.repeat)
        rows[(surface, "grain 1:0.5:0.3")] = best(lambda: grainforge.fso(surface=surface, aspect=(1, 0.5, 0.3),
                                                                         rng=0), args.repeat)
    print("| what (10,242 vertices, M = n_max = 40) | paper wall / CPU (ms) | seamless wall / CPU (ms) "
          "| seamless / paper (CPU) |")
    print("|---|---|---|---|")
    for what in ("wm_sum", "grain", "grain 1:0.5:0.3"):
        (pw, pc), (sw, sc) = rows[("paper", what)], rows[("seamless", what)]
        print(f"| {what} | {1e3 * pw:.1f} / {1e3 * pc:.1f} | {1e3 * sw:.1f} / {1e3 * sc:.1f} | {sc / pc:.2f} |")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
