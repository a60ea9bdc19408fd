"""Engine input text from the templates of ``grainforge/dem/texts/`` (:mod:`grainforge.dem.text`).

The decks are written as the user gets them (``grainforge dem`` and ``grainforge simulate``, the engine run
replaced by reading the deck back): every template in the folder is read by some writer, and no placeholder
reaches an engine.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

import pytest
from click.testing import CliRunner

import grainforge.dem.text as text
from grainforge.cli.main import cli
from grainforge.dem.text import fill, render
from grainforge.simulate.capabilities import RUNS, TEST_RUNS

#: an unfilled placeholder: "@name" or "@{name}" (an "@@" is written as "@")
PLACEHOLDER = re.compile(r"@(\{?[a-z_][a-z0-9_]*)")


def template_names() -> set[str]:
    return {p.name for p in resources.files("grainforge.dem").joinpath("texts").iterdir() if p.is_file()}


def test_fill_puts_every_value_and_leaves_the_engines_syntax_alone():
    got = fill('variable d equal @d\nprint "${d} @{d}x @@ ${d_ke}"\nx = {"a": 1} % 2\n', {"d": 0.25})
    assert got == 'variable d equal 0.25\nprint "${d} 0.25x @ ${d_ke}"\nx = {"a": 1} % 2\n'


def test_fill_refuses_a_missing_value_and_a_value_for_no_placeholder():
    with pytest.raises(KeyError, match="d1"):
        fill("region domain block @d0 @d1\n", {"d0": "0.0"})
    with pytest.raises(KeyError, match="values for no placeholder of the template: extra"):
        fill("region domain block @d0\n", {"d0": "0.0", "extra": "1"})
    with pytest.raises(KeyError):  # a template's own names are checked too
        render("liggghts-settle.in", {"name": "fill"})


@pytest.fixture(scope="module")
def grains(tmp_path_factory):
    out = tmp_path_factory.mktemp("g") / "g"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return out


class _Written(SystemExit):
    """Raised in place of the engine run once the deck is read back: a SystemExit, which the command group lets
    through as it is (any other exception would be reported as a bug, exit 1)."""

    def __init__(self):
        super().__init__(99)


def _simulate_cases():
    """Every test, engine and shape simulate runs (its own table), with the options of a quick deck."""
    shape_args = {"clump": [], "levelset": ["--spacing", "0.15", "--templates", "2"]}
    for test in ("repose", "tilt", "triaxial"):
        for engine, shapes in TEST_RUNS.get(test, RUNS).items():
            for shape in shapes:
                yield test, ["--engine", engine, "--shape", shape, *shape_args[shape]]


DEM_CASES = [["--engine", "liggghts", "--spheres", "6", "--count", "2"],
             ["--engine", "lammps", "--spheres", "6", "--count", "2"],
             ["--engine", "lammps", "--shape", "polyhedron", "--vertices", "20"],
             ["--engine", "yade", "--spheres", "6"]]


def test_every_template_is_used_by_a_writer_and_no_placeholder_reaches_an_engine(grains, tmp_path, monkeypatch):
    import grainforge.simulate.engine as engine
    import grainforge.simulate.pipeline as pipeline

    read = set()
    real = text.template_text

    def spy(name):
        read.add(name)
        return real(name)

    monkeypatch.setattr(text, "template_text", spy)
    monkeypatch.setattr(pipeline, "check_installed", lambda engine, mpi: None)  # no engine runs here
    inputs = {}

    def written(deck, **kw):
        deck = Path(deck)
        (name,) = [p for p in ("in.run", "run.py") if (deck / p).is_file()]
        inputs[f"{deck.parent.name}: {deck.name}/{name}"] = (deck / name).read_text()
        raise _Written()

    monkeypatch.setattr(engine, "run_deck", written)
    for k, (test, args) in enumerate(_simulate_cases()):
        before = len(inputs)
        r = CliRunner().invoke(cli, ["simulate", test, str(grains), "--out", str(tmp_path / f"s{k}"), "--quick",
                                     "--workers", "1", *args])
        assert isinstance(r.exception, _Written), (test, args, r.output)
        assert len(inputs) == before + 1
    for k, args in enumerate(DEM_CASES):
        out = tmp_path / f"d{k}"
        r = CliRunner().invoke(cli, ["dem", str(grains), "--out", str(out), "--workers", "1", *args])
        assert r.exit_code == 0, r.output
        inputs[f"dem {' '.join(args)}"] = (out / ("run.py" if "yade" in args else "in.run")).read_text()
    assert read == template_names()
    for where, deck in inputs.items():
        assert not PLACEHOLDER.findall(deck), where
    # the texts the engines read carry the values filled in
    tilt = next(v for k, v in inputs.items() if "tilt-seed" in k and "variable beta" in v)
    assert re.search(r"^timestep \d", tilt, re.MULTILINE) and "boundary p p f" in tilt
    assert any("Ig2_LevelSet_LevelSet_ScGeom" in v and "def tilt():" in v for v in inputs.values())


def test_a_level_set_scene_is_the_clump_scene_with_the_level_set_part_after_the_helpers():
    from grainforge.simulate.levelset_scenes import scene_text

    for test in ("repose", "tilt", "triaxial"):
        clump, levelset = scene_text(test), scene_text(test, "levelset")
        helpers, part = render("yade-helpers.py.in", {}), render("yade-levelset.py.in", {})
        assert clump.replace(helpers, helpers + "\n\n" + part, 1) == levelset
        assert "Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=False)" in levelset
        assert levelset.index("def stable_dt") < levelset.index("Ig2_LevelSet_LevelSet_ScGeom")
        assert levelset.index("Ig2_LevelSet_LevelSet_ScGeom") < levelset.index(f"def {test}():")
