"""grainforge check: printability of meshes against printer profiles."""

import numpy as np
import pytest
import trimesh

from grainforge.cli import check as check_cli
from grainforge.cli.main import cli
from grainforge.fabrication import printability
from grainforge.fabrication.printability import (
    GRID_ENTRIES_PER_FACE,
    _candidate_slices,
    _ray_cells,
    _segments,
    _short_rays,
    check_mesh,
    local_thickness,
    self_intersections,
    triangle_grid,
)
from grainforge.geometry.solid import moller_trumbore
from grainforge.io.threemf import ThreeMFWriter, mesh_xml


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


@pytest.mark.parametrize("horizon, max_pairs", [(0.5, printability.MAX_PAIRS), (0.5, 97), (100.0, 1000)])
def test_short_rays_agree_with_full_ray_casting(horizon, max_pairs, monkeypatch):
    # a horizon far beyond the grain (100 vs 5.2 long) and tiny pair slices change nothing
    monkeypatch.setattr(printability, "MAX_PAIRS", max_pairs)
    m = _neck(0.07)
    idx, full = local_thickness(m, max_rays=1500)
    idx2, short = local_thickness(m, max_rays=1500, max_distance=horizon)
    assert (idx == idx2).all()
    near = full < horizon
    assert near.any() and np.allclose(short[near], full[near], rtol=1e-6)
    assert np.isinf(short[~near]).all()
    if horizon > 10:
        assert near.all()


def _rays(mesh, k=300):
    """Inward rays from the centres of k faces, as local_thickness casts them."""
    idx = np.arange(0, len(mesh.faces), len(mesh.faces) // k)[:k]
    n = mesh.face_normals[idx]
    eps = 1e-7 * float(np.ptp(mesh.vertices, axis=0).max())
    return idx, mesh.triangles_center[idx] - n * eps, n, eps


def test_triangle_grid_entries_are_capped_by_the_mesh_size():
    # fine triangles next to a few huge ones: the huge ones would cover many cells of a fine grid
    fine = trimesh.creation.icosphere(4, radius=1.0)
    huge = trimesh.creation.box(extents=(400.0, 400.0, 400.0))
    tri = np.concatenate([fine.triangles, huge.triangles])
    g = triangle_grid(tri)
    assert g.entries <= GRID_ENTRIES_PER_FACE * len(tri) + 1000
    assert g.count.sum() == g.entries and len(np.unique(g.owner)) == len(tri)  # every triangle binned
    tight = triangle_grid(tri, max_entries=2 * len(tri))
    assert tight.entries <= 2 * len(tri) and tight.cell > g.cell
    # the grid holds every triangle in every cell its bounding box overlaps
    lo, hi = g.cell_of(tri.min(axis=1)), g.cell_of(tri.max(axis=1))
    assert ((hi - lo + 1).prod(axis=1).sum()) == g.entries


def test_ray_candidates_are_bounded_by_the_grain_not_the_horizon():
    # the out-of-memory cause: the candidates of a ray were every triangle within horizon/2 of its
    # midpoint, i.e. the whole grain once the horizon (4 x min_wall: 3.2 mm on FDM) exceeds it
    m = trimesh.creation.icosphere(5, radius=1.0)  # 20,480 faces, 2 units across
    idx, origins, normals, eps = _rays(m)
    g = triangle_grid(m.triangles)
    counts = {}
    for horizon in (2.0 + 4 * eps, 1e3, 1e6):
        reach = min(horizon, float(np.linalg.norm(np.ptp(m.vertices, axis=0))) + 4 * eps)
        _, slot = _ray_cells(g, origins, -normals, reach, 2 * eps)
        counts[horizon] = int(g.count[slot].sum())
        assert _segments(g, reach) <= 2 * 2 * np.sqrt(3) / g.cell + 1
    assert counts[1e3] == counts[1e6]  # the walk stops at the mesh's diagonal
    assert counts[1e6] / len(idx) < len(m.faces) / 20  # a ray meets triangles near its path only


def test_candidate_slices_are_bounded_and_hold_every_hit():
    m = _neck(0.07)
    idx, origins, normals, eps = _rays(m, 200)
    g = triangle_grid(m.triangles)
    reach = float(np.linalg.norm(np.ptp(m.vertices, axis=0))) + 4 * eps
    ray, slot = _ray_cells(g, origins, -normals, reach, 2 * eps)
    slices = list(_candidate_slices(g, ray, slot, 50))
    assert len(slices) > 1 and all(len(r) <= 50 for r, _ in slices)
    found = {(int(a), int(b)) for r, c in slices for a, b in zip(r, c)}
    # brute force: every (ray, triangle) crossing within reach is among the candidates
    R, T = np.meshgrid(np.arange(len(idx)), np.arange(len(m.faces)), indexing="ij")
    R, T = R.ravel(), T.ravel()
    ok, u, w, t = moller_trumbore(origins[R], -normals[R] * reach, m.triangles[T], det_min=1e-30)
    hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0) & (t <= 1)
    assert hit.sum() > len(idx)
    assert {(int(a), int(b)) for a, b in zip(R[hit], T[hit])} <= found
    # and the thickness is the same whatever the slice size
    a = _short_rays(m, idx, origins, normals, reach, eps, max_pairs=50)
    b = _short_rays(m, idx, origins, normals, reach, eps)
    assert np.array_equal(a, b) and np.isfinite(a).all()


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


def test_cli_says_first_which_grains_are_below_the_reliable_size(runner, tmp_path, monkeypatch):
    s = trimesh.creation.icosphere(3, radius=1.0)
    (tmp_path / "g").mkdir()
    s.export(tmp_path / "g" / "a-small.stl")  # 2 mm: below generic-fdm's 4 mm
    trimesh.Trimesh(s.vertices * 2.5, s.faces).export(tmp_path / "g" / "b-large.stl")  # 5 mm
    events = []
    real_check, real_say = printability.check_mesh, check_cli._say
    monkeypatch.setattr(printability, "check_mesh", lambda *a, **k: events.append(("check", k["name"]))
                        or real_check(*a, **k))
    monkeypatch.setattr(check_cli, "_say", lambda line, stream: events.append(("say", line))
                        or real_say(line, stream))
    res = runner.invoke(cli, ["check", str(tmp_path / "g"), "--printer", "generic-fdm", "--csv"])
    assert res.exit_code == 1, res.output
    said = [ln for ln in res.stderr.splitlines() if "will not print reliably" in ln]
    assert said == [(f"{tmp_path / 'g' / 'a-small.stl'}: a-small: will not print reliably on generic-fdm: "
                     "equivalent diameter 1.99 mm < reliable size 4 mm")]
    assert events[:2] == [("say", said[0]), ("check", "a-small")]  # said before the slow tests run
    assert ("check", "b-large") in events and len(events) == 3  # nothing said for the 5 mm grain
    rows = {r[1]: r for r in (ln.split(",") for ln in res.stdout.strip().splitlines()[1:])}
    assert rows["a-small"][2] == "FAIL" and rows["a-small"][-1].startswith("equivalent diameter 1.99 mm <")
    assert rows["b-large"][2] == "OK"
    # the same small grain on a finer printer: no line
    res = runner.invoke(cli, ["check", str(tmp_path / "g" / "a-small.stl"), "--printer", "generic-sla"])
    assert res.exit_code == 0 and "will not print reliably" not in res.stderr


def test_cli_out_of_memory_names_the_file_not_grains(runner, tmp_path, monkeypatch):
    s = trimesh.creation.icosphere(2, radius=1.0)
    s.export(tmp_path / "g.stl")

    def oom(*a, **k):
        raise MemoryError

    monkeypatch.setattr(printability, "check_mesh", oom)
    res = runner.invoke(cli, ["check", str(tmp_path / "g.stl")])
    assert res.exit_code == 2
    assert res.stderr.strip() == (f"Error: not enough memory to check {tmp_path / 'g.stl'}; files are read and "
                                  "checked one at a time, so check a version with fewer triangles, or a 3MF's "
                                  "objects in smaller files")
    assert "grains" not in res.stderr and res.stdout == ""
