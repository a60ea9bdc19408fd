"""2D contours: Fourier-descriptor, fractal-profile and image sources (docs/design/algorithms.md §2a–2c)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from grainforge.outline.contours import PRESETS, Contour, descriptor_spectrum, scan_image
from grainforge.outline.imaging import draw_contours, load_image
from grainforge.params import ParameterError


def save_png(path, img):
    from PIL import Image

    Image.fromarray(img).save(path)
    return path


# ---------------------------------------------------------------- Fourier descriptors
@given(
    d2=st.floats(0.0, 0.3), d3=st.floats(0.0, 0.15), d8=st.floats(0.0, 0.05),
    b1=st.floats(-3.0, -0.5), b2=st.floats(-3.0, -0.5), seed=st.integers(0, 2**32 - 1),
)
def test_descriptor_round_trip(d2, d3, d8, b1, b2, seed):
    """Generate a contour from descriptors, measure it: every D_n >= 0.01 comes back within 2 %."""
    want = descriptor_spectrum(d2, d3, d8, decay=(b1, b2), modes=64)
    try:
        c = Contour.from_descriptors((d2, d3, d8), decay=(b1, b2), rng=seed)
    except ParameterError as exc:  # large D's can make a radius non-positive: that is an error
        assert exc.name == "descriptors"
        return
    got = c.descriptors(64)
    big = want >= 0.01
    np.testing.assert_allclose(got[big], want[big], rtol=0.02)
    # and nothing appears where nothing was put (D1 = 0, no modes above N)
    assert got[1] < 1e-9
    assert np.abs(descriptors_beyond(c, 64)).max() < 1e-9


def descriptors_beyond(c, n):
    return c.descriptors(c.n_angles // 2)[n + 1:]


def test_regression_of_the_other_modes():
    D = descriptor_spectrum(0.15, 0.10, 0.03, decay=(-2.0, -1.0), modes=16)
    assert D[0] == 1 and D[1] == 0
    assert D[4] == pytest.approx(0.10 * (4 / 3) ** -2)
    assert D[7] == pytest.approx(0.10 * (7 / 3) ** -2)
    assert D[16] == pytest.approx(0.03 * 2 ** -1)


def test_presets_are_the_papers():
    assert PRESETS["rough-sphere"] == (0.0, 0.0, 0.02)
    assert PRESETS["rough-angular"] == (0.15, 0.10, 0.03)
    c = Contour.from_descriptors("rough-angular", rng=5)
    np.testing.assert_allclose(c.descriptors()[[2, 3, 8]], (0.15, 0.10, 0.03), rtol=1e-9)


def test_same_seed_same_contour_and_phases_vary():
    a = Contour.from_descriptors((0.1, 0.05, 0.02), rng=3)
    b = Contour.from_descriptors((0.1, 0.05, 0.02), rng=3)
    c = Contour.from_descriptors((0.1, 0.05, 0.02), rng=4)
    assert a.radii.tobytes() == b.radii.tobytes()
    assert not np.allclose(a.radii, c.radii)


def test_non_positive_radius_is_an_error_not_abs():
    with pytest.raises(ParameterError, match="descriptors .*radius falls"):
        Contour.from_descriptors((0.9, 0.9, 0.5), rng=0)


@pytest.mark.parametrize(
    "bad, match",
    [((0.1, 0.1), "three numbers"), ((0.1, -0.1, 0.02), r"\[0, 1\]"), ("rough-cube", "preset must be one of")],
)
def test_bad_descriptors(bad, match):
    with pytest.raises(ParameterError, match=match):
        Contour.from_descriptors(bad)


# ---------------------------------------------------------------- transforms
def test_rotation_mirror_alignment_and_stretch():
    c = Contour.from_descriptors("rough-angular", rng=11)
    t = np.linspace(0, 2 * np.pi, 50)
    r = c.rotated(0.7)
    np.testing.assert_allclose(r(t + 0.7), c(t), atol=1e-5)
    np.testing.assert_allclose(r.descriptors(), c.descriptors(), atol=1e-12)
    rc = c.recentred()  # about the area centroid: recentring again moves nothing
    np.testing.assert_allclose(rc.recentred().centroid, rc.centroid, atol=1e-6)
    assert np.abs(rc.centroid).max() > 1e-3
    np.testing.assert_allclose(c.mirrored()(t), c(-t), atol=1e-12)
    a = c.aligned()
    assert a.longest_direction() == 0.0
    diam = a(t) + a(t + np.pi)
    assert a(0.0) + a(np.pi) >= diam.max() - 1e-3
    ex, ey = c.extents()
    s = c.stretched(2.0, 0.5)
    sx, sy = s.extents()
    assert (sx / sy) == pytest.approx(4 * ex / ey, rel=1e-2)


def test_contour_normalised_and_interpolated():
    c = Contour(3.0 + np.cos(np.arange(256) * 2 * np.pi / 256 * 3))
    assert c.scale == pytest.approx(3.0)
    assert c.radii.mean() == pytest.approx(1.0)
    t = np.array([0.1, 1.0, 5.5])
    np.testing.assert_allclose(c(t), (3 + np.cos(3 * t)) / 3, atol=1e-6)
    with pytest.raises(ValueError, match="finite and positive"):
        Contour(np.array([1.0] * 10 + [-1.0]))


# ---------------------------------------------------------------- fractal profiles
def test_fractal_contour_amplitude_band_limit_and_closure():
    c = Contour.from_fractal(fractal_dimension=2.4, length_ratio=2.0, amplitude=0.05, modes=64, rng=1)
    assert np.std(c.radii) * c.scale == pytest.approx(0.05, rel=1e-9)
    # integer harmonics only: the spectrum stops at `modes`, so the profile closes at 2π
    # with neither a step nor a kink (a seam would spread energy over every harmonic)
    D = c.descriptors(c.n_angles // 2)
    assert D[65:].max() < 1e-12
    assert D[2:65].max() > 0.01
    # continuity across the seam: the jump from θ = 2π − h to 0 is like any other step
    steps = np.abs(np.diff(np.r_[c.radii, c.radii[0]]))
    assert steps[-1] <= steps[:-1].max()


def test_fractal_dimension_controls_roughness():
    """Higher D puts more of the profile's variance into the high harmonics."""

    def high_share(D):
        shares = []
        for seed in range(8):
            d = Contour.from_fractal(fractal_dimension=D, rng=seed).descriptors(64)
            shares.append((d[16:] ** 2).sum() / (d[2:] ** 2).sum())
        return np.mean(shares)

    assert high_share(2.8) > 2 * high_share(2.2)


def test_fractal_bad_input():
    with pytest.raises(ParameterError, match="fractal_dimension"):
        Contour.from_fractal(fractal_dimension=3.0)
    with pytest.raises(ParameterError, match="amplitude .*radius falls"):
        Contour.from_fractal(amplitude=0.5, length_ratio=0.5, rng=0)


# ---------------------------------------------------------------- images
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_image_round_trip(tmp_path, seed):
    """Draw a known contour into a 512-px PNG and extract it: D2, D3, D8 within 5 %."""
    truth = Contour.from_descriptors("rough-angular", rng=seed)
    img = draw_contours((512, 512), [(truth, (256, 256), 180.0)])
    path = save_png(tmp_path / "grain.png", img)
    got = Contour.from_image(path)
    # an image contour is described about its area centroid: compare with the truth about its own
    known = truth.recentred()
    np.testing.assert_allclose(got.descriptors()[[2, 3, 8]], known.descriptors()[[2, 3, 8]], rtol=0.05)
    assert got.scale == pytest.approx(180.0 * known.scale, rel=0.01)
    np.testing.assert_allclose(got.centroid, np.array([256, -256]) + 180.0 * known.centroid, atol=0.5)


def test_image_inverted_and_holes_filled(tmp_path):
    truth = Contour.from_descriptors("rough-sphere", rng=7)
    img = draw_contours((256, 256), [(truth, (128, 128), 80.0)])
    img[120:136, 120:136] = 0  # a hole inside the grain
    dark = 255 - img  # dark grain on a bright background
    for im in (img, dark):
        got = Contour.from_image(im)
        assert got.scale == pytest.approx(80.0, rel=0.02)
        assert got.descriptors()[8] == pytest.approx(0.02, rel=0.1)


def test_image_non_star_shaped_is_reported():
    img = np.zeros((200, 220))
    yy, xx = np.mgrid[:200, :220]
    img[np.hypot(xx - 100, yy - 120) < 60] = 1
    img[115:125, 100:190] = 1  # an arm to the right ...
    img[30:125, 180:190] = 1  # ... that turns up: rays towards it cross the boundary more than once
    c = Contour.from_image(img)
    assert not c.star_shaped
    assert Contour.from_image(np.hypot(xx - 100, yy - 120) < 60).star_shaped


@pytest.mark.parametrize("a, b, centre", [(80, 50, (150, 150)), (60, 60, (100, 120)), (90, 45, (150.5, 140))])
def test_binary_ellipse_rays_through_pixel_corners(tmp_path, a, b, centre):
    """A binary (0/255) ellipse PNG: its traced outline has vertices exactly on rays (θ = 0, π, ...).
    Every ray must still meet the boundary (such images were once refused with "no grain measured"),
    at the ellipse's radius."""
    yy, xx = np.mgrid[:300, :300]
    cx, cy = centre
    img = ((((xx - cx) / a) ** 2 + ((yy - cy) / b) ** 2 <= 1) * 255).astype(np.uint8)
    scan = scan_image(load_image(save_png(tmp_path / "ellipse.png", img)))
    assert len(scan.contours) == 1 and scan.unmeasurable == 0
    c = scan.contours[0]
    assert c.star_shaped
    theta = 2 * np.pi * np.arange(len(c.radii)) / len(c.radii)
    r_true = a * b / np.hypot(b * np.cos(theta), a * np.sin(theta))
    np.testing.assert_allclose(c.radii * c.scale, r_true, atol=1.0)  # the outline is traced through pixel edges


def test_image_errors(tmp_path):
    with pytest.raises(ValueError, match="no such image"):
        load_image(tmp_path / "missing.png")
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    with pytest.raises(ValueError, match="cannot read image"):
        load_image(bad)
    with pytest.raises(ValueError, match="uniform"):
        Contour.from_image(np.full((32, 32), 7.0))


def test_scan_image_counts_border_and_specks():
    shapes = [(Contour.from_descriptors("rough-angular", rng=i), (100 + 200 * (i % 3), 100 + 200 * (i // 3)), 60.0)
              for i in range(6)]
    img = draw_contours((330, 620), shapes)  # the bottom row touches the border
    img[5:8, 300:303] = 255  # a speck
    scan = scan_image(img, min_area=50)
    assert len(scan.contours) == 3
    assert scan.border == 3 and scan.small == 1
    for c, (truth, _, _) in zip(scan.contours, shapes[:3]):
        # 60-px grains: D2, D3 within 5 %; roughness D8 (a 2-px ripple here) within 0.005
        known = truth.recentred().descriptors()
        np.testing.assert_allclose(c.descriptors()[[2, 3]], known[[2, 3]], rtol=0.05)
        assert abs(c.descriptors()[8] - known[8]) < 0.005


def test_recentred_circle_and_symmetric_contours():
    """A centred circle sampled at the ray angles puts vertices exactly on rays: none may be missed."""
    import numpy as np

    from grainforge.outline.contours import Contour

    th = 2 * np.pi * np.arange(256) / 256
    for r in (np.ones(256), 1 + 0.05 * np.cos(3 * th)):
        D = Contour(r).recentred().descriptors(4)
        np.testing.assert_allclose(D[[1, 2, 4]], 0.0, atol=1e-12)
        assert abs(D[3] - (0.05 if np.ptp(r) > 0 else 0.0)) < 1e-9
