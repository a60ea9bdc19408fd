"""Resolution matching: the coarsest mesh a printer cannot tell from the true surface.

A grain generated on a geodesic sphere (FSO, CRI) samples a smooth or fractal
radius function at the sphere's vertices; between vertices the mesh is flat.
The printer reproduces nothing finer than its resolution, so a mesh is fine
enough once every flat triangle stays within **half the printer resolution**
of the surface it stands for (the chordal, or sagitta, deviation).  That is
the rule used here; see ``docs/printing.md`` for why it replaces the literal
"edge length of half the resolution" (which would mean ~80,000 triangles per
2 mm grain and 650 million in the paper's tray).

The deviation of level ``s`` is measured, not assumed: the grain is generated
at level ``s + 1``, whose extra vertices are exactly the edge midpoints of
level ``s`` projected onto the surface, and the deviation is the largest
distance between such a vertex and the midpoint of the straight edge it
splits (in mm, after scaling to the printed size).  This is a lower bound of
the true deviation of a fractal surface, and it is exact to second order for a
smooth one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from ..errors import InputError
from ..geometry.geodesic import MAX_SUBDIVISIONS, icosphere

__all__ = ["Resolution", "chordal_deviation", "match_subdivisions", "supports_matching"]

#: finest level resolution matching will choose (level 6: 40,962 vertices).
MAX_MATCHED = 6
#: a chosen mesh whose mean edge exceeds this fraction of the printed size no longer carries the
#: grain's shape (levels 0-2); :meth:`Resolution.shape_warning` says so.
COARSE_EDGE_FRACTION = 0.1


@dataclass(frozen=True)
class Resolution:
    """The choice made by :func:`match_subdivisions`.

    Attributes
    ----------
    subdivisions : int
        Icosphere level chosen.
    deviation : float
        Largest measured chordal deviation at that level over the pilot grains, mm.
    tolerance : float
        The allowed deviation (half the printer resolution), mm.
    edge : float
        Mean edge length of the chosen mesh at the printed size, mm.
    faces : int
        Triangles per grain.
    converged : bool
        False when the finest level allowed (by ``max_level`` or the triangle
        budget) still exceeds the tolerance; that level is then used and its
        deviation reported.
    limited_by : str
        ``"tolerance"`` (the rule was met), ``"budget"`` (the triangle budget
        capped the level) or ``"max level"``.
    """

    subdivisions: int
    deviation: float
    tolerance: float
    edge: float
    faces: int
    converged: bool
    limited_by: str = "tolerance"

    def retained_wavelength(self) -> float:
        """The shortest surface wavelength the chosen mesh can carry, mm: two mean edges (Nyquist).

        Returns
        -------
        float
            mm.
        """
        return 2.0 * self.edge

    def shape_warning(self, size: float) -> str | None:
        """A warning when the chosen mesh is too coarse to keep the grain's shape, else None.

        That is when the mean edge exceeds :data:`COARSE_EDGE_FRACTION` of the
        printed ``size`` (levels 0–2 of a geodesic sphere: 12 to 162 surface
        points); the message states the detail that is kept.

        Parameters
        ----------
        size : float
            The printed size, mm.

        Returns
        -------
        str or None

        Examples
        --------
        >>> r = Resolution(0, 0.0886, 0.2, 0.311, 20, True)
        >>> print(r.shape_warning(0.5))  # doctest: +NORMALIZE_WHITESPACE
        resolution matching keeps only 12 surface points (level 0, 20 faces, mean edge 311 µm = 62% of
        the 0.5 mm size): the printed grain is a polyhedron with the grain's radii at its vertices;
        surface detail finer than 0.622 mm (two mean edges) is removed, because the printer cannot
        reproduce it at this size.
        >>> Resolution(4, 0.01, 0.016, 0.1, 5120, True).shape_warning(2.0) is None
        True
        """
        if self.edge <= COARSE_EDGE_FRACTION * size:
            return None
        points = 10 * 4**self.subdivisions + 2
        why = ("the triangle budget allows no finer mesh" if self.limited_by == "budget"
               else "the printer cannot reproduce it at this size")
        return (f"resolution matching keeps only {points} surface points (level {self.subdivisions}, "
                f"{self.faces} faces, mean edge {self.edge * 1000:.0f} µm = {100 * self.edge / size:.0f}% of the "
                f"{size:g} mm size): the printed grain is a polyhedron with the grain's radii at its vertices; "
                f"surface detail finer than {self.retained_wavelength():.3g} mm (two mean edges) is removed, "
                f"because {why}.")

    def describe(self) -> str:
        """One line for the user: level, faces, mean edge and deviation against the tolerance.

        Returns
        -------
        str

        Examples
        --------
        >>> Resolution(4, 0.01, 0.016, 0.1, 5120, True).describe()
        'subdivisions 4: 5120 faces, mean edge 100 µm, chordal deviation 10.0 µm ≤ 16.0 µm'
        """
        cmp = "≤" if self.converged else f"> (level capped by the {self.limited_by})"
        return (f"subdivisions {self.subdivisions}: {self.faces} faces, mean edge {self.edge * 1000:.0f} µm, "
                f"chordal deviation {self.deviation * 1000:.1f} µm {cmp} {self.tolerance * 1000:.1f} µm")


@cache
def _midpoint_index(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges (E, 2) of level ``level`` and the level+1 vertex at each edge's midpoint."""
    from scipy.spatial import cKDTree

    v, f = icosphere(level)
    fine, _ = icosphere(level + 1)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    e = np.unique(e, axis=0)
    mid = v[e[:, 0]] + v[e[:, 1]]
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    dist, idx = cKDTree(fine).query(mid)
    if dist.max() > 1e-9:  # pragma: no cover - guards the icosphere construction
        raise RuntimeError("icosphere levels are not nested")
    return e, idx


def supports_matching(method: str) -> bool:
    """Whether ``method``'s Params has an icosphere ``subdivisions`` field.

    Parameters
    ----------
    method : str
        A method name.

    Returns
    -------
    bool

    Examples
    --------
    >>> supports_matching("fso"), supports_matching("dpa")
    (True, False)
    """
    from ..methods import get

    return any(f.name == "subdivisions" for f in dataclasses.fields(get(method).Params))


def chordal_deviation(grain, level: int) -> float:
    """Chordal deviation of level ``level`` measured on a grain generated at ``level + 1``.

    Parameters
    ----------
    grain : Grain
        Generated on an icosphere of level ``level + 1`` (any scale).
    level : int

    Returns
    -------
    float
        Largest distance between a level+1 vertex and the midpoint of the
        level-``level`` edge it splits, in the grain's units.

    Examples
    --------
    >>> import grainforge
    >>> from grainforge.methods.fso import Params
    >>> g = grainforge.generate("fso", Params(amplitude=0.0, subdivisions=3), rng=0)
    >>> d = chordal_deviation(g, 2)   # a unit sphere: sagitta of the level-2 edges
    >>> 0.010 < d < 0.015
    True
    """
    v = grain.vertices
    if len(v) != 10 * 4 ** (level + 1) + 2:
        raise InputError(f"grain is not a level-{level + 1} geodesic mesh ({len(v)} vertices)")
    e, idx = _midpoint_index(level)
    chord_mid = 0.5 * (v[e[:, 0]] + v[e[:, 1]])
    return float(np.linalg.norm(v[idx] - chord_mid, axis=1).max())


def match_subdivisions(
    method: str,
    params: Any,
    *,
    size: float,
    size_definition: str,
    printer,
    seeds: Sequence[int],
    max_level: int = MAX_MATCHED,
    max_faces: int | None = None,
) -> Resolution:
    """The coarsest icosphere level whose chordal deviation is ≤ half the printer resolution.

    Pilot grains (one per seed) are generated at increasing levels and scaled
    to ``size``; the first level at which every pilot stays within tolerance
    is chosen.

    Parameters
    ----------
    method : str
        A method whose Params has a ``subdivisions`` field.
    params : the method's Params
        ``subdivisions`` is ignored (it is what is chosen).
    size : float
        Printed size in mm under ``size_definition``.
    size_definition : str
        One of :data:`grainforge.fabrication.scale.SIZE_DEFINITIONS`.
    printer : Printer or str
        The printer (its resolution sets the tolerance).
    seeds : sequence of int
        Pilot seeds (usually the first grains of the job).
    max_level : int, default MAX_MATCHED
        Finest level considered.
    max_faces : int, optional
        Triangle budget per grain: levels with more faces are not considered
        (``build_tray`` passes its per-job budget divided by the grain count).

    Returns
    -------
    Resolution

    Raises
    ------
    ValueError
        For a method without ``subdivisions``, no pilot seed, or an unknown printer.

    Examples
    --------
    >>> from grainforge.methods.fso import Params
    >>> r = match_subdivisions("fso", Params(amplitude=0.0), size=2.0, size_definition="equivalent",
    ...                        printer="objet-eden-250", seeds=[0])
    >>> r.subdivisions, r.converged      # a 2 mm sphere at 32 µm
    (2, True)
    """
    from ..methods import generate
    from .printers import get_printer
    from .scale import scale_factor

    printer = get_printer(printer)
    if not supports_matching(method):
        raise InputError(f"method {method!r} has no subdivisions parameter; resolution matching does not apply")
    if not seeds:
        raise InputError("at least one pilot seed is needed")
    max_level = int(min(max_level, MAX_SUBDIVISIONS - 1))
    limit = "max level"
    if max_faces is not None:
        budget_level = 0
        while 20 * 4 ** (budget_level + 1) <= max_faces:
            budget_level += 1
        if budget_level < max_level:
            max_level, limit = budget_level, "budget"
    tol = printer.max_deviation
    dev = np.inf
    level = 0
    for level in range(0, max_level + 1):
        fine_params = dataclasses.replace(params, subdivisions=level + 1)
        dev = 0.0
        for seed in seeds:
            g = generate(method, fine_params, int(seed))
            k = scale_factor(g, size, size_definition)
            dev = max(dev, chordal_deviation(g, level) * k)
            if dev > tol:
                break
        if dev <= tol:
            break
    g = generate(method, dataclasses.replace(params, subdivisions=level), int(seeds[0]))
    k = scale_factor(g, size, size_definition)
    e, _ = _midpoint_index(level)
    edge = float(np.linalg.norm(g.vertices[e[:, 0]] - g.vertices[e[:, 1]], axis=1).mean() * k)
    ok = bool(dev <= tol)
    return Resolution(level, float(dev), tol, edge, len(g.faces), ok, "tolerance" if ok else limit)
