"""Geodesic (icosahedral) spheres and spherical coordinates."""

from __future__ import annotations

from functools import cache

import numpy as np

from ..errors import InputError

__all__ = ["icosphere", "spherical", "MAX_SUBDIVISIONS"]

MAX_SUBDIVISIONS = 8


@cache
def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(ico.vertices, dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.asarray(ico.faces, dtype=np.int64)
    v.setflags(write=False)
    f.setflags(write=False)
    return v, f


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit geodesic sphere: an icosahedron subdivided ``subdivisions`` times.

    Parameters
    ----------
    subdivisions : int
        0 to 8; the sphere has ``10 * 4**subdivisions + 2`` vertices.

    Returns
    -------
    vertices : (V, 3) float64
        Unit vectors (read-only, cached).
    faces : (F, 3) int64
        Outward-oriented triangles (read-only, cached).

    Raises
    ------
    ValueError
        If ``subdivisions`` is outside [0, 8].

    Examples
    --------
    >>> v, f = icosphere(5)
    >>> len(v), len(f)
    (10242, 20480)
    """
    s = int(subdivisions)
    if not 0 <= s <= MAX_SUBDIVISIONS:
        raise InputError(f"subdivisions must be in [0, {MAX_SUBDIVISIONS}], got {subdivisions!r}")
    return _icosphere(s)


def spherical(unit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth θ ∈ [0, 2π) and polar angle φ ∈ [0, π] of unit vectors.

    Parameters
    ----------
    unit : (V, 3) float64

    Returns
    -------
    theta, phi : (V,) float64

    Examples
    --------
    >>> t, p = spherical(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]))
    >>> np.round(t, 4).tolist(), np.round(p, 4).tolist()
    ([1.5708, 0.0], [1.5708, 3.1416])
    """
    theta = np.mod(np.arctan2(unit[:, 1], unit[:, 0]), 2 * np.pi)
    phi = np.arccos(np.clip(unit[:, 2], -1.0, 1.0))
    return theta, phi
