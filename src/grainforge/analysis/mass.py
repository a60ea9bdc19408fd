"""Mass properties of closed triangle meshes: volume, area, centroid, second moments.

Used by :mod:`grainforge.analysis.descriptors` and :mod:`grainforge.analysis.fourier`;
a module of its own so that ``fourier`` does not import ``descriptors`` (which imports ``fourier``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mass_properties", "principal_moments"]


def mass_properties(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """Volume, area, centroid and second central moments of a closed triangle mesh.

    Signed tetrahedra from the vertex mean: ∫x xᵀ dV over a tetrahedron
    (0, a, b, c) is (V/20)(aaᵀ + bbᵀ + ccᵀ + ssᵀ) with s = a + b + c.

    Returns
    -------
    dict
        ``volume``, ``area``, ``centroid`` (3,), ``covariance`` (3, 3): the
        second central moment per unit volume (its trace is R_g²), and
        ``face_areas`` (F,).
    """
    from ..solid import cross3

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    o = v.mean(0)
    a, b, c = v[f[:, 0]] - o, v[f[:, 1]] - o, v[f[:, 2]] - o
    cr = cross3(b - a, c - a)
    face_areas = 0.5 * np.linalg.norm(cr, axis=1)
    vol6 = np.einsum("ij,ij->i", a, cross3(b, c))
    V = vol6.sum() / 6.0
    s = a + b + c
    if V != 0:
        centroid_o = (vol6[:, None] * s).sum(0) / (24.0 * V)
        w = vol6 / 120.0
        X = np.concatenate([a, b, c, s])
        # einsum, not BLAS: a threaded BLAS call on this skinny product is slow on a busy machine
        second = np.einsum("ti,tj->ij", X * np.tile(w, 4)[:, None], X)
        cov = second / V - np.outer(centroid_o, centroid_o)
    else:
        centroid_o = np.zeros(3)
        cov = np.zeros((3, 3))
    return {
        "volume": float(V), "area": float(face_areas.sum()), "centroid": centroid_o + o,
        "covariance": cov, "face_areas": face_areas,
    }


def principal_moments(v: np.ndarray, f: np.ndarray, mp: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centre and covariance for principal axes: the solid's if it has volume, else the surface's."""
    if mp is None:
        mp = mass_properties(v, f)
    if mp["volume"] > 0 and np.all(np.linalg.eigvalsh(mp["covariance"]) > 0):
        return mp["centroid"], mp["covariance"]
    fa = mp["face_areas"]
    cen = v[f].mean(1)
    wsum = fa.sum() or 1.0
    c0 = (fa[:, None] * cen).sum(0) / wsum
    d = cen - c0
    return c0, np.einsum("t,ti,tj->ij", fa, d, d) / wsum
