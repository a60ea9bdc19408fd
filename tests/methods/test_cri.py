"""The CRI generator (docs/design/algorithms.md §2d): sections, invariants, determinism, bad input."""

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

import grainforge
from grainforge.geometry.solid import solid_problems
from grainforge.io import export_bytes
from grainforge.methods import generate
from grainforge.methods.cri import GRID, PLANES, Params, build, construct
from grainforge.outline.contours import Contour, descriptor_spectrum
from grainforge.outline.imaging import draw_contours
from grainforge.params import ParameterError

# angle of a point in each principal plane, measured as in docs/design/algorithms.md §2d
_ANGLE = {
    "xy": lambda p: np.arctan2(p[:, 1], p[:, 0]),
    "xz": lambda p: np.arctan2(p[:, 2], p[:, 0]),
    "yz": lambda p: np.arctan2(p[:, 2], p[:, 1]),
}
_NORMAL = {"xy": (0, 0, 1), "xz": (0, 1, 0), "yz": (1, 0, 0)}
_OFF = {"xy": 2, "xz": 1, "yz": 0}


def _png(path, seed, radius=200):
    from PIL import Image

    c = Contour.from_descriptors("rough-angular", rng=seed)
    Image.fromarray(draw_contours((512, 512), [(c, (256, 256), radius)])).save(path)
    return str(path)


@pytest.fixture(scope="module")
def three_images(tmp_path_factory):
    d = tmp_path_factory.mktemp("grains")
    return [_png(d / f"g{i}.png", 10 + i) for i in range(3)]


def _sources(images):
    return {
        "fourier": Params(preset="rough-angular", subdivisions=5),
        "fourier-3-sets": Params(descriptors=(0.1, 0.05, 0.02), descriptors_xz=(0.2, 0.1, 0.03),
                                 descriptors_yz=(0.05, 0.02, 0.01), subdivisions=5),
        "fractal": Params(contour="fractal", subdivisions=5),
        "image": Params(images=",".join(images), subdivisions=5),
    }


@pytest.mark.parametrize("source", ["fourier", "fourier-3-sets", "fractal", "image"])
def test_principal_sections_reproduce_the_contours(source, three_images):
    """Each principal section of the mesh is its (corrected) input contour within 1 % of r0.

    Image contours: 2 %.  Their outlines keep sharp corners up to harmonic 2^s = 32 (nothing is
    stretched any more), so the mesh's chords miss them by up to 1.3 % of r0 at s = 5, and 1.7 %
    with the default ridge twist (the cut crosses edges whose off-plane ends are turned).
    """
    tol = 0.02 if source == "image" else 0.01
    p = _sources(three_images)[source]
    v, f, info = build(p, np.random.default_rng(3))
    con = construct(p, 3)
    mesh = trimesh.Trimesh(v, f, process=False)
    for k, plane in enumerate(PLANES):
        section = Contour(con.sections[k])  # normalised shape
        r0 = con.sections[k].mean()
        # 1. vertices lying exactly in the plane (the icosphere has 128 per plane at level 5)
        on = np.abs(v[:, _OFF[plane]]) < 1e-12
        assert on.sum() >= 100
        pts = v[on]
        r = np.linalg.norm(pts, axis=1)
        expect = section(_ANGLE[plane](pts)) * section.scale
        assert np.abs(r - expect).max() < tol * r0, plane
        # 2. the mesh's planar cross-section, everywhere along it
        cut = mesh.section(plane_origin=(0, 0, 0), plane_normal=_NORMAL[plane])
        cp = np.asarray(cut.vertices)
        err = np.abs(np.linalg.norm(cp, axis=1) - section(_ANGLE[plane](cp)) * section.scale)
        assert err.max() < tol * r0, plane
    # the corrected contours meet at the six axis points
    s, q = con.sections, GRID // 4
    pairs = [((0, 0), (1, 0)), ((0, 2 * q), (1, 2 * q)), ((0, q), (2, 0)), ((0, 3 * q), (2, 2 * q)),
             ((1, q), (2, q)), ((1, 3 * q), (2, 3 * q))]
    for (a, i), (b, j) in pairs:
        assert s[a][i] == pytest.approx(s[b][j], rel=1e-12)
    # measured descriptors of the sections are recorded, and the correction is modest
    for k, plane in enumerate(PLANES):
        assert info[f"section_{plane}_D8"] == pytest.approx(Contour(s[k]).descriptors()[8], rel=1e-9)
    assert 0 <= info["correction"] < 0.3


def test_contours_are_band_limited_to_the_mesh():
    """A level-s grain keeps harmonics up to 2^s: coarse grains are low-passed, not aliased."""
    for s, kept in ((2, 4), (3, 8), (5, 32), (6, 64)):
        p = Params(preset="rough-angular", subdivisions=s)
        D = np.array([Contour(x).descriptors(128) for x in construct(p, 1).sections])
        # above kept + 2 nothing is left (the smooth stretch and correction, which are mostly
        # modes 0-2, shift a little energy by up to two harmonics)
        if kept < 64:
            unlimited = descriptor_spectrum(0.15, 0.10, 0.03)[kept + 3]
            assert D[:, kept + 3:].max() < 0.15 * unlimited
        assert build(p, np.random.default_rng(1))[2]["modes_used"] == min(64, kept)
    hi = Contour(construct(Params(preset="rough-angular", subdivisions=3), 1).sections[0])
    assert hi.descriptors()[8] > 0.015  # roughness D8 survives at level 3


def test_sections_keep_the_input_contours_shape():
    """Alignment, a consistent L:I:S and the correction change the contours little (rough spheres)."""
    p = Params(preset="rough-sphere")
    con = construct(p, 0)
    for k in range(3):
        ins = con.inputs[k].descriptors(16)
        sec = Contour(con.sections[k]).descriptors(16)
        assert abs(sec[8] - ins[8]) < 0.005  # roughness D8 = 0.02 kept
        assert sec[2] < 0.03  # no strong elongation appears


def test_three_descriptor_sets_are_used():
    g = grainforge.cri(descriptors=(0.1, 0.05, 0.02), descriptors_xz=(0.2, 0.1, 0.03),
                       descriptors_yz=(0.0, 0.0, 0.01), subdivisions=2, rng=1)
    assert g.info["contour_xy_D2"] == pytest.approx(0.1)
    assert g.info["contour_xz_D2"] == pytest.approx(0.2)
    assert g.info["contour_xz_D8"] == pytest.approx(0.03)
    assert g.info["contour_yz_D8"] == pytest.approx(0.01)


@pytest.mark.parametrize("aspect", [(2.0, 1.5, 1.0), (1.2, 1.1, 1.0), (3.0, 1.0, 1.0)])
def test_aspect_sets_the_extents(aspect):
    p = Params(aspect=aspect, subdivisions=5)
    v, f, info = build(p, np.random.default_rng(2))
    ext = np.ptp(v, axis=0)
    np.testing.assert_allclose(ext / ext[2], np.array(aspect) / aspect[2], rtol=1e-6)
    assert not solid_problems(v, f)


def test_presets_from_python_and_defaults():
    a = grainforge.cri(preset="rough-angular", subdivisions=3, rng=0)
    b = grainforge.cri(descriptors=(0.15, 0.10, 0.03), subdivisions=3, rng=0)
    c = grainforge.cri(subdivisions=3, rng=0)  # default: the rough-angular descriptors
    assert export_bytes(a) == export_bytes(b) == export_bytes(c)
    assert a.params.descriptors == (0.15, 0.10, 0.03)
    s = grainforge.cri(preset="rough-sphere", subdivisions=3, rng=0)
    assert s.params.descriptors == (0.0, 0.0, 0.02)
    # rough spheres are rounder than rough angular grains
    from grainforge.analysis.descriptors import basic_descriptors

    assert basic_descriptors(s)["sphericity"] > basic_descriptors(a)["sphericity"]


def test_given_contours_and_images(three_images):
    cs = [Contour.from_image(p) for p in three_images]
    a = grainforge.cri(contours=cs, subdivisions=3, rng=0)
    b = grainforge.cri(images=three_images, subdivisions=3, rng=0)
    c = grainforge.cri(images=",".join(three_images), subdivisions=3, rng=0)
    assert export_bytes(a) == export_bytes(c)
    assert a.vertices.tobytes() == b.vertices.tobytes()
    # image contours use no randomness: without the ridge twist (whose turns the seed draws) every seed
    # gives the same grain
    d0 = grainforge.cri(images=three_images, subdivisions=3, ridge_twist=0.0, rng=0)
    d5 = grainforge.cri(images=three_images, subdivisions=3, ridge_twist=0.0, rng=5)
    assert d0.vertices.tobytes() == d5.vertices.tobytes()
    assert a.params.contour == "given" and b.params.contour == "image"
    assert b.info["contour_xy_D2"] == pytest.approx(cs[0].descriptors()[2])


@given(
    d=st.tuples(st.floats(0, 0.25), st.floats(0, 0.12), st.floats(0, 0.05)),
    decay=st.tuples(st.floats(-3, -0.5), st.floats(-3, -0.5)),
    modes=st.integers(8, 120),
    morph=st.floats(0.5, 8),
    aspect=st.none() | st.tuples(st.floats(1, 3), st.floats(0.5, 1), st.floats(0.3, 1)).map(
        lambda t: (t[0], t[0] * t[1], t[0] * t[1] * t[2])),
    fractal=st.booleans(),
    s=st.integers(0, 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_mesh_invariants_and_determinism(d, decay, modes, morph, aspect, fractal, s, seed):
    kw = dict(modes=modes, morph_exponent=morph, aspect=aspect, subdivisions=s)
    if fractal:
        kw.update(contour="fractal")
    else:
        kw.update(descriptors=d, decay=decay)
    try:
        p = Params(**kw)
        g = generate("cri", p, seed)
    except ParameterError as exc:  # descriptors too large for a positive radius
        assert exc.name == "descriptors" and "radius" in exc.reason
        return
    assert solid_problems(g.vertices, g.faces) == []
    assert g.mesh.is_watertight and g.mesh.volume > 0
    assert len(g.vertices) == 10 * 4**s + 2
    again = generate("cri", Params(**kw), seed)
    assert export_bytes(g) == export_bytes(again)


@pytest.mark.parametrize(
    "kw, name, match",
    [
        (dict(preset="rough-sphere", descriptors=(0.1, 0.1, 0.1)), "preset", "conflicts"),
        (dict(descriptors=(0.1, 0.1)), "descriptors", "3 comma-separated"),
        (dict(descriptors=(0.1, 0.1, 1.5)), "descriptors", r"\[0, 1\]"),
        (dict(contour="fractal", descriptors=(0.1, 0.1, 0.1)), "descriptors", "Fourier-descriptor"),
        (dict(contour="image"), "images", "required"),
        (dict(images="a.png,b.png"), "images", "three image files"),
        (dict(images="a.png,b.png,c.png", contour="fractal"), "images", "cannot be combined"),
        (dict(aspect=(1.0, 2.0, 3.0)), "aspect", "L >= I >= S"),
        (dict(decay=(-1.0,)), "decay", "2 comma-separated"),
        (dict(decay=(1.0, -1.0)), "decay", r"\[-10, 0\]"),
        (dict(modes=4), "modes", r"\[8, 120\]"),
        (dict(morph_exponent=0.0), "morph_exponent", r"\[0.5, 8\]"),
        (dict(preset="rough-cube"), "preset", "must be one of"),
    ],
)
def test_bad_parameters(kw, name, match):
    with pytest.raises(ParameterError, match=match) as info:
        Params(**kw)
    assert info.value.name == name


def test_bad_generation_inputs(tmp_path):
    with pytest.raises(ParameterError, match="descriptors_xz .*radius falls"):
        grainforge.cri(descriptors_xz=(0.9, 0.9, 0.5), subdivisions=1, rng=0)
    with pytest.raises(ParameterError, match="images .*no such image"):
        grainforge.cri(images=[tmp_path / "a.png"] * 3, subdivisions=1)
    with pytest.raises(ParameterError, match="sections"):
        Params(sections=(Contour(np.ones(16)),))


@pytest.mark.slow
def test_demo_section(tmp_path):
    """The demo's CRI section writes its figures, grains and manifests (quick mode)."""
    from grainforge.viz.demo import SECTIONS, cri_gallery

    assert cri_gallery in [f for _, f in SECTIONS]
    written = cri_gallery(tmp_path, quick=True)
    names = {p.name for p in written}
    assert {"cri-contours.png", "cri-grains.png", "cri-sections.png", "cri"} <= names
    for run in ("rough-sphere", "rough-angular", "fractal", "micrographs"):
        assert (tmp_path / "cri" / run / "manifest.csv").is_file()
        assert (tmp_path / "cri" / run / "cri-0000.stl").stat().st_size > 84
    for png in ("cri-contours.png", "cri-grains.png", "cri-sections.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
