"""A virtual test and a calibration from Python (grainforge.simulate.pipeline, grainforge.simulate.calibration):
docs/simulate.md's example as written, with Yade; the pipeline with a stand-in engine whose layer fails at the
contact friction angle (atan μ), in seconds."""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import require_engine

from grainforge.errors import OutputExistsError
from grainforge.simulate import CalibrationResult, VirtualTestResult, calibrate_friction, run_virtual_test, settings_for
from grainforge.simulate.pipeline import Count, Estimate, Evaluated, Note, RunProgress

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "examples" / "paper-rough-spheres.toml"


def _python_block(page: Path, section: str) -> str:
    """The first ```python block of ``section`` in ``page``."""
    text = page.read_text(encoding="utf-8").split(f"\n## {section}\n", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"```python\n(.*?)```", text, re.DOTALL)[:1]
    return block


@pytest.mark.slow
def test_the_docs_python_example_runs_as_written(tmp_path, monkeypatch, capsys):
    """docs/simulate.md, *From Python*: a quick tilt test of the paper's rough spheres in Yade, read back."""
    require_engine("yade")
    (tmp_path / "examples").mkdir()
    shutil.copy(RECIPE, tmp_path / "examples" / RECIPE.name)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(_python_block(ROOT / "docs" / "simulate.md", "From Python"), "docs/simulate.md", "exec"), scope)
    result, events = scope["result"], scope["events"]
    printed = capsys.readouterr().out.splitlines()
    assert isinstance(result, VirtualTestResult) and printed[0] == result.line
    assert result.line.startswith("paper-rough-spheres.toml: tilt failure angle ")
    assert result.out == Path("out/tilt-python")
    with open(result.out / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["angle_deg"]) for r in rows] == pytest.approx([r["angle_deg"] for r in result.rows], nan_ok=True)
    assert sorted(p.name for p in result.out.iterdir()) == ["results.csv", "templates.csv", "tilt-seed0", "tilt.png"]
    assert [type(e) for e in events if not isinstance(e, (Count, RunProgress))] == [Estimate, Note, Estimate]
    assert any(isinstance(e, RunProgress) for e in events)


# ---- the pipeline with a stand-in engine -------------------------------------------------------------------------

def _stand_in(deck, *, engine="yade", mpi=None, progress=None) -> dict:
    """A tilt run whose layer slides at the contact friction angle: its result.json, written in ``deck``."""
    deck = Path(deck)
    scene = json.loads((deck / "grains.json").read_text())["scene"]
    fails = float(scene["friction_deg"])
    tilt = np.arange(5.0, 80.0, 0.05)
    history = np.column_stack([tilt, np.where(tilt < fails, 0.0, 1.0)]).tolist()
    result = {"test": "tilt", "d_mean": 0.002, "grains": 30, "inserted": 30, "lost": 0, "steps": 1, "dt": 1e-5,
              "time": 1.0, "history": history, "failure_angle": fails}
    (deck / "result.json").write_text(json.dumps(result))
    if progress is not None:
        progress(1.0, "tilt")
    return result


@pytest.fixture
def stand_in_engine(monkeypatch):
    import grainforge.simulate.engine as engine
    import grainforge.simulate.pipeline as pipeline

    monkeypatch.setattr(engine, "run_deck", _stand_in)
    monkeypatch.setattr(pipeline, "check_installed", lambda engine, mpi: None)  # nothing is run


def test_a_virtual_test_returns_its_result_and_prints_nothing(stand_in_engine, tmp_path, capsys):
    settings = settings_for("tilt", quick=True, templates=2, friction=0.5)
    events = []
    result = run_virtual_test("tilt", [RECIPE], out=tmp_path / "t", settings=settings, quick=True, workers=1,
                              label="rough spheres", progress=events.append)
    assert capsys.readouterr() == ("", "")  # the library speaks through its result and its events
    angle = math.degrees(math.atan(0.5))
    assert result.rows[0]["angle_deg"] == pytest.approx(angle, abs=0.05)
    assert result.line == (f"rough spheres: tilt failure angle {result.rows[0]['angle_deg']:.1f}° (one seed); "
                           f"{tmp_path / 't' / 'results.csv'}, {tmp_path / 't' / 'tilt.png'}")
    assert result.passed and result.failed_runs == "" and result.clump_warning is None
    assert sorted(p.name for p in result.out.iterdir()) == ["results.csv", "templates.csv", "tilt-seed0", "tilt.png"]
    with open(result.out / "results.csv", newline="") as fh:
        (row,) = csv.DictReader(fh)
    assert float(row["angle_deg"]) == pytest.approx(result.rows[0]["angle_deg"]) and row["label"] == "rough spheres"
    # the events in the order a command shows them: the estimate, the templates chosen, their making, the runs
    kinds = [type(e) for e in events]
    assert kinds[0] is Estimate and not events[0].inputs_read
    assert kinds.index(Note) < kinds.index(Estimate, 1) < kinds.index(RunProgress)
    assert events[kinds.index(Estimate, 1)].inputs_read
    note = events[kinds.index(Note)].text
    assert note.startswith("templates: ") and note.endswith("; templates.csv")  # the choice and its KS figures
    assert {e.what for e in events if isinstance(e, Count)} == {"grains", "clumps"}
    # the same call again is refused (nothing replaced), then replaces them with overwrite
    before = (result.out / "results.csv").stat().st_mtime_ns
    # an OutputExistsError (a FileExistsError) naming the setting as Python does
    with pytest.raises(OutputExistsError, match="exists .*; use overwrite$"):
        run_virtual_test("tilt", [RECIPE], out=tmp_path / "t", settings=settings, quick=True, workers=1)
    assert (result.out / "results.csv").stat().st_mtime_ns == before
    again = run_virtual_test("tilt", [RECIPE], out=tmp_path / "t", settings=settings, quick=True, workers=1,
                             overwrite=True)
    assert again.rows[0]["angle_deg"] == result.rows[0]["angle_deg"] and again.label == "paper-rough-spheres.toml"


@pytest.mark.parametrize("options, message", [
    # the library names its settings as Python does (the command line names its options instead)
    ({"resume": True, "overwrite": True}, "resume and overwrite exclude each other"),
    ({"engine": "yade", "mpi": 2}, "mpi: yade runs one process per seed"),
    ({"shape": "levelset", "as_spheres": True}, "as_spheres is the sphere baseline"),
    ({"spacing": 0.1}, "spacing is the level set's grid: use it with shape levelset"),
])
def test_options_that_do_not_go_together_are_refused_before_any_work(options, message, stand_in_engine, tmp_path):
    settings = settings_for("tilt", quick=True)
    with pytest.raises(ValueError, match=re.escape(message)):
        run_virtual_test("tilt", [RECIPE], out=tmp_path / "t", settings=settings, **options)
    assert not (tmp_path / "t").exists()


def test_a_failed_engine_run_is_an_exception_and_keeps_its_deck(monkeypatch, tmp_path):
    import grainforge.simulate.engine as engine
    import grainforge.simulate.pipeline as pipeline
    from grainforge.simulate import EngineFailed

    def fails(deck, **kwargs):
        (Path(deck) / "yade.log").write_text("boom\n")
        raise EngineFailed(f"Yade failed in {deck} (exit 1): boom", deck)

    monkeypatch.setattr(engine, "run_deck", fails)
    monkeypatch.setattr(pipeline, "check_installed", lambda engine, mpi: None)
    out = tmp_path / "t"
    with pytest.raises(EngineFailed, match=r"Yade failed in tilt-seed0 \(exit 1\): boom; its deck and log are in ") as e:
        run_virtual_test("tilt", [RECIPE], out=out, settings=settings_for("tilt", quick=True, templates=2), quick=True,
                         workers=1)
    assert e.value.deck == out / "failed-tilt-seed0" and (e.value.deck / "yade.log").read_text() == "boom\n"
    assert sorted(p.name for p in out.iterdir()) == ["failed-tilt-seed0"]


def test_a_calibration_finds_the_friction_and_returns_every_evaluation(stand_in_engine, tmp_path, capsys):
    settings = settings_for("tilt", quick=True, templates=2)
    events = []
    result = calibrate_friction("tilt", [RECIPE], out=tmp_path / "mu", target_angle=30.0, settings=settings,
                                quick=True, workers=1, given={"templates": 2}, progress=events.append)
    assert capsys.readouterr() == ("", "")
    assert isinstance(result, CalibrationResult) and result.passed
    # the stand-in's layer fails at atan(μ): μ = tan 30° within the search's tolerance (0.5°)
    assert abs(math.degrees(math.atan(result.friction)) - 30.0) <= 0.5
    assert [e.friction for e in result.evaluations] == [e.friction for e in events if isinstance(e, Evaluated)]
    assert len(result.rows) == len(result.evaluations) * settings.seeds
    record = json.loads((result.out / "calibration.json").read_text())
    assert record["friction"] == result.friction and record["command"] == result.command
    assert result.command.startswith(f"grainforge simulate tilt {RECIPE} --friction {result.friction:.3g} "
                                     "--templates 2 --quick")
    assert result.line.startswith(f"paper-rough-spheres.toml: friction {result.friction:.3f}")
    assert "reaches 30° on the tilt test" in result.line
    assert sorted(p.name for p in result.out.iterdir()) == ["calibration.csv", "calibration.json", "calibration.png",
                                                            "runs", "templates.csv"]
    assert {e.evaluation for e in events if isinstance(e, RunProgress)} == set(range(len(result.evaluations)))


def test_a_target_out_of_reach_is_refused_and_keeps_nothing(stand_in_engine, tmp_path):
    from grainforge.simulate.friction_search import Unreachable

    out = tmp_path / "mu"
    with pytest.raises(Unreachable, match=r"run\(s\) made, nothing kept"):
        calibrate_friction("tilt", [RECIPE], out=out, target_angle=70.0, settings=settings_for("tilt", quick=True,
                                                                                              templates=2),
                           friction_range=(0.05, 1.0), quick=True, workers=1)
    assert not out.exists() or list(out.iterdir()) == []
