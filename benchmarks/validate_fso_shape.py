"""Validation tables for FSO aspect and the seamless surface (docs/validation.md §4–5).

1. Aspect tracking: I/L and S/I of FSO grains with ``--aspect`` measured on the
   STL file as written (read back by trimesh, which merges vertices by
   position): minimum-volume box (grainforge.analysis.box) and the axes of the
   inertia-equivalent ellipsoid (trimesh's inertia tensor).  Mean over 20
   grains at the default amplitude, paper and seamless surfaces.
2. Seam metrics, paper vs seamless: mirror correlation of the small-scale relief
   about the equator and about four other latitude circles, and the relief RMS
   in the polar caps against the equatorial band (grainforge.analysis.relief).
3. Surface fractal dimension against the input D for both surfaces.

Usage: ``nice python benchmarks/validate_fso_shape.py [--only aspect,seam,fd] [--grains 20]``
(about 10 min in all on a loaded 2-core machine); prints Markdown tables.
"""

from __future__ import annotations

import argparse
import io
import sys
import time

import numpy as np

ASPECTS = [(1.0, 1.0, 1.0), (1.0, 0.8, 0.6), (1.0, 0.7, 0.5), (1.0, 0.5, 0.3), (1.0, 0.4, 0.25)]


def inertia_axes(mesh) -> np.ndarray:
    """Semi-axes (descending) of the solid ellipsoid with the mesh's volume and principal moments."""
    I = np.sort(np.linalg.eigvalsh(mesh.moment_inertia))  # density 1: mass = volume
    V = mesh.volume
    a2 = 2.5 / V * np.array([I[1] + I[2] - I[0], I[0] + I[2] - I[1], I[0] + I[1] - I[2]])
    return np.sort(np.sqrt(np.maximum(a2, 0.0)))[::-1]


def measure_file_ratios(grain) -> tuple[float, ...]:
    """(I/L, S/I) of the minimum box, of the inertia ellipsoid and of trimesh's oriented bounding box,
    measured on the written STL."""
    import trimesh

    from grainforge.analysis.box import minimum_box
    from grainforge.io import export_bytes

    mesh = trimesh.load(io.BytesIO(export_bytes(grain, "stl")), file_type="stl")
    L, I, S = minimum_box(mesh.vertices)[0]
    a, b, c = inertia_axes(mesh)
    tL, tI, tS = np.sort(trimesh.bounds.oriented_bounds(mesh.vertices)[1])[::-1]
    return I / L, S / I, b / a, c / b, tI / tL, tS / tI


def aspect_table(grains: int = 20, surfaces=("paper", "seamless"), aspects=ASPECTS):
    from grainforge import fso

    rows = []
    for surface in surfaces:
        for asp in aspects:
            t0 = time.process_time()
            gs = [fso(aspect=asp, surface=surface, rng=seed) for seed in range(grains)]
            cpu = (time.process_time() - t0) / grains
            res = np.array([g.info.get("aspect_residual", 0.0) for g in gs])
            m = np.array([measure_file_ratios(g) for g in gs])
            rows.append((surface, asp, m.mean(axis=0), m.std(axis=0, ddof=1), res, cpu))
            print(f"  aspect {surface} {asp} done", file=sys.stderr)
    print(f"\n### Aspect tracking ({grains} grains each, default parameters, level 5)\n")
    print("| surface | requested A:B:C | requested I/L, S/I | box I/L | box S/I | inertia I/L | inertia S/I "
          "| worst error (box, inertia) | trimesh OBB I/L, S/I | aspect_residual median (max) | CPU s/grain |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for surface, asp, mean, sd, res, cpu in rows:
        want = np.array([asp[1] / asp[0], asp[2] / asp[1]] * 3)
        err = np.abs(mean[:4] / want[:4] - 1.0).max()
        cells = " | ".join(f"{m:.3f} ± {s:.3f}" for m, s in zip(mean[:4], sd[:4]))
        obb = ", ".join(f"{m:.3f} ({100 * (m / w - 1):+.1f} %)" for m, w in zip(mean[4:], want[4:]))
        print(f"| {surface} | {':'.join(f'{a:g}' for a in asp)} | {want[0]:.3f}, {want[1]:.3f} | {cells} "
              f"| {100 * err:.1f} % | {obb} | {np.median(res):.4f} ({res.max():.4f}) | {cpu:.2f} |")
    return rows


SEAM_DELTAS = (0.02, 0.05, 0.1, 0.2)
OTHER_CIRCLES = (np.pi / 2 - 0.9, np.pi / 2 - 0.5, np.pi / 2 + 0.5, np.pi / 2 + 0.9)


def seam_metrics(surface: str, grains: int, subdivisions: int = 5, n: int = 720):
    """Per grain: equator mirror correlations (δ), mean over the other circles (δ), cap RMS, band RMS."""
    from grainforge.analysis.relief import cap_band_rms, mirror_correlation
    from grainforge.methods import fso

    eq, oth, caps = [], [], []
    for seed in range(grains):
        v, f, _ = fso.build(fso.Params(subdivisions=subdivisions, surface=surface), np.random.default_rng(seed))
        z = np.zeros(3)  # the construction centre (fso.build's vertices are not yet centred)
        eq.append(mirror_correlation(v, f, polar=np.pi / 2, deltas=SEAM_DELTAS, n=n, centre=z))
        oth.append(np.mean([mirror_correlation(v, f, polar=p, deltas=SEAM_DELTAS, n=n, centre=z) for p in OTHER_CIRCLES], axis=0))
        caps.append(cap_band_rms(v, f, cap=0.2, band=0.1, centre=z))
    return np.array(eq), np.array(oth), np.array(caps)


def seam_table(grains: int = 10):
    print(f"\n### Seam metrics ({grains} grains each, default parameters, level 5)\n")
    print("| surface | δ (rad) | mirror corr. about equator | mean about 4 other circles | difference |")
    print("|---|---|---|---|---|")
    caps = {}
    for surface in ("paper", "seamless"):
        eq, oth, cb = seam_metrics(surface, grains)
        caps[surface] = cb
        for k, d in enumerate(SEAM_DELTAS):
            print(f"| {surface} | {d:g} | {eq[:, k].mean():.3f} | {oth[:, k].mean():.3f} "
                  f"| {eq[:, k].mean() - oth[:, k].mean():+.3f} |")
    print("\n| surface | relief RMS, polar caps (< 0.2 rad) | equatorial band (± 0.1 rad) | cap / band |")
    print("|---|---|---|---|")
    for surface, cb in caps.items():
        c, b = cb.mean(axis=0)
        print(f"| {surface} | {c:.4f} | {b:.4f} | {c / b:.2f} |")
    return caps


def fd_table(seeds=range(5), dims=(2.0, 2.2, 2.4, 2.6, 2.8)):
    from grainforge import fso
    from grainforge.analysis.descriptors import describe

    print("\n### Surface fractal dimension against the input D (level 5, L = 7 R0, amplitude 0.1, "
          f"{len(seeds)} seeds, mean ± sd)\n")
    print("| input D | paper | seamless |")
    print("|---|---|---|")
    fits = {}
    for D in dims:
        cells = []
        for surface in ("paper", "seamless"):
            vals = np.array([describe(fso(fractal_dimension=D, surface=surface, rng=s), fourier=False)
                             ["fractal_dimension"] for s in seeds])
            fits.setdefault(surface, []).append(vals.mean())
            cells.append(f"{vals.mean():.3f} ± {vals.std(ddof=1):.3f}")
        print(f"| {D:.1f} | {cells[0]} | {cells[1]} |")
    for surface, m in fits.items():
        slope, icpt = np.polyfit(dims, m, 1)
        rms = np.sqrt(np.mean((np.asarray(m) - np.asarray(dims)) ** 2))
        print(f"\n{surface}: slope of measured on input D {slope:.2f}, RMS difference {rms:.3f}", end="")
    print()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="aspect,seam,fd")
    ap.add_argument("--grains", type=int, default=20)
    args = ap.parse_args(argv)
    parts = set(args.only.split(","))
    t0 = time.time()
    if "aspect" in parts:
        aspect_table(args.grains)
    if "seam" in parts:
        seam_table(max(6, args.grains // 2))
    if "fd" in parts:
        fd_table()
    print(f"\n(total {time.time() - t0:.0f} s wall)", file=sys.stderr)


if __name__ == "__main__":
    main()
