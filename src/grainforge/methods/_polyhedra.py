"""Convex primary particles for DPA and an exact convex–convex intrusion test.

Every solid is centred on the origin and scaled to **unit volume**, so the
primary size a = V_p^(1/3) is 1 and aggregate volumes are counts of primaries.
Faces are convex polygons listed counter-clockwise seen from outside.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from ..errors import InputError

__all__ = ["Solid", "solid", "PRIMITIVES", "intrudes", "sat_intrudes", "sat_gap", "face_normals", "edge_directions",
           "mirror", "rotate_about", "rotation_matrix", "face_frame"]

_PHI = (1.0 + 5.0**0.5) / 2.0


def _cyclic(points):
    p = np.asarray(points, dtype=np.float64)
    return np.concatenate([p, p[:, [1, 2, 0]], p[:, [2, 0, 1]]])


def _signs(base):
    """All sign combinations of the non-zero entries of each row (no duplicates)."""
    out = []
    for row in np.atleast_2d(base):
        for s in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3):
            out.append(row * s)
    return np.unique(np.round(np.array(out), 12), axis=0)


def _raw_vertices(name: str) -> np.ndarray:
    if name == "tetrahedron":
        return np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64)
    if name == "cube":
        return _signs([0.5, 0.5, 0.5])
    if name == "octahedron":
        return np.concatenate([np.eye(3), -np.eye(3)])
    if name == "icosahedron":
        return _signs(_cyclic([[0.0, 1.0, _PHI]]))
    if name == "dodecahedron":
        return np.concatenate([_signs([1.0, 1.0, 1.0]), _signs(_cyclic([[0.0, 1.0 / _PHI, _PHI]]))])
    if name == "truncated-octahedron":
        import itertools

        perms = np.array(list(set(itertools.permutations([0.0, 1.0, 2.0]))))
        return _signs(perms)
    raise InputError(f"unknown primitive {name!r}")


#: primitive names accepted by :func:`solid` (and by ``dpa(primitive=...)``).
PRIMITIVES = ("cube", "octahedron", "tetrahedron", "dodecahedron", "icosahedron", "truncated-octahedron")


@dataclass(frozen=True)
class Solid:
    """A convex polyhedron of unit volume centred on the origin.

    Attributes
    ----------
    name : str
    vertices : (V, 3) float64
    faces : tuple of int arrays
        Each face's vertex indices, counter-clockwise seen from outside.
    triangles : (T, 3) int64
        Fan triangulation of the faces (outward).
    edges : (E, 2) int64
        Vertex pairs, one per edge.
    edge_dirs : (D, 2) int64
        One representative edge per direction (parallel edges removed).
    circumradius, inradius : float
    gyration2 : float
        Squared radius of gyration of the solid about its centre.
    orientations : tuple of int arrays
        For each face, the indices j of the rotations by 2πj/k about the face
        normal (k = number of the face's edges) that give *distinct* children.
    """

    name: str
    vertices: np.ndarray
    faces: tuple
    triangles: np.ndarray
    edges: np.ndarray
    edge_dirs: np.ndarray
    circumradius: float
    inradius: float
    gyration2: float
    orientations: tuple

    @property
    def max_orientations(self) -> int:
        return max(len(f) for f in self.faces)


def mirror(points: np.ndarray, centre: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Reflect ``points`` through the plane through ``centre`` with unit ``normal``."""
    d = (points - centre) @ normal
    return points - 2.0 * d[..., None] * normal


def rotation_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` about ``axis``: :func:`grainforge.geometry.rotations.axis_angle_matrix`."""
    from ..geometry.rotations import axis_angle_matrix

    return axis_angle_matrix(axis, angle)


def rotate_about(points: np.ndarray, centre: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotate ``points`` by ``angle`` about the line through ``centre`` along unit ``axis``."""
    if angle == 0.0:
        return points
    return (points - centre) @ rotation_matrix(axis, angle).T + centre


def face_frame(vertices: np.ndarray, face: np.ndarray, centroid: np.ndarray):
    """Centre and outward unit normal of one face of a convex solid."""
    p = vertices[face]
    c = p.mean(axis=0)
    n = np.cross(p[1] - p[0], p[2] - p[0])
    n /= np.linalg.norm(n)
    if np.dot(n, c - centroid) < 0:
        n = -n
    return c, n


def _same_points(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> bool:
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return bool((d.min(axis=1) < tol).all())


@cache
def solid(name: str) -> Solid:
    """The unit-volume :class:`Solid` called ``name`` (one of :data:`PRIMITIVES`).

    Examples
    --------
    >>> s = solid("octahedron")
    >>> len(s.vertices), len(s.faces), [len(o) for o in s.orientations][:2]
    (6, 8, [1, 1])
    >>> [len(o) for o in solid("truncated-octahedron").orientations].count(2)
    8
    """
    from scipy.spatial import ConvexHull

    if name not in PRIMITIVES:
        raise InputError(f"primitive must be one of {', '.join(PRIMITIVES)}, got {name!r}")
    v = _raw_vertices(name)
    hull = ConvexHull(v)
    v = v * (1.0 / hull.volume) ** (1.0 / 3.0)
    # group hull triangles into planar faces by their plane equation
    eq = np.round(hull.equations, 9)
    planes, inverse = np.unique(eq, axis=0, return_inverse=True)
    faces = []
    for k in range(len(planes)):
        n = planes[k, :3]
        idx = np.unique(hull.simplices[inverse.ravel() == k])
        c = v[idx].mean(axis=0)
        u = v[idx[0]] - c
        u /= np.linalg.norm(u)
        w = np.cross(n, u)
        ang = np.arctan2((v[idx] - c) @ w, (v[idx] - c) @ u)
        faces.append(idx[np.argsort(ang)].astype(np.int64))
    # deterministic face order: by the face centre's coordinates
    centres = np.array([v[f].mean(axis=0) for f in faces])
    order = np.lexsort(np.round(centres, 9).T[::-1])
    faces = tuple(faces[i] for i in order)
    tris = np.array([[f[0], f[i], f[i + 1]] for f in faces for i in range(1, len(f) - 1)], dtype=np.int64)
    edge_set = sorted({tuple(sorted((int(f[i]), int(f[(i + 1) % len(f)])))) for f in faces for i in range(len(f))})
    edges = np.array(edge_set, dtype=np.int64)
    dirs = v[edges[:, 1]] - v[edges[:, 0]]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    keep: list[int] = []
    for i, d in enumerate(dirs):
        if all(abs(abs(float(d @ dirs[j])) - 1.0) > 1e-9 for j in keep):
            keep.append(i)
    centroid = np.zeros(3)
    R = float(np.linalg.norm(v, axis=1).max())
    r = min(float(np.dot(v[f[0]], face_frame(v, f, centroid)[1])) for f in faces)
    # second moment of the unit-density solid: Σ over tetrahedra (0, a, b, c)
    a, b, c = v[tris[:, 0]], v[tris[:, 1]], v[tris[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    s2 = (np.einsum("ij,ij->i", a, a) + np.einsum("ij,ij->i", b, b) + np.einsum("ij,ij->i", c, c)
          + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c) + np.einsum("ij,ij->i", a, c))
    gyr2 = float((vol * s2 / 10.0).sum() / vol.sum())
    orientations = []
    for f in faces:
        fc, fn = face_frame(v, f, centroid)
        base = mirror(v, fc, fn)
        k = len(f)
        distinct: list[int] = []
        kids: list[np.ndarray] = []
        for j in range(k):
            kid = rotate_about(base, fc, fn, 2.0 * np.pi * j / k)
            if not any(_same_points(kid, other) for other in kids):
                distinct.append(j)
                kids.append(kid)
        orientations.append(np.array(distinct, dtype=np.int64))
    return Solid(
        name=name, vertices=v, faces=faces, triangles=tris, edges=edges, edge_dirs=edges[keep],
        circumradius=R, inradius=r, gyration2=gyr2, orientations=tuple(orientations),
    )


def face_normals(s: Solid, verts: np.ndarray) -> np.ndarray:
    """(..., F, 3) unit face normals (sign arbitrary) of solids with vertices (..., V, 3)."""
    f0 = np.array([f[0] for f in s.faces])
    f1 = np.array([f[1] for f in s.faces])
    f2 = np.array([f[2] for f in s.faces])
    n = np.cross(verts[..., f1, :] - verts[..., f0, :], verts[..., f2, :] - verts[..., f0, :])
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def edge_directions(s: Solid, verts: np.ndarray) -> np.ndarray:
    """(..., D, 3) unit directions of the non-parallel edges of solids with vertices (..., V, 3)."""
    d = verts[..., s.edge_dirs[:, 1], :] - verts[..., s.edge_dirs[:, 0], :]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _overlap(axes: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Overlap of the projections of a and b (P, V, 3) on axes (P, A, 3): (P, A)."""
    pa = axes @ a.transpose(0, 2, 1)
    pb = axes @ b.transpose(0, 2, 1)
    return np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))


def sat_intrudes(a, a_normals, a_edges, b, b_normals, b_edges, tol: float = 1e-9) -> np.ndarray:
    """Separating-axis intrusion test of P pairs with precomputed normals and edge directions.

    ``a`` and ``b`` (P, V, 3) with normals (P, F, 3) and edge directions
    (P, D, 3).  Returns (P,) bool: True where the interiors of pair p
    overlap by more than ``tol`` on every candidate axis (face normals of
    both, cross products of an edge of each).  Face axes are tried first;
    edge–edge axes only for the pairs they do not separate.
    """
    P = len(b)
    if P == 0:
        return np.zeros(0, dtype=bool)
    axes = np.concatenate([a_normals, b_normals], axis=1)
    hit = (_overlap(axes, a, b) > tol).all(axis=1)
    idx = np.flatnonzero(hit)
    if len(idx) == 0:
        return hit
    ea = a_edges[idx][:, :, None, :]
    eb = b_edges[idx][:, None, :, :]
    cross = np.stack([
        ea[..., 1] * eb[..., 2] - ea[..., 2] * eb[..., 1],
        ea[..., 2] * eb[..., 0] - ea[..., 0] * eb[..., 2],
        ea[..., 0] * eb[..., 1] - ea[..., 1] * eb[..., 0],
    ], axis=-1).reshape(len(idx), -1, 3)
    length = np.sqrt((cross**2).sum(-1))[..., None]
    # parallel edges give no axis: use a face normal instead (already tested, overlapping)
    cross = np.where(length > 1e-9, cross / np.where(length > 1e-9, length, 1.0), a_normals[idx][:, :1, :])
    hit[idx] = (_overlap(cross, a[idx], b[idx]) > tol).all(axis=1)
    return hit


def sat_gap(a, a_normals, a_edges, b, b_normals, b_edges, reach: float) -> np.ndarray:
    """Separating-axis gap of P pairs of convex solids (same inputs as :func:`sat_intrudes`).

    The gap is the largest separation of the projections over the candidate
    axes (face normals of both, cross products of an edge of each): negative
    when the solids overlap (minus the overlap depth), 0 when they touch, and
    a lower bound on their distance when positive.  Edge–edge axes are only
    computed for the pairs whose face axes give a gap below ``reach`` (for
    the others the face gap is returned).

    Examples
    --------
    >>> s = solid("cube")
    >>> v = s.vertices
    >>> b = np.stack([v + [1, 0, 0], v + [1.5, 0, 0], v + [0.75, 0, 0]])
    >>> a = np.broadcast_to(v, b.shape)
    >>> sat_gap(a, face_normals(s, a), edge_directions(s, a), b, face_normals(s, b),
    ...         edge_directions(s, b), 1.0).round(3).tolist()
    [-0.0, 0.5, -0.25]
    """
    P = len(b)
    if P == 0:
        return np.zeros(0)
    axes = np.concatenate([a_normals, b_normals], axis=1)
    gap = -_overlap(axes, a, b).min(axis=1)
    idx = np.flatnonzero(gap < reach)
    if len(idx) == 0:
        return gap
    ea = a_edges[idx][:, :, None, :]
    eb = b_edges[idx][:, None, :, :]
    cross = np.cross(ea, eb).reshape(len(idx), -1, 3)
    length = np.sqrt((cross**2).sum(-1))[..., None]
    cross = np.where(length > 1e-9, cross / np.where(length > 1e-9, length, 1.0), a_normals[idx][:, :1, :])
    gap[idx] = np.maximum(gap[idx], -_overlap(cross, a[idx], b[idx]).min(axis=1))
    return gap


def intrudes(s: Solid, a: np.ndarray, others: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Whether convex solid ``a`` intrudes into each of ``others`` (separating axis theorem).

    Two convex polyhedra are disjoint exactly when their projections on one
    of the candidate axes — the face normals of both and the cross products
    of one edge direction of each — do not overlap.  Here an overlap of at
    most ``tol`` (in units of the primary size) counts as separated, so
    solids that touch along a face, an edge or a vertex do not intrude.

    Parameters
    ----------
    s : Solid
        The shape both solids are congruent to (gives the face and edge lists).
    a : (V, 3) float64
        Vertices of the candidate.
    others : (M, V, 3) float64
        Vertices of the existing solids.
    tol : float
        Overlap depth tolerated (default 1e-9).

    Returns
    -------
    (M,) bool
        True where the interiors overlap by more than ``tol``.

    Examples
    --------
    >>> s = solid("cube")
    >>> v = s.vertices
    >>> intrudes(s, v, np.stack([v + [1, 0, 0], v + [0.5, 0, 0], v + [1, 1, 1]])).tolist()
    [False, True, False]
    """
    a = np.asarray(a, dtype=np.float64)
    others = np.asarray(others, dtype=np.float64).reshape(-1, len(a), 3)
    aa = np.broadcast_to(a, others.shape)
    return sat_intrudes(aa, face_normals(s, aa), edge_directions(s, aa),
                        others, face_normals(s, others), edge_directions(s, others), tol)
