"""How smoothly a CRI grain's Atlas descriptors follow the recipe (the fit's common random numbers).

The fit assumes that grain i of a recipe changes a little when a setting
changes a little (same seed, same uniform draws).  This measures it: grains
0..N-1 of an Ottawa-like CRI recipe, and of the same recipe with the
elongation mean moved by EPS, each measured the Atlas way (69 voxels
across); prints the grains whose descriptors moved by more than 1e-3, and
for every grain whether CRI's choice of contour orientation
(``cri._best_orientation``: the argmin of a cost over 64 orientations)
changed, with the two smallest costs (equal ones are a tie that float
rounding breaks).

Usage: ``nice .venv/bin/python benchmarks/fit_sensitivity.py [N] [EPS]`` (default 30, 1e-5).
"""

from __future__ import annotations

import sys

import numpy as np

from grainforge.fit import DESCRIPTORS, measure_made_grain, read_sand, recipe_text


def main(n: int = 30, eps: float = 1e-5) -> None:
    sand = read_sand("examples/sand-atlas/ottawa-7.3um.csv", 7.3)

    def tn(mean, sd, low, high):
        return {"distribution": "truncnormal", "mean": mean, "sd": sd, "low": low, "high": high}

    def text(de):
        # the settings of the earlier (distribution-fitting) CRI fit of Ottawa
        params = {"descriptors": [0.0, tn(0.09, 0.015, 0.03, 0.15), tn(0.006153, 0.002567, 0.0, 0.016421)],
                  "subdivisions": 5,
                  "aspect": {"distribution": "zingg", "elongation": tn(0.803 + de, 0.1, 0.403 + de, 1.0),
                             "flatness": tn(0.804, 0.106, 0.404, 1.0)}}
        return recipe_text("cri", params, sand=sand, count=500, seed=2024)

    import grainforge.methods.cri as cri

    choices = []
    original = cri._best_orientation

    def recording(fines):  # the same cost as cri._best_orientation, to see its argmin and ties
        q = cri.GRID // 4
        v = np.array([f[[0, q, 2 * q, 3 * q]] for f in fines])[:, cri._PERMUTATIONS]
        a, b, c = v[0][:, None, None, :], v[1][None, :, None, :], v[2][None, None, :, :]
        cost = ((a[..., 0] - b[..., 0]) ** 2 + (a[..., 2] - b[..., 2]) ** 2 + (a[..., 1] - c[..., 0]) ** 2
                + (a[..., 3] - c[..., 2]) ** 2 + (b[..., 1] - c[..., 1]) ** 2 + (b[..., 3] - c[..., 3]) ** 2).ravel()
        two = np.sort(cost)[:2]
        choices.append((int(np.argmin(cost)), float(two[0]), float(two[1])))
        return original(fines)

    cri._best_orientation = recording
    t0, t1 = text(0.0), text(eps)
    moved = flipped = 0
    print(f"grain | {' | '.join(DESCRIPTORS)} (recipe, then elongation mean + {eps:g})")
    for i in range(n):
        choices.clear()
        a = np.array(measure_made_grain(t0, i, voxel_size_um=7.3)[1:5])
        b = np.array(measure_made_grain(t1, i, voxel_size_um=7.3)[1:5])
        (ca, lo_a, second_a), (cb, _, _) = choices[0], choices[-1]
        flipped += ca != cb
        if np.abs(a - b).max() > 1e-3 or ca != cb:
            moved += np.abs(a - b).max() > 1e-3
            print(i, " | ".join(f"{x:.4f} -> {y:.4f}" for x, y in zip(a, b)),
                  f"| orientation {ca} -> {cb}, two smallest costs {lo_a:.17g} {second_a:.17g}")
    print(f"{moved} of {n} grains moved by more than 1e-3; {flipped} changed their orientation choice")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 30, float(sys.argv[2]) if len(sys.argv) > 2 else 1e-5)
