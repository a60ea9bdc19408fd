"""Representative templates (grainforge.dem.representative, --templates of dem and simulate).

K grains chosen out of N must have the population's descriptor distribution: every per-descriptor
two-sample KS statistic (scipy's ks_2samp, chosen K against all N) at most 0.1 at K = 40, where
the first K rows of a sorted table are far off.

``tests/data/ottawa-twins-descriptors.csv`` holds the mesh descriptors (the manifest's
sphericity, convexity, L, I, S and equivalent diameter; flatness S/I, elongation I/L) of a real
twin population: the 500 grains of ``grainforge fit examples/sand-atlas/ottawa-7.3um.csv
--voxel-size-um 7.3 --out FIT`` then ``grainforge batch FIT/recipe.toml --out GRAINS``.
"""

import csv
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import require_engine

from grainforge.cli.main import cli
from grainforge.dem.representative import (
    DESCRIPTORS,
    choose_representative,
    descriptor_matrix,
    ks_statistics,
)

DATA = Path(__file__).parents[1] / "data"
ROOT = Path(__file__).resolve().parents[2]
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"
TWINS = DATA / "ottawa-twins-descriptors.csv"
ATLAS_COLUMNS = ("True Sphericity (-)", "Convexity (-)", "Flatness (-)", "Elongation (-)", "Equivalent Diameter (µm)")
KS_LINE = re.compile(r"KS against them: sphericity (0\.\d{3}), convexity (0\.\d{3}), flatness (0\.\d{3}), "
                     r"elongation (0\.\d{3}), size (0\.\d{3}) \(largest (0\.\d{3})\)")


def ottawa() -> np.ndarray:
    with open(OTTAWA, encoding="utf-8", newline="") as fh:
        return np.array([[float(r[c]) for c in ATLAS_COLUMNS] for r in csv.DictReader(fh)])


def sand_like(n: int = 400, seed: int = 0) -> np.ndarray:
    """Rows drawn like Ottawa sand's: a normal law with its means and covariance (size in log)."""
    x = ottawa()
    x[:, 4] = np.log(x[:, 4])
    rows = np.random.default_rng(seed).multivariate_normal(x.mean(0), np.cov(x.T), size=n)
    rows[:, :4] = np.clip(rows[:, :4], 0.3, 1.0)
    rows[:, 4] = np.exp(rows[:, 4])
    return rows


def twins() -> np.ndarray:
    with open(TWINS, encoding="utf-8", newline="") as fh:
        rows = [{k.removesuffix("_mm"): float(v) for k, v in r.items() if k != "file"} for r in csv.DictReader(fh)]
    return descriptor_matrix(rows)


# ---- the choice ----

@pytest.mark.parametrize("name, table", [("sand-like rows", sand_like()), ("Ottawa twins", None),
                                         ("Ottawa's 3367 grains", None)])
def test_ks_is_at_most_0_1_for_every_descriptor_at_k_40(name, table):
    if table is None:
        table = twins() if name == "Ottawa twins" else ottawa()
    choice = choose_representative(table, 40)
    assert len(choice.indices) == 40 == len(set(choice.indices.tolist())) and choice.selected
    assert set(choice.ks) == set(DESCRIPTORS)
    assert choice.largest_ks <= 0.1, choice.ks
    # the reported figures are scipy's, chosen rows against all rows
    assert choice.ks == ks_statistics(table, choice.indices)


def test_the_twin_table_is_a_population_of_a_few_hundred():
    t = twins()
    assert t.shape == (500, 5) and 0.3 < t[:, 4].mean() < 0.7  # mm: Ottawa's d_eq about 0.5 mm


@pytest.mark.parametrize("column", range(5), ids=DESCRIPTORS)
def test_the_first_k_of_a_sorted_table_are_far_off_and_the_choice_is_not(column):
    table = sand_like()
    table = table[np.argsort(table[:, column], kind="stable")]
    first = ks_statistics(table, range(40))
    choice = choose_representative(table, 40)
    assert first[DESCRIPTORS[column]] > 0.8
    assert choice.largest_ks <= 0.1 < max(first.values())


def test_the_choice_is_deterministic_for_a_seed():
    table = sand_like(300, seed=3)
    a, b = choose_representative(table, 40, rng=7), choose_representative(table, 40, rng=7)
    assert np.array_equal(a.indices, b.indices) and a.ks == b.ks
    # the row order of the input does not decide which grains look alike: any seed reaches the target
    for seed in (0, 1, 2):
        assert choose_representative(table, 40, rng=seed).largest_ks <= 0.1


def test_k_at_least_n_takes_every_row_without_selection():
    table = sand_like(30)
    for k in (30, 31, 1000):
        c = choose_representative(table, k)
        assert c.indices.tolist() == list(range(30)) and not c.selected
        assert set(c.ks.values()) == {0.0}
        assert "no selection" in c.summary()


def test_scaled_to_one_size_the_sizes_tie():
    table = sand_like(200)
    table[:, 4] = 2.0 * (1 + 1e-12 * np.arange(200))  # one size, up to rounding
    assert choose_representative(table, 40).ks["size"] == 0.0


@pytest.mark.parametrize("k", [0, -1, 2.5])
def test_a_k_below_one_is_refused(k):
    with pytest.raises(ValueError, match="k must be"):
        choose_representative(sand_like(50), k)


def test_bad_tables_are_refused_naming_the_row():
    table = sand_like(50)
    table[7, 2] = np.nan
    with pytest.raises(ValueError, match="grain 7"):
        choose_representative(table, 10)
    with pytest.raises(ValueError, match="no grains"):
        choose_representative(np.empty((0, 5)), 10)
    with pytest.raises(ValueError, match=r"\(N, 5\)"):
        choose_representative(np.ones((10, 4)), 3)
    with pytest.raises(ValueError, match="grain 0: no size"):
        descriptor_matrix([{"sphericity": 0.9, "convexity": 0.9, "flatness": 0.7, "elongation": 0.7}])


# ---- grainforge dem --templates ----

@pytest.fixture(scope="module")
def population(tmp_path_factory):
    """24 small rf grains of 1 mm, with their manifest, and the same files in a folder without one."""
    from click.testing import CliRunner

    root = tmp_path_factory.mktemp("templates")
    r = CliRunner().invoke(cli, ["generate", "rf", "--count", "24", "--seed", "5", "--subdivisions", "3",
                                 "--size", "1", "--out", str(root / "grains")])
    assert r.exit_code == 0, r.output
    loose = root / "loose"
    loose.mkdir()
    for f in (root / "grains").glob("*.stl"):
        shutil.copy(f, loose / f.name)
    return root


def _templates_csv(path: Path) -> list[dict]:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("folder, how", [("grains", "descriptors from the manifest"), ("loose", "24 measured")])
def test_dem_writes_k_templates_with_the_pour_spread_over_them(runner, population, tmp_path, folder, how):
    import json

    out = tmp_path / "deck"
    r = runner.invoke(cli, ["dem", str(population / folder), "--out", str(out), "--templates", "6", "--grains", "20",
                            "--spheres", "4", "--workers", "1"])
    assert r.exit_code == 0, r.output
    line = [ln for ln in r.stderr.splitlines() if ln.startswith("templates:")]
    assert len(line) == 1 and f"templates: 6 of 24 grains, {how}; KS against them" in line[0], r.stderr
    assert KS_LINE.search(line[0]) and line[0].endswith("; templates.csv")
    rows = _templates_csv(out / "templates.csv")
    assert [r["template"] for r in rows[:-1]] == sorted(p.stem for p in (out).glob("*.xyzr"))
    assert rows[-1]["template"] == "KS" and rows[-1]["source"] == "chosen 6 vs 24 candidates"
    figures = [float(x) for x in KS_LINE.search(line[0]).groups()[:5]]
    assert [float(rows[-1][d]) for d in DESCRIPTORS[:-1]] + [float(rows[-1]["size_mm"])] == pytest.approx(
        figures, abs=6e-4)
    assert all(float(r["size_mm"]) == pytest.approx(1.0, rel=1e-4) for r in rows[:-1])
    deck = json.loads((out / "grains.json").read_text())
    counts = [g["count"] for g in deck["grains"]]
    assert len(counts) == 6 and sum(counts) == 20 and max(counts) - min(counts) <= 1


def test_dem_with_templates_at_least_the_inputs_takes_all_and_says_so(runner, population, tmp_path):
    out = tmp_path / "deck"
    r = runner.invoke(cli, ["dem", str(population / "grains"), "--out", str(out), "--templates", "30",
                            "--spheres", "4", "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert "templates: all 24 grains (30 asked): no selection; templates.csv" in r.stderr
    rows = _templates_csv(out / "templates.csv")
    assert len(rows) == 25 and rows[-1]["source"] == "all 24 candidates taken"


def test_a_candidate_that_is_not_a_solid_is_named_before_the_choice(runner, population, tmp_path):
    """Candidates measured from their files are checked as templates are: a hollow grain among them is named
    in one line (it is not left to sway the choice, nor dropped unseen when another grain is chosen)."""
    import trimesh

    folder = tmp_path / "mixed"
    shutil.copytree(population / "loose", folder)
    outer, inner = trimesh.creation.icosphere(radius=0.5), trimesh.creation.icosphere(subdivisions=1, radius=0.25)
    inner.invert()
    trimesh.util.concatenate([outer, inner]).export(folder / "rf-0003.stl")  # replaces a grain: a cavity
    out = tmp_path / "deck"
    r = runner.invoke(cli, ["dem", str(folder), "--out", str(out), "--templates", "3", "--spheres", "4",
                            "--workers", "1"])
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("Error")]
    assert r.exit_code == 2 and len(lines) == 1, r.output
    assert "rf-0003.stl: not a closed solid (cavity" in lines[0]
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("command", [["dem"], ["simulate", "repose"], ["simulate", "tilt"]])
@pytest.mark.parametrize("k", ["0", "-2"])
def test_templates_below_one_is_refused_in_one_line(runner, population, tmp_path, command, k):
    out = tmp_path / "o"
    r = runner.invoke(cli, [*command, str(population / "grains"), "--out", str(out), "--templates", k])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--templates" in lines[0] and "Traceback" not in r.output, r.output
    assert not out.exists()


# ---- simulate: the choice from files and from a recipe ----

def test_simulate_chooses_from_a_recipe_pool_and_from_files(population):
    from grainforge.simulate import Settings
    from grainforge.simulate.specimen import build_population, choose_grains

    recipe = ROOT / "examples" / "angular-sand.toml"
    s = Settings(templates=5, spheres=4)
    a = choose_grains([recipe], s, pool=20)
    assert a.measured == 20 and a.available == 200 and len(a.picks) == 5 and a.choice.selected
    assert a.picks == choose_grains([recipe], s, pool=20).picks  # deterministic
    assert all(0 <= i < 200 for i in a.picks) and a.names == [f"angular-{i:04d}" for i in a.picks]
    assert "templates: 5 of 20 candidates evenly spread over 200 grains, 20 measured; KS against them" in a.summary()
    templates = build_population([recipe], s, chosen=a)
    assert [t.name for t in templates] == a.names
    # the templates' sizes are those the choice measured (the recipe's grains, generated again)
    assert [t.d_eq * 1e3 for t in templates] == pytest.approx(a.table[:, 4].tolist(), rel=1e-6)
    b = choose_grains([population / "grains"], s)
    assert b.measured == 0 and len(b.picks) == 5 and all(Path(p).parent == population / "grains" for p in b.picks)


@pytest.mark.slow  # a quick Yade run
def test_simulate_prints_the_ks_line_and_writes_templates_csv(runner, population, tmp_path):
    require_engine("yade")
    out = tmp_path / "sim"
    # 30 grains of soft contacts (E = 1e5 Pa: a third of the steps): the templates' line and file are the point,
    # not the heap (a quick repose heap has 120)
    r = runner.invoke(cli, ["simulate", "repose", str(population / "grains"), "--out", str(out), "--quick",
                            "--templates", "8", "--grains", "30", "--young", "1e5"])
    # exit 3: a run failed its own check (a heap of 30 grains may measure no angle), named on stderr
    assert r.exit_code == 0 or (r.exit_code == 3 and "check failed: seed" in r.stderr), r.output
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("templates:")]
    assert len(line) == 1 and KS_LINE.search(line[0]), r.stdout
    assert "templates: 8 of 24 grains, descriptors from the manifest" in line[0]
    rows = _templates_csv(out / "templates.csv")
    assert len(rows) == 9 and rows[-1]["template"] == "KS"
    largest = max(float(rows[-1][d]) for d in (*DESCRIPTORS[:-1], "size_mm"))
    assert largest == pytest.approx(float(KS_LINE.search(line[0]).group(6)), abs=6e-4)
