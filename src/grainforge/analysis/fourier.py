"""Fourier descriptors of 2D outlines and of a 3D grain's principal projections.

The 2D convention is Mollon & Zhao (2012), docs/design/algorithms.md §2b: from the area
centroid of the outline, ``N = 128`` rays at θ_j = 2πj/N give the radii
r_j (outermost crossing); with c = rfft(r)/N, r0 = c0 and D_n = 2|c_n|/r0.

For a 3D grain the outline is the silhouette of the mesh projected on each of
its three principal planes (L–I, L–S, I–S, axes from the volume inertia), so
printed, scanned or generated grains can be compared with descriptors
measured on micrographs.  The silhouette radii are computed exactly from the
projected triangles (:func:`silhouette_radii`), not from a raster, so they
carry no pixel noise.  Outlines given as polygons or images (micrographs)
go through :func:`grainforge.outline.contours.polygon_contour` and
:func:`grainforge.outline.contours.mask_contour`, with the same convention.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = [
    "N_RAYS", "FD_ORDERS", "PLANES", "descriptors_from_radii",
    "principal_axes", "silhouette_radii", "projection_descriptors", "fd_columns",
    "MICROGRAPH_COLUMNS", "MICROGRAPH_MM_COLUMNS", "RAY_BYTES", "RAY_MEMORY", "check_rays", "micrograph_rows",
]

#: rays cast from the centroid (docs/design/algorithms.md §2b)
N_RAYS = 128
#: the descriptor orders reported
FD_ORDERS = tuple(range(2, 17))
#: principal planes, as pairs of principal axes (0 = longest, 2 = shortest)
PLANES = {"LI": (0, 1), "LS": (0, 2), "IS": (1, 2)}


def fd_columns() -> list[str]:
    """Names of the projection descriptor columns: ``fd_LI_2`` … ``fd_IS_16``.

    Returns
    -------
    list of str
        ``fd_{plane}_{n}`` for the planes LI, LS, IS and the orders :data:`FD_ORDERS`.

    Examples
    --------
    >>> fd_columns()[:2], len(fd_columns())
    (['fd_LI_2', 'fd_LI_3'], 45)
    """
    return [f"fd_{p}_{n}" for p in PLANES for n in FD_ORDERS]


def _polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid of the closed polygon ``poly`` (:func:`grainforge.outline.contours.polygon_area_centroid`); the
    vertices' mean when it encloses no area."""
    from ..outline.contours import polygon_area_centroid

    a, cx, cy = polygon_area_centroid(poly[:, 0], poly[:, 1])
    if abs(a) < 1e-300:
        return poly.mean(0)
    return np.array([cx, cy])


def descriptors_from_radii(r: np.ndarray, orders=FD_ORDERS) -> np.ndarray:
    """Fourier descriptors D_n = 2|c_n|/c_0 of equally spaced radii (c = rfft(r)/N).

    Parameters
    ----------
    r : (N,) array_like of float
        Radii at θ_j = 2πj/N, positive mean.
    orders : sequence of int, default FD_ORDERS
        The orders n wanted (each < N/2 + 1).

    Returns
    -------
    (len(orders),) float64

    Raises
    ------
    ValueError
        If the mean radius is not positive or an order is too high for N.

    Examples
    --------
    >>> th = 2 * np.pi * np.arange(128) / 128
    >>> r = 1 + 0.2 * np.cos(2 * th - 1.0) + 0.05 * np.cos(8 * th)
    >>> np.round(descriptors_from_radii(r, orders=(2, 3, 8)), 6).tolist()
    [0.2, 0.0, 0.05]
    """
    from ..outline.contours import descriptors_of_radii

    r = np.asarray(r, dtype=np.float64)
    if not r.mean() > 0:
        raise InputError("mean radius must be positive")
    orders = np.asarray(orders)
    if orders.max() >= len(r) // 2 + 1:
        raise InputError(f"order {int(orders.max())} needs more than {len(r)} radii")
    return descriptors_of_radii(r)[orders]


def principal_axes(vertices: np.ndarray, faces: np.ndarray, mass=None) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and principal axes (rows, longest first) of a mesh.

    For a closed mesh with positive volume the axes are those of the solid's
    second moments; otherwise of the area-weighted surface.

    ``mass`` may pass precomputed :func:`~grainforge.analysis.mass.mesh_moments`.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    mass : dict, optional
        :func:`~grainforge.analysis.mass.mesh_moments` of the mesh, if computed already.

    Returns
    -------
    centre : (3,) float64
    axes : (3, 3) float64
        Orthonormal rows, in order of decreasing spread (right-handed).
    """
    from .mass import principal_moments

    centre, cov = principal_moments(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), mass)
    w, vec = np.linalg.eigh(cov)
    axes = vec[:, ::-1].T.copy()
    # deterministic signs: each axis points towards its farthest vertex
    proj = np.einsum("vi,ji->vj", vertices - centre, axes)
    flip = np.abs(proj.max(0)) < np.abs(proj.min(0))
    axes[flip] *= -1
    if np.linalg.det(axes) < 0:
        axes[2] *= -1
    return centre, axes


def silhouette_radii(
    points: np.ndarray, faces: np.ndarray, *, origin, n_rays: int = N_RAYS, rays: np.ndarray | None = None,
) -> tuple[np.ndarray, bool]:
    """Outermost crossing of the silhouette of projected triangles along rays from ``origin``.

    The silhouette is the union of the triangles ``points[faces]``; along
    each ray θ_j = 2πj/n_rays its radius is the farthest point of any
    triangle the ray meets, computed exactly from the triangle edges (no
    rasterisation).  Each triangle is only tested against the few rays inside
    its angular span, so the cost is proportional to the number of triangles.

    Parameters
    ----------
    points : (V, 2) float64
        Projected vertices.
    faces : (F, 3) int64
        Triangles (any orientation).
    origin : (2,) float64
        Where the rays start.
    n_rays : int, default N_RAYS
        Rays θ_j = 2πj/n_rays.
    rays : (n_rays,) bool, optional
        Only trace these rays (the others get NaN radii).

    Returns
    -------
    r : (n_rays,) float64
    star_shaped : bool
        True if every ray is covered by the silhouette from the origin to its
        outermost crossing (no gap: the outline is crossed once).

    Raises
    ------
    ValueError
        If some ray meets no triangle (the origin is outside the silhouette).

    Examples
    --------
    >>> sq = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    >>> r, star = silhouette_radii(sq, np.array([[0, 1, 2], [0, 2, 3]]), origin=(0.0, 0.0), n_rays=8)
    >>> np.round(r, 6).tolist()[:2], star
    ([1.0, 1.414214], True)
    """
    q = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    wanted = np.ones(n_rays, bool) if rays is None else np.asarray(rays, dtype=bool)
    step = 2 * np.pi / n_rays
    # corner coordinates, one (F,) array per corner; the angles once per vertex
    x, y = q[:, 0], q[:, 1]
    ang = np.arctan2(y, x)
    i0, i1, i2 = f[:, 0], f[:, 1], f[:, 2]
    x0, x1, x2, y0, y1, y2 = x[i0], x[i1], x[i2], y[i0], y[i1], y[i2]
    a0 = ang[i0]
    d1, d2 = _wrap(ang[i1] - a0), _wrap(ang[i2] - a0)  # relative to the first corner
    lo = a0 + np.minimum(np.minimum(d1, d2), 0.0)
    hi = a0 + np.maximum(np.maximum(d1, d2), 0.0)
    # triangles containing the origin see every ray
    c0 = (x1 - x0) * (-y0) - (y1 - y0) * (-x0)
    c1 = (x2 - x1) * (-y1) - (y2 - y1) * (-x1)
    c2 = (x0 - x2) * (-y2) - (y0 - y2) * (-x2)
    inside = ((c0 >= 0) & (c1 >= 0) & (c2 >= 0)) | ((c0 <= 0) & (c1 <= 0) & (c2 <= 0))
    k0 = np.where(inside, 0, np.ceil(lo / step - 1e-9).astype(np.int64))
    k1 = np.where(inside, n_rays - 1, np.floor(hi / step + 1e-9).astype(np.int64))
    # (triangle, ray) pairs for the rays within each triangle's angular span, wanted rays only
    tri_idx, ray = _span_pairs(k0, k1, n_rays)
    if rays is not None:
        keep = wanted[ray]
        ray, tri_idx = ray[keep], tri_idx[keep]
    th = step * np.arange(n_rays)
    ux, uy = np.cos(th)[ray], np.sin(th)[ray]
    X = (x0[tri_idx], x1[tri_idx], x2[tri_idx])
    Y = (y0[tri_idx], y1[tri_idx], y2[tri_idx])
    t_hi = np.full(len(ray), -np.inf)
    t_lo = np.full(len(ray), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for m in range(3):  # ray t·u = P + s·E for each edge P → P' of the triangle
            px, py = X[m], Y[m]
            ex, ey = X[(m + 1) % 3] - px, Y[(m + 1) % 3] - py
            den = uy * ex - ux * ey
            t = (py * ex - px * ey) / den
            sp = (ux * py - uy * px) / den
            ok = (sp >= -1e-9) & (sp <= 1 + 1e-9) & (t >= 0)  # NaN (parallel edge) compares False
            np.maximum(t_hi, np.where(ok, t, -np.inf), out=t_hi)
            np.minimum(t_lo, np.where(ok, t, np.inf), out=t_lo)
    t_lo[inside[tri_idx]] = 0.0
    hit = np.isfinite(t_hi)
    ray, t_lo, t_hi = ray[hit], t_lo[hit], t_hi[hit]
    r = np.full(n_rays, -np.inf)
    np.maximum.at(r, ray, t_hi)
    if not np.all(np.isfinite(r[wanted])):
        raise InputError("the silhouette does not surround its centroid")
    r[~wanted] = np.nan
    if len(ray) == 0:
        return r, True
    # star-shaped: per ray, the union of [t_lo, t_hi] covers [0, r] without a gap
    big = 4.0 * float(r.max()) + 1.0
    s_ = t_lo + ray * big
    o = _stable_argsort(s_)
    s_, e_, ray_o = s_[o], t_hi[o] + ray[o] * big, ray[o]
    reach = np.maximum.accumulate(e_)
    first = np.r_[True, ray_o[1:] != ray_o[:-1]]
    tol = 1e-9 * big
    gap_first = first & (t_lo[o] > tol)
    gap_next = ~first & (s_ > np.r_[-np.inf, reach[:-1]] + tol)
    return r, not bool(gap_first.any() or gap_next.any())


def _wrap(d: np.ndarray) -> np.ndarray:
    """Angle differences in [−2π, 2π] wrapped to [−π, π] (unchanged when already there)."""
    return np.where(d > np.pi, d - 2 * np.pi, np.where(d < -np.pi, d + 2 * np.pi, d))


def _span_pairs(k0: np.ndarray, k1: np.ndarray, n_rays: int) -> tuple[np.ndarray, np.ndarray]:
    """Expand index spans [k0_i, k1_i] (empty if k1 < k0) into (item, ray mod n_rays) pairs."""
    count = np.maximum(k1 - k0 + 1, 0)
    item = np.repeat(np.arange(len(k0)), count)
    # k = k0 + (position − position of the item's first pair)
    k = np.arange(len(item))
    k -= (np.cumsum(count) - count - k0)[item]
    if len(k) and -n_rays <= k.min() and k.max() < 2 * n_rays:  # always so for angles in [−2π, 2π]
        k += np.where(k < 0, n_rays, np.where(k >= n_rays, -n_rays, 0))  # much cheaper than np.mod
        return item, k
    return item, np.mod(k, n_rays)


def _stable_argsort(a: np.ndarray) -> np.ndarray:
    """``np.argsort(a, kind="stable")``, through the faster default sort when ``a`` has no ties."""
    o = np.argsort(a)
    s = a[o]
    if np.any(s[1:] == s[:-1]):
        o = np.argsort(a, kind="stable")
    return o


def _polygon_area_centroid_of_radii(r: np.ndarray, origin: np.ndarray) -> np.ndarray:
    th = 2 * np.pi * np.arange(len(r)) / len(r)
    return origin + _polygon_centroid(np.stack([r * np.cos(th), r * np.sin(th)], 1))


def _edge_faces(faces: np.ndarray):
    """Undirected edges shared by exactly two faces: (E, 2) vertex pairs and (E, 2) face indices."""
    f = np.asarray(faces, dtype=np.int64)
    a = f.ravel()  # half-edge h = 3·face + corner runs from a[h] to b[h]
    b = f[:, [1, 2, 0]].ravel()
    n, m = int(f.max()) + 1, len(a)
    key = np.minimum(a, b)
    key *= n
    key += np.maximum(a, b)  # min·n + max: the undirected edge
    if n * n * m < 2**62:
        # stable argsort of the keys as one plain sort of key·m + h (faster than a stable argsort)
        key *= m
        key += np.arange(m)
        key.sort()
        k, o = np.divmod(key, m)
    else:
        o = np.argsort(key, kind="stable")
        k = key[o]
    pair = np.flatnonzero(k[1:] == k[:-1])  # runs of equal keys: the half-edges of one edge
    lo, hi = np.divmod(k[pair], n)
    return np.stack([lo, hi], 1), np.stack([o[pair] // 3, o[pair + 1] // 3], 1)


def _outline_radii(q: np.ndarray, edges: np.ndarray, n_rays: int):
    """Outermost crossing of segments q[edges] along rays from the origin (NaN where none),
    and per ray the number of crossings nearer than the outermost one."""
    step = 2 * np.pi / n_rays
    xa, ya = q[edges[:, 0], 0], q[edges[:, 0], 1]
    xb, yb = q[edges[:, 1], 0], q[edges[:, 1], 1]
    ang = np.arctan2(ya, xa)
    d = _wrap(np.arctan2(yb, xb) - ang)
    lo = ang + np.minimum(d, 0)
    hi = ang + np.maximum(d, 0)
    idx, ray = _span_pairs(np.ceil(lo / step - 1e-9).astype(np.int64), np.floor(hi / step + 1e-9).astype(np.int64), n_rays)
    th = step * np.arange(n_rays)
    ux, uy = np.cos(th)[ray], np.sin(th)[ray]
    px, py = xa[idx], ya[idx]
    ex, ey = xb[idx] - px, yb[idx] - py
    with np.errstate(divide="ignore", invalid="ignore"):
        den = uy * ex - ux * ey
        t = (py * ex - px * ey) / den
    r = np.full(n_rays, -np.inf)
    ok = np.isfinite(t) & (t >= 0)
    np.maximum.at(r, ray[ok], t[ok])
    inner = ok & (t < r[ray] * (1 - 1e-7))
    return np.where(np.isfinite(r), r, np.nan), np.bincount(ray[inner], minlength=n_rays)


def projection_descriptors(
    vertices, faces, *, orders=FD_ORDERS, axes=None, closed: bool = False, n_rays: int = N_RAYS,
) -> dict[str, float]:
    """Fourier descriptors of the silhouettes on the three principal planes.

    The mesh is projected on each principal plane and the silhouette radii are
    found exactly along ``n_rays`` rays (:func:`silhouette_radii`).  As in
    docs/design/algorithms.md §2b the origin is the silhouette's area centroid: the area
    centroid of the 512-ray outline polygon seen from the projected volume
    centroid (exact for star-shaped outlines up to the polygon sampling; for a
    closed mesh the outline is taken from the contour edges alone, which is
    much cheaper).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    orders : sequence of int
        Descriptor orders (default 2…16).
    axes : (centre, axes), optional
        Precomputed :func:`principal_axes`.
    closed : bool
        The mesh is closed and outward-oriented: only the triangles facing
        each view are used (the silhouette is the same, at half the cost).
    n_rays : int
        Rays per silhouette (default 128).

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
    >>> round(d["fd_LI_2"], 3), round(d["fd_IS_2"], 3)  # 2:1 ellipse (exact 0.338), circle
    (0.338, 0.0)
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    centre, ax = axes if axes is not None else principal_axes(v, f)
    p = np.einsum("vi,ji->vj", v - centre, ax)
    out: dict[str, float] = {}
    star = True
    if closed:
        edges, edge_faces = _edge_faces(f)
        # triangle sides b − a and c − a per principal coordinate, for the facing tests
        ab, ac = [], []
        for coord in p.T.copy():
            at = coord[f[:, 0]]
            ab.append(coord[f[:, 1]] - at)
            ac.append(coord[f[:, 2]] - at)
    for name, (i, j) in PLANES.items():
        q = p[:, [i, j]]
        origin = np.zeros(2)
        tris, r = f, None
        if closed:
            front = ab[i] * ac[j] - ab[j] * ac[i] >= 0  # twice the signed projected area
            tris = np.compress(front, f, axis=0)  # (compress: much faster than boolean indexing of rows)
            # the outline lies on the contour edges (between a front and a back face)
            contour = np.compress(front[edge_faces[:, 0]] != front[edge_faces[:, 1]], edges, axis=0)
            r_fine, _ = _outline_radii(q, contour, 512)
            if np.all(np.isfinite(r_fine)):
                origin = _polygon_area_centroid_of_radii(r_fine, origin)
                r, inner = _outline_radii(q - origin, contour, n_rays)
                # rays crossing no contour edge before the outermost one are
                # covered from the origin; only the others need the exact test
                s = True
                if not np.all(np.isfinite(r)):
                    r, s = silhouette_radii(q, tris, origin=origin, n_rays=n_rays)
                elif inner.any():
                    _, s = silhouette_radii(q, tris, origin=origin, n_rays=n_rays, rays=inner > 0)
        if r is None:  # open mesh, or no closed outline among the contour edges: the exact silhouette
            r_fine, _ = silhouette_radii(q, tris, origin=origin, n_rays=512)
            origin = _polygon_area_centroid_of_radii(r_fine, origin)
            r, s = silhouette_radii(q, tris, origin=origin, n_rays=n_rays)
        star &= s
        for n, d in zip(orders, descriptors_from_radii(r, orders)):
            out[f"fd_{name}_{n}"] = float(d)
    out["fd_star_shaped"] = 1.0 if star else 0.0
    return out


#: columns of a micrograph's rows (:func:`micrograph_rows`): positions and sizes state their unit, pixels (x to
#: the right from the left edge, y = −row: up); the descriptors are dimensionless
MICROGRAPH_COLUMNS = ["image", "grain", "x_px", "y_px", "area_px2", "r0_px", "star_shaped", "elongation",
                      "irregularity", "roughness"] + [f"D{n}" for n in FD_ORDERS]
#: the columns in millimetres that a pixel size adds (placed after ``image`` and ``grain``)
MICROGRAPH_MM_COLUMNS = ["x_mm", "y_mm", "area_mm2", "r0_mm"]
#: memory one ray costs while a grain's radii are cast (bytes; 1e8 rays held 5.9 GB)
RAY_BYTES = 64
#: largest memory the rays of one grain may take
RAY_MEMORY = 2 * 1024**3


def check_rays(rays: int) -> None:
    """Refuse a number of rays per grain whose radii would not fit in memory (estimated first).

    Parameters
    ----------
    rays : int
        Rays cast from each grain's area centroid (:func:`micrograph_rows`).

    Raises
    ------
    ValueError
        Above :data:`RAY_MEMORY` at :data:`RAY_BYTES` per ray; the message names the most rays that fit.

    Examples
    --------
    >>> check_rays(128)
    >>> check_rays(10**8)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: 100000000 rays need about 6.0 GiB per grain (limit 2 GiB); use at most 33554432 (the descriptors need only 34)
    """
    need = rays * RAY_BYTES
    if need > RAY_MEMORY:
        raise InputError(
            f"{rays} rays need about {need / 1024**3:.1f} GiB per grain (limit {RAY_MEMORY / 1024**3:.0f} GiB); "
            f"use at most {RAY_MEMORY // RAY_BYTES} (the descriptors need only {2 * FD_ORDERS[-1] + 2})")


def micrograph_rows(path: str, *, min_area: int, threshold: float | None, foreground: str, rays: int,
                    pixel_size: float | None = None):
    """Fourier descriptors D2..D16 of every grain of one micrograph, as rows, and the scan summary.

    Positions and sizes are in pixels (``x_px``, ``area_px2``, ...) and, with
    ``pixel_size`` (µm per pixel), also in millimetres (``x_mm``, ``area_mm2``, ...);
    elongation, irregularity and roughness are D2, D3 and D8 (:data:`MICROGRAPH_COLUMNS`).

    Parameters
    ----------
    path : str
        The image file.
    min_area : int
        Specks smaller than this many pixels are skipped.
    threshold : float or None
        Grey level separating grains and background; None: Otsu's.
    foreground : {"auto", "dark", "bright"}
        Which side of the threshold the grains are.
    rays : int
        Rays cast from each grain's area centroid.
    pixel_size : float, optional
        Micrometres per pixel: adds the :data:`MICROGRAPH_MM_COLUMNS`.

    Returns
    -------
    rows : list of dict
        One per grain measured, keyed by the column names.
    scan : grainforge.outline.contours.GrainScan
        The image's scan (grains skipped at the border, too small, or not measurable).

    Raises
    ------
    ValueError
        An image that cannot be read, or bad settings (:func:`grainforge.outline.contours.scan_image`).
    """
    from ..outline.contours import scan_image

    n_max = FD_ORDERS[-1]
    scan = scan_image(path, min_area=min_area, threshold=threshold, foreground=foreground, n_angles=rays)
    rows = []
    for i, (c, area) in enumerate(zip(scan.contours, scan.areas)):
        D = c.descriptors(n_max)
        row = {
            "image": path, "grain": i, "x_px": round(float(c.centroid[0]), 3), "y_px": round(float(-c.centroid[1]), 3),
            "area_px2": area, "r0_px": round(c.scale, 4), "star_shaped": c.star_shaped,
            "elongation": float(D[2]), "irregularity": float(D[3]), "roughness": float(D[8]),
        }
        row.update({f"D{n}": float(D[n]) for n in FD_ORDERS})
        if pixel_size is not None:
            mm = pixel_size / 1000.0
            row.update({"x_mm": row["x_px"] * mm, "y_mm": row["y_px"] * mm, "area_mm2": area * mm * mm,
                        "r0_mm": c.scale * mm})
        rows.append(row)
    return rows, scan
