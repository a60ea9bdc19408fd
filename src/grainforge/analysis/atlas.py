"""Measuring a grain the way a μCT study does (docs/design/algorithms.md §8, the Sand Atlas definitions).

The Sand Atlas (and the ``spam`` library it uses) measures each segmented
particle on its binary voxel image.  :func:`atlas_descriptors` does the same
to a mesh:

1. **Voxelise** at voxel size ``h``: a voxel belongs to the grain when its
   centre is inside the mesh (:func:`voxelise`, which is
   :func:`grainforge.geometry.voxel.inside_mask` with the scanner's conventions:
   centres on the lattice ``h·(k + 1/2)``, parity along x).
2. ``V = n h³`` for ``n`` voxels, ``d_eq = (6V/π)^(1/3)``.
3. **True sphericity** ``π^(1/3) (6V)^(2/3) / A`` with ``A`` the area of the
   marching-cubes surface at level 0.5 of the binary image smoothed by a
   Gaussian of σ = 0.75 voxel (:func:`scipy.ndimage.gaussian_filter`) —
   ``spam``'s ``trueSphericity``: :func:`skimage.measure.marching_cubes`
   (its default, Lewiner's variant, as spam uses), and the area as
   :func:`skimage.measure.mesh_surface_area` sums it (:func:`_surface_area`).
4. **Convexity** = ``n`` / the number of voxel centres inside (or on) the
   convex hull of the grain's voxel centres (:class:`scipy.spatial.ConvexHull`)
   — ``spam``'s ``convexVolume``.  The lattice points in the hull are counted
   column by column between the hull's lower and upper facets, whose planes
   are taken with integer normals from the lattice points themselves
   (:func:`_hull_count`).
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

import functools
import math
from typing import Any

import numpy as np

from ..errors import InputError
from ..geometry.moments import sphere_diameter
from ..geometry.rotations import random_rotation

__all__ = ["voxelise", "voxel_image", "opening_fraction", "atlas_descriptors", "voxel_descriptors", "ATLAS_COLUMNS",
           "SIGMA", "CONVENTIONS", "OPENING_RADIUS", "MIN_VOXELS_ACROSS", "IMAGE_BYTES_PER_CELL", "image_cells",
           "check_atlas_request"]

#: Gaussian filter width (voxels) before marching cubes, as the Sand Atlas (``spam``) uses.
SIGMA = 0.75
#: radius of the ball of :func:`atlas_descriptors`' opening fraction, as a share of the grain's equivalent
#: diameter (one voxel at 30 voxels across; docs/fit.md, "What a scan's images add")
OPENING_RADIUS = 1.0 / 30.0
#: below this many voxels across its equivalent diameter a grain's image no longer measures its shape: the
#: descriptors leave their ranges (a ball 4 voxels across measures a true sphericity of about 1.5) and
#: ``grainforge fit`` refuses tables of such grains (5 to 1,000 voxels across)
MIN_VOXELS_ACROSS = 5.0
#: peak memory while one grain's image is measured, in bytes per cell of its box (the image, the smoothed
#: field of the marching cubes, the two distance transforms of the opening fraction and scipy's index
#: arrays): 67–76 measured with tracemalloc on ellipsoids at 60–180 voxels across, rounded up
IMAGE_BYTES_PER_CELL = 80.0
#: the columns of :func:`atlas_descriptors`, in order (prefixed ``atlas_`` in ``grainforge analyse``).
ATLAS_COLUMNS = (
    "voxel_size", "voxels_across", "voxels", "volume", "equivalent_diameter", "major", "middle", "minor",
    "sphericity", "convexity", "flatness", "elongation", "opening_fraction",
)
def image_cells(extents, voxel_size: float) -> float:
    """Cells of the voxel image of a grain whose bounding box has ``extents``, at ``voxel_size``
    (:func:`voxelise`'s box: the voxels the box spans and a margin).

    Parameters
    ----------
    extents : (3,) array_like of float
        The bounding box's sides, in the mesh's unit.
    voxel_size : float
        Voxel edge, same unit.

    Returns
    -------
    float
        Number of voxels (as a float: it only sizes estimates).

    Examples
    --------
    >>> image_cells([1.0, 1.0, 1.0], 0.1)
    2197.0
    """
    e = np.asarray(extents, dtype=np.float64)
    return float(np.prod(np.ceil(e / float(voxel_size)) + 3.0))


def check_atlas_request(bodies, *, voxel_size: float | None = None, voxels_across: float | None = None,
                        workers: int = 1, memory: float | None = None, unit: str = "") -> None:
    """Refuse, before any image is made, a Sand-Atlas measurement that means nothing or cannot fit in memory.

    Parameters
    ----------
    bodies : iterable of (str, (3,) array_like, float)
        Each grain's name, bounding-box extents and equivalent diameter (the mesh's units).
    voxel_size, voxels_across : float
        The resolution, as :func:`atlas_descriptors` takes it (exactly one).
    workers : int
        Grains measured at once (each holds its own image).
    memory : float, optional
        Bytes the measurement may use (default: half of this machine's memory,
        :func:`grainforge.runtime.estimate.check_memory`).
    unit : str, optional
        The lengths' unit, named after a voxel size the message suggests (``"mm"``).

    Raises
    ------
    ValueError
        A grain below :data:`MIN_VOXELS_ACROSS` voxels across, named with its resolution.
    grainforge.runtime.estimate.TooLargeError
        The largest image times ``workers`` over the budget: the message names the
        largest ``voxels_across`` (or the smallest ``voxel_size``) that fits.

    Examples
    --------
    >>> check_atlas_request([("g", [1.0, 1.0, 1.0], 1.0)], voxels_across=40)
    >>> check_atlas_request([("g", [1.0, 1.0, 1.0], 1.0)], voxels_across=4)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: g: 4 voxels across its equivalent diameter is below 5, where the Atlas descriptors measure shape (a ball 4 voxels across has a true sphericity of about 1.5); measure at 5 voxels across or more
    """
    from ..runtime.estimate import TooLargeError, machine_memory

    if (voxel_size is None) == (voxels_across is None):
        raise InputError("give exactly one of voxel_size and voxels_across")
    budget = 0.5 * machine_memory() if memory is None else float(memory)
    worst, worst_name = 0.0, ""
    for name, extents, d_eq in bodies:
        if not (math.isfinite(d_eq) and d_eq > 0):
            continue  # an open or empty body: analyse flags it and does not image it
        h = d_eq / voxels_across if voxel_size is None else voxel_size
        across = d_eq / h
        if across < MIN_VOXELS_ACROSS:
            fix = (f"a voxel size of at most {d_eq / MIN_VOXELS_ACROSS:.3g}{' ' + unit if unit else ''}"
                   if voxel_size is not None
                   else f"{MIN_VOXELS_ACROSS:g} voxels across or more")
            raise InputError(f"{name}: {across:.3g} voxels across its equivalent diameter is below "
                             f"{MIN_VOXELS_ACROSS:g}, where the Atlas descriptors measure shape (a ball 4 voxels "
                             f"across has a true sphericity of about 1.5); measure at {fix}")
        cells = image_cells(extents, h)
        if cells > worst:
            worst, worst_name = cells, name
    need = worst * IMAGE_BYTES_PER_CELL * max(1, int(workers))
    if need > budget:
        shrink = (budget / need) ** (1.0 / 3.0) * 0.97  # the image's cells go as the resolution cubed
        if voxel_size is None:
            fits = f"{{voxels_across}} {math.floor(voxels_across * shrink)}"
        else:
            fits = f"a voxel size of {voxel_size / shrink:.3g}{' ' + unit if unit else ''} or more"
        raise TooLargeError(f"{worst_name}: its voxel image ({worst:.3g} cells) would need about "
                            f"{need / 1024**3:.3g} GiB with {max(1, int(workers))} grain(s) measured at once; the "
                            f"limit is {budget / 1024**3:.3g} GiB (half this machine's memory): the largest that "
                            f"fits is {fits} (or fewer {{workers}})", setting=("voxels_across", "workers"))


def voxelise(vertices, faces, voxel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The binary voxel image of a closed mesh: voxels whose centre is inside.

    :func:`grainforge.geometry.voxel.inside_mask` (the one voxeliser) with the
    conventions of a scan: voxel centres on the lattice ``h·(k + 1/2)``
    whatever the mesh's position (``anchor="lattice"``), and the parity rule
    along x (``axis=0, rule="parity"``).

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
    >>> cube = trimesh.creation.box(extents=(3, 3, 3))     # 4 x 4 x 4 centres, 56 on the faces:
    >>> int(voxelise(cube.vertices, cube.faces, 1.0)[0].sum())   # those on one side of each pair count
    27
    """
    from ..geometry.voxel import grid_for, inside_mask

    h = float(voxel_size)
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"voxel size must be a positive number, got {voxel_size!r}")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    # voxel centres on the lattice h·(k + 1/2): independent of where the box starts; one empty voxel
    # beyond the outermost centre that can be inside
    grid = grid_for(v, h, pad=1, anchor="lattice")
    shape = grid.shape
    if np.prod(np.asarray(shape, dtype=np.float64)) > 2e8:
        raise InputError(f"voxel size {h:g} gives a {shape[0]}x{shape[1]}x{shape[2]} image: too fine for this grain")
    # columns along x (the image's slowest axis): the parity sweep goes over whole (y, z) planes
    return inside_mask(v, f, grid, axis=0, rule="parity"), grid.origin


def _column_ends(mask: np.ndarray) -> np.ndarray:
    """Candidate vertices of the convex hull of the voxel centres of ``mask``, as (m, 3) lattice points.

    The hull of the voxel centres is the hull of each z column's lowest and
    highest voxel.  Of these, an end that lies in the convex hull of the ends
    of two opposite neighbouring columns (along x, y or a diagonal) is
    dropped: every dropped point is a convex combination of others, so the
    hull is unchanged (a point outside the hull would need a neighbour
    farther out in every generic direction, and the farthest has none).
    """
    filled = mask.any(axis=2)
    nz = mask.shape[2]
    first = np.where(filled, np.argmax(mask, axis=2), 0)
    last = np.where(filled, nz - 1 - np.argmax(np.ascontiguousarray(mask[:, :, ::-1]), axis=2), -1)
    keep_top = filled.copy()
    keep_bot = filled.copy()
    bot, top = first.astype(np.float64), last.astype(np.float64)
    pf = np.pad(filled, 1)
    pb, pt = np.pad(bot, 1), np.pad(top, 1)
    nx, ny = filled.shape
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        a = (slice(1 - di, 1 - di + nx), slice(1 - dj, 1 - dj + ny))  # neighbour at (i - di, j - dj)
        b = (slice(1 + di, 1 + di + nx), slice(1 + dj, 1 + dj + ny))  # neighbour at (i + di, j + dj)
        both = pf[a] & pf[b]
        lo2, hi2 = pb[a] + pb[b], pt[a] + pt[b]  # twice the neighbours' mean bottom and top
        keep_top &= ~(both & (lo2 <= 2 * top) & (2 * top <= hi2))
        keep_bot &= ~(both & (lo2 <= 2 * bot) & (2 * bot <= hi2))
    keep_bot &= first != last  # a one-voxel column: its top is its bottom
    it = np.argwhere(keep_top)
    ib = np.argwhere(keep_bot)
    return np.concatenate([np.column_stack([it, last[keep_top]]), np.column_stack([ib, first[keep_bot]])])


def _hull_count(mask: np.ndarray) -> int:
    """Lattice points inside or on the convex hull of the voxel centres of ``mask`` (3D bool).

    Per voxel column (x, y) inside the hull's shadow, the hull spans
    ``max(down planes) <= z <= min(up planes)``; each column needs only the
    facets whose xy projection holds it (:func:`_triangle_columns`): the
    plane of any of them is the hull's top (or bottom) there.  The shadow is
    the set of columns under some facet.
    """
    from scipy.spatial import ConvexHull

    mask = np.asarray(mask, dtype=bool)
    pts = _column_ends(mask).astype(np.float64)
    centred = pts - np.round(pts.mean(axis=0))  # moved by an integer (still lattice points): Qhull is ~1.5x faster
    if len(pts) < 4 or np.linalg.matrix_rank(centred) < 3:
        return _flat_hull_count(np.argwhere(mask))
    # joggled input (QJ): lattice points are highly degenerate (many coplanar), and merging
    # coplanar facets costs Qhull twice as long; the joggle (~1e-11) is far below the tolerance
    hull = ConvexHull(centred, qhull_options="QJ")
    nx, ny = mask.shape[:2]
    # facet planes from the lattice points themselves (integer normals: exact values at lattice columns);
    # the joggled equations only orient them
    tri = pts[hull.simplices]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n *= np.sign(np.einsum("ij,ij->i", n, hull.equations[:, :3]))[:, None]
    off = -np.einsum("ij,ij->i", n, tri[:, 0])
    zmax = np.full(nx * ny, np.inf)
    zmin = np.full(nx * ny, -np.inf)
    for sel, acc, out in ((n[:, 2] > 0, np.minimum, zmax), (n[:, 2] < 0, np.maximum, zmin)):
        t, ci, cj = _triangle_columns(tri[sel, :, 0], tri[sel, :, 1])
        n0, n1, n2, o = (np.ascontiguousarray(a) for a in (n[sel, 0], n[sel, 1], n[sel, 2], off[sel]))
        z = -(o[t] + n0[t] * ci + n1[t] * cj) / n2[t]
        acc.at(out, ci * ny + cj, z)  # a flat index: ufunc.at's fast path
    # the shadow: the columns under some up facet (and over some down facet)
    shadow = np.isfinite(zmax) & np.isfinite(zmin)
    tol = 1e-9
    count = np.maximum(np.floor(zmax[shadow] + tol) - np.ceil(zmin[shadow] - tol) + 1, 0)
    return int(count.sum())


def _flat_hull_count(points: np.ndarray) -> int:
    """Lattice points in the convex hull of lattice ``points`` (m, 3) that lie in a plane, on a line or at a point.

    Examples
    --------
    >>> L = np.array([[0, 0, 0], [4, 0, 0], [0, 1, 0], [1, 1, 0], [0, 4, 0]])   # x + y <= 4 at z = 0
    >>> _flat_hull_count(L)
    15
    >>> _flat_hull_count(np.array([[0, 0, 0], [2, 4, 6]]))                       # (0,0,0), (1,2,3), (2,4,6)
    3
    """
    from scipy.spatial import ConvexHull

    p = np.unique(np.asarray(points, dtype=np.int64), axis=0)
    if len(p) == 1:
        return 1
    lo, hi = p.min(axis=0), p.max(axis=0)
    g = np.stack(np.meshgrid(*(np.arange(a, b + 1) for a, b in zip(lo, hi)), indexing="ij"), -1).reshape(-1, 3)
    d = p - p[0]
    far = d[np.argmax(np.abs(d).sum(axis=1))]
    normal = np.cross(far, d)
    k = np.argmax(np.abs(normal).sum(axis=1))
    if not normal[k].any():  # on a line: the points of g on it, between its ends (integer arithmetic)
        e = g - p[0]
        proj = e @ far
        span = d @ far
        on = ~np.cross(e, far).any(axis=1) & (proj >= span.min()) & (proj <= span.max())
        return int(on.sum())
    n = normal[k]
    on = (g - p[0]) @ n == 0
    keep = [a for a in range(3) if a != np.argmax(np.abs(n))]  # the plane projects one-to-one on these axes
    h = ConvexHull(p[:, keep].astype(np.float64))
    inside = (h.equations[:, :2] @ g[on][:, keep].T.astype(np.float64) + h.equations[:, 2:]) <= 1e-9
    return int(inside.all(axis=0).sum())


def _triangle_columns(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every lattice column (i, j) in each closed triangle of lattice points, scanned row by row.

    ``x``, ``y``: (F, 3) coordinates (integers held as floats) of the
    triangles' corners.  Returns (triangle index, i, j).  A column on an edge
    or corner belongs to every triangle that has it (a lattice point off a
    segment between lattice points ``L`` apart is at least ``1/L`` from it,
    so the 1e-9 tolerance only absorbs rounding).

    Examples
    --------
    >>> t, i, j = _triangle_columns(np.array([[0.0, 2, 0]]), np.array([[0.0, 0, 2]]))
    >>> sorted(zip(i.tolist(), j.tolist()))
    [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (2, 0)]
    """
    tol = 1e-9
    x0 = np.ceil(x.min(axis=1) - tol).astype(np.int64)
    nrow = np.maximum(np.floor(x.max(axis=1) + tol).astype(np.int64) - x0 + 1, 0)
    tr = np.repeat(np.arange(len(x)), nrow)
    row = (np.repeat(x0 - np.cumsum(nrow) + nrow, nrow) + np.arange(int(nrow.sum()))).astype(np.float64)
    lo = np.full(len(tr), np.inf)
    hi = np.full(len(tr), -np.inf)
    for k in range(3):  # the edges that span the row: y where they cross it (a vertical edge: both ends)
        px, py, qx, qy = x[tr, k], y[tr, k], x[tr, (k + 1) % 3], y[tr, (k + 1) % 3]
        spans = (np.minimum(px, qx) - tol <= row) & (row <= np.maximum(px, qx) + tol)
        dx = qx - px
        vertical = dx == 0
        at = py + (row - px) * (qy - py) / np.where(vertical, 1.0, dx)
        elo = np.where(vertical, np.minimum(py, qy), at)
        ehi = np.where(vertical, np.maximum(py, qy), at)
        lo = np.where(spans, np.minimum(lo, elo), lo)
        hi = np.where(spans, np.maximum(hi, ehi), hi)
    j0 = np.ceil(lo - tol)
    ncol = np.maximum(np.floor(hi + tol) - j0 + 1, 0).astype(np.int64)
    j0 = j0.astype(np.int64)
    start = np.cumsum(ncol) - ncol
    j = np.repeat(j0 - start, ncol) + np.arange(int(ncol.sum()))
    return np.repeat(tr, ncol), np.repeat(row.astype(np.int64), ncol), j


def straddling_cubes(volume: np.ndarray, level: float) -> np.ndarray:
    """Mask for :func:`skimage.measure.marching_cubes`: both end corners of every cube that straddles ``level``.

    A cube (2 × 2 × 2 samples) straddles when some of its corners are above
    ``level`` and some are not; only those cubes hold surface.  The mask marks
    each such cube at its lowest and its highest corner, so scikit-image
    visits every straddling cube whichever corner it tests, and skips most of
    the others (the surface is the same: ``tests/analysis/test_atlas.py``).

    Examples
    --------
    >>> v = np.zeros((4, 4, 4), np.float32); v[1, 1, 1] = 1.0
    >>> int(straddling_cubes(v, 0.5).sum())  # 8 cubes' lowest corners 0-1, highest 1-2; (1, 1, 1) is both
    15
    """
    b = np.asarray(volume) > level

    def corners(op):  # op over each cube's 8 corners, one axis at a time
        x = op(b[:-1], b[1:])
        x = op(x[:, :-1], x[:, 1:])
        return op(x[:, :, :-1], x[:, :, 1:])

    cubes = corners(np.logical_or) ^ corners(np.logical_and)  # some corner above, not every one
    mask = np.zeros(b.shape, dtype=bool)
    mask[:-1, :-1, :-1] = cubes
    mask[1:, 1:, 1:] |= cubes
    return mask


@functools.cache
def _marching_cubes():
    """:func:`skimage.measure.marching_cubes`, imported once (its lazy loader costs 0.1 ms a lookup)."""
    from skimage.measure import marching_cubes

    return marching_cubes


def _surface_area(verts: np.ndarray, tris: np.ndarray) -> float:
    """Area of a triangle mesh: :func:`skimage.measure.mesh_surface_area`'s sum, ~3x faster.

    The same float32 arithmetic on contiguous per-coordinate arrays (scikit-image
    gathers whole (F, 3, 3) corner blocks), summed in float64.

    Examples
    --------
    >>> from skimage.measure import mesh_surface_area
    >>> rng = np.random.default_rng(0)
    >>> v, t = rng.random((50, 3), dtype=np.float32), rng.integers(0, 50, (80, 3))
    >>> bool(np.isclose(_surface_area(v, t), mesh_surface_area(v, t), rtol=1e-6))
    True
    """
    x, y, z = np.ascontiguousarray(np.asarray(verts).T)
    a, b, c = np.ascontiguousarray(np.asarray(tris).T)
    x0, y0, z0 = x[a], y[a], z[a]
    ux, uy, uz = x[b] - x0, y[b] - y0, z[b] - z0
    vx, vy, vz = x[c] - x0, y[c] - y0, z[c] - z0
    cx, cy, cz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    return float(np.sqrt(cx * cx + cy * cy + cz * cz).sum(dtype=np.float64)) / 2.0


#: how true sphericity cuts the grain out before smoothing (:func:`voxel_descriptors`)
CONVENTIONS = ("atlas", "whole")
#: voxels added to spam's cube half-size (``getLabel(..., margin=2)`` in ``trueSphericity``)
ATLAS_MARGIN = 2


def _atlas_cube(mask: np.ndarray, centre: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """The grain cut out as ``spam.label.trueSphericity`` cuts it (the Sand Atlas's convention).

    spam (0.9.1) extracts a cube centred on the voxel ``floor(c)`` below the
    centre of mass ``c`` (float32), of half-size ``max(ceil(c − lo)) + 2``
    voxels, ``lo`` the bounding box's *lower* faces: both of its offsets are
    taken from the lower faces, so a grain that reaches further above its
    centre of mass than below is clipped at the cube's upper faces.  Outside
    the image the cube is zero (spam pads with zeros).
    """
    com = centre.astype(np.float32)
    offset = int(np.max(np.ceil(com.astype(np.float64) - lo))) + ATLAS_MARGIN
    start = np.floor(com).astype(np.int64) - offset
    size = 2 * offset + 1
    cube = np.zeros((size, size, size), dtype=np.float32)
    src = tuple(slice(max(a, 0), min(a + size, e)) for a, e in zip(start, mask.shape))
    dst = tuple(slice(s.start - a, s.stop - a) for s, a in zip(src, start))
    cube[dst] = mask[src]
    return cube


def voxel_descriptors(mask: np.ndarray, voxel_size: float = 1.0, *, convention: str = "atlas") -> dict[str, float]:
    """Atlas descriptors of a binary voxel image (one particle).

    Parameters
    ----------
    mask : (nx, ny, nz) bool ndarray
    voxel_size : float
        Voxel edge in the units wanted for lengths.
    convention : {"atlas", "whole"}
        How true sphericity sees the grain.  ``"atlas"`` (default) measures it
        as the Sand Atlas did, with ``spam.label.trueSphericity``: the grain
        cut out of a cube whose size comes from the lower bounding-box faces
        only (a grain reaching further above its centre of mass than below is
        clipped there and its sphericity over-stated), smoothed with scipy's
        default ``reflect`` boundary.  ``"whole"`` smooths the whole grain
        with empty space around it.  The other descriptors do not depend on it
        (docs/validation.md, "Atlas descriptors").

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
    from scipy.ndimage import gaussian_filter  # (``from scipy import ndimage`` costs 0.4 ms a call)

    marching_cubes = _marching_cubes()
    mask = np.asarray(mask, dtype=bool)
    # inertia-equivalent ellipsoid from the voxel centres' covariance (moments from the image's projections)
    u8 = mask.view(np.uint8)
    pxy, pxz, pyz = (u8.sum(axis=k, dtype=np.int32).astype(np.float64) for k in (2, 1, 0))
    n = int(pxy.sum())
    if n == 0:
        raise InputError("the voxel image is empty (the grain is smaller than a voxel)")
    h = float(voxel_size)
    V = n * h**3
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
    # the image is zero outside [lo, hi), so mode="constant" filters it exactly on any crop; the 0.5
    # level lies within one voxel of the grain's box (a voxel layer beyond the last is below 0.5:
    # at most half of the kernel minus its centre weight), so one empty voxel per side suffices
    if convention == "atlas":
        smooth = gaussian_filter(_atlas_cube(mask, m, lo), SIGMA, mode="reflect", truncate=4.0)
    elif convention == "whole":
        pad = 1
        sub = np.zeros(tuple(hi - lo + 2 * pad), dtype=np.float32)
        sub[tuple(slice(pad, pad + e) for e in hi - lo)] = mask[tuple(slice(a, b) for a, b in zip(lo, hi))]
        smooth = gaussian_filter(sub, SIGMA, mode="constant", truncate=4.0)
    else:
        raise InputError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    # degenerate triangles add no area: keeping them skips scikit-image's clean-up pass; the mask
    # limits scikit-image's work to the cubes that straddle the level (the same surface, bit for bit)
    verts, tris, _, _ = marching_cubes(smooth, level=0.5, allow_degenerate=True, mask=straddling_cubes(smooth, 0.5))
    area = _surface_area(verts, tris) * h**2
    sph = math.pi ** (1 / 3) * (6 * V) ** (2 / 3) / area if area > 0 else math.nan
    conv = n / _hull_count(mask)
    return {
        "voxels": int(n), "volume": V, "equivalent_diameter": float(sphere_diameter(V)),
        "major": float(major), "middle": float(middle), "minor": float(minor),
        "sphericity": float(sph), "convexity": float(conv),
        "flatness": float(minor / middle) if middle > 0 else math.nan,
        "elongation": float(middle / major) if major > 0 else math.nan,
    }


def atlas_descriptors(
    mesh_or_vertices, faces=None, *, voxel_size: float | None = None, voxels_across: float | None = None,
    rotation: Any = None, convention: str = "atlas",
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
    rotation : (3, 3) array_like, or int, SeedSequence or Generator, optional
        Turn the grain before voxelising (a scan sees grains in any
        orientation): a rotation matrix, or the randomness of a uniform one
        (:func:`grainforge.geometry.rotations.random_rotation`, scipy's convention, normalised by
        :mod:`grainforge.rng`).  Default: as given.
    convention : {"atlas", "whole"}
        How true sphericity cuts the grain out (:func:`voxel_descriptors`).

    Returns
    -------
    dict
        ``voxel_size``, ``voxels_across`` (the mesh's d_eq / h),
        :func:`voxel_descriptors`' values (lengths in the mesh's units) and
        ``opening_fraction``: :func:`opening_fraction` at a ball of
        :data:`OPENING_RADIUS` times the mesh's d_eq (not a Sand Atlas
        descriptor; the column ``grainforge fit`` reads as ``Opening Fraction (-)``).

    Examples
    --------
    >>> import trimesh
    >>> ball = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    >>> d = atlas_descriptors(ball, voxels_across=40)
    >>> round(d["equivalent_diameter"], 2), round(d["elongation"], 2), d["convexity"] > 0.99
    (2.0, 1.0, True)
    >>> d["opening_fraction"] > 0.99  # a ball has no edge for the smaller ball to miss
    True
    """
    mask, h, d_mesh = voxel_image(mesh_or_vertices, faces, voxel_size=voxel_size, voxels_across=voxels_across,
                                  rotation=rotation)
    out = {"voxel_size": h, "voxels_across": d_mesh / h}
    out.update(voxel_descriptors(mask, h, convention=convention))
    out["opening_fraction"] = opening_fraction(mask, OPENING_RADIUS * d_mesh / h)
    return out


def voxel_image(
    mesh_or_vertices, faces=None, *, voxel_size: float | None = None, voxels_across: float | None = None,
    rotation: Any = None,
) -> tuple[np.ndarray, float, float]:
    """The binary voxel image :func:`atlas_descriptors` measures: ``(mask, h, d_eq of the mesh)``.

    Arguments as :func:`atlas_descriptors`'s; ``h`` is the voxel edge in the mesh's units.

    Parameters
    ----------
    mesh_or_vertices : Grain, trimesh.Trimesh or (V, 3) array_like
        As :func:`atlas_descriptors`.
    faces : (F, 3) array_like of int, optional
        With vertices.
    voxel_size : float, optional
        Voxel edge in the mesh's units.
    voxels_across : float, optional
        Instead of ``voxel_size``: d_eq / h.
    rotation : (3, 3) array_like, or None, int, SeedSequence or Generator, optional
        A rotation matrix, or the randomness of a uniform one
        (:func:`grainforge.geometry.rotations.random_rotation`,
        scipy's convention, normalised by :mod:`grainforge.rng`).

    Returns
    -------
    mask : (Z, Y, X) bool
        The voxel image (cell centres inside the mesh).
    h : float
        The voxel edge, in the mesh's unit.
    d_eq : float
        The mesh's equivalent diameter.

    Raises
    ------
    ValueError
        If both or neither of ``voxel_size`` and ``voxels_across`` are given, either is not positive,
        or the mesh is not closed.

    Examples
    --------
    >>> import trimesh
    >>> mask, h, d = voxel_image(trimesh.creation.icosphere(subdivisions=4), voxels_across=20)
    >>> round(d / h), bool(abs(mask.sum() * h**3 / (4 / 3 * 3.14159) - 1) < 0.05)
    (20, True)
    """
    from ..geometry.solid import is_closed, signed_volume

    if faces is None:
        v, f = np.asarray(mesh_or_vertices.vertices, np.float64), np.asarray(mesh_or_vertices.faces, np.int64)
    else:
        v, f = np.asarray(mesh_or_vertices, np.float64), np.asarray(faces, np.int64)
    if (voxel_size is None) == (voxels_across is None):
        raise InputError("give exactly one of voxel_size and voxels_across")
    if not is_closed(f, len(v)):
        raise InputError("the mesh is not closed: a voxel image needs an inside")
    vol = abs(signed_volume(v, f))
    d_mesh = float(sphere_diameter(vol))
    if voxels_across is not None:
        if not (math.isfinite(voxels_across) and voxels_across > 0):
            raise InputError(f"voxels across must be a positive number, got {voxels_across!r}")
        h = d_mesh / float(voxels_across)
    else:
        h = float(voxel_size)
        if not (math.isfinite(h) and h > 0):
            raise InputError(f"voxel size must be a positive number, got {voxel_size!r}")
    if rotation is not None:
        if isinstance(rotation, (np.ndarray, list, tuple)) and np.shape(rotation) == (3, 3):
            R = np.asarray(rotation, dtype=np.float64)
        else:
            R = random_rotation(rotation)
        v = v @ R.T
    mask, _ = voxelise(v, f, h)
    return mask, h, d_mesh


def opening_fraction(mask: np.ndarray, radius: float) -> float:
    """Share of a grain's voxels that a ball of ``radius`` voxels reaches while staying inside it.

    That is the volume of the grain's morphological opening by the ball over the grain's: 1 for a grain
    whose edges and corners are all rounder than the ball, less the sharper they are.  It is not one of
    the Sand Atlas's descriptors; it responds to edge rounding far more than to a grain's seed
    (``benchmarks/fit_opening.py``, docs/fit.md).  The opening (erosion, then dilation) is taken with
    Euclidean distance transforms (:func:`scipy.ndimage.distance_transform_edt`): the eroded set is the
    voxels farther than ``radius`` from the outside, and its dilation the voxels within ``radius`` of it.

    Parameters
    ----------
    mask : (X, Y, Z) bool ndarray
        The grain's binary voxel image.
    radius : float
        The ball's radius in voxels (> 0).

    Returns
    -------
    float
        In [0, 1]; 0 where no voxel is farther than ``radius`` from the outside.

    Examples
    --------
    A cube of 60 voxels keeps all but its edges and corners; the rounded cube's volume is
    (a − 2r)³ + 6 (a − 2r)² r + 3π (a − 2r) r² + 4π r³/3:

    >>> a, r = 60, 6.0
    >>> exact = ((a - 2 * r) ** 3 + 6 * (a - 2 * r) ** 2 * r + 3 * math.pi * (a - 2 * r) * r**2
    ...          + 4 * math.pi * r**3 / 3) / a**3
    >>> round(exact, 4), round(opening_fraction(np.ones((a, a, a), bool), r), 4)
    (0.9756, 0.9744)

    On a few voxels across the answer is coarse: each voxel the ball cannot reach counts whole.
    """
    from scipy import ndimage

    if not (math.isfinite(radius) and radius > 0):
        raise InputError(f"radius must be a positive number of voxels, got {radius!r}")
    m = np.pad(np.asarray(mask, bool), int(math.ceil(radius)) + 2)
    total = int(m.sum())
    if total == 0:
        raise InputError("the mask is empty")
    # a voxel centre's distance to the grain's surface is its distance to the nearest outside centre less
    # half a voxel; the eroded set reaches half a voxel beyond its outermost centres
    core = ndimage.distance_transform_edt(m) > radius + 0.5
    if not core.any():
        return 0.0
    kept = ndimage.distance_transform_edt(~core) <= radius + 0.5
    return float((kept & m).sum() / total)
