"""Resolution matching says when it removes the shape, and when a budget beats the tolerance."""

from __future__ import annotations

import csv

import pytest

from grainforge.cli.main import cli


def _manifest(folder):
    with open(folder / "manifest.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_tiny_grain_on_a_coarse_printer_warns_and_records_it(runner, tmp_path):
    out = tmp_path / "tiny"
    res = runner.invoke(cli, ["generate", "fso", "--size", "0.5", "--printer", "generic-fdm", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "WARNING: resolution matching keeps only 12 surface points (level 0, 20 faces" in res.stderr
    assert "surface detail finer than" in res.stderr and "is removed" in res.stderr
    row = _manifest(out)[0]
    assert int(row["subdivisions"]) == 0
    assert "12 surface points" in row["resolution_warning"]
    assert float(row["retained_wavelength_mm"]) == pytest.approx(2 * float(row["mean_edge_mm"]))


def test_no_warning_when_the_shape_is_kept(runner, tmp_path):
    out = tmp_path / "big"
    res = runner.invoke(cli, ["generate", "fso", "--size", "20", "--printer", "generic-fdm", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "WARNING" not in res.stderr
    row = _manifest(out)[0]
    assert row["resolution_warning"] == "" and int(row["subdivisions"]) >= 3


def test_tray_budget_below_tolerance_is_said_prominently_and_previews_have_their_folder(runner, tmp_path):
    out = tmp_path / "plates" / "t.3mf"
    res = runner.invoke(cli, ["tray", "--method", "fso", "--count", "4", "--size", "2", "--max-triangles", "400",
                              "--max-subdivisions", "4", "--printer", "objet-eden-250", "--workers", "1",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    warnings = [ln for ln in lines if ln.startswith("WARNING:")]
    assert warnings and lines[-len(warnings):] == warnings          # last, where they are seen
    assert ("triangle budget (--max-triangles 400 a print file, --plates 1, for 4 grains: 100 faces per grain) "
            "caps the mesh at level 1 (80 faces)") in warnings[0]
    assert "exceeds the printer tolerance 16.0 µm" in warnings[0]
    # FSO is fractal: the finest level allowed is the best the tolerance gets, and one grain of it needs a larger budget
    assert "level 4 (5120 faces a grain" in warnings[0] and "is the finest allowed (--max-subdivisions 4)" \
        in warnings[0] and "--max-triangles 5120 or more and --plates auto" in warnings[0]
    assert f"previews {tmp_path / 'plates' / 't-plate1.png'}" in res.stderr
