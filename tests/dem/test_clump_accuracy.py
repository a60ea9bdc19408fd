"""Clumps built to an accuracy target: the fewest greedy spheres whose intersection over union with the grain
(``clump_accuracy``) reaches the target, up to a cap; the figures in grains.json and clumps.csv; the options."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from conftest import require_engine

import grainforge
from grainforge.cli.main import cli
from grainforge.dem.clump import clump, clump_accuracy
from grainforge.dem.inputs import read_grain
from grainforge.dem.massprops import mass_properties

#: the deck's measuring grid (grainforge.dem.template.CLUMP_MEASURE_RESOLUTION)
DECK_RESOLUTION = 60


@pytest.fixture(scope="module")
def ball():
    s = trimesh.creation.icosphere(4)
    return np.asarray(s.vertices), np.asarray(s.faces)


@pytest.fixture(scope="module")
def rough():
    g = grainforge.cri(rng=1)
    return g.vertices, g.faces


def test_a_ball_needs_one_sphere_at_a_modest_target(ball):
    v, f = ball
    c = clump(v, f, spheres=30, target_iou=0.85, measure_resolution=40)
    assert c.count == 1 and c.meets_target is True and c.target == 0.85
    assert c.accuracy.iou >= 0.85
    # two at least when the engine asks for it
    assert clump(v, f, spheres=30, target_iou=0.85, measure_resolution=40, min_spheres=2).count == 2


def test_a_harder_grain_needs_more_spheres_and_the_fewest_that_reach_the_target(ball, rough):
    v, f = rough
    low = clump(v, f, spheres=60, target_iou=0.7, measure_resolution=40)
    high = clump(v, f, spheres=60, target_iou=0.8, measure_resolution=40)
    sphere = clump(*ball, spheres=60, target_iou=0.8, measure_resolution=40)
    assert low.meets_target and high.meets_target and sphere.meets_target
    assert sphere.count < low.count < high.count <= 60
    # the chosen spheres are the greedy order's first ones, and one fewer misses the target
    fixed = clump(v, f, spheres=60)
    for c in (low, high):
        assert np.array_equal(c.centres, fixed.centres[:c.count]) and np.array_equal(c.radii, fixed.radii[:c.count])
        fewer = clump_accuracy(v, f, fixed.centres[:c.count - 1], fixed.radii[:c.count - 1], resolution=40)
        assert fewer.iou < c.target <= c.accuracy.iou


@pytest.mark.parametrize("cap", [1, 5, 12])
@pytest.mark.parametrize("target", [0.5, 0.8, 0.99])
def test_the_count_never_exceeds_the_cap_and_a_miss_is_marked(rough, cap, target):
    v, f = rough
    c = clump(v, f, spheres=cap, target_iou=target, measure_resolution=30)
    assert 1 <= c.count <= cap
    assert c.meets_target == (c.accuracy.iou >= target)
    if not c.meets_target:
        assert c.count == cap  # a clump that misses keeps every sphere it may take
    # the reported figures are clump_accuracy's own on the measuring grid
    assert c.accuracy == clump_accuracy(v, f, c.centres, c.radii, resolution=30)
    assert (c.coverage, c.spill) == (c.accuracy.coverage, c.accuracy.spill)


def test_without_a_target_the_clump_is_the_fixed_count_one(rough):
    v, f = rough
    c = clump(v, f, spheres=8, rng=0)
    assert c.count == 8 and c.accuracy is None and c.target is None and c.meets_target is None


def test_bad_targets_are_refused(ball):
    for bad in (0.0, 1.0, 1.5, -0.2, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="accuracy target"):
            clump(*ball, spheres=5, target_iou=bad)


def _dem(grain_files, out, *args):
    return CliRunner().invoke(cli, ["dem", str(grain_files), "--out", str(out), "--workers", "1", *args])


def test_deck_reports_each_grain_and_names_the_ones_that_miss(grain_files, tmp_path):
    out = tmp_path / "deck"
    r = _dem(grain_files, out, "--clump-accuracy", "0.8", "--spheres", "30")
    assert r.exit_code == 3, r.output  # a grain misses: the deck is written, the check failed
    deck = json.loads((out / "grains.json").read_text())["grains"]
    with open(out / "clumps.csv", newline="") as fh:
        rows = {row["name"]: row for row in csv.DictReader(fh)}
    assert list(next(iter(rows.values()))) == ["name", "spheres", "iou", "coverage", "spill", "volume_error",
                                               "inertia_error", "target", "meets_target"]
    assert sorted(rows) == sorted(g["name"] for g in deck) == ["cri-0001", "dpa-0002", "fso-0000"]
    missed = []
    for g in deck:
        row = rows[g["name"]]
        # the table holds the record's figures, exactly
        for key in ("iou", "coverage", "spill", "volume_error", "inertia_error", "target"):
            assert float(row[key]) == g[key]
        assert int(row["spheres"]) == g["spheres"] and row["meets_target"] == str(g["meets_target"]).lower()
        assert g["target"] == 0.8 and g["accuracy_resolution"] == DECK_RESOLUTION and 1 <= g["spheres"] <= 30
        # an independent recomputation: the mesh as the deck holds it (m, centroid at the origin), the spheres
        # as the .xyzr file holds them
        v, f = read_grain(grain_files / f"{g['name']}.stl")
        v = v * 1e-3
        v = v - mass_properties(v, f).centroid
        spheres = np.loadtxt(out / g["xyzr"], comments="#", ndmin=2)
        a = clump_accuracy(v, f, spheres[:, :3], spheres[:, 3], resolution=DECK_RESOLUTION)
        assert a.iou == pytest.approx(g["iou"], abs=1e-12)
        assert a.coverage == pytest.approx(g["coverage"], abs=1e-12)
        assert a.spill == pytest.approx(g["spill"], abs=1e-12)
        assert a.volume_error == pytest.approx(g["volume_error"], abs=1e-12)
        assert a.inertia_error == pytest.approx(g["inertia_error"], abs=1e-12)
        assert g["meets_target"] == (a.iou >= 0.8)
        if not g["meets_target"]:
            assert g["spheres"] == 30
            missed.append(g["name"])
    # the DPA aggregate needs far more than 30 spheres: named, with its figure, in one line
    assert missed == ["dpa-0002"]
    warnings = [line for line in r.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "dpa-0002 (" in warnings[0] and "0.8 within 30 spheres" in warnings[0]
    last = r.output.strip().splitlines()[-1]
    counts = sorted(g["spheres"] for g in deck)
    assert f"clumps of {counts[0]}/{counts[1]}/{counts[2]} spheres (min/median/max, at most 30)" in last
    assert "2 of 3 grains reach IoU ≥ 0.8" in last


def test_many_misses_are_counted_with_the_table(grain_files, tmp_path, monkeypatch):
    monkeypatch.setattr("grainforge.dem.template.NAMED_MISSES", 0)
    out = tmp_path / "deck"
    r = _dem(grain_files, out, "--clump-accuracy", "0.9", "--spheres", "3")
    assert r.exit_code == 3, r.output
    warnings = [line for line in r.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1
    assert "3 grains do not reach" in warnings[0] and f"{out / 'clumps.csv'} lists them" in warnings[0]


def test_same_inputs_same_bytes_and_no_table_without_a_target(grain_files, tmp_path):
    args = ["--clump-accuracy", "0.75", "--spheres", "20", "--engine", "liggghts"]
    a, b, plain = tmp_path / "a", tmp_path / "b", tmp_path / "plain"
    assert _dem(grain_files, a, *args).exit_code in (0, 3)
    assert _dem(grain_files, b, *args).exit_code in (0, 3)
    names = sorted(p.name for p in a.iterdir())
    assert "clumps.csv" in names and names == sorted(p.name for p in b.iterdir())
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    # LIGGGHTS refuses a multisphere of one sphere: two at least in its deck
    assert min(g["spheres"] for g in json.loads((a / "grains.json").read_text())["grains"]) >= 2
    r = _dem(grain_files, plain, "--spheres", "20", "--engine", "liggghts")
    assert r.exit_code == 0 and not (plain / "clumps.csv").exists()
    assert all("iou" not in g and "target" not in g for g in json.loads((plain / "grains.json").read_text())["grains"])
    assert "IoU" not in r.output


@pytest.mark.parametrize("value", ["0", "1", "1.5", "-0.3", "nan", "inf"])
@pytest.mark.parametrize("command", [["dem"], ["simulate", "repose"], ["simulate", "calibrate", "tilt"]])
def test_bad_accuracy_options_give_one_line_and_exit_2(grain_files, tmp_path, command, value):
    out = tmp_path / "out"
    extra = ["--target-angle", "30"] if "calibrate" in command else []
    r = CliRunner().invoke(cli, [*command, str(grain_files), "--out", str(out), "--clump-accuracy", value, *extra])
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "--clump-accuracy" in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("command, args, message", [
    (["dem"], ["--shape", "levelset"], "--clump-accuracy applies to --shape clump only"),
    (["simulate", "tilt"], ["--shape", "levelset"], "use it with --shape clump"),
    (["simulate", "repose"], ["--as-spheres"], "without --as-spheres"),
])
def test_accuracy_with_another_representation_is_refused(grain_files, tmp_path, command, args, message):
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, [*command, str(grain_files), "--out", str(out), "--clump-accuracy", "0.8", *args])
    assert r.exit_code == 2 and message in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()


def test_simulate_population_and_its_decks_carry_the_figures(grain_files, tmp_path):
    from grainforge.simulate import Settings, build_population
    from grainforge.simulate.engine import write_test_deck

    settings = Settings(templates=3, grains=6, spheres=12, seeds=1)
    templates = build_population([grain_files], settings, clump_accuracy=0.7)
    assert all(t.clump.target == 0.7 and t.clump.count <= 12 for t in templates)
    for t in templates:
        assert t.clump.meets_target == (t.clump.accuracy.iou >= 0.7)
    write_test_deck(templates, "tilt", settings=settings, seed=0, out=tmp_path / "deck")
    with open(tmp_path / "deck" / "clumps.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["name"] for r in rows] == [t.name for t in templates]
    assert [float(r["iou"]) for r in rows] == [t.clump.accuracy.iou for t in templates]


def test_simulate_cap_is_spheres_or_the_default_or_quicks():
    from grainforge.cli.simulate import run_settings
    from grainforge.dem.clump import DEFAULT_SPHERE_CAP
    from grainforge.simulate import QUICK

    assert run_settings("tilt", {"spheres": None}, False, "clump", 0.8).spheres == DEFAULT_SPHERE_CAP
    assert run_settings("tilt", {"spheres": 25}, False, "clump", 0.8).spheres == 25
    assert run_settings("tilt", {"spheres": None}, True, "clump", 0.8).spheres == QUICK["spheres"]
    # without a target, nothing changes
    assert run_settings("tilt", {"spheres": None}, False, "clump").spheres == 10


def test_calibrate_prints_a_command_with_the_target():
    from grainforge.cli.simulate_friction import use_command

    words = use_command("tilt", ["g"], friction=0.6, given={}, quick=False, as_spheres=False, shape="clump", spacing=None,
                        clump_accuracy=0.85).split()
    assert words[words.index("--clump-accuracy") + 1] == "0.85"
    assert "--clump-accuracy" not in use_command("tilt", ["g"], friction=0.6, given={}, quick=False, as_spheres=False,
                                                 shape="clump", spacing=None)


@pytest.mark.slow
def test_quick_simulate_with_a_target_in_yade(grain_files, tmp_path):
    require_engine("yade")
    out = tmp_path / "tilt"
    # the clumps' target is the point, not the angle: soft contacts (E = 1e5 Pa: a third of the steps), tilted from
    # 20° in 2° steps
    r = CliRunner().invoke(cli, ["simulate", "tilt", str(grain_files), "--out", str(out), "--quick",
                                 "--clump-accuracy", "0.6", "--young", "1e5", "--tilt-start", "20", "--tilt-step", "2"])
    assert r.exit_code in (0, 3), r.output
    with open(out / "clumps.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and all(int(row["spheres"]) <= 6 for row in rows)
    missing = [row["name"] for row in rows if row["meets_target"] == "false"]
    warnings = [line for line in r.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == (1 if missing else 0) and all(name in warnings[0] for name in missing)
    assert (r.exit_code == 3) == bool(missing or "check failed" in r.output), r.output
    assert (out / "tilt-seed0" / "clumps.csv").is_file()
    results = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    assert results[0]["clump_accuracy"] == "0.6"
