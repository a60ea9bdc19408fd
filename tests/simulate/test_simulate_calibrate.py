"""`grainforge simulate calibrate`: the friction search (pure, on stand-in angle functions), its refusals,
and one quick engine calibration (slow)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import require_engine, require_long_lane

from grainforge.cli.main import cli
from grainforge.simulate.friction_search import (
    Unreachable,
    friction_uncertainty,
    pooled_sd,
    search_friction,
)


def smooth(mu):
    """A stand-in that rises with μ and saturates, as the tilt angles do (docs/simulate.md)."""
    return 15.0 + 30.0 * (1.0 - math.exp(-2.0 * mu))


def exact_root(target):
    return -0.5 * math.log(1.0 - (target - 15.0) / 30.0)


@pytest.mark.parametrize("target", [20.0, 30.0, 38.0, 43.0])
def test_search_finds_the_root_of_a_smooth_angle_in_few_evaluations(target):
    s = search_friction(smooth, target, tolerance=0.1)
    assert s.converged
    assert abs(smooth(s.friction) - target) < 0.15
    assert s.friction == pytest.approx(exact_root(target), abs=0.02)
    assert len(s.evaluations) <= 8
    lo, hi = s.bracket
    assert lo.angle <= target <= hi.angle and lo.friction <= hi.friction
    # the slope is the bracket's secant: between the derivatives 60 exp(-2 mu) at its ends (mean value)
    assert 60.0 * math.exp(-2.0 * hi.friction) <= s.slope <= 60.0 * math.exp(-2.0 * lo.friction)


def test_every_evaluation_is_inside_the_bounds_and_reported():
    seen = []
    s = search_friction(smooth, 44.0, low=0.1, high=3.0, tolerance=0.05, progress=seen.append)
    assert [e.friction for e in seen] == [e.friction for e in s.evaluations]
    assert all(0.1 <= e.friction <= 3.0 for e in s.evaluations)
    # bracketing from 0.5 doubles μ: 0.5, 1, 2
    assert [e.friction for e in s.evaluations[:3]] == [0.5, 1.0, 2.0]


@pytest.mark.parametrize("target, side", [(50.0, "highest"), (12.0, "lowest")])
def test_a_target_beyond_the_range_is_unreachable_with_the_angles_reached(target, side):
    with pytest.raises(Unreachable) as info:
        search_friction(smooth, target, low=0.05, high=1.5)
    lo, hi = info.value.reached
    # the bound on the target's side was evaluated, and the start 0.5
    if side == "highest":
        assert (lo, hi) == (pytest.approx(smooth(0.5)), pytest.approx(smooth(1.5)))
    else:
        assert (lo, hi) == (pytest.approx(smooth(0.05)), pytest.approx(smooth(0.5)))
    assert side in str(info.value) and f"{target:g}°" in str(info.value)


def test_noisy_angle_still_brackets_and_lands_within_the_noise():
    rng = np.random.default_rng(3)
    noise = 0.4

    def noisy(mu):
        return smooth(mu) + rng.normal(0.0, noise)

    s = search_friction(noisy, 35.0, tolerance=0.5, max_evaluations=10)
    # within what the noise allows: 3 noise sd over the local slope
    assert abs(s.friction - exact_root(35.0)) < 3 * noise / (60.0 * math.exp(-2.0 * exact_root(35.0)))


def test_a_flat_angle_stops_at_the_evaluation_budget_not_converged():
    # a step function: the secant lands on a side every time, the bracket narrows slowly
    def step(mu):
        return 20.0 if mu < 0.7071 else 40.0

    s = search_friction(step, 30.0, tolerance=0.1, friction_tolerance=1e-9, max_evaluations=5)
    assert not s.converged and len(s.evaluations) == 5
    lo, hi = s.bracket
    assert lo.friction < 0.7071 <= hi.friction


@pytest.mark.parametrize("hit, offset", [(0.5, 0.3), (0.5, -0.3), (0.25, 0.3), (0.25, -0.3)],
                         ids=["first-below", "first-above", "second-bracketing", "second-not-bracketing"])
def test_the_first_angle_within_the_tolerance_ends_the_search_while_bracketing_too(hit, offset):
    """The first friction (0.5) or the second (0.25, halved from 0.5 whose angle is above the target) lands 0.3°
    from the target, within the 0.5° tolerance: no further friction is tried. Above the target, the second does not
    bracket it (both angles are above): that friction is then the estimate itself."""
    target = smooth(hit) + offset
    tried = []
    s = search_friction(lambda mu: tried.append(mu) or smooth(mu), target, tolerance=0.5)
    assert tried == ([0.5] if hit == 0.5 else [0.5, 0.25])
    assert s.converged and [e.friction for e in s.evaluations] == tried
    if hit == 0.25 and offset > 0:  # bracketed by 0.25 and 0.5: their interpolation
        assert s.friction == pytest.approx(0.25 + (target - smooth(0.25)) * 0.25 / (smooth(0.5) - smooth(0.25)))
    else:  # one friction within the tolerance, the target not bracketed: that friction, no bracket slope
        assert s.friction == hit and s.bracket == (s.evaluations[-1],) * 2 and math.isnan(s.slope)


def test_a_nan_angle_stops_the_search():
    with pytest.raises(ValueError, match="no angle could be measured at friction 0.5"):
        search_friction(lambda mu: float("nan"), 30.0)


def test_bad_bounds_are_refused():
    with pytest.raises(ValueError, match="low < high"):
        search_friction(smooth, 30.0, low=1.0, high=0.5)


def test_uncertainty_from_the_seed_spread_and_slope():
    # sd 2 over 4 seeds = 1 degree standard error; at 20 degrees per unit mu: 0.05
    assert friction_uncertainty(20.0, 2.0, 4) == pytest.approx(0.05)
    assert pooled_sd([[1.0, 3.0], [5.0]]) == pytest.approx(math.sqrt(2.0))
    assert math.isnan(pooled_sd([[1.0], [2.0]]))


# ---- the command: refusals before any work ----------------------------------------------------------

@pytest.fixture
def grains(three_cri_grains):
    return three_cri_grains


@pytest.mark.parametrize("args, message", [
    (["--target-angle", "85"], "outside 5–80°"),
    (["--target-angle", "2"], "outside 5–80°"),
    (["--target-angle", "nan"], "'nan' is not a finite number"),
    (["--target-angle", "30", "--friction-range", "1", "0.5"], "low < high"),
    (["--target-angle", "30", "--friction", "0.5"], "No such option"),
    (["--target-angle", "30", "--shape", "polyhedron"], "'polyhedron' is not one of"),
    (["--target-angle", "30", "--start", "3"], "--start: 3 is outside --friction-range 0.05 1.5"),
    (["--target-angle", "30", "--start", "nan"], "--start"),
    (["--target-angle", "30", "--friction-range", "0.5", "1", "--start", "0.2"], "outside --friction-range 0.5 1"),
    (["--target-angle", "30", "--spacing", "0.1"], "--spacing is the level set's grid"),
    (["--target-angle", "30", "--max-frictions", "1"], "--max-frictions"),
    (["--target-angle", "30", "--grains", "20000", "--seeds", "100"], "lower"),
])
def test_bad_calibrations_are_refused_in_one_line(grains, tmp_path, args, message):
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "tilt", str(grains), "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert "Traceback" not in r.output
    assert message in r.stderr, r.stderr
    assert lines[-1].startswith("Error") and message in r.stderr
    assert not out.exists()


def test_tilt_options_are_refused_for_a_repose_calibration(grains, tmp_path):
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "repose", str(grains), "--out", str(tmp_path / "c"),
                                 "--target-angle", "30", "--tilt-step", "1"])
    assert r.exit_code == 2 and "calibrate repose takes neither" in r.stderr


def test_the_printed_command_uses_the_calibrated_friction():
    from grainforge.cli.simulate_friction import use_command

    cmd = use_command("tilt", ["x.toml"], friction=0.6321, given={"grains": 50, "seeds": None}, quick=False, as_spheres=False,
                      shape="levelset", spacing=0.1)
    assert cmd == ("grainforge simulate tilt x.toml --friction 0.632 --grains 50 --shape levelset --spacing 0.1 "
                   "--out out/tilt-calibrated")


@pytest.mark.slow
def test_quick_calibration_in_yade(grains, tmp_path):
    """A --quick tilt calibration: up to four frictions of one seed, stopping at the first within the tolerance;
    all outputs, the command that uses μ."""
    require_engine("yade")
    out = tmp_path / "cal"
    # a target inside what quick rough-angular layers reach over μ 0.05–1.5 (else: 'not reached', exit 2); the
    # tilt in 2° steps (finer than the tolerance; each run about half the quick default's 1°), of soft contacts
    # (E = 1e5 Pa: a time step three times longer; the quick calibration at --quick's own settings is the
    # documented command's, tests/project/test_documented_commands.py)
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "tilt", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", "33", "--tolerance", "3", "--max-frictions", "4",
                                 "--start", "0.3", "--tilt-step", "2", "--young", "1e5"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((out / "calibration.csv").read_text().splitlines()))
    assert 1 <= len(rows) <= 4 and {"friction", "seed", "angle_deg"} <= set(rows[0])
    # one seed: each row is a friction's angle; every friction before the last missed the tolerance
    assert all(abs(float(row["angle_deg"]) - 33.0) > 3.0 for row in rows[:-1])
    rec = json.loads((out / "calibration.json").read_text())
    assert 0.05 <= rec["friction"] <= 1.5 and rec["runs"] == len(rows)
    (lo_mu, lo_a), (hi_mu, hi_a) = rec["bracket"]
    assert lo_a <= 33.0 + 3.0 and hi_a >= 33.0 - 3.0
    assert (out / "calibration.png").stat().st_size > 10_000
    assert f"--friction {rec['friction']:.3g}" in r.stdout and "grainforge simulate tilt" in r.stdout
    assert rec["command"] in r.stdout
    assert "friction " in r.stderr  # the per-friction progress lines
    assert not list(out.glob(".grainforge-staging-*"))


def test_the_local_slope_is_a_line_through_the_nearby_evaluations_not_the_bracket_secant():
    from grainforge.simulate.friction_search import Evaluation, local_slope

    # a line of slope 10 with noise on two close points: their secant is 60, the fit stays near 10
    ev = [Evaluation(0.5, 30.0), Evaluation(1.0, 35.0), Evaluation(1.05, 35.0 - 1.0), Evaluation(1.1, 36.0 + 1.0),
          Evaluation(1.5, 40.0)]
    assert (37.0 - 34.0) / 0.05 == pytest.approx(60.0)
    assert local_slope(ev, 1.07) == pytest.approx(10.0, abs=3.0)
    # fewer than three within the window: every evaluation
    assert local_slope([Evaluation(0.1, 20.0), Evaluation(1.5, 34.0)], 0.8) == pytest.approx(10.0)
    assert math.isnan(local_slope([Evaluation(1.0, 20.0)], 1.0))


def test_the_printed_command_keeps_the_engine_and_its_mpi_ranks():
    """A calibration run in LIGGGHTS under MPI prints the command that runs the same engine the same way."""
    import shlex

    from grainforge.cli.simulate_friction import use_command

    words = shlex.split(use_command("tilt", ["g"], friction=0.2, given={"grains": 100}, quick=False, as_spheres=False,
                                    shape="clump", spacing=None, engine="liggghts", mpi=2))
    assert words[words.index("--engine") + 1] == "liggghts"
    assert words[words.index("--mpi") + 1] == "2"
    assert words[words.index("--friction") + 1] == "0.2"
    yade = shlex.split(use_command("tilt", ["g"], friction=0.2, given={}, quick=False, as_spheres=False, shape="clump",
                                   spacing=None))
    assert "--engine" not in yade and "--mpi" not in yade


# ---- the triaxial calibration, on a stand-in engine -------------------------------------------------

#: a stand-in Yade for the triaxial scene: reads the deck's friction and writes the result.json of a drained test
#: whose stress ratio peaks at M_ult + 0.3 early (a quarter of the axial strain) and ends at M_ult = 0.5 + μ
STAND_IN_TRIAXIAL = '''
import json, math, os
scene = json.load(open("grains.json"))["scene"]
mu = math.tan(math.radians(scene["friction_deg"]))
goal, strain = 1e3 * scene["confining_kpa"], scene["axial_strain"]
records = []
for k in range(201):
    e = strain * k / 200
    m = 0.5 + mu + 0.3 * math.exp(-((e - 0.25 * strain) / (0.1 * strain)) ** 2)
    p = goal / (1 - m / 3)
    records += [e, goal, goal, goal + m * p, m * p, p, m, -0.1 * e, 0.6, 4.0, p, 0.001, 0.001]
print("grainforge-progress 1.0 done", flush=True)
json.dump({"test": "triaxial", "grains": scene["grains"], "inserted": scene["grains"], "lost": 0, "d_mean": 0.002,
           "grain_density": 1180.0, "confining": goal, "packing": scene["packing"], "strain_rate": 1.0,
           "inertial_number": scene["inertial_number"], "compacted": os.environ.get("STAND_IN_COMPACTED") != "0",
           "void_ratio_compacted": 0.6, "void_ratio_initial": 0.6,
           "columns": ["axial_strain", "sigma_x", "sigma_y", "sigma_z", "q", "p", "q_over_p", "volumetric_strain",
                       "void_ratio", "coordination", "p_love_weber", "unbalanced", "overlap_over_d"],
           "records": records, "steps": 1000, "time": 0.1, "dt": 1e-4}, open("result.json", "w"))
'''


def _friction_angle(m):
    return math.degrees(math.asin(3 * m / (6 + m)))


@pytest.fixture
def stand_in_yade(tmp_path, monkeypatch):
    import sys

    fake = tmp_path / "stand-in-yade"
    fake.write_text(f"#!{sys.executable}\n" + STAND_IN_TRIAXIAL)
    fake.chmod(0o755)
    monkeypatch.setenv("GRAINFORGE_YADE", str(fake))
    return fake


@pytest.mark.parametrize("angle, column, extra", [
    ("ultimate", "ultimate_friction_deg", []),
    ("ultimate", "ultimate_friction_deg", ["--angle", "ultimate"]),
    ("peak", "peak_friction_deg", ["--angle", "peak"]),
])
def test_a_triaxial_calibration_reaches_the_ultimate_friction_angle(grains, tmp_path, stand_in_yade, angle, column,
                                                                    extra):
    """On a stand-in engine whose ultimate stress ratio is 0.5 + μ (peak 0.3 higher), a 30° target: μ = 0.7 on the
    ultimate angle (the default), about 0.4 on the peak one; every run's angle in calibration.csv is that column
    of its row, which is the angle of the curve its result.json holds."""
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "triaxial", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", "30", "--tolerance", "0.05", *extra])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((out / "calibration.csv").read_text().splitlines()))
    assert {"friction", "angle_deg", "peak_friction_deg", "ultimate_friction_deg", "problems"} <= set(rows[0])
    for row in rows:
        mu = float(row["friction"])
        assert float(row["ultimate_friction_deg"]) == pytest.approx(_friction_angle(0.5 + mu), abs=1e-9)
        assert float(row["angle_deg"]) == float(row[column])
        curve = out / "runs" / f"e{row['evaluation']}-mu{mu:.4f}" / f"triaxial-seed{row['seed']}" / "triaxial.csv"
        assert len(curve.read_text().splitlines()) == 202  # the header and the 201 records
    rec = json.loads((out / "calibration.json").read_text())
    assert rec["test"] == "triaxial" and rec["angle"] == f"{angle} friction angle" and rec["angle_column"] == column
    assert rec["converged"] and rec["failed_runs"] == []
    if angle == "ultimate":  # 30° is M = 1.2
        assert rec["friction"] == pytest.approx(0.7, abs=0.005)
    else:  # the peak is 0.3 higher, a little less after the moving mean
        assert 0.38 < rec["friction"] < 0.43
    assert rec["settings"]["packing"] == "dense" and rec["settings"]["young"] == 1e8
    assert f"reaches 30° ({angle} friction angle) on the triaxial test" in r.stdout
    assert rec["command"] in r.stdout and rec["command"].startswith("grainforge simulate triaxial ")
    assert f"--friction {rec['friction']:.3g}" in rec["command"] and "--quick" in rec["command"]
    assert (out / "calibration.png").stat().st_size > 10_000


@pytest.mark.parametrize("frictions, target", [
    ([0.5], _friction_angle(1.0) + 0.3),           # the start within the tolerance
    ([0.5, 0.25], _friction_angle(0.75) - 0.3),    # halved to 0.25, within the tolerance, above: not bracketed
])
def test_a_calibration_stops_at_the_first_friction_within_the_tolerance(grains, tmp_path, stand_in_yade, frictions,
                                                                        target):
    """On the stand-in engine (ultimate stress ratio 0.5 + μ): a friction whose angle is within the 0.5° tolerance
    ends the calibration, bracketed or not; no further friction is run, and that friction is the estimate."""
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "triaxial", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", f"{target:.4f}"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((out / "calibration.csv").read_text().splitlines()))
    assert [float(row["friction"]) for row in rows] == frictions
    assert sorted(p.name for p in (out / "runs").iterdir()) == [f"e{k}-mu{mu:.4f}" for k, mu in enumerate(frictions)]
    rec = json.loads((out / "calibration.json").read_text())
    assert rec["converged"] and rec["evaluations"] == rec["runs"] == len(frictions)
    assert rec["friction"] == frictions[-1]
    assert abs(float(rows[-1]["angle_deg"]) - target) <= 0.5
    assert f"friction {frictions[-1]:.3f}" in r.stdout and f"({len(frictions)} runs)" in r.stdout
    if len(frictions) == 1:
        assert "one friction tried: no slope, no uncertainty" in r.stdout


def test_a_triaxial_calibration_out_of_reach_ends_as_a_tilt_one_does(grains, tmp_path, stand_in_yade):
    """Ultimate angles up to asin(6/8) = 48.6° at μ = 1.5: a 60° target is not reached; one line, exit 2, nothing
    kept."""
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "triaxial", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", "60"])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[-1] == (f"Error: target angle 60° is not reached for friction in [0.05, 1.5]: the angles measured "
                         f"span {_friction_angle(1.0):.1f}–{_friction_angle(2.0):.1f}° (the highest at friction 1.5); "
                         "3 run(s) made, nothing kept")
    assert not out.exists() or not list(out.iterdir())


def test_triaxial_runs_that_fail_their_check_are_named_after_the_outputs(grains, tmp_path, stand_in_yade,
                                                                         monkeypatch):
    """A compaction that did not come to rest (the stand-in says so): the calibration's outputs are written, every
    run is named on one line, exit 3."""
    monkeypatch.setenv("STAND_IN_COMPACTED", "0")
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "triaxial", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", "30", "--max-frictions", "2"])
    assert r.exit_code == 3, r.output
    rec = json.loads((out / "calibration.json").read_text())
    assert len(rec["failed_runs"]) == rec["runs"] == 2
    assert r.stderr.strip().splitlines()[-1] == (
        "check failed: friction 0.5, seed 0: the specimen was not at rest at the confining stress when the shearing "
        "started; friction 1, seed 0: the specimen was not at rest at the confining stress when the shearing started "
        "(calibration.csv has every run)")


@pytest.mark.slow
def test_quick_triaxial_calibration_in_yade_reads_the_ultimate_angles_simulate_triaxial_writes(grains, tmp_path):
    """Two --quick triaxial runs (μ 0.25 and 0.5) by `simulate triaxial`, then a calibration of two frictions
    between them aiming at the mean of their ultimate angles: it runs the same decks (Yade repeats a run), so
    each friction's angle is results.csv's ultimate_friction_deg, and μ is the interpolation between them."""
    require_long_lane("four triaxial runs in Yade (4-10 min); the stand-in engine tests (-k triaxial) check the "
                      "same wiring in the suite")
    require_engine("yade")
    ultimate = {}
    for mu in (0.25, 0.5):
        out = tmp_path / f"mu{mu}"
        r = CliRunner().invoke(cli, ["simulate", "triaxial", str(grains), "--out", str(out), "--quick",
                                     "--friction", str(mu)])
        assert r.exit_code == 0, r.output
        (row,) = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
        ultimate[mu] = float(row["ultimate_friction_deg"])
    assert ultimate[0.25] < ultimate[0.5], ultimate  # else the mean is not bracketed from 0.25 upwards
    target = round(0.5 * (ultimate[0.25] + ultimate[0.5]), 2)
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", "triaxial", str(grains), "--out", str(out), "--quick",
                                 "--target-angle", str(target), "--friction-range", "0.25", "0.5", "--start", "0.25",
                                 "--max-frictions", "2"])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((out / "calibration.csv").read_text().splitlines()))
    assert [float(row["friction"]) for row in rows] == [0.25, 0.5]
    for row in rows:
        assert float(row["angle_deg"]) == float(row["ultimate_friction_deg"]) == ultimate[float(row["friction"])]
    rec = json.loads((out / "calibration.json").read_text())
    lo, hi = ultimate[0.25], ultimate[0.5]
    assert rec["friction"] == pytest.approx(0.25 + (target - lo) * 0.25 / (hi - lo), abs=1e-9)
    assert rec["command"] in r.stdout and "grainforge simulate triaxial" in rec["command"]
    assert not list(out.glob(".grainforge-*"))
