"""Fractality of aggregates (DPA, paper §2.3 and Eq. 5; docs/design/algorithms.md §3).

All lengths are in units of the primary size a = V_p^(1/3) and volumes in
units of the primary volume V_p, so every figure here is dimensionless.

- Aggregate fractal dimension (Eq. 5): D_A = log V / log A, with V the true
  volume (N primaries ⇒ V = N) and A the mean edge of the smallest
  (minimum-volume) bounding box.
- Scaling dimension D_A,s: the same log V against log A, fitted over the
  aggregate's own growth (the first n primaries, n from N/16 to N) instead
  of drawn from a single primary (V = A = 1) to the whole aggregate.  Eq. 5
  is the secant of that curve through (1, 1); for compact aggregates its
  prefactor (V ≈ c·A³, c < 1) keeps Eq. 5 well below 3 at any practical N
  (2.6 at N = 1000), while the slope is ≈ 3.
- Porosity: 1 − V / V_hull (V_hull the volume of the convex hull).
- Radius of gyration R_g of the solid aggregate (uniform density).
- Mass–radius dimension over an ensemble: N = k_f (R_g/a)^D_f.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = [
    "aggregate_dimension",
    "scaling_dimension",
    "bounding_box_edges",
    "porosity",
    "radius_of_gyration",
    "mass_radius_fit",
    "aggregate_measures",
]


def aggregate_dimension(volume: float, box_edges) -> float:
    """D_A = log V / log A (paper Eq. 5).

    Parameters
    ----------
    volume : float
        V in units of the primary volume.
    box_edges : (3,) float
        Edges of the minimum-volume bounding box in units of the primary size;
        A is their mean.

    Returns
    -------
    float
        D_A, or NaN when A ≤ 1 or V ≤ 1 (a single primary: 0/0).

    Examples
    --------
    >>> aggregate_dimension(27.0, (3.0, 3.0, 3.0))
    3.0
    >>> round(aggregate_dimension(10.0, (10.0, 1.0, 1.0)), 4)  # a straight rod of 10 cubes
    1.661
    """
    A = float(np.mean(box_edges))
    V = float(volume)
    if not (A > 1.0 and V > 1.0):
        return float("nan")
    return float(np.log(V) / np.log(A))


#: sub-aggregates of the scaling fit: sizes N, N/√2, N/2, … down to max(SCALING_MIN, N/SCALING_SPAN)
SCALING_SPAN = 16
SCALING_MIN = 8


def scaling_dimension(points, owner, primaries: int, *, whole_mean_edge: float | None = None) -> float:
    """Slope of log V against log A over an aggregate's growth (its scaling dimension).

    The first n primaries of an aggregate grown one primary at a time are
    themselves an aggregate; V(n) = n and A(n) is the mean edge of their
    minimum-volume box.  The slope of log n against log A(n), fitted by least
    squares over n = N, N/√2, N/2, … ≥ max(8, N/16), is the mass–size
    dimension without Eq. 5's prefactor: 3 for compact growth, 1 for a rod.

    Parameters
    ----------
    points : (P, 3) float
        Vertices of the primaries.
    owner : (P,) int
        0-based index (growth order) of the primary each point belongs to.
    primaries : int
        N.
    whole_mean_edge : float, optional
        A(N), the box mean edge of the whole aggregate, if already measured.

    Returns
    -------
    float
        The slope, or NaN with fewer than three sub-aggregate sizes (N < 16).

    Examples
    --------
    >>> import numpy as np
    >>> rod = np.array([[i + dx, dy, dz] for i in range(64) for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)])
    >>> round(scaling_dimension(rod, np.repeat(np.arange(64), 8), 64), 2)  # a straight rod of cubes
    1.08
    """
    from .box import minimum_box

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    own = np.asarray(owner).ravel()
    N = int(primaries)
    low = max(SCALING_MIN, N / SCALING_SPAN)
    sizes = sorted({int(round(N / np.sqrt(2.0) ** j)) for j in range(80) if N / np.sqrt(2.0) ** j >= low})
    if len(sizes) < 3:
        return float("nan")
    A = [float(whole_mean_edge) if n == N and whole_mean_edge is not None
         else float(minimum_box(pts[own < n])[0].mean()) for n in sizes]
    return float(np.polyfit(np.log(A), np.log(sizes), 1)[0])


def bounding_box_edges(points) -> np.ndarray:
    """Edges (descending) of the minimum-volume bounding box of ``points``.

    Uses :func:`grainforge.analysis.box.minimum_box` (exact over the convex
    hull's face directions; the classical face-flush search for the 3D
    minimum-volume box, never smaller than it).

    Parameters
    ----------
    points : (P, 3) array_like of float
        The aggregate's vertices (only their convex hull matters).

    Returns
    -------
    (3,) float64
        L ≥ I ≥ S, in the points' unit.

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array(np.meshgrid([0, 4], [0, 1], [0, 2])).T.reshape(-1, 3)
    >>> bounding_box_edges(corners).round(6).tolist()
    [4.0, 2.0, 1.0]
    """
    from .box import minimum_box

    return minimum_box(points)[0]


def porosity(volume: float, points, hull=None) -> float:
    """1 − V / V_hull with V_hull the convex hull volume of ``points`` (or of ``hull``, their
    scipy ``ConvexHull`` if already computed).

    Parameters
    ----------
    volume : float
        The aggregate's volume, in the cube of the points' unit.
    points : (P, 3) array_like of float
        Its vertices.
    hull : scipy.spatial.ConvexHull, optional
        Their hull, if already computed.

    Returns
    -------
    float
        In [0, 1) (clipped at 0 when the volume exceeds the hull's by rounding).

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array(np.meshgrid([0, 2], [0, 2], [0, 2])).T.reshape(-1, 3)
    >>> porosity(8.0, corners), porosity(4.0, corners)
    (0.0, 0.5)
    """
    from scipy.spatial import ConvexHull

    if hull is None:
        hull = ConvexHull(np.asarray(points, dtype=np.float64))
    return float(max(0.0, 1.0 - float(volume) / hull.volume))


def radius_of_gyration(centres, primary_gyration2: float = 0.0) -> float:
    """R_g of an aggregate of equal, non-overlapping primaries.

    By the parallel-axis theorem R_g² = mean |c_i − c̄|² + r_p², with c_i
    the primaries' centres and r_p their own radius of gyration.

    Parameters
    ----------
    centres : (N, 3) float64
    primary_gyration2 : float
        r_p² of one primary (1/4 for a unit cube).

    Returns
    -------
    float
        In the centres' unit.

    Examples
    --------
    >>> radius_of_gyration([[0, 0, 0]], 0.25)
    0.5
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    d2 = ((c - c.mean(axis=0)) ** 2).sum(axis=1).mean()
    return float(np.sqrt(d2 + primary_gyration2))


def mass_radius_fit(primaries, gyration_radii) -> tuple[float, float]:
    """Least-squares fit of N = k_f (R_g/a)^D_f over an ensemble.

    Parameters
    ----------
    primaries : (M,) numbers of primaries N
    gyration_radii : (M,) R_g in units of the primary size

    Returns
    -------
    (D_f, k_f) : tuple of float

    Raises
    ------
    ValueError
        With fewer than two distinct R_g values.

    Examples
    --------
    >>> import numpy as np
    >>> rg = np.array([2.0, 4.0, 8.0])
    >>> D, k = mass_radius_fit(1.5 * rg**2.2, rg)
    >>> round(D, 6), round(k, 6)
    (2.2, 1.5)
    """
    n = np.asarray(primaries, dtype=np.float64).ravel()
    r = np.asarray(gyration_radii, dtype=np.float64).ravel()
    if n.shape != r.shape:
        raise InputError("primaries and gyration_radii must have the same length")
    if len(np.unique(r)) < 2:
        raise InputError("the mass-radius fit needs at least two different radii of gyration")
    slope, intercept = np.polyfit(np.log(r), np.log(n), 1)
    return float(slope), float(np.exp(intercept))


def aggregate_measures(points, centres, *, volume: float, primary_gyration2: float, owner=None) -> dict[str, float]:
    """D_A, its scaling form, porosity, R_g and the box mean edge A of one aggregate.

    Parameters
    ----------
    points : (P, 3) float64
        Vertices of all primaries (the hull and the box depend only on them).
    centres : (N, 3) float64
        Centres of the primaries.
    volume : float
        Aggregate volume in primary volumes (N for N primaries).
    primary_gyration2 : float
        Squared radius of gyration of one primary.
    owner : (P,) int, optional
        Growth index of the primary of each point; with it ``D_A_scaling``
        (:func:`scaling_dimension`) is measured, else it is NaN.

    Returns
    -------
    dict of str to float
        ``D_A`` (Eq. 5, :func:`aggregate_dimension`), ``D_A_scaling``, ``porosity``, ``R_g`` (in the
        points' unit) and ``box_mean_edge`` (the mean edge A of the minimum-volume box).

    Examples
    --------
    >>> corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1])).T.reshape(-1, 3).astype(float)
    >>> m = aggregate_measures(corners, [[0.5, 0.5, 0.5]], volume=1.0, primary_gyration2=0.25)
    >>> m["porosity"], m["R_g"], m["box_mean_edge"]
    (0.0, 0.5, 1.0)
    """
    from scipy.spatial import ConvexHull

    from .box import minimum_box

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    hull = ConvexHull(pts)  # one hull for the box and the porosity
    edges = minimum_box(pts, hull)[0]
    n = len(np.asarray(centres).reshape(-1, 3))
    scaling = float("nan")
    if owner is not None:
        scaling = scaling_dimension(pts, owner, n, whole_mean_edge=float(edges.mean()))
    return {
        "D_A": aggregate_dimension(volume, edges),
        "D_A_scaling": scaling,
        "porosity": porosity(volume, pts, hull),
        "R_g": radius_of_gyration(centres, primary_gyration2),
        "box_mean_edge": float(edges.mean()),
    }
