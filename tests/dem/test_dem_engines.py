"""Decks run by the real engines (Yade, LIGGGHTS, LAMMPS) on 20 generated grains.

Each test writes a deck with `grainforge dem`, runs the engine from inside the
deck folder exactly as docs/dem.md says, and reads back what the engine holds:
every grain inserted; each body's mass, centre of mass and principal inertia
equal to the mesh's within 1e-6 relative; the pour settles (kinetic energy
below the deck's stated threshold) with no grain lost.

Without an engine the test is skipped with the reason; with
GRAINFORGE_REQUIRE_ENGINES=1 (set by .ci/run) a missing engine is a failure.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from conftest import require_engine

from grainforge.cli.main import cli

# every test here runs a DEM engine: the full suite (make test) runs them, the fast lane does not
pytestmark = pytest.mark.slow

DENSITY = 2650.0
UNIT = 1e-3  # grain files are in mm
REL = 1e-6


#: the engine (or mpirun) a test needs: skipped with the reason, a failure under GRAINFORGE_REQUIRE_ENGINES=1
require = require_engine


@pytest.fixture
def yade():
    return require("yade")


@pytest.fixture
def liggghts():
    return require("liggghts")


@pytest.fixture
def lmp():
    return require("lmp")


@pytest.fixture
def mpirun():
    return require("mpirun", "openmpi-bin")


#: Open MPI settings for the runs under mpirun: CI runs as root; two ranks even on a one-core
#: machine; a waiting rank yields its core (the runs share two cores with other work)
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMPI_MCA_mpi_yield_when_idle": "1"}


@pytest.fixture(scope="module")
def population(tmp_path_factory):
    """20 grains, 10 mm: 7 fso, 7 cri, 6 dpa, written by `grainforge generate`."""
    root = tmp_path_factory.mktemp("population")
    for method, count, seed in (("fso", 7, 11), ("cri", 7, 22), ("dpa", 6, 33)):
        r = CliRunner().invoke(cli, ["generate", method, "--count", str(count), "--seed", str(seed),
                                     "--size", "10", "--out", str(root / method)])
        assert r.exit_code == 0, r.output
    return root


def mesh_truth(files):
    """Mass (kg), principal inertia (kg m², ascending) of every grain file, by trimesh."""
    truth = {}
    for f in files:
        m = trimesh.load(f)  # an independent reader: merges vertices by position
        truth[f.stem] = (DENSITY * m.volume * UNIT**3,
                         np.sort(DENSITY * m.principal_inertia_components * UNIT**5),
                         float((6 * m.volume / np.pi) ** (1 / 3)) * UNIT)
    return truth


def make_deck(population, tmp_path, engine, *extra):
    """A deck of the 20 grains (clumps of 8 spheres unless ``extra`` gives a --shape or --spheres: the contacts
    cost the run, and every check here holds for any clump) and the meshes' mass properties."""
    out = tmp_path / engine
    r = CliRunner().invoke(cli, ["dem", str(population / "fso"), str(population / "cri"), str(population / "dpa"),
                                 "--out", str(out), "--engine", engine, "--density", str(DENSITY),
                                 *([] if "--shape" in extra or "--spheres" in extra else ["--spheres", "8"]), *extra])
    assert r.exit_code == 0, r.output
    files = sorted(population.glob("*/*.stl"))
    assert len(files) == 20
    return out, mesh_truth(files)


def run(cmd, cwd, timeout=900, env=None):
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL, env=None if env is None else {**os.environ, **env})
    assert proc.returncode == 0, f"{cmd} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def settle_record(out):
    """(largest KE of the last checks, threshold) from a LIGGGHTS/LAMMPS deck's settle.txt, which
    must say settled."""
    words = (out / "settle.txt").read_text().split()
    rec = dict(zip(words[::2], (float(v) for v in words[1::2])))
    assert rec["settled"] == 1, rec
    return rec["ke"], rec["threshold"]


def check_report(report, truth, n=20):
    """Every one of ``n`` grains inserted (all of ``truth`` when n = 20) with its mesh's mass properties,
    settled, none lost."""
    inserted = report["inserted"]
    assert len(inserted) == n
    names = sorted(r["name"] for r in inserted)
    assert names == sorted(truth) if n == len(truth) else set(names) <= set(truth)
    for r in inserted:
        mass, principal, d_eq = truth[r["name"]]
        assert r["mass"] == pytest.approx(mass, rel=REL)
        assert np.allclose(np.sort(r["inertia"]), principal, rtol=REL, atol=0)
        assert np.allclose(r["pos"], r["target"], rtol=0, atol=REL * d_eq)
    assert report["settled"], f"kinetic energy {report['kinetic_energy']} ≥ {report['ke_threshold']}"
    assert report["lost"] == []
    assert len(report["final"]) == n


def turns(q_wxyz):
    """Rotation matrices of quaternions (w, x, y, z), by scipy."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()


def check_placed(report, out, truth):
    """Yade placed grain k of the pour turned by row k of the deck's orientations: every contact
    sphere, as Yade held it right after insertion, sits at target + R_k · (its template offset)."""
    deck = json.loads((out / "grains.json").read_text())
    R = turns(deck["scene"]["orientations"])
    placed = np.array(report["placed"])
    for k, r in enumerate(report["inserted"]):
        rows = np.loadtxt(out / f"{r['name']}.xyzr", comments="#").reshape(-1, 4)
        mine = placed[placed[:, 3] == r["id"], :3]
        expect = np.array(r["target"]) + rows[:, :3] @ R[k].T
        assert len(mine) == len(rows)
        d = np.linalg.norm(mine[:, None] - expect[None], axis=2).min(axis=1)
        assert d.max() < REL * truth[r["name"]][2], r["name"]


def test_yade_deck_runs(yade, population, tmp_path):  # the engine first: skip before generating grains
    out, truth = make_deck(population, tmp_path, "yade")
    proc = run([yade, "-n", "-x", "run.py"], cwd=out)
    # run by hand, the deck names Yade's temporary folder first and removes it as it ends (Yade leaves it)
    (named,) = [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("grainforge-tempdir ")]
    assert os.path.basename(named).startswith("yade-") and not os.path.exists(named)
    report = json.loads((out / "results-yade.json").read_text())
    check_report(report, truth)
    check_placed(report, out, truth)
    assert any((out / "vtk").glob("*.vtu"))


def grain_frame_meshes(population):
    """Every grain mesh in metres with its volume centroid at the origin (read by trimesh)."""
    out = {}
    for f in sorted(population.glob("*/*.stl")):
        m = trimesh.load(f)
        m.apply_scale(UNIT)
        m.apply_translation(-m.center_mass)
        out[f.stem] = m
    return out


@pytest.mark.parametrize("shape, extra, tol", [
    # hull vertices are mesh vertices: they sit on the surface to rounding (default vertex count)
    ("polyhedron", [], 1e-6),
    # Yade ray-traces its surface nodes on the discrete field: within a grid spacing of the mesh (0.08 d_eq; the
    # default 0.05 builds 4 times the exact distances: 36 s for this test instead of about 15)
    ("levelset", ["--spacing", "0.08"], 0.08),
])
def test_yade_polyhedron_and_levelset_decks_run(yade, population, tmp_path, shape, extra, tol):
    # 8 of the 20 grains (fso, cri and dpa drawn by --grains): polyhedron and level-set contacts are
    # costly, and 8 grains exercise every kind
    out, truth = make_deck(population, tmp_path, "yade", "--shape", shape, "--grains", "8", "--seed", "3", *extra)
    run([yade, "-n", "-x", "run.py"], cwd=out)
    report = json.loads((out / "results-yade.json").read_text())
    check_report(report, truth, n=8)
    # the contact shape sits where the mesh is: Yade's own vertices / surface nodes, mapped back
    # into the grain frame with the insertion's position and rotation, lie on the mesh surface
    meshes = grain_frame_meshes(population)
    for r in report["inserted"]:
        pts = np.array(r["contact_points"])
        assert len(pts) >= 8
        d_eq = truth[r["name"]][2]
        sd = trimesh.proximity.signed_distance(meshes[r["name"]], pts)
        assert np.abs(sd).max() < tol * d_eq, (r["name"], np.abs(sd).max() / d_eq)
    assert any((out / "vtk").glob("*.vt*"))


def read_dump(path):
    """The first snapshot of a LAMMPS/LIGGGHTS text dump as a float array."""
    rows, on = [], False
    for line in path.read_text().splitlines():
        if line.startswith("ITEM: ENTRIES") or line.startswith("ITEM: ATOMS"):
            on = True
            continue
        if line.startswith("ITEM:") and on:
            break
        if on and line.strip():
            rows.append([float(x) for x in line.split()])
    return np.array(rows)


def check_centres(bodies, atoms, deck, truth, type_col=1, x_cols=(3, 4, 5)):
    """Every template sphere sits at its |offset| from the engine's centre of mass.

    The spheres were written relative to the mesh centroid, so this holds only
    if the engine's centre of mass is the mesh centroid (rotation-invariant).
    """
    grains = deck["grains"]
    for b in bodies:
        t = grains[int(b[type_col]) - 1]
        rows = np.loadtxt(deck["_dir"] / t["xyzr"], comments="#").reshape(-1, 4)
        d_eq = truth[t["name"]][2]
        xcm = b[list(x_cols)]
        dist = np.linalg.norm(atoms[:, 1:4] - xcm, axis=1)
        for x, y, z, r in rows:
            match = (np.abs(atoms[:, 4] - r) <= REL * r) & (np.abs(dist - np.linalg.norm((x, y, z))) <= REL * d_eq)
            assert match.any(), f"{t['name']}: no sphere of radius {r} at {np.linalg.norm((x, y, z))} from xcm"


def test_liggghts_deck_runs(liggghts, population, tmp_path):
    out, truth = make_deck(population, tmp_path, "liggghts")
    run([liggghts, "-in", "in.run"], cwd=out)
    deck = json.loads((out / "grains.json").read_text())
    deck["_dir"] = out
    bodies = read_dump(out / "bodies-initial.txt")
    assert len(bodies) == 20  # every grain inserted
    assert sorted(int(t) for t in bodies[:, 1]) == list(range(1, 21))
    for b in bodies:
        mass, principal, _ = truth[deck["grains"][int(b[1]) - 1]["name"]]
        assert b[2] == pytest.approx(mass, rel=REL)
        assert np.allclose(np.sort(b[6:9]), principal, rtol=REL, atol=0)
    check_centres(bodies, read_dump(out / "atoms-initial.txt"), deck, truth)
    # each grain turned by its insertion's `orientation constant` quaternion: its spheres, as LIGGGHTS
    # placed them, sit at xcm + R · (template offsets)
    quats = [[float(x) for x in m] for m in re.findall(r"orientation constant (\S+) (\S+) (\S+) (\S+)",
                                                         (out / "in.insert").read_text())]
    slot_of = np.cumsum([0] + [t["count"] for t in deck["grains"]])
    atoms = read_dump(out / "atoms-initial.txt")
    for b in bodies:
        k = int(b[1]) - 1
        t = deck["grains"][k]
        assert t["count"] == 1
        rows = np.loadtxt(out / t["xyzr"], comments="#").reshape(-1, 4)
        expect = b[3:6] + rows[:, :3] @ turns(quats[slot_of[k]])[0].T
        d = np.linalg.norm(atoms[None, :, 1:4] - expect[:, None], axis=2).min(axis=1)
        assert d.max() < REL * truth[t["name"]][2], t["name"]
    ke, thr = settle_record(out)
    assert ke < thr
    final = read_dump(out / "bodies-final.txt")
    assert len(final) == 20  # no grain lost
    w = deck["box"][0]
    assert ((final[:, 3:5] > 0) & (final[:, 3:5] < w)).all() and (final[:, 5] > 0).all()
    # translational kinetic energy from the bodies' own velocities: also below the threshold
    assert 0.5 * (final[:, 2] * (final[:, 6:9] ** 2).sum(axis=1)).sum() < thr
    assert any((out / "post").glob("*.vtk"))


def test_lammps_deck_runs(lmp, population, tmp_path):
    from grainforge.dem.lammps import rotation_matrix

    out, truth = make_deck(population, tmp_path, "lammps", "--spheres", "20")  # as cheap as 8 spheres in LAMMPS
    run([lmp, "-in", "in.run"], cwd=out)
    deck = json.loads((out / "grains.json").read_text())
    place = {p["mol"]: p for p in deck["placements"]}
    bodies = read_dump(out / "bodies-initial.txt")  # mol mass x y z inertia(3)
    assert len(bodies) == 20 and sorted(bodies[:, 0].astype(int)) == list(range(1, 21))
    for b in bodies:
        p = place[int(b[0])]
        mass, principal, d_eq = truth[p["name"]]
        assert b[1] == pytest.approx(mass, rel=REL)
        assert np.allclose(np.sort(b[5:8]), principal, rtol=REL, atol=0)
        assert np.allclose(b[2:5], p["xcm"], rtol=0, atol=REL * d_eq)
    # every atom sits where the template puts it, seen from the engine's centre of mass
    atoms = read_dump(out / "atoms-initial.txt")  # id mol x y z radius
    assert len(np.unique(atoms[:, 1])) == 20
    xcm = {int(b[0]): b[2:5] for b in bodies}
    for m, p in place.items():
        rows = np.loadtxt(out / f"{p['name']}.xyzr", comments="#").reshape(-1, 4)
        R = rotation_matrix(np.array(p["axis"]), np.radians(p["theta_deg"]))
        mine = atoms[atoms[:, 1] == m]
        expect = xcm[m] + rows[:, :3] @ R.T
        assert len(mine) == len(rows)
        d = np.linalg.norm(mine[:, None, 2:5] - expect[None], axis=2).min(axis=1)
        assert d.max() < REL * truth[p["name"]][2]
    ke, thr = settle_record(out)
    assert ke < thr
    final = read_dump(out / "bodies-final.txt")  # mol mass x y z I(3) v(3)
    assert len(final) == 20
    w = deck["box"][0]
    assert ((final[:, 2:4] > 0) & (final[:, 2:4] < w)).all() and (final[:, 4] > 0).all()
    assert 0.5 * (final[:, 1] * (final[:, 8:11] ** 2).sum(axis=1)).sum() < thr
    assert any((out / "post").glob("*.vtk"))


def read_lammps_body_data(path):
    """Atoms, velocities and Bodies of a LAMMPS data file of rounded/polyhedron bodies.

    Returns ``{id: {"mass", "x", "v", "angmom", "inertia" (3x3, box frame), "vertices" (K, 3)}}``
    in the file's units.
    """
    lines = path.read_text().splitlines()
    heads = {l.split("#")[0].strip(): i for i, l in enumerate(lines)
             if l.strip() and l.split("#")[0].strip() in ("Atoms", "Velocities", "Bodies")}
    n = int(next(l.split()[0] for l in lines if l.strip().endswith(" atoms")))
    out = {}
    for l in lines[heads["Atoms"] + 2: heads["Atoms"] + 2 + n]:  # id type bodyflag mass x y z [images]
        w = l.split()
        out[int(w[0])] = {"mass": float(w[3]), "x": np.array([float(x) for x in w[4:7]])}
    if "Velocities" in heads:
        for l in lines[heads["Velocities"] + 2: heads["Velocities"] + 2 + n]:  # id vx vy vz lx ly lz
            w = l.split()
            out[int(w[0])].update(v=np.array([float(x) for x in w[1:4]]), angmom=np.array([float(x) for x in w[4:7]]))
    tokens = " ".join(lines[heads["Bodies"] + 1:]).split()
    k = 0
    for _ in range(n):
        bid, ni, nd = (int(x) for x in tokens[k:k + 3])
        ints = [int(x) for x in tokens[k + 3:k + 3 + ni]]
        d = np.array([float(x) for x in tokens[k + 3 + ni:k + 3 + ni + nd]])
        k += 3 + ni + nd
        nv = ints[0]
        I = np.array([[d[0], d[3], d[4]], [d[3], d[1], d[5]], [d[4], d[5], d[2]]])
        out[bid].update(inertia=I, vertices=d[6:6 + 3 * nv].reshape(nv, 3))
    return out


def test_lammps_polyhedron_deck_runs(lmp, population, tmp_path):
    """LAMMPS rounded/polyhedron bodies at the default vertex count: read back with write_data (units micro: µm,
    pg, µs). The contacts' cost grows fast with the vertices: 14 s to settle at 12, 41 s at 16."""
    from grainforge.dem.lammps import rotation_matrix
    from grainforge.dem.lammps_body import MICRO
    from grainforge.dem.polyhedron import DEFAULT_VERTICES

    L, M = MICRO["length"], MICRO["mass"]
    out, truth = make_deck(population, tmp_path, "lammps", "--shape", "polyhedron")
    run([lmp, "-in", "in.run"], cwd=out, timeout=1800)
    deck = json.loads((out / "grains.json").read_text())
    place = {p["id"]: p for p in deck["placements"]}
    meshes = grain_frame_meshes(population)
    initial = read_lammps_body_data(out / "data.initial")
    assert sorted(initial) == list(range(1, 21))  # every grain inserted
    assert sorted(p["name"] for p in place.values()) == sorted(truth)
    for bid, b in initial.items():
        p = place[bid]
        mass, principal, d_eq = truth[p["name"]]
        assert b["mass"] / M == pytest.approx(mass, rel=REL)
        assert np.allclose(np.linalg.eigvalsh(b["inertia"]) / (M * L * L), principal, rtol=REL, atol=0)
        assert np.allclose(b["x"] / L, p["xcm"], rtol=0, atol=REL * d_eq)
        # the engine's hull vertices, turned back into the grain frame, lie on the mesh surface
        R = rotation_matrix(np.array(p["axis"]), np.radians(p["theta_deg"]))
        local = (b["vertices"] / L) @ R
        assert len(local) == deck["grains"][p["grain"]]["vertices"] <= DEFAULT_VERTICES["lammps"]
        sd = trimesh.proximity.signed_distance(meshes[p["name"]], local)
        assert np.abs(sd).max() < REL * d_eq, (p["name"], np.abs(sd).max() / d_eq)
    ke, thr = settle_record(out)
    assert ke < thr
    final = read_lammps_body_data(out / "data.final")
    assert sorted(final) == list(range(1, 21))  # no grain lost
    w = deck["box"][0] * L
    x = np.array([b["x"] for b in final.values()])
    assert ((x[:, :2] > 0) & (x[:, :2] < w)).all() and (x[:, 2] > 0).all()
    # kinetic energy recomputed from the bodies' velocities and angular momenta (L·I⁻¹·L)
    ke_own = sum(0.5 * b["mass"] * b["v"] @ b["v"] + 0.5 * b["angmom"] @ np.linalg.solve(b["inertia"], b["angmom"])
                 for b in final.values())
    assert ke_own < thr
    assert any((out / "post").glob("*.vtk"))


# --- the same decks under MPI: `mpirun -np 2` against one process -----------------------------------

def mpi_decks(population, tmp_path, engine, *extra):
    """One small deck (6 of the 20 grains, drawn by --grains) copied into ``one`` and ``two``."""
    src, _ = make_deck(population, tmp_path, engine, "--grains", "6", "--seed", "2", *extra)
    one, two = tmp_path / "one", tmp_path / "two"
    shutil.copytree(src, one)
    shutil.copytree(src, two)
    return one, two


def assert_columns(log):
    """Two ranks side by side (``processors * * 1``): the one column of 6 grains crosses the cut."""
    assert re.search(r"(2 by 1|1 by 2) by 1 MPI processor grid", log), log[-2000:]


def run_pour(cmd, cwd, timeout=900, env=None):
    """Run a deck; a run that ends is fine whether or not the pour settled (compared by the caller)."""
    proc = subprocess.run(cmd, check=False, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL, env=None if env is None else {**os.environ, **env})
    assert proc.returncode == 0 or "NOT SETTLED" in proc.stdout, (
        f"{cmd} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


def settled(out, proc):
    """Whether the pour settled: the deck's settle.txt (``ke x threshold y settled 0|1 steps N``), and
    the run's last line saying the same."""
    words = (out / "settle.txt").read_text().split()
    flag = dict(zip(words[::2], words[1::2]))["settled"] == "1"
    last = proc.stdout.strip().splitlines()[-1]
    assert last.startswith("SETTLED in" if flag else "NOT SETTLED after"), last
    return flag


def compare_ranks(state1, state2, d_mean, width):
    """Two final states (``mass``, ``key``, ``x`` (N, 3) per run) of the same pour: the same grains
    and mass, every centre in the box, and a bed alike (mean and top height within half a mean
    diameter: the ranks draw their own random numbers, so grains land differently)."""
    assert len(state1["mass"]) == len(state2["mass"]) == 6
    assert sorted(state1["key"]) == sorted(state2["key"])
    assert np.sum(state2["mass"]) == pytest.approx(np.sum(state1["mass"]), rel=1e-12)
    for s in (state1, state2):
        x = s["x"]
        assert ((x[:, :2] > 0) & (x[:, :2] < width)).all() and (x[:, 2] > 0).all()
    z1, z2 = state1["x"][:, 2], state2["x"][:, 2]
    assert abs(z1.mean() - z2.mean()) < 0.5 * d_mean, (z1, z2)
    assert abs(z1.max() - z2.max()) < 0.5 * d_mean, (z1, z2)


@pytest.mark.slow
def test_liggghts_clump_deck_under_mpirun_matches_one_rank(liggghts, mpirun, population, tmp_path):
    one, two = mpi_decks(population, tmp_path, "liggghts", "--spheres", "8")
    p1 = run_pour([liggghts, "-in", "in.run"], cwd=one)
    p2 = run_pour([mpirun, "-np", "2", liggghts, "-in", "in.run"], cwd=two, env=MPI_ENV)
    assert_columns(p2.stdout)
    deck = json.loads((one / "grains.json").read_text())
    states = []
    for out in (one, two):
        assert len(read_dump(out / "bodies-initial.txt")) == 6  # each grain inserted once
        final = read_dump(out / "bodies-final.txt")  # id type mass x y z v
        states.append({"mass": final[:, 2], "key": final[:, 1].astype(int).tolist(), "x": final[:, 3:6]})
    d_mean = np.mean([g["d_eq"] for g in deck["grains"] for _ in range(g["count"])])
    compare_ranks(*states, d_mean, deck["box"][0])
    assert settled(one, p1) == settled(two, p2)


def test_lammps_clump_deck_under_mpirun_matches_one_rank(lmp, mpirun, population, tmp_path):
    one, two = mpi_decks(population, tmp_path, "lammps", "--spheres", "8")
    p1 = run_pour([lmp, "-in", "in.run"], cwd=one)
    p2 = run_pour([mpirun, "-np", "2", lmp, "-in", "in.run"], cwd=two, env=MPI_ENV)
    assert_columns(p2.stdout)
    deck = json.loads((one / "grains.json").read_text())
    states = []
    for out in (one, two):
        final = read_dump(out / "bodies-final.txt")  # mol mass x y z I(3) v(3)
        states.append({"mass": final[:, 1], "key": final[:, 0].astype(int).tolist(), "x": final[:, 2:5]})
    d_mean = np.mean([g["d_eq"] for g in deck["grains"] for _ in range(g["count"])])
    compare_ranks(*states, d_mean, deck["box"][0])
    assert settled(one, p1) == settled(two, p2)
    # the VTK conversion (a `shell` command) ran once, on rank 0, over the same dumps
    assert sorted(p.name for p in (one / "post").glob("*.vtk")) == sorted(p.name for p in (two / "post").glob("*.vtk"))


@pytest.mark.slow
def test_lammps_polyhedron_deck_under_mpirun_matches_one_rank(lmp, mpirun, population, tmp_path):
    from conftest import require_long_lane

    from grainforge.dem.lammps_body import MICRO

    require_long_lane("a polyhedron pour on 1 and 2 ranks (70 s of CPU in CI); in the suite LAMMPS's domain "
                      "decomposition is checked on the clump deck, the polyhedron deck on one rank")

    L, M = MICRO["length"], MICRO["mass"]
    one, two = mpi_decks(population, tmp_path, "lammps", "--shape", "polyhedron", "--vertices", "8")
    p1 = run_pour([lmp, "-in", "in.run"], cwd=one, timeout=1800)
    p2 = run_pour([mpirun, "-np", "2", lmp, "-in", "in.run"], cwd=two, timeout=1800, env=MPI_ENV)
    assert_columns(p2.stdout)
    deck = json.loads((one / "grains.json").read_text())
    states = []
    for out in (one, two):
        final = read_lammps_body_data(out / "data.final")
        ids = sorted(final)
        states.append({"mass": np.array([final[i]["mass"] / M for i in ids]), "key": ids,
                       "x": np.array([final[i]["x"] / L for i in ids])})
    d_mean = np.mean([deck["grains"][p["grain"]]["d_eq"] for p in deck["placements"]])
    compare_ranks(*states, d_mean, deck["box"][0])
    assert settled(one, p1) == settled(two, p2)


@pytest.mark.slow
def test_liggghts_pour_of_300_grains_inserts_each_once_on_2_and_4_ranks(liggghts, mpirun, population, tmp_path):
    """Insertion only (the deck's in.run up to its pour): 300 grains on a 8 x 8 lattice, cut into
    2 x 1 and 2 x 2 columns — every grain inserted once, each template as often as the deck says.
    (The former insertion, a whole lattice cell per grain with an overlap check, put 293 of these
    300 in on one process and 292 on 2 or 4 ranks.)"""
    src, _ = make_deck(population, tmp_path, "liggghts", "--grains", "300", "--seed", "1", "--spheres", "4")
    text = (src / "in.run").read_text()
    (src / "in.insert-only").write_text(text[:text.index("dump vtk")] + "run 10\n")
    deck = json.loads((src / "grains.json").read_text())
    expect = sorted(k + 1 for k, g in enumerate(deck["grains"]) for _ in range(g["count"]))
    assert len(expect) == 300
    for ranks in (2, 4):
        p = run([mpirun, "-np", str(ranks), liggghts, "-in", "in.insert-only"], cwd=src, env=MPI_ENV)
        assert re.search(r"(2 by 1|1 by 2|2 by 2) by 1 MPI processor grid", p.stdout)
        bodies = read_dump(src / "bodies-initial.txt")
        assert sorted(bodies[:, 1].astype(int).tolist()) == expect, ranks
# ---- the settle report: last line and exit status, on small decks -----------------------------

SETTLED = re.compile(r"SETTLED in (\d+) steps")
NOT_SETTLED = re.compile(r"NOT SETTLED after (\d+) steps \(KE (\S+) > (\S+) (J|pg um\^2/us\^2, micro units = 1e-15 J)\)")

#: the README's grain parameters (2 mm FSO grains); two grains make a column two grains high
README_FSO = ["--seed", "100", "--size", "2", "--fractal-dimension", "2.4", "--length-ratio", "7",
              "--amplitude", "0.1"]


@pytest.fixture(scope="module")
def two_grains(tmp_path_factory):
    root = tmp_path_factory.mktemp("two")
    r = CliRunner().invoke(cli, ["generate", "fso", "--count", "2", *README_FSO, "--out", str(root / "g")])
    assert r.exit_code == 0, r.output
    return root / "g"


ENGINE_CASES = {  # id: engine, shape, executable, command, template options
    "yade-clump": ("yade", "clump", "yade", ["-n", "-x", "run.py"], {"spheres": 8}),
    "yade-polyhedron": ("yade", "polyhedron", "yade", ["-n", "-x", "run.py"], {"polyhedron_vertices": 8}),
    # a coarse grid (0.15 d, as the quick level-set tilt's): the last line and the exit status are the claim here;
    # the level sets' accuracy is test_yade_polyhedron_and_levelset_decks_run's
    "yade-levelset": ("yade", "levelset", "yade", ["-n", "-x", "run.py"], {"levelset_spacing": 0.15}),
    "liggghts-clump": ("liggghts", "clump", "liggghts", ["-in", "in.run"], {"spheres": 8}),
    "lammps-clump": ("lammps", "clump", "lmp", ["-in", "in.run"], {"spheres": 8}),
    "lammps-polyhedron": ("lammps", "polyhedron", "lmp", ["-in", "in.run"], {"polyhedron_vertices": 8}),
}


def engine_cases(*slow):
    """The cases as pytest parameters, those named in ``slow`` marked slow (> 20 s: Yade builds
    level-set bodies slowly, ≈ 1 min; its polyhedron pour to rest takes ≈ 30 s)."""
    return [pytest.param(*c, id=i, marks=[pytest.mark.slow] if i in slow else []) for i, c in ENGINE_CASES.items()]


def small_deck(grains, out, engine, shape, options, **settings):
    """A deck of the two grains, with scene settings changed by ``settings``."""
    from grainforge.dem import lammps, lammps_body, liggghts, yade
    from grainforge.dem.inputs import build_templates
    from grainforge.io.inputs import mesh_paths

    templates = build_templates(mesh_paths([grains]), workers=1, shape=shape, **options)
    module = {"yade": yade, "liggghts": liggghts,
              "lammps": lammps_body if shape == "polyhedron" else lammps}[engine]
    module.write_deck(templates, out, settings=module.pour_settings(**settings))
    return json.loads((out / "grains.json").read_text())


def last_line(stdout):
    lines = [l for l in stdout.splitlines() if l.strip()]
    return lines[-1] if lines else ""


def engine_steps(out, engine):
    if engine == "yade":
        return json.loads((out / "results-yade.json").read_text())["steps"]
    words = (out / "settle.txt").read_text().split()
    return int(float(dict(zip(words[::2], words[1::2]))["steps"]))


@pytest.mark.parametrize("engine, shape, exe, args, options", engine_cases("yade-levelset"))
def test_deck_reports_not_settled_with_exit_status(engine, shape, exe, args, options, two_grains, tmp_path):
    """A threshold of 0 J can never be met: the run ends after its budget (here the fall and three
    checks) with NOT SETTLED as its last line and exit status 1."""
    path = require(exe)
    out = tmp_path / "deck"
    small_deck(two_grains, out, engine, shape, options, ke_ratio=0.0, settle_time=0.6)
    proc = subprocess.run([path, *args], cwd=out, capture_output=True, text=True, timeout=600,
                          stdin=subprocess.DEVNULL)
    line = last_line(proc.stdout)
    m = NOT_SETTLED.fullmatch(line)
    assert m, f"last line {line!r}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    assert proc.returncode == 1
    assert int(m.group(1)) == engine_steps(out, engine)
    assert float(m.group(2)) > float(m.group(3)) == 0.0
    # the energies' unit is the deck's: joules in SI decks, LAMMPS micro units in the polyhedron deck
    assert (m.group(4) == "J") == (not (engine == "lammps" and shape == "polyhedron"))
    assert sum(1 for l in proc.stdout.splitlines() if "SETTLED" in l) == 1


@pytest.mark.parametrize("engine, shape, exe, args, options", engine_cases("yade-levelset", "yade-polyhedron"))
def test_deck_reports_settled(engine, shape, exe, args, options, two_grains, tmp_path):
    """At the default criterion two README grains settle: last line SETTLED in N steps, exit 0."""
    path = require(exe)
    out = tmp_path / "deck"
    deck = small_deck(two_grains, out, engine, shape, options)
    proc = subprocess.run([path, *args], cwd=out, capture_output=True, text=True, timeout=900,
                          stdin=subprocess.DEVNULL)
    line = last_line(proc.stdout)
    m = SETTLED.fullmatch(line)
    assert m, f"last line {line!r}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    assert proc.returncode == 0
    steps = engine_steps(out, engine)
    assert int(m.group(1)) == steps
    if engine == "yade":
        rep = json.loads((out / "results-yade.json").read_text())
        assert rep["settled"] and rep["ke_window"] < rep["ke_threshold"] and rep["lost"] == []
    else:  # stopped before its budget: fall + max_checks × check_every (+ the read-back runs)
        s = deck["settle"]
        assert steps <= s["fall_steps"] + s["max_checks"] * s["check_every"] + 3
    assert sum(1 for l in proc.stdout.splitlines() if "SETTLED" in l) == 1


@pytest.mark.slow
def test_readme_dem_example_settles(tmp_path):
    """The README's commands as written (20 FSO grains of 2 mm, 30-sphere clumps, Yade) settle:
    they did not when the budget was a fixed 150,000 steps (docs/dem.md)."""
    yade = require("yade")
    r = CliRunner().invoke(cli, ["generate", "fso", "--out", str(tmp_path / "grains"), "--count", "20",
                                 *README_FSO])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["dem", str(tmp_path / "grains"), "--out", str(tmp_path / "deck"), "--engine", "yade",
                                 "--density", "2650", "--spheres", "30"])
    assert r.exit_code == 0, r.output
    proc = subprocess.run([yade, "-n", "-x", "run.py"], cwd=tmp_path / "deck", capture_output=True, text=True,
                          timeout=1200, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    m = SETTLED.fullmatch(last_line(proc.stdout))
    rep = json.loads((tmp_path / "deck" / "results-yade.json").read_text())
    assert m and int(m.group(1)) == rep["steps"]
    assert rep["settled"] and rep["lost"] == [] and len(rep["final"]) == 20
