"""Convex polyhedron of a grain, for engines with convex polyhedral particles."""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["convex_polyhedron", "DEFAULT_VERTICES", "engine_vertices"]

#: engine -> hull vertices of ``grainforge dem --shape polyhedron`` when ``--vertices`` is not
#: given: a 14-grain pour of 2 mm grains settles in well under 2 min on 2 cores in each (contact
#: cost grows steeply with the count). LAMMPS dilates the hull by its rounded radius, so 12
#: vertices there hold about the volume of 16 in Yade (docs/dem.md, docs/benchmarks.md).
DEFAULT_VERTICES = {"yade": 16, "lammps": 12}


def convex_polyhedron(vertices: np.ndarray, *, max_vertices: int | None = None) -> np.ndarray:
    """Vertices of the convex hull, optionally simplified to at most ``max_vertices``.

    Simplification keeps the hull vertices that hold the most volume: greedily, starting from a
    large tetrahedron of hull vertices (the vertex farthest from the centroid, the one farthest
    from it, the one farthest from their line, the one farthest from their plane), it adds the
    vertex farthest outside the hull of those kept so far, until ``max_vertices`` are kept; the
    result is their hull (convex, inside the grain's hull). On rough 2 mm grains 16 vertices keep
    ≈ 0.9 of the full hull's volume, where keeping the vertices farthest apart kept ≈ 0.7
    (docs/dem.md).

    Parameters
    ----------
    vertices : (V, 3) float64
        Points of the grain (its mesh's vertices; any length unit).
    max_vertices : int, optional
        The most hull vertices kept (≥ 4); ``None``: every hull vertex.

    Returns
    -------
    (K, 3) float64
        Hull vertices (K ≤ max_vertices), in a deterministic order.

    Raises
    ------
    ValueError
        If ``max_vertices`` is below 4 (and the hull has more vertices).

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> len(convex_polyhedron(s.vertices)), len(convex_polyhedron(s.vertices, max_vertices=20))
    (642, 20)
    """
    from scipy.spatial import ConvexHull

    v = np.asarray(vertices, dtype=np.float64)
    hull = v[np.sort(ConvexHull(v).vertices)]
    if max_vertices is None or len(hull) <= max_vertices:
        return hull
    if int(max_vertices) < 4:
        raise InputError(f"max_vertices must be ≥ 4, got {max_vertices!r}")
    c = hull.mean(axis=0)
    a = int(np.argmax(np.linalg.norm(hull - c, axis=1)))
    b = int(np.argmax(np.linalg.norm(hull - hull[a], axis=1)))
    ab = (hull[b] - hull[a]) / np.linalg.norm(hull[b] - hull[a])
    rel = hull - hull[a]
    c3 = int(np.argmax(np.linalg.norm(rel - np.outer(rel @ ab, ab), axis=1)))
    n = np.cross(hull[b] - hull[a], hull[c3] - hull[a])
    d = int(np.argmax(np.abs(rel @ n)))
    chosen = [a, b, c3, d]
    while len(chosen) < int(max_vertices):
        eq = ConvexHull(hull[chosen]).equations  # outward unit normals, offsets: n·x + o ≤ 0 inside
        out = (hull @ eq[:, :3].T + eq[:, 3]).max(axis=1)
        out[chosen] = -np.inf
        k = int(np.argmax(out))
        if not out[k] > 0:
            break
        chosen.append(k)
    sub = hull[np.sort(chosen)]
    return sub[np.sort(ConvexHull(sub).vertices)]


def engine_vertices(engine: str, vertices: int | None = None) -> int:
    """The most convex-hull vertices of a polyhedron written for ``engine``: ``vertices``, or its default.

    Parameters
    ----------
    engine : {"yade", "lammps"}
        The engine the polyhedra are for.
    vertices : int, optional
        The most asked for; default :data:`DEFAULT_VERTICES` of the engine.

    Returns
    -------
    int
        The vertex cap.

    Raises
    ------
    ValueError
        More than LAMMPS reads per body (:data:`grainforge.dem.lammps_body.MAX_VERTICES`).

    Examples
    --------
    >>> engine_vertices("yade"), engine_vertices("lammps", 20)
    (16, 20)
    """
    from .lammps_body import MAX_VERTICES

    if vertices is None:
        return DEFAULT_VERTICES[engine]
    if engine == "lammps" and vertices > MAX_VERTICES:
        raise InputError(f"LAMMPS reads at most {MAX_VERTICES} vertices per body, got {vertices}")
    return vertices
