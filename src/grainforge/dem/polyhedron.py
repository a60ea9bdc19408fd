"""Convex polyhedron of a grain, for engines with convex polyhedral particles."""

from __future__ import annotations

import numpy as np

__all__ = ["convex_polyhedron"]


def convex_polyhedron(vertices: np.ndarray, *, max_vertices: int | None = None) -> np.ndarray:
    """Vertices of the convex hull, optionally simplified to at most ``max_vertices``.

    Simplification keeps the hull vertices farthest apart (greedy farthest-point
    selection, starting from the vertex farthest from the centroid), then takes
    their hull: the result is convex and lies inside the grain's hull.

    Parameters
    ----------
    vertices : (V, 3) float64
    max_vertices : int, optional
        ≥ 4.

    Returns
    -------
    (K, 3) float64
        Hull vertices (K ≤ max_vertices), in a deterministic order.

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
        raise ValueError(f"max_vertices must be ≥ 4, got {max_vertices!r}")
    c = hull.mean(axis=0)
    chosen = [int(np.argmax(np.linalg.norm(hull - c, axis=1)))]
    dist = np.linalg.norm(hull - hull[chosen[0]], axis=1)
    for _ in range(int(max_vertices) - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(hull - hull[k], axis=1))
    sub = hull[np.sort(chosen)]
    return sub[np.sort(ConvexHull(sub).vertices)]
