"""The engine scripts shipped as package data (grainforge.dem.scripts): valid Python, rendered as decks need.

No engine is needed: the scripts are compiled, not run (tests/dem/test_dem_engines.py runs the decks).
"""

from __future__ import annotations

import py_compile
from importlib import resources

import pytest

from grainforge.dem.scripts import START, inject, render, script_names

SCRIPTS = script_names()


def test_the_scripts_are_found():
    assert {"yade_library.py", "yade_pour.py", "lammps_dump2vtk.py", "lammps_body_dump2vtk.py"} <= set(SCRIPTS)


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_script_compiles(name, tmp_path):
    with resources.as_file(resources.files("grainforge.dem.scripts").joinpath(name)) as path:
        py_compile.compile(str(path), cfile=str(tmp_path / "x.pyc"), doraise=True)
    # and so does the text a deck gets
    compile(render(name), name, "exec")


def test_yade_run_py_is_the_library_and_the_scene_and_compiles():
    from grainforge.dem.yade import LIBRARY, POUR_SCENE

    run = LIBRARY + POUR_SCENE
    compile(run, "run.py", "exec")
    assert START not in run and "from yade_library import" not in run
    assert run.rstrip().endswith("sys.exit(0 if pour() else 1)")
    assert 'print("SETTLED in %d steps" % O.iter)' in POUR_SCENE


def test_render_drops_only_a_header_ended_by_the_marker():
    text = resources.files("grainforge.dem.scripts").joinpath("yade_pour.py").read_text(encoding="utf-8")
    head, _, body = text.partition(START + "\n")
    assert render("yade_pour.py") == body and "import *" in head
    assert render("yade_library.py") == resources.files("grainforge.dem.scripts").joinpath(
        "yade_library.py").read_text(encoding="utf-8")


def test_inject_sets_parameter_lines_and_refuses_the_rest():
    text = "A = 1  # @param\nB = 'x'  # @param\nprint(A, B)\n"
    out = inject(text, {"A": [1.5, 2], "B": {"k": None}})
    assert out == "A = [1.5, 2]\nB = {'k': None}\nprint(A, B)\n"
    assert inject(text) == text
    ns = {}
    exec(compile(inject(text, {"A": 3}).replace("print(A, B)\n", ""), "t", "exec"), ns)
    assert ns["A"] == 3 and ns["B"] == "x"
    with pytest.raises(ValueError, match="C"):
        inject(text, {"C": 1})
    with pytest.raises(ValueError, match="A"):
        inject(text, {"A": float("nan")})
    with pytest.raises(ValueError, match="A"):
        inject(text + "A = 2  # @param\n", {"A": 1})


def test_render_names_an_unknown_script():
    with pytest.raises(ValueError, match="nope.py"):
        render("nope.py")
