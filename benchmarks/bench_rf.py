"""rf timings: one random-field grain per degree and subdivision level.

Target: an rf grain at 10,242 vertices (subdivisions 5), degree up to 32, in ≤ 20 ms
on one core.  Prints figures; asserts nothing.  Run: ``.venv/bin/python benchmarks/bench_rf.py``.
The first call per (level, degree) builds and caches the harmonic basis; its cost is printed too.
"""

from __future__ import annotations

import os
import time

from _timing import one_core, samples

one_core()  # one core (the synthesis itself uses einsum, not BLAS)

import numpy as np  # noqa: E402


def best(fn, repeat=7, number=10, clock=time.perf_counter):
    """Best per-call time over ``repeat`` runs of ``number`` calls (wall clock, or CPU time if
    ``clock`` is ``time.process_time``)."""
    wall, cpu = samples(fn, repeat, number)
    return float((cpu if clock is time.process_time else wall).min())


def main():
    from grainforge.geometry.harmonics import _cached
    from grainforge.io import export_bytes
    from grainforge.methods import generate
    from grainforge.methods.rf import Params, build

    print(f"load average: {os.getloadavg()}")
    print("rf grain (rough-angular), best of 7 × 10, one process; wall clock (CPU time), ms:")
    print(f"{'s':>2} {'vertices':>9} {'L':>3} {'first call':>18} {'build':>18} {'generate':>18} {'+STL':>18}")
    cpu = time.process_time
    for s, L in ((3, 32), (4, 32), (5, 16), (5, 32), (5, 48), (5, 64), (6, 32)):
        p = Params(preset="rough-angular", degree=L, subdivisions=s)
        _cached.cache_clear()
        t0, c0 = time.perf_counter(), cpu()
        build(p, np.random.default_rng(0))
        first, cfirst = time.perf_counter() - t0, cpu() - c0
        seeds = iter(range(10**6))
        t_b = best(lambda: build(p, np.random.default_rng(next(seeds))))
        c_b = best(lambda: build(p, np.random.default_rng(next(seeds))), clock=cpu)
        t_g = best(lambda: generate("rf", p, next(seeds)), repeat=5, number=5)
        c_g = best(lambda: generate("rf", p, next(seeds)), repeat=5, number=5, clock=cpu)
        g = generate("rf", p, 0)
        t_s = best(lambda: export_bytes(g, "stl"), repeat=5, number=5)
        c_s = best(lambda: export_bytes(g, "stl"), repeat=5, number=5, clock=cpu)
        print(f"{s:>2} {10 * 4**s + 2:>9} {L:>3} {first * 1e3:>8.1f} ({cfirst * 1e3:>7.1f}) "
              f"{t_b * 1e3:>8.2f} ({c_b * 1e3:>7.2f}) {t_g * 1e3:>8.2f} ({c_g * 1e3:>7.2f}) "
              f"{t_s * 1e3:>8.2f} ({c_s * 1e3:>7.2f})")
    print("  build = spectrum C_l, a_lm draw, synthesis at the vertices, radius check;")
    print("  generate = build + the shared solid check and centring (methods.generate).")
    p = Params(aspect=(2.0, 1.5, 1.0))
    seeds = iter(range(10**6))
    print(f"  s=5 L=32 aspect 2:1.5:1: build {best(lambda: build(p, np.random.default_rng(next(seeds)))) * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
