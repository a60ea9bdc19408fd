"""Measuring faceted grains: facet flatness and the radius of rounded edges.

Both measures take a mesh as any reader sees it (e.g. an STL read back with
trimesh) and the *intended* facet geometry (planes and edges, e.g. from
:func:`grainforge.methods.angular.core`), and report how closely the mesh
realises it.  They do not use the generator's radius function.
"""

from __future__ import annotations

import numpy as np

__all__ = ["facet_flatness", "edge_radius", "fit_circle"]


def facet_flatness(vertices, faces, normals, tolerance_deg: float = 2.0) -> float:
    """Share of the surface area whose normal lies within ``tolerance_deg`` of a facet plane.

    Each triangle's normal is compared with the nearest of the facet normals
    (the largest dot product).  For a rough surface a triangle may by chance
    lie within the tolerance of another facet's normal; with k facets and a
    2° tolerance that is a solid angle of k·0.0038 sr out of 4π (0.6 % for
    k = 20), so the measure is at most that generous.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    normals : (k, 3) float
        Unit outward normals of the facet planes.
    tolerance_deg : float

    Returns
    -------
    float in [0, 1]

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> facet_flatness(box.vertices, box.faces, np.vstack([np.eye(3), -np.eye(3)]))
    1.0
    >>> facet_flatness(box.vertices, box.faces, np.eye(3))
    0.5
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area2 = np.linalg.norm(cross, axis=1)
    ok = area2 > 0
    unit = cross[ok] / area2[ok, None]
    best = (unit @ np.asarray(normals, dtype=np.float64).T).max(axis=1)
    flat = best >= np.cos(np.deg2rad(tolerance_deg))
    return float(area2[ok][flat].sum() / area2.sum())


def fit_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares circle through 2D points (Kåsa's algebraic fit): (centre, radius).

    Parameters
    ----------
    points : (P, 2) array_like of float
        At least three points, not collinear.

    Returns
    -------
    centre : (2,) float64
    radius : float
        In the points' unit.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 9)
    >>> c, r = fit_circle(np.column_stack([2 + 0.5 * np.cos(t), -1 + 0.5 * np.sin(t)]))
    >>> np.round(c, 9).tolist(), round(r, 9)
    ([2.0, -1.0], 0.5)
    """
    p = np.asarray(points, dtype=np.float64)
    A = np.column_stack([2 * p, np.ones(len(p))])
    b = (p * p).sum(axis=1)
    (cx, cy, k), *_ = np.linalg.lstsq(A, b, rcond=None)
    return np.array([cx, cy]), float(np.sqrt(k + cx * cx + cy * cy))


def edge_radius(mesh, point, *, direction, n1, n2, reach: float, min_points: int = 5) -> float | None:
    """Radius of curvature of a rounded edge, from the mesh's cross-section.

    The mesh is cut by the plane through ``point`` normal to the edge
    ``direction``; the section points within ``reach`` of ``point`` whose
    direction from it lies strictly between the two facet normals ``n1`` and
    ``n2`` (the rounded arc, not the flat facets) are fitted with a circle.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    point : (3,) float
        A point on the edge's axis (for a rounded polytope: on the edge of the
        shrunk core, the circle's centre).
    direction : (3,) float
        Unit edge direction.
    n1, n2 : (3,) float
        Unit normals of the two facets that meet at the edge.
    reach : float
        Largest distance from ``point`` of the section points used.
    min_points : int
        Fewest arc points for a fit; fewer gives ``None``.

    Returns
    -------
    float or None
        The fitted circle's radius, or None when the arc has too few points.
    """
    import trimesh

    segs = trimesh.intersections.mesh_plane(mesh, plane_normal=direction, plane_origin=point)
    if len(segs) == 0:
        return None
    pts = segs.reshape(-1, 3) - point
    e1 = n1 - np.dot(n1, direction) * direction
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(direction, e1)
    xy = np.column_stack([pts @ e1, pts @ e2])
    ang = np.arctan2(xy[:, 1], xy[:, 0])
    m2 = np.array([n2 @ e1, n2 @ e2])
    a2 = np.arctan2(m2[1], m2[0])  # angle of n2 from n1 in the section plane, in (−π, π]
    lo, hi = (0.0, a2) if a2 > 0 else (a2, 0.0)
    margin = 0.1 * (hi - lo)
    near = np.hypot(xy[:, 0], xy[:, 1]) <= reach
    arc = near & (ang > lo + margin) & (ang < hi - margin)
    sel = np.unique(np.round(xy[arc], 12), axis=0)
    if len(sel) < min_points:
        return None
    return fit_circle(sel)[1]
