"""Timing of the Sand-Atlas voxel descriptors: target ≤ 25 ms per grain per core at 60 voxels across.

One process, BLAS single-threaded (as in a worker).  Prints best and median
wall clock and CPU time (time.process_time, all threads) per stage and in
total (stages: scanline voxelising, lattice hull count, Gaussian filter +
marching cubes (scikit-image) and its area on the grain's box + 1 voxel), for a CRI grain (20,480 faces) and a
sphere, at 30, 60 and 69 voxels across.  Usage:
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_atlas.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np


def timed(fn, repeat):
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return min(wall) * 1e3, float(np.median(wall)) * 1e3, min(cpu) * 1e3, float(np.median(cpu)) * 1e3


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    import trimesh
    from scipy import ndimage
    from skimage.measure import marching_cubes

    import grainforge
    from grainforge.analysis.atlas import (
        _hull_count,
        _surface_area,
        atlas_descriptors,
        straddling_cubes,
        voxelise,
    )
    from grainforge.geometry.rotations import random_rotation
    from grainforge.geometry.solid import signed_volume
    from grainforge.methods import get

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")
    cri = grainforge.generate("cri", get("cri").Params(descriptors=(0, 0.09, 0.006), aspect=(1, 0.76, 0.58)), 1)
    ball = trimesh.creation.icosphere(subdivisions=5)
    print("| grain | voxels across | total best / median ms (CPU best / median) | voxelise | hull count "
          "| Gaussian + marching cubes |")
    print("|---|---|---|---|---|---|")
    for label, m in (("CRI (20,480 faces)", cri), ("sphere (20,480 faces)", ball)):
        v = np.asarray(m.vertices) @ random_rotation(3).T
        f = np.asarray(m.faces)
        d_eq = (6 * abs(signed_volume(v, f)) / math.pi) ** (1 / 3)
        for n in (30, 60, 69):
            atlas_descriptors(v, f, voxels_across=n)  # warm-up
            tot = timed(lambda: atlas_descriptors(v, f, voxels_across=n), args.repeat)
            vox = timed(lambda: voxelise(v, f, d_eq / n), args.repeat)
            mask, _ = voxelise(v, f, d_eq / n)
            hull = timed(lambda: _hull_count(mask), args.repeat)
            sub = np.pad(mask.astype(np.float32), 1)

            def sph():
                s = ndimage.gaussian_filter(sub, 0.75, mode="constant", truncate=4.0)
                verts, tris, _, _ = marching_cubes(s, level=0.5, allow_degenerate=True, mask=straddling_cubes(s, 0.5))
                _surface_area(verts, tris)

            mc = timed(sph, args.repeat)
            print(f"| {label} | {n} | {tot[0]:.1f} / {tot[1]:.1f} ({tot[2]:.1f} / {tot[3]:.1f}) "
                  f"| {vox[0]:.1f} ({vox[2]:.1f}) | {hull[0]:.1f} ({hull[2]:.1f}) | {mc[0]:.1f} ({mc[2]:.1f}) |",
                  flush=True)


if __name__ == "__main__":
    main()
