"""grainforge fit: reading Atlas CSVs, the fit's plumbing, and recovering a synthetic sand's known aspects."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np
import pytest

from grainforge.cli.main import cli
from grainforge.fit import FITS, compare, read_sand, recipe_text
from grainforge.population import parse_recipe

HEADER = ["Particle ID", "Volume (µm³)", "Equivalent Diameter (µm)", "Major Axis Length (µm)",
          "Middle Axis Length (µm)", "Minor Axis Length (µm)", "True Sphericity (-)", "Convexity (-)",
          "Flatness (-)", "Elongation (-)", "Compactness (-)"]


def _write_sand(path, rows):
    """An Atlas-format CSV from dicts with d_eq (µm) and the four descriptors."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        for i, r in enumerate(rows, start=1):
            d = r["equivalent_diameter"]
            w.writerow([i, math.pi / 6 * d**3, d, 1.2 * d, d, 0.8 * d, r["sphericity"], r["convexity"],
                        r["flatness"], r["elongation"], 0.1])
    return path


def _fake_rows(n=30, seed=0):
    rng = np.random.default_rng(seed)
    return [{"equivalent_diameter": float(rng.uniform(300, 500)), "sphericity": float(rng.uniform(0.8, 0.95)),
             "convexity": float(rng.uniform(0.9, 0.99)), "flatness": float(rng.uniform(0.6, 0.9)),
             "elongation": float(rng.uniform(0.6, 0.9))} for _ in range(n)]


OTTAWA = Path(__file__).resolve().parents[1] / "examples" / "sand-atlas" / "ottawa-7.3um.csv"


def test_read_sand_reads_the_shipped_ottawa_file():
    s = read_sand(OTTAWA, 7.3)
    assert s.count == 3367
    assert s.values["sphericity"].mean() == pytest.approx(0.885, abs=0.001)
    assert s.values["flatness"].mean() == pytest.approx(0.768, abs=0.001)
    assert (s.equivalent_diameter / s.voxel_size).mean() == pytest.approx(503 / 7.3, rel=0.01)


@pytest.mark.parametrize("content, words", [
    ("", "empty file"),
    ("a,b,c\n1,2,3\n", "missing column(s)"),
    (",".join(HEADER) + "\n", "no grains"),
    (",".join(HEADER) + "\n1,2,300,4,5,6,0.9,0.9,abc,0.8,0.1\n", "line 2, column 'Flatness (-)': not a number"),
    (",".join(HEADER) + "\n1,2,300,4,5,6,0.9,0.9,1.7,0.8,0.1\n", "out of range"),
    ("file,method,seed,volume,sphericity\nfso-0000.stl,fso,1,2.0,0.9\n", "not a Sand Atlas CSV"),
])
def test_bad_sand_files_give_one_line_and_exit_2(runner, tmp_path, content, words):
    p = tmp_path / "sand.csv"
    p.write_text(content, encoding="utf-8")
    r = runner.invoke(cli, ["fit", str(p), "--voxel-size-um", "7", "--out", str(tmp_path / "o")])
    assert r.exit_code == 2, r.output
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_voxel_size_is_required_unless_a_column_gives_it(runner, tmp_path):
    p = _write_sand(tmp_path / "s.csv", _fake_rows(5))
    r = runner.invoke(cli, ["fit", str(p), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and "--voxel-size-um" in r.stderr
    text = p.read_text(encoding="utf-8").splitlines()
    text = [text[0] + ",Voxel Size (μm)"] + [t + ",5.0" for t in text[1:]]  # Greek mu is accepted too
    p.write_text("\n".join(text) + "\n", encoding="utf-8")
    assert read_sand(p).voxel_size == 5.0
    r = runner.invoke(cli, ["fit", str(p), "--out", str(tmp_path / "o"), "--method", "nope"])
    assert r.exit_code == 2 and "--method" in r.stderr


def test_recipe_text_is_a_valid_batch_recipe_with_the_sand_grading(tmp_path):
    s = read_sand(_write_sand(tmp_path / "s.csv", _fake_rows(50)), 7.0)
    params = {"descriptors": [0.0, 0.1, 0.006], "subdivisions": 5,
              "aspect": {"distribution": "zingg", "elongation": 0.8,
                         "flatness": {"distribution": "uniform", "low": 0.6, "high": 0.9}}}
    r = parse_recipe(recipe_text("cri", params, s, count=500, seed=1, header="a\nb"))
    assert r.count == 500 and r.size_definition == "equivalent" and r.size.basis == "count"
    assert r.size.sieves_mm[0] == pytest.approx(s.equivalent_diameter.min() / 1000, rel=1e-5)
    assert r.size.sieves_mm[-1] == pytest.approx(s.equivalent_diameter.max() / 1000, rel=1e-5)
    assert r.params["aspect"].kind == "zingg"


def test_twin_recipe_gives_each_grain_its_own_settings_and_size(runner, tmp_path):
    """What `fit` writes ([grains]: one value per grain), `batch` runs, grain i with grain i's settings."""
    from grainforge.fit import twin_recipe_text
    from grainforge.population import draw_grain

    spec = FITS["rf"]
    us = [np.array([0.1, 0.2, 0.8, 0.7]), np.array([0.3, 0.1, 0.6, 0.9])]
    own = [{**spec.grain_params(u)} for u in us]
    text = twin_recipe_text(spec, own, [0.41, 0.52], seed=3, header="test")
    recipe = parse_recipe(text)
    for i in range(len(us)):
        _, params, size = draw_grain(recipe, i)
        assert size == [0.41, 0.52][i]
        assert list(params.descriptors) == own[i]["descriptors"] and list(params.aspect) == own[i]["aspect"]
        assert params.subdivisions == 5
    (tmp_path / "recipe.toml").write_text(text.replace("subdivisions = 5", "subdivisions = 3"), encoding="utf-8")
    r = runner.invoke(cli, ["batch", str(tmp_path / "recipe.toml"), "--out", str(tmp_path / "grains")])
    assert r.exit_code == 0, r.output + r.stderr
    assert len(list((tmp_path / "grains").glob("rf-*.stl"))) == 2


@pytest.mark.parametrize("grains, words", [
    ("size_mm = [0.4]", "grains.size_mm: must be a list of count = 2 values"),
    ("size_mm = [0.4, -1.0]", "grain 1: must be in"),
    ("nope = [1, 2]", "grains.nope: is not a rf parameter"),
    ("aspect = [[1.0, 0.5, 0.4], { distribution = \"uniform\", low = 0.1, high = 0.2 }]", "not a distribution"),
    ("descriptors = [[0.0, 0.1, 0.01], [0.0, 0.9, 0.01]]", "grain 1"),
])
def test_bad_grains_tables_name_the_field(grains, words):
    from grainforge.population import RecipeError

    text = f'method = "rf"\ncount = 2\nseed = 1\n[size]\nmm = 0.4\n[grains]\n{grains}\n'
    if "size_mm" in grains:
        text = text.replace("mm = 0.4\n", 'definition = "equivalent"\n')
    with pytest.raises(RecipeError, match="grains") as exc:
        parse_recipe(text)
    assert words in str(exc.value)


def test_compare_passes_identical_samples_and_fails_shifted_ones():
    rng = np.random.default_rng(1)
    a = rng.uniform(0.6, 0.9, size=(400, 4))
    assert compare(a, a.copy())["pass"] and compare(a, a.copy())["score"] == 0
    b = a.copy()
    b[:, 1] += 0.02
    st = compare(a, b)
    assert not st["pass"] and st["per"]["convexity"]["mean_diff"] == pytest.approx(0.02)
    assert st["per"]["sphericity"]["pass"] and set(st["corr"]) >= {"flatness-elongation"}


ANGULAR = Path(__file__).resolve().parent / "data" / "synthetic-angular-sand.csv"
ANGULAR_SETTINGS = ANGULAR.with_name("synthetic-angular-sand-settings.csv")


@pytest.mark.slow  # about 150 grains of 0.05 s CPU each at 30 voxels across, and the inverse solves
def test_twin_fit_plumbing_on_a_tiny_population(tmp_path):
    """A tiny design and population: grain i of the recipe, made as batch makes it, measures exactly as the fit
    measured it; fit.csv pairs each grain with a distinct sand row; the design is cached."""
    from grainforge.fit import fit_sand, measure_grain, write_outputs

    sand = read_sand(ANGULAR)
    result = fit_sand(sand, "rf", count=50, refine=1, design_grains=48, cache=tmp_path / "cache")
    assert result.grains_measured >= 48 + 50 and len(result.generated) == 50
    for i in (0, 7):
        again = measure_grain(result.recipe, i, sand.voxel_size)
        assert np.allclose(again[:5], result.generated[i], atol=1e-9), i
    assert np.allclose(result.targets, sand.table()[result.sand_rows])
    paths = write_outputs(sand, result, tmp_path / "out")
    rows = list(csv.DictReader(paths[1].read_text(encoding="utf-8").splitlines()))
    assert len(rows) == 50 and len({r["sand_row"] for r in rows}) == 50
    j = int(rows[3]["sand_row"]) - 1
    assert float(rows[3]["sand_convexity"]) == pytest.approx(sand.values["convexity"][j])
    assert float(rows[3]["twin_convexity"]) == pytest.approx(result.generated[3, 2])
    stats = list(csv.DictReader(paths[2].read_text(encoding="utf-8").splitlines()))
    assert sum(r["statistic"] == "spearman" for r in stats) == 6
    again = fit_sand(sand, "rf", count=50, refine=0, design_grains=48, cache=tmp_path / "cache")
    assert again.grains_measured == 50  # the design came from the cache


@pytest.mark.slow  # about 340 grains at 30 voxels across
def test_twins_of_a_small_population_meet_the_criteria(tmp_path):
    """A twin fit of 60 rows of the synthetic angular sand (rf-made, so every grain is reachable): every
    criterion holds."""
    from grainforge.fit import TWIN_TOL, fit_sand

    result = fit_sand(read_sand(ANGULAR), "rf", count=60, refine=3, design_grains=160, cache=tmp_path / "cache")
    st = result.stats
    assert st["twin_within"] >= 0.9 and st["reachable"] >= 0.9, st
    for pair, (a, b) in st["corr"].items():
        assert abs(a - b) <= 0.1, (pair, a, b)
    assert st["pass"], st
    assert np.mean(result.twin_error <= TWIN_TOL) >= 0.9


@pytest.mark.slow
@pytest.mark.xfail(reason="last run (docs/benchmarks.md, Twin fits): the aspect settings are recovered within 1 %, but "
                          "irregularity +11 % and roughness -27 %: the two trade against each other in the descriptors",
                   strict=False)
@pytest.mark.skipif(os.environ.get("GRAINFORGE_FIT_RECOVERY") != "1",
                    reason="statistical profile (minutes of CPU): GRAINFORGE_FIT_RECOVERY=1 pytest tests/test_fit.py "
                           "-m slow; see docs/fit.md for its last result")
def test_fit_recovers_the_known_settings_of_the_synthetic_angular_sand(tmp_path):
    """Twins of every row of the synthetic angular sand: the criteria hold and the fitted settings' means are
    within 5 % of the known ones (tests/data/synthetic-angular-sand-settings.csv)."""
    from grainforge.fit import fit_sand

    sand = read_sand(ANGULAR)
    result = fit_sand(sand, "rf", count=None, workers=2, log=lambda line: print(line, flush=True))
    assert result.stats["pass"], result.stats
    truth = list(csv.DictReader(ANGULAR_SETTINGS.read_text(encoding="utf-8").splitlines()))
    for k in ("irregularity", "roughness", "elongation", "flatness"):
        known = np.mean([float(r[k]) for r in truth])
        fitted = np.mean([s[k] for s in result.settings])
        print(k, known, fitted)
        assert fitted == pytest.approx(known, rel=0.05), k


def test_bad_tables_are_refused_before_anything_is_written(runner, tmp_path):
    """One grain, a constant column (correlations undefined), a voxel size needing days: one line, exit 2."""
    rows = _fake_rows(60)
    for r in rows:
        r["convexity"] = 0.93
    cases = {"one.csv": (_fake_rows(1), "7", "1 grain(s); a fit needs at least 50"),
             "flat.csv": (rows, "7", "every grain has the same convexity"),
             "fine.csv": (_fake_rows(60), "1.0", "over --max-minutes 60")}
    for name, (content, voxel, words) in cases.items():
        p = _write_sand(tmp_path / name, content)
        extra = ["--max-voxels-across", "0", "--workers", "1"] if name == "fine.csv" else []
        r = runner.invoke(cli, ["fit", str(p), "--voxel-size-um", voxel, "--out", str(tmp_path / "o"), *extra])
        assert r.exit_code == 2, (name, r.output, r.stderr)
        assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1, (name, r.stderr)
        assert not (tmp_path / "o").exists()


def test_existing_outputs_are_not_overwritten_without_overwrite(runner, tmp_path):
    p = _write_sand(tmp_path / "s.csv", _fake_rows(5))
    out = tmp_path / "o"
    out.mkdir()
    (out / "fit.csv").write_text("keep", encoding="utf-8")
    r = runner.invoke(cli, ["fit", str(p), "--voxel-size-um", "7", "--out", str(out)])
    assert r.exit_code == 2 and "exists" in r.stderr and "--overwrite" in r.stderr
    assert (out / "fit.csv").read_text(encoding="utf-8") == "keep"


def test_fit_warns_and_exits_1_when_batch_would_refuse_its_recipe(runner, tmp_path, monkeypatch):
    """The CLI runs batch's pilot check on the recipe it wrote: an unmakeable end is a warning and exit 1."""
    import grainforge.fit as fitmod

    s = read_sand(_write_sand(tmp_path / "s.csv", _fake_rows(50)), 7.0)
    params = {"descriptors": [0.0, 0.05, {"distribution": "uniform", "low": 0.0, "high": 0.3}], "subdivisions": 3}
    text = recipe_text("rf", params, s, count=500, seed=1, header="test")
    gen = np.full((50, 5), 0.8)
    gen[:, 0], gen[:, 1:] = s.equivalent_diameter, s.table()
    stats = compare(s.table(), gen[:, 1:], twin_within=1.0)
    stats.update(reachable=1.0, unreachable_by={})

    def fake_fit(sand, method, **kw):
        return fitmod.FitResult(method="rf", recipe=text, stats=stats, generated=gen, sand_rows=np.arange(50),
                                settings=[{"irregularity": 0.05}] * 50, reachable=np.ones(50, bool),
                                targets=s.table())

    monkeypatch.setattr(fitmod, "fit_sand", fake_fit)
    out = tmp_path / "o"
    r = runner.invoke(cli, ["fit", str(tmp_path / "s.csv"), "--voxel-size-um", "7", "--out", str(out)])
    assert r.exit_code == 1, r.output + r.stderr
    assert "warning: grainforge batch would refuse this recipe" in r.stderr and "params.descriptors" in r.stderr
    assert (out / "recipe.toml").read_text(encoding="utf-8") == text  # the outputs are kept
