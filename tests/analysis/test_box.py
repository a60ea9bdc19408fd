"""Minimum-volume oriented box (grainforge.analysis.box)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from grainforge import fso
from grainforge.analysis.box import MAX_HULL_VERTICES, minimum_box


def _rotation(seed):
    return trimesh.transformations.random_rotation_matrix(np.random.default_rng(seed).random(3))[:3, :3]


def _reference(points):
    """Independent face-flush search: a loop over every hull-face normal, each projection's 2D
    hull from Qhull, and the rectangle flush with each 2D hull edge measured over all its
    vertices (O(n²), no sorting tricks)."""
    hull = ConvexHull(points)
    X = points[hull.vertices]
    best = np.inf
    for n in hull.equations[:, :3]:
        a = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        q = np.stack([X @ a, X @ b], 1)
        h2 = ConvexHull(q)
        poly = q[h2.vertices]
        e = np.roll(poly, -1, 0) - poly
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        t = poly @ e.T
        s = poly @ np.stack([-e[:, 1], e[:, 0]], 1).T
        area = np.ptp(t, axis=0) * np.ptp(s, axis=0)
        best = min(best, float(area.min() * np.ptp(X @ n)))
    return best


def test_rotated_box_is_exact():
    corners = np.array(np.meshgrid([0, 3], [0, 1], [0, 2])).T.reshape(-1, 3).astype(float)
    R = _rotation(4)
    extents, axes = minimum_box(corners @ R.T + 5.0)
    np.testing.assert_allclose(extents, [3, 2, 1], atol=1e-12)
    np.testing.assert_allclose(np.abs(axes @ R), np.eye(3)[[0, 2, 1]], atol=1e-12)


def test_axis_aligned_box_has_no_rounding():
    box = trimesh.creation.box(extents=(4, 2, 1))
    assert minimum_box(box.vertices)[0].tolist() == [4.0, 2.0, 1.0]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(8, 80))
def test_matches_independent_search_and_holds_every_point(seed, n):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3)) * rng.uniform(0.2, 3.0, 3)
    extents, axes = minimum_box(pts)
    np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.ptp(pts @ axes.T, axis=0), extents, rtol=1e-12)  # the box holds every point
    assert np.all(np.diff(extents) <= 0)
    assert np.prod(extents) == pytest.approx(_reference(pts), rel=1e-9)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_never_larger_than_trimesh_and_equal_to_the_exhaustive_search_on_rough_grains(seed):
    v = np.asarray(fso(subdivisions=4, rng=seed).vertices)
    ours = np.prod(minimum_box(v)[0])
    _, ext = trimesh.bounds.oriented_bounds(v)
    assert ours <= np.prod(ext) * (1 + 1e-9)
    assert ours == pytest.approx(_reference(v), rel=1e-9)


def test_lattice_points_with_collinear_outline_edges():
    # a 4×3×2 block of lattice points: many coplanar hull facets and collinear outline edges
    cells = np.array(np.meshgrid(range(5), range(4), range(3))).T.reshape(-1, 3).astype(float)
    extents, _ = minimum_box(cells @ _rotation(7).T)
    np.testing.assert_allclose(extents, [4, 3, 2], atol=1e-9)


@pytest.mark.parametrize("level", [5, 6])
def test_dense_smooth_hull_is_searched_on_extreme_points_and_close(level):
    # an ellipsoid hull with 10,242 or 40,962 vertices: more than MAX_HULL_VERTICES, so the search
    # runs on the extreme points in 1,024 directions, then the box is turned to fit all points
    # (approximate: within 0.05 % of the 4 × 2 × 1 box the faceted ellipsoid fits in; measured
    # 0.011 % and 0.004 %); the box is measured on every point, so it holds them all
    e = trimesh.creation.icosphere(level)
    e.apply_scale((2.0, 1.0, 0.5))
    assert len(e.vertices) > MAX_HULL_VERTICES
    pts = e.vertices @ _rotation(2).T
    extents, axes = minimum_box(pts)
    np.testing.assert_allclose(extents, [4, 2, 1], rtol=5e-4)
    np.testing.assert_allclose(np.ptp(pts @ axes.T, axis=0), extents, rtol=1e-12)


def test_flat_points_fall_back():
    sq = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], dtype=float)
    extents, _ = minimum_box(sq)
    np.testing.assert_allclose(extents, [2, 1, 0], atol=1e-12)


def test_collinear_and_single_points():
    line = np.array([[0, 0, 0], [1, 1, 0], [3, 3, 0]], dtype=float)
    np.testing.assert_allclose(minimum_box(line)[0], [3 * np.sqrt(2), 0, 0], atol=1e-12)
    np.testing.assert_allclose(minimum_box(np.ones((1, 3)))[0], [0, 0, 0])


def test_the_lower_bound_skips_candidates_but_never_the_winner():
    """The subset bound (_lower_bounds) is a true lower bound for every candidate, and the search
    with it returns the box of the search over every candidate, bit for bit."""
    from scipy.spatial import ConvexHull

    from grainforge import cri, fso
    from grainforge.analysis import box

    for g in (fso(subdivisions=4, rng=1), cri(descriptors=(0.15, 0.10, 0.03), rng=2)):
        hull = ConvexHull(g.vertices)
        X, fn, edges, edge_faces = box._hull_edges(hull)
        n = box._candidate_normals(fn)
        exact = np.concatenate([box._chunk_volumes(X, X.mean(axis=0), fn, edges, edge_faces, n[i:i + 200])[0]
                                for i in range(0, len(n), 200)])
        lower = box._lower_bounds(X, n)
        assert np.all(lower <= exact * (1 + 1e-12))
        assert np.mean(lower > exact.min()) > 0.5  # most candidates are skipped
        bounded = box.minimum_box(g.vertices, hull)
        saved = box._BOUND_DIRECTIONS
        try:
            box._BOUND_DIRECTIONS = 10**9  # no bound: every candidate searched
            plain = box.minimum_box(g.vertices, hull)
        finally:
            box._BOUND_DIRECTIONS = saved
        assert np.array_equal(bounded[0], plain[0]) and np.array_equal(bounded[1], plain[1])
