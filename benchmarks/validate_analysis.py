"""Validation figures for docs/validation.md (not a timing benchmark).

1. Surface fractal dimension measured on FSO grains against the input D
   (D = 2.0 … 2.8, L = 7 R0, amplitude 0.1, five seeds, icosphere levels 4 and 5).
2. FD round trip of CRI grains: Fourier descriptors of the three principal
   projections against the input contours' (D2, D3, D8).
3. Descriptors of analytic shapes (sphere, cube, box, ellipsoid).

Usage: ``python benchmarks/validate_analysis.py [--out docs/img]``; prints
Markdown tables and writes ``fractal-dimension-fso.png``.
"""

from __future__ import annotations

import argparse
import io
import time
from pathlib import Path

import numpy as np


def fractal_table(levels=(4, 5), seeds=range(5), dims=(2.0, 2.1, 2.2, 2.3, 2.4, 2.5, 2.6, 2.7, 2.8)):
    from grainforge import fso
    from grainforge.analysis.descriptors import describe

    res = {}
    for s in levels:
        for D in dims:
            vals = []
            for seed in seeds:
                g = fso(fractal_dimension=D, length_ratio=7.0, subdivisions=s, rng=seed)
                vals.append(describe(g, fourier=False)["fractal_dimension"])
            res[(s, D)] = np.array(vals)
    return res


def fractal_plot(res, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grainforge.io import atomic_write

    fig, ax = plt.subplots(figsize=(4.6, 4.2), dpi=110)
    levels = sorted({s for s, _ in res})
    for s, marker in zip(levels, "os^"):
        dims = sorted(D for ss, D in res if ss == s)
        m = [res[(s, D)].mean() for D in dims]
        sd = [res[(s, D)].std(ddof=1) for D in dims]
        ax.errorbar(dims, m, yerr=sd, marker=marker, ms=4, capsize=2, label=f"icosphere level {s} ({10 * 4**s + 2} vertices)")
    ax.plot([2, 2.8], [2, 2.8], "k--", lw=0.8, label="measured = input")
    ax.set(xlabel="input D (FSO)", ylabel="measured surface fractal dimension", xlim=(1.95, 2.85), ylim=(1.95, 3.0))
    ax.legend(fontsize=7)
    ax.set_title("Variogram estimate on FSO grains\n(L = 7 R0, amplitude 0.1, 5 seeds, mean ± sd)", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    plt.close(fig)
    atomic_write(out, buf.getvalue())


def cri_table(seeds=range(3)):
    from grainforge.analysis.descriptors import describe
    from grainforge.methods.cri import cri

    sets = [(0.0, 0.0, 0.02), (0.15, 0.10, 0.03), (0.25, 0.05, 0.02)]
    rows = []
    for d in sets:
        meas = {p: [] for p in ("LI", "LS", "IS")}
        sect = {p: [] for p in ("xy", "xz", "yz")}
        for seed in seeds:
            g = cri(descriptors=d, subdivisions=5, rng=seed)
            r = describe(g, fractal=False)
            for p in meas:
                meas[p].append([r[f"fd_{p}_{n}"] for n in (2, 3, 8)])
            for p in sect:
                sect[p].append([g.info[f"section_{p}_D{n}"] for n in (2, 3, 8)])
        rows.append((d, {p: np.mean(v, axis=0) for p, v in meas.items()}, {p: np.mean(v, axis=0) for p, v in sect.items()}))
    return rows


def analytic_table():
    import trimesh
    from scipy.special import ellipeinc, ellipkinc

    from grainforge.analysis.descriptors import describe

    a, b, c = 2.0, 1.5, 1.0
    phi = np.arccos(c / a)
    k2 = a**2 * (b**2 - c**2) / (b**2 * (a**2 - c**2))
    area = 2 * np.pi * c**2 + 2 * np.pi * a * b / np.sin(phi) * (
        ellipeinc(phi, k2) * np.sin(phi) ** 2 + ellipkinc(phi, k2) * np.cos(phi) ** 2
    )
    vol = 4 / 3 * np.pi * a * b * c
    shapes = {
        "sphere r=1 (icosphere 6)": (trimesh.creation.icosphere(6), dict(
            volume=4 / 3 * np.pi, sphericity=1.0, L=2.0, S=2.0, krumbein_sphericity=1.0,
            radius_of_gyration=np.sqrt(3 / 5), roughness=0.0, fd_LI_2=0.0)),
        "cube a=1": (trimesh.creation.box(), dict(
            volume=1.0, sphericity=(np.pi / 6) ** (1 / 3), L=1.0, S=1.0, krumbein_sphericity=1.0,
            radius_of_gyration=0.5, roughness=None, fd_LI_2=None)),
        "box 4×2×1": (trimesh.creation.box(extents=(4, 2, 1)), dict(
            volume=8.0, sphericity=np.pi ** (1 / 3) * 48 ** (2 / 3) / 28, L=4.0, S=1.0, krumbein_sphericity=0.5,
            radius_of_gyration=np.sqrt((16 + 4 + 1) / 12), roughness=None, fd_LI_2=None)),
        "ellipsoid 2×1.5×1 (icosphere 6)": (None, dict(
            volume=vol, sphericity=np.pi ** (1 / 3) * (6 * vol) ** (2 / 3) / area, L=4.0, S=2.0,
            krumbein_sphericity=(3 * 2 / 16) ** (1 / 3), radius_of_gyration=np.sqrt((a**2 + b**2 + c**2) / 5),
            roughness=0.0, fd_LI_2=None)),
    }
    e = trimesh.creation.icosphere(6)
    e.apply_scale((a, b, c))
    shapes["ellipsoid 2×1.5×1 (icosphere 6)"] = (e, shapes["ellipsoid 2×1.5×1 (icosphere 6)"][1])
    rows = []
    for name, (m, truth) in shapes.items():
        d = describe(m)
        rows.append((name, {k: (v, d[k]) for k, v in truth.items() if v is not None}))
    return rows


def fractal_section(args):
    print("\n## Fractal dimension on FSO grains\n")
    res = fractal_table()
    levels = sorted({s for s, _ in res})
    print("| input D | " + " | ".join(f"level {s}: mean ± sd" for s in levels) + " |")
    print("|---|" + "---|" * len(levels))
    for D in sorted({D for _, D in res}):
        print(f"| {D:.1f} | " + " | ".join(f"{res[(s, D)].mean():.3f} ± {res[(s, D)].std(ddof=1):.3f}" for s in levels) + " |")
    fractal_plot(res, Path(args.out) / "fractal-dimension-fso.png")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="docs/img")
    ap.add_argument("--skip-fractal", action="store_true", help="skip the (slow) FSO fractal-dimension sweep")
    args = ap.parse_args()
    t0 = time.perf_counter()
    print("## Analytic shapes\n")
    for name, vals in analytic_table():
        print(f"**{name}**: " + ", ".join(f"{k} {t:.4f} → {m:.4f}" for k, (t, m) in vals.items()))
    if not args.skip_fractal:
        fractal_section(args)
    print("\n## CRI round trip (mean over 3 seeds): input (D2, D3, D8) → projection FDs | section FDs\n")
    print("| input | LI (xy) | LS (xz) | IS (yz) | section xy | section xz | section yz |")
    print("|---|---|---|---|---|---|---|")
    f3 = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
    for d, meas, sect in cri_table():
        print(f"| {f3(d)} | " + " | ".join(f3(meas[p]) for p in ("LI", "LS", "IS")) + " | "
              + " | ".join(f3(sect[p]) for p in ("xy", "xz", "yz")) + " |")
    print(f"\n(validation took {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
