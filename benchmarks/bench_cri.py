"""CRI timings: one grain per subdivision level, and ``grainforge fourier`` on a 2048² image.

Targets: one CRI grain at subdivisions 5 in ≤ 20 ms on one core;
``grainforge fourier`` on a 2048×2048 image with ~200 grains in ≤ 5 s.
Prints figures; asserts nothing.  Run: ``.venv/bin/python benchmarks/bench_cri.py``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _timing import samples


def best(fn, repeat=7, number=10, clock=time.perf_counter):
    """Best per-call time over ``repeat`` runs of ``number`` calls (wall clock, or CPU time if
    ``clock`` is ``time.process_time``)."""
    wall, cpu = samples(fn, repeat, number)
    return float((cpu if clock is time.process_time else wall).min())


def bench_grains():
    from grainforge.io import export_bytes
    from grainforge.methods import generate
    from grainforge.methods.cri import Params, build

    print("CRI grain (rough-angular), best of 7 × 10, one process; wall clock (CPU time):")
    print(f"{'s':>2} {'vertices':>9} {'build ms':>16} {'generate ms':>16} {'+STL ms':>16}")
    cpu = time.process_time
    for s in range(0, 7):
        p = Params(preset="rough-angular", subdivisions=s)
        seeds = iter(range(10**6))
        t_build = best(lambda: build(p, np.random.default_rng(next(seeds))))
        c_build = best(lambda: build(p, np.random.default_rng(next(seeds))), clock=cpu)
        t_gen = best(lambda: generate("cri", p, next(seeds)), repeat=5, number=5)
        c_gen = best(lambda: generate("cri", p, next(seeds)), repeat=5, number=5, clock=cpu)
        g = generate("cri", p, 0)
        t_stl = best(lambda: export_bytes(g, "stl"), repeat=5, number=5)
        c_stl = best(lambda: export_bytes(g, "stl"), repeat=5, number=5, clock=cpu)
        print(f"{s:>2} {10 * 4**s + 2:>9} {t_build * 1e3:>7.2f} ({c_build * 1e3:>6.2f}) "
              f"{t_gen * 1e3:>7.2f} ({c_gen * 1e3:>6.2f}) {t_stl * 1e3:>7.2f} ({c_stl * 1e3:>6.2f})")
    print("  build = the CRI geometry (contours, correction, radii on the icosphere);")
    print("  generate = build + the shared solid check and centring (methods.generate).")
    for source, p in (("fractal", Params(contour="fractal")), ("aspect 2:1.5:1", Params(aspect=(2, 1.5, 1)))):
        seeds = iter(range(10**6))
        t = best(lambda: build(p, np.random.default_rng(next(seeds))))
        print(f"  s=5 {source}: build {t * 1e3:.2f} ms")


def bench_fourier():
    from PIL import Image

    from grainforge.outline.contours import Contour
    from grainforge.outline.imaging import draw_contours

    rng = np.random.default_rng(0)
    items = []
    n = 15  # 15 × 15 cells, radius ~40–50 px: ~200 grains inside, some touching the border
    cell = 2048 / n
    for i in range(n):
        for j in range(n):
            c = Contour.from_descriptors((0.15, 0.10, 0.03), rng=rng)
            x = (j + 0.5) * cell + rng.uniform(-10, 10)
            y = (i + 0.5) * cell + rng.uniform(-10, 10)
            items.append((c, (x, y), rng.uniform(38, 50)))
    img = draw_contours((2048, 2048), items)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "field.png"
        Image.fromarray(img).save(path)
        exe = Path(sys.executable).with_name("grainforge")
        times = []
        for _ in range(3):
            t = time.perf_counter()
            res = subprocess.run([str(exe), "fourier", str(path), "--csv", str(Path(d) / "fd.csv")],
                                 capture_output=True, text=True, check=True)
            times.append(time.perf_counter() - t)
        print(f"grainforge fourier, 2048×2048 PNG, {len(items)} drawn grains: best {min(times):.2f} s "
              f"(whole command incl. interpreter start-up), {res.stderr.strip()}")
        from grainforge.outline.contours import scan_image

        t = time.perf_counter()
        scan = scan_image(str(path), n_angles=128)
        print(f"  scan_image alone: {time.perf_counter() - t:.2f} s for {len(scan.contours)} grains")


if __name__ == "__main__":
    print(f"load average: {os.getloadavg()}")
    bench_grains()
    bench_fourier()
