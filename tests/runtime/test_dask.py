"""The Dask backend against a real distributed.LocalCluster with separate worker processes."""

from __future__ import annotations

import sys

import pytest

from grainforge.cli.main import cli
from grainforge.population import parse_recipe, run_batch

# a distributed LocalCluster starts in seconds: the full suite runs these, the fast lane does not
pytestmark = pytest.mark.slow

distributed = pytest.importorskip("distributed")

RECIPE = """\
method = "fso"
count = 6
seed = 8786
[params]
fractal_dimension = { distribution = "truncnormal", mean = 2.4, sd = 0.1, low = 2.2, high = 2.6 }
length_ratio = { distribution = "uniform", low = 3.0, high = 8.0 }
ridges = 8
frequencies = 8
subdivisions = 2
[size]
definition = "sieve"
sieves_mm = [0.6, 0.85, 1.18]
percent_passing = [0, 50, 100]
basis = "count"
"""


def tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_dask_cluster_output_is_byte_identical_to_local(cluster, runner, tmp_path):
    recipe = tmp_path / "pop.toml"
    recipe.write_text(RECIPE)
    with distributed.Client(cluster) as client:
        pids = set(client.run(lambda: __import__("os").getpid()).values())
    assert len(pids) == 2 and __import__("os").getpid() not in pids  # separate worker processes
    res = runner.invoke(cli, ["batch", str(recipe), "--out", str(tmp_path / "dask"),
                              "--scheduler", cluster.scheduler_address])
    assert res.exit_code == 0, res.output
    run_batch(parse_recipe(RECIPE, source=str(recipe)), tmp_path / "local", workers=1)
    assert tree(tmp_path / "dask") == tree(tmp_path / "local")


def test_unreachable_scheduler_is_one_line(monkeypatch, runner, tmp_path):
    monkeypatch.setattr("grainforge.runtime.cluster.CONNECT_TIMEOUT", "2s")
    recipe = tmp_path / "pop.toml"
    recipe.write_text(RECIPE)
    res = runner.invoke(cli, ["batch", str(recipe), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9"])
    assert res.exit_code == 2
    assert "cannot connect to the Dask scheduler at tcp://127.0.0.1:9" in res.output


def test_missing_dask_names_the_extra(monkeypatch, runner, tmp_path):
    recipe = tmp_path / "pop.toml"
    recipe.write_text(RECIPE)
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    res = runner.invoke(cli, ["batch", str(recipe), "--out", str(tmp_path / "o"), "--scheduler", "tcp://x:8786"])
    assert res.exit_code == 2
    assert "pip install 'grainforge[dask]'" in res.output
