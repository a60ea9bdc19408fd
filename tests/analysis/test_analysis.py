"""Shape descriptors against analytic values, invariances, file handling and the analyse CLI.

Tolerances: faceted spheres and ellipsoids (icosphere level 5, 20,480 faces)
under-estimate volume and area by about 0.1 %; the minimum-volume box is
trimesh's hull-direction search (exact for boxes, within ~1 % otherwise);
silhouette Fourier descriptors are computed exactly from the projected
triangles, so they change with the mesh, not with its placement.
"""

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from grainforge import fso
from grainforge.analysis.descriptors import (
    BASIC_COLUMNS,
    DESCRIPTOR_COLUMNS,
    basic_descriptors,
    describe,
    is_closed,
    mesh_moments,
    principal_dimensions,
)
from grainforge.analysis.fourier import (
    descriptors_from_radii,
    fd_columns,
    projection_descriptors,
)
from grainforge.analysis.fractal import fractal_dimension
from grainforge.analysis.measure import analyse_file, split_bodies


def ellipsoid(a, b, c, level=4):
    m = trimesh.creation.icosphere(level)
    m.apply_scale((a, b, c))
    return m


def ellipse_fd(a, b, orders=(2, 4)):
    t = 2 * np.pi * np.arange(4096) / 4096
    r = a * b / np.sqrt((b * np.cos(t)) ** 2 + (a * np.sin(t)) ** 2)
    return descriptors_from_radii(r, orders)


def ellipsoid_area(a, b, c):
    from scipy.special import ellipeinc, ellipkinc

    phi = np.arccos(c / a)
    k2 = a**2 * (b**2 - c**2) / (b**2 * (a**2 - c**2))
    return 2 * np.pi * c**2 + 2 * np.pi * a * b / np.sin(phi) * (
        ellipeinc(phi, k2) * np.sin(phi) ** 2 + ellipkinc(phi, k2) * np.cos(phi) ** 2
    )


@pytest.fixture(scope="module")
def grain():
    return fso(subdivisions=4, rng=11)


@pytest.fixture(scope="module")
def grain_d(grain):
    return describe(grain)


# ---------------------------------------------------------------- analytic shapes


def test_sphere():
    r = 2.0
    m = trimesh.creation.icosphere(4, radius=r)
    d = describe(m)
    assert d["volume"] == pytest.approx(4 / 3 * np.pi * r**3, rel=5e-3)
    assert d["surface_area"] == pytest.approx(4 * np.pi * r**2, rel=5e-3)
    assert d["equivalent_diameter"] == pytest.approx(2 * r, rel=2e-3)
    assert d["sphericity"] == pytest.approx(1.0, abs=2e-3)
    assert d["convexity"] == pytest.approx(1.0, abs=1e-9)
    assert d["porosity"] == pytest.approx(0.0, abs=1e-9)
    for k in ("L", "I", "S", "L_pca", "I_pca", "S_pca"):
        assert d[k] == pytest.approx(2 * r, rel=5e-3)
    assert d["elongation"] == pytest.approx(1.0, abs=2e-3)
    assert d["flatness"] == pytest.approx(1.0, abs=2e-3)
    assert d["krumbein_sphericity"] == pytest.approx(1.0, abs=2e-3)
    assert d["radius_of_gyration"] == pytest.approx(np.sqrt(3 / 5) * r, rel=5e-3)
    assert d["roughness"] < 1e-6
    assert np.isnan(d["fractal_dimension"])  # a smooth sphere has no measurable fractal dimension
    assert max(d[c] for c in fd_columns()) < 0.01
    assert d["closed"] == 1.0 and d["fd_star_shaped"] == 1.0


def test_cube_and_box():
    d = describe(trimesh.creation.box(), fractal=False)
    assert d["sphericity"] == pytest.approx((np.pi / 6) ** (1 / 3), abs=1e-12)  # 0.806
    assert d["volume"] == pytest.approx(1.0, abs=1e-12)
    assert d["radius_of_gyration"] == pytest.approx(0.5, abs=1e-12)
    assert (d["L"], d["I"], d["S"]) == pytest.approx((1, 1, 1), abs=1e-9)
    # (a cube's principal axes are not unique, so its projections are not tested)

    b = describe(trimesh.creation.box(extents=(4, 2, 1)), fractal=False)
    assert (b["L"], b["I"], b["S"]) == pytest.approx((4, 2, 1), abs=1e-9)
    assert (b["L_pca"], b["I_pca"], b["S_pca"]) == pytest.approx((4, 2, 1), abs=1e-9)
    assert b["volume"] == pytest.approx(8.0)
    assert b["surface_area"] == pytest.approx(28.0)
    assert b["sphericity"] == pytest.approx(np.pi ** (1 / 3) * 48 ** (2 / 3) / 28)
    assert b["elongation"] == pytest.approx(0.5) and b["flatness"] == pytest.approx(0.5)
    assert b["krumbein_sphericity"] == pytest.approx(0.5)
    assert b["radius_of_gyration"] == pytest.approx(np.sqrt(21 / 12))
    # principal projections are rectangles 4×2, 4×1, 2×1: compare with their exact radial functions
    t = 2 * np.pi * np.arange(128) / 128
    for plane, (w, h) in {"LI": (4, 2), "LS": (4, 1), "IS": (2, 1)}.items():
        r = np.minimum(w / 2 / np.maximum(np.abs(np.cos(t)), 1e-12), h / 2 / np.maximum(np.abs(np.sin(t)), 1e-12))
        exact = descriptors_from_radii(r)
        got = np.array([b[f"fd_{plane}_{n}"] for n in range(2, 17)])
        assert got == pytest.approx(exact, abs=1e-9), plane


def test_ellipsoid():
    a, b, c = 2.0, 1.5, 1.0
    d = describe(ellipsoid(a, b, c))
    V = 4 / 3 * np.pi * a * b * c
    assert d["volume"] == pytest.approx(V, rel=5e-3)
    assert d["surface_area"] == pytest.approx(ellipsoid_area(a, b, c), rel=5e-3)
    assert d["sphericity"] == pytest.approx(np.pi ** (1 / 3) * (6 * V) ** (2 / 3) / ellipsoid_area(a, b, c), rel=3e-3)
    assert (d["L_pca"], d["I_pca"], d["S_pca"]) == pytest.approx((4, 3, 2), rel=5e-3)
    assert (d["L"], d["I"], d["S"]) == pytest.approx((4, 3, 2), rel=1e-2)
    assert d["radius_of_gyration"] == pytest.approx(np.sqrt((a**2 + b**2 + c**2) / 5), rel=5e-3)
    assert d["roughness"] < 1e-6  # the 1/r² fit represents ellipsoids exactly
    # principal projections are ellipses a:b, a:c, b:c
    for plane, (p, q) in {"LI": (a, b), "LS": (a, c), "IS": (b, c)}.items():
        d2, d4 = ellipse_fd(p, q)
        assert d[f"fd_{plane}_2"] == pytest.approx(d2, abs=5e-3)
        assert d[f"fd_{plane}_4"] == pytest.approx(d4, abs=5e-3)
        assert d[f"fd_{plane}_3"] < 5e-3


def test_basic_descriptors_api_unchanged(grain):
    d = basic_descriptors(grain)
    assert tuple(d) == BASIC_COLUMNS
    full = describe(grain, fractal=False, fourier=False)
    assert {k: full[k] for k in BASIC_COLUMNS} == pytest.approx(d)
    assert principal_dimensions(grain) == pytest.approx((d["L"], d["I"], d["S"]))
    assert list(full) == list(DESCRIPTOR_COLUMNS)


def test_aggregate_dimension():
    cubes = [trimesh.creation.box(transform=trimesh.transformations.translation_matrix((i, j, k)))
             for i in range(3) for j in range(3) for k in range(3)]
    block = trimesh.boolean.union(cubes, engine="manifold")
    assert describe(block, fractal=False, fourier=False, primary_volume=1.0)["aggregate_dimension"] == pytest.approx(3.0)
    rod = trimesh.boolean.union(
        [trimesh.creation.box(transform=trimesh.transformations.translation_matrix((i, 0, 0))) for i in range(10)],
        engine="manifold",
    )
    d = describe(rod, fractal=False, fourier=False, primary_volume=1.0)
    assert d["aggregate_dimension"] == pytest.approx(np.log(10) / np.log(4))  # V = 10, mean edge (10+1+1)/3
    assert np.isnan(describe(rod, fractal=False, fourier=False)["aggregate_dimension"])
    with pytest.raises(ValueError, match="primary_volume"):
        describe(rod, fractal=False, fourier=False, primary_volume=0.0)


def test_porosity_of_a_concave_solid():
    # an L-shaped prism: 3 unit cubes, hull volume 3.5
    L = trimesh.boolean.union([trimesh.creation.box(transform=trimesh.transformations.translation_matrix(t))
                               for t in ((0, 0, 0), (1, 0, 0), (0, 1, 0))], engine="manifold")
    d = describe(L, fractal=False, fourier=False)
    assert d["convexity"] == pytest.approx(3 / 3.5)
    assert d["porosity"] == pytest.approx(0.5 / 3.5)


# ---------------------------------------------------------------- invariances


@pytest.mark.parametrize("seed", [0, 1])
def test_rotation_and_translation_invariance(grain, grain_d, seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    m = grain.mesh
    m.vertices = m.vertices @ R.T + rng.uniform(-5, 5, 3)
    d = describe(m)
    for k in ("volume", "surface_area", "sphericity", "convexity", "radius_of_gyration", "L_pca", "I_pca", "S_pca"):
        assert d[k] == pytest.approx(grain_d[k], rel=1e-6), k
    for k in ("L", "I", "S"):  # every hull-face direction is searched: only rounding differs
        assert d[k] == pytest.approx(grain_d[k], rel=1e-9), k
    assert d["roughness"] == pytest.approx(grain_d["roughness"], rel=1e-6)
    assert d["fractal_dimension"] == pytest.approx(grain_d["fractal_dimension"], abs=1e-6)
    for c in fd_columns():  # exact silhouettes in the principal frame: only rounding differs
        assert d[c] == pytest.approx(grain_d[c], abs=1e-6), c


def test_resolution_invariance():
    # 1,280 against 20,480 faces: the coarse mesh's chords lose ~1 % of the volume
    a = describe(ellipsoid(2.0, 1.5, 1.0, level=3), fractal=False)
    b = describe(ellipsoid(2.0, 1.5, 1.0, level=5), fractal=False)
    for k in ("volume", "surface_area", "sphericity", "L_pca", "I_pca", "S_pca", "radius_of_gyration"):
        assert a[k] == pytest.approx(b[k], rel=1.2e-2), k
    for k in ("L", "I", "S"):
        assert a[k] == pytest.approx(b[k], rel=1e-2), k
    for c in fd_columns():
        assert a[c] == pytest.approx(b[c], abs=5e-3), c


def test_scale():
    m = trimesh.creation.box(extents=(3, 2, 1))
    d1 = describe(m, fractal=False)
    m.apply_scale(2.5)
    d2 = describe(m, fractal=False)
    assert d2["volume"] == pytest.approx(d1["volume"] * 2.5**3)
    for k in ("sphericity", "convexity", "elongation", "flatness", "roughness", "fd_LI_2", "fd_LS_4"):
        assert d2[k] == pytest.approx(d1[k], abs=1e-9), k


# ---------------------------------------------------------------- texture


def test_roughness_and_fractal_dimension_order():
    smooth = describe(fso(fractal_dimension=2.0, subdivisions=5, rng=4), fourier=False)
    rough = describe(fso(fractal_dimension=2.7, subdivisions=5, rng=4), fourier=False)
    assert 2.0 <= smooth["fractal_dimension"] < rough["fractal_dimension"] <= 3.0
    # at the same RMS amplitude, a rougher spectrum puts more variance in the residual
    assert rough["roughness"] > smooth["roughness"]


def test_fractal_dimension_white_noise_and_smooth():
    u = np.asarray(trimesh.creation.icosphere(4).vertices)
    noise = np.random.default_rng(0).normal(size=len(u))
    assert fractal_dimension(u, noise, 0.05) == pytest.approx(3.0, abs=0.05)
    assert np.isnan(fractal_dimension(u, np.zeros(len(u)), 0.05))
    assert np.isnan(fractal_dimension(u, noise, 0.2))  # no scaling range on so coarse a mesh


# ---------------------------------------------------------------- Fourier descriptors


def test_descriptors_from_radii_round_trip():
    rng = np.random.default_rng(3)
    th = 2 * np.pi * np.arange(128) / 128
    D = np.zeros(17)
    D[2:] = rng.uniform(0.0, 0.05, 15)
    r = 1 + sum(D[n] * np.cos(n * th - rng.uniform(0, 2 * np.pi)) for n in range(2, 17))
    assert descriptors_from_radii(r) == pytest.approx(D[2:], abs=1e-12)
    with pytest.raises(ValueError, match="order"):
        descriptors_from_radii(r[:16])
    with pytest.raises(ValueError, match="positive"):
        descriptors_from_radii(-r)


def test_polygon_and_mask_contours():
    from grainforge.outline.contours import mask_contour, polygon_contour

    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    c = polygon_contour(sq, n_angles=8)
    assert c.star_shaped
    assert c.radii * c.scale == pytest.approx([1, np.sqrt(2)] * 4)
    # a square with a slot cut in from the right: rays through the slot's end cross three times
    slot = np.array([[-1, -1], [1, -1], [1, 0.2], [0.3, 0.2], [0.3, 0.3], [1, 0.3], [1, 1], [-1, 1]], dtype=float)
    c = polygon_contour(slot, n_angles=128)
    assert not c.star_shaped
    assert (c.radii * c.scale).max() == pytest.approx(np.sqrt(2), rel=0.02)  # the outermost crossing is kept
    with pytest.raises(ValueError, match="no grain"):
        mask_contour(np.zeros((10, 10), bool))
    with pytest.raises(ValueError, match="3 points"):
        polygon_contour(sq[:2])


def test_projection_descriptors_of_an_open_mesh():
    # an open hemisphere-like mesh still has a silhouette
    m = trimesh.creation.icosphere(3)
    keep = m.triangles_center[:, 2] > -0.2
    half = trimesh.Trimesh(m.vertices, m.faces[keep], process=False)
    d = projection_descriptors(half.vertices, half.faces)
    assert set(d) == set(fd_columns()) | {"fd_star_shaped"}
    assert all(np.isfinite(v) for v in d.values())


# ---------------------------------------------------------------- files and bodies


def test_is_closed_and_mass_properties():
    b = trimesh.creation.box()
    assert is_closed(b.faces, 8)
    assert not is_closed(b.faces[:, ::-1][[0, 1]], 8)
    flipped = np.vstack([b.faces[:6], b.faces[6:, ::-1]])  # inconsistent orientation
    assert not is_closed(flipped, 8)
    assert mesh_moments(b.vertices, b.faces[:, ::-1])["volume"] == pytest.approx(-1.0)


def test_split_bodies_and_flags(tmp_path):
    a = trimesh.creation.box()
    s = trimesh.creation.icosphere(3)
    s.apply_translation((4, 0, 0))
    both = trimesh.util.concatenate([a, s])
    assert [len(f) for _, f in split_bodies(both.vertices, both.faces)] == [12, 1280]
    p = tmp_path / "two.stl"
    both.export(p)
    rows = analyse_file(p, fractal=False)
    assert [r["flags"] for r in rows] == ["multi-body", "multi-body"]
    assert rows[0]["volume"] == pytest.approx(1.0)
    assert rows[1]["sphericity"] == pytest.approx(1.0, abs=0.01)

    inside_out = trimesh.Trimesh(a.vertices, a.faces[:, ::-1], process=False)
    inside_out.export(tmp_path / "inv.obj")
    (row,) = analyse_file(tmp_path / "inv.obj", fractal=False, fourier=False)
    assert row["flags"] == "inverted" and row["volume"] == pytest.approx(1.0)

    trimesh.Trimesh(a.vertices, a.faces[:-2], process=False).export(tmp_path / "open.ply")
    (row,) = analyse_file(tmp_path / "open.ply", fractal=False, fourier=False)
    assert row["flags"] == "open" and row["closed"] == 0.0


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "3mf"])
def test_formats_agree(tmp_path, grain, fmt):
    from grainforge.io import write_mesh

    p = tmp_path / f"g.{fmt}"
    if fmt == "3mf":
        from grainforge.io.threemf import ThreeMFWriter, mesh_xml

        with open(p, "wb") as fh, ThreeMFWriter(fh) as w:
            w.add_object("g", mesh_xml(grain.vertices, grain.faces))
    else:
        write_mesh(grain, p)
    (row,) = analyse_file(p, fractal=False)
    ref = describe(grain, fractal=False)
    assert row["flags"] == ""
    for k in ("volume", "sphericity", "convexity", "roughness"):
        assert row[k] == pytest.approx(ref[k], rel=1e-5), k
    # 3MF stores coordinates as decimal text (5 decimals), which moves the silhouette by about 1e-6
    assert row["fd_LI_2"] == pytest.approx(ref["fd_LI_2"], abs=1e-5)


# ---------------------------------------------------------------- CLI


def test_cli_analyse_table_csv_json(runner, tmp_path, grain):
    from grainforge.cli.main import cli
    from grainforge.io import write_mesh

    p = write_mesh(grain, tmp_path / "g.stl")
    out = tmp_path / "d.csv"
    res = runner.invoke(cli, ["analyse", str(p), "--csv", str(out), "--no-fractal"])
    assert res.exit_code == 0, res.output
    assert "sph" in res.stdout and "g.stl" in res.stdout
    header = out.read_text().splitlines()[0].split(",")
    assert header[:5] == ["file", "body", "bodies", "faces", "flags"] and "fd_IS_16" in header
    res = runner.invoke(cli, ["analyse", str(p), "--csv", str(out)])
    assert res.exit_code == 2 and "exists" in res.output
    res = runner.invoke(cli, ["analyse", str(p), "--json", "--no-fourier"])
    rows = json.loads(res.stdout)
    assert rows[0]["volume_mm3"] == pytest.approx(grain.mesh.volume)
    assert "fd_LI_2" not in rows[0]


@pytest.mark.parametrize("content", [b"", b"solid nonsense\nfacet garbage", b"\x00" * 30, b"not a mesh at all" * 20])
def test_cli_analyse_bad_files(runner, tmp_path, content):
    from grainforge.cli.main import cli

    p = tmp_path / "bad.stl"
    p.write_bytes(content)
    res = runner.invoke(cli, ["analyse", str(p)])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and "bad.stl" in lines[0]


def test_cli_analyse_missing_and_bad_3mf(runner, tmp_path):
    from grainforge.cli.main import cli

    res = runner.invoke(cli, ["analyse", str(tmp_path / "nope.ply")])
    assert res.exit_code == 2 and "no such file" in res.output
    (tmp_path / "x.3mf").write_bytes(b"PK not a zip")
    res = runner.invoke(cli, ["analyse", str(tmp_path / "x.3mf")])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
