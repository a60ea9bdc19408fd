"""``grainforge batch``: determinism across workers, safety, resume after a real kill."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from grainforge.cli.main import cli
from grainforge.population import JOURNAL, load_recipe, run_batch

RECIPE = """\
method = "fso"
count = 8
seed = 31
[params]
fractal_dimension = { distribution = "uniform", low = 2.2, high = 2.6 }
amplitude = { distribution = "truncnormal", mean = 0.08, sd = 0.02, low = 0.04, high = 0.12 }
ridges = { distribution = "choice", values = [6, 8] }
frequencies = 8
subdivisions = 2
[size]
definition = "equivalent"
distribution = "lognormal"
median_mm = 3.0
sigma = 0.3
"""


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (including the journal) -> bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def recipe_file(tmp_path) -> Path:
    p = tmp_path / "pop.toml"
    p.write_text(RECIPE)
    return p


def test_batch_is_byte_identical_for_one_and_two_workers(runner, recipe_file, tmp_path):
    outs = []
    for w in (1, 2):
        out = tmp_path / f"w{w}"
        res = runner.invoke(cli, ["batch", str(recipe_file), "--out", str(out), "--workers", str(w)])
        assert res.exit_code == 0, res.output
        outs.append(tree(out))
    assert outs[0] == outs[1]
    names = set(outs[0])
    assert {f"fso-{i:04d}.stl" for i in range(8)} <= names
    assert {"manifest.csv", "manifest.json", "population.png", f"{JOURNAL}/recipe.toml"} <= names
    header, *lines = outs[0]["manifest.csv"].decode().splitlines()
    assert len(lines) == 8 and header.startswith("file,method,seed,fractal_dimension")
    summary = json.loads(outs[0]["manifest.json"])
    assert summary["count"] == 8 and summary["root_seed"] == 31
    fd = summary["parameters"]["fractal_dimension"]["achieved"]
    assert 2.2 <= fd["min"] <= fd["max"] <= 2.6


def test_existing_outputs_are_refused_in_one_line(runner, recipe_file, tmp_path):
    out = tmp_path / "o"
    assert runner.invoke(cli, ["batch", str(recipe_file), "--out", str(out), "--workers", "1"]).exit_code == 0
    before = tree(out)
    res = runner.invoke(cli, ["batch", str(recipe_file), "--out", str(out), "--workers", "1"])
    assert res.exit_code == 2
    assert "use --resume or --overwrite" in res.output and res.output.count("\n") == 1
    assert tree(out) == before
    res = runner.invoke(cli, ["batch", str(recipe_file), "--out", str(out), "--resume", "--overwrite"])
    assert res.exit_code == 2 and "exclude each other" in res.output


def test_bad_recipe_exits_2_naming_field_and_line_and_writes_nothing(runner, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(RECIPE.replace("high = 2.6", "high = 3.4"))
    out = tmp_path / "never"
    res = runner.invoke(cli, ["batch", str(bad), "--out", str(out)])
    assert res.exit_code == 2
    assert res.output.strip().endswith("bad.toml:5: params.fractal_dimension.high: must be in [2, 3), got 3.4")
    assert res.output.count("\n") == 1
    assert not out.exists()


def test_resume_with_another_recipe_is_refused(runner, recipe_file, tmp_path):
    out = tmp_path / "o"
    assert runner.invoke(cli, ["batch", str(recipe_file), "--out", str(out), "--workers", "1"]).exit_code == 0
    other = tmp_path / "other.toml"
    other.write_text(RECIPE.replace("seed = 31", "seed = 32"))
    res = runner.invoke(cli, ["batch", str(other), "--out", str(out), "--resume"])
    assert res.exit_code == 2 and "differs from the recipe" in res.output


def test_resume_regenerates_only_damaged_or_unrecorded_grains(recipe_file, tmp_path):
    r = load_recipe(recipe_file)
    ref = tmp_path / "ref"
    run_batch(r, ref, workers=1, report=False)
    expected = tree(ref)
    out = tmp_path / "o"
    run_batch(r, out, workers=1, report=False)
    (out / "fso-0002.stl").write_bytes((out / "fso-0002.stl").read_bytes()[:-50])  # truncated
    data = bytearray((out / "fso-0005.stl").read_bytes())
    data[200] ^= 0xFF  # same size, corrupt content
    (out / "fso-0005.stl").write_bytes(bytes(data))
    (out / JOURNAL / "grain-000006.json").unlink()  # file written, sidecar never recorded
    (out / "fso-0007.stl").unlink()
    (out / ".fso-0003.stl.abc123.tmp").write_bytes(b"half")  # leftover of a killed atomic write
    (out / JOURNAL / ".grain-000007.json.def456.tmp").write_bytes(b"")  # a sidecar cut off by the kill
    kept = {i: (out / f"fso-{i:04d}.stl").stat().st_mtime_ns for i in (0, 1, 3, 4)}
    res = run_batch(r, out, workers=2, resume=True, report=False)
    assert (res["generated"], res["reused"]) == (4, 4)
    assert tree(out) == expected
    assert kept == {i: (out / f"fso-{i:04d}.stl").stat().st_mtime_ns for i in (0, 1, 3, 4)}


@pytest.mark.slow
def test_resume_after_killing_a_real_batch_process(tmp_path):
    recipe = tmp_path / "slow.toml"
    # Grains slow enough (about 0.1-0.3 s each) to kill the run part-way.
    recipe.write_text(RECIPE.replace("count = 8", "count = 12").replace("subdivisions = 2", "subdivisions = 3")
                      .replace("frequencies = 8", "frequencies = 30").replace("values = [6, 8]", "values = [30, 40]"))
    exe = Path(sys.executable).with_name("grainforge")
    out = tmp_path / "killed"
    proc = subprocess.Popen([str(exe), "batch", str(recipe), "--out", str(out), "--workers", "2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.glob("fso-*.stl"))) < 3 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI process and its pool workers (own session)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not (out / "manifest.csv").exists()
    done_before = len(list((out / JOURNAL).glob("grain-*.json")))
    assert 1 <= done_before < 12
    res = subprocess.run([str(exe), "batch", str(recipe), "--out", str(out), "--resume", "--workers", "2"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert f"kept {done_before} intact" in res.stderr
    ref = tmp_path / "ref"
    run_batch(load_recipe(recipe), ref, workers=1)
    got, expected = tree(out), tree(ref)
    assert got == expected
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_a_grain_that_cannot_be_made_is_named_by_index_and_seed(runner, tmp_path):
    bad = tmp_path / "k.toml"
    bad.write_text(RECIPE.replace("amplitude = {", "k = 50.0\n# amplitude = {"))
    out = tmp_path / "o"
    res = runner.invoke(cli, ["batch", str(bad), "--out", str(out), "--workers", "1"])
    assert res.exit_code == 2
    assert res.output.startswith("Error: grain 0 (seed ") and "params.k 50.0 is too large" in res.output
    assert not (out / "manifest.csv").exists()


def test_resume_never_replaces_files_it_did_not_make(recipe_file, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "fso-0001.stl").write_bytes(b"someone else's grain")
    with pytest.raises(FileExistsError, match="not made by this batch"):
        run_batch(load_recipe(recipe_file), out, resume=True, workers=1)
    assert (out / "fso-0001.stl").read_bytes() == b"someone else's grain"
    assert not (out / JOURNAL).exists()
