"""A random sweep of ``grainforge dem`` settings over their declared ranges.

Every draw either is refused with one line and exit 2, writing nothing, or
writes a deck; a sample of the decks (one per engine and shape) is run in its
engine, which must end with the deck's own ``SETTLED`` or ``NOT SETTLED``
line and no engine error.  The ranges are read from the command's own option
declarations, so the sweep follows them.
"""

from __future__ import annotations

import json
import subprocess

import click
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from test_dem_engines import require

from grainforge.cli.dem import dem as dem_command
from grainforge.cli.main import cli

pytestmark = pytest.mark.slow

ENGINE_RUN = {"yade": ["yade", "-n", "-x", "run.py"], "liggghts": ["liggghts", "-in", "in.run"],
              "lammps": ["lmp", "-in", "in.run"]}
SHAPES = {"yade": ["clump", "polyhedron", "levelset"], "liggghts": ["clump"], "lammps": ["clump", "polyhedron"]}
SHAPE_OF = {"spheres": "clump", "refine": "clump", "vertices": "polyhedron", "spacing": "levelset"}


def _ranges():
    out = {}
    for p in dem_command.params:
        if isinstance(p.type, (click.IntRange, click.FloatRange)):
            out[p.name] = (p.type, p.type.min, p.type.max)
    return out


RANGES = _ranges()


def _value(data, name):
    kind, lo, hi = RANGES[name]
    if name == "refine":
        # the refinement's iterations cost CPU linearly: the range's top is estimated up front and refused
        # over a day (test_dem_limits.py); the sweep keeps its draws to seconds
        hi = 200
    if name == "spheres":
        hi = 200
    if name in ("count", "grains"):
        hi = 6  # the pour's size is capped by the deck (tested in test_dem.py); keep the runs short
    if isinstance(kind, click.IntRange):
        return str(data.draw(st.integers(lo, hi), label=name))
    # floats: log-uniform across the declared range
    x = data.draw(st.floats(np.log10(lo), np.log10(hi)), label=name)
    return repr(float(10.0**x))


def _draw(data):
    engine = data.draw(st.sampled_from(sorted(SHAPES)), label="engine")
    shape = data.draw(st.sampled_from(SHAPES[engine]), label="shape")
    args = ["--engine", engine, "--shape", shape, "--workers", "1"]
    for name in ("density", "unit", "count"):
        if data.draw(st.booleans(), label=f"give {name}"):
            args += [f"--{name}", _value(data, name)]
    for name, owner in SHAPE_OF.items():
        if owner == shape and data.draw(st.booleans(), label=f"give {name}"):
            flag = "--refine-iterations" if name == "refine" else f"--{name}"
            args += [flag, _value(data, name)]
    return engine, shape, args


@settings(max_examples=20, deadline=None)
@given(data=st.data())
def test_every_draw_is_a_deck_or_one_line(angular_grains, tmp_path_factory, data):
    """One input grain: the options' ranges are what is swept, and a template costs the same whichever grain
    it is made from (three grains cost three times as much and exercise nothing more)."""
    engine, shape, args = _draw(data)
    out = tmp_path_factory.mktemp("deck") / "d"
    grain = sorted(angular_grains.glob("*.stl"))[0]
    res = CliRunner().invoke(cli, ["dem", str(grain), "--out", str(out), *args])
    if res.exit_code == 2:
        lines = [ln for ln in res.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("Error: "), (args, res.output)
        assert not out.exists(), args
    else:
        assert res.exit_code == 0, (args, res.output)
        deck = json.loads((out / "grains.json").read_text())
        assert deck["grains"], args


@pytest.mark.parametrize("engine,shape", [(e, s) for e in sorted(SHAPES) for s in SHAPES[e] if s != "levelset"])
def test_a_sample_of_swept_decks_runs_in_its_engine(angular_grains, tmp_path, engine, shape):
    """One draw per engine and shape (level sets: in test_dem_engines.py), from a seeded generator."""
    require(ENGINE_RUN[engine][0])
    rng = np.random.default_rng([len(engine), len(shape), ord(engine[0]), ord(shape[0])])
    args = ["--engine", engine, "--shape", shape, "--workers", "1",
            "--density", repr(float(10 ** rng.uniform(2.5, 4.5))),
            "--unit", repr(float(10 ** rng.uniform(-4.5, -1.5)))]
    if shape == "clump":
        args += ["--spheres", str(int(rng.integers(2, 40)))]
    else:
        args += ["--vertices", str(int(rng.integers(6, 17)))]
    out = tmp_path / "d"
    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(out), *args])
    assert res.exit_code == 0, (args, res.output)
    run = subprocess.run(ENGINE_RUN[engine], cwd=out, capture_output=True, text=True, timeout=600,
                         stdin=subprocess.DEVNULL)
    last = run.stdout.strip().splitlines()[-1] if run.stdout.strip() else ""
    assert last.startswith(("SETTLED in", "NOT SETTLED after")), (args, run.stdout[-1500:], run.stderr[-1500:])
    assert "ERROR" not in run.stdout, (args, run.stdout[-1500:])
    assert run.returncode == (0 if last.startswith("SETTLED") else 1), (args, run.returncode)
