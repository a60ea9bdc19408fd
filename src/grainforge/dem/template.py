"""One grain made ready for a DEM engine: SI units, centroid at the origin.

A :class:`GrainTemplate` holds everything the engine decks need: the mesh in
metres with its volume centroid at the origin (the grain's own orientation
kept), its exact mass properties, and the chosen representation (a clump, a
convex polyhedron or a level set). It is engine-neutral; the writers in
:mod:`grainforge.dem.yade`, :mod:`grainforge.dem.liggghts` and
:mod:`grainforge.dem.lammps` turn templates into decks.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..rng import RNGLike
from .massprops import MassProperties, mass_properties

__all__ = ["GrainTemplate", "prepare", "SHAPES", "accuracy_warning", "accuracy_summary", "NAMED_MISSES"]

#: representations a template can carry
SHAPES = ("clump", "polyhedron", "levelset")

#: cells per d_eq of the grid on which a deck's clump coverage and spill are measured
CLUMP_MEASURE_RESOLUTION = 60


@dataclass(frozen=True)
class GrainTemplate:
    """A grain ready for export (SI units, centroid at the origin).

    Attributes
    ----------
    name : str
        File stem of the grain (safe for file names).
    vertices : (V, 3) float64 or None
        Mesh in metres, volume centroid at the origin, the grain's own orientation
        (``None`` after :meth:`without_mesh`).
    faces : (F, 3) int64 or None
    props : MassProperties
        Exact, unit density, in SI (m³, m⁵); the centroid is (0, 0, 0).
    density : float
        kg/m³.
    shape : str
        ``"clump"``, ``"polyhedron"`` or ``"levelset"``.
    clump : Clump or None
        The spheres (metres, same frame) for ``shape == "clump"``.
    polyhedron : (K, 3) float64 or None
        Convex-hull vertices for ``shape == "polyhedron"``.
    levelset : LevelSet or None
        For ``shape == "levelset"``: the distance field in the grain's *principal*
        frame (``x_grain = props.axes @ x_local``), centroid at the origin.
    source : str
        Where the grain came from (file path).
    count : int
        How many copies of this grain the population holds.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    props: MassProperties
    density: float
    shape: str = "clump"
    clump: Any = None
    polyhedron: Any = None
    levelset: Any = None
    source: str = ""
    count: int = 1
    info: dict = field(default_factory=dict)

    @property
    def mass(self) -> float:
        """kg."""
        return self.density * self.props.volume

    @property
    def inertia(self) -> np.ndarray:
        """(3, 3) inertia tensor about the centroid in the grain's frame, kg m²."""
        return self.density * self.props.inertia

    @property
    def principal(self) -> np.ndarray:
        """(3,) principal moments, kg m², ascending."""
        return self.density * self.props.principal

    @property
    def d_eq(self) -> float:
        """Volume-equivalent diameter, m."""
        return self.props.equivalent_diameter

    @property
    def bounding_radius(self) -> float:
        """Largest distance of a vertex (or clump sphere surface) from the centroid, m."""
        return self.info["bounding_radius"]

    def without_mesh(self) -> GrainTemplate:
        """The same template without its mesh (what the decks need; small to keep by the thousand).

        Returns
        -------
        GrainTemplate
            A copy whose ``vertices`` and ``faces`` are ``None``; this one is unchanged.
        """
        return dataclasses.replace(self, vertices=None, faces=None)


def prepare(vertices: np.ndarray, faces: np.ndarray, *, name: str, unit: float = 1e-3,
            density: float = 2650.0, shape: str = "clump", spheres: int = 30, refine_iterations: int = 0,
            polyhedron_vertices: int | None = None, levelset_spacing: float = 0.05,
            source: str = "", count: int = 1, rng: RNGLike = 0,
            size_range: tuple[float, float] | None = None, target_iou: float | None = None,
            min_spheres: int = 1) -> GrainTemplate:
    """Make a :class:`GrainTemplate` from a closed mesh.

    Parameters
    ----------
    vertices : (V, 3) float64
        In file units; ``unit`` converts them to metres (1e-3 for millimetres).
    faces : (F, 3) int64
        Triangles as vertex indices, counter-clockwise seen from outside; the mesh must enclose one
        solid (:func:`grainforge.dem.enclosure.enclosure_problems`).
    name : str
        The template's name: the stem of its deck files (safe for file names).
    unit : float
        Metres per file unit (> 0).
    density : float
        kg/m³ (> 0).
    shape : {"clump", "polyhedron", "levelset"}
        The representation built.
    spheres : int
        Sphere count of a clump (see :func:`grainforge.dem.clump.clump`); with
        ``target_iou``, the most spheres a clump may take.
    refine_iterations : int
        L-BFGS-B iterations refining the clump's centres and radii after the
        greedy placement (0: none; 30 gains a few points of coverage for
        several times the time, docs/dem.md).
    polyhedron_vertices : int, optional
        Simplify the convex hull to at most this many vertices.
    levelset_spacing : float
        Level-set grid spacing as a fraction of d_eq.
    source : str
        Where the grain came from (its file), for the records and messages.
    count : int
        Copies of this grain in the population (≥ 1).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The clump refinement's sample (:func:`grainforge.dem.clump.clump`; unused without
        ``refine_iterations``), normalised by :func:`grainforge.rng.as_generator`.
    size_range : (float, float), optional
        Equivalent diameters (m) the caller accepts; a grain outside is refused
        before its representation is built (the costly part).
    target_iou : float, optional
        Build the clump to this intersection over union with the grain, in
        (0, 1): the fewest spheres, up to ``spheres``, that reach it (measured
        by :func:`grainforge.dem.clump.clump_accuracy` on the grid of
        :data:`CLUMP_MEASURE_RESOLUTION` cells per d_eq). ``None``: ``spheres``
        spheres, as always.
    min_spheres : int
        With ``target_iou``: the fewest spheres a clump takes (2 for LIGGGHTS
        and LAMMPS, which refuse a body of one sphere).

    Returns
    -------
    GrainTemplate
        In metres, centroid at the origin, the grain's orientation kept, with its mesh.

    Raises
    ------
    ValueError
        For a mesh that is not a valid solid, a density ≤ 0, a unit ≤ 0, an unknown shape,
        ``refine_iterations < 0``, ``count < 1``, a ``target_iou`` outside (0, 1) or with a shape other
        than ``"clump"``, a grain outside ``size_range``.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box((2.0, 2.0, 2.0))
    >>> t = prepare(box.vertices, box.faces, name="box", density=1000.0, spheres=8)
    >>> round(t.mass, 12), t.clump.count      # a 2 mm cube (file units mm) of water: 8 mg
    (8e-06, 8)
    >>> a = prepare(box.vertices, box.faces, name="box", spheres=30, target_iou=0.8)
    >>> a.clump.count < 30, a.clump.meets_target
    (True, True)
    """
    from .enclosure import enclosure_problems

    if not (np.isfinite(density) and density > 0):
        raise InputError(f"density must be > 0 kg/m³, got {density!r}")
    if not (np.isfinite(unit) and unit > 0):
        raise InputError(f"unit must be > 0 m, got {unit!r}")
    if shape not in SHAPES:
        raise InputError(f"shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    if int(refine_iterations) < 0:
        raise InputError(f"refine_iterations must be ≥ 0, got {refine_iterations!r}")
    if int(count) < 1:
        raise InputError(f"count must be ≥ 1, got {count!r}")
    if target_iou is not None:
        if shape != "clump":
            raise InputError(f"target_iou is a clump's accuracy target; shape {shape!r} has none")
        from .clump import check_target

        target_iou = check_target(target_iou)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    problems = enclosure_problems(v, f)
    if problems:
        raise InputError(f"{source or name}: not a closed solid ({'; '.join(problems)})")
    v, mp = _in_metres(v, f, unit)
    if size_range is not None and not size_range[0] <= mp.equivalent_diameter <= size_range[1]:
        raise InputError(f"{source or name}: equivalent diameter {mp.equivalent_diameter:.3g} m is outside "
                         f"{size_range[0]:g}–{size_range[1]:g} m (at {unit:g} m per file unit): rescale the mesh or "
                         "give its unit (metres per file unit)")
    # the grain moves to its centroid; volume, inertia about the centroid and axes do not change
    v = v - mp.centroid
    mp = dataclasses.replace(mp, centroid=np.zeros(3))
    kw: dict[str, Any] = {}
    if shape == "clump":
        from .clump import clump

        kw["clump"] = clump(v, f, spheres=spheres, rng=rng, iterations=int(refine_iterations),
                            measure_resolution=CLUMP_MEASURE_RESOLUTION, target_iou=target_iou,
                            min_spheres=min_spheres)
    elif shape == "polyhedron":
        from .polyhedron import convex_polyhedron

        kw["polyhedron"] = convex_polyhedron(v, max_vertices=polyhedron_vertices)
    else:
        from .levelset import level_set

        # in the principal frame (engines such as Yade require an inertial local frame):
        # x_grain = axes @ x_local
        kw["levelset"] = level_set(v @ mp.axes, f, spacing=levelset_spacing)
    radius = float(np.linalg.norm(v, axis=1).max())
    if "clump" in kw:
        c = kw["clump"]
        radius = max(radius, float((np.linalg.norm(c.centres, axis=1) + c.radii).max()))
    return GrainTemplate(name=name, vertices=v, faces=f, props=mp, density=float(density), shape=shape,
                         source=source, count=int(count), info={"bounding_radius": radius}, **kw)


def _in_metres(vertices: np.ndarray, faces: np.ndarray, unit: float) -> tuple[np.ndarray, MassProperties]:
    v = np.asarray(vertices, dtype=np.float64) * unit
    return v, mass_properties(v, faces)


def check_level_set_budget(vertices: np.ndarray, faces: np.ndarray, *, unit: float, spacing: float) -> None:
    """Refuse a grain whose level set at ``spacing`` would exceed the node budget, before any work.

    The grid is the one :func:`prepare` builds (the grain centred and in its principal frame), so
    the refusal is the builder's own, only earlier.  A mesh that is not a closed solid is left to
    :func:`prepare`, which names its problems.

    Raises
    ------
    ValueError
        From :func:`grainforge.dem.levelset.level_set_grid`.
    """
    from .enclosure import enclosure_problems
    from .levelset import level_set_grid

    f = np.asarray(faces, dtype=np.int64)
    if enclosure_problems(np.asarray(vertices, dtype=np.float64), f):
        return
    v, mp = _in_metres(vertices, f, unit)
    level_set_grid((v - mp.centroid) @ mp.axes, f, spacing=spacing)


#: grains named one by one in the warning about clumps that miss their accuracy target; more are counted
NAMED_MISSES = 10


def accuracy_warning(templates, cap: int, table) -> str | None:
    """The one warning line naming the clumps that miss their accuracy target within ``cap`` spheres.

    Up to :data:`NAMED_MISSES` grains by name with their intersection over union, more as a count and the table
    (``clumps.csv``) that lists them.

    Parameters
    ----------
    templates : sequence of GrainTemplate
        The templates (those without a clump, or without a target, are not counted).
    cap : int
        The clumps' sphere cap.
    table : str or path
        The clump table the line names when it counts the misses.

    Returns
    -------
    str or None
        The line, or None when every clump reaches its target.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> miss = NS(name="dpa-0002", clump=NS(meets_target=False, target=0.9, accuracy=NS(iou=0.8123), count=30))
    >>> print(accuracy_warning([miss], 30, "deck/clumps.csv"))
    warning: 1 grain does not reach the intersection over union 0.9 within 30 spheres: dpa-0002 (0.812)
    """
    missing = [t for t in templates if t.clump is not None and t.clump.meets_target is False]
    if not missing:
        return None
    target = missing[0].clump.target
    head = (f"warning: {len(missing)} grain{'s do' if len(missing) > 1 else ' does'} not reach the intersection "
            f"over union {target:g} within {cap} spheres")
    if len(missing) <= NAMED_MISSES:
        return head + ": " + ", ".join(f"{t.name} ({t.clump.accuracy.iou:.3f})" for t in missing)
    return f"{head} (of {len(templates)}); {table} lists them (meets_target false)"


def accuracy_summary(templates, cap: int) -> str:
    """The clumps' sphere counts and how many reach their accuracy target, in one phrase.

    Parameters
    ----------
    templates : sequence of GrainTemplate
        The templates (those without a clump are left out).
    cap : int
        The clumps' sphere cap.

    Returns
    -------
    str
        ``clumps of 3/12/30 spheres (min/median/max, at most 30); 9 of 10 grains reach IoU ≥ 0.85``.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> ts = [NS(clump=NS(count=n, meets_target=n < 30, target=0.85)) for n in (1, 12, 30)]
    >>> accuracy_summary(ts, 30)
    'clumps of 1/12/30 spheres (min/median/max, at most 30); 2 of 3 grains reach IoU ≥ 0.85'
    """
    import statistics

    clumps = [t.clump for t in templates if t.clump is not None]
    if not clumps:
        return "no clumps"
    counts = [c.count for c in clumps]
    met = sum(bool(c.meets_target) for c in clumps)
    return (f"clumps of {min(counts)}/{statistics.median(counts):g}/{max(counts)} spheres (min/median/max, at most "
            f"{cap}); {met} of {len(clumps)} grains reach IoU ≥ {clumps[0].target:g}")
