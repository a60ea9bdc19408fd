"""The public FSO overlay function, the seamless surface form and the ellipsoidal precursor.

Statistical shape checks (aspect tracking, seam metrics) are in
tests/test_fso_shape.py; here: exact relations and kernel accuracy.
"""

import numpy as np
import pytest

import grainforge
from grainforge.geometry.geodesic import icosphere
from grainforge.methods import fso
from grainforge.params import ParameterError


@pytest.mark.parametrize("surface", fso.SURFACES)
@pytest.mark.parametrize("subdivisions", [2, 4])
def test_overlay_is_what_build_applies(surface, subdivisions):
    p = fso.Params(surface=surface, subdivisions=subdivisions)
    unit, _ = icosphere(subdivisions)
    d = fso.overlay(unit, p, rng=5)
    v, _, info = fso.build(p, np.random.default_rng(5))
    np.testing.assert_array_equal(v, unit * (1.0 + d)[:, None])
    # K from the level-3 reference sphere, whatever the points asked for
    ref, _ = icosphere(fso.REFERENCE_SUBDIVISIONS)
    assert np.sqrt(np.mean(fso.overlay(ref, p, rng=5) ** 2)) == pytest.approx(0.1, rel=1e-12)
    # the same field on a subset of the points: same values
    np.testing.assert_allclose(fso.overlay(unit[::7], p, rng=5), d[::7], rtol=0, atol=1e-12)


def test_overlay_with_raw_k_and_bad_input():
    unit, _ = icosphere(2)
    p = fso.Params(k=0.01, surface="seamless")
    f = fso.draw_field(p, np.random.default_rng(3))
    np.testing.assert_allclose(fso.overlay(unit, p, 3), 0.01 * fso.wm_sum_reference(unit, f), atol=1e-5)
    with pytest.raises(ValueError, match="shape"):
        fso.overlay(unit[:, :2], p, 3)
    with pytest.raises(TypeError):
        fso.overlay(unit, {"k": 0.01}, 3)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(
    "overrides", [{}, {"fractal_dimension": 2.95, "length_ratio": 0.2}, {"gamma": 1.05, "length_ratio": 900.0},
                  {"ridges": 1, "frequencies": 400, "gamma": 1.05}],
)
def test_seamless_kernel_matches_reference(seed, overrides):
    """Same accuracy requirement as the paper form: max |ΔS| ≤ 1e-3 · RMS(S) (radius error ≤ 1e-4·R0)."""
    unit, _ = icosphere(3)
    f = fso.draw_field(fso.Params(surface="seamless", **overrides), np.random.default_rng(seed))
    ref = fso.wm_sum_reference(unit, f)
    fast = fso.wm_sum(unit, f)
    assert np.abs(fast - ref).max() <= 1e-3 * np.sqrt(np.mean(ref**2))


def test_seamless_field_is_rotated_evenly_spread_axes():
    p = fso.Params(surface="seamless", ridges=12)
    f1 = fso.draw_field(p, np.random.default_rng(1))
    f2 = fso.draw_field(p, np.random.default_rng(2))
    base = fso.spread_axes(12)
    for f in (f1, f2):
        assert f.zeta is None and f.alpha is None and f.seamless
        # a rotation of the same axis set: all pairwise angles kept
        np.testing.assert_allclose(f.directions @ f.directions.T, base @ base.T, atol=1e-12)
    assert not np.allclose(f1.directions, f2.directions)


def test_seamless_overlay_has_zero_sphere_mean():
    """c̄_mn makes each term average to zero over the sphere (area-weighted, on a mesh resolving the field)."""
    unit, faces = icosphere(6)
    tri = unit[faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2
    weight = np.bincount(faces.ravel(), np.repeat(area, 3), minlength=len(unit))
    for seed in range(3):
        p = fso.Params(surface="seamless", frequencies=8)
        d = fso.overlay(unit, p, rng=seed)
        mean = np.average(d, weights=weight)
        assert abs(mean) < 3e-3 * np.sqrt(np.mean(d**2))


@pytest.mark.parametrize("aspect", [(2.0, 1.0, 0.5), (1.0, 3.0, 1.5)])
def test_aspect_is_the_precursor_times_the_overlay(aspect):
    p = fso.Params(aspect=aspect, subdivisions=3, surface="seamless")
    unit, _ = icosphere(3)
    v, faces, info = fso.build(p, np.random.default_rng(9))
    r = fso.ellipsoid_radius(unit, aspect)
    k = np.asarray(info["axis_scale"])
    # precursor × overlay, scaled per axis, then the per-grain linear correction (docs/methods/fso.md)
    pre = unit * (r * (1 + fso.overlay(unit, p, 9)))[:, None] * k
    M, _ = fso.aspect_correction(pre, faces, aspect)
    np.testing.assert_allclose(v, pre @ M, rtol=1e-8, atol=1e-8)  # the box search amplifies 1e-16 input noise
    assert 0.8 < k.min() <= k.max() < 1.25 and np.prod(k) == pytest.approx(1.0)
    # only the ratios matter; geometric mean of the semi-axes is R0 = 1
    np.testing.assert_allclose(fso.ellipsoid_radius(unit, np.asarray(aspect) * 3.7), r, rtol=1e-12)
    np.testing.assert_allclose(np.prod(fso.ellipsoid_radius(np.eye(3), aspect)), 1.0)


def test_equal_aspect_keeps_the_sphere_grain_exactly():
    a = grainforge.fso(subdivisions=3, rng=4)
    b = grainforge.fso(subdivisions=3, aspect=(2.5, 2.5, 2.5), rng=4)
    np.testing.assert_array_equal(a.vertices, b.vertices)


@pytest.mark.parametrize(
    "kwargs, name",
    [({"aspect": (1, 1)}, "aspect"), ({"aspect": (1, 0, 1)}, "aspect"), ({"aspect": (21, 1, 1)}, "aspect"),
     ({"surface": "smooth"}, "surface")],
)
def test_bad_new_parameters(kwargs, name):
    with pytest.raises(ParameterError) as exc:
        fso.Params(**kwargs)
    assert exc.value.name == name


def test_cli_accepts_colon_aspect_and_surface(runner, tmp_path):
    from grainforge.cli.main import cli

    res = runner.invoke(cli, ["generate", "fso", "--out", str(tmp_path / "g"), "--aspect", "2:1:0.5",
                              "--surface", "seamless", "--subdivisions", "2"])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "g" / "manifest.csv").read_text()
    assert "seamless" in text and "2.0 1.0 0.5" in text
    res = runner.invoke(cli, ["generate", "fso", "--out", str(tmp_path / "h"), "--aspect", "40:1:1"])
    assert res.exit_code == 2 and "--aspect" in res.output
