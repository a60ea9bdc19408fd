"""`grainforge simulate triaxial`: the angles measured from a triaxial curve (pure NumPy, known answers), the
refusals before any engine starts, an interrupt that leaves nothing, and quick dense and loose runs in Yade
checked against the physics of a drained triaxial test.

Without Yade the engine test is skipped with the reason; with GRAINFORGE_REQUIRE_ENGINES=1 a missing Yade is a
failure (``require_engine``).
"""

import csv
import json
import math

import numpy as np
import pytest
from conftest import require_engine

from grainforge.cli.main import cli
from grainforge.simulate import QUICK_TRIAXIAL, TriaxialSettings
from grainforge.simulate.settings import MIN_TRIAXIAL_GRAINS, check_size, triaxial_steps
from grainforge.simulate.triaxial import (
    CRITICAL_DILATANCY_RATE,
    CSV_COLUMNS,
    critical_state,
    dilatancy_angle,
    friction_angle,
    local_slope,
    triaxial_angles,
    triaxial_scene_settings,
)


def _m_of(phi_deg):
    """M = q/p' of a friction angle in triaxial compression (the inverse of sin φ = 3M/(6 + M))."""
    s = np.sin(np.radians(phi_deg))
    return 6.0 * s / (3.0 - s)


# ---- the post-processing, on synthetic curves with known answers ----------------------------------------


@pytest.mark.parametrize("phi", [0.0, 15.0, 30.0, 38.0, 48.0])
def test_friction_angle_inverts_the_triaxial_compression_stress_ratio(phi):
    assert float(friction_angle(_m_of(phi))) == pytest.approx(phi, abs=1e-9)


@pytest.mark.parametrize("psi", [-10.0, 0.0, 5.0, 19.47])
def test_dilatancy_angle_inverts_its_rate(psi):
    # sin ψ = -d/(2 - d)  <=>  d = -2 sin ψ / (1 - sin ψ); dilation (ε_v falling) gives ψ > 0
    s = np.sin(np.radians(psi))
    assert float(dilatancy_angle(-2.0 * s / (1.0 - s))) == pytest.approx(psi, abs=1e-9)


def test_local_slope_is_exact_on_a_line_and_shortens_its_window_at_the_ends():
    x = np.linspace(0.0, 0.3, 31)
    assert np.allclose(local_slope(x, 2.0 - 0.7 * x, 7), -0.7)


def _synthetic(n=301, end=0.25):
    """A dense specimen's curve with known angles: M rises to a peak of 42° at 4 % axial strain, falls to 31°
    (constant past 20 %); dε_v/dε₁ goes from +0.5 (contraction) to -1 at 5 % (ψ = asin(1/3) = 19.47°) and back
    to 0."""
    e = np.linspace(0.0, end, n)
    mp, mu, ep, tau = _m_of(42.0), _m_of(31.0), 0.04, 0.04
    m = np.where(e <= ep, mp * (e / ep) * (2.0 - e / ep), mu + (mp - mu) * np.exp(-((e - ep) / tau) ** 2))
    fine = np.linspace(0.0, end, 200001)
    # +0.5 at the start, -1 at 5 % (smoothly: a minimum), 0 at the end
    rate = np.where(fine <= 0.05, 0.5 - 1.5 * np.sin(0.5 * np.pi * fine / 0.05) ** 2,
                    -np.exp(-((fine - 0.05) / 0.03) ** 2))
    ev = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(fine))])
    return e, m, np.interp(e, fine, ev)


def test_triaxial_angles_of_a_synthetic_dense_curve():
    e, m, ev = _synthetic()
    a = triaxial_angles(e, m, ev)
    assert a.peak_friction_deg == pytest.approx(42.0, abs=0.05)
    assert a.peak_strain == pytest.approx(0.04, abs=0.002)
    assert a.ultimate_friction_deg == pytest.approx(31.0, abs=1e-6)
    # the slope over 1 % of strain averages the curve's sharp minimum of dε_v/dε₁ a little: 0.1° low here
    assert a.max_dilatancy_deg == pytest.approx(math.degrees(math.asin(1.0 / 3.0)), abs=0.15)
    assert a.max_dilatancy_strain == pytest.approx(0.05, abs=0.002)


def test_the_peak_is_not_one_noisy_record_and_the_ultimate_state_is_the_last_5_percent_of_strain():
    e, m, ev = _synthetic()
    spiky = m.copy()
    spiky[150] += 1.0  # one record far above the curve (at 12.5 %): the 5-point mean holds it to +0.2
    a = triaxial_angles(e, spiky, ev)
    assert a.peak_friction_deg == pytest.approx(42.0, abs=0.05)
    # the last 5 % of the strain range (ε₁ ≥ 0.2375) at M = 1.0, the rest as before: the ultimate angle is 1.0's
    tail = m.copy()
    tail[e >= 0.95 * e[-1]] = 1.0
    assert triaxial_angles(e, tail, ev).ultimate_friction_deg == pytest.approx(float(friction_angle(1.0)), abs=1e-9)


def test_the_synthetic_dense_curve_ends_at_a_critical_state_and_a_cut_one_does_not():
    """The synthetic curve's volume and stress ratio are steady past 20 % (ψ → 0, M = 31°'s): a critical state
    at 25 %; cut at 8 % (still dilating, M still falling) it is not; e_cs is the void ratio over the last 5 %."""
    e, m, ev = _synthetic()
    void = 0.6 + (1.0 + 0.6) * (-ev)  # e = e₀ + (1 + e₀)(−ε_v) for small strains: dilation raises it
    cs = critical_state(e, m, ev, void)
    assert cs["critical_state"] and abs(cs["final_dilatancy_rate"]) < 0.01
    assert cs["critical_void_ratio"] == pytest.approx(void[e >= 0.95 * e[-1]].mean(), rel=1e-12)
    short = e <= 0.08
    cut = critical_state(e[short], m[short], ev[short], void[short])
    assert not cut["critical_state"] and cut["final_dilatancy_rate"] < -CRITICAL_DILATANCY_RATE
    # a steady volume under a stress ratio still rising 20 % across the window is not a critical state either
    rising = m * (1.0 + np.clip((e - 0.2) / 0.05, 0.0, 1.0) * 0.2)
    assert not critical_state(e, rising, ev, void)["critical_state"]
    assert math.isnan(critical_state([0.0, 0.1], [1.0, 1.0], [0.0, 0.0], [0.6, 0.6])["critical_void_ratio"])
    with pytest.raises(ValueError, match="window"):
        critical_state(e, m, ev, void, window=0.0)


def test_triaxial_angles_of_a_curve_too_short_are_nan():
    a = triaxial_angles([0.0, 0.01], [0.0, 0.5], [0.0, 0.0])
    assert all(math.isnan(v) for v in a.values())
    with pytest.raises(ValueError, match="one length"):
        triaxial_angles([0.0, 0.1, 0.2], [0.0, 0.1], [0.0, 0.0, 0.0])


def test_the_scene_settings_and_the_estimate():
    s = triaxial_scene_settings(TriaxialSettings(grains=120, confining_kpa=50.0, packing="loose"), 7)
    assert s["gravity"] == 0.0 and s["confining_kpa"] == 50.0 and s["packing"] == "loose" and s["seed"] == 7
    assert len(s["orientations"]) == 120
    # the shearing's steps grow as 1/I and as the axial strain; the estimate with them
    base = TriaxialSettings()
    slower = TriaxialSettings(inertial_number=base.inertial_number / 2)
    assert triaxial_steps(slower) > 1.5 * triaxial_steps(base)
    assert check_size("triaxial", TriaxialSettings(grains=1000), available=3) > check_size(
        "triaxial", base, available=3)


# ---- refusals: one line, exit 2, before any engine starts or anything is written --------------------------


@pytest.fixture(scope="module")
def spheres(tmp_path_factory):
    """Three rough-sphere CRI grains of 2 mm (the paper's rough spheres, coarse meshes)."""
    from click.testing import CliRunner

    out = tmp_path_factory.mktemp("triaxial") / "grains"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-sphere"])
    assert r.exit_code == 0, r.output
    return out


REFUSED = [
    (["--confining-kpa", "0"], "--confining-kpa"),
    (["--confining-kpa", "-20"], "--confining-kpa"),
    (["--confining-kpa", "20000"], "--confining-kpa"),
    (["--axial-strain", "0"], "--axial-strain"),
    (["--axial-strain", "1"], "--axial-strain"),
    (["--axial-strain", "-0.1"], "--axial-strain"),
    (["--grains", str(MIN_TRIAXIAL_GRAINS - 1)], f"needs --grains ≥ {MIN_TRIAXIAL_GRAINS}"),
    (["--grains", "30", "--quick"], "needs --grains ≥"),
    (["--packing", "medium"], "'medium' is not one of 'dense', 'loose'"),
    (["--inertial-number", "0.5"], "--inertial-number"),
    (["--shape", "levelset"], "--shape levelset: simulate triaxial's yade scene takes --shape clump only (Yade's "
     "level-set contact gains energy"),
    (["--engine", "liggghts", "--shape", "levelset"],
     "--shape levelset: simulate triaxial's liggghts scene takes --shape clump only"),
    (["--engine", "liggghts", "--grains", "60"], "--grains 60: a triaxial box of walls needs --grains ≥ 79"),
    # 64 ranks: refused for the cores first (the specimen's slabs, with an allocation that has them, are the
    # contract test's mpi_refusal cases, which also run every suggestion)
    (["--engine", "liggghts", "--mpi", "64"], "--mpi 64: only"),
    (["--mpi", "2"], "--mpi"),
]


@pytest.mark.parametrize("args, message", REFUSED, ids=[" ".join(a) for a, _ in REFUSED])
def test_bad_triaxial_settings_are_refused_in_one_line(runner, spheres, tmp_path, monkeypatch, args, message):
    for engine in ("YADE", "LIGGGHTS", "MPIRUN"):  # named only if reached
        monkeypatch.setenv(f"GRAINFORGE_{engine}", str(tmp_path / "no-engine-is-started"))
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "triaxial", str(spheres), "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.output, r.stderr
    assert message in r.stderr
    assert not out.exists()


def test_an_interrupted_triaxial_run_leaves_no_engine_and_no_folder(spheres, tmp_path):
    """SIGINT while the (stand-in) engine runs: exit 130, the engine and its child gone, --out never made."""
    from _processes import interrupt_simulate_run

    interrupt_simulate_run(["triaxial", str(spheres)], tmp_path)


# ---- quick runs in Yade ----------------------------------------------------------------------------------


def _rows(path):
    return list(csv.DictReader(path.read_text().splitlines()))


@pytest.mark.slow
def test_quick_dense_and_loose_triaxial_in_yade(runner, spheres, tmp_path):
    """100 rough spheres (6-sphere clumps) compacted to 20 kPa, sheared to 6 % at I = 0.01: the physics of a
    drained test holds, dense and loose differ as they should, the outputs have their columns."""
    require_engine("yade")
    from test_simulate import check_placed_as_the_deck_says

    found = {}
    for packing in ("dense", "loose"):
        out = tmp_path / packing
        r = runner.invoke(cli, ["simulate", "triaxial", str(spheres), "--out", str(out), "--quick",
                                "--packing", packing])
        assert r.exit_code == 0, r.output
        assert f"{packing}, e0 " in r.stdout and "peak friction angle" in r.stdout
        (row,) = _rows(out / "results.csv")
        for column in ("seed", "packing", "initial_void_ratio", "peak_friction_deg", "ultimate_friction_deg",
                       "max_dilatancy_deg", "inertial_number", "setting_confining_kpa", "setting_axial_strain",
                       "setting_packing", "setting_inertial_number", "setting_friction", "setting_young"):
            assert column in row, column
        assert row["packing"] == packing and row["problems"] == ""
        assert float(row["inertial_number"]) == pytest.approx(QUICK_TRIAXIAL["inertial_number"], rel=1e-9)
        assert float(row["axial_strain_reached"]) >= QUICK_TRIAXIAL["axial_strain"]
        run = out / "triaxial-seed0"
        table = _rows(run / "triaxial.csv")
        assert tuple(table[0]) == CSV_COLUMNS
        curve = np.array([[float(t[c]) for c in CSV_COLUMNS] for t in table])
        eps, q, p, ratio, ev, void, z = curve.T
        # isotropic at the start: q/p' near 0 at p' = the confining stress, then the stress ratio rises
        assert eps[0] == 0.0 and abs(ratio[0]) < 0.05 and p[0] == pytest.approx(20.0, rel=0.02)
        assert ratio.max() > 0.6 and np.median(ratio[eps > 0.5 * eps[-1]]) > 0.5
        assert np.allclose(ratio, q / p, rtol=1e-9)
        assert void[0] == pytest.approx(float(row["initial_void_ratio"]), rel=1e-6) and 0.3 < void[0] < 1.5
        assert z[0] > 3.0
        result = json.loads((run / "result.json").read_text())
        rec = np.array(result["records"])
        col = {name: rec[:, k] for k, name in enumerate(result["columns"])}
        # the lateral stress held at the confining stress while the specimen was sheared
        lateral = 0.5 * (col["sigma_x"] + col["sigma_y"]) / result["confining"] - 1.0
        shearing = col["axial_strain"] > 0.01 * eps[-1]
        # (not the mean: at I = 5e-3 a few records of the dense specimen's jam-and-release bursts, up to tens of
        # σ′₃, move it by 25 % while three records in four stay within a few per cent)
        held = np.abs(lateral[shearing])
        assert np.median(held) < 0.05 and np.percentile(held, 75) < 0.1, np.percentile(held, [50, 75, 90, 100])
        # Yade's getStress (the stress reported) and a Love-Weber sum over the grains' centres of mass agree
        assert np.allclose(col["p_love_weber"], col["p"], rtol=1e-6)
        # the void ratio follows the volumetric strain: (1 + e) = (1 + e0)(1 - ε_v)
        assert np.allclose(1.0 + void, (1.0 + void[0]) * (1.0 - ev), rtol=1e-9)
        # against the clumps' volume, from the deck's own coverage and spill of each grain drawn
        deck = json.loads((run / "grains.json").read_text())
        by_name = {g["name"]: g for g in deck["grains"]}
        drawn = [by_name[name] for name in result["placed"]["drawn"]]
        clumps = sum(g["volume"] * g["coverage"] / (1.0 - g["spill"]) for g in drawn)
        assert result["solid_volume_clumps"] == pytest.approx(clumps, rel=1e-9)
        e_c = (1.0 + void[0]) * result["solid_volume"] / result["solid_volume_clumps"] - 1.0
        assert float(row["initial_void_ratio_clumps"]) == pytest.approx(e_c, rel=1e-6)
        assert 0.0 < float(row["initial_void_ratio_clumps"]) != pytest.approx(void[0], rel=1e-3)
        assert float(row["state_parameter"]) == pytest.approx(void[0] - float(row["critical_void_ratio"]), abs=1e-9)
        assert row["critical_state"] in ("True", "False")
        check_placed_as_the_deck_says(run)
        assert (out / "triaxial.png").stat().st_size > 10_000
        found[packing] = (float(row["initial_void_ratio"]), ev)
    # compacted with friction, the loose specimen is looser, and contracts more than the dense one
    assert found["loose"][0] > found["dense"][0] + 0.02
    assert found["loose"][1][-1] > found["dense"][1][-1]


def test_a_noisy_volume_curve_makes_no_extreme_dilatancy_angle():
    """Frictionless spheres hardly change volume; records 0.05 % of strain apart with noise of 1e-4 in ε_v gave
    slopes of −5 and more over 5 records (ψ near 90°). Over 1 % of strain the slope is the curve's."""
    rng = np.random.default_rng(0)
    e = np.linspace(0.0, 0.1, 201)
    ev = -0.02 * e + rng.normal(0.0, 1e-4, e.size)  # a slight dilation, d = −0.02: ψ ≈ 0.6°
    a = triaxial_angles(e, np.full_like(e, 0.5), ev)
    assert 0.0 < a.max_dilatancy_deg < 5.0, a
    narrow = triaxial_angles(e, np.full_like(e, 0.5), ev, slope_strain=0.0)  # the old 5-record slope
    assert narrow.max_dilatancy_deg > 3 * a.max_dilatancy_deg


def test_a_collapsing_specimen_has_no_positive_dilatancy_angle():
    """A loose specimen collapsing at dε_v/dε₁ ≈ 2.5 made −d/(2 − d) = +5: clipped to +90°, a dilation."""
    e = np.linspace(0.0, 0.1, 101)
    ev = np.where(e < 0.03, 2.5 * e, 0.075 + 0.1 * (e - 0.03))  # collapse, then slow compression
    a = triaxial_angles(e, np.full_like(e, 0.8), ev)
    assert a.max_dilatancy_deg < 0.0, a


def test_the_level_set_refusal_still_has_its_reason():
    """``simulate triaxial`` refuses level sets because Yade's level-set contact gains energy in a frictionless,
    undamped collision (a grain pair parts with many times its kinetic energy), while two plain spheres keep it:
    measured by benchmarks/levelset_energy.py. Should a Yade fix this, the test fails: lift the refusal."""
    import subprocess
    import sys
    from pathlib import Path

    require_engine("yade")
    script = Path(__file__).resolve().parents[2] / "benchmarks" / "levelset_energy.py"
    proc = subprocess.run([sys.executable, str(script), "--cases", "plain-sphere,grain"], capture_output=True,
                          text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ratio = {line.split("|")[1].strip(): float(line.split("|")[2]) for line in proc.stdout.splitlines()
             if line.startswith("| ") and line.split("|")[2].strip()[0].isdigit()}
    assert ratio["plain-sphere"] == pytest.approx(1.0, abs=0.01)  # an elastic collision keeps its energy
    assert ratio["grain"] > 2.0, ratio
