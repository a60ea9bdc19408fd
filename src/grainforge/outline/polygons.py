"""Closed polygons in the plane: their area centroid, and the rays cast from it.

The polygon side of a grain's outline (:mod:`grainforge.outline.contours` turns the radii into a
:class:`~grainforge.outline.contours.Contour`): the shoelace area centroid
(:func:`polygon_area_centroid`, the one implementation) and the outermost crossing of regularly spaced rays
from the origin (:func:`ray_cast`), both on the polygon's vertices as they are, without a raster.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["polygon_area_centroid", "area_centroid", "ray_cast"]

TWO_PI = 2.0 * np.pi


def polygon_area_centroid(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Signed area and area centroid ``(area, cx, cy)`` of the closed polygon (x, y) (shoelace formula).

    The one implementation of a polygon's centroid; each caller decides what a polygon of (near) zero
    area means. With zero area the centroid is NaN.

    Parameters
    ----------
    x, y : (P,) ndarray of float
        Vertex coordinates in order; the closing edge is implied.

    Returns
    -------
    area : float
        Signed area (positive counter-clockwise), in the square of the coordinates' unit.
    cx, cy : float
        Area centroid (NaN when ``area`` is exactly 0).

    Examples
    --------
    >>> polygon_area_centroid(np.array([0.0, 2.0, 2.0, 0.0]), np.array([0.0, 0.0, 1.0, 1.0]))
    (2.0, 1.0, 0.5)
    """
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = float(cross.sum() / 2.0)
    if area == 0.0:
        return 0.0, float("nan"), float("nan")
    return area, float(((x + x1) * cross).sum() / (6.0 * area)), float(((y + y1) * cross).sum() / (6.0 * area))


def area_centroid(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Area centroid of the closed polygon (x, y) (:func:`polygon_area_centroid`), refusing one without area.

    Parameters
    ----------
    x, y : (P,) ndarray of float
        Vertex coordinates in order; the closing edge is implied.

    Returns
    -------
    cx, cy : float
        The area centroid.

    Raises
    ------
    ValueError
        If the polygon encloses no area.
    """
    area, cx, cy = polygon_area_centroid(x, y)
    if abs(area) < 1e-12:
        raise InputError("grain is too small to trace a contour")
    return cx, cy


def ray_cast(x: np.ndarray, y: np.ndarray, n_angles: int) -> tuple[np.ndarray, bool]:
    """Outermost crossing of each ray from the origin with the closed polygon (x, y).

    Each edge is intersected only with the rays inside its angular span
    (θ in [lo, hi), usually zero or one ray per edge), so the cost is
    O(edges + crossings) rather than O(edges × rays).

    The angle is unwrapped along the polygon, in units of the ray step, and
    the end of each edge is *the same number* as the start of the next (the
    closing vertex is the first one plus whole turns), so a ray that passes
    exactly through a vertex (common for outlines traced through pixel
    corners, e.g. at θ = 0 or π) belongs to exactly one of its two edges.

    Parameters
    ----------
    x, y : (P,) ndarray of float
        Vertex coordinates in order, relative to the origin of the rays; the closing edge is implied.
    n_angles : int
        Rays at θ_j = 2πj/n_angles.

    Returns
    -------
    radii : (n_angles,) float64
        The outermost crossing's distance along each ray.
    star : bool
        Every ray crosses the polygon once: the polygon is star-shaped from the origin.

    Raises
    ------
    ValueError
        If a ray crosses no edge (the polygon does not enclose the origin).

    Examples
    --------
    >>> diamond = np.array([[2.0, 0.0], [0.0, 1.0], [-2.0, 0.0], [0.0, -1.0]])  # vertices on the rays 0, π/2, …
    >>> r, star = ray_cast(diamond[:, 0], diamond[:, 1], 8)
    >>> np.round(r, 4).tolist(), star
    ([2.0, 0.9428, 1.0, 0.9428, 2.0, 0.9428, 1.0, 0.9428], True)
    >>> r2, _ = ray_cast(diamond[::-1, 0], -diamond[::-1, 1] + 0.0, 8)  # clockwise, y = -0.0 on the x axis
    >>> bool(np.allclose(r2, r))
    True
    """
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    step = TWO_PI / n_angles
    a0 = np.arctan2(y, x)
    du = (np.mod(np.arctan2(y1, x1) - a0 + np.pi, TWO_PI) - np.pi) / step  # signed step of each edge, in rays
    u = np.empty(len(x) + 1)
    u[0] = a0[0] / step
    if abs(u[0] - np.rint(u[0])) < 1e-9:
        # on a ray (to rounding): make it exactly so, else u[0] + turns·n_angles can round onto the
        # ray while u[0] stays just past it, and that ray is missed by both the first and last edge
        u[0] = np.rint(u[0])
    u[1:] = u[0] + np.cumsum(du)
    turns = np.rint((u[-1] - u[0]) / n_angles)
    u[-1] = u[0] + turns * n_angles  # the polygon closes: the last edge ends where the first begins
    lo = np.minimum(u[:-1], u[1:])
    hi = np.maximum(u[:-1], u[1:])
    k0 = np.ceil(lo).astype(np.int64)
    k1 = np.ceil(hi).astype(np.int64)  # rays k with lo <= k < hi
    count = np.maximum(k1 - k0, 0)
    edge = np.repeat(np.arange(len(x)), count)
    k = np.repeat(k0 - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
    t = k * step
    dx, dy = np.cos(t), np.sin(t)
    px, py = x[edge], y[edge]
    ex, ey = x1[edge] - px, y1[edge] - py
    den = dx * ey - dy * ex  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = (px * ey - py * ex) / den  # ray: s·d = p + u·e
    ok = np.isfinite(dist) & (dist > 0)
    ray = np.mod(k[ok], n_angles)
    radii = np.full(n_angles, -np.inf)
    np.maximum.at(radii, ray, dist[ok])
    if not np.isfinite(radii).all():
        raise InputError("grain boundary does not enclose its centroid; cannot cast rays")
    star = bool((np.bincount(ray, minlength=n_angles) == 1).all())
    return radii, star
