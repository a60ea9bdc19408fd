"""Level-set grains in the virtual bulk tests: the Yade scenes on Yade's level-set contact.

``simulate repose|tilt --shape levelset`` runs the scenes of
:mod:`grainforge.simulate.yade_scenes` with every grain's contact geometry a level
set — the signed distance field on a grid that ``grainforge dem --shape
levelset`` writes (:func:`grainforge.dem.levelset.level_set`), carried by a
clump whose six mass spheres give the mesh's exact mass, centre and inertia,
as for the sphere clumps.  The scene text is the clump scene with a short part
inserted after the shared helpers (:data:`LEVELSET_PART`) that redefines what
a level set needs:

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

__all__ = ["LEVELSET_PART", "scene_text", "scene_extra", "LEVELSET_NODES", "BASE_NODES", "MIN_TILT_GRAINS",
           "check_levelset_run", "quick_levelset"]

#: surface nodes of each grain's level set (as ``grainforge dem`` decks)
LEVELSET_NODES = 150
#: surface nodes of each level-set sphere of the rough base
BASE_NODES = 50

LEVELSET_PART = r'''

# ---- level-set grains: Yade's level-set contact geometry under the same contact law ------
def engines(extra_geoms=(), extra_bounds=()):
    """The clumps' contact law (linear spring + Coulomb friction, Cundall-Strack) on level-set contacts.

    Torques from the contact point (sphericalBodies=False): Yade's default takes the branch vector as a
    radius along the normal, right for spheres only; on a level set the normal force would have no moment.
    """
    return [
        ForceResetter(),
        InsertionSortCollider([Bo1_LevelSet_Aabb(), Bo1_Wall_Aabb(), Bo1_Sphere_Aabb()]),
        InteractionLoop(
            [Ig2_LevelSet_LevelSet_ScGeom(), Ig2_Wall_LevelSet_ScGeom()],
            [Ip2_FrictMat_FrictMat_FrictPhys()],
            [Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=False)],
        ),
        NewtonIntegrator(gravity=(0, 0, -SETTINGS["gravity"]), damping=SETTINGS["damping"], label="newton"),
    ]


def stable_dt(grains):
    """dt = safety * sqrt(m_min / k_max), k_max = E * (largest bounding radius): a level-set contact's radius."""
    m_min = min(t["mass"] for t in grains)
    r_max = max(t["bounding_radius"] for t in grains)
    return SETTINGS["dt_safety"] * math.sqrt(m_min / (SETTINGS["young"] * r_max))


_sphere_rough_base = rough_base


def rough_base(x0, x1, y0, y1, r, rnd, periodic=False):
    """The spheres' rough base (same places, same draws), each sphere a fixed level set."""
    ids = []
    for i in _sphere_rough_base(x0, x1, y0, y1, r, rnd, periodic):
        c = Vector3(O.bodies[i].state.pos)
        O.bodies.erase(i)
        ids.append(O.bodies.append(utils.levelSetBody("sphere", center=c, radius=r, spacing=r / 5.0,
                                                      nSurfNodes=SETTINGS["ls_base_nodes"], dynamic=False,
                                                      material=contact_material())))
    return ids


class _LevelSetWalls:
    """The repose cylinder as one fixed level-set tube (Yade has no facet/level-set contact)."""

    def facetCylinder(self, center, radius, height, segmentsNumber=32, wallMask=4, material=-1):
        import numpy
        t = 0.25 * radius  # wall thickness: far more than any overlap
        h = radius / 30.0  # grid spacing
        pad = 3 * h
        xs = numpy.arange(-(radius + t + pad), radius + t + pad + 0.5 * h, h)
        zs = numpy.arange(-(0.5 * height + pad), 0.5 * height + pad + 0.5 * h, h)
        X, Y, Z = numpy.meshgrid(xs, xs, zs, indexing="ij")
        # exact signed distance of a hollow cylinder: inner radius `radius`, thickness t, height `height`
        q1 = numpy.abs(numpy.hypot(X, Y) - (radius + 0.5 * t)) - 0.5 * t
        q2 = numpy.abs(Z) - 0.5 * height
        field = numpy.minimum(numpy.maximum(q1, q2), 0.0) + numpy.hypot(numpy.maximum(q1, 0.0),
                                                                          numpy.maximum(q2, 0.0))
        grid = RegularGrid(min=Vector3(xs[0], xs[0], zs[0]), spacing=h, nGP=Vector3i(len(xs), len(xs), len(zs)))
        b = utils.levelSetBody(grid=grid, distField=field.tolist(), center=Vector3(*center), nSurfNodes=8,
                               dynamic=False, material=material)
        b.state.pos = Vector3(*center)  # the tube's axis, whatever centre Yade computed for the field
        return [b]


geom = _LevelSetWalls()


def contact_spheres(ids):
    """[x, y, z, r, clump id] of every surface node of the level-set grains ids (r: half a grid spacing)."""
    out = []
    for i, b in contact_members(ids):
        r = 0.5 * b.shape.lsGrid.spacing
        for x in b.shape.surfNodes:
            p = b.state.pos + b.state.ori * x
            out.append([p[0], p[1], p[2], r, i])
    return out
'''


def scene_text(test: str, shape: str = "clump") -> str:
    """The Yade scene text of ``test`` for grains of ``shape`` (``"clump"`` or ``"levelset"``).

    The clump scene is returned unchanged; the level-set scene is the same text
    with :data:`LEVELSET_PART` inserted after the shared helpers.

    Examples
    --------
    >>> from grainforge.simulate.yade_scenes import TILT
    >>> scene_text("tilt") == TILT
    True
    >>> text = scene_text("tilt", "levelset")
    >>> text.index("Ig2_LevelSet_LevelSet_ScGeom") < text.index("def tilt():")
    True
    >>> "Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=False)" in text  # torques from the contact points
    True
    """
    from .yade_scenes import COMMON, REPOSE, TILT, TRIAXIAL

    scene = {"repose": REPOSE, "tilt": TILT, "triaxial": TRIAXIAL}[test]
    if shape == "clump":
        return scene
    if shape != "levelset":
        raise ValueError(f"shape must be clump or levelset, got {shape!r}")
    return COMMON + LEVELSET_PART + scene[len(COMMON):]


def scene_extra(shape: str = "clump") -> dict:
    """Settings a level-set scene reads beyond :func:`grainforge.simulate.scene_settings` (none for clumps).

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

    Examples
    --------
    >>> from grainforge.simulate import Settings
    >>> check_levelset_run("tilt", "levelset", Settings(grains=100))
    >>> check_levelset_run("tilt", "levelset", Settings(grains=30))
    Traceback (most recent call last):
    ...
    ValueError: --shape levelset: a tilt layer needs --grains ≥ 49 (a periodic cell at least 4 grains wide: Yade refuses a body wider than half the cell); got 30
    """
    if shape == "levelset" and test == "tilt" and settings.grains < MIN_TILT_GRAINS:
        raise ValueError(f"--shape levelset: a tilt layer needs --grains ≥ {MIN_TILT_GRAINS} (a periodic cell at "
                         f"least 4 grains wide: Yade refuses a body wider than half the cell); got {settings.grains}")


def quick_levelset(test: str, shape: str) -> dict:
    """What ``--quick`` changes for level sets beyond :data:`grainforge.simulate.QUICK` (tilt: the fewest grains).

    Examples
    --------
    >>> quick_levelset("tilt", "levelset")
    {'grains': 49}
    >>> quick_levelset("repose", "levelset"), quick_levelset("tilt", "clump")
    ({}, {})
    """
    return {"grains": MIN_TILT_GRAINS} if shape == "levelset" and test == "tilt" else {}
