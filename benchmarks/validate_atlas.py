"""Validation of the Sand-Atlas voxel descriptors (grainforge.analysis.atlas) for docs/validation.md.

1. Sphere and ellipsoids 1:0.8:0.6 and 1:0.5:0.3 (icosphere level 6 meshes) at
   10 … 100 voxels across d_eq, each in 5 random orientations: inertia-ellipsoid
   axes and Zingg ratios against the exact values, convexity, and the true
   sphericity against the exact Wadell sphericity (its resolution bias).
2. The same CRI and FSO grains measured on the mesh (grainforge.analysis.describe)
   and on the voxel image at 69 voxels across (Ottawa's resolution).

Usage: ``nice python benchmarks/validate_atlas.py [--mesh-only]``; prints Markdown tables.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh


def ellipsoid_area(a, b, c):
    """Exact surface area of an ellipsoid: Legendre's form, 2πc² + 2πab/sinφ (E sin²φ + F cos²φ)."""
    from scipy.special import ellipeinc, ellipkinc

    a, b, c = sorted((a, b, c), reverse=True)
    if a == b == c:
        return 4 * math.pi * a * a
    phi = math.acos(c / a)
    k2 = (a * a * (b * b - c * c)) / (b * b * (a * a - c * c)) if a != c else 0.0
    E, F = ellipeinc(phi, k2), ellipkinc(phi, k2)
    return 2 * math.pi * c * c + 2 * math.pi * a * b / math.sin(phi) * (E * math.sin(phi) ** 2 + F * math.cos(phi) ** 2)


def analytic_table():
    from grainforge.analysis.atlas import atlas_descriptors

    ball = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
    print("| shape | voxels across | major/2a | middle/2b | minor/2c | flatness (exact) | elongation (exact) "
          "| convexity | true sphericity | exact Wadell | bias |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for axes in ((1, 1, 1), (1, 0.8, 0.6), (1, 0.5, 0.3)):
        m = trimesh.Trimesh(ball.vertices * axes, ball.faces, process=False)
        V = 4 / 3 * math.pi * np.prod(axes)
        exact = math.pi ** (1 / 3) * (6 * V) ** (2 / 3) / ellipsoid_area(*axes)
        for n in (10, 20, 30, 45, 60, 69, 100):
            ds = [atlas_descriptors(m, voxels_across=n, rotation=s) for s in range(5)]
            g = {k: np.array([d[k] for d in ds]) for k in ds[0]}
            sph = g["sphericity"]
            print(f"| {axes[0]}:{axes[1]}:{axes[2]} | {n} | {g['major'].mean() / (2 * axes[0]):.4f} "
                  f"| {g['middle'].mean() / (2 * axes[1]):.4f} | {g['minor'].mean() / (2 * axes[2]):.4f} "
                  f"| {g['flatness'].mean():.4f} ({axes[2] / axes[1]:.4f}) "
                  f"| {g['elongation'].mean():.4f} ({axes[1] / axes[0]:.4f}) | {g['convexity'].mean():.4f} "
                  f"| {sph.mean():.4f} ± {sph.std():.4f} | {exact:.4f} | {sph.mean() - exact:+.4f} |", flush=True)


def mesh_vs_voxel_table():
    import grainforge
    from grainforge.analysis import describe
    from grainforge.analysis.atlas import atlas_descriptors
    from grainforge.methods import get

    cases = [
        ("CRI rough-sphere 1:0.8:0.6", "cri", dict(preset="rough-sphere", aspect=(1, 0.8, 0.6))),
        ("CRI rough-angular", "cri", dict(preset="rough-angular")),
        ("CRI D=(0,0.09,0.006) 1:0.76:0.58", "cri", dict(descriptors=(0, 0.09, 0.006), aspect=(1, 0.76, 0.58))),
        ("FSO default", "fso", dict()),
    ]
    from grainforge.analysis.mass import mesh_moments

    print("| grain | d_eq voxel/mesh | sphericity voxel (mesh Wadell) | convexity voxel (mesh) "
          "| flatness voxel (mesh inertia ellipsoid) | elongation voxel (mesh inertia ellipsoid) |")
    print("|---|---|---|---|---|---|")
    for label, method, kw in cases:
        acc = []
        for seed in range(3):
            g = grainforge.generate(method, get(method).Params(**kw), seed)
            d = atlas_descriptors(g, voxels_across=69, rotation=seed)
            m = describe(g, fractal=False, fourier=False)
            lam = np.sort(np.linalg.eigvalsh(mesh_moments(g.vertices, g.faces)["covariance"]))[::-1]
            ax = 2 * np.sqrt(5 * lam)  # the mesh's own inertia-equivalent ellipsoid
            acc.append((d["equivalent_diameter"] / m["equivalent_diameter"], d["sphericity"], m["sphericity"],
                        d["convexity"], m["convexity"], d["flatness"], ax[2] / ax[1], d["elongation"],
                        ax[1] / ax[0]))
        a = np.mean(acc, axis=0)
        print(f"| {label} (3 seeds) | {a[0]:.4f} | {a[1]:.3f} ({a[2]:.3f}) | {a[3]:.3f} ({a[4]:.3f}) "
              f"| {a[5]:.3f} ({a[6]:.3f}) | {a[7]:.3f} ({a[8]:.3f}) |", flush=True)


if __name__ == "__main__":
    import sys

    if "--mesh-only" not in sys.argv:
        analytic_table()
        print()
    mesh_vs_voxel_table()
