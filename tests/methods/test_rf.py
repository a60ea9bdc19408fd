"""The random-field generator rf (docs/design/algorithms.md §5): harmonics, spectrum, sections, inputs, CLI."""

import io

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

import grainforge
from grainforge.analysis.sections import random_normals, section_descriptors
from grainforge.geometry.geodesic import icosphere
from grainforge.geometry.harmonics import degree_order, real_harmonics, synthesis
from grainforge.geometry.solid import solid_problems
from grainforge.io import export_bytes
from grainforge.methods import generate
from grainforge.methods.rf import Params, angular_spectrum, build, coefficients, section_spectrum
from grainforge.outline.contours import Contour, descriptor_spectrum
from grainforge.outline.imaging import draw_contours
from grainforge.params import ParameterError


def _gauss_grid(L):
    """Nodes and weights integrating band-limited products up to degree 2L exactly."""
    x, w = np.polynomial.legendre.leggauss(L + 1)
    nt = 2 * L + 2
    th = 2 * np.pi * np.arange(nt) / nt
    X, T = np.meshgrid(x, th, indexing="ij")
    s = np.sqrt(1 - X**2)
    unit = np.stack([s * np.cos(T), s * np.sin(T), X], -1).reshape(-1, 3)
    weights = (w[:, None] * np.full(nt, 2 * np.pi / nt)).ravel()
    return unit, weights


def test_harmonics_are_orthonormal():
    L = 24
    unit, w = _gauss_grid(L)
    Y = real_harmonics(unit, L)
    G = Y.T @ (Y * w[:, None])
    assert np.abs(G - np.eye(len(G))).max() < 1e-11


def test_harmonics_match_scipy():
    sp = pytest.importorskip("scipy.special")
    if not hasattr(sp, "sph_harm_y"):
        pytest.skip("scipy < 1.15 has no sph_harm_y")
    rng = np.random.default_rng(5)
    u = rng.standard_normal((40, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    L = 30
    Y = real_harmonics(u, L)
    theta, phi = np.arctan2(u[:, 1], u[:, 0]), np.arccos(u[:, 2])
    for k, (l, m) in enumerate(zip(*degree_order(L))):
        c = sp.sph_harm_y(int(l), abs(int(m)), phi, theta)  # with the Condon–Shortley phase
        want = c.real if m == 0 else np.sqrt(2) * (-1.0) ** int(m) * (c.real if m > 0 else c.imag)
        assert np.allclose(Y[:, k], want, atol=1e-12), (l, m)


@pytest.mark.parametrize("symmetric", [True, False])
def test_mirror_synthesis_equals_the_dense_sum(symmetric):
    rng = np.random.default_rng(2)
    if symmetric:
        unit, _ = icosphere(4)
    else:
        unit = rng.standard_normal((500, 3))
        unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    a = rng.standard_normal(33**2 - 4)
    f = synthesis(unit, 32, 2)(a)
    assert np.abs(f - real_harmonics(unit, 32, 2) @ a).max() < 1e-12


@pytest.mark.parametrize("d", [(0.15, 0.10, 0.03), (0.3, 0.2, 0.05), (0.05, 0.03, 0.01), (0.2, 0.1, 0.0)])
def test_angular_spectrum_inverts_the_section_relation(d):
    D = descriptor_spectrum(*d, modes=32)
    C = angular_spectrum(D)
    assert C[0] == C[1] == 0 and (C >= 0).all()
    assert np.allclose(section_spectrum(C)[2:], D[2:], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("d", [(0.0, 0.0, 0.02), (0.05, 0.02, 0.01)])
def test_spectra_no_isotropic_field_can_carry_are_met_from_above(d):
    """A section spectrum that jumps up at D8 (rough-sphere: D2..D7 = 0 under D8 = 0.02) cannot come
    from an isotropic field: D8 and above are met exactly, the low orders as closely as possible, from above."""
    D = descriptor_spectrum(*d, modes=32)
    got = section_spectrum(angular_spectrum(D))
    assert np.allclose(got[8:], D[8:], rtol=1e-10)
    assert np.all(got[2:8] >= D[2:8] * (1 - 1e-10)) and np.any(got[2:8] > D[2:8] * 1.2)
    raised = got[2:8] > D[2:8] * (1 + 1e-9)
    assert np.all(got[2:8][raised] < D[8])  # the leakage from the orders above stays below them


def test_every_requested_degree_is_in_the_grain():
    """The built radius is exactly Σ a_lm Y_lm over l = 2..L with the drawn a_lm; projecting that sum
    with an exact quadrature finds power in every degree 2..L and none in 0, 1 or above L."""
    L = 32
    p = Params(degree=L)
    v, f, info = build(p, np.random.default_rng(3))
    C = angular_spectrum(descriptor_spectrum(*p.descriptors, modes=L))
    a = coefficients(C, np.random.default_rng(3))
    unit, _ = icosphere(5)
    r = np.linalg.norm(v, axis=1)
    assert np.abs(r - 1.0 - real_harmonics(unit, L, 2) @ a).max() < 1e-12
    nodes, w = _gauss_grid(L + 2)
    fit = real_harmonics(nodes, L + 2).T @ (w * (real_harmonics(nodes, L, 2) @ a))
    l, _ = degree_order(L + 2)
    power = np.bincount(l, weights=fit**2) / (2 * np.arange(L + 3) + 1)
    assert power[0] < 1e-24 and power[1] < 1e-24  # l = 0, 1 left out
    assert power[L + 1] < 1e-24 and power[L + 2] < 1e-24
    ratio = power[2 : L + 1] / C[2 : L + 1]
    # fixed amplitudes (the default): every degree carries exactly its expected power C_l
    assert np.allclose(ratio, 1.0, rtol=1e-9), np.round(ratio, 4)


def test_fixed_and_gaussian_amplitudes_are_the_same_draws():
    """One standard-normal draw per coefficient either way: per degree the two differ by one positive factor."""
    C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=16), "gaussian")
    a = coefficients(C, np.random.default_rng(1), "fixed")
    g = coefficients(C, np.random.default_rng(1), "gaussian")
    l, _ = degree_order(16, 2)
    for k in range(2, 17):
        q = a[l == k] / g[l == k]
        assert np.allclose(q, q[0], rtol=1e-12) and q[0] > 0
        assert np.sum(a[l == k] ** 2) == pytest.approx((2 * k + 1) * C[k], rel=1e-12)
    with pytest.raises(ParameterError, match="one of fixed, gaussian") as info:
        Params(amplitudes="uniform")
    assert info.value.name == "amplitudes"


def _equator_c(a, L, orders):
    """c_n of the equator of Σ a_lm Y_lm (rows of a: fields), n in orders: (N, len(orders)) complex."""
    from grainforge.geometry.harmonics import legendre_equator

    P = legendre_equator(L)
    l, m = degree_order(L, 2)
    out = np.zeros((len(a), len(orders)), complex)
    for j, n in enumerate(orders):
        for k in range(n, L + 1, 2):
            w = np.sqrt(2) * P[k, n] / 2
            out[:, j] += w * (a[:, (l == k) & (m == n)][:, 0] - 1j * a[:, (l == k) & (m == -n)][:, 0])
    return out


@pytest.mark.parametrize("amplitudes", ["fixed", "gaussian"])
def test_mean_modulus_factor_matches_monte_carlo(amplitudes):
    """κ_n = E|c_n|/(E|c_n|²)^½ from the characteristic function, against 20,000 drawn fields (the equator
    stands for any central section: both kinds of field are isotropic).  E|c_n|² must equal Σ C_l P̄_ln(0)²
    within 3 % (≈ 4 s.e. of a 20,000-sample mean of an exponential |c|²), and the sample ratio
    mean|c| / (mean|c|²)^½ must equal κ_n within 0.6 % (its s.e. is ≈ 0.13 %: numerator and denominator
    move together); the fixed κ_2 differs from √π/2 by 4 %."""
    from grainforge.methods.rf import _transfer, mean_modulus_factor

    L, orders = 16, [2, 3, 4, 5, 8, 12]
    C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=L), amplitudes)
    rng = np.random.default_rng(11)
    a = np.stack([coefficients(C, rng, amplitudes) for _ in range(20_000)])
    c = np.abs(_equator_c(a, L, orders))
    power = (_transfer(L) @ C)[orders]
    kappa = mean_modulus_factor(C, amplitudes)[orders]
    assert np.allclose((c**2).mean(0), power, rtol=0.03), ((c**2).mean(0) / power)
    sample = c.mean(0) / np.sqrt((c**2).mean(0))
    assert np.allclose(sample, kappa, rtol=0.006), (sample, kappa)
    if amplitudes == "fixed":
        assert kappa[0] > 1.03 * np.sqrt(np.pi) / 2  # order 2 is far from Rayleigh, and so is the MC


def test_fixed_amplitudes_make_grains_carry_their_spectrum_more_tightly():
    """Grain to grain, the mean D_2, D_3 over 16 random central sections (no mesh, rays from the origin) varies
    less with fixed amplitudes: its s.d. over 60 grains is below 0.7 × the Gaussian one (measured ≈ 0.5;
    the ratio of two 60-sample s.d. has a relative s.e. of ~13 %).  Both means stay within 6 % of the target."""
    from grainforge.analysis.sections import plane_basis

    L = 32
    D = descriptor_spectrum(0.15, 0.1, 0.03, modes=L)
    th = 2 * np.pi * np.arange(128) / 128
    rings = []
    for nrm in random_normals(16, rng=5):
        b = plane_basis(nrm)
        rings.append(real_harmonics(np.cos(th)[:, None] * b[0] + np.sin(th)[:, None] * b[1], L, 2))
    Y = np.stack(rings)  # (16, 128, K)
    sd, mean = {}, {}
    for amp in ("fixed", "gaussian"):
        C = angular_spectrum(D, amp)
        per_grain = []
        for s in range(60):
            r = 1 + Y @ coefficients(C, np.random.default_rng(s), amp)
            c = np.fft.rfft(r, axis=1)
            per_grain.append((2 * np.abs(c[:, 2:4]) / c[:, :1].real).mean(0))  # random rotation per grain
        per_grain = np.array(per_grain) / D[2:4]
        sd[amp], mean[amp] = per_grain.std(0, ddof=1), per_grain.mean(0)
    assert np.all(sd["fixed"] < 0.7 * sd["gaussian"]), (sd["fixed"], sd["gaussian"])
    for amp in sd:
        assert np.all(np.abs(mean[amp] - 1) < 0.06), (amp, mean[amp])


def _read_back(g):
    return trimesh.load(io.BytesIO(export_bytes(g, "stl")), file_type="stl")


@pytest.mark.slow
def test_sections_carry_the_requested_descriptors_in_every_direction():
    """50 grains written to STL and read back (trimesh merges vertices by position).

    Random orientations: the mean D_n of 4 central sections per grain is within
    10 % of the request for n = 2..16 (statistical: the standard error of the
    mean is 2–3 % with fixed amplitudes).  Sections perpendicular to x, y and
    z: their means of D_n/target over n = 2..16 agree within 10 % (the s.e. of
    one axis's mean, from the grain-to-grain spread, is ≈ 2.3 %; a range of 10 %
    among three such means is ≈ 4.3 s.e., by chance about 1 % of the time;
    measured ranges on three seed sets: 3.4, 4.5, 5.3 %); per order they differ
    by up to ~25 % from sampling alone at 50 grains (docs/validation.md rf.2c:
    so would any isotropic field's).
    """
    d = (0.15, 0.10, 0.03)
    want = descriptor_spectrum(*d, modes=32)[2:17]
    rand, axes = [], []
    for s in range(50):
        m = _read_back(grainforge.rf(descriptors=d, rng=1000 + s))
        c = m.center_mass
        rand += [section_descriptors(m, n, origin=c) for n in random_normals(4, rng=s)]
        axes.append([section_descriptors(m, e, origin=c) for e in np.eye(3)])
    ratio = np.mean(rand, axis=0) / want
    assert np.all(np.abs(ratio - 1) < 0.10), np.round(ratio, 3)
    per_axis = (np.mean(axes, axis=0) / want).mean(axis=1)
    assert np.ptp(per_axis) < 0.10, per_axis
    assert np.all(np.abs(per_axis - 1) < 0.10), per_axis
    # no preferred direction, order by order: a Friedman test (paired by grain) of x = y = z; with 15
    # orders, p < 0.001 somewhere happens by chance 1.5 % of the time (a fixed seed set: deterministic)
    from scipy.stats import friedmanchisquare

    axes = np.asarray(axes)
    p = [friedmanchisquare(*axes[:, :, k].T).pvalue for k in range(15)]
    assert min(p) > 1e-3, np.round(p, 4)


def test_valid_solid_star_shaped_and_deterministic():
    for seed in range(3):
        g = grainforge.rf(descriptors=(0.2, 0.12, 0.04), aspect=(2, 1.4, 1), subdivisions=4, rng=seed)
        m = _read_back(g)
        assert solid_problems(m.vertices, m.faces) == []
        assert m.is_watertight and m.is_winding_consistent and m.volume > 0 and m.body_count == 1
        assert len(m.vertices) == 2562
        assert export_bytes(g) == export_bytes(grainforge.rf(descriptors=(0.2, 0.12, 0.04), aspect=(2, 1.4, 1),
                                                            subdivisions=4, rng=seed))
    # the field does not depend on the mesh level: coarse vertices are the fine ones
    a, b = grainforge.rf(subdivisions=3, rng=7), grainforge.rf(subdivisions=5, rng=7)
    ra = np.linalg.norm(build(a.params, np.random.default_rng(7))[0], axis=1)
    rb = np.linalg.norm(build(b.params, np.random.default_rng(7))[0], axis=1)
    assert np.allclose(ra, rb[: len(ra)], atol=1e-12)


@pytest.mark.parametrize("aspect", [(2.0, 1.5, 1.0), (1.0, 0.5, 0.3)])
def test_aspect_sets_the_extents(aspect):
    g = grainforge.rf(aspect=aspect, rng=4)
    ext = np.ptp(_read_back(g).vertices, axis=0)
    assert np.allclose(ext / ext[0], np.array(aspect) / aspect[0], rtol=1e-4)


def test_too_rough_a_field_names_the_parameter():
    with pytest.raises(ParameterError, match="too large .*smallest radius") as info:
        for seed in range(20):
            grainforge.rf(descriptors=(0.3, 0.3, 0.3), subdivisions=2, rng=seed)
    assert info.value.name == "descriptors"


@pytest.mark.parametrize(
    "kw, name, match",
    [
        (dict(preset="rough-sphere", descriptors=(0.1, 0.1, 0.1)), "preset", "conflicts"),
        (dict(descriptors=(0.1, 0.1)), "descriptors", "3 comma-separated"),
        (dict(descriptors=(0.1, 0.1, 0.5)), "descriptors", r"\[0, 0.3\]"),
        (dict(degree=4), "degree", r"\[8, 64\]"),
        (dict(aspect=(1.0, 2.0, 3.0)), "aspect", "L >= I >= S"),
        (dict(aspect=(80.0, 50.0, 1.0)), "aspect", "at most 50"),
        (dict(spectrum="no-such.csv"), "spectrum", "no such file"),
        (dict(decay=(1.0, -1.0)), "decay", r"\[-10, 0\]"),
    ],
)
def test_bad_parameters(kw, name, match):
    with pytest.raises(ParameterError, match=match) as info:
        Params(**kw)
    assert info.value.name == name


# ------------------------------------------------------------------ measured spectra
def _sample_image(path, count=6, seed=0):
    """A synthetic 'micrograph' of ``count`` grains with different descriptors."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    items = []
    for i in range(count):
        d = (rng.uniform(0.05, 0.2), rng.uniform(0.02, 0.1), rng.uniform(0.01, 0.03))
        items.append((Contour.from_descriptors(d, rng=rng), (90 + 170 * (i % 3), 90 + 170 * (i // 3)), 60))
    Image.fromarray(draw_contours((180 + 170 * ((count - 1) // 3), 180 + 170 * 2), items)).save(path)
    return str(path)


@pytest.fixture(scope="module")
def spectrum_csv(tmp_path_factory):
    from click.testing import CliRunner

    from grainforge.cli.main import cli as main

    d = tmp_path_factory.mktemp("fd")
    img = _sample_image(d / "sample.png")
    res = CliRunner().invoke(main, ["fourier", img, "--csv", str(d / "fd.csv")])
    assert res.exit_code == 0, res.output
    return str(d / "fd.csv")


def test_grains_draw_measured_spectra(spectrum_csv):
    from grainforge.outline.spectra import read_spectra

    table = read_spectra(spectrum_csv)
    assert len(table) == 6
    rows = set()
    for seed in range(12):
        g = grainforge.rf(spectrum=spectrum_csv, subdivisions=3, rng=seed)
        row = g.info["spectrum_row"]
        rows.add(row)
        assert g.info["spectrum_grain"] == table.labels[row]
    assert len(rows) >= 4  # the population varies as the measured grains do
    # the last grain's field carries its measured grain's D2..D16 (exactly, or from above where no
    # isotropic field can: then the recorded misfit says by how much)
    from grainforge.outline.spectra import extend_spectrum

    D = extend_spectrum(table.D[row], -5 / 3, 32)
    got = section_spectrum(angular_spectrum(D))[2:17]
    assert np.all(got >= table.D[row] * (1 - 1e-9))
    assert np.max(got / table.D[row] - 1) == pytest.approx(g.info["spectrum_misfit"], abs=1e-9) or \
        g.info["spectrum_misfit"] > np.max(got / table.D[row] - 1)


def test_sections_carry_measured_spectra(spectrum_csv):
    """60 grains (level 4) from a measured table, read back from STL, 4 random central sections each:
    the mean D_n over grains is within 15 % of the mean spectrum of the measured grains they drew,
    n = 2..12.  The 10 % target of docs/validation.md is for 50 grains at level 5 with 16 sections;
    here 4 sections per grain give a standard error of ~4 %, n = 7 carries a systematic +5 %
    (sections measured about their area centroid, docs/validation.md rf.1b) and level 4 loses a few %
    at n ≥ 9 (measured: n = 7 +10 %, n = 9 −11 %), so 15 % is the target plus those."""
    from grainforge.outline.spectra import read_spectra

    table = read_spectra(spectrum_csv)
    got, want = [], []
    for s in range(60):
        try:
            g = grainforge.rf(spectrum=spectrum_csv, subdivisions=4, rng=3000 + s)
        except ValueError:
            continue
        m = _read_back(g)
        c = m.center_mass
        got.append(np.mean([section_descriptors(m, n, origin=c) for n in random_normals(4, rng=s)], axis=0)[:11])
        want.append(table.D[g.info["spectrum_row"]][:11])
    assert len(got) >= 55
    ratio = np.mean(got, axis=0) / np.mean(want, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), np.round(ratio, 3)


def test_cri_accepts_the_same_spectrum(spectrum_csv):
    from grainforge.outline.spectra import read_spectra

    table = read_spectra(spectrum_csv)
    g = grainforge.cri(spectrum=spectrum_csv, subdivisions=3, rng=1)
    assert g.params.contour == "spectrum"
    measured = np.array([[g.info[f"contour_{p}_D{n}"] for n in (2, 3, 8)] for p in ("xy", "xz", "yz")])
    hits = [np.allclose(measured, table.D[k][[0, 1, 6]], atol=1e-9) for k in range(len(table))]
    assert sum(hits) == 1  # all three contours carry one measured grain's D2, D3, D8
    with pytest.raises(ParameterError, match="not contour='spectrum'") as info:
        grainforge.cri(spectrum=spectrum_csv, descriptors=(0.1, 0.1, 0.1))
    assert info.value.name == "descriptors"


def test_malformed_spectrum_tables(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("image,grain,D2\nx,0,0.1\n")
    with pytest.raises(ParameterError, match="missing column") as info:
        Params(spectrum=str(bad))
    assert info.value.name == "spectrum"
    cols = ",".join(f"D{n}" for n in range(2, 17))
    bad.write_text(cols + "\n" + ",".join(["0.1"] * 14 + ["oops"]) + "\n")
    with pytest.raises(ParameterError, match="non-numeric"):
        Params(spectrum=str(bad))


def test_cli_generate_rf(runner, tmp_path, spectrum_csv):
    from grainforge.cli.main import cli as main

    out = tmp_path / "g"
    res = runner.invoke(main, ["generate", "rf", "--out", str(out), "--count", "2", "--subdivisions", "3",
                               "--spectrum", spectrum_csv, "--size", "2", "--aspect", "2:1.5:1"])
    assert res.exit_code == 0, res.output
    rows = (out / "manifest.csv").read_text().splitlines()
    assert len(rows) == 3 and "spectrum_row" in rows[0]
    m = trimesh.load(out / "rf-0001.stl")
    assert m.is_watertight and m.volume > 0
    ext = np.ptp(m.vertices, axis=0)
    assert np.allclose(ext / ext[2], (2.0, 1.5, 1.0), rtol=0.03)  # exact on level 5; this is level 3
    res = runner.invoke(main, ["generate", "rf", "--out", str(tmp_path / "h"), "--spectrum", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "--spectrum" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "h").exists() or not any((tmp_path / "h").iterdir())
    res = runner.invoke(main, ["generate", "rf", "--out", str(tmp_path / "i"), "--descriptors", "0.3,0.3,0.3"])
    assert res.exit_code == 2 and "--descriptors" in res.output


def test_figure_like_use_from_python():
    g = generate("rf", Params(preset="rough-sphere", subdivisions=2), 0)
    assert g.method == "rf" and g.info["spectrum_row"] is None and g.info["field_rms"] > 0


@given(
    d=st.tuples(st.floats(0, 0.3), st.floats(0, 0.3), st.floats(0, 0.3)),
    decay=st.tuples(st.floats(-10, 0), st.floats(-10, 0)),
    degree=st.integers(8, 64),
    aspect=st.none() | st.tuples(st.floats(1, 3), st.floats(0.3, 1), st.floats(0.3, 1)).map(
        lambda t: (t[0], t[0] * t[1], t[0] * t[1] * t[2])),
    s=st.integers(0, 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_any_declared_parameters_give_a_valid_solid_or_a_named_refusal(d, decay, degree, aspect, s, seed):
    p = Params(descriptors=d, decay=decay, degree=degree, aspect=aspect, subdivisions=s)
    try:
        g = generate("rf", p, seed)
    except ParameterError as exc:
        assert exc.name == "descriptors" and "smallest radius" in exc.reason
        return
    m = _read_back(g)
    assert solid_problems(m.vertices, m.faces) == []
    assert m.is_watertight and m.volume > 0 and len(m.vertices) == 10 * 4**s + 2


@pytest.mark.slow
def test_demo_section(tmp_path):
    """The demo's rf section: a sample micrograph, its D2..D16 table, grains and a contact sheet."""
    from grainforge.outline.spectra import read_spectra
    from grainforge.viz.demo import SECTIONS, rf_gallery

    assert rf_gallery in [f for _, f in SECTIONS]
    written = rf_gallery(tmp_path, quick=True)
    assert {p.name for p in written} == {"rf", "rf-grains.png"}
    assert len(read_spectra(tmp_path / "rf" / "fd.csv")) == 30  # every drawn grain is measured
    assert len((tmp_path / "rf" / "from-spectrum" / "manifest.csv").read_text().splitlines()) == 7
    assert (tmp_path / "rf-grains.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
