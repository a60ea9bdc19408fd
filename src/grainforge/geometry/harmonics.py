"""Real spherical harmonics on unit vectors, and fast synthesis of band-limited fields.

The real, orthonormal harmonics (∫ Y_lm Y_l'm' dΩ = δ_ll' δ_mm') are

    Y_l0 = P̄_l0(cos φ),  Y_lm = √2 P̄_lm(cos φ) cos mθ,  Y_l,−m = √2 P̄_lm(cos φ) sin mθ  (m > 0),

with θ the azimuth from +x, φ the polar angle from +z and P̄_lm the
orthonormalised associated Legendre functions (no Condon–Shortley phase),
computed by the standard stable three-term recurrence

    P̄_00 = 1/√(4π),  P̄_mm = √((2m+1)/(2m)) sin φ P̄_(m−1)(m−1),  P̄_(m+1)m = √(2m+3) cos φ P̄_mm,
    P̄_lm = a_lm (cos φ P̄_(l−1)m − b_lm P̄_(l−2)m),
    a_lm = √((4l²−1)/(l²−m²)),  b_lm = √(((l−1)²−m²)/(4(l−1)²−1)),

vectorised over the vertices and over m (one step per degree l).  Columns
are ordered by (l, m) with m = −l…l: column ``l² + l + m − lmin²``.

Synthesis f = Σ a_lm Y_lm uses the mirror symmetries of the basis: under
x → −x, y → −y, z → −z every Y_lm is even or odd, so f at a vertex v is a
signed sum of eight partial sums evaluated at |v| (component-wise).  A
geodesic sphere is symmetric under the three mirrors, so its 10,242 vertices
have only 1,329 distinct |v|: the synthesis reads an 8× smaller basis.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError

__all__ = ["real_harmonics", "legendre_equator", "degree_order", "Synthesis", "synthesis", "icosphere_synthesis"]


def degree_order(degree: int, lmin: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Degree l and order m of each column of :func:`real_harmonics`.

    Parameters
    ----------
    degree : int
        Highest degree L.
    lmin : int, default 0
        Lowest degree.

    Returns
    -------
    l, m : ((L+1)² − lmin²,) int64
        Degree and order of each column.

    Examples
    --------
    >>> l, m = degree_order(2, lmin=1)
    >>> l.tolist(), m.tolist()
    ([1, 1, 1, 2, 2, 2, 2, 2], [-1, 0, 1, -2, -1, 0, 1, 2])
    """
    l = np.concatenate([np.full(2 * k + 1, k) for k in range(lmin, degree + 1)]).astype(np.int64)
    m = np.concatenate([np.arange(-k, k + 1) for k in range(lmin, degree + 1)]).astype(np.int64)
    return l, m


def _recurrence_coefficients(degree: int) -> tuple[np.ndarray, np.ndarray]:
    L = degree
    l = np.arange(L + 1, dtype=np.float64)[:, None]
    m = np.arange(L + 1, dtype=np.float64)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.sqrt((4 * l * l - 1) / (l * l - m * m))
        b = np.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
    return a, b


def _legendre_rows(x: np.ndarray, s: np.ndarray, degree: int):
    """Yield (l, P̄_l,0..l (V, l+1)) for l = 0..degree at cos φ = x, sin φ = s."""
    a, b = _recurrence_coefficients(degree)
    sect = np.full_like(x, 1.0 / np.sqrt(4 * np.pi))  # P̄_ll
    prev2 = prev1 = None
    for l in range(degree + 1):
        row = np.empty((len(x), l + 1))
        if l >= 1:
            row[:, l - 1] = np.sqrt(2 * l + 1) * x * prev1[:, l - 1]
            sect = np.sqrt((2 * l + 1) / (2 * l)) * s * sect
        if l >= 2:
            k = l - 1
            row[:, :k] = a[l, :k] * (x[:, None] * prev1[:, :k] - b[l, :k] * prev2[:, :k])
        row[:, l] = sect
        yield l, row
        prev2, prev1 = prev1, row


def real_harmonics(unit: np.ndarray, degree: int, lmin: int = 0) -> np.ndarray:
    """Real orthonormal spherical harmonics Y_lm at unit vectors, l = lmin…degree.

    Parameters
    ----------
    unit : (V, 3) float64
        Unit vectors.
    degree : int
        Highest degree L ≥ lmin.
    lmin : int
        Lowest degree.

    Returns
    -------
    (V, (L+1)² − lmin²) float64
        Column ``l² + l + m − lmin²`` holds Y_lm.

    Raises
    ------
    ValueError
        Unless 0 ≤ lmin ≤ degree.

    Examples
    --------
    >>> Y = real_harmonics(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), 1)
    >>> np.round(Y[:, 1:] * np.sqrt(4 * np.pi / 3), 12).tolist()  # Y_1,-1 ∝ y, Y_10 ∝ z, Y_11 ∝ x
    [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    u = np.asarray(unit, dtype=np.float64)
    L = int(degree)
    if not 0 <= lmin <= L:
        raise InputError(f"need 0 <= lmin <= degree, got lmin={lmin}, degree={degree}")
    x = np.clip(u[:, 2], -1.0, 1.0)
    s = np.hypot(u[:, 0], u[:, 1])
    theta = np.arctan2(u[:, 1], u[:, 0])
    mm = np.arange(1, L + 1)
    cos_m = np.sqrt(2.0) * np.cos(theta[:, None] * mm)
    sin_m = np.sqrt(2.0) * np.sin(theta[:, None] * mm)
    out = np.empty((len(u), (L + 1) ** 2 - lmin**2))
    for l, row in _legendre_rows(x, s, L):
        if l < lmin:
            continue
        c = l * l + l - lmin**2  # column of m = 0
        out[:, c] = row[:, 0]
        if l:
            out[:, c + 1 : c + l + 1] = row[:, 1:] * cos_m[:, :l]
            out[:, c - l : c] = (row[:, 1:] * sin_m[:, :l])[:, ::-1]
    return out


def legendre_equator(degree: int) -> np.ndarray:
    """P̄_lm(0) for l, m = 0…degree (zero when m > l or l + m is odd), shape (L+1, L+1).

    Parameters
    ----------
    degree : int
        Highest degree L ≥ 0.

    Returns
    -------
    (L+1, L+1) float64
        ``out[l, m]`` = P̄_lm(0), orthonormalised as in :func:`real_harmonics` (without the √2 of m > 0).

    Examples
    --------
    >>> P = legendre_equator(2)
    >>> round(float(P[2, 2] ** 2 * 4 * np.pi), 6)  # (2l+1)(l−m)!/(l+m)! · P_22(0)² = 5/24 · 9
    1.875
    """
    L = int(degree)
    out = np.zeros((L + 1, L + 1))
    for l, row in _legendre_rows(np.zeros(1), np.ones(1), L):
        out[l, : l + 1] = row[0]
    out[np.abs(out) < 1e-300] = 0.0
    return out


# ------------------------------------------------------------------ synthesis
@dataclass(frozen=True)
class Synthesis:
    """A harmonic basis at the distinct |v| of a vertex set, and how to expand it.

    Attributes
    ----------
    degree, lmin : int
    basis : (8, R, K_c) list of float64 arrays
        Per parity class c, the columns of that class at the R distinct |v|.
    columns : list of (K_c,) int64
        The coefficient indices of each class.
    rep : (V,) int64
        Index of |v| among the distinct ones, per vertex.
    signs : (V, 8) float64
        Sign of class c at vertex v.
    """

    degree: int
    lmin: int
    basis: tuple
    columns: tuple
    rep: np.ndarray
    signs: np.ndarray

    def __call__(self, coefficients: np.ndarray) -> np.ndarray:
        """f(v) = Σ a_lm Y_lm(v) for coefficients in column order, at every vertex.

        Evaluated with einsum (no BLAS), so the result does not depend on the
        number of threads and is bit-identical from run to run.
        """
        a = np.asarray(coefficients, dtype=np.float64)
        parts = np.stack([np.einsum("rk,k->r", B, a[c]) for B, c in zip(self.basis, self.columns)])  # (8, R)
        return np.einsum("vc,cv->v", self.signs, parts[:, self.rep])


def _parities(degree: int, lmin: int) -> np.ndarray:
    """(K, 3) 0/1 parity of each column under x, y, z → −x, −y, −z."""
    l, m = degree_order(degree, lmin)
    am = np.abs(m)
    px = np.where(m >= 0, am % 2, (am + 1) % 2)
    py = (m < 0).astype(np.int64)
    pz = (l + am) % 2
    return np.stack([px, py, pz], 1)


#: largest basis (in float64 values) kept in the cache of :func:`synthesis`
CACHE_VALUES = 16_000_000


def synthesis(unit: np.ndarray, degree: int, lmin: int = 0) -> Synthesis:
    """The :class:`Synthesis` of degrees lmin…degree at ``unit`` (not cached; see :func:`_cached`).

    Parameters
    ----------
    unit : (V, 3) array_like of float
        Unit vectors where the field is evaluated.
    degree : int
        Highest degree L ≥ lmin.
    lmin : int, default 0
        Lowest degree.

    Returns
    -------
    Synthesis
        Call it with ``(L+1)² − lmin²`` coefficients (column order of :func:`real_harmonics`) to get the
        field at every vector, shape (V,).

    Examples
    --------
    >>> from grainforge.geometry.geodesic import icosphere
    >>> v, _ = icosphere(2)
    >>> rng = np.random.default_rng(0)
    >>> a = rng.standard_normal(9 * 9 - 4)
    >>> f = synthesis(v, 8, 2)(a)
    >>> bool(np.allclose(f, real_harmonics(v, 8, 2) @ a))
    True
    """
    u = np.asarray(unit, dtype=np.float64)
    au = np.abs(u)
    reps, rep = np.unique(au, axis=0, return_inverse=True)
    rep = rep.ravel()
    Y = real_harmonics(reps, degree, lmin)
    par = _parities(degree, lmin)
    cls = par[:, 0] + 2 * par[:, 1] + 4 * par[:, 2]
    columns = tuple(np.flatnonzero(cls == c) for c in range(8))
    basis = tuple(np.ascontiguousarray(Y[:, c]) for c in columns)
    neg = np.signbit(u)  # (V, 3): the vertex is the mirror image of |v| in these axes
    bits = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], dtype=bool)  # (8, 3)
    odd = (neg[:, None, :] & bits[None, :, :]).sum(axis=2) % 2  # (V, 8)
    signs = np.where(odd == 1, -1.0, 1.0)
    return Synthesis(int(degree), int(lmin), basis, columns, rep, signs)


@lru_cache(maxsize=2)
def _cached(subdivisions: int, degree: int, lmin: int) -> Synthesis:
    from .geodesic import icosphere

    unit, _ = icosphere(subdivisions)
    return synthesis(unit, degree, lmin)


def icosphere_synthesis(subdivisions: int, degree: int, lmin: int = 0) -> Synthesis:
    """:func:`synthesis` at the vertices of ``icosphere(subdivisions)``, cached when small enough.

    Parameters
    ----------
    subdivisions : int
        The geodesic sphere, :func:`grainforge.geometry.geodesic.icosphere` (0 to 8).
    degree : int
        Highest degree L ≥ lmin.
    lmin : int, default 0
        Lowest degree.

    Returns
    -------
    Synthesis
        As :func:`synthesis`; the same object for repeated calls while the basis holds at most
        :data:`CACHE_VALUES` values (two kept).

    Examples
    --------
    >>> icosphere_synthesis(2, 4) is icosphere_synthesis(2, 4)
    True
    """
    from .geodesic import icosphere

    unit, _ = icosphere(subdivisions)
    if len(unit) // 7 * (degree + 1) ** 2 <= CACHE_VALUES:  # about V/7.7 distinct |v|
        return _cached(int(subdivisions), int(degree), int(lmin))
    return synthesis(unit, degree, lmin)
