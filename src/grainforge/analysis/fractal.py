"""Surface roughness and a surface fractal dimension estimate from the radial function.

Both work on the grain's radial function r(u) = |x − c| sampled at the
vertices (u the unit direction from the volume centroid c):

* **roughness** — a smooth low-order shape is fitted by area-weighted least
  squares of 1/r² on the polynomials of degree ≤ 4 in u (the same space as
  the spherical harmonics of degree ≤ 4), r_fit = (fit)^(−1/2).  Fitting 1/r²
  rather than r makes every centred ellipsoid exact (1/r² = uᵀAu is
  quadratic in u), so form (elongation, flatness) does not count as
  roughness.  Roughness is the area-weighted RMS of r − r_fit relative to the
  mean radius: 0 for spheres and ellipsoids.
* **fractal dimension** — the variogram of the residual h:
  γ(δ) = ½ E[(h(u) − h(u′))²] over vertex pairs at angular separation δ.
  For a self-affine surface γ ∝ δ^(2H) with Hurst exponent H, and the
  surface's fractal dimension is D = 3 − H (the profile spectrum exponent is
  β = 1 + 2H, so this is D = (7 − β)/2 of docs/design/algorithms.md §4).  The slope is
  fitted in log–log over δ from twice the mesh's median angular edge length
  (below that the mesh interpolates linearly, which biases the slope towards
  smoothness) to 0.35 rad (above that the degree-4 trend removal flattens the
  variogram).  The estimate is clipped to [2, 3].

The estimator is deterministic: the shortest-separation bin holds every
vertex pair in it, the others all pairs of an evenly strided subset of 1,000
vertices.  It measures the *sampled* surface, so a rough grain on a coarse
mesh reads smoother than its generator's D; ``docs/validation.md`` shows how
it tracks FSO's input D.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["radial_function", "smooth_fit", "roughness", "variogram", "fractal_dimension", "FIT_DEGREE"]

#: degree of the smooth fit removed before roughness and fractal analysis
FIT_DEGREE = 4
#: homogeneous monomials of degrees 4 and 3 (15 + 10 = 25): on the unit sphere (x² + y² + z² = 1)
#: they span every polynomial of degree ≤ 4, i.e. the spherical harmonics of degree ≤ 4, without redundancy
_MONOMIALS = [(a, b, d - a - b) for d in (FIT_DEGREE, FIT_DEGREE - 1) for a in range(d + 1) for b in range(d + 1 - a)]


def radial_function(vertices: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (V, 3) and radii (V,) of vertices seen from ``centre``.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Points.
    centre : (3,) ndarray of float
        The origin of the radii.

    Returns
    -------
    u : (V, 3) float64
        Unit directions (zero vectors give the vertex offset unchanged: 0).
    r : (V,) float64
        Distances, in the vertices' unit.
    """
    d = np.asarray(vertices, dtype=np.float64) - centre
    r = np.linalg.norm(d, axis=1)
    return d / np.where(r > 0, r, 1.0)[:, None], r


def _basis(u: np.ndarray) -> np.ndarray:
    """The 25 monomials of ``_MONOMIALS`` at the directions ``u``, as rows: (25, V)."""
    n = len(u)
    # powers 0…4 of each coordinate, built by repeated multiplication: pw[axis, k] = u[:, axis]**k
    pw = np.empty((3, FIT_DEGREE + 1, n))
    pw[:, 0] = 1.0
    pw[:, 1] = u.T
    for k in range(2, FIT_DEGREE + 1):
        np.multiply(pw[:, k - 1], pw[:, 1], out=pw[:, k])
    B = np.empty((len(_MONOMIALS), n))
    for row, (a, b, c) in enumerate(_MONOMIALS):
        np.multiply(pw[0, a], pw[1, b], out=B[row])
        B[row] *= pw[2, c]
    return B


def _pairs_by_exponent():
    """Representative basis pairs (i, j) of each distinct exponent sum e_i + e_j, and the map
    from the 25 × 25 Gram entries to them (the Gram matrix has only 109 distinct entries)."""
    e = np.array(_MONOMIALS)
    s = e[:, None, :] + e[None, :, :]  # exponents of B_i·B_j
    key = (s[..., 0] * (2 * FIT_DEGREE + 1) + s[..., 1]) * (2 * FIT_DEGREE + 1) + s[..., 2]
    _, first, inverse = np.unique(key.ravel(), return_index=True, return_inverse=True)
    i, j = np.unravel_index(first, key.shape)
    return list(zip(i.tolist(), j.tolist())), inverse.reshape(key.shape)


_GRAM_PAIRS, _GRAM_INDEX = _pairs_by_exponent()


def smooth_fit(u: np.ndarray, r: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Smooth radii: area-weighted least-squares fit of 1/r² by polynomials of degree ≤ 4 in u.

    Exact for spheres and centred ellipsoids of any orientation.

    Parameters
    ----------
    u : (V, 3) array_like of float
        Unit directions.
    r : (V,) array_like of float
        Radii along them (> 0).
    weights : (V,) array_like of float
        Area weights.

    Returns
    -------
    (V,) float64
        The smooth radii, in the unit of ``r``.

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(3)
    >>> _ = e.apply_scale((3.0, 2.0, 1.0))
    >>> u, r = radial_function(e.vertices, np.zeros(3))
    >>> bool(np.allclose(smooth_fit(u, r, np.ones(len(r))), r, rtol=1e-8))
    True
    """
    B = _basis(np.asarray(u, dtype=np.float64))  # (25, V)
    Bw = B * weights
    # normal equations (25 × 25).  Entry (i, j) is the weighted sum of the monomial B_i·B_j, so
    # only one product per distinct monomial is summed.  einsum rather than BLAS: threaded BLAS
    # on these skinny products is slow on a busy machine.
    moments = np.array([np.einsum("v,v->", Bw[i], B[j]) for i, j in _GRAM_PAIRS])
    scale = float(np.mean(r)) or 1.0
    g = (scale / r) ** 2
    coef, *_ = np.linalg.lstsq(moments[_GRAM_INDEX], np.einsum("iv,v->i", Bw, g), rcond=1e-12)
    fit = np.einsum("iv,i->v", B, coef)
    return scale / np.sqrt(np.maximum(fit, 1e-6))


def roughness(residual: np.ndarray, weights: np.ndarray, mean_radius: float) -> float:
    """Area-weighted RMS of the radial residual over the mean radius.

    Parameters
    ----------
    residual : (V,) ndarray of float
        r − smooth r per vertex.
    weights : (V,) ndarray of float
        Area weights.
    mean_radius : float
        The normaliser, in the unit of ``residual``.

    Returns
    -------
    float
        Dimensionless.

    Examples
    --------
    >>> roughness(np.array([0.1, -0.1]), np.ones(2), 2.0)
    0.05
    """
    return float(np.sqrt(np.sum(weights * residual**2) / np.sum(weights)) / mean_radius)


@functools.lru_cache(maxsize=4)
def _strided_subset(n: int, subset: int) -> np.ndarray:
    """The evenly strided subset of ``n`` vertices (indices)."""
    idx = np.unique(np.linspace(0, n - 1, min(subset, n)).round().astype(np.int64))
    idx.flags.writeable = False
    return idx


def variogram(u: np.ndarray, h: np.ndarray, bins: np.ndarray, *, subset: int = 1000):
    """Binned variogram ½⟨(h_i − h_j)²⟩ against angular separation (radians).

    Pairs: the first bin holds *every* vertex pair whose separation falls in
    it (found with a k-d tree radius query); the other bins hold all pairs
    a < b of an evenly strided subset of ``subset`` vertices whose separation
    falls in them.  Each bin's pairs are taken in row-major (a, b) order.

    Parameters
    ----------
    u : (V, 3) array_like of float
        Unit directions of the vertices.
    h : (V,) array_like of float
        The field at each vertex (e.g. the radial residual).
    bins : (B + 1,) array_like of float
        Bin edges of the angular separation, radians, increasing.
    subset : int, default 1000
        Vertices used for the bins after the first.

    Returns
    -------
    centres : (B,) float64
        Mean separation of the pairs in each bin (NaN if empty).
    gamma : (B,) float64
    counts : (B,) int64

    Examples
    --------
    >>> import trimesh
    >>> u = np.asarray(trimesh.creation.icosphere(3).vertices)
    >>> c, g, n = variogram(u, u[:, 2], np.array([0.1, 0.2, 0.4]))
    >>> bool(np.all(n > 100)), bool(g[0] < g[1])   # a linear trend: γ grows with separation
    (True, True)
    """
    from scipy.spatial import cKDTree

    u = np.asarray(u, dtype=np.float64)
    h = np.asarray(h, dtype=np.float64)
    n = len(u)
    bins = np.asarray(bins, dtype=np.float64)
    edges = -np.cos(bins)  # bin on −cos(separation), which increases with the separation (no arccos per pair)
    nb = len(bins) - 1

    def chord(angle):  # the chord between unit vectors at this angle, with a margin for rounding
        return 2.0 * np.sin(min(float(angle), np.pi) / 2.0) * (1.0 + 1e-6) + 1e-12

    ux, uy, uz = np.ascontiguousarray(u.T)

    def pairs_of(points, reach):  # pairs a < b closer than reach (in the tree's order)
        ab = cKDTree(points).query_pairs(reach, output_type="ndarray")
        return ab[:, 0], ab[:, 1]

    def binned(a, b, first, last):  # the pairs (a, b) in bins first..last − 1, in row-major (a, b) order
        negdot = -(ux[a] * ux[b] + uy[a] * uy[b] + uz[a] * uz[b])
        which = np.searchsorted(edges, negdot, side="right") - 1
        good = np.flatnonzero((which >= first) & (which < last))
        good = good[np.argsort(a[good] * n + b[good], kind="stable")]
        a, b = a[good], b[good]
        return which[good], 0.5 * (h[a] - h[b]) ** 2, negdot[good]

    # the first bin: every pair (about 10 per vertex on a regular mesh, where it spans 2 to 2.5 edges)
    near = binned(*pairs_of(u, chord(bins[min(1, nb)])), 0, min(1, nb))
    # the other bins: the subset's pairs closer than the last edge
    idx = _strided_subset(n, subset)
    a, b = pairs_of(u[idx], chord(bins[-1]))
    far = binned(idx[a], idx[b], 1, nb)
    which, sq, nd = (np.concatenate(x) for x in zip(near, far))
    counts = np.bincount(which, minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        gamma = np.bincount(which, sq, minlength=nb) / counts
        sep = np.arccos(np.clip(-nd, -1.0, 1.0))
        centres = np.bincount(which, sep, minlength=nb) / counts
    return centres, gamma, counts


def fractal_dimension(u: np.ndarray, residual: np.ndarray, edge_angle: float, *, max_separation: float = 0.35) -> float:
    """Surface fractal dimension D = 3 − H from the slope 2H of the residual's variogram.

    Parameters
    ----------
    u : (V, 3) float64
        Unit directions of the vertices.
    residual : (V,) float64
        Radial deviation from the smooth fit.
    edge_angle : float
        Median angular length of the mesh's edges (radians); the fit starts at twice it.
    max_separation : float
        Largest separation fitted (radians).

    Returns
    -------
    float
        In [2, 3]; NaN when the scaling range is empty (very coarse mesh) or
        the residual vanishes (a smooth shape has no fractal dimension).

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(4)
    >>> u = np.asarray(s.vertices)
    >>> h = np.random.default_rng(0).normal(size=len(u)) * 1e-2  # white noise: H = 0
    >>> round(fractal_dimension(u, h, 0.05), 1)
    3.0
    """
    lo = 2.0 * float(edge_angle)
    if not lo < max_separation / 2 or not np.any(residual):
        return float("nan")
    if np.sqrt(np.mean(residual**2)) < 1e-9:
        return float("nan")
    bins = np.geomspace(lo, max_separation, 9)
    centres, gamma, counts = variogram(u, residual, bins)
    ok = (counts >= 20) & (gamma > 0)
    if ok.sum() < 3:
        return float("nan")
    slope = np.polyfit(np.log(centres[ok]), np.log(gamma[ok]), 1)[0]
    H = slope / 2.0
    return float(np.clip(3.0 - H, 2.0, 3.0))
