"""``grainforge simulate triaxial --engine liggghts [--mpi N]``: the walled-box deck (no engine), the refusals before
any engine starts, and quick runs in LIGGGHTS under ``mpirun -np 2`` read back and checked against the physics of a
drained triaxial test.

Without LIGGGHTS or mpirun the engine tests are skipped with the reason; with GRAINFORGE_REQUIRE_ENGINES=1 a missing
engine is a failure (``require_engine``).  (The interrupt of a run under mpirun: tests/cli/test_cli_signals.py.)
"""

import csv
import io
import json
import math
import re

import numpy as np
import pytest
from conftest import require_engine

from grainforge.cli.main import cli
from grainforge.simulate import TriaxialSettings, build_population
from grainforge.simulate import liggghts_triaxial as lt
from grainforge.simulate.settings import QUICK_TRIAXIAL_LIGGGHTS
from grainforge.simulate.triaxial import CSV_COLUMNS, triaxial_scene_settings

QUICK = TriaxialSettings(**QUICK_TRIAXIAL_LIGGGHTS)


@pytest.fixture(scope="module")
def grains(tmp_path_factory):
    """Three rough-sphere CRI grains of 2 mm (the paper's rough spheres, coarse meshes)."""
    from click.testing import CliRunner

    out = tmp_path_factory.mktemp("triaxial-lg") / "grains"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-sphere"])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="module")
def templates(grains):
    return build_population([grains], QUICK)


def _numbers(line: str) -> list[float]:
    return [float(x) for x in line.split()]


# ---- the deck (no engine) -------------------------------------------------------------------------------


def test_the_deck_is_the_same_for_a_seed_and_differs_between_seeds(templates):
    a, b, c = (lt.triaxial_deck_files(templates, QUICK, seed) for seed in (0, 0, 1))
    assert a == b
    assert a["in.insert"] != c["in.insert"]
    seeds = [int(m) for m in re.findall(r"insert/pack seed (\d+)", a["in.insert"])]
    assert len(seeds) == QUICK.grains == len(set(seeds))


def test_grain_k_takes_row_k_of_the_scenes_orientations(templates):
    """The deck inserts grain k in row k of the orientations the Yade scene of that seed places it in."""
    from dem.test_orientations import assert_uniform, liggghts_quaternions, matrices

    settings = TriaxialSettings(**{**QUICK_TRIAXIAL_LIGGGHTS, "grains": 300})
    files = lt.triaxial_deck_files(templates, settings, 5)
    q = liggghts_quaternions(files["in.insert"])
    yade = triaxial_scene_settings(settings, 5)["orientations"]
    assert np.allclose(q, yade, rtol=0, atol=1e-14)
    assert np.allclose(json.loads(files["grains.json"])["result"]["scene"]["orientations"], yade, rtol=0, atol=0)
    assert_uniform(matrices(q))


def _plate(text: str) -> np.ndarray:
    return np.array([_numbers(ln.split("vertex")[1]) for ln in text.splitlines() if "vertex" in ln])


def test_six_plates_close_the_box_and_stay_inside_the_domain(templates):
    files = lt.triaxial_deck_files(templates, QUICK, 0)
    run = files["in.run"]
    lo, hi = (float(x) for x in re.search(r"region domain block (\S+) (\S+)", run).groups())
    rec = json.loads(files["grains.json"])["result"]
    half = 0.5 * np.array(rec["box_initial"])
    # the lateral walls may move out to LATERAL_REACH × the initial width / √(1 − ε_a): the plates reach past that
    reach = half.max() * lt.LATERAL_REACH / math.sqrt(1.0 - QUICK.axial_strain)
    for a, name in enumerate("xyz"):
        for side, sign in ((0, -1), (1, 1)):
            v = _plate(files[f"wall-{name}{side}.stl"])
            assert np.allclose(v[:, a], sign * half[a])  # the wall at its face of the box
            others = [b for b in range(3) if b != a]
            assert np.all(np.abs(v[:, others]).max(axis=0) > reach)  # past the box's edges, with the lateral reach
            assert np.all((v > lo) & (v < hi))
            axis = [0.0, 0.0, 0.0]
            axis[a] = -float(sign)  # moves along its inward normal
            assert re.search(rf"fix w{name}{side} all mesh/surface/stress/servo file wall-{name}{side}.stl .* axis "
                             + " ".join(re.escape(repr(x)) for x in axis), run)
    # every grain's node inside the box, its bounding sphere clear of the walls and of every other one
    nodes = np.array(rec["nodes"])
    r_b = max(g["bounding_radius"] for g in json.loads(files["grains.json"])["grains"])
    assert np.all(np.abs(nodes) + r_b < half)
    gaps = np.linalg.norm(nodes[:, None] - nodes[None], axis=2) + np.eye(len(nodes)) * 1e9
    assert gaps.min() > 2 * r_b


@pytest.mark.parametrize("packing", ["dense", "loose"])
def test_the_deck_uses_the_contact_settings(templates, packing):
    s = TriaxialSettings(**{**QUICK_TRIAXIAL_LIGGGHTS, "packing": packing, "friction": 0.7, "young": 2e8,
                            "poisson": 0.25})
    files = lt.triaxial_deck_files(templates, s, 0)
    run = files["in.run"]
    kn = _numbers(re.search(r"fix kn all property/global kn peratomtypepair 3 (.*)", run)[1])
    kt = _numbers(re.search(r"fix kt all property/global kt peratomtypepair 3 (.*)", run)[1])
    mu = [_numbers(m) for m in re.findall(r"coefficientFriction peratomtypepair 3 (.*)", run)]
    rec = json.loads(files["grains.json"])["result"]
    assert kn[0] == pytest.approx(2e8 * rec["contact_radius"], rel=1e-12) and np.allclose(kt, 0.25 * np.array(kn))
    # the grains at μ (a dense specimen compacted at 0, then μ), the walls frictionless throughout
    grains_mu = [m[0] for m in mu]
    assert grains_mu == ([0.0, 0.7] if packing == "dense" else [0.7])
    assert all(m[2] == m[6] == 0.0 for m in mu)
    # the Yade scene's time step, 0.3 √(m_min / (E r_max)), r_max the largest contact sphere of the grains drawn
    grains = json.loads(files["grains.json"])["grains"]
    m_min = min(g["mass"] for g in grains)
    r_max = max(np.loadtxt(io.StringIO(files[g["xyzr"]]), comments="#").reshape(-1, 4)[:, 3].max() for g in grains)
    assert rec["dt"] == pytest.approx(0.3 * math.sqrt(m_min / (2e8 * r_max)), rel=1e-12)
    # the axial strain rate of the inertial number, from the grains' own density and mean diameter
    assert rec["strain_rate"] == pytest.approx(s.inertial_number * math.sqrt(2e4 / rec["grain_density"])
                                               / rec["d_mean"], rel=1e-12)


def test_the_ranks_grid_and_the_specimen_it_needs():
    assert lt.processor_grid(2) == (2, 1, 1) and lt.processor_grid(64) == (4, 4, 4)
    lt.check_ranks(TriaxialSettings(grains=100), 2)
    lt.check_ranks(TriaxialSettings(grains=700), 64)  # 8.3 diameters wide, 2.1 a rank
    with pytest.raises(ValueError, match=r"^mpi 27: .* cut 3 ways .* use mpi 8 .* grains 265 or more"):
        lt.check_ranks(TriaxialSettings(grains=200), 27)


def test_mpi_beyond_the_cores_is_refused_before_any_engine_starts(runner, grains, tmp_path, monkeypatch):
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})
    for name in ("SLURM_NTASKS", "SLURM_NPROCS", "PBS_NP", "NSLOTS", "LSB_DJOB_NUMPROC", "PBS_NODEFILE"):
        monkeypatch.delenv(name, raising=False)
    for engine in ("YADE", "LIGGGHTS", "MPIRUN"):
        monkeypatch.setenv(f"GRAINFORGE_{engine}", str(tmp_path / "no-engine-is-started"))
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "triaxial", str(grains), "--out", str(out), "--engine", "liggghts",
                            "--grains", "1000", "--mpi", "3"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--mpi 3: only 2 rank(s) available (2 core(s) here)" in lines[0], r.stderr
    assert not out.exists()


# ---- quick runs in LIGGGHTS under mpirun -np 2 ----------------------------------------------------------


def _run(runner, grains, out, *extra):
    require_engine("liggghts")
    require_engine("mpirun")
    r = runner.invoke(cli, ["simulate", "triaxial", str(grains), "--out", str(out), "--quick", "--engine",
                            "liggghts", "--mpi", "2", *extra])
    assert r.exit_code == 0, r.output
    (row,) = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    run = out / "triaxial-seed0"
    table = list(csv.DictReader((run / "triaxial.csv").read_text().splitlines()))
    assert tuple(table[0]) == CSV_COLUMNS
    curve = np.array([[float(t[c]) for c in CSV_COLUMNS] for t in table])
    result = json.loads((run / "result.json").read_text())
    assert re.search(r"\d by \d by \d MPI processor grid", (run / "liggghts.log").read_text())
    assert "1 by 1 by 1 MPI" not in (run / "liggghts.log").read_text()
    return r, row, curve, result, run


def _slope(eps, ev):
    """Least-squares dε_v/dε₁ over the shearing past its first 1 %."""
    past = eps > 0.01
    return float(np.polyfit(eps[past], ev[past], 1)[0])


def _placed_as_the_deck_says(run):
    """Every sphere, as LIGGGHTS inserted it, at its grain's centre + R_k · (its template offset), grain k turned
    by row k of the deck's orientations (the body at node k)."""
    from scipy.spatial.transform import Rotation

    deck = json.loads((run / "grains.json").read_text())
    rec = deck["result"]
    q = np.array(rec["scene"]["orientations"])
    R = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    nodes = np.array(rec["nodes"])
    atoms = np.array([_numbers(ln) for ln in (run / "atoms.txt").read_text().splitlines()
                      if len(ln.split()) == 6 and not ln.startswith("ITEM")])
    bodies = np.array([_numbers(ln) for ln in (run / "bodies-initial.txt").read_text().splitlines()
                       if len(ln.split()) == 4 and not ln.startswith("ITEM")])
    files = {t["name"]: t["xyzr"] for t in deck["grains"]}
    assert len(bodies) == len(nodes) == len(q)
    seen = set()
    for body, *centre in bodies:
        k = int(np.argmin(np.linalg.norm(nodes - centre, axis=1)))
        seen.add(k)
        assert np.linalg.norm(nodes[k] - centre) < 1e-6 * rec["d_mean"]
        rows = np.loadtxt(run / files[deck["drawn"][k]], comments="#").reshape(-1, 4)
        mine = atoms[atoms[:, 1] == body, 3:]
        expect = np.asarray(centre) + rows[:, :3] @ R[k].T
        assert len(mine) == len(rows)
        assert np.linalg.norm(mine[:, None] - expect[None], axis=2).min(axis=1).max() < 1e-9 * rec["d_mean"]
    assert seen == set(range(len(nodes)))


@pytest.mark.slow
def test_quick_dense_triaxial_in_liggghts_under_mpirun_2(runner, grains, tmp_path):
    """100 rough spheres (6-sphere clumps) in a box of six servo walls, compacted to 20 kPa without friction, sheared
    to 6 % at I = 2e-3 on two MPI ranks: the physics of a drained test holds, the outputs are the Yade run's."""
    from test_simulate_liggghts import yade_record_keys

    from grainforge.simulate.yade_scenes import TRIAXIAL

    out = tmp_path / "dense"
    r, row, curve, result, run = _run(runner, grains, out)
    assert "dense, e0 " in r.stdout and "peak friction angle" in r.stdout
    assert row["engine"] == "liggghts" and row["mpi_ranks"] == "2" and row["problems"] == ""
    assert int(row["inserted"]) == QUICK.grains and int(row["lost"]) == 0
    assert float(row["inertial_number"]) == pytest.approx(QUICK.inertial_number, rel=1e-9)
    assert float(row["axial_strain_reached"]) >= QUICK.axial_strain
    # the Yade scene's record, field for field (but its placement record): results.csv and the figure are shared
    assert set(result) == yade_record_keys(TRIAXIAL) - {"placed"}
    eps, q, p, ratio, ev, void, z = curve.T
    # isotropic at the start, at the confining stress; then the stress ratio rises
    assert eps[0] == 0.0 and abs(ratio[0]) < 0.02 and p[0] == pytest.approx(20.0, rel=0.02)
    assert ratio.max() > 0.6 and np.median(ratio[eps > 0.5 * eps[-1]]) > 0.5
    assert np.allclose(ratio, q / p, rtol=1e-9)
    # the lateral stress held at the confining stress while sheared (the walls' servo)
    rec = np.array(result["records"])
    col = {name: rec[:, k] for k, name in enumerate(result["columns"])}
    lateral = 0.5 * (col["sigma_x"] + col["sigma_y"]) / result["confining"] - 1.0
    assert np.median(np.abs(lateral[eps > 0.01 * eps[-1]])) < 0.03
    assert float(row["lateral_stress_error_median"]) < 0.03
    # a dense frictional specimen dilates: ε_v falls (compression positive)
    assert _slope(eps, ev) < -0.3 and ev[-1] < -0.01
    # the void ratio follows the walls' volume: (1 + e) = (1 + e0)(1 − ε_v); a walled box of 100 grains is looser
    # than a periodic cell (the grains cannot fill the walls' corners)
    assert np.allclose(1.0 + void, (1.0 + void[0]) * (1.0 - ev), rtol=1e-9) and 0.5 < void[0] < 1.5
    assert z[0] > 3.0 and float(row["overlap_over_d_max"]) < 0.01
    _placed_as_the_deck_says(run)
    assert not (run / "contacts.txt").exists()  # read into the coordination and overlaps, then removed
    assert (out / "triaxial.png").stat().st_size > 10_000


@pytest.mark.slow
def test_a_frictionless_sphere_packing_hardly_dilates_in_liggghts(runner, grains, tmp_path):
    """Volume-equivalent spheres at μ = 0 (compacted and sheared without friction) on two MPI ranks: hardly any
    dilatancy (a small slope of ε_v against ε₁, where the frictional clumps above dilate at more than 0.3), a low
    stress ratio, and the lateral stress still held."""
    _, row, curve, result, _ = _run(runner, grains, tmp_path / "spheres", "--as-spheres", "--friction", "0")
    assert row["problems"] == "" and row["setting_friction"] == "0.0"
    eps, q, p, ratio, ev, void, z = curve.T
    assert abs(_slope(eps, ev)) < 0.25 and np.abs(ev).max() < 0.025
    assert np.mean(ratio[eps > 0.5 * eps[-1]]) < 0.6
    assert float(row["lateral_stress_error_median"]) < 0.05
