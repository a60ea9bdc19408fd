"""`grainforge simulate calibrate material`: μ and μ_r fitted together to several angles. The search on stand-in
functions; the command on a stand-in engine whose tilt and triaxial angles are known smooth functions of (μ, μ_r)
plus a seed's noise (tests/_material_stand_in.py): the answer, determinism, resume, targets out of reach,
refusals; and one quick calibration in LIGGGHTS (long lane)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import _material_stand_in as stand_in
import numpy as np
import pytest
from conftest import require_engine

from grainforge.cli.main import cli
from grainforge.simulate import MaterialCalibration, calibrate_material, settings_for
from grainforge.simulate.surrogate import Target, design_points, search_material

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "examples" / "paper-rough-spheres.toml"
#: the (μ, μ_r) the stand-in's targets are made at
TRUE = (0.6, 0.2)
TARGETS = {t: stand_in.angle(t, *TRUE) for t in ("tilt", "triaxial")}


def _noisy(rng, noise=0.8, seeds=3):
    return lambda k, mu, mr: {t: list(stand_in.angle(t, mu, mr) + rng.normal(0.0, noise, seeds))
                              for t in ("tilt", "triaxial")}


# ---- the search, on stand-in functions --------------------------------------------------------------------------

@pytest.mark.parametrize("true", [(0.3, 0.05), (0.6, 0.2), (1.0, 0.35)])
def test_the_search_recovers_the_known_point_within_its_region(true):
    targets = [Target(t, stand_in.angle(t, *true)) for t in ("tilt", "triaxial")]
    s = search_material(_noisy(np.random.default_rng(1)), targets, budget=16)
    assert s.reached and s.converged and len(s.points) < 16
    assert s.friction_bounds[0] <= true[0] <= s.friction_bounds[1]
    assert s.rolling_friction_bounds[0] <= true[1] <= s.rolling_friction_bounds[1]
    # the region is an answer, not the whole box
    assert s.friction_bounds[1] - s.friction_bounds[0] < 0.8 * 1.4
    assert s.rolling_friction_bounds[1] - s.rolling_friction_bounds[0] < 0.8 * 0.5
    for t in targets:  # the best point's predicted angles are the targets within the noise
        assert abs(s.predicted[t.name][0] - t.angle) < t.sd
    # the white noise the surrogates fitted is the stand-in's seed noise (0.8°), roughly
    assert all(0.4 < sd < 1.3 for sd in s.noise_sd.values())


def test_targets_out_of_reach_are_not_a_fit():
    # a low tilt angle needs a low μ, a high triaxial angle a high μ_r beyond the bounds: not reached together
    s = search_material(_noisy(np.random.default_rng(2)), [Target("tilt", 20.0), Target("triaxial", 45.0)],
                        budget=10)
    assert not s.reached and not s.converged and len(s.points) == 10
    assert s.misfit > s.threshold


def test_the_initial_design_is_the_same_for_the_same_seed_and_spreads_over_the_box():
    a = design_points(6, [0.1, 0.0], [1.5, 0.5], 3)
    assert (a == design_points(6, [0.1, 0.0], [1.5, 0.5], 3)).all()
    assert not (a == design_points(6, [0.1, 0.0], [1.5, 0.5], 4)).all()
    # a Latin hypercube: one point in each sixth of each range
    for i, (lo, hi) in enumerate([(0.1, 1.5), (0.0, 0.5)]):
        assert sorted(np.floor((a[:, i] - lo) / (hi - lo) * 6).astype(int)) == list(range(6))


# ---- the calibration with a stand-in engine ---------------------------------------------------------------------

@pytest.fixture
def material_engine(monkeypatch):
    import grainforge.simulate.engine as engine
    import grainforge.simulate.friction_search as friction_search
    import grainforge.simulate.pipeline as pipeline

    calls = []

    def run(deck, **kwargs):
        calls.append(Path(deck).name)
        return stand_in.run_deck(deck, **kwargs)

    monkeypatch.setattr(engine, "run_deck", run)
    monkeypatch.setattr(engine, "measure_result", stand_in.measure_result)
    monkeypatch.setattr(friction_search, "_write_curves", lambda folder, rows: None)  # no stress-strain curve
    monkeypatch.setattr(pipeline, "check_installed", lambda engine, mpi: None)  # nothing is run
    return calls


ARGS = ["--quick", "--templates", "2", "--seeds", "2", "--budget", "10"]


def _calibrate(runner, out, *extra, targets=TARGETS, args=ARGS):
    given = [w for t, a in targets.items() for w in ("--target", f"{t}={a:.2f}")]
    return runner.invoke(cli, ["simulate", "calibrate", "material", str(RECIPE), *given, *args, "--out", str(out),
                               *extra])


def test_the_command_recovers_the_known_point_and_prints_the_commands(material_engine, runner, tmp_path):
    out = tmp_path / "cal"
    r = _calibrate(runner, out, "--workers", "1")
    assert r.exit_code == 0, r.output
    record = json.loads((out / "calibration.json").read_text())
    assert record["reached"] and record["runs"] == record["points"] * 2 * 2  # two tests, two seeds a point
    (mu_lo, mu_hi), (mr_lo, mr_hi) = record["friction_bounds"], record["rolling_friction_bounds"]
    assert mu_lo <= TRUE[0] <= mu_hi and mr_lo <= TRUE[1] <= mr_hi
    assert mu_lo <= record["friction"] <= mu_hi and mr_lo <= record["rolling_friction"] <= mr_hi
    for target in record["targets"]:
        assert abs(target["predicted_angle_deg"] - round(TARGETS[target["test"]], 2)) < target["target_sd_deg"]
    lines = r.stdout.strip().splitlines()
    mu, mr = f"{record['friction']:.3g}", f"{record['rolling_friction']:.3g}"
    assert lines[-2:] == [record["commands"]["tilt"], record["commands"]["triaxial"]]
    assert lines[-2].startswith(f"grainforge simulate tilt {RECIPE} --friction {mu} --rolling-friction {mr} "
                                "--templates 2 --seeds 2 --quick")
    assert lines[-1].startswith("grainforge simulate triaxial ")
    assert f"friction {record['friction']:.3f} ({mu_lo:.3g}–{mu_hi:.3g})" in lines[-3]
    assert "point 0: friction " in r.stderr  # a line after each point
    # every run in calibration.csv: each point's two tests and two seeds, their angles the runs' result.json
    with open(out / "calibration.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == record["runs"] and {r["test"] for r in rows} == {"tilt", "triaxial"}
    row = rows[-1]
    run = next((out / "runs").glob(f"p{int(row['point']):02d}-*")) / f"{row['test']}-seed{row['seed']}"
    assert float(row["angle_deg"]) == pytest.approx(json.loads((run / "result.json").read_text())["angle"])
    assert sorted(p.name for p in out.iterdir()) == ["calibration.csv", "calibration.json", "calibration.png",
                                                     "runs", "templates-tilt.csv", "templates-triaxial.csv"]
    assert (out / "calibration.png").stat().st_size > 20_000


def test_the_same_arguments_give_the_same_bytes_with_any_worker_count(material_engine, runner, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert _calibrate(runner, a, "--workers", "1").exit_code == 0
    r = _calibrate(runner, b, "--workers", "2")
    assert r.exit_code == 0, r.output
    for name in ("calibration.csv", "calibration.json", "calibration.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


@pytest.mark.slow
def test_on_a_dask_cluster_the_outputs_are_the_local_ones(material_engine, monkeypatch, runner, tmp_path):
    """Each run a task of a LocalCluster of two worker processes (they import the stand-in engine, passed as the
    run's function): the same calibration.csv, calibration.json and calibration.png as one local worker."""
    distributed = pytest.importorskip("distributed")
    import os

    tests = str(Path(stand_in.__file__).parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([tests, os.environ.get("PYTHONPATH", "")]))
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert _calibrate(runner, local, "--workers", "1").exit_code == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as cluster:
        r = _calibrate(runner, remote, "--scheduler", cluster.scheduler_address)
    assert r.exit_code == 0, r.output
    for name in ("calibration.csv", "calibration.json", "calibration.png"):
        assert (local / name).read_bytes() == (remote / name).read_bytes(), name


def test_a_resumed_calibration_reuses_the_finished_runs_and_gives_the_same_outputs(material_engine, monkeypatch,
                                                                                       runner, tmp_path):
    import grainforge.simulate.engine as engine

    whole = tmp_path / "whole"
    assert _calibrate(runner, whole, "--workers", "1").exit_code == 0
    total = len(material_engine)
    # interrupted at the 7th run (point 1's triaxial test): six runs finished and journalled
    material_engine.clear()
    run = engine.run_deck

    def interrupted(deck, **kwargs):
        if len(material_engine) >= 6:
            raise KeyboardInterrupt
        return run(deck, **kwargs)

    monkeypatch.setattr(engine, "run_deck", interrupted)
    out = tmp_path / "cut"
    _calibrate(runner, out, "--workers", "1")
    assert not (out / "calibration.json").exists()
    assert len(list((out / ".grainforge-sweep").glob("runs+p*"))) == 6
    monkeypatch.setattr(engine, "run_deck", run)
    material_engine.clear()
    r = _calibrate(runner, out, "--workers", "1", "--resume")
    assert r.exit_code == 0, r.output
    assert len(material_engine) == total - 6  # the six finished runs were not run again
    for name in ("calibration.csv", "calibration.json", "calibration.png"):
        assert (whole / name).read_bytes() == (out / name).read_bytes(), name
    assert not (out / ".grainforge-sweep").exists()


def test_targets_out_of_reach_are_said_plainly_with_exit_3(material_engine, runner, tmp_path):
    out = tmp_path / "cal"
    r = _calibrate(runner, out, "--workers", "1", targets={"tilt": 20.0, "triaxial": 45.0},
                   args=["--quick", "--templates", "2", "--budget", "8"])
    assert r.exit_code == 3, r.output
    assert "tilt 20° and triaxial 45° are not reached together with friction in 0.1–1.5" in r.stdout
    assert "grainforge simulate tilt" not in r.stdout  # no command for values that are no fit
    assert "check failed: the targets are not reached together" in r.stderr
    record = json.loads((out / "calibration.json").read_text())
    assert not record["reached"] and record["misfit"] > record["misfit_threshold"] and record["points"] == 8


def test_the_library_returns_the_result_and_prints_nothing(material_engine, tmp_path, capsys):
    settings = {t: settings_for(t, quick=True, templates=2) for t in TARGETS}
    result = calibrate_material([RECIPE], out=tmp_path / "m", targets=[f"{t}={a}" for t, a in TARGETS.items()],
                                settings=settings, quick=True, workers=1, budget=10)
    assert capsys.readouterr() == ("", "")
    assert isinstance(result, MaterialCalibration) and result.passed and result.reached
    assert result.friction_bounds[0] <= TRUE[0] <= result.friction_bounds[1]
    assert result.record == json.loads((result.out / "calibration.json").read_text())
    assert len(result.rows) == len(result.search.points) * 2


@pytest.mark.parametrize("args, message", [
    (["--target", "shear=30"], "unknown test 'shear'"),
    (["--target", "tilt=38", "--target", "tilt=36"], "tilt is given twice"),
    (["--target", "tilt"], "is not TEST=ANGLE or TEST=ANGLE:SD"),
    (["--target", "tilt=85"], "target angle 85° is outside 5–80°"),
    (["--target", "tilt=38:0"], "the spread of tilt must be a positive number"),
    (["--target", "tilt=38", "--friction-range", "1", "0.5"], "--friction-range: need 0 ≤ low < high ≤ 5"),
    (["--target", "tilt=38", "--rolling-friction-range", "0", "2"], "--rolling-friction-range: need 0 ≤ low < high"),
    (["--target", "tilt=38", "--budget", "4", "--initial-points", "5"], "--initial-points: need 2 ≤ initial points"),
    (["--target", "tilt=38", "--packing", "dense"], "--packing is the triaxial test's: no triaxial target"),
    (["--target", "tilt=38", "--angle", "peak"], "--angle is a triaxial target's"),
    (["--target", "tilt=38", "--rolling-friction", "0.1"], "No such option"),
    (["--target", "tilt=38", "--shape", "levelset"], "μ_r acts at sphere contacts"),
    (["--target", "tilt=38", "--grains", "20000", "--seeds", "100", "--budget", "60"], "lower"),
])
def test_bad_material_calibrations_are_refused_in_one_line(material_engine, runner, tmp_path, args, message):
    out = tmp_path / "cal"
    r = runner.invoke(cli, ["simulate", "calibrate", "material", str(RECIPE), "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in r.output and message in r.stderr, r.stderr
    assert lines[-1].startswith("Error") and message in lines[-1]
    assert not out.exists() and material_engine == []


def test_calibrate_test_still_takes_one_target_and_names_material(runner, tmp_path):
    r = runner.invoke(cli, ["simulate", "calibrate", "--help"])
    assert r.exit_code == 0 and "simulate calibrate material" in " ".join(r.output.split())
    r = runner.invoke(cli, ["simulate", "calibrate", "--target-angle", "30", "material", str(RECIPE), "--out",
                            str(tmp_path / "c")])
    assert r.exit_code == 2 and "write material right after calibrate" in r.stderr
    r = runner.invoke(cli, ["simulate", "calibrate", "material", "--help"])
    assert r.exit_code == 0 and "simulate calibrate material [OPTIONS] INPUTS" in r.output.splitlines()[0]


# ---- with the engine -------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_a_quick_material_calibration_in_liggghts(runner, tmp_path):
    """Two points of a quick tilt and a quick triaxial test in LIGGGHTS, one seed each (about 30 s of CPU, the
    engine's included): every output, each run's angle in calibration.csv, and a line that says whether the
    targets are reached."""
    require_engine("liggghts")
    out = tmp_path / "cal"
    r = runner.invoke(cli, ["simulate", "calibrate", "material", str(RECIPE), "--target", "tilt=30",
                            "--target", "triaxial=25", "--engine", "liggghts", "--quick", "--tilt-step", "2",
                            "--budget", "2", "--initial-points", "2", "--workers", "1", "--out", str(out)])
    assert r.exit_code in (0, 3), r.output
    record = json.loads((out / "calibration.json").read_text())
    assert record["points"] == 2 and record["runs"] == 4
    with open(out / "calibration.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted(r["test"] for r in rows) == ["tilt", "tilt", "triaxial", "triaxial"]
    assert all(math.isfinite(float(r["angle_deg"])) for r in rows)
    assert ("are not reached together" in r.stdout) == (not record["reached"])
    assert (out / "calibration.png").stat().st_size > 20_000


def _record(**changes):
    record = {"targets": [{"test": "tilt", "target_angle_deg": 38.0, "target_sd_deg": 1.0,
                           "predicted_angle_deg": 37.8, "predicted_sd_deg": 0.3}],
              "friction": 0.6, "rolling_friction": 0.2, "friction_bounds": [0.5, 0.7],
              "rolling_friction_bounds": [0.1, 0.3], "friction_range": [0.1, 1.5], "rolling_friction_range": [0.0, 0.5],
              "misfit": 0.04, "misfit_threshold": 3.84, "reached": True, "converged": True, "budget": 16, "points": 7,
              "runs": 14}
    return {**record, **changes}


def test_the_line_says_when_the_region_is_wide_and_when_the_surrogate_is_unsure():
    from grainforge.simulate.material import material_line

    line = material_line(_record(), "sand", "out")
    assert line == ("sand: friction 0.600 (0.5–0.7), rolling friction 0.200 (0.1–0.3) reach tilt 38° (predicted "
                    "tilt 37.8°) (7 points, 14 runs); out/calibration.json")
    wide = material_line(_record(rolling_friction_bounds=[0.0, 0.4], converged=False), "sand", "out")
    assert "(budget of 16 points spent); the region within the noise spans over half the rolling friction range" in wide
    unsure = _record(reached=False, misfit=9.0, targets=[{**_record()["targets"][0], "predicted_sd_deg": 2.5}])
    line = material_line(unsure, "sand", "out")
    assert line.startswith("sand: tilt 38° are not reached together with friction in 0.1–1.5 and rolling friction "
                           "in 0–0.5: the closest point, friction 0.600, rolling friction 0.200, gives tilt 37.8°")
    assert "the surrogate is still unsure there (± 2.5°): more points (budget) may reach them" in line
