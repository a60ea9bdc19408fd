"""Measuring a grain the way a μCT study does (ALGORITHMS.md §8, the Sand Atlas definitions).

The Sand Atlas (and the ``spam`` library it uses) measures each segmented
particle on its binary voxel image.  :func:`atlas_descriptors` does the same
to a mesh:

1. **Voxelise** at voxel size ``h``: a voxel belongs to the grain when its
   centre is inside the mesh.  The inside test is ray parity: one ray per
   voxel column along +z, cast with trimesh's ray engine (Embree through
   ``embreex`` when installed), and a voxel centre is inside when an odd
   number of surface crossings lies below it.  Columns with an odd number of
   crossings (a ray grazing an edge) are cast again a little to the side.
2. ``V = n h³`` for ``n`` voxels, ``d_eq = (6V/π)^(1/3)``.
3. **True sphericity** ``π^(1/3) (6V)^(2/3) / A`` with ``A`` the area of the
   marching-cubes surface (:func:`skimage.measure.marching_cubes`) at level
   0.5 of the binary image smoothed by a Gaussian of σ = 0.75 voxel
   (:func:`scipy.ndimage.gaussian_filter`) — ``spam``'s ``trueSphericity``.
4. **Convexity** = ``n`` / the number of voxel centres inside (or on) the
   convex hull of the grain's voxel centres (:class:`scipy.spatial.ConvexHull`)
   — ``spam``'s ``convexVolume``.  The lattice points in the hull are counted
   column by column from the hull's facet planes.
5. **Inertia-equivalent ellipsoid**: full axis lengths ``2·√(5 λ_i)`` for the
   eigenvalues ``λ_i`` of the covariance of the voxel centres (a solid
   ellipsoid of semi-axes a has variance a²/5 along it); flatness =
   minor/middle, elongation = middle/major.

The resolution is given either as a voxel size (``voxel_size``, in the mesh's
units) or as voxels across the mesh's equivalent diameter
(``voxels_across``).  A grain measured this way is comparable with a sand
scanned at the same number of voxels per grain; true sphericity in
particular depends on it (docs/validation.md, "Atlas descriptors").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["voxelise", "atlas_descriptors", "voxel_descriptors", "ATLAS_COLUMNS", "SIGMA", "random_rotation"]

#: Gaussian filter width (voxels) before marching cubes, as the Sand Atlas (``spam``) uses.
SIGMA = 0.75
#: the columns of :func:`atlas_descriptors`, in order (prefixed ``atlas_`` in ``grainforge analyse``).
ATLAS_COLUMNS = (
    "voxel_size", "voxels_across", "voxels", "volume", "equivalent_diameter", "major", "middle", "minor",
    "sphericity", "convexity", "flatness", "elongation",
)
#: relative side steps of re-cast rays for columns with an odd number of crossings
_RETRY = ((1e-4, 3e-4), (-2e-4, 1e-4), (3e-4, -2e-4))


def random_rotation(rng: Any) -> np.ndarray:
    """A uniformly random 3×3 rotation matrix from ``rng`` (anything ``default_rng`` accepts).

    Examples
    --------
    >>> R = random_rotation(1)
    >>> bool(np.allclose(R @ R.T, np.eye(3))), round(float(np.linalg.det(R)), 9)
    (True, 1.0)
    """
    from scipy.spatial.transform import Rotation

    return Rotation.random(random_state=np.random.default_rng(rng)).as_matrix()


def _crossings(mesh, origins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ray index, z) of every surface crossing of the +z rays from ``origins``."""
    direction = np.zeros_like(origins)
    direction[:, 2] = 1.0
    loc, ray, _ = mesh.ray.intersects_location(origins, direction, multiple_hits=True)
    return np.asarray(ray, dtype=np.int64), np.asarray(loc, dtype=np.float64).reshape(-1, 3)[:, 2]


def voxelise(vertices, faces, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The binary voxel image of a closed mesh: voxels whose centre is inside.

    Parameters
    ----------
    vertices : (V, 3) array_like
    faces : (F, 3) array_like
    voxel_size : float
        Edge ``h`` of the cubic voxels, in the mesh's units.

    Returns
    -------
    mask : (nx, ny, nz) bool ndarray
        ``mask[i, j, k]`` is the voxel centred at ``origin + (i, j, k)·h``;
        the image has at least one empty voxel on each side.
    origin : (3,) ndarray
        Centre of voxel ``(0, 0, 0)``.

    Raises
    ------
    ValueError
        If ``voxel_size`` is not positive or a column keeps an odd number of
        surface crossings (the mesh is not closed).

    Examples
    --------
    >>> import trimesh
    >>> m = trimesh.creation.box(extents=(4, 2, 1))
    >>> mask, origin = voxelise(m.vertices, m.faces, 0.5)
    >>> int(mask.sum()), mask.shape          # 8 x 4 x 2 voxel centres inside
    (64, (12, 8, 6))
    """
    import trimesh

    h = float(voxel_size)
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f"voxel size must be a positive number, got {voxel_size!r}")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    lo, hi = v.min(0), v.max(0)
    # voxel centres on the lattice h·(k + 1/2): independent of where the box starts
    first = np.floor(lo / h - 0.5) - 1  # one empty voxel below the lowest centre inside
    last = np.ceil(hi / h - 0.5) + 1
    shape = (last - first + 1).astype(np.int64)
    origin = (first + 0.5) * h
    if np.prod(shape.astype(np.float64)) > 2e8:
        raise ValueError(f"voxel size {h:g} gives a {shape[0]}x{shape[1]}x{shape[2]} image: too fine for this grain")
    mesh = trimesh.Trimesh(v, f, process=False)
    ix, iy = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    cols = np.column_stack([ix.ravel(), iy.ravel()])
    xy = origin[:2] + cols * h
    z0 = lo[2] - h
    toggles = np.zeros((len(cols), shape[2] + 1), dtype=np.int32)
    todo = np.arange(len(cols))
    for step in ((0.0, 0.0),) + _RETRY:
        origins = np.column_stack([xy[todo] + np.asarray(step) * h, np.full(len(todo), z0)])
        ray, z = _crossings(mesh, origins)
        counts = np.bincount(ray, minlength=len(todo))
        good = counts % 2 == 0
        keep = good[ray]
        # a crossing at height z toggles every voxel centre above it
        k = np.clip(np.ceil((z[keep] - origin[2]) / h), 0, shape[2]).astype(np.int64)
        np.add.at(toggles, (todo[ray[keep]], k), 1)
        todo = todo[~good]
        if len(todo) == 0:
            break
    else:
        raise ValueError(f"{len(todo)} voxel column(s) cross the surface an odd number of times: the mesh is not closed")
    inside = (np.cumsum(toggles[:, :-1], axis=1) % 2).astype(bool)
    return inside.reshape(shape[0], shape[1], shape[2]), origin


def _column_ends(mask: np.ndarray) -> np.ndarray:
    """(2m, 3) lattice points: the lowest and highest voxel of each of the m non-empty z columns."""
    filled = mask.any(axis=2)
    ij = np.argwhere(filled)
    col = mask[ij[:, 0], ij[:, 1]]  # (m, nz)
    first = np.argmax(col, axis=1)
    last = mask.shape[2] - 1 - np.argmax(col[:, ::-1], axis=1)
    return np.concatenate([np.column_stack([ij, first]), np.column_stack([ij, last])])


def _hull_count(mask: np.ndarray) -> int:
    """Lattice points inside or on the convex hull of the voxel centres of ``mask`` (3D bool)."""
    from scipy.spatial import ConvexHull, QhullError

    mask = np.asarray(mask, dtype=bool)
    # the hull of the voxel centres is the hull of each column's end points
    pts = _column_ends(mask).astype(np.float64)
    try:
        hull = ConvexHull(pts)
    except QhullError:  # flat (one voxel thick): every lattice point of the hull is a voxel
        return int(mask.sum())
    eq = np.unique(np.round(hull.equations, 12), axis=0)  # coplanar triangles share one plane
    nz = eq[:, 2]
    up, down, flat = nz > 1e-12, nz < -1e-12, np.abs(nz) <= 1e-12
    tol = 1e-7
    x0, y0 = pts[:, 0].min(), pts[:, 1].min()
    gx, gy = np.meshgrid(np.arange(x0, pts[:, 0].max() + 1), np.arange(y0, pts[:, 1].max() + 1), indexing="ij")
    P = np.column_stack([np.ones(gx.size), gx.ravel(), gy.ravel()])  # (columns, 3): 1, x, y
    # inside: nx x + ny y + nz z + b <= 0, so per column z <= (-b - nx x - ny y) / nz where nz > 0
    # (and >= where nz < 0): one matrix product per side, then the tightest plane
    coef = -eq[:, [3, 0, 1]]
    zmax = np.min(P @ (coef[up] / nz[up, None]).T, axis=1)
    zmin = np.max(P @ (coef[down] / nz[down, None]).T, axis=1)
    count = np.maximum(np.floor(zmax + tol) - np.ceil(zmin - tol) + 1, 0)
    if flat.any():  # vertical planes bound the columns themselves
        count[np.any(P @ coef[flat].T < -tol, axis=1)] = 0
    return int(count.sum())


def voxel_descriptors(mask: np.ndarray, voxel_size: float = 1.0) -> dict[str, float]:
    """Atlas descriptors of a binary voxel image (one particle).

    Parameters
    ----------
    mask : (nx, ny, nz) bool ndarray
    voxel_size : float
        Voxel edge in the units wanted for lengths.

    Returns
    -------
    dict
        ``voxels``, ``volume``, ``equivalent_diameter``, ``major``, ``middle``,
        ``minor`` (full axes of the inertia-equivalent ellipsoid),
        ``sphericity``, ``convexity``, ``flatness``, ``elongation``.

    Examples
    --------
    >>> g = np.indices((41, 41, 41)) - 20
    >>> ball = (g ** 2).sum(0) <= 15 ** 2
    >>> d = voxel_descriptors(ball)
    >>> round(d["major"] / 30, 2), round(d["flatness"], 3), round(d["convexity"], 3)
    (1.0, 1.0, 1.0)
    """
    from scipy import ndimage
    from skimage.measure import marching_cubes, mesh_surface_area

    mask = np.asarray(mask, dtype=bool)
    n = int(np.count_nonzero(mask))
    if n == 0:
        raise ValueError("the voxel image is empty (the grain is smaller than a voxel)")
    h = float(voxel_size)
    V = n * h**3
    # inertia-equivalent ellipsoid from the voxel centres' covariance (moments from the image's projections)
    pxy = mask.sum(axis=2, dtype=np.float64)
    pxz = mask.sum(axis=1, dtype=np.float64)
    pyz = mask.sum(axis=0, dtype=np.float64)
    x, y, z = (np.arange(k, dtype=np.float64) for k in mask.shape)
    px, py, pz = pxy.sum(1), pxy.sum(0), pxz.sum(0)
    m = np.array([px @ x, py @ y, pz @ z]) / n
    c = np.empty((3, 3))
    c[0, 0], c[1, 1], c[2, 2] = px @ x**2 / n, py @ y**2 / n, pz @ z**2 / n
    c[0, 1] = c[1, 0] = x @ pxy @ y / n
    c[0, 2] = c[2, 0] = x @ pxz @ z / n
    c[1, 2] = c[2, 1] = y @ pyz @ z / n
    c -= np.outer(m, m)
    lam = np.sort(np.linalg.eigvalsh(c))[::-1]
    major, middle, minor = 2.0 * np.sqrt(5.0 * np.maximum(lam, 0.0)) * h
    lo = np.array([np.flatnonzero(p)[0] for p in (px, py, pz)])
    hi = np.array([np.flatnonzero(p)[-1] + 1 for p in (px, py, pz)])
    # true sphericity: Gaussian-smoothed image, marching cubes at 0.5 (crop + pad so the filter has room)
    pad = int(math.ceil(4 * SIGMA)) + 1
    sub = np.zeros(tuple(hi - lo + 2 * pad), dtype=np.float32)
    sub[tuple(slice(pad, pad + e) for e in hi - lo)] = mask[tuple(slice(a, b) for a, b in zip(lo, hi))]
    smooth = ndimage.gaussian_filter(sub, SIGMA, mode="constant", truncate=4.0)
    verts, tris, _, _ = marching_cubes(smooth, level=0.5)
    area = mesh_surface_area(verts, tris) * h**2
    sph = math.pi ** (1 / 3) * (6 * V) ** (2 / 3) / area if area > 0 else math.nan
    conv = n / _hull_count(mask)
    return {
        "voxels": int(n), "volume": V, "equivalent_diameter": (6 * V / math.pi) ** (1 / 3),
        "major": float(major), "middle": float(middle), "minor": float(minor),
        "sphericity": float(sph), "convexity": float(conv),
        "flatness": float(minor / middle) if middle > 0 else math.nan,
        "elongation": float(middle / major) if major > 0 else math.nan,
    }


def atlas_descriptors(
    mesh_or_vertices, faces=None, *, voxel_size: float | None = None, voxels_across: float | None = None,
    rotation: Any = None,
) -> dict[str, float]:
    """Sand-Atlas descriptors of a closed mesh, measured on its voxel image.

    Parameters
    ----------
    mesh_or_vertices : Grain, trimesh.Trimesh or (V, 3) array_like
        Anything with ``.vertices`` and ``.faces``, or the vertices (then give ``faces``).
    faces : (F, 3) array_like, optional
    voxel_size : float, optional
        Voxel edge in the mesh's units.
    voxels_across : float, optional
        Instead of ``voxel_size``: ``d_eq / h`` with ``d_eq`` the mesh's
        equivalent diameter (exactly one of the two must be given).
    rotation : (3, 3) array_like or seed, optional
        Turn the grain before voxelising (a scan sees grains in any
        orientation): a rotation matrix, or a seed/Generator for
        :func:`random_rotation`.  Default: as given.

    Returns
    -------
    dict
        ``voxel_size``, ``voxels_across`` (the mesh's d_eq / h) and
        :func:`voxel_descriptors`' values (lengths in the mesh's units).

    Examples
    --------
    >>> import trimesh
    >>> ball = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    >>> d = atlas_descriptors(ball, voxels_across=40)
    >>> round(d["equivalent_diameter"], 2), round(d["elongation"], 2), d["convexity"] > 0.99
    (2.0, 1.0, True)
    """
    from ..solid import is_closed, signed_volume

    if faces is None:
        v, f = np.asarray(mesh_or_vertices.vertices, np.float64), np.asarray(mesh_or_vertices.faces, np.int64)
    else:
        v, f = np.asarray(mesh_or_vertices, np.float64), np.asarray(faces, np.int64)
    if (voxel_size is None) == (voxels_across is None):
        raise ValueError("give exactly one of voxel_size and voxels_across")
    if not is_closed(f, len(v)):
        raise ValueError("the mesh is not closed: a voxel image needs an inside")
    vol = abs(signed_volume(v, f))
    d_mesh = (6 * vol / math.pi) ** (1 / 3)
    if voxels_across is not None:
        if not (math.isfinite(voxels_across) and voxels_across > 0):
            raise ValueError(f"voxels across must be a positive number, got {voxels_across!r}")
        h = d_mesh / float(voxels_across)
    else:
        h = float(voxel_size)
        if not (math.isfinite(h) and h > 0):
            raise ValueError(f"voxel size must be a positive number, got {voxel_size!r}")
    if rotation is not None:
        if isinstance(rotation, (np.ndarray, list, tuple)) and np.shape(rotation) == (3, 3):
            R = np.asarray(rotation, dtype=np.float64)
        else:
            R = random_rotation(rotation)
        v = v @ R.T
    mask, _ = voxelise(v, f, h)
    out = {"voxel_size": h, "voxels_across": d_mesh / h}
    out.update(voxel_descriptors(mask, h))
    return out
