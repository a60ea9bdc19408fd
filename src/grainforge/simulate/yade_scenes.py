"""Yade scene texts of the virtual bulk tests.

Each scene is Python text for Yade's own interpreter, a template file of
``grainforge/dem/texts/`` (package data: ``yade-repose.py.in``,
``yade-tilt.py.in``, ``yade-triaxial.py.in``) whose one placeholder,
``@{helpers}``, :func:`scene_text` fills with the shared helpers
(``yade-helpers.py.in``; for level-set grains followed by
``yade-levelset.py.in``).  The scenes take no number from grainforge's side:
they read every setting at run time.  The text is appended to the grain
library of :mod:`grainforge.dem.yade` (``load_deck``, ``add_grain``,
``kinetic_energy``, ...), so every grain enters the simulation as a clump
with the mesh's exact mass, centre and inertia.  Settings come from
``grains.json["scene"]`` (:data:`SETTINGS` inside Yade).  A scene prints
``grainforge-progress <fraction> <phase>`` lines (read by
:func:`grainforge.simulate.run_yade`) and writes ``result.json``: the contact
spheres of every grain at the end (x, y, z, r in metres, clump id), the
phases' step counts and times, and the test's own record.  The angle itself
is measured afterwards, in grainforge, from that file
(:mod:`grainforge.simulate.angles`).

These texts run inside Yade (its Python, its numpy); they never import
grainforge.  They draw no orientation: grain ``k`` is placed in row ``k`` of
``grains.json["scene"]["orientations"]`` (the library's ``orientation``),
drawn uniformly by :func:`grainforge.dem.deck.grain_orientations`, the one
draw every deck and scene uses.  ``result.json["placed"]`` records, right after
insertion and as Yade holds them, every contact body (``bodies``: position,
clump id, its own turn), each grain's centre of mass (``centres``) and the
template drawn for it (``drawn``), so the orientations the engine received
can be read back and checked.
"""

from __future__ import annotations

from ..errors import InputError

__all__ = ["scene_text", "COMMON", "LEVELSET_PART", "REPOSE", "TILT", "TRIAXIAL"]  # noqa: F822

#: the templates of ``grainforge/dem/texts/`` (package data): the shared helpers, what level sets redefine, and
#: each test's scene, whose ``@{helpers}`` takes the helpers
_HELPERS, _LEVELSET, _SCENES = "yade-helpers.py.in", "yade-levelset.py.in", {
    "repose": "yade-repose.py.in", "tilt": "yade-tilt.py.in", "triaxial": "yade-triaxial.py.in"}
#: module attributes holding a text (module ``__getattr__``): the clump scenes and the helper parts
_TEXTS = {"COMMON": lambda: _part(_HELPERS), "LEVELSET_PART": lambda: _part(_LEVELSET),
          "REPOSE": lambda: scene_text("repose"), "TILT": lambda: scene_text("tilt"),
          "TRIAXIAL": lambda: scene_text("triaxial")}


def __getattr__(name):
    # the texts are package data, read when asked for (grainforge.dem.text)
    if name in _TEXTS:
        return _TEXTS[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _part(name: str) -> str:
    from ..dem.text import render

    return render(name, {})


def scene_text(test: str, shape: str = "clump") -> str:
    """The Yade scene text of ``test`` for grains of ``shape`` (``"clump"`` or ``"levelset"``).

    The test's template (``yade-<test>.py.in``) with its ``@{helpers}`` filled: the shared helpers
    (``yade-helpers.py.in``), and for level sets after them, two blank lines apart, what level-set grains
    redefine (``yade-levelset.py.in``, see :mod:`grainforge.simulate.levelset_scenes`).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    shape : {"clump", "levelset"}
        The grains' representation in Yade.

    Returns
    -------
    str
        Python text for Yade, appended to the grain library of :mod:`grainforge.dem.yade`.

    Raises
    ------
    ValueError
        For an unknown ``test`` or ``shape``.

    Examples
    --------
    >>> text = scene_text("tilt", "levelset")
    >>> text.index("def stable_dt") < text.index("Ig2_LevelSet_LevelSet_ScGeom") < text.index("def tilt():")
    True
    >>> "Ig2_LevelSet_LevelSet_ScGeom" in scene_text("tilt")
    False
    """
    from ..dem.text import render

    if test not in _SCENES:
        raise InputError(f"test must be one of {', '.join(_SCENES)}, got {test!r}")
    if shape not in ("clump", "levelset"):
        raise InputError(f"shape must be clump or levelset, got {shape!r}")
    parts = [_part(_HELPERS)] + ([_part(_LEVELSET)] if shape == "levelset" else [])
    return render(_SCENES[test], {"helpers": "\n\n".join(parts)})
