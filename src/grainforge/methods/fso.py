"""Fractal Surface Overlay (FSO): a Weierstrass–Mandelbrot surface on a geodesic sphere.

Implements Eqs. 2 and 3 of Hanaor et al., *3D printable geomaterials*
(see ``docs/methods/fso.md`` and docs/design/algorithms.md §1).  For a vertex at azimuth
θ and polar angle φ, with φ' = φ in the upper hemisphere and π − φ in the
lower one,

    R = R0 + K Σ_m Σ_n w_n {cos(ψ_mn + ζ_mn c) − cos(k_n φ' cos(θ − α_m) + ψ_mn + ζ_mn c)}

where w_n = (2πγ^(n−1)/L)^(D−3), k_n = 2πγ^n/L, c = cos φ in the upper
hemisphere and 0 in the lower one (Eq. 3 has no ζ terms).

``surface="seamless"`` evaluates the same double sum (same w_n, k_n, M,
n_max, γ) as a function of the 3D unit vector u, with ridge family m a
plane wave along an axis d_m:

    R = R0 + K Σ_m Σ_n w_n {c̄_mn − cos(k_n d_m·u + ψ_mn)},

c̄_mn = cos ψ_mn sin k_n / k_n being the term's mean over the sphere; the
axes d_m are evenly spread (golden spiral over a hemisphere of axes) and
turned by one random rotation per grain, so no latitude or pole is special.

``aspect=(A, B, C)`` puts the overlay on an ellipsoidal precursor with
semi-axes proportional to A, B, C along x, y, z (geometric mean R0): the
radius in direction u is ``r_e(u)·(1 + K·S(u))``, i.e. the overlay is applied
along the radius, relative to the precursor's radius.  The grain's x, y, z
are then scaled (:func:`aspect_scale`) and a small symmetric, volume-keeping
linear map (:func:`aspect_correction`) makes the proportions measured by its
minimum box and by its inertia ellipsoid A:B:C.  See ``docs/methods/fso.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry.geodesic import icosphere, spherical
from ..geometry.rotations import random_rotation
from ..params import ParameterError, param, validate
from ..rng import RNGLike, as_generator

__all__ = ["Params", "build", "fso", "overlay", "wm_sum", "wm_sum_reference", "draw_field", "Field",
           "SURFACES", "ellipsoid_radius", "spread_axes"]

NAME = "fso"
VALIDITY_PARAMETER = "amplitude"
#: vertices are unit directions times a positive radius: the solid contract's star certificate applies
STAR_SHAPED = True
#: generation outputs recorded in manifests (K actually used, extreme radii / R0)
INFO_COLUMNS = ("K", "min_radius", "max_radius", "axis_scale", "aspect_residual")
DEFAULT_AMPLITUDE = 0.1
#: icosphere level on which the ``amplitude`` RMS is measured (642 points),
#: so that K, and therefore the grain, does not depend on the mesh resolution.
REFERENCE_SUBDIVISIONS = 3
#: smallest allowed radius, as a fraction of R0.
MIN_RADIUS = 0.05
#: largest phase, in turns, the double sum may reach (keeps float64 phases exact to ~1e-6 rad).
MAX_TURNS = 2.0**32
TWO_PI = 2.0 * np.pi
#: overlay forms: Eqs. 2–3 on latitude/longitude ("paper"), or on the 3D unit vector ("seamless")
SURFACES = ("paper", "seamless")
#: largest ratio of the longest to the shortest aspect axis
MAX_ASPECT_RATIO = 20.0


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
        None, "RMS of (R − R0)/R0, measured on the sphere; exclusive with k.  A value is refused when the "
        "smallest radius would fall below 0.05·R0 (the grain would no longer be star-shaped)",
        low=0.0, high=1.0, shown_default=f"{DEFAULT_AMPLITUDE:g}",
    )
    k: float | None = param(
        None, "the paper's amplitude scaling K of Eq. 2, R = R0 + K·Σ_m Σ_n w_n{...} with R0 = 1 (K is in "
        "units of R0): sets the overlay's size directly instead of through its RMS; exclusive with amplitude", low=0.0,
    )
    ridges: int = param(40, "number of superimposed ridges M", kind="int", low=1, high=400)
    frequencies: int = param(40, "number of frequencies n_max", kind="int", low=1, high=400)
    gamma: float = param(1.5, "frequency density γ", low=1.0, low_open=True, high=10.0)
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)
    surface: str = param(
        "paper", "overlay form: paper = Eqs. 2-3 in latitude/longitude (mirror seam at the equator, "
        "poles pinned at R0); seamless = the same sum on the 3D unit vector", kind="str", choices=SURFACES,
    )
    aspect: tuple[float, float, float] = param(
        (1.0, 1.0, 1.0), "proportions A:B:C of the grain along x, y, z, as its minimum box and inertia "
        "ellipsoid measure them: an ellipsoidal precursor (overlay along the radius), then a small per-grain "
        f"linear correction (ratios only; longest/shortest at most {MAX_ASPECT_RATIO:g})", kind="floats",
        low=0.0, low_open=True, high=100.0, shown_default="1:1:1",
    )

    def __post_init__(self):
        validate(self)
        if len(self.aspect) != 3:
            raise ParameterError("aspect", f"must be 3 numbers A:B:C, got {self.aspect!r}")
        if max(self.aspect) > MAX_ASPECT_RATIO * min(self.aspect):
            raise ParameterError(
                "aspect", f"longest/shortest must be at most {MAX_ASPECT_RATIO:g}, got "
                f"{':'.join(f'{a:g}' for a in self.aspect)}",
            )
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
    """The random field of one grain.

    ``surface="paper"``: phases ψ, ζ (M, n_max) and ridge angles α (M,);
    ``surface="seamless"``: phases ψ (M, n_max) and unit ridge axes d (M, 3)
    (``zeta`` and ``alpha`` are then None).
    """

    psi: np.ndarray
    zeta: np.ndarray | None
    alpha: np.ndarray | None
    weights: np.ndarray  # (n_max,) w_n
    wavenumbers: np.ndarray  # (n_max,) k_n
    directions: np.ndarray | None = None  # (M, 3) d_m, seamless only

    @property
    def seamless(self) -> bool:
        """Whether this is the seamless (3D unit-vector) form."""
        return self.directions is not None


def spread_axes(m: int) -> np.ndarray:
    """``m`` unit axes spread evenly over the hemisphere z > 0 (golden spiral, equal area).

    An axis and its opposite give the same ridge family (ψ is uniform), so a
    hemisphere of axes covers every orientation once.

    Parameters
    ----------
    m : int
        Number of axes (the ridge families M).

    Returns
    -------
    (m, 3) float64
        Unit vectors, z from 1/(2m) to 1 − 1/(2m).

    Examples
    --------
    >>> d = spread_axes(40)
    >>> d.shape, bool(np.allclose(np.linalg.norm(d, axis=1), 1.0)), bool((d[:, 2] > 0).all())
    ((40, 3), True, True)
    """
    i = np.arange(m, dtype=np.float64)
    z = (i + 0.5) / m
    r = np.sqrt(1.0 - z * z)
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def draw_field(p: Params, rng: RNGLike) -> Field:
    """Draw the random field of one grain from ``rng``.

    Paper form: ψ and ζ ~ U(0, 2π) (in that order), α_m = π m / M.
    α_m = πm/M follows Yan & Komvopoulos (1998): ridge directions evenly
    cover all orientations, so the overlay is statistically isotropic.

    Seamless form: ψ ~ U(0, 2π), then one uniform random rotation applied to
    the evenly spread axes :func:`spread_axes` (M) — the 3D counterpart of
    α_m = πm/M, with no preferred orientation of the set.

    Parameters
    ----------
    p : Params
        D, L/R0, M, n_max, γ and the surface form are used.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  Paper form:
        M·n_max uniform draws for ψ, then as many for ζ; seamless form: the ψ draws,
        then four normal draws for the rotation.

    Returns
    -------
    Field
        ψ (and ζ, α_m or the ridge axes), the weights w_n and wavenumbers k_n.
    """
    rng = as_generator(rng)
    M, N = p.ridges, p.frequencies
    n = np.arange(1, N + 1, dtype=np.float64)
    weights = (TWO_PI * p.gamma ** (n - 1) / p.length_ratio) ** (p.fractal_dimension - 3.0)
    wavenumbers = TWO_PI * p.gamma**n / p.length_ratio
    psi = rng.uniform(0.0, TWO_PI, size=(M, N))
    if p.surface == "seamless":
        directions = spread_axes(M) @ random_rotation(rng, convention="scalar-first").T
        return Field(psi, None, None, weights, wavenumbers, directions)
    zeta = rng.uniform(0.0, TWO_PI, size=(M, N))
    alpha = np.pi * np.arange(1, M + 1) / M
    return Field(psi, zeta, alpha, weights, wavenumbers)


def _hemisphere_coords(unit: np.ndarray):
    theta, phi = spherical(unit)
    upper = phi <= np.pi / 2
    phi_eff = np.where(upper, phi, np.pi - phi)
    return theta, phi, phi_eff, upper


def _seamless_mean(f: Field) -> np.ndarray:
    """c̄_mn = cos ψ_mn · sin k_n / k_n: the sphere mean of cos(k_n d·u + ψ_mn)."""
    return np.cos(f.psi) * (np.sin(f.wavenumbers) / f.wavenumbers)


def wm_sum_reference(unit: np.ndarray, f: Field) -> np.ndarray:
    """The double sum S, evaluated straightforwardly in float64.

    Used as the accuracy reference for :func:`wm_sum` in tests and benchmarks.

    Parameters
    ----------
    unit : (V, 3) float64
        Unit vectors.
    f : Field
        Paper or seamless form.

    Returns
    -------
    (V,) float64
    """
    unit = np.asarray(unit, dtype=np.float64)
    out = np.empty(len(unit))
    if f.seamless:
        first = float((_seamless_mean(f) * f.weights).sum())
        for i0 in range(0, len(unit), 256):
            sl = slice(i0, i0 + 256)
            u = unit[sl] @ f.directions.T  # (v, M)
            a = f.wavenumbers[None, None, :] * u[:, :, None] + f.psi[None]
            out[sl] = first - (np.cos(a) * f.weights).sum(axis=(1, 2))
        return out
    theta, phi, phi_eff, upper = _hemisphere_coords(unit)
    c = np.where(upper, np.cos(phi), 0.0)
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


def _magic(tmax: float) -> tuple[int, float]:
    """Fraction bits fb and the rounding constant 1.5·2^(52−fb) for phases up to ``tmax`` units."""
    # the magic add is exact-rounding only while |phase| < 2^(51−fb): keep a bit of margin
    fb = min(32, 50 - int(np.ceil(np.log2(tmax))))
    return fb, 1.5 * 2.0 ** (52 - fb)


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
    fb, magic = _magic(float(np.max(np.abs(kt))) * (np.pi / 2) + 2.0)
    Q = np.empty((4, f.psi.size))
    Q[0] = (np.cos(f.alpha)[:, None] * kt).ravel()
    Q[1] = (np.sin(f.alpha)[:, None] * kt).ravel()
    Q[2] = (f.zeta / unit_rad).ravel()
    Q[3] = (f.psi / unit_rad).ravel() + magic
    return P, Q, fb


def _seamless_setup(unit, f: Field):
    """P (V, 4) = (x, y, z, 1) and Q (4, M·N): the phase k_n d_m·u + ψ_mn in units of 3 turns, as in
    :func:`_phase_setup` (|d·u| ≤ 1 < π/2, so the same precision bound holds)."""
    unit_rad = TWO_PI * _WRAP_TURNS
    kt = f.wavenumbers / unit_rad
    P = np.empty((len(unit), 4))
    P[:, :3] = unit
    P[:, 3] = 1.0
    fb, magic = _magic(float(np.max(np.abs(kt))) + 2.0)
    Q = np.empty((4, f.psi.size))
    for j in range(3):
        Q[j] = (f.directions[:, j][:, None] * kt).ravel()
    Q[3] = (f.psi / unit_rad).ravel() + magic
    return P, Q, fb


def wm_sum(unit: np.ndarray, f: Field, chunk: int | None = None) -> np.ndarray:
    """Fast evaluation of the double sum S (paper Eqs. 2–3, or the seamless form).

    Paper form: the first term Σ w_n cos(ψ_mn + ζ_mn c) does not depend on
    θ: it is a constant in the lower hemisphere and a Chebyshev interpolant in
    c = cos φ in the upper one.  Seamless form: the first term is the constant
    Σ w_n c̄_mn.  The second term is evaluated per block of ``chunk``
    vertices in four array passes over the ``chunk × M·n_max`` terms:

    1. phases in units of 3 turns, rounded to 2^−fb units, by one float64
       rank-4 matrix product (see ``_phase_setup``; fb = 30 at the defaults);
    2. reduction modulo 3 turns: the low 32 bits of each float64 are taken
       as int32 (a truncating integer cast), i.e. the phase in units of 2^−fb
       modulo 2^(32−fb) units (shifted left when fb < 28 so that only the
       fraction remains), then converted to float32 radians;
    3. float32 cosine (docs/design/algorithms.md §1 item 7);
    4. the w_n-weighted sum over (m, n) with ``einsum`` (float32).

    Only steps 2–4 run in float32.  At the defaults the result agrees with
    :func:`wm_sum_reference` to ~1e-5 in S (~2e-6 of its RMS, a radius error
    ~1e-7·R0 at amplitude 0.1); the worst case found over the parameter
    ranges (L/R0 ≈ 1000 with γ ≈ 1, where S is a small difference of large
    sums) is ~3e-4 of the RMS, i.e. 3e-5·R0.  See docs/methods/fso-performance.md.
    The evaluation is deterministic and independent of ``chunk``: the matrix
    product has only 4 terms per entry, always goes through BLAS's gemm (a
    one-row block is computed as two rows: gemv kernels round differently),
    and runs single-threaded for blocks this small; everything else is
    element-wise or NumPy's own ``einsum`` loop.  Bits are reproducible on one
    CPU feature level and NumPy/OpenBLAS build (docs/validation.md,
    "Reproducibility").

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
    >>> from grainforge.geometry.geodesic import icosphere
    >>> unit, _ = icosphere(2)
    >>> for surface in SURFACES:
    ...     f = draw_field(Params(surface=surface), np.random.default_rng(0))
    ...     print(surface, bool(np.abs(wm_sum(unit, f) - wm_sum_reference(unit, f)).max() < 1e-3))
    paper True
    seamless True
    """
    unit = np.asarray(unit, dtype=np.float64)
    if f.seamless:
        P, Q, fb = _seamless_setup(unit, f)
        first = np.full(len(unit), float((_seamless_mean(f) * f.weights).sum()))
    else:
        theta, phi, phi_eff, upper = _hemisphere_coords(unit)
        cosphi = np.cos(phi)
        c = np.where(upper, cosphi, 0.0)
        P, Q, fb = _phase_setup(theta, phi_eff, c, f)
        first = np.full(len(unit), float((f.weights * np.cos(f.psi)).sum()))
        if upper.any():
            first[upper] = _first_term_upper(f)(cosphi[upper])
    shift = 32 - fb if fb < 28 else 0
    scale = np.float32(TWO_PI * _WRAP_TURNS / 2.0 ** (fb + shift))
    w_t = np.tile(f.weights, f.psi.shape[0]).astype(np.float32)  # w_n for the flattened (m, n)

    V, T = len(unit), Q.shape[1]
    if chunk is None:
        chunk = WM_BLOCK_TERMS // T
    chunk = max(1, min(int(chunk), V))
    s = np.empty((chunk, T))
    pair = np.empty((2, T))
    i32 = np.empty((chunk, T), dtype=np.int32)
    x = np.empty((chunk, T), dtype=np.float32)
    out = np.empty(V)
    for i0 in range(0, V, chunk):
        n = min(chunk, V - i0)
        ss, ii, xx = s[:n], i32[:n], x[:n]
        if n == 1:
            # a one-row product would go through BLAS's gemv, whose kernels
            # round differently from gemm's: use a two-row product instead
            np.matmul(np.repeat(P[i0 : i0 + 1], 2, axis=0), Q, out=pair)
            ss[0] = pair[0]
        else:
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


def ellipsoid_radius(unit: np.ndarray, aspect) -> np.ndarray:
    """Radius in direction ``unit`` of the ellipsoid with semi-axes ∝ ``aspect`` (geometric mean 1).

    Parameters
    ----------
    unit : (V, 3) array_like of float
        Unit vectors.
    aspect : (3,) sequence of float
        Semi-axes along x, y, z, up to a common factor (> 0).

    Returns
    -------
    (V,) float64
        The radius, semi-axes scaled to a geometric mean of 1.

    Examples
    --------
    >>> u = np.eye(3)
    >>> np.round(ellipsoid_radius(u, (4, 2, 1)), 6).tolist()
    [2.0, 1.0, 0.5]
    """
    a = np.asarray(aspect, dtype=np.float64)
    a = a / np.exp(np.log(a).mean())
    return 1.0 / np.sqrt(((np.asarray(unit, dtype=np.float64) / a) ** 2).sum(axis=1))


def _scale(p: Params, f: Field, unit: np.ndarray, S: np.ndarray) -> float:
    """K: ``p.k``, or ``p.amplitude`` over the RMS of S on the level-3 reference sphere."""
    if p.k is not None:
        return float(p.k)
    ref_unit, _ = icosphere(REFERENCE_SUBDIVISIONS)
    nref = len(ref_unit)
    if len(unit) >= nref and np.array_equal(unit[:nref], ref_unit):
        # finer icospheres start with the level-3 vertices, and wm_sum is
        # evaluated vertex by vertex (bit-identical whatever the block), so
        # this is exactly wm_sum(ref_unit, f) without evaluating it again
        S_ref = S[:nref]
    else:
        S_ref = wm_sum(ref_unit, f)
    rms = float(np.sqrt(np.mean(S_ref**2)))
    return p.amplitude / rms if rms > 0 else 0.0


def overlay(unit: np.ndarray, params: Params | None = None, rng: RNGLike = None) -> np.ndarray:
    """The FSO overlay K·S(u): the relative radius perturbation at unit vectors ``unit``.

    A pure function of its arguments: the field (ψ, ζ or the ridge axes) is
    drawn from ``rng`` exactly as :func:`build` draws it, and K comes from
    ``params.k`` or from ``params.amplitude`` (the RMS of K·S on the level-3
    reference icosphere, whatever ``unit`` is).  So for the same ``params``
    and seed, ``unit * (1 + overlay(unit, params, seed))[:, None]`` is the
    vertex set that :func:`build` makes on the same unit vectors with
    ``aspect=(1, 1, 1)``; with an aspect, multiply by the precursor radius
    (:func:`ellipsoid_radius`) as well.  ``params.surface`` selects the paper
    form (Eqs. 2–3, latitude/longitude) or the seamless form (3D unit
    vector); ``params.aspect`` and ``params.subdivisions`` are not used.
    No check on the smallest radius is made here (``build`` makes it).

    Parameters
    ----------
    unit : (N, 3) array_like
        Unit vectors (any points on the unit sphere, in any order).
    params : Params, optional
        D, L/R0, amplitude or k, M, n_max, γ, surface (default ``Params()``).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced.

    Returns
    -------
    (N,) float64
        (R − R_precursor)/R_precursor at each unit vector.

    Raises
    ------
    TypeError
        If ``params`` is not :class:`Params`.
    ValueError
        If ``unit`` is not (N, 3).

    Examples
    --------
    >>> from grainforge.geometry.geodesic import icosphere
    >>> unit, _ = icosphere(3)
    >>> d = overlay(unit, Params(surface="seamless", amplitude=0.05), rng=7)
    >>> d.shape, round(float(np.sqrt(np.mean(d**2))), 6)
    ((642,), 0.05)
    """
    p = Params() if params is None else params
    if not isinstance(p, Params):
        raise TypeError(f"params must be fso.Params, got {type(p).__name__}")
    unit = np.asarray(unit, dtype=np.float64)
    if unit.ndim != 2 or unit.shape[1] != 3:
        raise InputError(f"unit must have shape (N, 3), got {unit.shape}")
    f = draw_field(p, rng)
    S = wm_sum(unit, f)
    return _scale(p, f, unit, S) * S


def build(p: Params, rng: RNGLike):
    """Vertices, faces and info of one FSO grain (R0 = 1, not yet centred).

    Parameters
    ----------
    p : Params
        The grain's parameters (validated).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The draws of
        :func:`draw_field`, in that order.

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
    unit, faces = icosphere(p.subdivisions)
    f = draw_field(p, as_generator(rng))
    S = wm_sum(unit, f)
    K = _scale(p, f, unit, S)
    R = 1.0 + K * S
    rmin = float(R.min())
    if rmin <= MIN_RADIUS:
        which = "k" if p.k is not None else "amplitude"
        value = getattr(p, which)
        raise ParameterError(
            which,
            f"{value} is too large for this grain: the smallest radius would be {rmin:.3f}·R0 "
            f"(must stay above {MIN_RADIUS}·R0 for a star-shaped solid); lower it",
        )
    faces = np.array(faces)
    vertices = unit * R[:, None]
    scale = (1.0, 1.0, 1.0)
    residual = 0.0
    if len(set(p.aspect)) > 1:
        vertices = unit * (R * ellipsoid_radius(unit, p.aspect))[:, None]
        scale = aspect_scale(vertices, faces, p.aspect)
        vertices = vertices * np.asarray(scale)
        M, residual = aspect_correction(vertices, faces, p.aspect)
        vertices = vertices @ M
    radii = np.linalg.norm(vertices, axis=1)
    info = {"K": float(K), "min_radius": float(radii.min()), "max_radius": float(radii.max()),
            "axis_scale": tuple(round(float(x), 9) for x in scale), "aspect_residual": round(float(residual), 9)}
    return vertices, faces, info


#: passes of :func:`aspect_scale`'s fixed-point iteration
ASPECT_PASSES = 3


def _axis_sizes(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per axis x, y, z: √(extent · inertia diameter), the inertia diameter being 2√(5·C_ii) (C the
    solid's second central moment per unit volume; exact, 2a, for an aligned ellipsoid)."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    V = vol6.sum() / 6.0
    s = a + b + c
    centroid = (vol6[:, None] * s).sum(0) / (24.0 * V)
    second = (vol6[:, None] * (a * a + b * b + c * c + s * s)).sum(0) / (120.0 * V)
    var = second - centroid**2
    return np.sqrt(np.ptp(vertices, axis=0) * 2.0 * np.sqrt(5.0 * var))


def aspect_scale(vertices: np.ndarray, faces: np.ndarray, aspect) -> tuple[float, float, float]:
    """Axis factors (geometric mean 1) that give the grain the requested x:y:z proportions.

    Relief changes the proportions a little, and differently for the two usual
    measures: the extremes (a box) gain more on the blunt sides of the
    ellipsoid than at its sharp tips, the bulk (the inertia ellipsoid) hardly
    changes.  So the size along each axis is taken as the geometric mean of
    the extent and of the inertia diameter (:func:`_axis_sizes`), and x, y, z
    are scaled until those sizes are in the ratio A:B:C (fixed-point
    iteration, ``ASPECT_PASSES`` passes; the factors stay within a few % of 1
    at the default amplitude).  Both measures then track the request (the box
    slightly above, the inertia ellipsoid slightly below; docs/validation.md).
    """
    want = np.asarray(aspect, dtype=np.float64)
    want = want / np.exp(np.log(want).mean())
    k = np.ones(3)
    for _ in range(ASPECT_PASSES):
        m = _axis_sizes(vertices * k, faces)
        k = k * want / (m / np.exp(np.log(m).mean()))
        k /= np.exp(np.log(k).mean())
    return tuple(float(x) for x in k)


#: Gauss–Newton passes of :func:`aspect_correction`, and the log-ratio residual at which it stops
CORRECTION_PASSES = 8
CORRECTION_TOLERANCE = 2e-3
#: Levenberg–Marquardt damping of a pass's step (in units of log-ratio per unit of E)
CORRECTION_DAMPING = 0.05


def _second_moment(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Central second moment (3, 3) per unit volume of the solid bounded by a closed, outward mesh."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    vol6 = np.einsum("ij,ij->i", a, np.cross(b, c))
    V = vol6.sum() / 6.0
    s = a + b + c
    centroid = (vol6[:, None] * s).sum(0) / (24.0 * V)
    second = sum(np.einsum("i,ij,ik->jk", vol6, x, x) for x in (a, b, c, s)) / (120.0 * V)
    return second - np.outer(centroid, centroid)


def _sym(e: np.ndarray) -> np.ndarray:
    return np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]])


def _quad_row(u: np.ndarray) -> np.ndarray:
    """Coefficients of the six entries of a symmetric E in u·E·u."""
    return np.array([u[0] ** 2, u[1] ** 2, u[2] ** 2, 2 * u[0] * u[1], 2 * u[0] * u[2], 2 * u[1] * u[2]])


def aspect_correction(vertices: np.ndarray, faces: np.ndarray, aspect) -> tuple[np.ndarray, float]:
    """Symmetric, volume-preserving linear map that gives the grain the measured proportions A:B:C.

    ``--aspect`` promises I/L and S/I of the grain as measured, by its
    minimum-volume box and by its inertia-equivalent ellipsoid.  A rough
    grain's two measures differ: the box follows the highest peaks, and
    for moderate aspects (1:0.8:0.6) the box of smallest volume is often
    turned 20–45° from the precursor's axes (rotating a box around a
    1:0.8 ellipsoid costs at most 2.5 % of volume by Hadamard's
    inequality, less than relief of 10 % RMS changes the extents), while
    the inertia ellipsoid feels the random shape of the overlay itself.
    Neither is a fault of the grain, and no scaling along x, y, z fixes
    both.  So, per grain, a map M = exp(E), E symmetric with trace 0 (the
    volume is kept), is solved for by Gauss–Newton so that the log-ratios
    log(I/L), log(S/I) of both the minimum box and the inertia-ellipsoid
    axes equal those of A:B:C: to first order a box edge along unit u and
    an inertia semi-axis along eigenvector u both change by u·E·u in log,
    which gives four linear equations in E's five free entries
    (minimum-norm solution).  The box is re-measured after every pass
    (its orientation can jump); a pass that does not lower the largest
    residual is retried from the best map with half the step.  At most
    ``CORRECTION_PASSES`` passes; stops below ``CORRECTION_TOLERANCE``.

    Returns
    -------
    M : (3, 3) float64
        Symmetric, det 1; apply as ``vertices @ M``.  Being linear it keeps
        the grain star-shaped about the origin and a valid solid.
    residual : float
        Largest |log(measured ratio / requested ratio)| left (recorded as
        ``aspect_residual``; docs/validation.md gives its distribution).

    Examples
    --------
    >>> from grainforge.geometry.geodesic import icosphere
    >>> u, f = icosphere(3)
    >>> M, res = aspect_correction(u * [1.1, 0.9, 1.0], np.array(f), (3, 2, 1))
    >>> bool(res < 2e-3), round(float(np.linalg.det(M)), 9)
    (True, 1.0)
    """
    from scipy.spatial import ConvexHull

    from ..analysis.box import minimum_box

    want = np.sort(np.asarray(aspect, dtype=np.float64))[::-1]
    target = np.diff(np.log(want))
    X = np.asarray(vertices, dtype=np.float64)
    hull_points = X[ConvexHull(X).vertices]  # a linear map keeps the hull's vertices

    def measure(M):
        lam, vec = np.linalg.eigh(M @ _second_moment(X, faces) @ M)
        lam, vec = lam[::-1], vec[:, ::-1]
        d, B = minimum_box(hull_points @ M)
        r = np.r_[np.diff(np.log(d)) - target, np.diff(0.5 * np.log(np.maximum(lam, 1e-300))) - target]
        A = np.array([_quad_row(B[1]) - _quad_row(B[0]), _quad_row(B[2]) - _quad_row(B[1]),
                      _quad_row(vec[:, 1]) - _quad_row(vec[:, 0]), _quad_row(vec[:, 2]) - _quad_row(vec[:, 1]),
                      [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]])
        return float(np.sqrt(np.mean(r**2))), r, A

    M = np.eye(3)
    err, r, A = measure(M)
    best = (err, M, r, A)
    step = 1.0
    for _ in range(CORRECTION_PASSES):
        if best[0] < CORRECTION_TOLERANCE:
            break
        _, Mb, rb, Ab = best
        # damped (Levenberg–Marquardt) step: when the box and the inertia ellipsoid share their axes
        # the four equations are nearly dependent and cannot all be met; the damping then splits
        # the difference instead of taking a huge step along the near-singular direction
        Aw = np.vstack([Ab, CORRECTION_DAMPING * np.eye(6)])
        Aw[4] *= 100.0  # trace 0: the volume is kept
        e = np.linalg.lstsq(Aw, np.r_[-rb, 0.0, np.zeros(6)], rcond=None)[0]
        w, V = np.linalg.eigh(_sym(step * e))
        # x ↦ x·Mb·exp(E) applies E in the current grain's frame; its left polar factor P
        # (Mb·exp(E) = P·Q, Q a rotation applied last) has the same measured ratios and is symmetric
        U, s, _ = np.linalg.svd(Mb @ (V * np.exp(w)) @ V.T)
        M = (U * s) @ U.T
        M /= np.cbrt(np.linalg.det(M))
        err, r, A = measure(M)
        if err < best[0]:
            best = (err, M, r, A)
        else:
            step *= 0.5
    return best[1], best[0]


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
    surface: str = "paper",
    aspect=(1.0, 1.0, 1.0),
    rng: RNGLike = None,
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
    surface : {"paper", "seamless"}
        ``paper`` (default): Eqs. 2–3 in latitude/longitude, with their
        mirror seam at the equator and R = R0 at both poles.  ``seamless``:
        the same sum as a function of the 3D unit vector (no special
        latitude or pole); see :func:`wm_sum`.
    aspect : (A, B, C)
        Proportions along x, y, z (default 1:1:1, a sphere, no correction):
        an ellipsoidal precursor with these semi-axis ratios carries the
        overlay (along the radius, relative to the precursor radius), then
        each grain is corrected so that its minimum box and its inertia
        ellipsoid both have I/L and S/I of A:B:C (:func:`aspect_correction`;
        the residual is ``info["aspect_residual"]``).  Longest/shortest at
        most 20.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seed or generator (:mod:`grainforge.rng`).  An int, a plain SeedSequence's entropy, or the seed
        drawn for None is recorded as ``Grain.seed``; a Generator leaves it None.

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
        surface=surface, aspect=tuple(aspect),
    )
    return generate(NAME, p, rng)
