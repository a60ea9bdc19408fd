"""Level-set grains in the virtual bulk tests: the Yade scenes on Yade's level-set contact.

``simulate repose|tilt --shape levelset`` runs the scenes of
:mod:`grainforge.simulate.yade_scenes` with every grain's contact geometry a level
set — the signed distance field on a grid that ``grainforge dem --shape
levelset`` writes (:func:`grainforge.dem.levelset.level_set`), carried by a
clump whose six mass spheres give the mesh's exact mass, centre and inertia,
as for the sphere clumps.  The scene text is the clump scene with a short part
after the shared helpers that redefines what a level set needs: the template
``grainforge/dem/texts/yade-levelset.py.in`` (:data:`LEVELSET_PART`), which
:func:`scene_text` puts into the test's ``@{helpers}`` after the shared ones:

- the engines: Yade's level-set contact geometry (``Ig2_LevelSet_LevelSet_ScGeom``,
  ``Ig2_Wall_LevelSet_ScGeom``) under the same contact law as the clumps
  (``Ip2_FrictMat_FrictMat_FrictPhys`` and ``Law2_ScGeom_FrictPhys_CundallStrack``:
  a linear spring and Coulomb friction, Yade's local damping), with the law's
  ``sphericalBodies=False``: each contact force acts at its contact point.  Yade's
  default (``True``) takes every branch vector as a radius along the contact
  normal, exact for spheres only: a level set's normal forces then have no
  moment, and a cube on a plane tips over at a tilt of 1–2° instead of sliding
  at atan μ (``benchmarks/levelset_block.py``; Yade 2023.02a honours the flag
  in periodic cells too, across the cell's boundary);
- the rough base: the same spheres at the same places (the same random
  draws), each a fixed level-set sphere (Yade 2023 has no sphere–level-set
  contact);
- the repose test's cylinder: one fixed level-set tube of the facet
  cylinder's inner radius and height (Yade has no facet–level-set contact),
  lifted and removed as the facets are;
- the time step: the same rule, ``dt = 0.3 sqrt(m_min / k_max)``, with the
  stiffest contact ``k_max = E r`` at the grain's bounding radius (a level-set
  contact's radii are the centre-to-contact distances);
- the final record: each grain's surface nodes (world coordinates, radius
  half a grid spacing) in place of the contact spheres, which the heap
  measurement reads as it reads spheres.

Notes
-----
What differs from the clumps' contact, in Yade's level-set implementation:
a pair of grains touches at **one** point, the surface node of the smaller
grain deepest inside the larger one's field (a clump pair may touch at several
sphere pairs at once); and the normal stiffness ``k_n = E r`` takes ``r``, the
distance from each grain's centre to that point (about half a grain), where a
clump takes its member spheres' radii (smaller): level-set grains are stiffer
at the same ``--young``, and their step is shorter.  The friction law, the
damping, the material and the scenes are the same.
"""

from __future__ import annotations

from ..errors import InputError
from .yade_scenes import scene_text

__all__ = ["LEVELSET_PART", "scene_text", "scene_extra", "LEVELSET_NODES", "BASE_NODES",  # noqa: F822
           "MIN_TILT_GRAINS", "check_levelset_run", "quick_levelset"]

#: surface nodes of each grain's level set (as ``grainforge dem`` decks)
LEVELSET_NODES = 150
#: surface nodes of each level-set sphere of the rough base
BASE_NODES = 50


def __getattr__(name):
    # LEVELSET_PART: the text of grainforge/dem/texts/yade-levelset.py.in (package data), read when asked for
    if name == "LEVELSET_PART":
        from . import yade_scenes

        return yade_scenes.LEVELSET_PART
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def scene_extra(shape: str = "clump") -> dict:
    """Settings a level-set scene reads beyond :func:`grainforge.simulate.scene_settings` (none for clumps).

    Parameters
    ----------
    shape : {"clump", "levelset"}
        The grains' representation in Yade.

    Returns
    -------
    dict
        ``ls_nodes`` and ``ls_base_nodes`` (surface nodes of a grain and of the base's grains) for level sets;
        empty for clumps.

    Examples
    --------
    >>> scene_extra("levelset")
    {'ls_nodes': 150, 'ls_base_nodes': 50}
    >>> scene_extra()
    {}
    """
    return {"ls_nodes": LEVELSET_NODES, "ls_base_nodes": BASE_NODES} if shape == "levelset" else {}


#: fewest grains of a level-set tilt: the tilt's periodic cell is ``round(sqrt(grains / 4))`` lattice cells
#: wide, and Yade refuses a body whose bound box is over half the cell; a level set's bound box (its grid's
#: inside corners, turned with the grain) can reach 1.7 lattice cells, so the cell must be 4 wide
MIN_TILT_GRAINS = 49


def check_levelset_run(test: str, shape: str, settings) -> None:
    """Refuse (``ValueError``, one line) a level-set run Yade cannot set up.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    shape : {"clump", "levelset"}
        The grains' representation; only level sets are checked.
    settings : Settings
        The runs' settings (their ``grains``).

    Raises
    ------
    ValueError
        If a level-set tilt has fewer than :data:`MIN_TILT_GRAINS` grains.

    Examples
    --------
    >>> from grainforge.simulate import Settings
    >>> check_levelset_run("tilt", "levelset", Settings(grains=100))
    >>> check_levelset_run("tilt", "levelset", Settings(grains=30))
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: shape levelset: a tilt layer needs grains ≥ 49 (a periodic cell at least 4 grains wide: Yade refuses a body wider than half the cell); got 30
    """
    if shape == "levelset" and test == "tilt" and settings.grains < MIN_TILT_GRAINS:
        raise InputError(f"{{shape}} levelset: a tilt layer needs {{grains}} ≥ {MIN_TILT_GRAINS} (a periodic cell at "
                         f"least 4 grains wide: Yade refuses a body wider than half the cell); got {settings.grains}",
                         setting=("shape", "grains"))


def quick_levelset(test: str, shape: str) -> dict:
    """What ``--quick`` changes for level sets beyond :data:`grainforge.simulate.QUICK` (tilt: the fewest grains).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    shape : {"clump", "levelset"}
        The grains' representation.

    Returns
    -------
    dict
        The settings ``--quick`` sets beyond :data:`grainforge.simulate.QUICK` (``grains`` for a level-set tilt),
        else empty.

    Examples
    --------
    >>> quick_levelset("tilt", "levelset")
    {'grains': 49}
    >>> quick_levelset("repose", "levelset"), quick_levelset("tilt", "clump")
    ({}, {})
    """
    return {"grains": MIN_TILT_GRAINS} if shape == "levelset" and test == "tilt" else {}
