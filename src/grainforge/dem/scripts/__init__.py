"""Engine scripts shipped as real Python files (package data), and how a deck gets their text.

The Python a deck carries for an engine's own interpreter (Yade's ``run.py``,
the LAMMPS decks' ``dump2vtk.py``) lives in this folder as ``.py`` files, so
that they are compiled and linted like any other source; they never import
grainforge and are never imported by it (Yade's names exist only inside Yade).
:func:`render` reads one with :mod:`importlib.resources` when a deck is written.

Two conventions keep every file a valid Python file:

- **Lint header.** A script that is a *part* of a deck's script (a scene
  appended to ``yade_library.py``) may begin with lines that only linters need,
  such as ``from yade_library import *``, ended by the line
  ``# @grainforge-script-start@``. :func:`render` drops everything up to and
  including that line.
- **Parameters.** A line ``NAME = <default>  # @param`` is a per-deck value:
  ``render(name, {"NAME": value})`` replaces the line by ``NAME = <repr(value)>``
  (values of Python literal types: numbers, strings, booleans, ``None``,
  lists, tuples and dicts of them). Unmentioned parameters keep their default.

The scripts of this folder: ``yade_library.py`` (grain insertion with exact
mass properties), ``yade_pour.py`` (the example pour), ``lammps_dump2vtk.py``
and ``lammps_body_dump2vtk.py`` (the LAMMPS decks' dump converters).

Examples
--------
>>> render("yade_library.py").startswith("# Yade deck written by grainforge")
True
>>> "@grainforge-script-start@" in render("yade_pour.py")
False
>>> inject("N = 1  # @param\\nprint(N)\\n", {"N": 5})
'N = 5\\nprint(N)\\n'
"""

from __future__ import annotations

import ast
import re
from importlib import resources

from ...errors import InputError

__all__ = ["render", "inject", "script_names", "START"]

#: the line ending a script's lint header (see the module text)
START = "# @grainforge-script-start@"

_PARAM = re.compile(r"^(?P<name>[A-Za-z_]\w*) = .*  # @param$", re.MULTILINE)


def script_names() -> list[str]:
    """File names of the scripts shipped in this folder (``*.py`` but this module), sorted.

    Returns
    -------
    list of str
        File names, e.g. ``"yade_library.py"``.

    Examples
    --------
    >>> "yade_pour.py" in script_names()
    True
    """
    return sorted(p.name for p in resources.files(__name__).iterdir()
                  if p.name.endswith(".py") and p.name != "__init__.py")


def inject(text: str, params: dict | None = None) -> str:
    """``text`` with its ``NAME = …  # @param`` lines set to ``params`` (see the module text).

    Parameters
    ----------
    text : str
        A script's text.
    params : dict, optional
        Parameter name -> value, each a Python literal (numbers, strings, booleans, ``None``, and
        lists, tuples and dicts of them); unmentioned parameters keep their defaults.

    Returns
    -------
    str
        ``text`` with each named parameter line replaced by ``NAME = <repr(value)>``.

    Raises
    ------
    ValueError
        A name of ``params`` has no parameter line (or more than one), or its
        value is not a Python literal.
    """
    for name, value in (params or {}).items():
        literal = repr(value)
        try:
            ok = ast.literal_eval(literal) == value
        except (ValueError, SyntaxError):
            ok = False
        if not ok:
            raise InputError(f"script parameter {name}: {literal} is not a Python literal")
        hits = [m for m in _PARAM.finditer(text) if m.group("name") == name]
        if len(hits) != 1:
            raise InputError(f"script parameter {name}: {len(hits)} lines '{name} = ...  # @param' (need one)")
        m = hits[0]
        text = text[: m.start()] + f"{name} = {literal}" + text[m.end():]
    return text


def render(name: str, params: dict | None = None) -> str:
    """The deck text of script ``name`` of this folder: lint header dropped, parameters set.

    Parameters
    ----------
    name : str
        File name in this folder, e.g. ``"yade_pour.py"`` (:func:`script_names`).
    params : dict, optional
        Values of the script's ``# @param`` lines (:func:`inject`).

    Returns
    -------
    str
        The script's text as a deck carries it.

    Raises
    ------
    ValueError
        If there is no such script, or :func:`inject` refuses ``params``.
    """
    if name not in script_names():
        raise InputError(f"no engine script {name!r}; shipped: {', '.join(script_names())}")
    text = resources.files(__name__).joinpath(name).read_text(encoding="utf-8")
    head, sep, body = text.partition(START + "\n")
    if sep and (not head or head.endswith("\n")):
        text = body
    return inject(text, params)
