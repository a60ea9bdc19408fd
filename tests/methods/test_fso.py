"""FSO generator: mesh invariants, amplitude, determinism, bad input, the paper's claims."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.stats import mannwhitneyu

import grainforge
from grainforge.analysis.descriptors import principal_dimensions
from grainforge.geometry.geodesic import icosphere
from grainforge.geometry.solid import solid_problems, volume_centroid
from grainforge.methods import fso as fso_mod
from grainforge.params import ParameterError


def assert_valid_solid(g):
    m = g.mesh
    assert m.is_watertight
    assert m.is_winding_consistent
    assert m.body_count == 1
    assert m.volume > 0  # outward orientation
    assert solid_problems(g.vertices, g.faces) == []
    # outward: the normals of faces far from the centre point away from it
    assert (np.einsum("ij,ij->i", m.triangles_center, m.face_normals) > 0).mean() > 0.5


@given(
    D=st.floats(2.0, 2.95),
    L=st.floats(0.1, 12.0),
    amp=st.floats(0.0, 0.15),
    M=st.integers(1, 40),
    N=st.integers(1, 40),
    gamma=st.floats(1.1, 2.5),
    s=st.integers(0, 4),
    seed=st.integers(0, 2**32),
    surface=st.sampled_from(fso_mod.SURFACES),
    aspect=st.tuples(st.floats(0.2, 4.0), st.floats(0.2, 4.0), st.floats(0.2, 4.0)),
)
def test_invariants_over_parameter_space(D, L, amp, M, N, gamma, s, seed, surface, aspect):
    try:
        g = grainforge.fso(
            fractal_dimension=D, length_ratio=L, amplitude=amp, ridges=M, frequencies=N,
            gamma=gamma, subdivisions=s, surface=surface, aspect=aspect, rng=seed,
        )
    except ParameterError as exc:  # documented refusals only
        assert exc.name in ("amplitude", "frequencies")
        assume(False)
    assert len(g.vertices) == 10 * 4**s + 2
    assert_valid_solid(g)
    np.testing.assert_allclose(volume_centroid(g.vertices, g.faces), 0, atol=1e-9)
    assert g.method == "fso" and g.seed == seed


def test_default_grain_shape_and_counts():
    g = grainforge.fso(rng=0)
    assert g.vertices.shape == (10242, 3)
    assert g.faces.shape == (20480, 3)
    assert_valid_solid(g)
    assert g.params.amplitude == 0.1 and g.params.k is None


def test_amplitude_is_rms_on_reference_sphere():
    p = fso_mod.Params(amplitude=0.07, subdivisions=fso_mod.REFERENCE_SUBDIVISIONS)
    v, _, info = fso_mod.build(p, np.random.default_rng(3))
    r = np.linalg.norm(v, axis=1)
    assert np.sqrt(np.mean((r - 1.0) ** 2)) == pytest.approx(0.07, rel=1e-12)
    # the same K is used at any resolution, so the RMS stays close at s = 5
    p5 = fso_mod.Params(amplitude=0.07, subdivisions=5)
    v5, _, info5 = fso_mod.build(p5, np.random.default_rng(3))
    assert info5["K"] == pytest.approx(info["K"], rel=1e-12)
    r5 = np.linalg.norm(v5, axis=1)
    assert np.sqrt(np.mean((r5 - 1.0) ** 2)) == pytest.approx(0.07, rel=0.1)


def test_raw_k_follows_eq_2_and_3():
    p = fso_mod.Params(k=0.004, subdivisions=2)
    rng = np.random.default_rng(11)
    v, _, info = fso_mod.build(p, rng)
    f = fso_mod.draw_field(p, np.random.default_rng(11))
    unit, _ = icosphere(2)
    expected = 1.0 + 0.004 * fso_mod.wm_sum_reference(unit, f)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), expected, atol=1e-6)
    assert info["K"] == 0.004


def test_poles_and_equator_continuity():
    """Both poles sit at R0 (the cos ψ terms cancel); the two hemispheres meet at the equator."""
    p = fso_mod.Params(k=0.01, subdivisions=1)
    f = fso_mod.draw_field(p, np.random.default_rng(5))
    pts = np.array([[0, 0, 1.0], [0, 0, -1.0]])
    np.testing.assert_allclose(fso_mod.wm_sum_reference(pts, f), 0, atol=1e-9)
    eps = 1e-7
    th = np.linspace(0, 2 * np.pi, 17)
    above = np.stack([np.cos(th) * np.sin(np.pi / 2 - eps), np.sin(th) * np.sin(np.pi / 2 - eps),
                      np.full_like(th, np.cos(np.pi / 2 - eps))], 1)
    below = above * np.array([1, 1, -1])
    np.testing.assert_allclose(fso_mod.wm_sum_reference(above, f), fso_mod.wm_sum_reference(below, f), atol=1e-3)


def test_determinism_and_seed_sensitivity():
    a = grainforge.fso(subdivisions=3, rng=7)
    b = grainforge.fso(subdivisions=3, rng=7)
    c = grainforge.fso(subdivisions=3, rng=8)
    assert np.array_equal(a.vertices, b.vertices)
    assert not np.allclose(a.vertices, c.vertices)
    gen = grainforge.fso(subdivisions=3, rng=np.random.default_rng(7))
    assert np.array_equal(gen.vertices, a.vertices) and gen.seed is None


def test_none_rng_records_a_reproducible_seed():
    g = grainforge.fso(subdivisions=2)
    assert isinstance(g.seed, int)
    assert np.array_equal(grainforge.fso(subdivisions=2, rng=g.seed).vertices, g.vertices)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"fractal_dimension": 3.0}, "fractal_dimension"),
        ({"fractal_dimension": 1.99}, "fractal_dimension"),
        ({"fractal_dimension": float("nan")}, "fractal_dimension"),
        ({"length_ratio": 0.0}, "length_ratio"),
        ({"length_ratio": -1.0}, "length_ratio"),
        ({"amplitude": -0.01}, "amplitude"),
        ({"k": -0.01}, "k"),
        ({"amplitude": 0.1, "k": 0.01}, "amplitude"),
        ({"ridges": 0}, "ridges"),
        ({"ridges": 2.5}, "ridges"),
        ({"frequencies": 0}, "frequencies"),
        ({"gamma": 1.0}, "gamma"),
        ({"subdivisions": -1}, "subdivisions"),
        ({"subdivisions": 9}, "subdivisions"),
        ({"fractal_dimension": "2.4"}, "fractal_dimension"),
        ({"frequencies": 400, "gamma": 3.0}, "frequencies"),
    ],
)
def test_bad_parameters_raise_naming_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name}\b") as info:
        grainforge.fso(subdivisions=1, **kwargs) if "subdivisions" not in kwargs else grainforge.fso(**kwargs)
    assert isinstance(info.value, ParameterError) and info.value.name == name


def test_too_large_amplitude_is_refused_not_clipped():
    with pytest.raises(ParameterError, match=r"^amplitude .*smallest radius") as info:
        grainforge.fso(amplitude=0.9, subdivisions=3, rng=0)
    assert info.value.name == "amplitude"
    with pytest.raises(ParameterError, match=r"^k "):
        grainforge.fso(k=1.0, subdivisions=3, rng=0)


def test_bad_rng():
    with pytest.raises(ValueError, match="seed"):
        grainforge.fso(subdivisions=1, rng=-1)
    with pytest.raises(ValueError, match="rng"):
        grainforge.fso(subdivisions=1, rng="x")


def roughness(grain):
    """Mean dihedral angle (degrees) between adjacent faces: the roughness measure of docs/methods/fso.md."""
    return float(np.degrees(grain.mesh.face_adjacency_angles).mean())


def test_claim_larger_length_ratio_elongates():
    """Paper §2.1: L above πR0 controls elongation. Lower I/L over 40 seeds, one-sided Mann–Whitney."""
    def ratios(L):
        out = []
        for s in range(40):
            Lx, Ix, _ = principal_dimensions(grainforge.fso(length_ratio=L, subdivisions=3, rng=s))
            out.append(Ix / Lx)
        return np.array(out)

    short, long_ = ratios(2.0), ratios(10.0)
    assert long_.mean() < short.mean()
    assert mannwhitneyu(long_, short, alternative="less").pvalue < 0.01


def test_claim_higher_fractal_dimension_is_rougher():
    """Paper §2.1 / Fig. 2: at fixed amplitude, higher D gives a rougher surface (20 seeds)."""
    means = []
    samples = {}
    for D in (2.0, 2.4, 2.8):
        samples[D] = np.array([roughness(grainforge.fso(fractal_dimension=D, subdivisions=4, rng=s)) for s in range(20)])
        means.append(samples[D].mean())
    assert means[0] < means[1] < means[2]
    assert mannwhitneyu(samples[2.8], samples[2.0], alternative="greater").pvalue < 1e-4
