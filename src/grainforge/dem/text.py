"""Engine input text from templates: the LIGGGHTS/LAMMPS inputs and Yade scenes grainforge writes.

Each engine text is a file in ``grainforge/dem/texts/`` (package data), written in the engine's own
language with ``@name`` or ``@{name}`` where grainforge puts a value, and ``@@`` for a literal ``@``.
The ``@`` delimiter leaves the engines' own syntax alone: LIGGGHTS and LAMMPS use ``$name`` and
``${name}`` for their variables, Python (Yade's scenes) uses braces and ``%``.  The deck writers
compute every number in Python and format it there (the way trimesh's exporters compute, then
format); a template only places the formatted text.  A name left unfilled, or a value given for no
name, is an error, so a template and its writer cannot drift apart silently.

Examples
--------
>>> from grainforge.dem.text import fill
>>> fill("variable d equal @d  # @@ literal\\n", {"d": "0.002"})
'variable d equal 0.002  # @ literal\\n'
"""

from __future__ import annotations

import string
from collections.abc import Mapping
from functools import cache
from importlib import resources

__all__ = ["EngineText", "fill", "render", "block", "template_text"]


class EngineText(string.Template):
    """:class:`string.Template` with ``@`` as its delimiter (``@name``, ``@{name}``, ``@@``)."""

    delimiter = "@"
    idpattern = r"[a-z_][a-z0-9_]*"
    flags = 0  # names are lower case: an upper-case word after "@" is engine text


def fill(text: str, values: Mapping[str, object]) -> str:
    """Put ``values`` (already formatted, or anything ``str()`` formats) into template ``text``.

    Parameters
    ----------
    text : str
        The template, with ``@name`` / ``@{name}`` placeholders.
    values : mapping
        Every placeholder's value; no other keys.

    Returns
    -------
    str
        The engine text.

    Raises
    ------
    KeyError
        A placeholder without a value, or a value without a placeholder.
    """
    template = EngineText(text)
    names = set(template.get_identifiers())
    extra = set(values) - names
    if extra:
        raise KeyError(f"values for no placeholder of the template: {', '.join(sorted(extra))}")
    return template.substitute({k: str(v) for k, v in values.items()})


@cache
def template_text(name: str) -> str:
    """The text of template ``name`` in ``grainforge/dem/texts/`` (package data).

    Parameters
    ----------
    name : str
        File name of the template, e.g. ``"liggghts-tilt.in"``.

    Returns
    -------
    str
        The file's text, placeholders unfilled (read once per process).

    Raises
    ------
    FileNotFoundError
        If there is no such template.

    Examples
    --------
    >>> template_text("liggghts-multisphere.in").splitlines()[0]
    'include in.templates'
    """
    return resources.files("grainforge.dem").joinpath("texts", name).read_text(encoding="utf-8")


def render(name: str, values: Mapping[str, object]) -> str:
    """Template ``name`` of ``grainforge/dem/texts/`` filled with ``values`` (see :func:`fill`).

    Parameters
    ----------
    name : str
        File name of the template, e.g. ``"liggghts-tilt.in"``.
    values : mapping
        Every placeholder's value.

    Returns
    -------
    str
        The engine text.
    """
    return fill(template_text(name), values)


def block(name: str, values: Mapping[str, object] | None = None) -> str:
    """Template ``name`` rendered as a block of lines for a placeholder line of another template.

    A template file ends with a newline; the line it is placed on ends with its own, so the block
    is the rendered text without its final newline.

    Parameters
    ----------
    name : str
        File name of the template in ``grainforge/dem/texts/``.
    values : mapping, optional
        Every placeholder's value (none for a template without placeholders).

    Returns
    -------
    str
        The engine text without its final newline.

    Examples
    --------
    >>> block("liggghts-multisphere.in").splitlines()[0]
    'include in.templates'
    """
    return render(name, values or {}).removesuffix("\n")
