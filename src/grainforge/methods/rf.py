"""Random-field grains (rf): an isotropic Gaussian field of the radius, from a 2D descriptor spectrum.

Mollon & Zhao (2014) style; docs/design/algorithms.md §5 and ``docs/methods/rf.md``.  The
radius on the unit sphere is r(u) = r0 (1 + f(u)), with f a zero-mean,
isotropic Gaussian random field synthesised with real spherical harmonics
(:mod:`grainforge.geometry.harmonics`) at the vertices of a geodesic sphere:

    f(u) = Σ_{l=2}^{L} Σ_{m=−l}^{l} a_lm Y_lm(u),   a_lm ~ N(0, C_l)

(l = 1 is left out so that the origin stays near the centroid).  The angular
power spectrum C_l is *derived* (not calibrated) from the requested 2D
spectrum: a planar section through the centre of an isotropic field has, for
every orientation, the statistics of the equator, whose circular Fourier
coefficients are c_n = r0 Σ_{l≥n} a_ln √2 P̄_ln(0) (cosine and sine parts
alike), so

    E|c_n|² = r0² Σ_{l≥n} C_l P̄_ln(0)²      (P̄_ln(0) = 0 when l + n is odd).

Each part of c_n is Gaussian, so |c_n| is Rayleigh distributed and
E|c_n| = (√π/2)·(E|c_n|²)^½.  Requiring the *mean* section descriptor
E[D_n] = E[2|c_n|/c_0] to equal the requested D_n gives the triangular system

    Σ_{l≥n} C_l P̄_ln(0)² = D_n² / π,   n = 2…L,

solved from n = L downwards (:func:`angular_spectrum`).  When a spectrum
cannot be carried by any isotropic field (the exact solution would need a
negative C_l — e.g. a large D8 over a zero D3…D7), the closest non-negative
C_l in relative terms is used (NNLS) and the misfit is recorded
(``spectrum_misfit``).

**Fixed amplitudes** (the default, ``amplitudes="fixed"``; Angulo & Pontzen
2016): the a_lm of each degree are drawn as above and then scaled together
so that the grain's own power in that degree, Σ_m a_lm², equals its
expected value (2l + 1) C_l exactly; the direction of the coefficient
vector of each degree stays uniformly random, so the field is still
isotropic, but a grain no longer varies in how much relief it has at each
scale — only in where and how it is oriented.  E|c_n|² is unchanged; the
ratio E|c_n|/(E|c_n|²)^½ is no longer the Rayleigh value √π/2 but a
number κ_n (up to 4 % larger at n = 2) computed exactly from the
characteristic function of c_n (:func:`mean_modulus_factor`), and the
system above becomes Σ_{l≥n} C_l P̄_ln(0)² = D_n²/(4κ_n²), solved by a
fixed-point iteration on κ (:func:`angular_spectrum`).
``amplitudes="gaussian"`` keeps the independent Gaussian a_lm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache, lru_cache

import numpy as np

from ..errors import InputError
from ..geometry.geodesic import icosphere
from ..geometry.harmonics import degree_order, icosphere_synthesis, legendre_equator
from ..outline.contours import DEFAULT_DECAY, PRESETS, descriptor_spectrum
from ..outline.spectra import extend_spectrum, read_spectra
from ..params import ParameterError, check_aspect, check_lengths, param, resolve_descriptors, validate
from ..rng import RNGLike, as_generator

__all__ = ["Params", "build", "rf", "angular_spectrum", "section_spectrum", "target_spectrum", "coefficients", "field",
           "centred_section_spectrum", "centring_shift", "mean_modulus_factor", "AMPLITUDES"]

NAME = "rf"
VALIDITY_PARAMETER = "descriptors"
#: vertices are unit directions times a positive radius: the solid contract's star certificate applies
STAR_SHAPED = True
#: default (D2, D3, D8) when neither descriptors, a preset nor a spectrum is given
DEFAULT_PRESET = "rough-angular"
#: smallest allowed radius, as a fraction of r0
MIN_RADIUS = 0.05
#: largest L/S of a requested aspect
MAX_ASPECT = 50.0
#: how the coefficients of a degree are drawn: "fixed" (each degree carries exactly its expected
#: power, random orientation; Angulo & Pontzen 2016) or "gaussian" (independent N(0, C_l))
AMPLITUDES = ("fixed", "gaussian")
#: icosphere level on which the extents are measured for a requested aspect
ASPECT_REFERENCE_SUBDIVISIONS = 5
#: generation outputs recorded in manifests: the measured grain whose spectrum
#: was used (``spectrum`` input), the RMS of f, the largest relative misfit of
#: the expected mean section descriptors to the requested ones (0 when the
#: triangular system has a non-negative solution), the axis scaling of a
#: requested aspect, and the extreme radii / r0 before it.
INFO_COLUMNS = ("spectrum_row", "spectrum_grain", "field_rms", "spectrum_misfit", "axis_scale", "min_radius",
                "max_radius")


@dataclass(frozen=True)
class Params:
    """Parameters of the random-field generator (Mollon & Zhao 2014 style)."""

    preset: str | None = param(
        None, "named descriptors: rough-sphere = 0,0,0.02; rough-angular = 0.15,0.10,0.03",
        kind="str", choices=tuple(PRESETS),
    )
    descriptors: tuple[float, float, float] | None = param(
        None, "mean D2,D3,D8 (elongation, irregularity, roughness) of central sections in any orientation",
        kind="floats", low=0.0, high=0.3, shown_default=f"the {DEFAULT_PRESET} preset",
    )
    spectrum: str | None = param(
        None, "a 'grainforge fourier' CSV: each grain takes the D2..D16 of one measured grain, drawn at random",
        kind="str",
    )
    decay: tuple[float, float] = param(
        DEFAULT_DECAY, "decay exponents B1,B2: D_n = D3 (n/3)^B1 for n=4..7, D8 (n/8)^B2 for n>8 "
        "(with --spectrum, B2 continues the measured spectrum above D16)", kind="floats", low=-10.0, high=0.0,
    )
    degree: int = param(32, "highest spherical-harmonic degree L (and descriptor order) of the field",
                        kind="int", low=8, high=64)
    aspect: tuple[float, float, float] | None = param(
        None, "stretch x:y:z so that the grain's extents are in the ratio L:I:S",
        kind="floats", low=0.0, low_open=True, high=100.0, shown_default="isotropic",
    )
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)
    amplitudes: str = param(
        "fixed", "fixed: every degree l of each grain carries exactly its power (2l+1)C_l in a random "
        "orientation (Angulo & Pontzen 2016); gaussian: independent a_lm ~ N(0, C_l)",
        kind="str", choices=AMPLITUDES,
    )

    def __post_init__(self):
        validate(self)
        check_lengths(self, {"descriptors": 3, "decay": 2, "aspect": 3})
        if self.spectrum is not None:
            for name in ("preset", "descriptors"):
                if getattr(self, name) is not None:
                    raise ParameterError(name, "cannot be combined with spectrum: give one of them")
            read_spectra(self.spectrum)  # fail early on a missing or malformed table
        else:
            resolve_descriptors(self, PRESETS, DEFAULT_PRESET)
        check_aspect(self.aspect, MAX_ASPECT)


# ------------------------------------------------------------------ spectra
@cache
def _transfer(degree: int) -> np.ndarray:
    """M[n, l] = P̄_ln(0)² for n, l = 0..L (upper triangular in (n, l))."""
    P = legendre_equator(degree)
    M = (P**2).T.copy()
    M.setflags(write=False)
    return M


#: E|Z|/(E|Z|²)^½ of a circular complex Gaussian Z (the Rayleigh mean)
RAYLEIGH = float(np.sqrt(np.pi) / 2.0)
#: Gauss–Legendre nodes and the upper limit (in units of 1/RMS) of the integral of mean_modulus_factor
_KAPPA_NODES, _KAPPA_LIMIT = 64, 30.0


def _check_amplitudes(amplitudes: str) -> None:
    if amplitudes not in AMPLITUDES:
        raise InputError(f"amplitudes must be one of {AMPLITUDES}, got {amplitudes!r}")


def mean_modulus_factor(C: np.ndarray, amplitudes: str = "fixed") -> np.ndarray:
    """κ_n = E|c_n| / (E|c_n|²)^½ of the order-n coefficient of a central section, n = 0…L.

    With Gaussian a_lm every κ_n is √π/2 (Rayleigh).  With fixed amplitudes
    the degree-l coefficient vector is a_l = ((2l + 1) C_l)^½ u_l, u_l uniform
    on the unit sphere of R^(2l+1), and

        c_n = Σ_l (v_l (2l + 1)/2)^½ z_l,   v_l = C_l P̄_ln(0)²,

    with z_l the projection of u_l on two coordinates.  z_l is isotropic in
    the plane, with characteristic function ₀F₁(; l + ½; −k²/4), so c_n has
    φ(k) = Π_l ₀F₁(; l + ½; −k² v_l (2l + 1)/8), and for any isotropic 2D
    variable E|c| = ∫₀^∞ (1 − φ(k)) k⁻² dk (Gaussian φ = e^{−σ²k²/4} gives
    σ√π/2).  The integral is taken with 64 Gauss–Legendre nodes on
    [0, 30/σ] plus the tail σ/30 (relative error below 10⁻¹⁰ against 4,000
    nodes on [0, 200/σ]).  Orders without power get √π/2.

    Parameters
    ----------
    C : (L + 1,) array_like of float
        Angular power spectrum C_0 … C_L of the field.
    amplitudes : {"fixed", "gaussian"}, default "fixed"
        How the a_lm are drawn (:func:`coefficients`).

    Returns
    -------
    (L + 1,) float64
        κ_0 … κ_L.

    Examples
    --------
    >>> C = np.zeros(9); C[2] = 1.0  # one degree: c_2 is the 2D projection of a uniform 5-vector
    >>> round(float(mean_modulus_factor(C)[2]), 6)  # E√B/√(E B), B ~ Beta(1, 3/2): (3π/16)/√(2/5)
    0.931367
    >>> float(mean_modulus_factor(C, "gaussian")[2]) == RAYLEIGH
    True
    """
    _check_amplitudes(amplitudes)
    C = np.asarray(C, dtype=np.float64)
    L = len(C) - 1
    out = np.full(L + 1, RAYLEIGH)
    if amplitudes == "gaussian":
        return out
    from scipy.special import hyp0f1

    x, w = np.polynomial.legendre.leggauss(_KAPPA_NODES)
    t = (x + 1.0) * (_KAPPA_LIMIT / 2.0)
    w = w * (_KAPPA_LIMIT / 2.0)
    V = _transfer(L) * C[None, :]  # V[n, l] = C_l P̄_ln(0)²
    degrees = np.arange(L + 1)
    for n in range(1, L + 1):
        v = V[n]
        ls = np.flatnonzero(v > 0.0)
        if len(ls) == 0:
            continue
        q = v[ls] / v[ls].sum() * (2 * degrees[ls] + 1) / 8.0  # k in units of 1/σ
        phi = np.prod(hyp0f1(degrees[ls, None] + 0.5, -q[:, None] * t[None, :] ** 2), axis=0)
        out[n] = float(np.sum(w * (1.0 - phi) / t**2) + 1.0 / _KAPPA_LIMIT)
    return out


def section_spectrum(C: np.ndarray, amplitudes: str = "fixed") -> np.ndarray:
    """Expected mean descriptor E[D_n] of a central section of the field with spectrum C_l.

    E[D_n] = 2κ_n (Σ_{l≥n} C_l P̄_ln(0)²)^½ (to first order in f: c_0 ≈ r0),
    κ_n from :func:`mean_modulus_factor` (√π/2 for Gaussian amplitudes).

    Parameters
    ----------
    C : (L + 1,) array_like of float
        Angular power spectrum C_0 … C_L.
    amplitudes : {"fixed", "gaussian"}, default "fixed"
        How the a_lm are drawn.

    Returns
    -------
    (L + 1,) float64
        E[D_0] … E[D_L] (relative to r0 = 1).

    Examples
    --------
    >>> C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=16))
    >>> np.round(section_spectrum(C)[[2, 3, 8]], 6).tolist()
    [0.15, 0.1, 0.03]
    """
    C = np.asarray(C, dtype=np.float64)
    return 2.0 * mean_modulus_factor(C, amplitudes) * np.sqrt(_transfer(len(C) - 1) @ C)


def _back_substitute(T: np.ndarray) -> np.ndarray:
    """Non-negative C_l with Σ_{l≥n} C_l P̄_ln(0)² = T_n from n = L down (C_n = 0 where it cannot be met)."""
    L = len(T) - 1
    M = _transfer(L)
    C = np.zeros(L + 1)
    for n in range(L, 1, -1):
        rest = float(M[n, n + 2 :: 2] @ C[n + 2 :: 2])
        C[n] = max(0.0, (T[n] - rest) / M[n, n])
    return C


@lru_cache(maxsize=4096)
def _angular_spectrum_cached(key: bytes, amplitudes: str) -> np.ndarray:
    D = np.frombuffer(key, dtype=np.float64)
    kappa = np.full(len(D), RAYLEIGH)
    C = _back_substitute(D**2 / (4.0 * kappa**2))
    if amplitudes == "fixed":
        for _ in range(20):  # κ depends weakly on C: stationary to 1e-10 in ~5 steps
            new = mean_modulus_factor(C, "fixed")
            C = _back_substitute(D**2 / (4.0 * new**2))
            if np.max(np.abs(new - kappa)) < 1e-10:
                break
            kappa = new
    C.setflags(write=False)
    return C


def angular_spectrum(D: np.ndarray, amplitudes: str = "fixed") -> np.ndarray:
    """C_l (l = 0…L, L = len(D) − 1) whose central sections have mean descriptors D_n, n = 2…L.

    Solves Σ_{l≥n} C_l P̄_ln(0)² = D_n²/(4κ_n²) by back-substitution from
    n = L downwards; C_0 = C_1 = 0.  κ_n = √π/2 for Gaussian amplitudes;
    for fixed amplitudes κ_n depends on C itself (:func:`mean_modulus_factor`)
    and the solve is repeated until κ is stationary.  Where the target D_n is
    smaller than what the higher degrees already put into order n (no
    isotropic field can then carry the spectrum: e.g. D2…D7 = 0 under
    D8 > 0), C_n is set to 0, so the expected D_n is the smallest possible,
    above the target; all orders whose targets can be met are met exactly.
    Cached per (D, amplitudes).

    Parameters
    ----------
    D : (L + 1,) float64
        Target mean descriptors D_0…D_L (D_0, D_1 ignored).
    amplitudes : {"fixed", "gaussian"}

    Returns
    -------
    (L + 1,) float64
        C_0 … C_L (a copy of the cached solution).

    Raises
    ------
    ValueError
        If ``amplitudes`` is not one of :data:`AMPLITUDES`.

    Examples
    --------
    >>> C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=32))
    >>> bool((C[2:] > 0).all()), C[:2].tolist()
    (True, [0.0, 0.0])
    >>> C = angular_spectrum(descriptor_spectrum(0.0, 0.0, 0.02, modes=32))  # rough-sphere
    >>> np.round(section_spectrum(C)[[2, 3, 8, 9]], 4).tolist()
    [0.0141, 0.0116, 0.02, 0.0164]
    """
    _check_amplitudes(amplitudes)
    D = np.ascontiguousarray(D, dtype=np.float64)
    return _angular_spectrum_cached(D.tobytes(), amplitudes).copy()


def _centring_matrix(L: int, s2: float) -> np.ndarray:
    """A[n, m], n, m = 2…L: powers E|c_n|² about the area centroid from those about the field's origin."""
    n = np.arange(2, L + 1, dtype=np.float64)
    A = np.diag(1.0 - n**2 * s2 / 2.0)
    A[np.arange(len(n) - 1), np.arange(1, len(n))] = (n[1:] ** 2) * s2 / 4.0  # from order n + 1
    A[np.arange(1, len(n)), np.arange(len(n) - 1)] = (n[:-1] ** 2) * s2 / 4.0  # from order n − 1 (≥ 2)
    return A


def centring_shift(C: np.ndarray) -> float:
    """E|δ|²: mean squared offset of a central section's area centroid from the field's origin.

    To first order δ = 2·c_1 (the section's first circular harmonic), and
    E|c_1|² = Σ_l C_l P̄_l1(0)² as for every order (odd l ≥ 3: the field has no l = 1).

    Parameters
    ----------
    C : (L + 1,) array_like of float
        Angular power spectrum C_0 … C_L.

    Returns
    -------
    float
        E|δ|², in units of r0².

    Examples
    --------
    >>> centring_shift(np.array([0.0, 0.0, 1e-3])) == 0.0  # even degrees move no centroid
    True
    """
    C = np.asarray(C, dtype=np.float64)
    return float(4.0 * (_transfer(len(C) - 1)[1] @ C))


def centred_section_spectrum(C: np.ndarray, amplitudes: str = "fixed") -> np.ndarray:
    """Expected mean descriptor E[D_n] of a central section measured about its *area centroid*.

    Rays from the area centroid instead of the field's origin see each
    order n phase-modulated by the offset δ (a boundary feature at angle φ
    from the origin is seen at θ ≈ φ − Im(δe^{−iφ})): by the Bessel expansion
    the order keeps J_0(n|δ|)² ≈ 1 − n²|δ|²/2 of its power and gives
    n²|δ|²/4 to each neighbour n ± 1 (order 1 is the offset itself and is
    removed).  With P_n = E|c_n|² from :func:`section_spectrum` and
    σ² = E|δ|² (:func:`centring_shift`; δ is independent of the c_n, n ≥ 2):

        P'_n = P_n (1 − n²σ²/2) + σ²/4 · ((n−1)² P_{n−1} + (n+1)² P_{n+1}),

    and E[D_n] = 2κ_n √P'_n (κ_n of the field's own section,
    :func:`mean_modulus_factor`; √π/2 for Gaussian amplitudes).  This is what ``grainforge fourier`` and
    ``analysis.sections`` measure (rays from the area centroid).  A model
    for explaining measurements, not used to make grains: it is the
    leading order in n²σ² (σ² ≈ 0.008 for ``rough-angular``, so good to
    n ≈ 8; beyond, the loss and the gains of a smooth spectrum cancel and
    the model's near-cancellation is all it says).  Inverting it to
    pre-compensate the field was tried and rejected: the tridiagonal
    inverse oscillates from order to order (±15 % by n = 16).

    Parameters
    ----------
    C : (L + 1,) array_like of float
        Angular power spectrum C_0 … C_L.
    amplitudes : {"fixed", "gaussian"}, default "fixed"
        How the a_lm are drawn.

    Returns
    -------
    (L + 1,) float64
        E[D_n] about the centroid; orders 0 and 1 are 0.

    Examples
    --------
    >>> C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=32))
    >>> D = centred_section_spectrum(C)  # D8 over D7 and D9: order 8 loses, 7 gains
    >>> bool(D[8] < 0.03 and D[7] > section_spectrum(C)[7])
    True
    """
    C = np.asarray(C, dtype=np.float64)
    P = _transfer(len(C) - 1) @ C
    out = np.zeros_like(P)
    out[2:] = _centring_matrix(len(C) - 1, centring_shift(C)) @ P[2:]
    return 2.0 * mean_modulus_factor(C, amplitudes) * np.sqrt(np.maximum(out, 0.0))


def target_spectrum(p: Params, rng: RNGLike) -> tuple[np.ndarray, int | None]:
    """Target mean section descriptors D_0…D_L of one grain, and the measured row used (if any).

    With ``spectrum`` the row is drawn from ``rng`` first (one integer draw).

    Parameters
    ----------
    p : Params
        ``spectrum`` (a measured table) or ``descriptors``, with ``decay`` and ``degree``.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  One integer draw
        with ``spectrum``, none otherwise.

    Returns
    -------
    D : (degree + 1,) float64
        Target mean descriptors.
    row : int or None
        The measured table's row drawn, or None.
    """
    if p.spectrum is not None:
        table = read_spectra(p.spectrum)
        row = table.draw(rng)
        return extend_spectrum(table.D[row], p.decay[1], p.degree), row
    try:
        return descriptor_spectrum(*p.descriptors, decay=p.decay, modes=p.degree), None
    except ParameterError as exc:  # pragma: no cover - ranges are validated by Params
        raise ParameterError("descriptors", exc.reason) from None


def coefficients(C: np.ndarray, rng: RNGLike, amplitudes: str = "fixed") -> np.ndarray:
    """The a_lm in the order (l, m), l = 2…L, m = −l…l, from one standard-normal draw per coefficient.

    Gaussian: a_lm = √C_l · g_lm.  Fixed: the draws g_l of each degree are
    scaled to a vector of length √((2l + 1) C_l), so Σ_m a_lm² = (2l + 1) C_l
    exactly and the direction is uniform (the same draws, the same order:
    the two differ only by one factor per degree).

    Parameters
    ----------
    C : (L + 1,) array_like of float
        Angular power spectrum C_0 … C_L.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  One
        standard-normal draw per coefficient, in column order.
    amplitudes : {"fixed", "gaussian"}, default "fixed"
        Fixed length per degree, or Gaussian.

    Returns
    -------
    ((L+1)² − 4,) float64
        a_lm in the column order of :func:`grainforge.geometry.harmonics.real_harmonics` (lmin = 2).

    Examples
    --------
    >>> C = angular_spectrum(descriptor_spectrum(0.15, 0.1, 0.03, modes=16))
    >>> a = coefficients(C, np.random.default_rng(0))
    >>> l, _ = degree_order(16, 2)
    >>> bool(np.allclose(np.bincount(l, weights=a**2)[2:], (2 * np.arange(2, 17) + 1) * C[2:]))
    True
    """
    _check_amplitudes(amplitudes)
    C = np.asarray(C, dtype=np.float64)
    l, _ = degree_order(len(C) - 1, 2)
    g = as_generator(rng).standard_normal(len(l))
    if amplitudes == "gaussian":
        return g * np.sqrt(C[l])
    norm2 = np.bincount(l, weights=g * g, minlength=len(C))
    scale = np.sqrt((2 * np.arange(len(C)) + 1) * C / np.where(norm2 > 0.0, norm2, 1.0))
    return g * scale[l]


def field(a: np.ndarray, degree: int, subdivisions: int) -> np.ndarray:
    """f = Σ a_lm Y_lm (l = 2…degree) at the vertices of ``icosphere(subdivisions)``."

    Parameters
    ----------
    a : ((degree+1)² − 4,) array_like of float
        Coefficients a_lm, l = 2 … degree (:func:`coefficients`).
    degree : int
        Highest degree L.
    subdivisions : int
        Icosphere level.

    Returns
    -------
    (V,) float64
        f at the icosphere's vertices (relative radius perturbation).
    """
    return icosphere_synthesis(subdivisions, degree, 2)(a)


def _misfit(C: np.ndarray, D: np.ndarray, amplitudes: str) -> float:
    want = D[2:]
    got = section_spectrum(C, amplitudes)[2:]
    ok = want > 1e-9
    return float(np.max(np.abs(got[ok] / want[ok] - 1.0))) if ok.any() else 0.0


@lru_cache(maxsize=4096)
def _solve(key: bytes, amplitudes: str) -> tuple[np.ndarray, float]:
    """C_l and its misfit for the target spectrum D (as bytes), cached: the κ_n solve takes ~30 ms."""
    C = _angular_spectrum_cached(key, amplitudes)
    return C, _misfit(C, np.frombuffer(key, dtype=np.float64), amplitudes)


def build(p: Params, rng: RNGLike):
    """Vertices, faces and info of one rf grain (r0 = 1, not yet centred).

    Parameters
    ----------
    p : Params
        The grain's parameters (validated).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The measured row
        (with ``spectrum``), then one normal draw per coefficient.

    Returns
    -------
    vertices : (V, 3) float64
        In model units, about the construction origin (not yet centred on the centroid).
    faces : (F, 3) int64
        Outward, counter-clockwise triangles.
    info : dict
        The generation's derived quantities, the keys of :data:`INFO_COLUMNS`.

    Raises
    ------
    ParameterError
        Naming the parameter to lower when the grain would not be a valid star-shaped solid.
    """
    rng = as_generator(rng)
    D, row = target_spectrum(p, rng)
    C, misfit = _solve(np.ascontiguousarray(D, dtype=np.float64).tobytes(), p.amplitudes)
    unit, faces = icosphere(p.subdivisions)
    a = coefficients(C, rng, p.amplitudes)
    f = field(a, p.degree, p.subdivisions)
    R = 1.0 + f
    rmin = float(R.min())
    if not rmin > MIN_RADIUS:
        if row is not None:
            table = read_spectra(p.spectrum)
            raise ParameterError(
                "spectrum", f"row {row + 2} ({table.labels[row]}) gives a radius of {rmin:.3f}·r0 for this seed "
                f"(must stay above {MIN_RADIUS}·r0 for a star-shaped solid); remove that grain or lower --degree",
            )
        raise ParameterError(
            "descriptors", f"{p.descriptors} are too large for this grain: the smallest radius would be "
            f"{rmin:.3f}·r0 (must stay above {MIN_RADIUS}·r0 for a star-shaped solid); lower them",
        )
    vertices = unit * R[:, None]
    scale = (1.0, 1.0, 1.0)
    if p.aspect is not None:
        if p.subdivisions == ASPECT_REFERENCE_SUBDIVISIONS:
            ref = vertices
        else:
            # the same field on the reference sphere, so the stretch does not depend on the mesh level
            ref_unit, _ = icosphere(ASPECT_REFERENCE_SUBDIVISIONS)
            ref = ref_unit * (1.0 + field(a, p.degree, ASPECT_REFERENCE_SUBDIVISIONS))[:, None]
        ext = np.ptp(ref, axis=0)
        logk = np.log(np.asarray(p.aspect, dtype=np.float64)) - np.log(ext)  # in logs: any scale of L:I:S
        k = np.exp(logk - logk.mean())
        scale = tuple(float(x) for x in k)
        vertices = vertices * k
    info = {
        "spectrum_row": row,
        "spectrum_grain": None if row is None else read_spectra(p.spectrum).labels[row],
        "field_rms": float(np.sqrt(np.sum(C * (2 * np.arange(len(C)) + 1)) / (4 * np.pi))),
        "spectrum_misfit": misfit,
        "axis_scale": scale,
        "min_radius": rmin,
        "max_radius": float(R.max()),
    }
    return vertices, np.array(faces), info


def rf(
    *,
    descriptors: Sequence[float] | None = None,
    preset: str | None = None,
    spectrum: str | None = None,
    decay: Sequence[float] = DEFAULT_DECAY,
    degree: int = 32,
    aspect: Sequence[float] | None = None,
    subdivisions: int = 5,
    amplitudes: str = "fixed",
    rng: RNGLike = None,
):
    """Generate one grain whose radius is an isotropic Gaussian random field (Mollon & Zhao 2014 style).

    Parameters
    ----------
    descriptors : (D2, D3, D8), optional
        Mean descriptors of central sections in any orientation (default the
        ``rough-angular`` preset 0.15, 0.10, 0.03); D4…D7 and D9…D_L follow
        the CRI regression with ``decay``.
    preset : {"rough-sphere", "rough-angular"}, optional
    spectrum : str, optional
        A CSV written by ``grainforge fourier``: the grain takes the D2…D16
        of one measured grain, drawn from ``rng``.
    decay : (β1, β2)
        Regression exponents (default −5/3, −5/3).
    degree : int
        Highest harmonic degree L, 8–64 (default 32).
    aspect : (L, I, S), optional
        Stretch x, y, z so that the extents are in this ratio.
    subdivisions : int
        Icosphere level 0–8 (default 5: 10,242 vertices).
    amplitudes : {"fixed", "gaussian"}
        "fixed" (default): each degree of the grain carries exactly its
        expected power, in a random orientation; "gaussian": independent
        Gaussian coefficients (the grain's power per degree varies too).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seed or generator (:mod:`grainforge.rng`).  An int, a plain SeedSequence's entropy, or the seed
        drawn for None is recorded as ``Grain.seed``; a Generator leaves it None.

    Returns
    -------
    Grain
        Centred on its volume centroid, mean radius about 1.

    Raises
    ------
    ValueError
        For an out-of-range or conflicting parameter (named), an unreadable
        spectrum table, or a field whose radius reaches 5 % of r0.

    Examples
    --------
    >>> import grainforge
    >>> g = grainforge.rf(descriptors=(0.1, 0.05, 0.02), subdivisions=3, rng=0)
    >>> len(g.vertices), bool(g.mesh.is_watertight)
    (642, True)
    """
    from . import generate

    p = Params(
        preset=preset, descriptors=None if descriptors is None else tuple(descriptors), spectrum=spectrum,
        decay=tuple(decay), degree=degree, aspect=None if aspect is None else tuple(aspect),
        subdivisions=subdivisions, amplitudes=amplitudes,
    )
    return generate(NAME, p, rng)
