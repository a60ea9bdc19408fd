"""The NumPy z-buffer rasteriser, shaded pictures and contact sheets."""

import numpy as np
import pytest
import trimesh

from grainforge.viz.render import contact_sheet, rasterize, render_image, silhouette, view_rotation

PNG = b"\x89PNG\r\n\x1a\n"


def test_rasterize_counts_pixel_centres():
    # right triangle with legs of 7 px: centres with x + y <= 7 (edges included) -> 8+7+...+1
    xy = np.array([[1.0, 1.0], [8.0, 1.0], [1.0, 8.0]])
    cover = rasterize(xy, np.array([[0, 1, 2]]), (10, 10))
    assert cover.sum() == 36
    assert cover[1, 1] and cover[1, 8] and cover[8, 1] and not cover[8, 8]
    # winding does not matter for coverage
    assert np.array_equal(rasterize(xy, np.array([[0, 2, 1]]), (10, 10)), cover)


def test_rasterize_clips_and_skips_degenerate():
    xy = np.array([[-5.0, -5.0], [20.0, -5.0], [-5.0, 20.0], [3.0, 3.0]])
    cover = rasterize(xy, np.array([[0, 1, 2], [3, 3, 3]]), (6, 6))
    assert cover.all()  # the big triangle covers the whole 6x6 image


def test_zbuffer_keeps_the_nearest_face():
    sq = np.array([[0.0, 0.0], [9.0, 0.0], [9.0, 9.0], [0.0, 9.0]])
    xy = np.vstack([sq, sq])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    depth = np.array([5.0] * 4 + [1.0] * 4)  # the second square is nearer
    face, bary = rasterize(xy, faces, (10, 10), depth=depth)
    assert set(np.unique(face)) == {2, 3}
    assert np.allclose(bary.sum(-1), 1.0)


def test_large_and_small_triangles_mix():
    # many tiny triangles and one large one, bucketed separately
    rng = np.random.default_rng(0)
    base = rng.uniform(5, 95, (500, 2))
    tiny = np.concatenate([base, base + [1.5, 0], base + [0, 1.5]])
    faces = np.stack([np.arange(500), np.arange(500, 1000), np.arange(1000, 1500)], 1)
    xy = np.vstack([tiny, [[0, 0], [99, 0], [0, 99]]])
    faces = np.vstack([faces, [[1500, 1501, 1502]]])
    cover = rasterize(xy, faces, (100, 100))
    big = rasterize(xy, faces[-1:], (100, 100))
    assert big.sum() == 100 * 101 // 2
    assert cover.sum() > big.sum()


def test_silhouette_of_a_box():
    m = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    mask = silhouette(m.vertices[:, :2], m.faces, size=101, margin=0)
    assert mask.shape == (101, 101)
    assert mask.mean() == pytest.approx(0.5, abs=0.01)


def test_view_rotation_is_orthonormal():
    R = view_rotation(33.0, -71.0)
    assert np.allclose(R @ R.T, np.eye(3))
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_render_image_sphere_is_lit_and_framed():
    img = render_image(trimesh.creation.icosphere(3), size=80)
    assert img.shape == (80, 80, 3)
    assert np.allclose(img[0, 0], 1.0) and np.allclose(img[-1, -1], 1.0)  # background corners
    inside = img[40, 40]
    assert inside.max() < 1.0 and inside.min() > 0.05
    # the key light comes from the upper left: that side is brighter than the lower right
    assert img[25, 25].sum() > img[58, 58].sum()


def test_render_image_open_mesh_and_colour():
    m = trimesh.creation.icosphere(2)
    half = trimesh.Trimesh(m.vertices, m.faces[m.triangles_center[:, 2] > 0], process=False)
    img = render_image(half, size=48, color=(0.2, 0.4, 0.8), background=(0, 0, 0))
    covered = img.sum(-1) > 0
    assert covered.mean() > 0.3
    assert img[covered][:, 2].mean() > img[covered][:, 0].mean()  # blue grain


def test_contact_sheet_png_deterministic(tmp_path):
    meshes = [trimesh.creation.icosphere(2), trimesh.creation.box()]
    a = contact_sheet(meshes, ["sphere", "box\nsecond line"], tmp_path / "a.png", title="t", panel_size=1.2, dpi=60)
    b = contact_sheet(meshes, ["sphere", "box\nsecond line"], tmp_path / "b.png", title="t", panel_size=1.2, dpi=60)
    assert a.read_bytes()[:8] == PNG
    assert a.read_bytes() == b.read_bytes()


def test_contact_sheet_bad_input(tmp_path):
    with pytest.raises(ValueError, match="one label per mesh"):
        contact_sheet([trimesh.creation.box()], [], tmp_path / "x.png")
    with pytest.raises(ValueError, match="nothing to render"):
        contact_sheet([], [], tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()
