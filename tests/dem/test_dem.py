"""DEM export: exact mass properties, voxeliser, clumps, decks and the `dem` command (no engine needed)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

import grainforge
from grainforge.cli.main import cli
from grainforge.dem.clump import clump, clump_quality
from grainforge.dem.massprops import mass_properties, rotation_to_quaternion
from grainforge.dem.template import prepare
from grainforge.geometry.voxel import grid_for, inside_mask


def test_mass_properties_box_analytic():
    a, b, c = 1.0, 2.0, 3.0
    box = trimesh.creation.box((a, b, c))
    box.apply_translation((0.3, -0.2, 5.0))
    mp = mass_properties(box.vertices, box.faces)
    V = a * b * c
    assert mp.volume == pytest.approx(V, rel=1e-14)
    assert np.allclose(mp.centroid, (0.3, -0.2, 5.0), atol=1e-13)
    expect = V / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert np.allclose(np.diag(mp.inertia), expect, rtol=1e-13)
    assert np.allclose(mp.inertia - np.diag(np.diag(mp.inertia)), 0, atol=1e-12)


def test_mass_properties_sphere_converges_to_analytic():
    s = trimesh.creation.icosphere(6)
    mp = mass_properties(s.vertices, s.faces)
    # inscribed polyhedron: volume and inertia approach 4/3 π and 8/15 π from below
    assert mp.volume == pytest.approx(4 / 3 * np.pi, rel=2e-3)
    assert np.allclose(mp.principal, 8 / 15 * np.pi, rtol=4e-3)


@pytest.mark.parametrize("method", ["fso", "cri", "dpa"])
def test_mass_properties_match_trimesh(method):
    g = getattr(grainforge, method)(rng=7)
    m = g.mesh
    mp = mass_properties(g.vertices, g.faces)
    assert mp.volume == pytest.approx(m.volume, rel=1e-12)
    assert np.allclose(mp.centroid, m.center_mass, atol=1e-12)
    assert np.allclose(mp.inertia, m.moment_inertia, rtol=1e-10, atol=1e-12 * np.abs(m.moment_inertia).max())
    R = mp.axes
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R @ np.diag(mp.principal) @ R.T, mp.inertia, atol=1e-12)
    q = rotation_to_quaternion(R)
    assert np.linalg.norm(q) == pytest.approx(1.0)


def test_mass_properties_rejects_inward_mesh():
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match="volume must be positive"):
        mass_properties(box.vertices, box.faces[:, ::-1])


def test_inside_mask_volume_matches_mesh():
    g = grainforge.fso(rng=2)
    m = g.mesh
    grid = grid_for(g.vertices, 0.02, pad=2)
    inside = inside_mask(g.vertices, g.faces, grid)
    assert inside.sum() * 0.02**3 == pytest.approx(m.volume, rel=5e-3)
    # independent check on a sample of cells: trimesh ray containment
    rng = np.random.default_rng(0)
    idx = np.argwhere(np.ones(grid.shape, bool))[rng.choice(inside.size, 400, replace=False)]
    assert (m.contains(grid.points(idx)) == inside[tuple(idx.T)]).mean() > 0.995


def test_clump_quality_of_known_sphere_sets():
    s = trimesh.creation.icosphere(5)
    cov, spill = clump_quality(s.vertices, s.faces, np.zeros((1, 3)), np.array([0.5]), resolution=60)
    assert cov == pytest.approx(0.125, rel=0.03) and spill == 0.0
    cov, spill = clump_quality(s.vertices, s.faces, np.zeros((1, 3)), np.array([2.0]), resolution=60)
    assert cov == 1.0 and spill == pytest.approx(1 - 1 / 8, rel=0.01)


@pytest.mark.parametrize("method", ["fso", "cri", "dpa"])
def test_clump_improves_with_sphere_count(method):
    g = getattr(grainforge, method)(rng=5)
    few = clump(g.vertices, g.faces, spheres=5, rng=0)
    many = clump(g.vertices, g.faces, spheres=40, rng=0)
    assert few.count == 5 and 1 <= many.count <= 40
    assert many.coverage > few.coverage
    # grown spheres reach past the surface a little; most on the porous DPA aggregates (≈ 6 % at 40)
    assert many.spill < 0.08
    # reported quality = independent re-measure on a finer grid (within grid error)
    cov, spill = clump_quality(g.vertices, g.faces, many.centres, many.radii, resolution=140)
    assert cov == pytest.approx(many.coverage, abs=0.02)
    assert spill == pytest.approx(many.spill, abs=0.01)


def test_clump_is_deterministic():
    g = grainforge.cri(rng=1)
    a = clump(g.vertices, g.faces, spheres=10, rng=3)
    b = clump(g.vertices, g.faces, spheres=10, rng=3)
    assert np.array_equal(a.centres, b.centres) and np.array_equal(a.radii, b.radii)


def test_prepare_rejects_bad_input():
    box = trimesh.creation.box()
    with pytest.raises(ValueError, match="density"):
        prepare(box.vertices, box.faces, name="b", density=0.0)
    with pytest.raises(ValueError, match="not a closed solid"):
        prepare(box.vertices, box.faces[:-1], name="b")
    with pytest.raises(ValueError, match="shape"):
        prepare(box.vertices, box.faces, name="b", shape="cube")


def test_prepare_units_and_centroid():
    g = grainforge.fso(rng=4).scaled(5.0)  # mm
    t = prepare(g.vertices, g.faces, name="g", unit=1e-3, density=2000.0, spheres=10)
    m = g.mesh
    assert t.mass == pytest.approx(2000.0 * m.volume * 1e-9, rel=1e-12)
    assert np.allclose(mass_properties(t.vertices, t.faces).centroid, 0, atol=1e-15)
    assert np.allclose(t.inertia, 2000.0 * m.moment_inertia * 1e-15, rtol=1e-9,
                       atol=1e-12 * np.abs(t.inertia).max())


# ---- the `dem` command -------------------------------------------------------------------

def test_dem_cli_yade_deck(grain_files, tmp_path):
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(out), "--engine", "yade",
                                 "--density", "2500", "--spheres", "12", "--workers", "1"])
    assert r.exit_code == 0, r.output
    deck = json.loads((out / "grains.json").read_text())
    assert [g["name"] for g in deck["grains"]] == ["cri-0001", "dpa-0002", "fso-0000"]
    for g in deck["grains"]:
        m = trimesh.load(grain_files / f"{g['name']}.stl")  # independent reader, merges vertices
        assert g["mass"] == pytest.approx(2500 * m.volume * 1e-9, rel=1e-6)
        assert np.allclose(g["principal_inertia"], 2500 * 1e-15 * np.sort(m.principal_inertia_components),
                           rtol=1e-6)
        rows = np.loadtxt(out / g["xyzr"], comments="#")
        assert rows.shape == (g["spheres"], 4) and g["spheres"] <= 12
        # spheres near the centroid-centred grain (metres)
        assert np.abs(rows[:, :3]).max() < 1e-3 * np.abs(m.vertices - m.center_mass).max()
        assert (out / f"{g['name']}.clump.vtk").read_text().startswith("# vtk DataFile")
    assert (out / "run.py").read_text().startswith("# Yade deck")


@pytest.mark.parametrize("args, message", [
    (["--engine", "liggghts", "--shape", "levelset"], "does not support --shape levelset"),
    (["--density", "0"], "--density"),
    (["--density", "-3"], "--density"),
])
def test_dem_cli_bad_options(grain_files, tmp_path, args, message):
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(out), *args])
    assert r.exit_code == 2
    assert message in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_dem_cli_non_solid_mesh(tmp_path):
    box = trimesh.creation.box((2.0, 2.0, 2.0))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)
    open_box.export(tmp_path / "open.stl")
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(tmp_path / "open.stl"), "--out", str(out)])
    assert r.exit_code == 2 and "not a closed solid" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not out.exists()


def test_dem_cli_refuses_overwrite(grain_files, tmp_path):
    out = tmp_path / "deck"
    args = ["dem", str(grain_files / "cri-0001.stl"), "--out", str(out), "--spheres", "5", "--workers", "1"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    before = {p: p.read_bytes() for p in out.iterdir()}
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2 and "--overwrite" in r.output
    assert {p: p.read_bytes() for p in out.iterdir()} == before
    assert CliRunner().invoke(cli, args + ["--overwrite"]).exit_code == 0
    assert {p: p.read_bytes() for p in out.iterdir()} == before  # same input, same bytes


@pytest.mark.slow
def test_dem_cli_yade_polyhedron_and_levelset_files(grain_files, tmp_path):
    """The files of the non-clump Yade decks hold the grain's hull / distance field (metres,
    centroid at the origin; the level set in the principal frame), with the mesh's mass."""
    from scipy.spatial.transform import Rotation

    for shape in ("polyhedron", "levelset"):
        out = tmp_path / shape
        own = ["--vertices", "30"] if shape == "polyhedron" else ["--spacing", "0.1"]  # each shape's own option
        r = CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(out), "--shape", shape, *own,
                                     "--workers", "1"])
        assert r.exit_code == 0, r.output
        deck = json.loads((out / "grains.json").read_text())
        assert deck["shape"] == shape
        for g in deck["grains"]:
            m = trimesh.load(grain_files / f"{g['name']}.stl")  # independent reader
            m.apply_scale(1e-3)
            assert g["mass"] == pytest.approx(2650 * m.volume, rel=1e-6)
            m.apply_translation(-m.center_mass)
            if shape == "polyhedron":
                hull = np.loadtxt(out / g["polyhedron"], comments="#")
                assert hull.shape == (g["vertices"], 3) and 4 <= len(hull) <= 30
                # hull vertices are mesh vertices of the centroid-centred grain
                d = np.linalg.norm(hull[:, None] - m.vertices[None], axis=2).min(axis=1)
                assert d.max() < 1e-9
            else:
                ls = json.loads((out / g["levelset"]).read_text())
                nx, ny, nz = ls["shape"]
                dist = np.array(ls["distance"]).reshape(nx, ny, nz)
                R = Rotation.from_rotvec(np.array(ls["axis"]) * ls["angle"]).as_matrix()
                # a few nodes: the field's value is the signed distance to the mesh (in the grain
                # frame x = R x_local), negative inside
                idx = np.array([[nx // 2, ny // 2, nz // 2], [0, 0, 0], [nx // 3, ny // 2, nz // 2]])
                local = np.array(ls["origin"]) + ls["spacing"] * idx
                sd = -trimesh.proximity.signed_distance(m, local @ R.T)  # trimesh: positive inside
                assert np.allclose(dist[tuple(idx.T)], sd, atol=1e-9)
                assert dist[tuple(idx[0])] < 0 < dist[0, 0, 0]


def test_dem_cli_lammps_polyhedron_files(grain_files, tmp_path):
    """The LAMMPS body deck: data.bodies holds each grain's mesh mass and rotated inertia (units
    micro), its hull vertices (on the mesh) with outward triangles and the hull's edges; the
    per-body line limits of read_data hold; the same input gives the same bytes."""
    from grainforge.dem.lammps import rotation_matrix
    from grainforge.dem.lammps_body import MICRO, hull_topology

    out = tmp_path / "deck"
    # the most vertices LAMMPS takes (the default is 12): the line limits are tested where they bind
    args = ["dem", str(grain_files), "--out", str(out), "--engine", "lammps", "--shape", "polyhedron",
            "--vertices", "56", "--workers", "1"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    deck = json.loads((out / "grains.json").read_text())
    lines = (out / "data.bodies").read_text().splitlines()
    start = lines.index("Bodies") + 2
    tokens = " ".join(lines[start:]).split()
    body_line_counts, k, i = [], 0, start
    for p in deck["placements"]:
        g = deck["grains"][p["grain"]]
        assert g["vertices"] <= 56
        m = trimesh.load(grain_files / f"{g['name']}.stl")  # independent reader
        m.apply_scale(1e-3)
        m.apply_translation(-m.center_mass)
        bid, ni, nd = (int(x) for x in tokens[k:k + 3])
        nv, ne, nf = (int(x) for x in tokens[k + 3:k + 6])
        d = np.array([float(x) for x in tokens[k + 6:k + 6 + nd]])
        k += 3 + ni + nd
        assert (bid, ni, nv) == (p["id"], 3, g["vertices"]) and nd == 6 + 3 * nv + 2 * ne + 4 * nf + 1
        R = rotation_matrix(np.array(p["axis"]), np.radians(p["theta_deg"]))
        I = np.array([[d[0], d[3], d[4]], [d[3], d[1], d[5]], [d[4], d[5], d[2]]]) / (MICRO["mass"] * 1e12)
        assert np.allclose(np.linalg.eigvalsh(I), 2650 * np.sort(m.principal_inertia_components), rtol=1e-9)
        assert np.allclose(R.T @ I @ R, 2650 * m.moment_inertia, rtol=0, atol=1e-9 * np.abs(I).max())
        local = d[6:6 + 3 * nv].reshape(nv, 3) / MICRO["length"] @ R
        assert np.linalg.norm(local[:, None] - m.vertices[None], axis=2).min(axis=1).max() < 1e-9
        faces = d[6 + 3 * nv + 2 * ne:6 + 3 * nv + 2 * ne + 4 * nf].reshape(nf, 4).astype(int)
        assert (faces[:, 3] == -1).all() and ne == 3 * nv - 6 and nf == 2 * nv - 4
        tri = trimesh.Trimesh(local, faces[:, :3], process=False)
        assert tri.is_watertight and tri.volume > 0  # closed, outward
        while not lines[i].startswith(f"{bid} 3 "):
            i += 1
        j = i + 1
        while j < len(lines) and lines[j] and not (len(lines[j].split()) == 3 and lines[j].split()[1] == "3"
                                                  and j > i + 1 and lines[j].split()[0] == str(bid + 1)):
            j += 1
        body_line_counts.append(j - i - 1)
        assert max(len(x) for x in lines[i:j]) < 256
        i = j
    assert max(body_line_counts) <= 31
    first = {p.name: p.read_bytes() for p in out.iterdir()}
    assert CliRunner().invoke(cli, args + ["--overwrite", "--workers", "2"]).exit_code == 0
    assert {p.name: p.read_bytes() for p in out.iterdir()} == first
    # more vertices than LAMMPS reads: one line, exit 2, nothing written
    bad = tmp_path / "bad"
    r = CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(bad), "--engine", "lammps",
                                 "--shape", "polyhedron", "--vertices", "80"])
    assert r.exit_code == 2 and "--vertices" in r.output and not bad.exists()
    f, e = hull_topology(trimesh.creation.icosphere(1).vertices)
    assert (len(f), len(e)) == (80, 120)


def test_dem_cli_clump_refinement(tmp_path):
    """--refine-iterations: a better value of the refinement's objective (covered grain − 4 × volume
    outside, per grain volume) than the greedy clump on every grain, and the same bytes for one worker
    or two (4 grains, so that two workers are used)."""
    src = tmp_path / "grains"
    src.mkdir()
    for i, method in enumerate(["fso", "cri", "dpa", "fso"]):
        grainforge.io.write_mesh(getattr(grainforge, method)(rng=10 + i).scaled(4.0), src / f"{method}-{i:04d}.stl")

    def deck(name, *extra):
        out = tmp_path / name
        r = CliRunner().invoke(cli, ["dem", str(src), "--out", str(out), "--engine", "liggghts",
                                     "--spheres", "10", *extra])
        assert r.exit_code == 0, r.output
        return out, {g["name"]: g for g in json.loads((out / "grains.json").read_text())["grains"]}

    _, greedy = deck("greedy", "--workers", "1")
    one, refined = deck("refined1", "--refine-iterations", "30", "--workers", "1")
    two, _ = deck("refined2", "--refine-iterations", "30", "--workers", "2")
    def objective(g):  # #U/#G = coverage / (1 - spill): the volume outside per grain volume is spill × that
        return g["coverage"] - 4.0 * g["spill"] * g["coverage"] / (1.0 - g["spill"])

    for name, g in refined.items():
        assert g["spheres"] == greedy[name]["spheres"] == 10
        assert objective(g) > objective(greedy[name]) + 0.005, (name, objective(g), objective(greedy[name]))
        assert g["spill"] < 0.05
    assert {p.name: p.read_bytes() for p in one.iterdir()} == {p.name: p.read_bytes() for p in two.iterdir()}
    r = CliRunner().invoke(cli, ["dem", str(src), "--out", str(tmp_path / "bad"), "--refine-iterations", "-1"])
    assert r.exit_code == 2 and "--refine-iterations" in r.output and not (tmp_path / "bad").exists()


def test_vertex_merge_of_soups_and_small_sets():
    """solid.unique_rows (read_grain's merge) on a grain's float32 soup and 300 small sets with
    repeats and -0.0: np.unique's rows and inverse, each group's first occurrence kept (its sign)."""
    from grainforge.geometry.solid import unique_rows

    rng = np.random.default_rng(6)
    g = grainforge.fso(rng=7)
    soups = [g.vertices[g.faces].reshape(-1, 3).astype(np.float32).astype(np.float64)]
    for k in range(300):
        p = rng.integers(-2, 3, size=(int(rng.integers(1, 60)), 3)) * 0.5
        p[rng.random(p.shape) < 0.2] *= -1  # -0.0 among the zeros
        p = p.astype(np.float32) if k % 3 == 0 else p
        if k % 7 == 0:
            p[0, 0] = 0.1  # not float32-exact in float64: the general path
        soups.append(p)
    for p in soups:
        u, inv = unique_rows(p)
        ru, rinv = np.unique(p, axis=0, return_inverse=True)
        assert u.dtype == p.dtype and np.array_equal(u, ru) and np.array_equal(inv, rinv.reshape(-1))
        first = np.unique(inv, return_index=True)[1]
        assert np.array_equal(np.signbit(u), np.signbit(p[first]))


def _trial_division_prime(n: int) -> bool:
    return n > 1 and all(n % p for p in range(2, math.isqrt(n) + 1))


def test_liggghts_deck_seeds_distinct_primes_for_1_to_200_templates():
    """Every random seed of a LIGGGHTS deck (templates, distributions, one insertion per grain) is a
    prime > 10000 that LIGGGHTS accepts, and no two are equal: for 1 to 200 templates of 1-3 copies
    (the engine stops on a repeated seed within an insertion and its distributions)."""
    import dataclasses
    import re

    from grainforge.dem.liggghts import SEED_MIN, deck_files

    t0 = prepare(trimesh.creation.box((2.0, 1.5, 1.0)).vertices, trimesh.creation.box((2.0, 1.5, 1.0)).faces,
                 name="g", spheres=3)
    seen = set()
    # every count to 40, then a spread to 200 (deck_seeds: the first seeds of a larger count are a smaller one's;
    # every count to 200 took 12 s of the fast lane)
    for n in [*range(1, 41), 63, 64, 99, 100, 101, 127, 128, 150, 199, 200]:
        templates = [dataclasses.replace(t0, name=f"g{i}", count=1 + (i * 7 + n) % 3) for i in range(n)]
        files = deck_files(templates)
        text = files["in.templates"] + files["in.insert"]
        seeds = [int(x) for x in re.findall(r"(?:particletemplate/multisphere|particledistribution/discrete|"
                                            r"insert/pack seed) (\d+)", text)]
        grains = sum(t.count for t in templates)
        assert len(seeds) == 2 * n + 1 + grains  # every random fix of the deck was found
        assert len(set(seeds)) == len(seeds), n
        assert text.count("insert/pack") == grains
        seen.update(seeds)
    # LIGGGHTS: prime, > 10000, and below INT_MAX once the MPI rank (up to thousands) is added
    assert all(SEED_MIN < s < 2**31 - 1 - 100_000 and _trial_division_prime(s) for s in seen)
    assert SEED_MIN == 10000
    # the same deck twice: the same seeds (nothing random in their choice)
    assert deck_files(templates)["in.insert"] == files["in.insert"]
    # the largest deck (as many templates as grains, MAX_POUR_GRAINS of them) still gets distinct seeds
    from grainforge.dem.inputs import MAX_POUR_GRAINS
    from grainforge.dem.liggghts import deck_seeds, seed_table

    big = deck_seeds(3 * MAX_POUR_GRAINS + 1)
    assert len(set(big)) == len(big) and set(big) <= set(seed_table().tolist())
    with pytest.raises(ValueError, match="seed table"):
        deck_seeds(len(seed_table()) + 1)


def test_liggghts_insertion_regions_stay_inside_one_mpi_rank():
    """`processors * * 1` cuts the box into P_x equal parts along x (and y); an insertion region cut
    by a part boundary may be inserted twice or not at all. The deck's margins keep every cut
    (P_x ≤ 32, lattices up to 300 cells wide) ≥ 200 region widths from every lattice node, and
    the deck puts each region on a node and the box at those margins."""
    import re

    from grainforge.dem import liggghts as lg

    nodes = np.arange(300) + 0.5
    for px in range(2, 33):
        k = np.arange(1, px)[:, None]
        for side in range(1, 301):
            cuts = -lg._MARGIN_LO + k * (side + lg._MARGIN_LO + lg._MARGIN_HI) / px
            assert np.abs(cuts - nodes[None, :side]).min() >= 200 * lg._NODE_BOX, (px, side)
    # the deck follows the constants: 7 grains on a 2 x 2 lattice
    t0 = prepare(trimesh.creation.box((2.0, 1.5, 1.0)).vertices, trimesh.creation.box((2.0, 1.5, 1.0)).faces,
                 name="g", spheres=3, count=7)
    files = lg.deck_files([t0])
    cell = 2.2 * t0.bounding_radius
    dom = [float(x) for x in re.search(r"region domain block (\S+) (\S+) (\S+) (\S+)", files["in.run"]).groups()]
    assert dom == pytest.approx([-lg._MARGIN_LO * cell, (2 + lg._MARGIN_HI) * cell] * 2, rel=1e-12)
    assert "processors * * 1" in files["in.run"]
    boxes = np.array([[float(x) for x in m] for m in re.findall(r"region r\d+ block" + r" (\S+)" * 6, files["in.insert"])])
    assert len(boxes) == 7
    centre = (boxes[:, 0::2] + boxes[:, 1::2]) / 2 / cell
    assert np.allclose(centre[:, :2] % 1, 0.5) and np.allclose(boxes[:, 1::2] - boxes[:, 0::2], lg._NODE_BOX * cell)
    assert "overlapcheck no" in files["in.insert"]  # no retries that test the rank's own borders


def test_dem_cli_grains_total_pour(tmp_path):
    """--grains N: a pour of exactly N grains drawn from the inputs in proportion, the same bytes
    for the same --seed; with fewer grains than inputs only the drawn inputs are in the deck;
    bad combinations and counts beyond the documented maximum: one line, exit 2, nothing written."""
    import re

    from grainforge.cli import dem as dem_cli
    from grainforge.dem.inputs import MAX_POUR_GRAINS, pour_counts

    src = tmp_path / "grains"
    src.mkdir()
    for i, method in enumerate(["fso", "cri", "fso"]):
        grainforge.io.write_mesh(getattr(grainforge, method)(rng=20 + i).scaled(3.0), src / f"{method}-{i:04d}.stl")

    def deck(name, engine, *extra):
        out = tmp_path / name
        r = CliRunner().invoke(cli, ["dem", str(src), "--out", str(out), "--engine", engine, "--spheres", "4",
                                     "--workers", "1", *extra])
        assert r.exit_code == 0, r.output
        return out, json.loads((out / "grains.json").read_text())

    out, g = deck("l7", "liggghts", "--grains", "7", "--seed", "1")
    counts = {r["name"]: r["count"] for r in g["grains"]}
    assert sum(counts.values()) == 7 and sorted(counts.values()) == [2, 2, 3]
    assert len(re.findall(r"^fix i\d+ all insert/pack", (out / "in.insert").read_text(), re.MULTILINE)) == 7
    assert list(counts.values()) == pour_counts(3, 7, rng=1).tolist()
    again, _ = deck("l7b", "liggghts", "--grains", "7", "--seed", "1")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == {p.name: p.read_bytes() for p in again.iterdir()}
    # LAMMPS: one rigid body per grain
    out, g = deck("m5", "lammps", "--grains", "5")
    assert len(g["placements"]) == 5 and int((out / "rigid.infile").read_text().splitlines()[1]) == 5
    # fewer grains than inputs: the two drawn inputs, once each
    _, g = deck("l2", "liggghts", "--grains", "2", "--seed", "3")
    assert [r["count"] for r in g["grains"]] == [1, 1] and len({r["name"] for r in g["grains"]}) == 2
    # proportion: every count within one of grains / inputs
    c = pour_counts(7, 1000, rng=5)
    assert c.sum() == 1000 and c.max() - c.min() <= 1
    assert dem_cli.MAX_POUR_GRAINS == MAX_POUR_GRAINS
    for bad in (["--grains", "0"], ["--grains", str(MAX_POUR_GRAINS + 1)], ["--grains", "4", "--count", "2"],
                ["--seed", "2"], ["--count", str(MAX_POUR_GRAINS // 3 + 1)]):
        dest = tmp_path / "bad"
        r = CliRunner().invoke(cli, ["dem", str(src), "--out", str(dest), *bad])
        assert r.exit_code == 2, (bad, r.output)
        assert len(r.output.strip().splitlines()) == 1 and not dest.exists(), (bad, r.output)


def test_dem_cli_polyhedron_default_vertices(grain_files, tmp_path):
    """Without --vertices each engine's deck gets its default hull size (Yade 16, LAMMPS 12)."""
    from grainforge.dem.polyhedron import DEFAULT_VERTICES

    for engine in ("yade", "lammps"):
        out = tmp_path / engine
        r = CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(out), "--engine", engine,
                                     "--shape", "polyhedron", "--workers", "1"])
        assert r.exit_code == 0, r.output
        deck = json.loads((out / "grains.json").read_text())
        assert {g["vertices"] for g in deck["grains"]} == {DEFAULT_VERTICES[engine]}


def test_convex_polyhedron_keeps_volume_greedily():
    """The kept vertices are chosen in one sequence (each adds the vertex farthest outside the hull
    so far), so the kept hull's volume grows strictly with K and stays below the full hull's."""
    from scipy.spatial import ConvexHull

    from grainforge.dem.polyhedron import convex_polyhedron

    g = grainforge.fso(rng=5)
    full = ConvexHull(convex_polyhedron(g.vertices)).volume
    vols = [ConvexHull(convex_polyhedron(g.vertices, max_vertices=k)).volume for k in (6, 8, 12, 16, 24)]
    assert all(a < b for a, b in zip(vols, vols[1:]))
    assert vols[-1] < full


@pytest.mark.slow
def test_a_level_sets_memory_does_not_grow_as_its_grid_gets_coarser():
    """The exact distances of a coarse grid's margin nodes gather every triangle (trimesh's candidates): the
    queries are grouped by their estimated candidates, so the peak stays that of one bounded query."""
    import tracemalloc

    import trimesh

    from grainforge.dem.levelset import level_set

    m = trimesh.creation.icosphere(5)  # 20,480 faces, as a rough grain
    m.apply_scale((1.0, 0.8, 0.6))
    peaks = []
    for spacing in (0.1, 0.5):
        tracemalloc.start()
        level_set(m.vertices, m.faces, spacing=spacing)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    # before: 0.05 → 172 MB, 0.5 → 1.3 GB on a 20,480-face grain; now both under about 100 MB
    assert max(peaks) < 150e6 and peaks[1] < 1.5 * peaks[0], peaks
