"""Calibration of the DPA exponent ε against D_A."""

import csv

import numpy as np
import pytest

from grainforge.methods.dpa import calibration as C
from grainforge.params import ParameterError


def _synthetic(eps, d_mean):
    eps = np.asarray(eps, dtype=float)
    z = np.zeros_like(eps)
    return C.Calibration(
        primitive="cube", primaries=100, repeats=3, seed=0, exponent=eps, D_A_mean=np.asarray(d_mean, float),
        D_A_std=z + 0.01, porosity_mean=z + 0.5, porosity_std=z, R_g_mean=z + 3, R_g_std=z,
    )


def test_parse_exponents():
    assert C.parse_exponents("1:3:1").tolist() == [1.0, 2.0, 3.0]
    assert C.parse_exponents("0.1:0.35:0.1").tolist() == [0.1, 0.2, 0.3]
    assert C.parse_exponents("5").tolist() == [5.0]
    for bad in ["0:1:0.5", "1:2", "a:b:c", "1:2:0", "", "-1,2"]:
        with pytest.raises(ParameterError, match="exponents"):
            C.parse_exponents(bad)


def test_inverse_of_a_known_curve():
    eps = np.geomspace(0.1, 100, 7)
    cal = _synthetic(eps, 2.5 - 0.1 * np.log(eps))
    for target in (2.2, 2.4, 2.5 - 0.1 * np.log(3.0)):
        e = cal.exponent_for(target)
        assert 2.5 - 0.1 * np.log(e) == pytest.approx(target, abs=1e-12)  # linear in log ε: exact
    with pytest.raises(ParameterError, match=r"target_fractal_dimension must be within the calibrated range"):
        cal.exponent_for(2.9)
    with pytest.raises(ParameterError, match="target_fractal_dimension"):
        cal.exponent_for(1.5)


def test_inverse_ignores_the_low_exponent_dip_and_noise():
    eps = [0.05, 0.1, 0.5, 1, 5, 10]
    cal = _synthetic(eps, [2.40, 2.47, 2.45, 2.46, 2.3, 2.2])
    e, m = cal.usable()
    assert e.tolist() == [0.1, 0.5, 1, 5, 10]
    assert np.all(np.diff(m) <= 0)
    assert 1 < cal.exponent_for(2.35) < 5


def test_csv_round_trip(tmp_path):
    cal = _synthetic([0.5, 1.0, 2.0], [2.4, 2.35, 2.3])
    path = cal.write_csv(tmp_path / "c.csv")
    back = C.Calibration.read_csv(path)
    for name in ("exponent", "D_A_mean", "D_A_std", "porosity_mean", "R_g_std"):
        assert np.array_equal(getattr(back, name), getattr(cal, name))
    assert (back.primitive, back.primaries, back.repeats, back.seed) == ("cube", 100, 3, 0)


def test_calibration_is_independent_of_worker_count():
    one = C.calibrate("cube", 30, exponents=[0.5, 8.0], repeats=3, rng=5, workers=1)
    two = C.calibrate("cube", 30, exponents=[0.5, 8.0], repeats=3, rng=5, workers=2)
    for name in ("D_A_mean", "D_A_std", "porosity_mean", "porosity_std", "R_g_mean"):
        assert np.array_equal(getattr(one, name), getattr(two, name))
    assert np.all(one.D_A_std > 0)  # the seeds differ


def test_calibrate_validates():
    with pytest.raises(ParameterError, match="exponent"):
        C.calibrate("cube", 20, exponents=[0.0, 1.0], repeats=2)
    with pytest.raises(ParameterError, match="primitive"):
        C.calibrate("sphere", 20, exponents=[1.0], repeats=2)
    with pytest.raises(ParameterError, match="repeats"):
        C.calibrate("cube", 20, exponents=[1.0], repeats=0)


def test_cache_location_and_reuse(tmp_path, monkeypatch):
    monkeypatch.setenv("GRAINFORGE_CACHE", str(tmp_path / "cache"))
    assert C.cache_dir() == tmp_path / "cache"
    grid = (0.5, 10.0)
    first = C.cached_calibration("cube", 25, exponents=grid, repeats=2, workers=1)
    files = list((tmp_path / "cache" / "calibration").glob("dpa-cube-N25-*.csv"))
    assert len(files) == 1

    def boom(*a, **k):
        raise AssertionError("the cached curve should have been read")

    monkeypatch.setattr(C, "calibrate", boom)
    again = C.cached_calibration("cube", 25, exponents=grid, repeats=2, workers=1)
    assert np.array_equal(again.D_A_mean, first.D_A_mean)
    monkeypatch.delenv("GRAINFORGE_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert C.cache_dir() == tmp_path / "xdg" / "grainforge"


def test_cli_calibrate_writes_csv_and_png(runner, tmp_path, monkeypatch):
    from grainforge.cli.main import cli

    out = tmp_path / "cal"
    args = ["calibrate", "dpa", "--primitive", "cube", "--primaries", "25", "--exponents", "0.5:4.5:2",
            "--repeats", "3", "--workers", "1", "--out", str(out)]
    res = runner.invoke(cli, args)
    assert res.exit_code == 0, res.output
    with open(out / "calibration.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["exponent"]) for r in rows] == [0.5, 2.5, 4.5]
    assert all(float(r["D_A_std"]) >= 0 and 1 < float(r["D_A_mean"]) < 3 for r in rows)
    assert (out / "calibration.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(cli, args)
    assert res.exit_code == 2 and "--overwrite" in res.output
    res = runner.invoke(cli, args[:-2] + ["--out", str(tmp_path / "x"), "--exponents", "4:1:1"])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists()

    # an interrupt while the figure is drawn (the last output): neither output appears, nor the folder the run
    # made; an earlier calibration's outputs in a folder given with --overwrite stay as they were
    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(C.Calibration, "plot", interrupted)
    fresh = tmp_path / "fresh"
    res = runner.invoke(cli, args[:-2] + ["--out", str(fresh)])
    assert res.exit_code != 0 and not fresh.exists(), res.output
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    res = runner.invoke(cli, args + ["--overwrite"])
    assert res.exit_code != 0 and {p.name: p.read_bytes() for p in out.iterdir()} == before, res.output


def test_generate_with_target_fractal_dimension_records_both(runner, tmp_path, monkeypatch):
    from grainforge.cli.main import cli

    monkeypatch.setenv("GRAINFORGE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(C, "DEFAULT_REPEATS", 3)
    monkeypatch.setattr(C, "DEFAULT_EXPONENTS", (0.3, 1.0, 3.0, 10.0, 30.0))
    cal = C.cached_calibration("cube", 30)
    e, m = cal.usable()
    target = float((m.max() + m.min()) / 2)
    out = tmp_path / "run"
    res = runner.invoke(cli, ["generate", "dpa", "--out", str(out), "--primaries", "30",
                              "--target-fractal-dimension", f"{target:.6f}"])
    assert res.exit_code == 0, res.output
    with open(out / "manifest.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    assert float(row["target_fractal_dimension"]) == pytest.approx(target, abs=1e-6)
    assert float(row["exponent"]) == pytest.approx(cal.exponent_for(float(f"{target:.6f}")), rel=1e-12)
    res = runner.invoke(cli, ["generate", "dpa", "--out", str(tmp_path / "r2"), "--primaries", "30",
                              "--target-fractal-dimension", "2.99"])
    assert res.exit_code == 2 and "calibrated range" in res.output


def test_old_calibration_files_without_scaling_columns_still_read(tmp_path):
    from grainforge.methods.dpa.calibration import COLUMNS, Calibration, calibrate

    c = calibrate("cube", 40, exponents=[0.5, 20.0], repeats=2, rng=3)
    assert np.all(np.isfinite(c.D_A_scaling_mean)) and np.all(c.D_A_scaling_std >= 0)
    path = c.write_csv(tmp_path / "new.csv")
    again = Calibration.read_csv(path)
    assert np.array_equal(again.D_A_scaling_mean, c.D_A_scaling_mean)
    # a file written before the scaling columns existed (and before headers stated units: R_g_mean)
    from grainforge.methods.dpa.calibration import UNITS
    from grainforge.units import with_unit

    old = [col for col in COLUMNS if not col.startswith("D_A_scaling")]
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    assert "R_g_mean_primary_sizes" in header and "R_g_mean" not in header
    keep = [header.index(with_unit(col, UNITS)) for col in old]
    body = [",".join(row.split(",")[i] for i in keep) for row in lines[1:]]
    (tmp_path / "old.csv").write_text("\n".join([",".join(old)] + body) + "\n")
    legacy = Calibration.read_csv(tmp_path / "old.csv")
    assert np.all(np.isnan(legacy.D_A_scaling_mean))
    assert np.array_equal(legacy.D_A_mean, c.D_A_mean) and np.array_equal(legacy.R_g_mean, c.R_g_mean)
    legacy.plot(tmp_path / "old.png")  # the plot copes without them
