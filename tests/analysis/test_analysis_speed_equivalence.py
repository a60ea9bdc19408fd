"""The vectorised fast paths of the shape analysis give the results of their straightforward versions.

The references below are the plain implementations the fast ones replaced
(per-corner angles, ``np.angle(np.exp(1j·x))`` wrapping, stable argsorts,
``np.mod``, a stacked design matrix): results must agree to rounding and the
star-shapedness flags exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from grainforge import fso
from grainforge.analysis import fourier, fractal


def _silhouette_radii_ref(points, faces, origin, n_rays, rays=None):
    q = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = q[f]
    step = 2 * np.pi / n_rays
    ang = np.arctan2(tri[..., 1], tri[..., 0])
    d = np.angle(np.exp(1j * (ang - ang[:, :1])))
    lo, hi = ang[:, 0] + d.min(1), ang[:, 0] + d.max(1)
    e0, e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]
    c0 = e0[:, 0] * (-tri[:, 0, 1]) - e0[:, 1] * (-tri[:, 0, 0])
    c1 = e1[:, 0] * (-tri[:, 1, 1]) - e1[:, 1] * (-tri[:, 1, 0])
    c2 = e2[:, 0] * (-tri[:, 2, 1]) - e2[:, 1] * (-tri[:, 2, 0])
    inside = ((c0 >= 0) & (c1 >= 0) & (c2 >= 0)) | ((c0 <= 0) & (c1 <= 0) & (c2 <= 0))
    k0 = np.where(inside, 0, np.ceil(lo / step - 1e-9).astype(np.int64))
    k1 = np.where(inside, n_rays - 1, np.floor(hi / step + 1e-9).astype(np.int64))
    pairs = [(i, k % n_rays) for i in range(len(f)) for k in range(k0[i], k1[i] + 1)]
    tri_idx, ray = (np.array(c, dtype=np.int64) for c in zip(*pairs))
    wanted = np.ones(n_rays, bool) if rays is None else np.asarray(rays, dtype=bool)
    keep = wanted[ray]
    ray, tri_idx = ray[keep], tri_idx[keep]
    th = step * np.arange(n_rays)
    ux, uy = np.cos(th)[ray], np.sin(th)[ray]
    E = np.roll(tri, -1, axis=1) - tri
    t_hi, t_lo = np.full(len(ray), -np.inf), np.full(len(ray), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for m in range(3):
            px, py = tri[tri_idx, m, 0], tri[tri_idx, m, 1]
            ex, ey = E[tri_idx, m, 0], E[tri_idx, m, 1]
            den = uy * ex - ux * ey
            t = (py * ex - px * ey) / den
            sp = (ux * py - uy * px) / den
            ok = (sp >= -1e-9) & (sp <= 1 + 1e-9) & (t >= 0)
            t_hi = np.maximum(t_hi, np.where(ok, t, -np.inf))
            t_lo = np.minimum(t_lo, np.where(ok, t, np.inf))
    t_lo = np.where(inside[tri_idx], 0.0, t_lo)
    hit = np.isfinite(t_hi)
    ray, t_lo, t_hi = ray[hit], t_lo[hit], t_hi[hit]
    r = np.full(n_rays, -np.inf)
    np.maximum.at(r, ray, t_hi)
    r[~wanted] = np.nan
    big = 4.0 * float(np.nanmax(r)) + 1.0
    o = np.argsort(t_lo + ray * big, kind="stable")
    s_, e_, ray_o = (t_lo + ray * big)[o], (t_hi + ray * big)[o], ray[o]
    reach = np.maximum.accumulate(e_)
    first = np.r_[True, ray_o[1:] != ray_o[:-1]]
    gap = (first & (t_lo[o] > 1e-9 * big)) | (~first & (s_ > np.r_[-np.inf, reach[:-1]] + 1e-9 * big))
    return r, not bool(gap.any())


@pytest.fixture(scope="module")
def grain():
    g = fso(subdivisions=3, rng=2)
    return np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces, dtype=np.int64)


def test_silhouette_radii_matches_reference(grain):
    v, f = grain
    centre, axes = fourier.principal_axes(v, f)
    p = (v - centre) @ axes.T
    rng = np.random.default_rng(0)
    for i, j in fourier.PLANES.values():
        q = p[:, [i, j]]
        for origin in (np.zeros(2), 0.05 * rng.normal(size=2)):
            for n_rays in (128, 37):
                for rays in (None, rng.random(n_rays) < 0.3):
                    r, star = fourier.silhouette_radii(q, f, origin=origin, n_rays=n_rays, rays=rays)
                    r_ref, star_ref = _silhouette_radii_ref(q, f, origin, n_rays, rays=rays)
                    assert star == star_ref
                    np.testing.assert_allclose(r, r_ref, rtol=1e-12, atol=0)


def test_silhouette_radii_not_star_shaped():
    # a C-shaped outline seen from a point in its notch: some ray leaves and re-enters it
    c = np.array([[0, 0], [3, 0], [3, 1], [1, 1], [1, 2], [3, 2], [3, 3], [0, 3]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 7], [4, 5, 6], [4, 6, 7]])
    for origin, expected in (((0.5, 1.5), False), ((0.5, 0.5), False), ((0.5, 2.5), False)):
        r, star = fourier.silhouette_radii(c, faces, origin=origin, n_rays=64)
        r_ref, star_ref = _silhouette_radii_ref(c, faces, origin, 64)
        assert star == star_ref == expected
        np.testing.assert_allclose(r, r_ref, rtol=1e-12)


def test_edge_faces_matches_stable_argsort(grain):
    _, f = grain
    for faces in (f, f + 2**30):  # the second overflows the packed key: the argsort path
        a, b = faces.ravel(), np.roll(faces, -1, axis=1).ravel()
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = lo * (int(faces.max()) + 1) + hi
        o = np.argsort(key, kind="stable")
        pair = np.flatnonzero(key[o][1:] == key[o][:-1])
        edges, edge_faces = fourier._edge_faces(faces)
        np.testing.assert_array_equal(edges, np.stack([lo[o][pair], hi[o][pair]], 1))
        np.testing.assert_array_equal(edge_faces, np.stack([o[pair] // 3, o[pair + 1] // 3], 1))


@pytest.mark.parametrize("n_rays", [8, 128])
def test_span_pairs_and_wrap(n_rays):
    rng = np.random.default_rng(1)
    k0 = rng.integers(-n_rays, n_rays, 200)
    k1 = k0 + rng.integers(-2, 5, 200)
    k1[:3] = k0[:3] + 3 * n_rays  # out of the usual range: the np.mod path
    for lo_, hi_ in ((k0[3:], k1[3:]), (k0, k1)):
        item, ray = fourier._span_pairs(lo_, hi_, n_rays)
        ref = [(i, k % n_rays) for i in range(len(lo_)) for k in range(lo_[i], hi_[i] + 1)]
        assert list(zip(item.tolist(), ray.tolist())) == ref
    d = np.r_[np.linspace(-2 * np.pi, 2 * np.pi, 1001), -np.pi, np.pi]
    np.testing.assert_allclose(fourier._wrap(d), np.angle(np.exp(1j * d)), rtol=0, atol=1e-14)
    a = np.r_[rng.random(50), 0.5, 0.5, 0.25, 0.5]
    np.testing.assert_array_equal(fourier._stable_argsort(a), np.argsort(a, kind="stable"))


def test_smooth_fit_matches_design_matrix_lstsq(grain):
    v, f = grain
    u, r = fractal.radial_function(v, v.mean(0))
    w = np.random.default_rng(2).random(len(r)) + 0.5
    B = np.stack([u[:, 0] ** a * u[:, 1] ** b * u[:, 2] ** c for a, b, c in fractal._MONOMIALS], 1)
    np.testing.assert_allclose(fractal._basis(u), B.T, rtol=1e-13, atol=1e-15)
    s = r.mean()
    sw = np.sqrt(w)
    coef = np.linalg.lstsq(B * sw[:, None], (s / r) ** 2 * sw, rcond=None)[0]
    np.testing.assert_allclose(fractal.smooth_fit(u, r, w), s / np.sqrt(B @ coef), rtol=1e-10)


def _variogram_ref(u, h, bins, subset=1000):
    """The variogram by brute force: every pair's separation (arccos), the first bin from all pairs,
    the others from all pairs of the strided subset."""
    n = len(u)
    i, j = np.triu_indices(n, 1)
    sep = np.arccos(np.clip(np.einsum("ij,ij->i", u[i], u[j]), -1.0, 1.0))
    which = np.digitize(sep, bins) - 1
    idx = np.unique(np.linspace(0, n - 1, min(subset, n)).round().astype(np.int64))
    in_subset = np.zeros(n, dtype=bool)
    in_subset[idx] = True
    good = (which == 0) | ((which >= 1) & (which < len(bins) - 1) & in_subset[i] & in_subset[j])
    counts = np.bincount(which[good], minlength=len(bins) - 1)
    with np.errstate(invalid="ignore"):  # empty bins: NaN, as in variogram
        gamma = np.bincount(which[good], 0.5 * (h[i] - h[j])[good] ** 2, minlength=len(bins) - 1) / counts
        centres = np.bincount(which[good], sep[good], minlength=len(bins) - 1) / counts
    return centres, gamma, counts


@pytest.mark.parametrize("subdivisions", [3, 4])
def test_variogram_matches_brute_force(subdivisions):
    g = fso(subdivisions=subdivisions, rng=3)
    u, r = fractal.radial_function(g.vertices, g.vertices.mean(axis=0))
    h = r - r.mean()
    bins = np.geomspace(0.09, 0.35, 9) if subdivisions == 4 else np.geomspace(0.22, 0.6, 9)  # from ≈ 2 edges
    centres, gamma, counts = fractal.variogram(u, h, bins)
    rc, rg, rn = _variogram_ref(u, h, bins)
    # binning on −cos instead of the angle can move a pair lying within rounding of a bin edge: none here
    np.testing.assert_array_equal(counts, rn)
    np.testing.assert_allclose(gamma, rg, rtol=1e-12)
    np.testing.assert_allclose(centres, rc, rtol=1e-12)


def test_analyse_not_solid_flag_same_with_the_star_certificate():
    """analyse proves star-shaped bodies free of self-intersections in O(F); the flag is the pair test's."""
    from grainforge.analysis.measure import analyse_mesh
    from grainforge.geometry.geodesic import icosphere
    from grainforge.geometry.solid import self_intersections

    v, f = icosphere(2)
    poked = v.copy()
    poked[0] = -1.6 * poked[0]  # one vertex pulled through the far side: its faces cross the surface there
    grain = fso(subdivisions=3, rng=0)
    for verts, faces, crossing in ((grain.vertices, grain.faces, False), (v, f, False), (poked, f, True)):
        assert (self_intersections(verts, faces) > 0) == crossing
        flags = analyse_mesh(verts, faces, fractal=False, fourier=False)["flags"]
        assert ("not-solid" in flags) == crossing, flags


def test_solid_problems_same_answer_with_the_star_certificate():
    """The certificate short cut (one body, no pinch, positive volume, no crossing) changes no answer."""
    from grainforge.geometry.geodesic import icosphere
    from grainforge.geometry.solid import solid_problems

    v, f = icosphere(2)
    poked = v.copy()
    poked[0] = -1.6 * poked[0]
    twin = 2 * v[0] - v  # a point-reflected copy touching the sphere at vertex 0 only: a pinch when merged
    pinched = (np.vstack([v, twin]), np.vstack([f, f[:, ::-1] + len(v)]))
    apart = (np.vstack([v, v + 3.0]), np.vstack([f, f + len(v)]))
    inside_out = (v, f[:, ::-1])
    grain = fso(subdivisions=3, rng=1)
    cases = [(grain.vertices, grain.faces), (v, f), (poked, f), pinched, apart, inside_out]
    answers = [solid_problems(vv, ff) for vv, ff in cases]
    assert answers[0] == answers[1] == [] and all(answers[2:]), answers
    for (vv, ff), plain in zip(cases, answers):
        for centre in (np.zeros(3), np.asarray(vv, dtype=np.float64).mean(axis=0), np.array([0.9, 0.0, 0.0])):
            assert solid_problems(vv, ff, star_centre=centre) == plain


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("exact32", [True, False])
def test_unique_rows_matches_np_unique(dtype, exact32):
    """Both sorting paths of unique_rows (packed float32 keys; lexsort) give np.unique's rows and inverse."""
    from grainforge.geometry.solid import unique_rows

    rng = np.random.default_rng(4)
    p = rng.integers(-3, 4, size=(4000, 3)).astype(np.float64) * 0.5  # many duplicates, negatives
    p[rng.random(p.shape) < 0.05] = -0.0  # signed zeros equal zeros
    p = np.vstack([p, [[np.float32(1e30), -np.float32(1e-30), 0.1]]])
    if not exact32 and dtype == np.float64:
        p[:, 2] += 1e-12 * rng.random(len(p))  # not representable in float32: the lexsort path
    p = p.astype(dtype)
    u, inv = unique_rows(p)
    ru, rinv = np.unique(p, axis=0, return_inverse=True)
    np.testing.assert_array_equal(u, ru)
    np.testing.assert_array_equal(inv, rinv.reshape(-1))
