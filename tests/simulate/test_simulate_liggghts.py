"""``grainforge simulate --engine liggghts [--mpi N]``: the LIGGGHTS decks, and quick runs in the real engine.

The engine tests run LIGGGHTS (serial and under ``mpirun -np 2``) and are skipped with the reason when
it or mpirun is missing; with GRAINFORGE_REQUIRE_ENGINES=1 a missing engine is a failure.
"""

from __future__ import annotations

import csv
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from dem.test_dem_engines import require  # skips, or fails under GRAINFORGE_REQUIRE_ENGINES=1

from grainforge.cli.main import cli
from grainforge.simulate import QUICK, Settings, build_population
from grainforge.simulate import liggghts_scenes as lg
from grainforge.simulate.yade_scenes import REPOSE, TILT


@pytest.fixture(scope="module")
def grains(tmp_path_factory):
    from click.testing import CliRunner

    out = tmp_path_factory.mktemp("g") / "g"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="module")
def templates(grains):
    return build_population([grains], Settings(**QUICK))


def yade_record_keys(scene: str) -> set:
    """The keys of the record a Yade scene writes (its ``write_result({...})`` call)."""
    call = scene[scene.index("write_result({"):]
    return set(re.findall(r'"(\w+)":', call[: call.index("})")]))


# ---- the decks (no engine) ------------------------------------------------------------------------------

@pytest.mark.parametrize("test", ["repose", "tilt"])
def test_deck_is_the_same_for_the_same_seed_and_differs_between_seeds(templates, test):
    s = Settings(**QUICK)
    a, b, c = (lg.run_deck_files(templates, test, s, seed) for seed in (0, 0, 1))
    assert a == b
    assert a["in.insert"] != c["in.insert"] and a["in.base"] != c["in.base"]
    # every grain inserted once, each insertion its own prime seed
    seeds = [int(m) for m in re.findall(r"insert/pack seed (\d+)", a["in.insert"])]
    assert len(seeds) == s.grains == len(set(seeds))


def test_clump_types_of_the_drawn_templates_are_consecutive(grains):
    """LIGGGHTS stops unless the multisphere types are 1, 2, ... with no gap: templates not drawn are left out."""
    s = Settings(**{**QUICK, "grains": 3, "templates": 3})
    templates = build_population([grains], s)
    files = lg.run_deck_files(templates, "tilt", s, 0)
    types = [int(t) for t in re.findall(r" type (\d+) mass", files["in.templates"])]
    assert types == list(range(1, len(types) + 1))
    used = {int(t) for t in re.findall(r"distributiontemplate pdd(\d+)", files["in.insert"])}
    assert used == set(types)
    s2 = Settings(**{**QUICK, "grains": 2, "templates": 3})
    for seed in range(6):  # two grains drawn from three templates: some seed leaves one out
        files = lg.run_deck_files(templates, "tilt", s2, seed)
        types = [int(t) for t in re.findall(r" type (\d+) mass", files["in.templates"])]
        assert types == list(range(1, len(types) + 1))


@pytest.mark.parametrize("test", ["repose", "tilt"])
def test_deck_uses_the_yade_contact_settings(templates, test):
    s = Settings(**QUICK, friction=0.7, young=2e6, poisson=0.25)
    files = lg.run_deck_files(templates, test, s, 0)
    run = files["in.run"]
    assert "pair_style gran model hooke/stiffness tangential history" in run
    kn = [float(x) for x in re.search(r"fix kn all property/global kn peratomtypepair 3 (.*)", run)[1].split()]
    kt = [float(x) for x in re.search(r"fix kt all property/global kt peratomtypepair 3 (.*)", run)[1].split()]
    mu = [float(x) for x in re.search(r"coefficientFriction peratomtypepair 3 (.*)", run)[1].split()]
    assert np.allclose(kt, 0.25 * np.array(kn)) and mu == [0.7] * 9
    import json

    rec = json.loads(files["grains.json"])["result"]
    # grain pair: k_n = E r at the mean contact-sphere radius, as Yade's law for two equal spheres
    assert kn[0] == pytest.approx(2e6 * rec["contact_radius"], rel=1e-12)
    # the time step rule of the Yade scenes, dt = 0.3 sqrt(m_min / k_max)
    m_min = min(g["mass"] for g in json.loads(files["grains.json"])["grains"])
    assert rec["dt"] == pytest.approx(0.3 * math.sqrt(m_min / max(kn)), rel=1e-12)


def test_a_sphere_is_a_multisphere_with_an_inner_sphere_that_never_touches(grains):
    s = Settings(**QUICK)
    files = lg.run_deck_files(build_population([grains], s, as_spheres=True), "tilt", s, 0)
    xyzr = [text for name, text in files.items() if name.endswith(".xyzr")]
    assert xyzr
    for text in xyzr:
        rows = np.array([[float(x) for x in ln.split()] for ln in text.splitlines() if not ln.startswith("#")])
        assert rows.shape == (2, 4) and np.all(rows[1, :3] == rows[0, :3])
        assert rows[1, 3] == pytest.approx(0.01 * rows[0, 3])
    fixes = [ln for ln in files["in.templates"].splitlines() if "particletemplate/multisphere" in ln]
    assert len(fixes) == len(xyzr) and all(" nspheres 2 " in ln for ln in fixes)


def test_local_damping_and_its_viscous_equivalent_have_one_restitution():
    t = lg.contact_table(Settings(damping=0.3), 1e-3, 3e-4, 5e-6)
    zeta = t["damping_ratio"]
    assert math.exp(-math.pi * zeta / math.sqrt(1 - zeta ** 2)) == pytest.approx(math.sqrt(0.7 / 1.3), rel=1e-12)
    # gamma_n = 2 zeta sqrt(k / m_eff), m_eff = m/2 for two grains
    assert t["gamman"][0][0] == pytest.approx(2 * zeta * math.sqrt(t["kn"][0][0] / 2.5e-6), rel=1e-12)


def test_insertion_nodes_stay_clear_of_every_processor_cut():
    x = np.array([0.5, 1.0 / 3.0 + 1e-9, 0.25, 0.123456, 1e-9, 1.0 - 1e-9])
    moved = lg._clear_of_cuts(x, 0.0, 1.0, 1e-4)
    cuts = np.concatenate([np.arange(0, p + 1) / p for p in range(1, lg.MAX_CUTS + 1)])
    assert np.abs(moved[:, None] - cuts[None, :]).min() >= 1e-4
    assert moved[3] == x[3] and np.abs(moved - x).max() < 1e-3
    assert ((moved > 0.0) & (moved < 1.0)).all()  # the ends (a periodic boundary) push inwards


def test_mpi_command_lets_open_mpi_run_as_root_and_oversubscribe(monkeypatch, tmp_path):
    for name in ("liggghts", "mpirun"):
        exe = tmp_path / name
        exe.write_text("#!/bin/sh\nexit 0\n")
        exe.chmod(0o755)
        monkeypatch.setenv(f"GRAINFORGE_{name.upper()}", str(exe))
    cmd, env = lg.engine_command(2 * (os.cpu_count() or 1))
    assert cmd[:3] == [str(tmp_path / "mpirun"), "-np", str(2 * (os.cpu_count() or 1))]
    assert cmd[3:] == [str(tmp_path / "liggghts"), "-in", "in.run", "-log", "none"]
    assert env["OMPI_MCA_rmaps_base_oversubscribe"] == "1"
    assert ("OMPI_ALLOW_RUN_AS_ROOT" in env) == (os.geteuid() == 0)
    assert lg.engine_command(None) == ([str(tmp_path / "liggghts"), "-in", "in.run", "-log", "none"], {})


# ---- the real engine ------------------------------------------------------------------------------------

def check_run(runner, grains, out, test, *extra):
    # the plumbing at the tilt's 30 grains in both tests (the documented quick repose: test_documented_commands.py)
    r = runner.invoke(cli, ["simulate", test, str(grains), "--out", str(out), "--quick", "--engine", "liggghts",
                            "--grains", str(QUICK["grains"]), *extra])
    # exit 3: a run failed its own check (a quick run may measure no angle), named on stderr
    assert r.exit_code == 0 or (r.exit_code == 3 and "check failed: seed" in r.stderr), r.output
    rows = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    assert len(rows) == QUICK["seeds"]
    row = rows[0]
    assert int(row["inserted"]) == QUICK["grains"] and int(row["lost"]) == 0
    assert row["setting_friction"] == "0.5"
    assert row["engine"] == "liggghts"
    assert row["mpi_ranks"] == (extra[extra.index("--mpi") + 1] if "--mpi" in extra else "1")
    import json

    result = json.loads((out / f"{test}-seed0" / "result.json").read_text())
    # the Yade scene's record, field for field: measure_result, results.csv and the figure are shared
    # (but "placed": Yade's record of each contact body as inserted; the LIGGGHTS deck's insertions are its own)
    assert set(result) == yade_record_keys(REPOSE if test == "repose" else TILT) - {"placed"}
    assert len(result["spheres"]) > QUICK["grains"]
    angle = float(row["angle_deg"])
    if test == "repose":
        assert row["settled"] == "True"
        assert 0.0 < angle < 60.0 or (math.isnan(angle) and "too flat" in row["note"])
    else:
        assert np.asarray(result["history"]).shape[1] == 3
        assert 5.0 < angle < 80.0 or (math.isnan(angle) and "did not fail" in row["note"])
    assert (out / f"{test}.png").stat().st_size > 10_000
    return r, row


YADE_COLUMNS = ["label", "seed", "test", "grains", "inserted", "lost", "steps", "dt_s", "simulated_time_s",
                "angle_deg", "sector_sd_deg"]


@pytest.mark.slow
@pytest.mark.parametrize("test", ["repose", "tilt"])
def test_quick_run_in_liggghts(runner, grains, tmp_path, test):
    require("liggghts", "liggghts")
    out = tmp_path / test
    r, row = check_run(runner, grains, out, test)
    assert list(row)[: len(YADE_COLUMNS)] == YADE_COLUMNS
    assert "1 by 1 by 1 MPI processor grid" in (out / f"{test}-seed0" / "liggghts.log").read_text()


@pytest.mark.slow
def test_quick_run_in_liggghts_under_mpirun_2(runner, grains, tmp_path):
    require("liggghts", "liggghts")
    require("mpirun", "openmpi-bin")
    out = tmp_path / "repose"
    # soft contacts (E = 1e5 Pa: a time step three times longer): the ranks' grid and the outputs are the claim; the
    # quick settings as --quick sets them run on one rank above
    check_run(runner, grains, out, "repose", "--mpi", "2", "--young", "1e5")
    log = (out / "repose-seed0" / "liggghts.log").read_text()
    assert re.search(r"(2 by 1|1 by 2) by 1 MPI processor grid", log), log[:2000]


def _descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


@pytest.mark.slow
def test_an_interrupt_kills_mpirun_and_every_rank_and_leaves_nothing(grains, tmp_path):
    require("liggghts", "liggghts")
    require("mpirun", "openmpi-bin")
    from _processes import assert_gone, kill_sessions

    work = tmp_path / "work"
    work.mkdir()
    proc = subprocess.Popen([sys.executable, "-c", "from grainforge.cli.main import main; main()", "simulate",
                             "tilt", str(grains), "--out", "o", "--quick", "--engine", "liggghts", "--mpi", "2"],
                            cwd=work, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    started = [proc]
    try:
        deadline = time.monotonic() + 120  # a hang guard
        ranks: set[int] = set()
        while len(ranks) < 2:
            assert proc.poll() is None, proc.communicate()[1].decode()
            assert time.monotonic() < deadline, "the two LIGGGHTS ranks never started"
            below = _descendants(proc.pid)
            ranks = {p for p in below if Path(f"/proc/{p}/comm").exists()
                     and Path(f"/proc/{p}/comm").read_text().strip() == "liggghts"}
            time.sleep(0.1)
        engine = _descendants(proc.pid)
        os.kill(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err.decode()
        assert_gone(engine)
        assert list(work.iterdir()) == []
    finally:
        kill_sessions(started)
