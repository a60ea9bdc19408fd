"""grainforge check: printability of meshes against printer profiles."""

import numpy as np
import pytest
import trimesh

from grainforge.cli.main import cli
from grainforge.fabrication.printability import check_mesh, local_thickness, self_intersections
from grainforge.fabrication.threemf import ThreeMFWriter, mesh_xml


def _neck(radius):
    """Two unit spheres joined by a rod of the given radius (a two-particle aggregate)."""
    a = trimesh.creation.icosphere(3, radius=1.0).apply_translation([-1.6, 0, 0])
    b = trimesh.creation.icosphere(3, radius=1.0).apply_translation([1.6, 0, 0])
    rod = trimesh.creation.cylinder(radius=radius, height=2.4, sections=24)
    rod.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return trimesh.boolean.union([a, b, rod], engine="manifold")


def test_thickness_of_slab_is_exact():
    slab = trimesh.creation.box(extents=(5.0, 4.0, 0.3))
    _, t = local_thickness(slab)
    # rays from the big faces measure 0.3, those from the sides 4 or 5
    assert np.isclose(t.min(), 0.3, rtol=1e-6)
    assert set(np.round(t, 6)) == {0.3, 4.0, 5.0}


def test_sphere_prints():
    s = trimesh.creation.icosphere(4, radius=1.0)
    r = check_mesh(s.vertices, s.faces, "objet-eden-250")
    assert r.ok and r.status == "OK"
    assert r.solid == [] and r.self_intersections == 0
    assert r.min_thickness == np.inf  # nothing thinner than the 4 x min_wall horizon


def test_short_rays_agree_with_full_ray_casting():
    m = _neck(0.07)
    idx, full = local_thickness(m, max_rays=1500)
    idx2, short = local_thickness(m, max_rays=1500, max_distance=0.5)
    assert (idx == idx2).all()
    near = full < 0.5
    assert near.any() and np.allclose(short[near], full[near], rtol=1e-6)
    assert np.isinf(short[~near]).all()


def test_too_thin_wall_fails():
    slab = trimesh.creation.box(extents=(5.0, 5.0, 0.05))
    r = check_mesh(slab.vertices, slab.faces, "objet-eden-250")
    assert not r.ok
    assert any("thinner than the minimum wall" in f for f in r.failures)
    assert r.min_thickness == pytest.approx(0.05)
    # the same slab four times thicker (0.2 mm) is above the 0.1 mm minimum wall
    r2 = check_mesh(slab.vertices * [1, 1, 4], slab.faces, "objet-eden-250")
    assert r2.ok


def test_tiny_grain_fails():
    s = trimesh.creation.icosphere(3, radius=1.0)
    small = check_mesh(s.vertices * 0.1, s.faces, "objet-eden-250")  # 0.2 mm < 0.3 mm reliable size
    assert any("reliable size" in f for f in small.failures)
    fdm = check_mesh(s.vertices, s.faces, "generic-fdm")  # 2 mm < 4 mm for FDM
    assert any("reliable size" in f for f in fdm.failures)


def test_fragile_and_broken_necks():
    fragile = check_mesh(*(lambda m: (m.vertices, m.faces))(_neck(0.07)), "objet-eden-250")
    assert fragile.status == "WARN" and "fragile neck" in fragile.warnings[0]
    assert 0.1 < fragile.min_neck < 0.2
    broken = check_mesh(*(lambda m: (m.vertices, m.faces))(_neck(0.035)), "objet-eden-250")
    assert broken.status == "FAIL" and broken.min_neck < 0.1


def test_open_and_self_intersecting_meshes_fail():
    s = trimesh.creation.icosphere(2)
    r = check_mesh(s.vertices, s.faces[:-3], "objet-eden-250")
    assert not r.ok and "not watertight" in r.failures[0]
    a = trimesh.creation.box(extents=(2, 2, 2))
    b = a.copy().apply_translation([0.7, 0.4, 0.3])
    both = trimesh.util.concatenate([a, b])
    assert self_intersections(both.vertices, both.faces) > 0
    r = check_mesh(both.vertices, both.faces, "objet-eden-250")
    assert any("self-intersecting" in f for f in r.failures)
    assert any("separate bodies" in f for f in r.failures)


def test_self_intersection_of_folded_surface():
    s = trimesh.creation.icosphere(2)
    v = np.array(s.vertices)
    v[0] = -1.5 * v[0]  # pull one vertex through the opposite side
    assert self_intersections(v, s.faces) > 0
    assert self_intersections(s.vertices, s.faces) == 0


def test_cli_table_and_exit_codes(runner, tmp_path):
    good = trimesh.creation.icosphere(3, radius=1.0)
    thin = trimesh.creation.box(extents=(5.0, 5.0, 0.05))
    good.export(tmp_path / "good.stl")
    thin.export(tmp_path / "thin.stl")
    res = runner.invoke(cli, ["check", str(tmp_path / "good.stl"), "--printer", "objet-eden-250"])
    assert res.exit_code == 0, res.output
    assert "OK" in res.stdout
    res = runner.invoke(cli, ["check", str(tmp_path / "good.stl"), str(tmp_path / "thin.stl"), "--csv"])
    assert res.exit_code == 1
    lines = res.stdout.strip().splitlines()
    assert lines[0].startswith("file,part,status")
    assert [ln.split(",")[2] for ln in lines[1:]] == ["OK", "FAIL"]
    res = runner.invoke(cli, ["check", str(tmp_path / "missing.stl")])
    assert res.exit_code == 2 and "no such file" in res.output
    res = runner.invoke(cli, ["check", str(tmp_path / "good.stl"), "--printer", "nope"])
    assert res.exit_code == 2 and "printer must be one of" in res.output


def test_cli_checks_every_object_of_a_3mf(runner, tmp_path):
    s = trimesh.creation.icosphere(3, radius=1.0)
    with open(tmp_path / "two.3mf", "wb") as fh, ThreeMFWriter(fh) as w:
        w.add_object("big", mesh_xml(s.vertices, s.faces))
        w.add_object("tiny", mesh_xml(s.vertices * 0.1, s.faces), translation=(5, 0, 0))
    res = runner.invoke(cli, ["check", str(tmp_path / "two.3mf"), "--csv"])
    assert res.exit_code == 1
    rows = [ln.split(",") for ln in res.stdout.strip().splitlines()[1:]]
    assert [(r[1], r[2]) for r in rows] == [("big", "OK"), ("tiny", "FAIL")]
