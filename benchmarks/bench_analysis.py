"""Shape-analysis timings for a 20,480-face FSO grain (icosphere level 5).

Targets: every descriptor except the fractal dimension in ≤ 100 ms;
with it in ≤ 500 ms.  Prints best-of-N wall-clock figures per stage and in
total, one core.  Usage: ``python benchmarks/bench_analysis.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times) * 1e3, float(np.median(times)) * 1e3


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()

    from grainforge import fso
    from grainforge.analysis import descriptors as D
    from grainforge.analysis import fourier, fractal
    from grainforge.viz.render import render_image

    g = fso(subdivisions=5, rng=1)
    v, f = np.asarray(g.vertices), np.asarray(g.faces)
    print(f"mesh: {len(v)} vertices, {len(f)} faces; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    D.describe(g)  # warm-up (imports, caches)

    mp = D.mesh_moments(v, f)
    hull = D._hull(v)
    centre, axes = fourier.principal_axes(v, f, mp)
    u, r = fractal.radial_function(v, mp["centroid"])
    w = np.bincount(f.ravel(), np.repeat(mp["face_areas"] / 3, 3), minlength=len(v))
    res = (r - fractal.smooth_fit(u, r, w)) / r.mean()
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    edge = float(np.median(np.arccos(np.clip((u[e[:, 0]] * u[e[:, 1]]).sum(1), -1, 1))))

    stages = [
        ("closed check", lambda: D.is_closed(f, len(v))),
        ("volume, area, centroid, second moments", lambda: D.mesh_moments(v, f)),
        ("convex hull (scipy)", lambda: D._hull(v)),
        ("basic columns incl. minimum-volume box (analysis.box)", lambda: D._basic(v, mp, hull)),
        ("principal axes", lambda: fourier.principal_axes(v, f, mp)),
        ("radial fit + roughness", lambda: fractal.smooth_fit(u, r, w)),
        ("3 silhouettes + FDs (256 px)",
         lambda: fourier.projection_descriptors(v, f, axes=(centre, axes), closed=True)),
        ("fractal dimension (variogram)", lambda: fractal.fractal_dimension(u, res, edge)),
    ]
    print("\n| stage | best ms | median ms |\n|---|---:|---:|")
    for name, fn in stages:
        b, m = best(fn, args.repeat)
        print(f"| {name} | {b:.1f} | {m:.1f} |")

    totals = [
        ("basic_descriptors (manifest columns)", lambda: D.basic_descriptors(g)),
        ("describe, all but the fractal dimension", lambda: D.describe(g, fractal=False)),
        ("describe, everything", lambda: D.describe(g)),
        ("render_image 400 px (2× supersampled)", lambda: render_image(g, size=400)),
    ]
    print("\n| total | best ms | median ms | target |\n|---|---:|---:|---|")
    targets = {1: "≤ 100 ms", 2: "≤ 500 ms"}
    for i, (name, fn) in enumerate(totals):
        b, m = best(fn, args.repeat)
        print(f"| {name} | {b:.1f} | {m:.1f} | {targets.get(i, '')} |")

    # other generators' grains, and the box against trimesh's oriented_bounds on the same hull points
    import trimesh

    from grainforge import cri, dpa
    from grainforge.analysis.box import minimum_box

    others = [
        ("FSO s=5 (above)", g),
        ("CRI s=5", cri(subdivisions=5, rng=1)),
        ("DPA 200 octahedra", dpa(primitive="octahedron", primaries=200, rng=1)),
        ("DPA 1000 cubes, smooth 1", dpa(primitive="cube", primaries=1000, smooth=1, rng=1)),
    ]
    print("\n| grain | faces | describe w/o FD best ms | box ms | trimesh box ms | box volume / trimesh's |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, grain in others:
        gv = np.asarray(grain.vertices)
        h = D._hull(gv)
        hv = gv[h.vertices]
        D.describe(grain, fractal=False)
        b, _ = best(lambda: D.describe(grain, fractal=False), args.repeat)
        bb, _ = best(lambda: minimum_box(gv, h), args.repeat)
        bt, _ = best(lambda: trimesh.bounds.oriented_bounds(hv), args.repeat)
        ratio = np.prod(minimum_box(gv, h)[0]) / np.prod(trimesh.bounds.oriented_bounds(hv)[1])
        print(f"| {name} | {len(grain.faces)} | {b:.1f} | {bb:.1f} | {bt:.1f} | {ratio:.4f} |")


if __name__ == "__main__":
    main()
