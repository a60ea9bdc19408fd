"""Time the one voxeliser (grainforge.geometry.voxel.inside_mask) in the conventions of its two callers.

The DEM grids (clump coverage, level-set signs: ``anchor="centred"``, ``axis=2``,
``rule="winding"``) and the Sand-Atlas images (``anchor="lattice"``, ``axis=0``,
``rule="parity"``), on CRI grains at a few resolutions (cells across the grain's
largest extent).  Prints one row per resolution: cells, and the best of
``--repeat`` wall times per convention.

    python benchmarks/bench_voxel.py [--grains 3] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    import grainforge
    from grainforge.geometry.voxel import grid_for, inside_mask

    grains = [grainforge.cri(rng=s) for s in range(args.grains)]
    conventions = {"dem (centred, z, winding)": ("centred", 2, "winding"),
                   "atlas (lattice, x, parity)": ("lattice", 0, "parity")}
    print(f"{'across':>7} {'cells/grain':>12} " + " ".join(f"{k:>28}" for k in conventions))
    for across in (25, 50, 100):
        row, cells = [], 0
        for anchor, axis, rule in conventions.values():
            best = []
            for g in grains:
                v, f = np.asarray(g.vertices), np.asarray(g.faces)
                grid = grid_for(v, float(np.ptp(v, axis=0).max()) / across, pad=1, anchor=anchor)
                cells = int(np.prod(grid.shape))
                times = []
                for _ in range(args.repeat):
                    t = time.perf_counter()
                    inside_mask(v, f, grid, axis=axis, rule=rule)
                    times.append(time.perf_counter() - t)
                best.append(min(times))
            row.append(f"{1000 * np.mean(best):>25.1f} ms")
        print(f"{across:>7} {cells:>12} " + " ".join(row))


if __name__ == "__main__":
    main()
