"""Recipes, distributions, grading curves and per-grain seeds (grainforge.population)."""

from __future__ import annotations

import numpy as np
import pytest

import grainforge
from grainforge.io import export_bytes
from grainforge.population import (
    Distribution,
    GradingCurve,
    RecipeError,
    draw_grain,
    field_line,
    grain_stream,
    make_grain,
    parse_recipe,
    run_batch,
)

GOOD = """\
method = "fso"
count = 5
seed = 42
format = "stl"

[params]
fractal_dimension = { distribution = "uniform", low = 2.2, high = 2.6 }
length_ratio = { distribution = "truncnormal", mean = 5.0, sd = 1.0, low = 3.0, high = 8.0 }
amplitude = 0.08
ridges = { distribution = "choice", values = [8, 12], weights = [1, 3] }
frequencies = { distribution = "uniform", low = 6, high = 10 }
subdivisions = 1

[size]
definition = "sieve"
sieves_mm = [0.15, 0.3, 0.6, 1.18]
percent_passing = [0, 20, 80, 100]
basis = "count"
"""


def test_good_recipe_parses():
    r = parse_recipe(GOOD)
    assert (r.method, r.count, r.seed, r.format, r.size_definition) == ("fso", 5, 42, "stl", "sieve")
    assert r.params["amplitude"] == 0.08
    assert r.params["ridges"].kind == "choice" and r.params["ridges"].args["weights"] == (0.25, 0.75)
    assert r.params["frequencies"].integer
    assert r.size == GradingCurve((0.15, 0.3, 0.6, 1.18), (0.0, 20.0, 80.0, 100.0), "count")


def _edit(old: str, new: str) -> str:
    assert old in GOOD
    return GOOD.replace(old, new)


# (recipe text, dotted field, line, words expected in the reason)
BAD = [
    (GOOD.replace('method = "fso"\n', ""), "method", None, "required"),
    (_edit('method = "fso"', 'method = "nope"'), "method", 1, "must be one of"),
    (_edit("count = 5", "count = 0"), "count", 2, ">= 1"),
    (_edit("count = 5", "count = 2.5"), "count", 2, "whole number"),
    (_edit("seed = 42", "seed = -1"), "seed", 3, ">= 0"),
    (GOOD.replace("seed = 42\n", ""), "seed", None, "required"),
    (_edit('format = "stl"', 'format = "dwg"'), "format", 4, "stl"),
    (_edit('format = "stl"', 'colour = "red"'), "colour", 4, "unknown field"),
    (_edit("amplitude = 0.08", "amplitude = 1.5"), "params.amplitude", 9, "[0, 1]"),
    (_edit("amplitude = 0.08", "amplitud = 0.08"), "params.amplitud", 9, "not a fso parameter"),
    (_edit("high = 2.6", "high = 3.2"), "params.fractal_dimension.high", 7, "[2, 3)"),
    (_edit("low = 2.2", "low = 1.5"), "params.fractal_dimension.low", 7, "[2, 3)"),
    (_edit("low = 2.2, high = 2.6", "low = 2.6, high = 2.2"), "params.fractal_dimension.high", 7, "greater than low"),
    (_edit('"uniform", low = 2.2', '"gamma", low = 2.2'), "params.fractal_dimension.distribution", 7, "one of"),
    (_edit('"uniform", low = 2.2, high = 2.6', '"normal", mean = 2.4, sd = 0.1'),
     "params.fractal_dimension.distribution", 7, "truncnormal"),
    (_edit("low = 2.2, high = 2.6 }", "low = 2.2 }"), "params.fractal_dimension.high", 7, "required"),
    (_edit("low = 2.2, high = 2.6 }", "low = 2.2, high = 2.6, mode = 1 }"),
     "params.fractal_dimension.mode", 7, "not a field"),
    (_edit("sd = 1.0", "sd = -1.0"), "params.length_ratio.sd", 8, "positive"),
    (_edit("mean = 5.0", "mean = 9.0"), "params.length_ratio.mean", 8, "[low, high]"),
    (_edit("values = [8, 12]", "values = [8, 1200]"), "params.ridges.values", 10, "[1, 400]"),
    (_edit("weights = [1, 3]", "weights = [1]"), "params.ridges.weights", 10, "non-negative"),
    (_edit("low = 6, high = 10", "low = 6.5, high = 10"), "params.frequencies.low", 11, "whole number"),
    (_edit("amplitude = 0.08", "amplitude = 0.08\nk = 0.01"), "params.amplitude", 9, "cannot be combined"),
    (_edit('definition = "sieve"', 'definition = "hydrometer"'), "size.definition", 15, "equivalent"),
    (_edit("[0.15, 0.3, 0.6, 1.18]", "[0.15, 0.6, 0.3, 1.18]"), "size.sieves_mm", 16, "increasing"),
    (_edit("[0, 20, 80, 100]", "[0, 80, 20, 100]"), "size.percent_passing", 17, "decrease"),
    (_edit("[0, 20, 80, 100]", "[5, 20, 80, 100]"), "size.percent_passing", 17, "start at 0"),
    (_edit("[0, 20, 80, 100]", "[0, 20, 100]"), "size.percent_passing", 17, "4 numbers"),
    (_edit('basis = "count"', 'basis = "volume"'), "size.basis", 18, "mass"),
    (_edit('basis = "count"', 'basis = "count"\nmm = 2.0'), "size", 14, "exactly one"),
    (_edit('basis = "count"', 'sampling = "sobol"'), "size.sampling", 18, "quasi"),
    (GOOD + "[extra]\n", "extra", 19, "unknown field"),
    (_edit("amplitude = 0.08", "amplitude = "), "TOML", 9, "Invalid"),
]


@pytest.mark.parametrize("text, field, line, words", BAD, ids=[f"{b[1]}-{i}" for i, b in enumerate(BAD)])
def test_each_bad_field_is_named_with_its_line(text, field, line, words):
    with pytest.raises(RecipeError) as info:
        parse_recipe(text, source="r.toml")
    err = info.value
    assert err.field == field
    assert err.line == line
    assert words in err.reason
    prefix = f"r.toml:{line}: {field}: " if line else f"r.toml: {field}: "
    assert str(err).startswith(prefix)


def test_lognormal_size_validation():
    base = 'method = "fso"\ncount = 2\nseed = 1\n[size]\ndistribution = "lognormal"\nmedian_mm = 2.0\n'
    with pytest.raises(RecipeError, match=r":4: size.sigma: is required"):
        parse_recipe(base)
    with pytest.raises(RecipeError, match=r":7: size.sigma: must be a positive number"):
        parse_recipe(base + "sigma = 0\n")
    assert parse_recipe(base + "sigma = 0.3\n").size.median_mm == 2.0


def test_field_line_handles_headers_dotted_keys_and_comments():
    src = 'a = 1\n# [params]\n[params]\n  x.y = 2\n[params.z]\nlow = 3\n'
    assert field_line(src, ["a"]) == 1
    assert field_line(src, ["params", "x", "y"]) == 4
    assert field_line(src, ["params", "z", "low"]) == 6
    assert field_line(src, ["params", "w"]) == 3


def test_distributions_draw_inside_their_support_with_the_right_moments():
    rng = np.random.default_rng(0)
    n = 4000
    u = np.array([Distribution("uniform", {"low": 2.0, "high": 4.0}).draw(rng) for _ in range(n)])
    assert u.min() >= 2.0 and u.max() <= 4.0 and abs(u.mean() - 3.0) < 0.05  # SE 0.009
    t = np.array([Distribution("truncnormal", {"mean": 1.0, "sd": 1.0, "low": 0.5, "high": 1.5}).draw(rng)
                  for _ in range(n)])
    assert t.min() >= 0.5 and t.max() <= 1.5 and abs(t.mean() - 1.0) < 0.03  # symmetric truncation
    x = np.array([Distribution("normal", {"mean": 5.0, "sd": 2.0}).draw(rng) for _ in range(n)])
    assert abs(x.mean() - 5.0) < 0.15 and abs(x.std() - 2.0) < 0.1
    ln = np.array([Distribution("lognormal", {"median": 3.0, "sigma": 0.5}).draw(rng) for _ in range(n)])
    assert abs(np.median(ln) - 3.0) < 0.1 and abs(np.log(ln).std() - 0.5) < 0.03
    c = [Distribution("choice", {"values": ("a", "b"), "weights": (0.2, 0.8)}).draw(rng) for _ in range(n)]
    assert abs(c.count("a") / n - 0.2) < 0.03
    i = [Distribution("uniform", {"low": 3, "high": 5}, integer=True).draw(rng) for _ in range(300)]
    assert set(i) == {3, 4, 5}


def test_count_grading_inverse_cdf_is_log_linear():
    g = GradingCurve((0.1, 0.4, 1.6), (0.0, 50.0, 100.0), basis="count")
    assert g.sample_many(np.array([0.0, 0.25, 0.5, 1.0])) == pytest.approx([0.1, 0.2, 0.4, 1.6])


def test_mass_grading_converts_to_a_number_distribution_that_reproduces_the_mass_curve():
    g = GradingCurve((0.1, 0.2, 0.4, 0.8), (0.0, 30.0, 70.0, 100.0), basis="mass")
    d = g.sample_many((np.arange(200_000) + 0.5) / 200_000)  # fine quantile grid
    assert g.passing(d, d**3) == pytest.approx([0.0, 30.0, 70.0, 100.0], abs=0.05)
    # empty bins (flat parts of the curve) are never sampled
    g2 = GradingCurve((0.1, 0.2, 0.4, 0.8), (0.0, 50.0, 50.0, 100.0), basis="count")
    d2 = g2.sample_many(np.linspace(0, 1, 1001))
    assert not np.any((d2 > 0.2 + 1e-12) & (d2 < 0.4 - 1e-12))


def test_grain_stream_is_the_spawned_child_of_the_root_seed():
    child = np.random.SeedSequence(9).spawn(6)[5]
    assert grain_stream(9, 5).integers(0, 2**63) == np.random.default_rng(child).integers(0, 2**63)


def test_grain_draws_depend_on_root_seed_and_index_only():
    r5 = parse_recipe(GOOD)
    r50 = parse_recipe(GOOD.replace("count = 5", "count = 50"))
    for i in range(5):
        s5, p5, _ = draw_grain(r5, i)
        s50, p50, _ = draw_grain(r50, i)
        assert (s5, p5) == (s50, p50)  # seed and parameters: root seed and i alone
    assert len({draw_grain(r5, i)[0] for i in range(5)}) == 5
    rr = parse_recipe(GOOD.replace('basis = "count"', 'basis = "count"\nsampling = "random"'))
    rr50 = parse_recipe(GOOD.replace('basis = "count"', 'basis = "count"\nsampling = "random"')
                        .replace("count = 5", "count = 50"))
    assert [draw_grain(rr, i) for i in range(5)] == [draw_grain(rr50, i) for i in range(5)]


def test_recorded_seed_and_params_regenerate_the_grain_file():
    r = parse_recipe(GOOD)
    res = make_grain(r, 3)
    seed, params, size = draw_grain(r, 3)
    assert res.row["seed"] == seed and res.row["fractal_dimension"] == params.fractal_dimension
    from grainforge.fabrication.scale import to_size

    again = to_size(grainforge.generate("fso", params, seed), size, "sieve")
    assert export_bytes(again, "stl") == res.data
    assert res.row["I"] == pytest.approx(size, rel=1e-9)


@pytest.mark.slow
def test_grading_curve_of_2000_grains_is_within_the_stated_tolerance(tmp_path):
    # ASTM C778 graded standard sand (mid-band), by mass; FSO grains measured after generation.
    text = """\
method = "fso"
count = 2000
seed = 778
[params]
ridges = 2
frequencies = 2
subdivisions = 0
[size]
definition = "equivalent"
sieves_mm = [0.1, 0.15, 0.3, 0.425, 0.6, 1.18]
percent_passing = [0, 2, 25, 70, 98, 100]
basis = "mass"
"""
    r = parse_recipe(text)
    result = run_batch(r, tmp_path / "pop", workers=2)
    grading = result["summary"]["grading"]
    target = np.array(grading["target_percent_passing"])
    by_mass = np.array(grading["achieved_percent_passing"])
    # Stated tolerances (docs/populations.md), 2,000 grains, quasi sampling:
    # by mass 3.5 points (a handful of coarse grains carry the top 2 % of the mass),
    assert np.abs(by_mass - target).max() <= 3.5
    assert grading["max_abs_deviation_percent"] == pytest.approx(np.abs(by_mass - target).max())
    # by count, against the number distribution the mass curve implies, 0.25 points.
    sizes = np.array([row["equivalent_diameter"] for row in result["rows"]])
    by_count = r.size.passing(sizes)
    assert np.abs(by_count - r.size.number_percent_passing()).max() <= 0.25
    assert (tmp_path / "pop" / "population.png").stat().st_size > 10_000


ZINGG = """\
method = "cri"
count = 40
seed = 3
[params]
preset = "rough-sphere"
subdivisions = 2
aspect = { distribution = "zingg", elongation = { distribution = "truncnormal", mean = 0.7, sd = 0.1, low = 0.4, high = 1.0 }, flatness = 0.8 }
[size]
mm = 1.0
"""


def test_zingg_aspect_is_drawn_per_grain_within_its_support():
    r = parse_recipe(ZINGG)
    z = r.params["aspect"]
    assert z.kind == "zingg" and z.typical() == pytest.approx((1.0, 0.7, 0.56))
    aspects = np.array([draw_grain(r, i)[1].aspect for i in range(40)])
    e, f = aspects[:, 1] / aspects[:, 0], aspects[:, 2] / aspects[:, 1]
    assert np.all(aspects[:, 0] == 1.0) and np.all((e >= 0.4) & (e <= 1.0))
    assert np.allclose(f, 0.8) and e.std() > 0.05 and abs(e.mean() - 0.7) < 0.05
    assert np.array_equal(aspects[7], np.array(draw_grain(r, 7)[1].aspect))


@pytest.mark.parametrize("new, words", [
    ('elongation = { distribution = "normal", mean = 0.7, sd = 0.1 }', "unbounded"),
    ('elongation = { distribution = "uniform", low = 0.0, high = 0.9 }', "(0, 1]"),
    ('elongation = { distribution = "uniform", low = 0.5, high = 1.2 }', "(0, 1]"),
    ('elongation = { distribution = "choice", values = [0.5] }', "must be one of"),
    ('elongation = 1.5', "(0, 1]"),
])
def test_zingg_support_is_validated_before_any_work(new, words):
    text = ZINGG.replace('elongation = { distribution = "truncnormal", mean = 0.7, sd = 0.1, low = 0.4, high = 1.0 }',
                         new)
    with pytest.raises(RecipeError) as e:
        parse_recipe(text)
    assert "params.aspect.elongation" in str(e.value) and words in str(e.value) and e.value.line == 7


def test_zingg_only_for_ratio_parameters():
    with pytest.raises(RecipeError, match="zingg gives a ratio"):
        parse_recipe(ZINGG.replace("preset = \"rough-sphere\"",
                                   'morph_exponent = { distribution = "zingg", elongation = 0.5, flatness = 0.5 }'))


def test_list_parameters_are_drawn_element_by_element():
    text = ZINGG.replace('preset = "rough-sphere"',
                         'descriptors = [0.0, { distribution = "uniform", low = 0.05, high = 0.15 }, 0.01]')
    r = parse_recipe(text)
    d = np.array([draw_grain(r, i)[1].descriptors for i in range(30)])
    assert np.all(d[:, 0] == 0.0) and np.all(d[:, 2] == 0.01)
    assert np.all((d[:, 1] >= 0.05) & (d[:, 1] <= 0.15)) and d[:, 1].std() > 0.02
    bad = text.replace("high = 0.15", "high = 1.5")
    with pytest.raises(RecipeError, match=r"params\.descriptors\.1\.high: must be in \[0, 1\]"):
        parse_recipe(bad)
