"""Volume, area, centroid and second moments of closed triangle meshes (:func:`mesh_moments`).

Used by :mod:`grainforge.analysis.descriptors` and :mod:`grainforge.analysis.fourier`;
a module of its own so that ``fourier`` does not import ``descriptors`` (which imports ``fourier``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mesh_moments", "principal_moments"]


def mesh_moments(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """Volume, area, centroid and second central moments of a closed triangle mesh.

    The integrals are :func:`grainforge.geometry.solid.second_moments` (the one
    implementation, shared with :func:`grainforge.dem.massprops.mass_properties`);
    this adds the surface area and per-face areas, and does not reject a
    non-positive volume (``analyse`` reports open and inverted bodies).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    dict
        ``volume``, ``area``, ``centroid`` (3,), ``covariance`` (3, 3): the
        second central moment per unit volume (its trace is R_g²), and
        ``face_areas`` (F,).
    """
    from ..geometry.solid import cross3, second_moments

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    o = v.mean(0)
    a, b, c = v[f[:, 0]] - o, v[f[:, 1]] - o, v[f[:, 2]] - o  # from the vertex mean, as the moments
    face_areas = 0.5 * np.linalg.norm(cross3(b - a, c - a), axis=1)
    V, centroid, second = second_moments(v, f)
    cov = second / V if V != 0 else second
    return {
        "volume": float(V), "area": float(face_areas.sum()), "centroid": centroid,
        "covariance": cov, "face_areas": face_areas,
    }


def principal_moments(v: np.ndarray, f: np.ndarray, mp: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centre and covariance for principal axes: the solid's if it has volume, else the surface's.

    Parameters
    ----------
    v : (V, 3) ndarray of float
        Vertices.
    f : (F, 3) ndarray of int
        Faces.
    mp : dict, optional
        :func:`mesh_moments` of the mesh, if computed already.

    Returns
    -------
    centre : (3,) float64
        Volume or area centroid.
    covariance : (3, 3) float64
        Per unit volume (or area), in the square of the vertices' unit.
    """
    if mp is None:
        mp = mesh_moments(v, f)
    if mp["volume"] > 0 and np.all(np.linalg.eigvalsh(mp["covariance"]) > 0):
        return mp["centroid"], mp["covariance"]
    fa = mp["face_areas"]
    cen = v[f].mean(1)
    wsum = fa.sum() or 1.0
    c0 = (fa[:, None] * cen).sum(0) / wsum
    d = cen - c0
    return c0, np.einsum("t,ti,tj->ij", fa, d, d) / wsum
