"""Sand-Atlas voxel descriptors (grainforge.analysis.atlas) against analytic shapes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grainforge.analysis.atlas import (
    OPENING_RADIUS,
    _hull_count,
    atlas_descriptors,
    opening_fraction,
    voxel_descriptors,
    voxel_image,
    voxelise,
)
from grainforge.cli.main import cli
from grainforge.geometry.rotations import random_rotation


def _ellipsoid(a, b, c, subdivisions=5):
    ball = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return trimesh.Trimesh(ball.vertices * [a, b, c], ball.faces, process=False)


@pytest.mark.parametrize("axes", [(1, 1, 1), (1, 0.8, 0.6), (1, 0.5, 0.3)])
def test_ellipsoid_axes_and_ratios_are_exact_to_the_resolution(axes):
    n = 40
    m = _ellipsoid(*axes)
    for rot in (None, 3):
        d = atlas_descriptors(m, voxels_across=n, rotation=rot)
        h = d["voxel_size"]
        got = np.array([d["major"], d["middle"], d["minor"]])
        # the icosphere's chords make the mesh ellipsoid about 0.1 % smaller than the analytic one
        assert np.all(np.abs(got - 2 * np.array(axes)) < 0.5 * h + 0.003), (got, h)
        assert d["flatness"] == pytest.approx(axes[2] / axes[1], abs=1.0 / n)
        assert d["elongation"] == pytest.approx(axes[1] / axes[0], abs=1.0 / n)
        assert d["equivalent_diameter"] == pytest.approx(2 * np.prod(axes) ** (1 / 3), rel=0.01)
        assert d["convexity"] > 0.995
        assert d["voxels_across"] == pytest.approx(n, rel=0.01 if rot is None else 0.01)


def test_sphere_sphericity_bias_is_small_and_shrinks_with_resolution():
    ball = _ellipsoid(1, 1, 1)
    s = [atlas_descriptors(ball, voxels_across=n)["sphericity"] for n in (20, 60)]
    # measured (docs/validation.md): about +0.004 at 20 voxels across, -0.008 at 60 (from below as n grows)
    assert abs(s[0] - 1) < 0.02 and abs(s[1] - 1) < 0.012
    assert 0.98 < s[1] < 1.0


def test_box_voxel_count_and_concave_convexity_are_exact():
    # an L-shaped prism: 75 voxels per layer; its lattice hull holds the 85 points with x + y <= 13
    g = np.indices((10, 10, 4))
    mask = ~((g[0] >= 5) & (g[1] >= 5))
    d = voxel_descriptors(mask, voxel_size=2.0)
    assert d["voxels"] == 300 and d["volume"] == 300 * 8.0
    assert d["convexity"] == pytest.approx(75 / 85, abs=1e-12)
    m = trimesh.creation.box(extents=(3.0, 2.0, 1.0))
    mask, origin = voxelise(m.vertices, m.faces, 0.25)
    assert mask.sum() == 12 * 8 * 4


def test_hull_count_matches_a_brute_force_count():
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(5)
    for _ in range(3):
        mask = np.zeros((12, 13, 14), bool)
        pts = rng.integers(0, 12, size=(40, 3))
        mask[pts[:, 0], pts[:, 1], pts[:, 2]] = True
        grid = np.argwhere(np.ones(mask.shape, bool))
        brute = int(np.sum(Delaunay(np.argwhere(mask)).find_simplex(grid, tol=1e-9) >= 0))
        assert _hull_count(mask) == brute


def test_hull_count_of_flat_and_thin_masks():
    # one voxel thick: an L in a vertical plane (x fixed) holds 75 of the 85 lattice points of its hull
    g = np.indices((10, 10))
    layer = ~((g[0] >= 5) & (g[1] >= 5))
    mask = np.zeros((3, 10, 10), bool)
    mask[1] = layer
    assert _hull_count(mask) == 85
    assert _hull_count(np.moveaxis(mask, 0, 2)) == 85  # the same L lying flat
    line = np.zeros((7, 7, 7), bool)
    line[[0, 6], [0, 3], [0, 6]] = True  # a segment along (2, 1, 2): 4 lattice points
    assert _hull_count(line) == 4
    tilted = np.zeros((5, 5, 5), bool)
    tilted[[0, 4, 0], [0, 0, 4], [0, 4, 0]] = True  # the triangle x = z, x + y <= 4, x, y >= 0: 15 points
    assert _hull_count(tilted) == 15


def test_scanline_voxeliser_equals_ray_parity_and_hull_count_equals_brute_force_on_a_rough_grain():
    from scipy.spatial import ConvexHull, Delaunay

    import grainforge
    from grainforge.geometry.voxel import _ray_toggles
    from grainforge.methods import get

    g = grainforge.generate("cri", get("cri").Params(descriptors=(0, 0.12, 0.012), aspect=(1, 0.7, 0.55),
                                                     subdivisions=4), 2)
    v = np.asarray(g.vertices) @ random_rotation(5).T
    f = np.asarray(g.faces)
    for h in (0.08, 0.031):  # about 12 and 30 voxels across
        mask, origin = voxelise(v, f, h)
        nx, ny, nz = mask.shape
        cols = np.argwhere(np.ones((nx, ny), bool))
        # every column cast as a +z ray by trimesh (the independent route kept as the fallback)
        tog = _ray_toggles(v, f, origin[:2] + cols * h, v[:, 2].min() - h, origin[2], h, nz)
        rays = (np.cumsum(tog[:, :-1], axis=1) % 2).astype(bool).reshape(mask.shape)
        assert mask.sum() > 1000 and np.array_equal(mask, rays)
        vox = np.argwhere(mask)
        lo, hi = vox.min(0), vox.max(0)
        grid = np.argwhere(np.ones(tuple(hi - lo + 1), bool)) + lo
        corners = vox[ConvexHull(vox).vertices]  # Qhull with its default merging, on every voxel centre
        brute = int(np.sum(Delaunay(corners).find_simplex(grid, tol=1e-9) >= 0))
        assert _hull_count(mask) == brute and brute > mask.sum()


def test_rotation_is_a_rotation_and_is_reproducible():
    R = random_rotation(7)
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.array_equal(R, random_rotation(7))


def test_bad_inputs_raise_value_error():
    m = _ellipsoid(1, 1, 1, 2)
    with pytest.raises(ValueError, match="exactly one"):
        atlas_descriptors(m)
    with pytest.raises(ValueError, match="positive"):
        atlas_descriptors(m, voxel_size=-1.0)
    opened = trimesh.Trimesh(m.vertices, m.faces[:-4], process=False)
    with pytest.raises(ValueError, match="not closed"):
        atlas_descriptors(opened, voxels_across=20)


def test_atlas_agrees_with_mesh_descriptors_on_a_generated_grain():
    import grainforge
    from grainforge.analysis import describe
    from grainforge.methods import get

    g = grainforge.generate("cri", get("cri").Params(preset="rough-sphere", aspect=(1.0, 0.7, 0.5), subdivisions=4),
                            4)
    d = atlas_descriptors(g, voxels_across=50)
    mesh = describe(g, fractal=False, fourier=False)
    assert d["equivalent_diameter"] == pytest.approx(mesh["equivalent_diameter"], rel=0.01)
    assert d["convexity"] == pytest.approx(mesh["convexity"], abs=0.02)
    # Wadell sphericity of the mesh vs the smoothed voxel surface: same shape, within a few per cent
    assert d["sphericity"] == pytest.approx(mesh["sphericity"], abs=0.03)
    # the mesh's own inertia-equivalent ellipsoid (exact for the mesh) against the voxels'
    from grainforge.analysis.mass import mesh_moments

    lam = np.sort(np.linalg.eigvalsh(mesh_moments(g.vertices, g.faces)["covariance"]))[::-1]
    axes = 2 * np.sqrt(5 * lam)
    assert d["major"] == pytest.approx(axes[0], rel=0.01) and d["minor"] == pytest.approx(axes[2], rel=0.01)
    assert d["elongation"] == pytest.approx(axes[1] / axes[0], abs=0.005)
    assert d["flatness"] == pytest.approx(axes[2] / axes[1], abs=0.005)


def test_analyse_cli_adds_atlas_columns(runner, tmp_path):
    p = tmp_path / "ball.stl"
    _ellipsoid(1, 0.8, 0.6, 3).export(p)
    r = runner.invoke(cli, ["analyse", str(p), "--voxels-across", "30", "--no-fractal", "--no-fourier", "--json"])
    assert r.exit_code == 0, r.output
    import json

    row = json.loads(r.stdout)[0]
    assert row["atlas_voxels_across"] == pytest.approx(30) and row["atlas_voxel_size_mm"] > 0
    assert row["atlas_elongation"] == pytest.approx(0.8, abs=0.03)
    r = runner.invoke(cli, ["analyse", str(p), "--voxels-across", "30", "--voxel-size-mm", "0.1"])
    assert r.exit_code == 2 and "not both" in r.stderr


def test_analyse_atlas_csv_is_a_sand_table_that_fit_reads(runner, tmp_path):
    """--atlas-csv writes the closed bodies' atlas_* measures as a Sand Atlas table in µm (the files in mm), with
    the opening fraction, that grainforge.fit.read_sand reads back to the analyse table's values; an open body is
    left out (and said so); without a resolution, or with no closed body, it is one line and exit 2."""
    import json

    from grainforge.fit import read_sand

    _ellipsoid(1, 0.8, 0.6, 3).export(tmp_path / "a.stl")
    trimesh.creation.box((1.0, 0.9, 0.7)).export(tmp_path / "b.stl")
    opened = trimesh.creation.icosphere(2)
    opened.update_faces(np.arange(len(opened.faces)) != 0)
    opened.export(tmp_path / "c.stl")
    out = tmp_path / "sand.csv"
    r = runner.invoke(cli, ["analyse", str(tmp_path / "a.stl"), str(tmp_path / "b.stl"), str(tmp_path / "c.stl"),
                            "--voxel-size-mm", "0.04", "--no-fractal", "--no-fourier", "--json",
                            "--atlas-csv", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert "wrote 2 grain(s)" in r.stderr and "1 open body/bodies left out" in r.stderr
    rows = [row for row in json.loads(r.stdout) if row["atlas_sphericity"] is not None]
    sand = read_sand(out)
    assert sand.count == 2 and sand.voxel_size == pytest.approx(40.0)
    for i, row in enumerate(rows):
        assert sand.equivalent_diameter[i] == pytest.approx(1000 * row["atlas_equivalent_diameter_mm"], rel=1e-5)
        for k in ("sphericity", "convexity", "flatness", "elongation"):
            assert sand.values[k][i] == pytest.approx(row["atlas_" + k], rel=1e-5)
        assert sand.opening[i] == pytest.approx(row["atlas_opening_fraction"], rel=1e-5)
    # the box's sharp edges and corners are what the ball misses; the ellipsoid has none
    assert sand.opening[1] < sand.opening[0] - 0.005 and sand.opening[0] > 0.99

    r = runner.invoke(cli, ["analyse", str(tmp_path / "a.stl"), "--atlas-csv", str(tmp_path / "x.csv")])
    assert r.exit_code == 2 and "--atlas-csv needs --voxel-size-mm" in r.stderr
    r = runner.invoke(cli, ["analyse", str(tmp_path / "c.stl"), "--voxels-across", "20", "--no-fractal",
                            "--no-fourier", "--atlas-csv", str(tmp_path / "y.csv")])
    assert r.exit_code == 2 and "no closed body" in r.stderr
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "y.csv").exists()


def test_straddling_cube_mask_gives_scikit_image_the_same_surface():
    """The marching-cubes mask only skips cubes without surface: same triangles, same area, bit for bit."""
    from scipy import ndimage
    from skimage.measure import marching_cubes, mesh_surface_area

    import grainforge
    from grainforge.analysis.atlas import SIGMA, straddling_cubes
    from grainforge.methods import get

    for method, kw, seed in (("cri", dict(preset="rough-angular", subdivisions=4), 3), ("fso", dict(subdivisions=4), 1)):
        g = grainforge.generate(method, get(method).Params(**kw), seed)
        v = np.asarray(g.vertices) @ random_rotation(seed).T
        for n in (15, 45):
            mask, _ = voxelise(v, g.faces, 2.0 / n)
            smooth = ndimage.gaussian_filter(np.pad(mask.astype(np.float32), 1), SIGMA, mode="constant", truncate=4.0)
            full = marching_cubes(smooth, 0.5, allow_degenerate=True)
            masked = marching_cubes(smooth, 0.5, allow_degenerate=True, mask=straddling_cubes(smooth, 0.5))
            assert np.array_equal(full[0], masked[0]) and np.array_equal(full[1], masked[1])
            assert mesh_surface_area(*masked[:2]) == mesh_surface_area(*full[:2]) > 0


def test_voxel_image_is_what_atlas_descriptors_measures():
    m = _ellipsoid(1, 0.7, 0.5)
    mask, h, d = voxel_image(m, voxels_across=30, rotation=5)
    ref = atlas_descriptors(m, voxels_across=30, rotation=5)
    assert h == ref["voxel_size"] and d / h == pytest.approx(ref["voxels_across"])
    assert voxel_descriptors(mask, h) == {k: v for k, v in ref.items()
                                          if k not in ("voxel_size", "voxels_across", "opening_fraction")}
    assert ref["opening_fraction"] == opening_fraction(mask, OPENING_RADIUS * d / h)


def test_opening_fraction_against_shapes_with_known_openings():
    # a ball is its own opening by any smaller ball: all kept but the voxel staircase
    ball, _, _ = voxel_image(trimesh.creation.icosphere(subdivisions=5), voxels_across=40, rotation=1)
    assert [opening_fraction(ball, r) for r in (2, 4)] == [pytest.approx(1, abs=0.005)] * 2
    # an axis-aligned cube loses its edges and corners: the rounded cube's volume, to a voxel
    a = 60
    cube = np.ones((a, a, a), bool)
    for r in (6.0, 9.0):
        exact = ((a - 2 * r) ** 3 + 6 * (a - 2 * r) ** 2 * r + 3 * np.pi * (a - 2 * r) * r**2 + 4 * np.pi * r**3 / 3)
        assert opening_fraction(cube, r) == pytest.approx(exact / a**3, abs=0.002)
    # turned off the grid, the cube's faces become voxel staircases the ball cannot fill: about 1 % less
    box = trimesh.creation.box(extents=(1, 1, 1))
    for seed in (0, 1):
        mask, h, _ = voxel_image(box, voxels_across=80, rotation=seed)
        side, r = 1 / h, 0.1 / h
        exact = ((side - 2 * r) ** 3 + 6 * (side - 2 * r) ** 2 * r + 3 * np.pi * (side - 2 * r) * r**2
                 + 4 * np.pi * r**3 / 3) / side**3
        assert exact - 0.015 < opening_fraction(mask, r) < exact - 0.005, (seed, exact)
    # a ball wider than the grain reaches none of it
    assert opening_fraction(np.ones((4, 4, 4), bool), 5.0) == 0.0


def test_opening_fraction_grows_with_a_grains_edge_rounding():
    from grainforge import angular

    kept = []
    for rounding in (0.0, 0.3, 0.6):
        g = angular(facets=10, rounding=rounding, aspect=(1.0, 0.8, 0.6), rng=4)
        mask, _, _ = voxel_image(g, voxels_across=40, rotation=2)
        kept.append(opening_fraction(mask, 3.0))
    assert kept[0] < kept[1] < kept[2], kept


def test_opening_fraction_refuses_a_bad_radius_or_an_empty_mask():
    with pytest.raises(ValueError, match="radius"):
        opening_fraction(np.ones((5, 5, 5), bool), 0.0)
    with pytest.raises(ValueError, match="radius"):
        opening_fraction(np.ones((5, 5, 5), bool), float("nan"))
    with pytest.raises(ValueError, match="empty"):
        opening_fraction(np.zeros((5, 5, 5), bool), 1.0)


@pytest.mark.parametrize("args, words", [
    (["--voxels-across", "2"], "2 voxels across its equivalent diameter is below 5"),
    (["--voxels-across", "4"], "4 voxels across its equivalent diameter is below 5"),
    (["--voxel-size-mm", "1"], "measure at a voxel size of at most"),
    (["--voxels-across", "500"], "the largest that fits is --voxels-across "),
    (["--voxel-size-mm", "0.001"], "the largest that fits is a voxel size of "),
])
def test_atlas_measures_that_mean_nothing_or_cannot_fit_are_refused_before_any_image(runner, tmp_path, monkeypatch,
                                                                                       args, words):
    """Below 5 voxels across the descriptors leave their ranges (a 4-voxel ball: sphericity ≈ 1.5); past the
    memory budget (here 1 GiB) the largest resolution that fits is named; nothing is written either way."""
    import grainforge.runtime.estimate

    monkeypatch.setattr(grainforge.runtime.estimate, "machine_memory", lambda: 2 * 1024**3)
    p = tmp_path / "ball.stl"
    _ellipsoid(1, 0.8, 0.6, 3).export(p)
    out = tmp_path / "atlas.csv"
    r = runner.invoke(cli, ["analyse", str(p), *args, "--atlas-csv", str(out), "--no-fractal", "--no-fourier"])
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and words in lines[0], r.stderr
    assert not out.exists()


def test_the_largest_resolution_named_fits_and_one_more_does_not():
    from grainforge.analysis.atlas import IMAGE_BYTES_PER_CELL, check_atlas_request, image_cells
    from grainforge.runtime.estimate import TooLargeError

    body = [("g", np.array([1.0, 0.8, 0.6]), 0.8)]
    budget = 2e8
    with pytest.raises(TooLargeError) as info:
        check_atlas_request(body, voxels_across=400, memory=budget)
    n = int(str(info.value).split("voxels_across ")[1].split()[0])  # the library names the setting
    check_atlas_request(body, voxels_across=n, memory=budget)
    assert image_cells(body[0][1], 0.8 / n) * IMAGE_BYTES_PER_CELL <= budget
    with pytest.raises(TooLargeError):  # and a tenth more does not
        check_atlas_request(body, voxels_across=1.1 * n, memory=budget)
