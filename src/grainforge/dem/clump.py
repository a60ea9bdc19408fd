"""Multi-sphere (clump) approximation of a grain.

The algorithm ("greedy inscribed spheres + SDF refinement", ours):

1. Voxelise the grain (cell size ``d_eq / resolution``) and take the
   Euclidean distance transform of the inside (scipy): every inside cell
   centre is the centre of a candidate inscribed sphere of radius
   ``D(x) − h/2``.
2. Greedy placement: candidates are enlarged by ``overshoot · d_eq``, and
   each centre offers a second one grown by ``growth · D(x)``;
   repeatedly take the candidate that adds the most uncovered grain volume
   minus ``spill_weight`` × its new volume outside the grain. The gain of every candidate is first estimated
   analytically (sphere volume, minus ``1 + spill_weight`` times the cap beyond its depth, minus the lens
   overlaps with the spheres already placed); the best 8 are then counted exactly on the grid, and when
   none of them gains, the next 8. The greedy ends at the sphere count or when no candidate gains.
3. Optional refinement (``iterations > 0``, off by default: it costs several
   times the greedy's time, and from about 20 spheres on it trades coverage for
   less spill): all centres and radii are optimised together (L-BFGS-B) to
   maximise the covered grain volume minus ``spill_weight`` × the volume
   outside the grain, measured on a random sample of cell centres inside the
   grain and in a band around it, with a smooth (sigmoid) inside-the-union
   indicator of width ``h/2``.

4. Optional accuracy target (``target_iou``): the greedy order is nested (the
   first *k* spheres of a larger clump are the *k*-sphere clump), so the
   sphere count is the smallest prefix whose :func:`clump_accuracy` reaches
   the target, up to the cap ``spheres``: the greedy runs only as far as the
   prefixes of 8, 16, 32, … spheres need until one reaches it, then a bisection
   between that prefix and the one before finds the count (about twice log2 of
   the count measures).

Quality (:func:`clump_quality`) is measured independently on a finer grid:
coverage = vol(grain ∩ union)/vol(grain), spill = vol(union \\ grain)/vol(union),
counting cell centres (docs/design/algorithms.md §7). Mass properties for the engine never
come from the spheres: see :mod:`grainforge.dem.massprops`.

References
----------
Favier et al. 1999; Ferellec & McDowell 2010; Amberger et al. 2012;
Angelidakis et al. 2021 (CLUMP).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry.voxel import grid_for, inside_mask
from ..rng import as_generator

__all__ = ["Clump", "ClumpAccuracy", "ACCURACY_MEASURE_SECONDS", "CLUMP_TABLE_COLUMNS", "DEFAULT_SPHERE_CAP",
           "accuracy_measures", "accuracy_record", "check_target", "clump", "clump_accuracy", "clump_quality",
           "clump_table", "union_mask"]

#: the most spheres a clump built to an accuracy target takes when the caller names no cap
DEFAULT_SPHERE_CAP = 100
#: seconds of one :func:`clump_accuracy` of a clump on the decks' grid (60 cells per d_eq), one core: 15-20 ms
#: measured on 20,480-face grains of 30 to 100 spheres (the bisection's cost, for the up-front estimate)
ACCURACY_MEASURE_SECONDS = 0.025


#: the first prefix of the greedy order measured on the way to a target (then twice as many, up to the cap)
_FIRST_PREFIX = 8


def accuracy_measures(cap: int) -> int:
    """The most :func:`clump_accuracy` measures building one clump to a target takes.

    The prefixes of 8, 16, 32, … spheres up to ``cap`` until one reaches the target, then a
    bisection between it and the one before: the most is when only the whole cap reaches it.

    Parameters
    ----------
    cap : int
        The most spheres the clump may take (values below 1 count as 1).

    Returns
    -------
    int
        Measures at most (≥ 1).

    Examples
    --------
    >>> accuracy_measures(30), accuracy_measures(100), accuracy_measures(1)
    (7, 11, 1)
    """
    cap = max(int(cap), 1)
    lo, n, count = 0, min(cap, _FIRST_PREFIX), 1
    while n < cap:
        lo, n, count = n, min(2 * n, cap), count + 1
    return count + math.ceil(math.log2(max(n - lo, 1)))


@dataclass(frozen=True)
class Clump:
    """Spheres approximating a grain, with their measured quality.

    Attributes
    ----------
    centres : (N, 3) float64
        Sphere centres, in the grain's frame and units.
    radii : (N,) float64
    coverage : float
        vol(grain ∩ union) / vol(grain), on the measuring grid.
    spill : float
        vol(union outside the grain) / vol(union), on the measuring grid.
    resolution : int
        Cells per equivalent diameter of the measuring grid.
    accuracy : ClumpAccuracy or None
        The full measure (:func:`clump_accuracy` on the measuring grid) of a
        clump built to an accuracy target; ``None`` otherwise.
    target : float or None
        The intersection over union the clump was built to (``None``: a fixed
        sphere count).
    """

    centres: np.ndarray
    radii: np.ndarray
    coverage: float
    spill: float
    resolution: int
    accuracy: ClumpAccuracy | None = None
    target: float | None = None

    @property
    def count(self) -> int:
        """Number of spheres."""
        return int(len(self.radii))

    @property
    def meets_target(self) -> bool | None:
        """Whether the measured intersection over union reaches :attr:`target` (``None`` without a target)."""
        if self.target is None or self.accuracy is None:
            return None
        return bool(self.accuracy.iou >= self.target)

    def translated(self, offset) -> Clump:
        """The same clump with every centre moved by ``offset`` (its measures unchanged).

        Parameters
        ----------
        offset : (3,) array_like of float
            The move, in the clump's length unit.

        Returns
        -------
        Clump
            A new clump; this one is unchanged.
        """
        return dataclasses.replace(self, centres=self.centres + np.asarray(offset, dtype=np.float64))

    def scaled(self, factor: float) -> Clump:
        """The clump scaled by ``factor`` about the origin (its measures, all relative, unchanged).

        Parameters
        ----------
        factor : float
            Scale factor (> 0; e.g. 1e-3 from millimetres to metres).

        Returns
        -------
        Clump
            A new clump; this one is unchanged.
        """
        return dataclasses.replace(self, centres=self.centres * factor, radii=self.radii * factor)


def _equivalent_diameter(vertices, faces) -> float:
    from ..geometry.moments import signed_volume, sphere_diameter

    vol = signed_volume(vertices, faces)
    if not vol > 0:
        raise InputError(f"the grain's volume must be positive, got {vol!r}")
    return float(sphere_diameter(vol))


def union_mask(centres: np.ndarray, radii: np.ndarray, grid) -> np.ndarray:
    """Boolean array ``grid.shape``: which cell centres lie in at least one sphere.

    Each sphere is rasterised in its own bounding block (vectorised per sphere).

    Parameters
    ----------
    centres : (N, 3) array_like of float
        Sphere centres, in the grid's frame and length unit.
    radii : (N,) array_like of float
        Sphere radii, same unit; a cell centre at distance exactly ``r`` is inside.
    grid : grainforge.geometry.voxel.Grid
        The cells (their centres ``origin + (i, j, k) · spacing``).

    Returns
    -------
    ndarray of bool, shape ``grid.shape``
        True where a cell centre lies in at least one sphere.

    Examples
    --------
    A 4 × 4 × 4 grid of cells 0.5 wide over a cube of side 2: a sphere of radius 0.6 at the
    centre holds the 8 inner cell centres (at distance 0.43), not the next ones (0.83):

    >>> from grainforge.geometry.voxel import grid_for
    >>> g = grid_for(np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]), 0.5, pad=0)
    >>> g.shape, int(union_mask(np.zeros((1, 3)), np.array([0.6]), g).sum())
    ((4, 4, 4), 8)
    """
    out = np.zeros(grid.shape, dtype=bool)
    h = grid.spacing
    axes = grid.axes()
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    rr = radii[:, None]
    los = np.maximum(np.floor((centres - rr - grid.origin) / h).astype(int), 0).tolist()
    his = np.minimum(np.ceil((centres + rr - grid.origin) / h).astype(int) + 1, grid.shape).tolist()
    for c, r, lo, hi in zip(centres, radii.tolist(), los, his):
        if hi[0] <= lo[0] or hi[1] <= lo[1] or hi[2] <= lo[2]:
            continue
        dx = (axes[0][lo[0]:hi[0]] - c[0]) ** 2
        dy = (axes[1][lo[1]:hi[1]] - c[1]) ** 2
        dz = (axes[2][lo[2]:hi[2]] - c[2]) ** 2
        block = dx[:, None, None] + dy[None, :, None] + dz[None, None, :] <= r * r
        out[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] |= block
    return out


def clump_quality(vertices: np.ndarray, faces: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                  *, resolution: int = 100) -> tuple[float, float]:
    """Coverage and spill of a sphere set against a closed mesh, on a voxel grid.

    Counts cell centres of a grid of ``d_eq / resolution`` covering both the
    grain and the spheres: coverage = #(grain ∩ union) / #grain, spill =
    #(union \\ grain) / #union. The grid error is of order one cell over
    the surface (≈ 1/resolution relative).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        A closed, outward-oriented mesh (any length unit).
    centres : (N, 3) float64
    radii : (N,) float64
        The spheres, in the mesh's frame and unit.
    resolution : int
        Cells per equivalent diameter of the grain of the measuring grid.

    Returns
    -------
    coverage : float
        The share of the grain's cells inside the spheres, in [0, 1].
    spill : float
        The share of the spheres' cells outside the grain, in [0, 1].

    Raises
    ------
    ValueError
        If the mesh's volume is not positive.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(5)
    >>> cov, spill = clump_quality(s.vertices, s.faces, np.zeros((1, 3)), np.array([1.0]), resolution=60)
    >>> round(cov, 2), round(spill, 2)
    (1.0, 0.0)
    """
    v = np.asarray(vertices, dtype=np.float64)
    return _quality(v, faces, _equivalent_diameter(v, faces), centres, radii, resolution)


def _quality(v, faces, d, centres, radii, resolution):
    """:func:`clump_quality` for a mesh whose equivalent diameter ``d`` is known."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    box = np.vstack([v, centres - radii[:, None], centres + radii[:, None]])
    grid = grid_for(box, d / resolution, pad=1)
    grain = inside_mask(v, faces, grid)
    union = union_mask(centres, radii, grid)
    both = np.count_nonzero(grain & union)
    nu = np.count_nonzero(union)
    return float(both / max(np.count_nonzero(grain), 1)), float((nu - both) / max(nu, 1))


@dataclass(frozen=True)
class ClumpAccuracy:
    """How well a sphere set stands for a grain, measured on one voxel grid.

    Every figure counts cell centres of a grid of ``d_eq / resolution`` that
    covers the grain and every sphere (G: centres inside the mesh, U: centres
    inside at least one sphere).

    Attributes
    ----------
    iou : float
        Intersection over union, #(G ∩ U) / #(G ∪ U): 1 for a perfect clump; both
        missing grain and sphere volume outside the grain lower it.
    coverage : float
        #(G ∩ U) / #G, the share of the grain the spheres cover.
    spill : float
        #(U \\ G) / #U, the share of the spheres' union outside the grain.
    volume_error : float
        (#U − #G) / #G, signed: the union's volume against the grain's.
    inertia_error : float
        The largest relative difference between the three principal moments of
        inertia of U and of G (each about its own centroid, unit density), sorted.
    resolution : int
        Cells per equivalent diameter of the grid.
    """

    iou: float
    coverage: float
    spill: float
    volume_error: float
    inertia_error: float
    resolution: int

    def as_dict(self) -> dict:
        """The figures as a plain dict (JSON- and CSV-ready).

        Returns
        -------
        dict
            ``iou``, ``coverage``, ``spill``, ``volume_error``, ``inertia_error`` (floats) and
            ``resolution`` (int), as the attributes.
        """
        return {"iou": self.iou, "coverage": self.coverage, "spill": self.spill,
                "volume_error": self.volume_error, "inertia_error": self.inertia_error,
                "resolution": self.resolution}


#: the columns of ``clumps.csv``: one row per grain of a deck whose clumps were built to an accuracy target
CLUMP_TABLE_COLUMNS = ("name", "spheres", "iou", "coverage", "spill", "volume_error", "inertia_error", "target",
                       "meets_target")


def accuracy_record(c: Clump) -> dict:
    """The accuracy figures of a clump built to a target, as ``grains.json`` holds them (``{}`` without one).

    ``iou``, ``volume_error``, ``inertia_error`` and the grid (``accuracy_resolution``) of its
    :class:`ClumpAccuracy`, the ``target`` and ``meets_target`` (coverage, spill and the sphere
    count are in every clump's record already).

    Parameters
    ----------
    c : Clump
        A clump, built to a target or not.

    Returns
    -------
    dict
        ``iou``, ``volume_error``, ``inertia_error``, ``accuracy_resolution`` (cells per d_eq),
        ``target`` and ``meets_target``; ``{}`` for a clump of a fixed sphere count.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> sorted(accuracy_record(clump(s.vertices, s.faces, spheres=4, target_iou=0.8, measure_resolution=30)))
    ['accuracy_resolution', 'inertia_error', 'iou', 'meets_target', 'target', 'volume_error']
    >>> accuracy_record(clump(s.vertices, s.faces, spheres=4))
    {}
    """
    if c.target is None or c.accuracy is None:
        return {}
    a = c.accuracy
    return {"iou": a.iou, "volume_error": a.volume_error, "inertia_error": a.inertia_error,
            "accuracy_resolution": a.resolution, "target": c.target, "meets_target": c.meets_target}


def clump_table(records) -> str | None:
    """``clumps.csv``: one row per grain record (``grains.json``) that carries an accuracy target.

    Columns :data:`CLUMP_TABLE_COLUMNS`; numbers at full precision (they read back
    to the same floats), ``meets_target`` as ``true`` or ``false``. ``None`` when no
    record has a target (a deck of fixed-count clumps has no table).

    Parameters
    ----------
    records : iterable of dict
        The grain records of a deck's ``grains.json`` (:func:`grainforge.dem.deck.template_record`);
        those without a ``target`` are left out.

    Returns
    -------
    str or None
        The CSV text (a header, one row per record with a target, newline-ended), or ``None``.

    Examples
    --------
    >>> print(clump_table([{"name": "a", "spheres": 3, "iou": 0.9, "coverage": 0.95, "spill": 0.01,
    ...                     "volume_error": -0.04, "inertia_error": 0.1, "target": 0.85, "meets_target": True}]), end="")
    name,spheres,iou,coverage,spill,volume_error,inertia_error,target,meets_target
    a,3,0.9,0.95,0.01,-0.04,0.1,0.85,true
    >>> clump_table([{"name": "b", "spheres": 3}]) is None
    True
    """
    rows = [r for r in records if r.get("target") is not None]
    if not rows:
        return None

    def text(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        return repr(float(v)) if isinstance(v, float) else str(v)

    import csv
    import io

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CLUMP_TABLE_COLUMNS)
    writer.writerows([text(r[k]) for k in CLUMP_TABLE_COLUMNS] for r in rows)
    return buf.getvalue()


def _principal_moments(points: np.ndarray) -> np.ndarray:
    """Sorted principal moments of inertia of equal point masses (unit mass each)."""
    if len(points) == 0:
        return np.zeros(3)
    x = points - points.mean(axis=0)
    c = x.T @ x
    inertia = np.trace(c) * np.eye(3) - c
    return np.sort(np.linalg.eigvalsh(inertia))


def clump_accuracy(vertices: np.ndarray, faces: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                   *, resolution: int = 100) -> ClumpAccuracy:
    """Intersection over union, coverage, spill, volume and inertia errors of a sphere set.

    The measure every clump of grainforge is built to and reported with, and
    the one the comparison with other clump tools uses (``benchmarks/``):
    it reads only the mesh and the spheres, never how they were made. The grid
    error is of order one cell over the surface (about ``3/resolution``
    relative in the intersection over union).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        A closed, outward-oriented mesh.
    centres : (N, 3) float64
    radii : (N,) float64
        The spheres, in the mesh's frame and units.
    resolution : int
        Cells per equivalent diameter of the measuring grid (≥ 10).

    Returns
    -------
    ClumpAccuracy

    Raises
    ------
    ValueError
        If ``resolution`` is below 10 or the mesh's volume is not positive.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(5)
    >>> a = clump_accuracy(s.vertices, s.faces, np.zeros((1, 3)), np.array([1.0]), resolution=60)
    >>> round(a.iou, 2), round(a.volume_error, 2), round(a.inertia_error, 2)
    (1.0, 0.0, 0.0)
    >>> b = clump_accuracy(s.vertices, s.faces, np.zeros((1, 3)), np.array([0.8]), resolution=60)
    >>> round(b.iou, 2), round(b.coverage, 2), b.spill
    (0.51, 0.51, 0.0)
    """
    if int(resolution) < 10:
        raise InputError(f"resolution must be ≥ 10 cells per diameter, got {int(resolution)}")
    v = np.asarray(vertices, dtype=np.float64)
    return _Measure(v, faces, _equivalent_diameter(v, faces), resolution)(centres, radii)


class _Measure:
    """:func:`clump_accuracy` of many sphere sets against one mesh (the greedy prefixes of one clump).

    The grid of a sphere set covers the mesh and the spheres, so it is the same for every set
    whose spheres stay within the same box; the grain's cells and moments on a grid are kept and
    reused for the next set on the same grid.  Every figure is computed by the same code on the
    same grid as :func:`clump_accuracy` would compute it: the results are identical.
    """

    def __init__(self, v: np.ndarray, faces, d: float, resolution: int):
        resolution = int(resolution)
        if resolution < 10:
            raise InputError(f"resolution must be ≥ 10 cells per diameter, got {resolution}")
        self.v, self.faces, self.d, self.resolution = v, faces, d, resolution
        self.grains: dict = {}
        self.calls = 0

    def __call__(self, centres, radii) -> ClumpAccuracy:
        self.calls += 1
        v, resolution = self.v, self.resolution
        centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(radii, dtype=np.float64).reshape(-1)
        box = np.vstack([v, centres - radii[:, None], centres + radii[:, None]])
        grid = grid_for(box, self.d / resolution, pad=1)
        key = (grid.origin.tobytes(), grid.shape)
        if key not in self.grains:
            grain = inside_mask(v, self.faces, grid)
            self.grains[key] = (grain, np.count_nonzero(grain), _principal_moments(grid.points(np.argwhere(grain))))
        grain, ng, moments_g = self.grains[key]
        union = union_mask(centres, radii, grid)
        nu = np.count_nonzero(union)
        both = np.count_nonzero(grain & union)
        either = ng + nu - both
        moments_u = _principal_moments(grid.points(np.argwhere(union)))
        inertia_error = float(np.max(np.abs(moments_u - moments_g) / np.maximum(moments_g, 1e-300)))
        return ClumpAccuracy(iou=float(both / max(either, 1)), coverage=float(both / max(ng, 1)),
                             spill=float((nu - both) / max(nu, 1)), volume_error=float((nu - ng) / max(ng, 1)),
                             inertia_error=inertia_error, resolution=resolution)


def check_target(target) -> float:
    """``target`` as a float, or ``ValueError`` unless it is a finite number strictly between 0 and 1.

    Parameters
    ----------
    target : object
        The accuracy target (an intersection over union) as given: a number or a numeric string.

    Returns
    -------
    float
        ``float(target)``.

    Raises
    ------
    ValueError
        If ``target`` is not a number, not finite, or not in (0, 1).

    Examples
    --------
    >>> check_target(0.85)
    0.85
    >>> check_target(float("nan"))
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: the accuracy target (intersection over union) must be a number in (0, 1), got nan
    """
    try:
        t = float(target)
    except (TypeError, ValueError):
        t = math.nan
    if not (math.isfinite(t) and 0.0 < t < 1.0):
        raise InputError(f"the accuracy target (intersection over union) must be a number in (0, 1), got {target!r}")
    return t


def _lens_loss(r1, r, d):
    """Where spheres of radii ``r1`` (array) overlap one of radius ``r`` at distances ``d``:
    ``(which, volume)``, the indices with a positive overlap and the volume of the lens (the
    intersection; the smaller sphere's volume where one holds the other).

    Examples
    --------
    >>> which, vol = _lens_loss(np.array([1.0, 1.0, 0.2]), 1.0, np.array([1.0, 3.0, 0.5]))
    >>> which.tolist(), bool(np.isclose(vol[0], 5 * np.pi / 12)), bool(np.isclose(vol[1], 4 / 3 * np.pi * 0.2**3))
    ([0, 2], True, True)
    """
    d = np.maximum(d, 1e-300)
    s = r1 + r
    keep = np.flatnonzero(d < s)
    if len(keep) < len(d):
        r1, d, s = r1[keep], d[keep], s[keep]
    m = r1 - r
    vol = np.pi * (s - d) ** 2 * (d * d + 2 * d * s - 3 * m ** 2) / (12 * d)
    full = np.flatnonzero(d <= np.abs(m))
    if len(full):
        vol[full] = 4.0 / 3.0 * np.pi * np.minimum(r1[full], r) ** 3
    return keep, vol


#: candidates per chunk of the greedy's running estimates (the least of each chunk is kept)
_CHUNK = 256


def _exact_gain(c, r, ci, h, axes, shape, u_in, u_out, spill_weight):
    """A candidate sphere's exact gain on the grid: uncovered inside cells it covers less ``spill_weight`` times
    the uncovered outside ones; with its block of cells (its cell ± ceil(r/h) + 1, one more above, clipped to
    the grid) as a mask and the block's bounds ``lo``, ``hi``."""
    reach_cells = int(np.ceil(r / h))
    lo = [max(ci[k] - reach_cells - 1, 0) for k in range(3)]
    hi = [min(ci[k] + reach_cells + 2, shape[k]) for k in range(3)]
    dx = (axes[0][lo[0]:hi[0]] - c[0]) ** 2
    dy = (axes[1][lo[1]:hi[1]] - c[1]) ** 2
    dz = (axes[2][lo[2]:hi[2]] - c[2]) ** 2
    blk = dx[:, None, None] + dy[None, :, None] + dz[None, None, :] <= r * r
    box = (slice(lo[0], hi[0]), slice(lo[1], hi[1]), slice(lo[2], hi[2]))
    gain = np.count_nonzero(blk & u_in[box]) - spill_weight * np.count_nonzero(blk & u_out[box])
    return gain, blk, lo, hi


def _candidates(points, depth, inside_idx, h, overshoot, growth):
    """The greedy's candidate spheres (:func:`_greedy`'s arguments of the same names).

    Returns
    -------
    twins : int
        Candidates per centre: candidate t is centre t // twins, grown when t is odd.
    cp, cidx : ndarray
        The candidate centres and their cell indices (grid order, x index first).
    cr, cap : (K,) float64
        Each candidate's radius and the cap it reaches beyond its centre's depth.
    """
    cand = depth > 1.0 * h
    twins = 2 if growth > 0 else 1
    bd, cp, cidx = depth[cand], points[cand], inside_idx[cand]
    dd = np.repeat(bd, twins) if twins > 1 else bd
    cr = dd - 0.5 * h + overshoot
    if twins > 1:
        cr[1::2] += growth * dd[1::2]
    beyond = np.maximum(cr - dd, 0.0)
    cap = np.pi * beyond**2 * (3.0 * cr - beyond) / 3.0
    return twins, cp, cidx, cr, cap


def _greedy(points, depth, inside_idx, grid, n, h, inside, overshoot, spill_weight, growth=0.0):
    """Greedy spheres on the working grid.

    Parameters
    ----------
    points : (M, 3) float64
        The centres of the grain's inside cells.
    depth : (M,) float64
        Each cell's distance to the nearest outside cell centre.
    inside_idx : (M, 3) int64
        The cells' indices, in grid order (x index first).
    grid : grainforge.geometry.voxel.Grid
    n : int
        The most spheres to place.
    h : float
        The cell size.
    inside : ndarray of bool
        The grain's cells on ``grid``.
    overshoot : float
        Added to every candidate radius (a length).
    spill_weight : float
        The cost of an outside cell covered, in inside cells.
    growth : float
        Each centre deeper than one cell offers two candidates: radius ``depth − h/2 + overshoot``
        and the same plus ``growth · depth`` (only the first when ``growth`` is 0).

    Yields
    ------
    centre : (3,) float64
    radius : float
        Up to ``n`` spheres, one at a time in the order placed (each prefix is the greedy clump of
        its size, so a caller may stop early).

    Notes
    -----
    Each step takes the 8 candidates of largest estimated gain, counts their exact gain on the
    grid (uncovered inside cells − ``spill_weight`` × uncovered outside cells) and places the best;
    then the estimate of every candidate the new sphere overlaps loses the lens volume.  The
    estimate starts at the sphere's volume less ``1 + spill_weight`` times the cap it reaches
    beyond its depth (its loss if the surface were flat there).  When none of the 8 gains, those 8
    are dropped and the next 8 are counted: the greedy ends when no candidate is left with a
    positive estimate, or at ``n`` spheres.
    """
    twins, cp, cidx, cr, cap = _candidates(points, depth, inside_idx, h, overshoot, growth)
    # uncovered cells inside and outside the grain (one array each: two counts per candidate)
    u_in = inside.copy()
    u_out = ~inside
    axes = grid.axes()
    shape = grid.shape
    # minus the estimated gain (the selection wants the largest; -(e - l) == -e + l exactly)
    m = len(cr)
    # padded to whole chunks of _CHUNK (+inf: never chosen); the least of each chunk is kept, so the 8 best
    # candidates are found among the 8 chunks of least minimum (each of the 8 best lies in such a chunk)
    chunks = -(-m // _CHUNK)
    est = np.full(chunks * _CHUNK, np.inf)
    neg_est = est[:m]
    neg_est[:] = -(4.0 / 3.0 * np.pi * cr**3 - (1.0 + spill_weight) * cap)
    chunk_min = est.reshape(chunks, _CHUNK).min(axis=1)
    lanes = np.arange(_CHUNK)

    def best8():
        if chunks <= 8:
            return np.argpartition(neg_est, min(8, m - 1))[:8]
        near_chunks = np.argpartition(chunk_min, 7)[:8]
        pool = (near_chunks[:, None] * _CHUNK + lanes).ravel()
        return pool[np.argpartition(est[pool], 7)[:8]]

    def refresh(lo, hi):
        c0, c1 = lo // _CHUNK, -(-hi // _CHUNK)
        chunk_min[c0:c1] = est[c0 * _CHUNK:c1 * _CHUNK].reshape(c1 - c0, _CHUNK).min(axis=1)

    cr_max = float(cr.max()) if len(cr) else 0.0
    x_index = np.ascontiguousarray(cidx[:, 0])
    # centre coordinates, one contiguous array per axis (the per-step squared distances)
    px, py, pz = (np.ascontiguousarray(cp[:, k]) for k in range(3))
    placed = 0
    # exact gains counted in earlier steps, kept while no placed sphere's box meets the candidate's
    known: dict[int, tuple] = {}
    while placed < n and m:
        top = best8()
        top = top[top < m]
        if not neg_est[top].min() < 0:
            break  # no candidate left that is estimated to gain
        best, best_gain = -1, -1
        for t in top:
            t = int(t)
            if t in known:
                gain, blk, lo, hi = known[t]
            else:
                known[t] = gain, blk, lo, hi = _exact_gain(cp[t // twins], cr[t], cidx[t // twins].tolist(), h, axes,
                                                           shape, u_in, u_out, spill_weight)
            if gain > best_gain:
                best, best_gain, best_blk, best_lo, best_hi = t, gain, blk, lo, hi
        if best_gain <= 0:
            neg_est[top] = np.abs(neg_est[top]) + 1.0  # none of these gains: drop them, count the next 8
            for c in np.unique(top // _CHUNK).tolist():
                refresh(c * _CHUNK, c * _CHUNK + 1)
            continue
        c, r = cp[best // twins], cr[best]
        best_box = (slice(best_lo[0], best_hi[0]), slice(best_lo[1], best_hi[1]), slice(best_lo[2], best_hi[2]))
        u_in[best_box] &= ~best_blk
        u_out[best_box] &= ~best_blk
        (bl0, bl1, bl2), (bh0, bh1, bh2) = best_lo, best_hi
        known = {t: k for t, k in known.items()
                 if not (k[2][0] < bh0 and k[2][1] < bh1 and k[2][2] < bh2
                         and bl0 < k[3][0] and bl1 < k[3][1] and bl2 < k[3][2])}
        placed += 1
        yield c, r
        # only overlapping candidates lose estimated gain; they lie within r + the largest candidate
        # radius in x, i.e. in one slice of the candidates (listed in grid order, x index first)
        reach = int(np.ceil((r + cr_max) / h)) + 1
        xb = cidx[best // twins][0]
        a, b = np.searchsorted(x_index, [xb - reach, xb + reach + 1])
        d2 = (px[a:b] - c[0]) ** 2
        d2 += (py[a:b] - c[1]) ** 2
        d2 += (pz[a:b] - c[2]) ** 2
        if twins > 1:
            d2, a, b = np.repeat(d2, twins), a * twins, b * twins
        near = a + np.flatnonzero(d2 < (r + cr[a:b]) ** 2)
        which, loss = _lens_loss(cr[near], r, np.sqrt(d2[near - a]))
        neg_est[near[which]] += loss
        if len(which):
            refresh(int(near[which[0]]), int(near[which[-1]]) + 1)


def _take(placed, n: int, centres: list, radii: list) -> bool:
    """Append spheres from the greedy ``placed`` to ``centres`` and ``radii`` until they hold ``n``; False when
    the greedy ended first."""
    for c, r in placed:
        centres.append(c)
        radii.append(r)
        if len(radii) >= n:
            return True
    return len(radii) >= n


def _arrays(centres: list, radii: list, k: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array(centres[:k]).reshape(-1, 3), np.array(radii[:k])


def _grow_to_target(measure: _Measure, placed, cap: int, target: float,
                    least: int = 1) -> tuple[np.ndarray, np.ndarray, ClumpAccuracy]:
    """The fewest leading spheres of the greedy ``placed`` (at least ``least``, at most ``cap``) whose
    intersection over union reaches ``target``, and their measure.

    The greedy is run only as far as needed: the prefix of ``_FIRST_PREFIX`` spheres is measured, then
    twice as many, and so on up to the cap, until one reaches the target; the count is then found by
    bisection between the last prefix that missed and the first that reached it (at most
    :func:`accuracy_measures` measures).  A clump that misses with every sphere it may take keeps them
    all.  Each sphere of the greedy order adds more than ``spill_weight`` (> 1) times as much grain as
    it adds volume outside, so the intersection over union rises with the prefix on the working grid
    (on the measuring grid, up to its error).
    """
    centres: list = []
    radii: list = []
    lo, missed = least - 1, None  # the prefix of lo spheres misses the target (or is too few), measured so
    n = min(cap, max(_FIRST_PREFIX, least))
    while True:
        more = _take(placed, n, centres, radii)
        n = len(radii)
        if missed is not None and n == lo:  # the greedy ended: no sphere beyond the last prefix measured
            return (*_arrays(centres, radii, n), missed)
        best = measure(*_arrays(centres, radii, n))
        if best.iou >= target:
            break
        if not more or n >= cap:
            return (*_arrays(centres, radii, n), best)
        lo, missed, n = n, best, min(2 * n, cap)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        a = measure(*_arrays(centres, radii, mid))
        if a.iou >= target:
            hi, best = mid, a
        else:
            lo = mid
    return (*_arrays(centres, radii, hi), best)


def _refine(centres, radii, pin, pout, h, spill_weight, iterations):
    from scipy.optimize import minimize

    n = len(radii)
    tau = 0.5 * h
    pts = np.vstack([pin, pout])
    w = np.concatenate([-np.ones(len(pin)), spill_weight * np.ones(len(pout))]) / len(pin)

    def fun(x):
        c = x[: 3 * n].reshape(n, 3)
        r = x[3 * n:]
        diff = pts[:, None, :] - c[None, :, :]
        dist = np.sqrt(np.einsum("pnk,pnk->pn", diff, diff))
        phi = r[None, :] - dist
        k = np.argmax(phi, axis=1)
        rows = np.arange(len(pts))
        m = phi[rows, k]
        s = 1.0 / (1.0 + np.exp(-np.clip(m / tau, -40, 40)))
        loss = float(w @ s)
        g = w * s * (1 - s) / tau  # dloss/dm
        gr = np.bincount(k, weights=g, minlength=n)
        unit = diff[rows, k] / np.maximum(dist[rows, k], 1e-12)[:, None]
        gc = np.zeros((n, 3))
        for ax in range(3):
            gc[:, ax] = np.bincount(k, weights=g * unit[:, ax], minlength=n)
        return loss, np.concatenate([gc.ravel(), gr])

    x0 = np.concatenate([centres.ravel(), radii])
    bounds = [(None, None)] * (3 * n) + [(0.5 * h, None)] * n
    res = minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": iterations, "gtol": 1e-12, "ftol": 1e-12})
    return res.x[: 3 * n].reshape(n, 3), res.x[3 * n:]


def clump(vertices: np.ndarray, faces: np.ndarray, *, spheres: int = 30, resolution: int = 40,
          spill_weight: float = 4.0, samples: int = 3000, iterations: int = 0,
          measure_resolution: int = 100, overshoot: float = 0.02, growth: float = 0.1, rng=None,
          target_iou: float | None = None, min_spheres: int = 1) -> Clump:
    """A clump of ``spheres`` spheres approximating a closed mesh, or of as few as reach an accuracy.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        A closed, outward-oriented mesh (any units; the clump is in the same).
    spheres : int
        The trade-off knob: more spheres, better coverage, more cost in the
        DEM engine (≥ 1). With ``target_iou``, the most spheres the clump may take.
    resolution : int
        Cells per equivalent diameter of the working grid.
    spill_weight : float
        Cost of a unit of volume outside the grain relative to a unit of
        grain volume covered, in the refinement (> 0; larger → less spill).
    samples : int
        Cell centres sampled (inside and around) for the refinement.
    iterations : int
        L-BFGS-B iterations of the refinement (0: greedy spheres only).
    measure_resolution : int
        Cells per equivalent diameter of the grid that measures the result.
    overshoot : float
        Candidate radius = inscribed radius + ``overshoot · d_eq``: lets the
        spheres cross the surface a little (spill) to cover more of it.
    growth : float
        Each candidate centre also offers a sphere larger by ``growth`` × its
        depth (its distance to the surface on the working grid; ≥ 0, 0: one
        candidate per centre). The greedy takes the grown sphere where the
        grain it adds outweighs ``spill_weight`` × its spill: large spheres
        that reach past gently curved surface into the grain around them.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        The refinement's sample of cell centres, normalised by :func:`grainforge.rng.as_generator`
        (an int gives the same clump every time; unused without ``iterations``).
    target_iou : float, optional
        An accuracy target in (0, 1): the clump takes the fewest leading
        spheres of the greedy order (at most ``spheres``) whose intersection
        over union with the grain (:func:`clump_accuracy` on the measuring
        grid) reaches it: the prefixes of 8, 16, 32, … spheres are measured
        until one does, then a bisection finds the count. A clump that
        reaches it only with more spheres keeps ``spheres`` of them and has
        ``meets_target`` false. With ``iterations``, the refinement moves the
        chosen spheres afterwards and the figures are the refined clump's.
        ``None`` (default): exactly the fixed-count clump.
    min_spheres : int
        With ``target_iou``: the fewest spheres the clump takes (2 for an
        engine that refuses a body of one sphere, as LIGGGHTS and LAMMPS do).

    Returns
    -------
    Clump
        With a target, ``accuracy`` holds every figure of :func:`clump_accuracy`
        and ``meets_target`` says whether the target is reached.

    Raises
    ------
    ValueError
        For ``spheres < 1``, ``spill_weight ≤ 0``, a negative or non-finite ``growth``, a ``target_iou``
        outside (0, 1), ``measure_resolution < 10`` with a target, a mesh of non-positive volume, or an
        ``rng`` :func:`grainforge.rng.as_generator` refuses.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box((1.0, 1.0, 2.0))
    >>> c = clump(box.vertices, box.faces, spheres=8, rng=0)
    >>> c.count, round(c.coverage, 1), round(c.spill, 2)  # coverage 0.86-0.87 with the libraries' versions
    (8, 0.9, 0.08)

    A box's flat faces are where grown spheres spill most; without them
    (``growth=0``) the clump covers less and spills less:

    >>> flat = clump(box.vertices, box.faces, spheres=8, rng=0, growth=0)
    >>> flat.count, round(flat.coverage, 1), flat.coverage < c.coverage, flat.spill < c.spill
    (8, 0.8, True, True)

    Built to an accuracy instead: a ball needs one sphere for an intersection
    over union of 0.85, the box eight for 0.8; twenty do not reach 0.85.

    >>> ball = trimesh.creation.icosphere(4)
    >>> b = clump(ball.vertices, ball.faces, spheres=20, target_iou=0.85, measure_resolution=40)
    >>> b.count, b.meets_target, round(b.accuracy.iou, 3)
    (1, True, 0.875)
    >>> c = clump(box.vertices, box.faces, spheres=20, target_iou=0.8, measure_resolution=40)
    >>> c.count, c.meets_target, 0.8 <= c.accuracy.iou < 0.81
    (8, True, True)
    >>> c = clump(box.vertices, box.faces, spheres=20, target_iou=0.85, measure_resolution=40)
    >>> c.count, c.meets_target, 0.83 < c.accuracy.iou < 0.85
    (20, False, True)
    """
    from scipy import ndimage

    spheres = int(spheres)
    if spheres < 1:
        raise InputError(f"spheres must be ≥ 1, got {spheres!r}")
    if not spill_weight > 0:
        raise InputError(f"spill_weight must be positive, got {spill_weight!r}")
    if not (math.isfinite(growth) and growth >= 0):
        raise InputError(f"growth must be a finite number ≥ 0, got {growth!r}")
    if target_iou is not None:
        target_iou = check_target(target_iou)
        if int(measure_resolution) < 10:
            raise InputError(f"measure_resolution must be ≥ 10 cells per diameter, got {measure_resolution!r}")
    rng = as_generator(rng)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = _equivalent_diameter(v, f)
    h = d / resolution
    grid = grid_for(v, h, pad=3)
    inside = inside_mask(v, f, grid)
    # the distance transform on the inside's box plus one empty cell each side: the same distances
    # (the nearest empty cell of an inside cell is never beyond that layer) on fewer cells; scipy's
    # feature transform gives each inside cell its nearest empty cell, and the distance is taken
    # for the inside cells only (scipy's arithmetic: float64 squares of integer offsets, summed)
    idx = np.argwhere(inside)
    depth = np.zeros(len(idx))
    if len(idx):
        lo = np.maximum(idx.min(axis=0) - 1, 0)
        hi = np.minimum(idx.max(axis=0) + 2, inside.shape)
        crop = tuple(slice(a, b) for a, b in zip(lo, hi))
        ft = ndimage.distance_transform_edt(inside[crop], return_distances=False, return_indices=True)
        loc = (idx - lo).T
        off = (ft[:, loc[0], loc[1], loc[2]] - loc).astype(np.float64)
        off *= off
        depth = np.sqrt(np.add.reduce(off, axis=0)) * h
    pts = grid.points(idx)
    placed = _greedy(pts, depth, idx, grid, spheres, h, inside, overshoot * d, spill_weight, float(growth))
    measure = None
    if target_iou is None:
        c_list: list = []
        r_list: list = []
        _take(placed, spheres, c_list, r_list)
        centres, radii = _arrays(c_list, r_list, len(r_list))
    else:
        measure = _Measure(v, f, d, measure_resolution)
        centres, radii, accuracy = _grow_to_target(measure, placed, spheres, target_iou,
                                                   max(1, min(int(min_spheres), spheres)))
    if iterations > 0 and len(radii):
        outside_depth = ndimage.distance_transform_edt(~inside) * h
        band = (~inside) & (outside_depth <= 0.05 * d)
        near = depth <= 0.1 * d
        idx_all = idx
        idx, pts = idx[near], pts[near]
        oidx = np.argwhere(band)
        n_in = min(len(idx), samples)
        n_out = min(len(oidx), samples // 2)
        pin = pts[np.sort(rng.choice(len(idx), n_in, replace=False))]
        pout = grid.points(oidx[np.sort(rng.choice(len(oidx), n_out, replace=False))])
        # the band sample stands for the band's volume: weight by its share
        pin_w = len(idx) / n_in
        idx = idx_all
        pout_w = len(oidx) / max(n_out, 1)
        centres, radii = _refine(centres, radii, pin, pout, h, spill_weight * pout_w / pin_w, iterations)
    if measure is not None:
        if iterations > 0 and len(radii):
            accuracy = measure(centres, radii)
        # coverage and spill are _quality's own: the same counts on the same grid
        return Clump(centres, radii, accuracy.coverage, accuracy.spill, int(measure_resolution), accuracy=accuracy,
                     target=target_iou)
    cov, spill = _quality(v, f, d, centres, radii, measure_resolution)
    return Clump(centres, radii, float(cov), float(spill), int(measure_resolution))
