"""Fractal Surface Overlay (FSO): a Weierstrass–Mandelbrot surface on a geodesic sphere.

Implements Eqs. 2 and 3 of Hanaor et al., *3D printable geomaterials*
(see ``docs/methods/fso.md`` and ALGORITHMS.md §1).  For a vertex at azimuth
θ and polar angle φ, with φ' = φ in the upper hemisphere and π − φ in the
lower one,

    R = R0 + K Σ_m Σ_n w_n {cos(ψ_mn + ζ_mn c) − cos(k_n φ' cos(θ − α_m) + ψ_mn + ζ_mn c)}

where w_n = (2πγ^(n−1)/L)^(D−3), k_n = 2πγ^n/L, c = cos φ in the upper
hemisphere and 0 in the lower one (Eq. 3 has no ζ terms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geodesic import icosphere, spherical
from ..params import ParameterError, param, validate

__all__ = ["Params", "build", "fso", "wm_sum", "wm_sum_reference", "draw_field", "Field"]

NAME = "fso"
VALIDITY_PARAMETER = "amplitude"
#: vertices are unit directions times a positive radius: the solid contract's star certificate applies
STAR_SHAPED = True
#: generation outputs recorded in manifests (K actually used, extreme radii / R0)
INFO_COLUMNS = ("K", "min_radius", "max_radius")
DEFAULT_AMPLITUDE = 0.1
#: icosphere level on which the ``amplitude`` RMS is measured (642 points),
#: so that K, and therefore the grain, does not depend on the mesh resolution.
REFERENCE_SUBDIVISIONS = 3
#: smallest allowed radius, as a fraction of R0.
MIN_RADIUS = 0.05
#: largest phase, in turns, the double sum may reach (keeps float64 phases exact to ~1e-6 rad).
MAX_TURNS = 2.0**32
TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Params:
    """Parameters of the FSO generator (paper Eqs. 2–3)."""

    fractal_dimension: float = param(
        2.4, "fractal dimension D of the overlaid surface", low=2.0, high=3.0, high_open=True
    )
    length_ratio: float = param(
        7.0, "stochastic length parameter L relative to R0 (L/R0 > π elongates)",
        low=0.0, low_open=True, high=1000.0,
    )
    amplitude: float | None = param(
        None, f"RMS of (R − R0)/R0 (default {DEFAULT_AMPLITUDE}; exclusive with k)", low=0.0, high=1.0
    )
    k: float | None = param(None, "the paper's raw amplitude scaling K (exclusive with amplitude)", low=0.0)
    ridges: int = param(40, "number of superimposed ridges M", kind="int", low=1, high=400)
    frequencies: int = param(40, "number of frequencies n_max", kind="int", low=1, high=400)
    gamma: float = param(1.5, "frequency density γ", low=1.0, low_open=True, high=10.0)
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)

    def __post_init__(self):
        validate(self)
        if self.amplitude is not None and self.k is not None:
            raise ParameterError("amplitude", "cannot be combined with k: give one of them")
        if self.amplitude is None and self.k is None:
            object.__setattr__(self, "amplitude", DEFAULT_AMPLITUDE)
        # in logs: gamma**frequencies overflows a float for large gamma and n_max (10**400)
        log_turns = self.frequencies * np.log(self.gamma) + np.log(np.pi / 2) - np.log(self.length_ratio)
        turns = float(np.exp(min(log_turns, 700.0)))
        if log_turns > np.log(MAX_TURNS):
            raise ParameterError(
                "frequencies",
                f"too large for gamma={self.gamma} and length_ratio={self.length_ratio}: "
                f"γ^n_max·π/(2L) = {turns:.3g} turns exceeds {MAX_TURNS:.3g} (float64 phase precision)",
            )


@dataclass(frozen=True)
class Field:
    """The random field of one grain: phases ψ, ζ (M, n_max) and ridge angles α (M,)."""

    psi: np.ndarray
    zeta: np.ndarray
    alpha: np.ndarray
    weights: np.ndarray  # (n_max,) w_n
    wavenumbers: np.ndarray  # (n_max,) k_n


def draw_field(p: Params, rng: np.random.Generator) -> Field:
    """Draw ψ and ζ ~ U(0, 2π) (in that order) and set α_m = π m / M.

    α_m = πm/M follows Yan & Komvopoulos (1998): ridge directions evenly
    cover all orientations, so the overlay is statistically isotropic.
    """
    M, N = p.ridges, p.frequencies
    psi = rng.uniform(0.0, TWO_PI, size=(M, N))
    zeta = rng.uniform(0.0, TWO_PI, size=(M, N))
    alpha = np.pi * np.arange(1, M + 1) / M
    n = np.arange(1, N + 1, dtype=np.float64)
    weights = (TWO_PI * p.gamma ** (n - 1) / p.length_ratio) ** (p.fractal_dimension - 3.0)
    wavenumbers = TWO_PI * p.gamma**n / p.length_ratio
    return Field(psi, zeta, alpha, weights, wavenumbers)


def _hemisphere_coords(unit: np.ndarray):
    theta, phi = spherical(unit)
    upper = phi <= np.pi / 2
    phi_eff = np.where(upper, phi, np.pi - phi)
    return theta, phi, phi_eff, upper


def wm_sum_reference(unit: np.ndarray, f: Field) -> np.ndarray:
    """The double sum S of Eqs. 2–3, evaluated straightforwardly in float64.

    Used as the accuracy reference for :func:`wm_sum` in tests and benchmarks.

    Parameters
    ----------
    unit : (V, 3) float64
        Unit vectors.
    f : Field

    Returns
    -------
    (V,) float64
    """
    theta, phi, phi_eff, upper = _hemisphere_coords(unit)
    c = np.where(upper, np.cos(phi), 0.0)
    out = np.empty(len(unit))
    for i0 in range(0, len(unit), 256):
        sl = slice(i0, i0 + 256)
        u = phi_eff[sl, None] * np.cos(theta[sl, None] - f.alpha[None, :])
        b = f.psi[None] + f.zeta[None] * c[sl, None, None]
        a = f.wavenumbers[None, None, :] * u[:, :, None] + b
        out[sl] = ((np.cos(b) - np.cos(a)) * f.weights).sum(axis=(1, 2))
    return out


def _first_term_upper(f: Field):
    """Σ_mn w_n cos(ψ_mn + ζ_mn c) as a Chebyshev interpolant in c ∈ [0, 1].

    The function is band-limited (|ζ| < 2π): on c ∈ [0, 1] the Chebyshev
    coefficients of exp(iζc) are ~J_k(ζ/2) ≤ J_k(π) < 1e-16 for k ≥ 24, so a
    degree-28 interpolant (29 float64 cosines per term) is exact to rounding.
    """

    def exact(c):
        c = np.asarray(c, dtype=np.float64)
        return np.einsum("cmn,n->c", np.cos(f.psi[None] + f.zeta[None] * c[:, None, None]), f.weights)

    return np.polynomial.Chebyshev.interpolate(exact, 28, domain=[0.0, 1.0])


#: terms (vertices × M·n_max) per block in :func:`wm_sum`: 32 vertices at
#: M = n_max = 40.  The block's float64 phases take 410 kB, so its three work
#: arrays stay in L2, and the product's size (block terms × 4) stays below
#: OpenBLAS's multithreading threshold (65536·4), so it runs on one core.
WM_BLOCK_TERMS = 51_200


#: phases are reduced modulo this many turns: f32(2π·3) is 11 times closer to
#: 2π·3 than f32(2π) is to 2π, and the float32 scale's rounding error biases
#: every phase by the same relative amount (visible when S is a small
#: difference of large sums, e.g. L/R0 ≈ 1000 with γ ≈ 1).
_WRAP_TURNS = 3


def _phase_setup(theta, phi_eff, c, f: Field):
    """Per-vertex coefficients P (V, 4), per-term coefficients Q (4, M·N) and the fraction bits.

    The phase of term (m, n) at vertex v, in units of ``_WRAP_TURNS`` turns, is
    the rank-4 product ``P[v] @ Q[:, (m, n)]`` =
    (k_n φ'(cos θ cos α_m + sin θ sin α_m) + ζ_mn c + ψ_mn) / (2π·_WRAP_TURNS)
    (c = 0 in the lower hemisphere).  Q's last row also carries the "magic"
    constant 1.5·2^(52−fb): adding it rounds the float64 phase to a multiple of
    2^−fb units, so the low 32 bits of the float64 are the phase's fixed-point
    fraction (plus a few integer bits when fb < 32), see :func:`wm_sum`.
    """
    unit_rad = TWO_PI * _WRAP_TURNS
    kt = f.wavenumbers / unit_rad
    P = np.empty((len(theta), 4))
    P[:, 0] = phi_eff * np.cos(theta)
    P[:, 1] = phi_eff * np.sin(theta)
    P[:, 2] = c
    P[:, 3] = 1.0
    # |phase| bound: |u| ≤ φ' ≤ π/2, ζ, ψ < 2π (c ≤ 1)
    tmax = float(np.max(np.abs(kt))) * (np.pi / 2) + 2.0
    # the magic add is exact-rounding only while |phase| < 2^(51−fb): keep a bit of margin
    fb = min(32, 50 - int(np.ceil(np.log2(tmax))))
    magic = 1.5 * 2.0 ** (52 - fb)
    Q = np.empty((4, f.psi.size))
    Q[0] = (np.cos(f.alpha)[:, None] * kt).ravel()
    Q[1] = (np.sin(f.alpha)[:, None] * kt).ravel()
    Q[2] = (f.zeta / unit_rad).ravel()
    Q[3] = (f.psi / unit_rad).ravel() + magic
    return P, Q, fb


def wm_sum(unit: np.ndarray, f: Field, chunk: int | None = None) -> np.ndarray:
    """Fast evaluation of the double sum S of Eqs. 2–3.

    The first term Σ w_n cos(ψ_mn + ζ_mn c) does not depend on θ: it is a
    constant in the lower hemisphere and a Chebyshev interpolant in c = cos φ
    in the upper one.  The second term is evaluated per block of ``chunk``
    vertices in four array passes over the ``chunk × M·n_max`` terms:

    1. phases in units of 3 turns, rounded to 2^−fb units, by one float64
       rank-4 matrix product (see ``_phase_setup``; fb = 30 at the defaults);
    2. reduction modulo 3 turns: the low 32 bits of each float64 are taken
       as int32 (a truncating integer cast), i.e. the phase in units of 2^−fb
       modulo 2^(32−fb) units (shifted left when fb < 28 so that only the
       fraction remains), then converted to float32 radians;
    3. float32 cosine (ALGORITHMS.md §1 item 7);
    4. the w_n-weighted sum over (m, n) with ``einsum`` (float32).

    Only steps 2–4 run in float32.  At the defaults the result agrees with
    :func:`wm_sum_reference` to ~1e-5 in S (~2e-6 of its RMS, a radius error
    ~1e-7·R0 at amplitude 0.1); the worst case found over the parameter
    ranges (L/R0 ≈ 1000 with γ ≈ 1, where S is a small difference of large
    sums) is ~3e-4 of the RMS, i.e. 3e-5·R0.  See docs/methods/fso-performance.md.
    The evaluation is deterministic: the matrix product has only 4 terms per
    entry, summed in a fixed order, and runs single-threaded for blocks this
    small; everything else is element-wise or NumPy's own ``einsum`` loop.

    Parameters
    ----------
    unit : (V, 3) float64
        Unit vectors.
    f : Field
    chunk : int, optional
        Vertices per block (default: ``WM_BLOCK_TERMS // (M·n_max)``, at least 1).
        The result does not depend on it.

    Returns
    -------
    (V,) float64

    Examples
    --------
    >>> from grainforge.geodesic import icosphere
    >>> f = draw_field(Params(), np.random.default_rng(0))
    >>> unit, _ = icosphere(2)
    >>> bool(np.abs(wm_sum(unit, f) - wm_sum_reference(unit, f)).max() < 1e-3)
    True
    """
    unit = np.asarray(unit, dtype=np.float64)
    theta, phi, phi_eff, upper = _hemisphere_coords(unit)
    cosphi = np.cos(phi)
    c = np.where(upper, cosphi, 0.0)
    P, Q, fb = _phase_setup(theta, phi_eff, c, f)
    shift = 32 - fb if fb < 28 else 0
    scale = np.float32(TWO_PI * _WRAP_TURNS / 2.0 ** (fb + shift))
    w_t = np.tile(f.weights, f.psi.shape[0]).astype(np.float32)  # w_n for the flattened (m, n)

    first = np.full(len(unit), float((f.weights * np.cos(f.psi)).sum()))
    if upper.any():
        first[upper] = _first_term_upper(f)(cosphi[upper])

    V, T = len(unit), Q.shape[1]
    if chunk is None:
        chunk = WM_BLOCK_TERMS // T
    chunk = max(1, min(int(chunk), V))
    s = np.empty((chunk, T))
    i32 = np.empty((chunk, T), dtype=np.int32)
    x = np.empty((chunk, T), dtype=np.float32)
    out = np.empty(V)
    for i0 in range(0, V, chunk):
        n = min(chunk, V - i0)
        ss, ii, xx = s[:n], i32[:n], x[:n]
        np.matmul(P[i0 : i0 + n], Q, out=ss)
        np.copyto(ii, ss.view(np.int64), casting="unsafe")  # low 32 bits (wraps)
        if shift:
            uu = ii.view(np.uint32)  # unsigned: the shift wraps, well defined
            np.left_shift(uu, np.uint32(shift), out=uu)
        np.copyto(xx, ii, casting="unsafe")
        xx *= scale
        np.cos(xx, out=xx)
        out[i0 : i0 + n] = first[i0 : i0 + n] - np.einsum("vq,q->v", xx, w_t)
    return out


def build(p: Params, rng: np.random.Generator):
    """Vertices, faces and info of one FSO grain (R0 = 1, not yet centred)."""
    unit, faces = icosphere(p.subdivisions)
    f = draw_field(p, rng)
    S = wm_sum(unit, f)
    if p.k is not None:
        K = p.k
        which = "k"
    else:
        ref_unit, _ = icosphere(REFERENCE_SUBDIVISIONS)
        nref = len(ref_unit)
        if p.subdivisions >= REFERENCE_SUBDIVISIONS and np.array_equal(unit[:nref], ref_unit):
            # finer icospheres start with the level-3 vertices, and wm_sum is
            # evaluated vertex by vertex (bit-identical whatever the block), so
            # this is exactly wm_sum(ref_unit, f) without evaluating it again
            S_ref = S[:nref]
        else:
            S_ref = wm_sum(ref_unit, f)
        rms = float(np.sqrt(np.mean(S_ref**2)))
        K = p.amplitude / rms if rms > 0 else 0.0
        which = "amplitude"
    R = 1.0 + K * S
    rmin = float(R.min())
    if rmin <= MIN_RADIUS:
        value = p.k if which == "k" else p.amplitude
        raise ParameterError(
            which,
            f"{value} is too large for this grain: the smallest radius would be {rmin:.3f}·R0 "
            f"(must stay above {MIN_RADIUS}·R0 for a star-shaped solid); lower it",
        )
    vertices = unit * R[:, None]
    info = {"K": float(K), "min_radius": rmin, "max_radius": float(R.max())}
    return vertices, np.array(faces), info


def fso(
    *,
    fractal_dimension: float = 2.4,
    length_ratio: float = 7.0,
    amplitude: float | None = None,
    k: float | None = None,
    ridges: int = 40,
    frequencies: int = 40,
    gamma: float = 1.5,
    subdivisions: int = 5,
    rng=None,
):
    """Generate one grain by Fractal Surface Overlay (paper §2.1, Eqs. 2–3).

    Parameters
    ----------
    fractal_dimension : float
        D in [2, 3); higher is rougher at a fixed amplitude.
    length_ratio : float
        L/R0 > 0; small values give nodular grains, values above π elongated ones.
    amplitude : float, optional
        Target RMS of (R − R0)/R0, measured on a level-3 geodesic sphere
        (default 0.1).  Exclusive with ``k``.
    k : float, optional
        The paper's raw amplitude K.  Exclusive with ``amplitude``.
    ridges, frequencies : int
        M and n_max (default 40 each).
    gamma : float
        Frequency density γ > 1 (default 1.5).
    subdivisions : int
        Icosphere level 0–8 (default 5: 10,242 vertices).
    rng : None, int or numpy.random.Generator
        Seed or generator.  An int (or None, which draws one) is recorded
        as ``Grain.seed``.

    Returns
    -------
    Grain
        Centred on its volume centroid, R0 = 1.

    Raises
    ------
    ValueError
        For an out-of-range parameter, or when the amplitude is so large that
        some radius falls to 0.05·R0 or less (the message names the amplitude).

    References
    ----------
    Hanaor, Gan, Revay, Airey, Einav, *3D printable geomaterials*,
    Géotechnique (2016), Eqs. 2 and 3.

    Examples
    --------
    >>> from grainforge import fso
    >>> g = fso(fractal_dimension=2.4, length_ratio=7, subdivisions=3, rng=42)
    >>> len(g.vertices), g.seed
    (642, 42)
    >>> fso(fractal_dimension=3.2)
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: fractal_dimension must be in [2, 3), got 3.2
    """
    from . import generate

    p = Params(
        fractal_dimension=fractal_dimension, length_ratio=length_ratio, amplitude=amplitude, k=k,
        ridges=ridges, frequencies=frequencies, gamma=gamma, subdivisions=subdivisions,
    )
    return generate(NAME, p, rng)
