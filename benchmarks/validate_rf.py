"""Validation of the rf generator on the grains it writes (docs/validation.md, "rf: section
spectra and isotropy of random-field grains").

Every grain is generated, written to binary STL, read back with trimesh (vertices merged by
position) and cut by planes through its volume centroid (``grainforge.analysis.sections``: rays
from the outline's area centroid, D_n = 2|c_n|/c_0, the convention of ``grainforge fourier``).

The grains use the default fixed amplitudes (each degree carries exactly its power, random
orientation); the same seeds with ``amplitudes="gaussian"`` are the grains made before that option
existed (the same draws), shown alongside where it matters.

1. Random orientations: mean D_n (n = 2..16) of 8 sections per grain over 50 grains, against
   the requested mean descriptors; the same seeds with Gaussian amplitudes; also at
   subdivisions 6 (mesh-resolution effect).
2. No preferred direction: sections perpendicular to x, y, z, over the same 50 grains and over
   400 grains (at 50 grains the per-order sampling error of one axis mean is ~7 %).
1b. The same without a mesh (radii on great circles from the harmonics), both amplitudes:
   separates the measurement's own second-order effects (rays from the area centroid) from meshing.
2c. What any isotropic field gives at 50 grains, without a mesh: the largest x/y/z spread over
   n = 2..16 of 50-grain means, in many disjoint sets of 50 (Gaussian and fixed amplitudes; one
   central section per axis, and 7 parallel sections per axis at |h| <= 0.45 r0).
3. Measured spectra: 200 grains (and 4 disjoint sets of 50) from a ``grainforge fourier`` CSV of a synthetic sample
   micrograph (``grainforge.viz.demo.sample_micrograph``) against the table's mean spectrum.
4. Aspect: I/L and S/I of 20 grains (minimum box and inertia-ellipsoid axes).
5. Validity: share of seeds raising ParameterError (radius ≤ 0.05 r0) over a descriptor grid.

Run: ``nice .venv/bin/python benchmarks/validate_rf.py [--quick] > out/validate_rf.md`` (~10 min idle).
"""

from __future__ import annotations

import io
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ORDERS = np.arange(2, 17)
#: random sections per grain in the measured-spectrum part
SPECTRUM_SECTIONS = 16


def read_back(g):
    import trimesh

    from grainforge.io import export_bytes

    return trimesh.load(io.BytesIO(export_bytes(g, "stl")), file_type="stl")


def sections(mesh, normals):
    from grainforge.analysis.sections import section_descriptors

    c = mesh.center_mass
    return np.array([section_descriptors(mesh, n, origin=c) for n in normals])


def axis_great_circles(a_all, degree, offsets=(0.0,), n_pts=128):
    """D_n (n = 2..16) of sections ⊥ x, y, z of r = 1 + Σ a_lm Y_lm, no mesh: (N, 3, len(offsets), 15).

    A plane x_k = h cuts the star surface where |p| = r(p/|p|); the in-plane radius ρ along each
    ray from (h e_k) is found by the fixed point ρ = √(r² − h²) (6 steps).  D_n = 2|c_n|/c_0 of ρ
    with rays from the plane's centre (the field's own origin projected).
    """
    from grainforge.geometry.harmonics import real_harmonics

    psi = 2 * np.pi * np.arange(n_pts) / n_pts
    out = np.zeros((len(a_all), 3, len(offsets), 15))
    e = np.eye(3)
    for ax in range(3):
        n, b1, b2 = e[ax], e[(ax + 1) % 3], e[(ax + 2) % 3]
        ring = np.cos(psi)[:, None] * b1 + np.sin(psi)[:, None] * b2
        for j, h in enumerate(offsets):
            rho = np.full((len(a_all), n_pts), np.sqrt(1 - h * h))
            for _ in range(6 if h else 1):
                p = h * n + rho[..., None] * ring
                u = p / np.linalg.norm(p, axis=-1, keepdims=True)
                Y = real_harmonics(u.reshape(-1, 3), degree, 2).reshape(len(a_all), n_pts, -1)
                r = 1 + np.einsum("ntk,nk->nt", Y, a_all)
                rho = np.sqrt(np.maximum(r * r - h * h, 1e-6))
            c = np.fft.rfft(rho, axis=1) / n_pts
            out[:, ax, j] = 2 * np.abs(c[:, 2:17]) / c[:, :1].real
    return out


def random_and_axes(params, seeds, per_grain=8, axes=True):
    import grainforge
    from grainforge.analysis.sections import random_normals

    rand, ax = [], []
    for s in seeds:
        m = read_back(grainforge.generate("rf", params, s))
        rand.append(sections(m, random_normals(per_grain, rng=10_000 + s)))
        if axes:
            ax.append(sections(m, np.eye(3)))
    return np.concatenate(rand), (np.array(ax) if axes else None)


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def part_random(n_grains, quick):
    from grainforge.methods.rf import Params

    print(f"\n### 1–2. Sections of {n_grains} rf grains, rough-angular (0.15, 0.10, 0.03), L = 32\n")
    p = Params(preset="rough-angular")
    from grainforge.outline.contours import descriptor_spectrum

    want = descriptor_spectrum(0.15, 0.1, 0.03, modes=32)[2:17]
    t = time.time()
    rand, ax = random_and_axes(p, range(n_grains))
    rand_g, _ = random_and_axes(Params(preset="rough-angular", amplitudes="gaussian"), range(n_grains), axes=False)
    rg = rand_g.mean(0) / want
    sem_g = rand_g.reshape(n_grains, -1, 15).mean(1).std(0, ddof=1) / np.sqrt(n_grains) / want
    rand6, _ = random_and_axes(Params(preset="rough-angular", subdivisions=6), range(n_grains // 5 if quick else 25),
                               per_grain=8, axes=False)
    r = rand.mean(0) / want
    r6 = rand6.mean(0) / want
    sem = rand.reshape(n_grains, -1, 15).mean(1).std(0, ddof=1) / np.sqrt(n_grains) / want
    a = ax.mean(0) / want  # (3, 15)
    from scipy.stats import friedmanchisquare

    from grainforge.methods.rf import angular_spectrum, centred_section_spectrum

    model = centred_section_spectrum(angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=32)))[2:17] / want
    # paired by grain: do the three axis sections of the same grains differ more than chance?
    pval = [friedmanchisquare(ax[:, 0, k], ax[:, 1, k], ax[:, 2, k]).pvalue for k in range(15)]
    se_axis = ax.std(0, ddof=1).mean(0) / np.sqrt(n_grains) / want  # s.e. of one axis mean
    rows = []
    for k, n in enumerate(ORDERS):
        rows.append([str(n), f"{want[k]:.4f}", f"{rand.mean(0)[k]:.4f}", f"{r[k]:.3f} ± {sem[k]:.3f}",
                     f"{rg[k]:.3f} ± {sem_g[k]:.3f}", f"{model[k]:.3f}", f"{r6[k]:.3f}", f"{a[0, k]:.3f}", f"{a[1, k]:.3f}", f"{a[2, k]:.3f}",
                     f"{np.ptp(a[:, k]) / a[:, k].mean() * 100:.1f}", f"{100 * se_axis[k]:.1f}", f"{pval[k]:.2f}"])
    print(table(["n", "requested D_n", "mean D_n, random", "ratio ± s.e.", "Gaussian amplitudes: ratio ± s.e.",
                 "model: rays from the centroid",
                 "ratio, s = 6 (25 grains)", "⊥x ratio", "⊥y ratio", "⊥z ratio", "x/y/z spread %",
                 "s.e. of one axis mean %", "Friedman p (x = y = z)"], rows))
    print(f"\nFriedman tests (paired by grain) of equal x, y, z sections: smallest p = {min(pval):.3f} over 15 "
          f"orders (p < 0.05 expected by chance in {0.05 * 15:.2f} of 15).")
    print(f"\nRandom orientations: {len(rand)} sections; largest |ratio − 1| over n = 2..16: "
          f"{np.abs(r - 1).max() * 100:.1f} % (n = {ORDERS[np.argmax(np.abs(r - 1))]}); the same seeds with Gaussian "
          f"amplitudes: {np.abs(rg - 1).max() * 100:.1f} % (n = {ORDERS[np.argmax(np.abs(rg - 1))]}).")
    print(f"Axis sections, mean ratio over n = 2..16: x {a[0].mean():.3f}, y {a[1].mean():.3f}, z {a[2].mean():.3f}.")
    print(f"({time.time() - t:.0f} s)")
    return want


def part_analytic(n_grains):
    """The same statistics without a mesh: r on great circles straight from the harmonics."""
    from grainforge.analysis.sections import plane_basis, random_normals
    from grainforge.geometry.harmonics import real_harmonics
    from grainforge.methods.rf import angular_spectrum, coefficients
    from grainforge.outline.contours import Contour, descriptor_spectrum

    print(f"\n### 1b. Without a mesh: {n_grains} fields, 8 random great circles each (256 points)\n")
    t = time.time()
    D = descriptor_spectrum(0.15, 0.1, 0.03, modes=32)
    th = 2 * np.pi * np.arange(256) / 256
    cols, header = [], ["n"]
    for amp in ("fixed", "gaussian"):
        C = angular_spectrum(D, amp)
        o, rc = [], []
        for s in range(n_grains):
            a = coefficients(C, np.random.default_rng(s), amp)
            for nrm in random_normals(8, rng=10_000 + s):
                b = plane_basis(nrm)
                r = 1 + real_harmonics(np.cos(th)[:, None] * b[0] + np.sin(th)[:, None] * b[1], 32, 2) @ a
                c = np.fft.rfft(r) / 256
                o.append(2 * np.abs(c[2:17]) / c[0].real)
                rc.append(Contour(r).recentred().descriptors(16)[2:17])
        o, rc = np.array(o) / D[2:17], np.array(rc) / D[2:17]
        se = rc.reshape(n_grains, 8, 15).mean(1).std(0, ddof=1) / np.sqrt(n_grains)
        cols += [[f"{x:.3f}" for x in o.mean(0)], [f"{x:.3f}" for x in rc.mean(0)], [f"{x:.3f}" for x in se]]
        header += [f"{amp}: rays from the field's origin", f"{amp}: rays from the area centroid",
                   f"{amp}: s.e. of a 50-grain mean (8 sections)"]
        se50 = se * np.sqrt(n_grains / 50)
        cols[-1] = [f"{x:.3f}" for x in se50]
    rows = [[str(n)] + [c[k] for c in cols] for k, n in enumerate(ORDERS)]
    print(table(header, rows))
    print(f"\n({time.time() - t:.0f} s)")


def part_ideal(n_fields, n_cut_fields):
    """x/y/z agreement of 50-grain means for ideal isotropic fields (no mesh), disjoint sets of 50."""
    from grainforge.methods.rf import angular_spectrum, coefficients
    from grainforge.outline.contours import descriptor_spectrum

    print("\n### 2c. What an ideal isotropic field gives: x/y/z spread of 50-grain means, no mesh\n")
    t = time.time()
    D = descriptor_spectrum(0.15, 0.1, 0.03, modes=32)
    offsets = (-0.45, -0.3, -0.15, 0.0, 0.15, 0.3, 0.45)
    rows = []
    for amp in ("gaussian", "fixed"):
        C = angular_spectrum(D, amp)
        for label, n, offs in (("1 central section per axis", n_fields, (0.0,)),
                               ("7 parallel sections per axis, h = −0.45…0.45 r0", n_cut_fields, offsets)):
            a = np.stack([coefficients(C, np.random.default_rng(50_000 + s), amp) for s in range(n)])
            d = np.concatenate([axis_great_circles(a[k:k + 100], 32, offs) for k in range(0, n, 100)])
            d = d.mean(2) / D[2:17]  # (N, 3, 15): per grain and axis, mean over the parallel sections
            contrast = (d[:, 0] - d[:, 1]).std(0, ddof=1) / d.mean((0, 1))
            worst = []
            for k in range(n // 50):
                m = d[50 * k:50 * k + 50].mean(0)
                worst.append((np.ptp(m, 0) / m.mean(0)).max())
            worst = np.array(worst)
            rows.append([amp, label, str(n // 50), f"{contrast.min():.2f}–{contrast.max():.2f}",
                         f"{100 * np.median(worst):.1f}", f"{100 * worst.min():.1f}", f"{(worst <= 0.10).mean():.2f}"])
    print(table(["amplitudes", "sections", "sets of 50", "s.d. of (⊥x − ⊥y)/mean per grain, n = 2..16",
                 "largest spread over n = 2..16, median over sets %", "best set %", "share of sets within 10 %"], rows))
    print(f"\n({time.time() - t:.0f} s)")


def part_isotropy(n_grains, want):
    from grainforge.methods.rf import Params

    print(f"\n### 2b. No preferred direction: sections ⊥ x, y, z over {n_grains} grains\n")
    t = time.time()
    _, ax = random_and_axes(Params(preset="rough-angular"), range(5000, 5000 + n_grains), per_grain=0)
    a = ax.mean(0) / want
    spread = np.ptp(a, axis=0) / a.mean(0)
    rows = [[str(n), f"{a[0, k]:.3f}", f"{a[1, k]:.3f}", f"{a[2, k]:.3f}", f"{spread[k] * 100:.1f}"]
            for k, n in enumerate(ORDERS)]
    print(table(["n", "⊥x ratio", "⊥y ratio", "⊥z ratio", "spread (max − min)/mean %"], rows))
    print(f"\nLargest spread over n = 2..16: {spread.max() * 100:.1f} % (n = {ORDERS[np.argmax(spread)]}); "
          f"expected sampling spread of three means of {n_grains} Rayleigh-like values ≈ "
          f"{0.52 / np.sqrt(n_grains) * 1.7 * 100:.0f} % ({time.time() - t:.0f} s)")


def part_spectrum(n_grains):
    from grainforge.methods.rf import Params
    from grainforge.outline.spectra import read_spectra
    from grainforge.viz.demo import sample_micrograph, write_fourier_csv

    print(f"\n### 3. Measured spectra: {n_grains} grains from a 'grainforge fourier' table\n")
    with tempfile.TemporaryDirectory() as d:
        img = sample_micrograph(Path(d) / "sample.png")
        csv = write_fourier_csv([img], Path(d) / "fd.csv")
        table_ = read_spectra(csv)
        p = Params(spectrum=str(csv))
        import grainforge

        rows_used, rand, fails = [], [], 0
        s = -1
        while len(rand) < n_grains:
            s += 1
            try:
                g = grainforge.generate("rf", p, s)
            except ValueError:
                fails += 1
                continue
            rows_used.append(g.info["spectrum_row"])
            from grainforge.analysis.sections import random_normals

            rand.append(sections(read_back(g), random_normals(SPECTRUM_SECTIONS, rng=20_000 + s)).mean(0))
        rand = np.array(rand)
        want = table_.D[rows_used].mean(0)  # the drawn grains' spectra
        pop = table_.D.mean(0)
        se = rand.std(0, ddof=1) / np.sqrt(len(rand)) / want
        rows = [[str(n), f"{pop[k]:.4f}", f"{want[k]:.4f}", f"{rand.mean(0)[k]:.4f}",
                 f"{rand.mean(0)[k] / want[k]:.3f} ± {se[k]:.3f}"] for k, n in enumerate(ORDERS)]
        print(f"{len(table_)} measured grains; {len(rows_used)} rf grains made ({fails} seeds refused), "
              f"{len(set(rows_used))} distinct measured grains drawn.\n")
        print(table(["n", "table mean", "mean of the drawn rows", f"rf sections ({SPECTRUM_SECTIONS} random per grain)",
                     "ratio ± s.e."], rows))
        sd_meas = table_.D.std(0)
        sd_gen = rand.std(0)
        print(f"\nGrain-to-grain s.d. of D2, D3, D8: measured {sd_meas[0]:.3f}, {sd_meas[1]:.3f}, {sd_meas[6]:.3f}; "
              f"rf (per-grain section means) {sd_gen[0]:.3f}, {sd_gen[1]:.3f}, {sd_gen[6]:.3f}.")
        if len(rand) >= 100:
            k = len(rand) // 50
            print(f"\nThe same grains in {k} disjoint sets of 50 (the made grains in seed order, 50 at a time; "
                  f"seeds 0..{s}): "
                  "ratio per order\n")
            W = table_.D[rows_used]
            sub = [[f"{rand[50 * j:50 * j + 50].mean(0)[i] / W[50 * j:50 * j + 50].mean(0)[i]:.3f}" for j in range(k)]
                   for i in range(15)]
            print(table(["n"] + [f"set {j + 1}" for j in range(k)], [[str(n)] + sub[i] for i, n in enumerate(ORDERS)]))
            worst = [np.max(np.abs(rand[50 * j:50 * j + 50].mean(0) / W[50 * j:50 * j + 50].mean(0) - 1))
                     for j in range(k)]
            print("\nLargest |ratio − 1| per set: " + ", ".join(f"{100 * w:.1f} %" for w in worst))


def part_aspect(n_grains):
    import grainforge
    from grainforge.analysis.descriptors import principal_dimensions
    from grainforge.analysis.fourier import principal_axes

    print(f"\n### 4. Aspect (stretch afterwards, re-measured), {n_grains} grains each\n")
    rows = []
    for aspect in ((1.0, 1.0, 1.0), (2.0, 1.5, 1.0), (1.0, 0.5, 0.3)):
        box, ell = [], []
        for s in range(n_grains):
            m = read_back(grainforge.rf(aspect=None if aspect == (1.0, 1.0, 1.0) else aspect, rng=s))
            L, I, S = principal_dimensions(m)
            box.append((I / L, S / I))
            c, ax = principal_axes(m.vertices, m.faces)
            ext = np.ptp((m.vertices - c) @ ax.T, axis=0)
            ell.append((ext[1] / ext[0], ext[2] / ext[1]))
        box, ell = np.array(box), np.array(ell)
        want = (aspect[1] / aspect[0], aspect[2] / aspect[1])
        rows.append([":".join(f"{x:g}" for x in aspect), f"{want[0]:.3f}", f"{box[:, 0].mean():.3f} ± {box[:, 0].std():.3f}",
                     f"{ell[:, 0].mean():.3f}", f"{want[1]:.3f}", f"{box[:, 1].mean():.3f} ± {box[:, 1].std():.3f}",
                     f"{ell[:, 1].mean():.3f}"])
    print(table(["aspect", "I/L asked", "I/L min box", "I/L principal axes", "S/I asked", "S/I min box",
                 "S/I principal axes"], rows))


def part_validity(n_seeds):
    from grainforge.methods.rf import Params, build
    from grainforge.params import ParameterError

    print(f"\n### 5. Share of seeds refused (radius ≤ 0.05 r0), {n_seeds} seeds, s = 3\n")
    rows = []
    for d in ((0.15, 0.10, 0.03), (0.2, 0.1, 0.03), (0.2, 0.15, 0.04), (0.25, 0.15, 0.05), (0.3, 0.2, 0.05),
              (0.3, 0.3, 0.1), (0.0, 0.0, 0.1), (0.0, 0.0, 0.3)):
        p = Params(descriptors=d, subdivisions=3)
        bad = 0
        for s in range(n_seeds):
            try:
                build(p, np.random.default_rng(s))
            except ParameterError:
                bad += 1
        from grainforge.methods.rf import angular_spectrum
        from grainforge.outline.contours import descriptor_spectrum

        C = angular_spectrum(descriptor_spectrum(*d, modes=32))
        rms = np.sqrt(np.sum(C * (2 * np.arange(33) + 1)) / (4 * np.pi))
        rows.append([str(d), f"{rms:.3f}", f"{bad / n_seeds * 100:.0f} %"])
    print(table(["D2, D3, D8", "RMS of f", "refused"], rows))


def main():
    quick = "--quick" in sys.argv
    t = time.time()
    print("## rf validation (benchmarks/validate_rf.py" + (" --quick" if quick else "") + ")")
    want = part_random(10 if quick else 50, quick)
    part_analytic(40 if quick else 400)
    part_ideal(200 if quick else 4000, 100 if quick else 400)
    part_isotropy(40 if quick else 400, want)
    part_spectrum(10 if quick else 200)
    part_aspect(5 if quick else 20)
    part_validity(20 if quick else 100)
    print(f"\n(total {time.time() - t:.0f} s)")


if __name__ == "__main__":
    main()
