"""The one voxeliser (grainforge.geometry.voxel) against independent references: analytic solids and
trimesh's own point-in-mesh test (``contains``, ray parity with trimesh's own ray engine)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import grainforge
from grainforge.geometry.voxel import ANCHORS, RULES, grid_for, inside_mask


def _centres(grid):
    return np.stack(np.meshgrid(*grid.axes(), indexing="ij"), axis=-1).reshape(-1, 3)


@pytest.mark.parametrize("anchor", ANCHORS)
@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("rule", RULES)
def test_box_counts_are_exact(anchor, axis, rule):
    """An axis-aligned 2 × 1.2 × 0.8 box off the origin: the centres inside, counted analytically."""
    box = trimesh.creation.box((2.0, 1.2, 0.8))
    v = box.vertices + [0.31, -0.17, 0.05]
    grid = grid_for(v, 0.1, pad=2, anchor=anchor)
    got = inside_mask(v, box.faces, grid, axis=axis, rule=rule)
    c = _centres(grid)
    lo, hi = v.min(axis=0), v.max(axis=0)
    # centres exactly on a face (possible on the lattice) go to one side of each pair: compare off them
    on_face = np.any(np.isclose(c, lo, atol=1e-9) | np.isclose(c, hi, atol=1e-9), axis=1)
    want = np.all((c > lo) & (c < hi), axis=1)
    assert got.shape == grid.shape and got.flags.c_contiguous
    assert np.array_equal(got.reshape(-1)[~on_face], want[~on_face])
    if anchor == "centred":  # the irrational shift keeps every centre off the faces
        assert not on_face.any() and int(got.sum()) == 20 * 12 * 8


@pytest.mark.parametrize("anchor", ANCHORS)
def test_ball_is_the_analytic_ball_away_from_the_surface(anchor):
    """Cells farther than the chord error from the unit sphere are classified as the ball is;
    the count matches the mesh's volume / h³ to the discretisation's few per cent."""
    ball = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    h = 0.05
    grid = grid_for(ball.vertices, h, pad=1, anchor=anchor)
    got = inside_mask(ball.vertices, ball.faces, grid).reshape(-1)
    r = np.linalg.norm(_centres(grid), axis=1)
    far = np.abs(r - 1.0) > 2e-3  # the icosphere's chords sit at most ~1.2e-3 inside the sphere
    assert np.array_equal(got[far], r[far] < 1.0)
    assert got.sum() * h**3 == pytest.approx(ball.volume, rel=0.01)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_generated_grain_agrees_with_trimesh_contains(seed):
    # a CRI grain of 1,280 faces, 24 cells across (about 12,000 cells): trimesh without embreex casts its rays in
    # NumPy, 1-3 s here (the default 20,480 faces: 51 s at 24 cells, 14 s at 16)
    g = grainforge.cri(rng=seed, subdivisions=3)
    mesh = trimesh.Trimesh(g.vertices, g.faces, process=False)
    grid = grid_for(g.vertices, np.ptp(g.vertices, axis=0).max() / 24, pad=1)
    c = _centres(grid)
    ref = mesh.contains(c)
    for axis in (0, 2):
        for rule in RULES:
            got = inside_mask(g.vertices, g.faces, grid, axis=axis, rule=rule).reshape(-1)
            # trimesh's contains is a ray test with its own tolerances: a few cells at the surface may differ
            assert (got != ref).sum() <= 2, (axis, rule, int((got != ref).sum()))


def test_winding_is_the_union_parity_the_symmetric_difference():
    """Two overlapping closed boxes: winding number > 0 is their union, parity their XOR."""
    a = trimesh.creation.box((1.0, 1.0, 1.0))
    b = trimesh.creation.box((1.0, 1.0, 1.0))
    v = np.vstack([a.vertices, b.vertices + [0.5, 0.0, 0.0]])
    f = np.vstack([a.faces, b.faces + len(a.vertices)])
    grid = grid_for(v, 0.1, pad=1)
    c = _centres(grid)
    in_a = np.all(np.abs(c) < 0.5, axis=1)
    in_b = np.all(np.abs(c - [0.5, 0.0, 0.0]) < 0.5, axis=1)
    assert np.array_equal(inside_mask(v, f, grid, rule="winding").reshape(-1), in_a | in_b)
    assert np.array_equal(inside_mask(v, f, grid, rule="parity").reshape(-1), in_a ^ in_b)


def test_an_open_mesh_is_refused():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    top = np.flatnonzero(box.face_normals[:, 2] > 0.5)[0]  # a face the z columns cross
    grid = grid_for(box.vertices, 0.1)
    for rule in RULES:
        with pytest.raises(ValueError, match="not closed"):
            inside_mask(box.vertices, np.delete(box.faces, top, axis=0), grid, rule=rule)


def test_bad_conventions_are_refused():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="anchor"):
        grid_for(box.vertices, 0.1, anchor="corner")
    grid = grid_for(box.vertices, 0.1)
    with pytest.raises(ValueError, match="axis"):
        inside_mask(box.vertices, box.faces, grid, axis=3)
    with pytest.raises(ValueError, match="rule"):
        inside_mask(box.vertices, box.faces, grid, rule="even-odd")
