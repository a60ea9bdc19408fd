"""Fourier descriptors of 2D outlines and of a 3D grain's principal projections.

The 2D convention is Mollon & Zhao (2012), ALGORITHMS.md §2b: from the area
centroid of the outline, ``N = 128`` rays at θ_j = 2πj/N give the radii
r_j (outermost crossing); with c = rfft(r)/N, r0 = c0 and D_n = 2|c_n|/r0.

For a 3D grain the outline is the silhouette of the mesh projected on each of
its three principal planes (L–I, L–S, I–S, axes from the volume inertia), so
printed, scanned or generated grains can be compared with descriptors
measured on micrographs.  The silhouette is rasterised (see
:func:`grainforge.render.silhouette`) and traced with
``skimage.measure.find_contours``.

This module duplicates on purpose the image → contour → descriptor step that
:mod:`grainforge.contours` provides for micrographs; the two can be merged.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "N_RAYS", "FD_ORDERS", "PLANES", "radii_from_polygon", "radii_from_mask", "descriptors_from_radii",
    "principal_axes", "projection_descriptors", "fd_columns",
]

#: rays cast from the centroid (ALGORITHMS.md §2b)
N_RAYS = 128
#: the descriptor orders reported
FD_ORDERS = tuple(range(2, 17))
#: principal planes, as pairs of principal axes (0 = longest, 2 = shortest)
PLANES = {"LI": (0, 1), "LS": (0, 2), "IS": (1, 2)}


def fd_columns() -> list[str]:
    """Names of the projection descriptor columns: ``fd_LI_2`` … ``fd_IS_16``.

    Examples
    --------
    >>> fd_columns()[:2], len(fd_columns())
    (['fd_LI_2', 'fd_LI_3'], 45)
    """
    return [f"fd_{p}_{n}" for p in PLANES for n in FD_ORDERS]


def _polygon_centroid(poly: np.ndarray) -> np.ndarray:
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    a = cross.sum() / 2
    if abs(a) < 1e-300:
        return poly.mean(0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * a)


def radii_from_polygon(poly: np.ndarray, n_rays: int = N_RAYS) -> tuple[np.ndarray, bool]:
    """Radii of a closed polygon along ``n_rays`` rays from its area centroid.

    Parameters
    ----------
    poly : (P, 2) float64
        Vertices in order (closing edge implied; a repeated last point is fine).
    n_rays : int

    Returns
    -------
    r : (n_rays,) float64
        Distance to the outermost crossing along θ_j = 2πj/n_rays.
    star_shaped : bool
        True if every ray crosses the outline exactly once.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    >>> r, star = radii_from_polygon(np.c_[2 * np.cos(t), 2 * np.sin(t)])
    >>> bool(np.allclose(r, 2, atol=1e-3)), star
    (True, True)
    """
    p = np.asarray(poly, dtype=np.float64)
    if len(p) > 1 and np.allclose(p[0], p[-1]):
        p = p[:-1]
    if len(p) < 3:
        raise ValueError("an outline needs at least 3 points")
    p = p - _polygon_centroid(p)
    q = np.roll(p, -1, axis=0)
    e = q - p  # edges
    th = 2 * np.pi * np.arange(n_rays) / n_rays
    u = np.stack([np.cos(th), np.sin(th)], 1)  # (N, 2)
    # ray t·u = p + s·e  ->  solve for t (along ray) and s in [0, 1) (along edge)
    den = u[:, None, 0] * (-e[None, :, 1]) - u[:, None, 1] * (-e[None, :, 0])  # det[u, -e]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p[None, :, 0] * (-e[None, :, 1]) - p[None, :, 1] * (-e[None, :, 0])) / den
        s = (u[:, None, 0] * p[None, :, 1] - u[:, None, 1] * p[None, :, 0]) / den
    tol = 1e-9
    ok = (np.abs(den) > 1e-15) & (s >= -tol) & (s < 1 + tol) & (t > 0)
    r = np.where(ok, t, -np.inf).max(1)
    if not np.all(np.isfinite(r)):
        raise ValueError("the outline does not surround its centroid")
    # star-shaped: no crossing other than the outermost one (a vertex hit counts once)
    inner = ok & (t < r[:, None] * (1 - 1e-7))
    return r, not bool(inner.any())


def radii_from_mask(mask: np.ndarray, n_rays: int = N_RAYS) -> tuple[np.ndarray, bool]:
    """Radii of the largest object in a binary image (holes ignored), see :func:`radii_from_polygon`.

    Examples
    --------
    >>> yy, xx = np.mgrid[:101, :101]
    >>> disk = (xx - 50) ** 2 + (yy - 50) ** 2 <= 40**2
    >>> r, star = radii_from_mask(disk)
    >>> bool(abs(r.mean() - 40.5) < 0.5), star
    (True, True)
    """
    from skimage.measure import find_contours

    m = np.pad(np.asarray(mask, dtype=np.float64), 1)
    if not m.any():
        raise ValueError("the image holds no object")
    contours = find_contours(m, 0.5)
    longest = max(contours, key=len)
    return radii_from_polygon(longest[:, ::-1], n_rays)


def descriptors_from_radii(r: np.ndarray, orders=FD_ORDERS) -> np.ndarray:
    """Fourier descriptors D_n = 2|c_n|/c_0 of equally spaced radii (c = rfft(r)/N).

    Examples
    --------
    >>> th = 2 * np.pi * np.arange(128) / 128
    >>> r = 1 + 0.2 * np.cos(2 * th - 1.0) + 0.05 * np.cos(8 * th)
    >>> np.round(descriptors_from_radii(r, orders=(2, 3, 8)), 6).tolist()
    [0.2, 0.0, 0.05]
    """
    r = np.asarray(r, dtype=np.float64)
    c = np.fft.rfft(r) / len(r)
    r0 = c[0].real
    if not r0 > 0:
        raise ValueError("mean radius must be positive")
    orders = np.asarray(orders)
    if orders.max() >= len(c):
        raise ValueError(f"order {int(orders.max())} needs more than {len(r)} radii")
    return 2 * np.abs(c[orders]) / r0


def principal_axes(vertices: np.ndarray, faces: np.ndarray, mass=None) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and principal axes (rows, longest first) of a mesh.

    For a closed mesh with positive volume the axes are those of the solid's
    second moments; otherwise of the area-weighted surface.

    ``mass`` may pass precomputed :func:`~grainforge.analysis.descriptors.mass_properties`.

    Returns
    -------
    centre : (3,) float64
    axes : (3, 3) float64
        Orthonormal rows, in order of decreasing spread (right-handed).
    """
    from .descriptors import _moments

    centre, cov = _moments(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), mass)
    w, vec = np.linalg.eigh(cov)
    axes = vec[:, ::-1].T.copy()
    # deterministic signs: each axis points towards its farthest vertex
    proj = (vertices - centre) @ axes.T
    flip = np.abs(proj.max(0)) < np.abs(proj.min(0))
    axes[flip] *= -1
    if np.linalg.det(axes) < 0:
        axes[2] *= -1
    return centre, axes


def projection_descriptors(
    vertices, faces, *, size: int = 256, orders=FD_ORDERS, axes=None, closed: bool = False,
) -> dict[str, float]:
    """Fourier descriptors of the silhouettes on the three principal planes.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    size : int
        Silhouette image size in pixels (the object spans ``size − 8``).
    orders : sequence of int
        Descriptor orders (default 2…16).
    axes : (centre, axes), optional
        Precomputed :func:`principal_axes`.
    closed : bool
        The mesh is closed and outward-oriented: only the triangles facing
        each view are rasterised (the silhouette is the same, at half the cost).

    Returns
    -------
    dict
        ``fd_LI_n``, ``fd_LS_n``, ``fd_IS_n`` for each order n, and
        ``fd_star_shaped`` (1.0 if the three silhouettes are star-shaped from
        their centroids, else 0.0).

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(4)
    >>> _ = e.apply_scale((2.0, 1.0, 1.0))
    >>> d = projection_descriptors(e.vertices, e.faces)
    >>> round(d["fd_LI_2"], 2), round(d["fd_IS_2"], 2)  # 2:1 ellipse (exact 0.338), circle
    (0.34, 0.0)
    """
    from ..render import silhouette

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    centre, ax = axes if axes is not None else principal_axes(v, f)
    p = (v - centre) @ ax.T
    out: dict[str, float] = {}
    star = True
    for name, (i, j) in PLANES.items():
        ff = f
        if closed:
            q = p[:, [i, j]]
            a, b, c = q[f[:, 0]], q[f[:, 1]], q[f[:, 2]]
            area2 = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
            ff = f[area2 >= 0]
        mask = silhouette(p[:, [i, j]], ff, size=size)
        r, s = radii_from_mask(mask)
        star &= s
        for n, d in zip(orders, descriptors_from_radii(r, orders)):
            out[f"fd_{name}_{n}"] = float(d)
    out["fd_star_shaped"] = 1.0 if star else 0.0
    return out
