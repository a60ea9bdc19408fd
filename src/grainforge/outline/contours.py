"""Closed 2D grain contours in polar form, and their Fourier descriptors.

A :class:`Contour` is a star-shaped closed curve given by its radius r(θ) on a
regular grid θ_j = 2πj/N about an origin (the area centroid for image
contours).  Radii are stored normalised to a mean of 1 (the Fourier descriptor
D0); ``scale`` holds the mean radius in the source's units (pixels for an
image, 1 for a generated contour).

Three sources (paper §2.2, Fig. 3; docs/design/algorithms.md §2a–2c):

- :meth:`Contour.from_descriptors` — Fourier descriptors (Mollon & Zhao 2012):
  r(θ) = r0 [1 + Σ_{n=2}^{N} D_n cos(nθ − δ_n)], with D2, D3, D8 given and
  the others following the regression D_n = D3 (n/3)^β1 (n = 4..7),
  D_n = D8 (n/8)^β2 (n ≥ 9).
- :meth:`Contour.from_fractal` — the 2D variant of the paper's Eq. 1 along the
  circle, with integer harmonics so that the profile closes smoothly at 2π.
- :meth:`Contour.from_image` — a grain image: threshold, largest component,
  holes filled, boundary, rays from the area centroid (the image side lives in
  :mod:`grainforge.outline.imaging`).

:meth:`Contour.descriptors` is the inverse: c = rfft(r)/N, D_n = 2|c_n|/c0.

The polygon side (area centroid, rays cast from it) is :mod:`grainforge.outline.polygons`'s.

Examples
--------
>>> from grainforge.outline.contours import Contour
>>> c = Contour.from_descriptors((0.15, 0.10, 0.03), rng=0)
>>> [round(float(d), 3) for d in c.descriptors()[[2, 3, 8]]]
[0.15, 0.1, 0.03]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..params import ParameterError
from ..rng import RNGLike, as_generator
from .imaging import grain_masks, load_image
from .polygons import area_centroid, polygon_area_centroid, ray_cast

__all__ = [
    "Contour",
    "PRESETS",
    "DEFAULT_DECAY",
    "descriptor_spectrum",
    "descriptors_of_radii",
    "polygon_area_centroid",
    "polygon_contour",
    "mask_contour",
    "scan_image",
    "GrainScan",
]

TWO_PI = 2.0 * np.pi

#: named descriptor triplets (D2, D3, D8) from the paper (§3, Fig. 10).
PRESETS: dict[str, tuple[float, float, float]] = {
    "rough-sphere": (0.0, 0.0, 0.02),
    "rough-angular": (0.15, 0.10, 0.03),
}
#: default decay exponents (β1, β2): outline spectra of natural sands fall as
#: n^(−10/3) in power (Barclay & Buckingham 2009), i.e. n^(−5/3) in amplitude.
DEFAULT_DECAY = (-5.0 / 3.0, -5.0 / 3.0)
#: default number of Fourier modes N of a descriptor contour.
DEFAULT_MODES = 64
#: default number of angles of a generated or extracted contour.
DEFAULT_ANGLES = 256
#: smallest allowed radius of a contour, relative to its mean radius.
MIN_RADIUS = 0.05


def descriptor_spectrum(
    d2: float, d3: float, d8: float, *, decay: Sequence[float] = DEFAULT_DECAY, modes: int = DEFAULT_MODES
) -> np.ndarray:
    """The full amplitude spectrum D_0..D_N from (D2, D3, D8) and the regression.

    Parameters
    ----------
    d2, d3, d8 : float
        Elongation, irregularity and roughness descriptors (≥ 0).
    decay : (β1, β2)
        D_n = D3 (n/3)^β1 for n = 4..7 and D_n = D8 (n/8)^β2 for n = 9..N.
    modes : int
        N ≥ 8.

    Returns
    -------
    (N + 1,) float64
        D_0 = 1, D_1 = 0, then D_2..D_N.

    Raises
    ------
    ParameterError
        ``modes`` when it is below 8.

    Examples
    --------
    >>> D = descriptor_spectrum(0.15, 0.1, 0.03, decay=(-2, -2), modes=16)
    >>> round(float(D[6]), 4), round(float(D[16]), 4)
    (0.025, 0.0075)
    """
    if modes < 8:
        raise ParameterError("modes", f"must be at least 8, got {modes!r}")
    b1, b2 = (float(b) for b in decay)
    n = np.arange(modes + 1, dtype=np.float64)
    D = np.zeros(modes + 1)
    D[0] = 1.0
    D[2], D[3], D[8] = d2, d3, d8
    D[4:8] = d3 * (n[4:8] / 3.0) ** b1
    D[9:] = d8 * (n[9:] / 8.0) ** b2
    return D


def descriptors_of_radii(radii: np.ndarray, n_max: int | None = None) -> np.ndarray:
    """Fourier descriptors D_0..D_nmax of radii sampled on a regular angle grid.

    c = rfft(r)/N, D_n = 2|c_n|/c_0 (D_0 = 1).  Works on the last axis.

    Parameters
    ----------
    radii : (..., N) array_like of float
        Radii at θ_j = 2πj/N (last axis), any positive unit.
    n_max : int, optional
        Highest order returned (default: all, N//2).

    Returns
    -------
    (..., n_max + 1) float64
        D_0 = 1, D_1, …, D_nmax: amplitudes relative to the mean radius.

    Examples
    --------
    >>> t = 2 * np.pi * np.arange(64) / 64
    >>> np.round(descriptors_of_radii(1 + 0.2 * np.cos(2 * t), 3), 12).tolist()
    [1.0, 0.0, 0.2, 0.0]
    """
    r = np.asarray(radii, dtype=np.float64)
    c = np.fft.rfft(r, axis=-1) / r.shape[-1]
    D = 2.0 * np.abs(c) / np.real(c[..., :1])
    D[..., 0] = 1.0
    return D if n_max is None else D[..., : n_max + 1]


def _check_radii(radii: np.ndarray, name: str) -> None:
    rmin = float(radii.min())
    if not np.isfinite(radii).all():
        raise ParameterError(name, "gives non-finite contour radii")
    if rmin <= MIN_RADIUS * float(radii.mean()):
        raise ParameterError(
            name,
            f"give a contour whose radius falls to {rmin / radii.mean():.3f} of its mean "
            f"(must stay above {MIN_RADIUS}); lower them",
        )


@dataclass(frozen=True, eq=False)
class Contour:
    """A closed star-shaped contour r(θ) on a regular angle grid.

    Parameters
    ----------
    radii : (N,) float64
        r(θ_j), θ_j = 2πj/N, counter-clockwise from +x; normalised on
        construction so that its mean (D0) is 1.
    scale : float
        The mean radius in source units (pixels for an image).
    centroid : (2,) float64
        The origin in source units ((x, y) with y up for an image).
    star_shaped : bool
        False when some ray crossed the source boundary more than once (the
        outermost crossing was kept).
    source : str
        ``"fourier"``, ``"fractal"``, ``"image"`` or ``"radii"``.

    Examples
    --------
    >>> c = Contour(np.full(64, 2.0))
    >>> c.scale, float(c.radii.mean()), round(float(c(np.pi / 3)), 12)
    (2.0, 1.0, 1.0)
    """

    radii: np.ndarray
    scale: float = 1.0
    centroid: np.ndarray = field(default_factory=lambda: np.zeros(2))
    star_shaped: bool = True
    source: str = "radii"

    def __post_init__(self):
        r = np.array(self.radii, dtype=np.float64).ravel()
        if r.size < 8:
            raise InputError(f"a contour needs at least 8 radii, got {r.size}")
        if not np.isfinite(r).all() or r.min() <= 0:
            raise InputError("contour radii must be finite and positive")
        mean = float(r.mean())
        r = r / mean
        r.setflags(write=False)
        object.__setattr__(self, "radii", r)
        object.__setattr__(self, "scale", float(self.scale) * mean)
        c = np.array(self.centroid, dtype=np.float64).reshape(2)
        c.setflags(write=False)
        object.__setattr__(self, "centroid", c)

    # ----------------------------------------------------------------- basics
    @property
    def n_angles(self) -> int:
        """Number of grid angles N."""
        return len(self.radii)

    @property
    def theta(self) -> np.ndarray:
        """The grid angles θ_j = 2πj/N, shape (N,)."""
        return TWO_PI * np.arange(self.n_angles) / self.n_angles

    def points(self, physical: bool = False) -> np.ndarray:
        """(N, 2) boundary points; in source units about ``centroid`` if ``physical``.

        Parameters
        ----------
        physical : bool, default False
            Scale by ``scale`` and translate to ``centroid`` (source units, e.g. pixels with y up);
            otherwise normalised radii about the origin.

        Returns
        -------
        (N, 2) float64
            (x, y) at the grid angles θ_j, counter-clockwise.
        """
        r = self.radii * (self.scale if physical else 1.0)
        p = np.stack([r * np.cos(self.theta), r * np.sin(self.theta)], axis=1)
        return p + self.centroid if physical else p

    def descriptors(self, n_max: int = 16) -> np.ndarray:
        """Fourier descriptors D_0..D_nmax (docs/design/algorithms.md §2b).

        Parameters
        ----------
        n_max : int, default 16
            Highest order (capped at N // 2).

        Returns
        -------
        (n_max + 1,) float64
            D_0 = 1; D_1 ≈ 0 when the origin is the centroid.
        """
        n_max = min(int(n_max), self.n_angles // 2)
        return descriptors_of_radii(self.radii, n_max)

    def resampled(self, n: int) -> np.ndarray:
        """The radii on a regular grid of ``n`` angles by exact trigonometric interpolation.

        Parameters
        ----------
        n : int
            Number of angles of the new grid θ_k = 2πk/n.

        Returns
        -------
        (n,) float64
            Normalised radii (mean 1); band-limited to the shorter of the two grids.
        """
        return _resample(self.radii, int(n))

    def __call__(self, theta) -> np.ndarray:
        """r(θ) / r0 at any angles (periodic linear interpolation on a 16× finer grid)."""
        fine = _fine(self)
        G = len(fine)
        x = np.mod(np.asarray(theta, dtype=np.float64), TWO_PI) * (G / TWO_PI)
        i = np.floor(x).astype(np.int64)
        w = x - i
        i %= G
        return fine[i] * (1 - w) + fine[(i + 1) % G] * w

    # ---------------------------------------------------------- transforms
    def recentred(self) -> Contour:
        """The same curve described about its area centroid (so that D1 ≈ 0).

        Generated contours are described about the origin they were built
        on, which is not exactly their centroid; an image contour is always
        described about its centroid, so compare the two after recentring.

        Returns
        -------
        Contour
            Same ``n_angles`` and ``source``; ``centroid`` moved by the shift (in source units); ``star_shaped``
            false if a ray from the new origin crosses the curve more than once.
        """
        fine = _fine(self)
        t = TWO_PI * np.arange(len(fine)) / len(fine)
        x, y = fine * np.cos(t), fine * np.sin(t)
        cx, cy = area_centroid(x, y)
        radii, star = ray_cast(x - cx, y - cy, self.n_angles)
        centroid = self.centroid + self.scale * np.array([cx, cy])
        return Contour(radii * self.scale, 1.0, centroid, star and self.star_shaped, self.source)

    def rotated(self, angle: float) -> Contour:
        """The contour turned counter-clockwise by ``angle`` (exact, via a Fourier phase shift).

        Parameters
        ----------
        angle : float
            Radians, counter-clockwise.

        Returns
        -------
        Contour
            Same grid, scale, centroid and source.
        """
        N = self.n_angles
        c = np.fft.rfft(self.radii)
        k = np.arange(len(c))
        c = c * np.exp(-1j * k * float(angle))
        if N % 2 == 0:
            c[-1] = c[-1].real
        return Contour(np.fft.irfft(c, N), self.scale, self.centroid, self.star_shaped, self.source)

    def mirrored(self) -> Contour:
        """The contour reflected about the x axis (θ → −θ)."

        Returns
        -------
        Contour
            Same grid, scale, centroid and source.
        """
        r = np.roll(self.radii[::-1], 1)
        return Contour(r, self.scale, self.centroid, self.star_shaped, self.source)

    def longest_direction(self) -> float:
        """Angle in [0, π) of the longest diameter r(θ) + r(θ + π)."

        Returns
        -------
        float
            Radians, on the contour's 16× finer grid.
        """
        fine = _fine(self)
        G = len(fine)
        diam = fine[: G // 2] + fine[G // 2 :]
        return float(np.argmax(diam)) * TWO_PI / G

    def aligned(self) -> Contour:
        """The contour turned so that its longest diameter lies along +x.

        Returns
        -------
        Contour
            :meth:`rotated` by ``-longest_direction()``.
        """
        return self.rotated(-self.longest_direction())

    def extents(self) -> tuple[float, float]:
        """Width along x and height along y of the (normalised) contour.

        Returns
        -------
        width, height : float
            In units of the mean radius (multiply by ``scale`` for source units).
        """
        fine = _fine(self)
        t = TWO_PI * np.arange(len(fine)) / len(fine)
        x, y = fine * np.cos(t), fine * np.sin(t)
        return float(x.max() - x.min()), float(y.max() - y.min())

    def stretched(self, ax: float, ay: float) -> Contour:
        """The contour with x multiplied by ``ax`` and y by ``ay``, resampled on its grid.

        A linear map keeps a star-shaped contour star-shaped about the origin,
        and maps angles monotonically, so the resampling is a 1D interpolation.

        Parameters
        ----------
        ax, ay : float
            Scale factors along x and y (> 0).

        Returns
        -------
        Contour
            On the same grid of angles (its mean radius normalised again to 1, ``scale`` keeping the old mean).
        """
        fine = _fine(self)
        G = len(fine)
        t = TWO_PI * np.arange(G) / G
        x, y = ax * fine * np.cos(t), ay * fine * np.sin(t)
        a = np.mod(np.arctan2(y, x), TWO_PI)
        r = np.hypot(x, y)
        order = np.argsort(a, kind="stable")
        a, r = a[order], r[order]
        a = np.concatenate([a[-1:] - TWO_PI, a, a[:1] + TWO_PI])
        r = np.concatenate([r[-1:], r, r[:1]])
        new = np.interp(self.theta, a, r)
        return Contour(new, self.scale, self.centroid, self.star_shaped, self.source)

    # ---------------------------------------------------------- constructors
    @classmethod
    def from_descriptors(
        cls,
        descriptors: Sequence[float] = PRESETS["rough-angular"],
        *,
        decay: Sequence[float] = DEFAULT_DECAY,
        modes: int = DEFAULT_MODES,
        n_angles: int = DEFAULT_ANGLES,
        rng: RNGLike = None,
    ) -> Contour:
        """A random contour with given Fourier descriptors (docs/design/algorithms.md §2a).

        r(θ) = 1 + Σ_{n=2}^{N} D_n cos(nθ − δ_n), δ_n ~ U(0, 2π) drawn in the
        order n = 2..N from ``rng``.

        Parameters
        ----------
        descriptors : (D2, D3, D8) or str
            Elongation, irregularity, roughness; or a preset name from
            :data:`PRESETS` (``"rough-sphere"``, ``"rough-angular"``).
        decay : (β1, β2)
            Decay exponents of the regression (default −5/3, −5/3).
        modes : int
            Highest mode N (default 64).
        n_angles : int
            Grid size (default 256; must exceed 2N).
        rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
            Normalised by :func:`grainforge.rng.as_generator`; the phases δ_2 … δ_N are its first ``modes − 1``
            uniform draws.

        Returns
        -------
        Contour
            ``source="fourier"``, scale 1, centred on the origin it was built about.

        Raises
        ------
        ParameterError
            ``descriptors`` when some radius would fall to 5 % of the mean or
            below (the contour is not wrapped with abs()); ``preset`` for an unknown preset name;
            ``n_angles`` unless it exceeds 2·modes; ``modes`` below 8.

        Examples
        --------
        >>> c = Contour.from_descriptors("rough-sphere", rng=3)
        >>> round(float(c.descriptors()[8]), 4), round(float(c.descriptors()[2]), 4)
        (0.02, 0.0)
        """
        d = resolve_descriptors(descriptors)
        if n_angles <= 2 * modes:
            raise ParameterError("n_angles", f"must exceed 2·modes = {2 * modes}, got {n_angles}")
        D = descriptor_spectrum(*d, decay=decay, modes=modes)
        delta = as_generator(rng).uniform(0.0, TWO_PI, size=modes - 1)
        return cls(_radii_from_spectrum(D, delta, n_angles), source="fourier")

    @classmethod
    def from_spectrum(cls, D: Sequence[float], *, n_angles: int = DEFAULT_ANGLES, rng: RNGLike = None) -> Contour:
        """A random contour with a full amplitude spectrum D_0…D_N (D_0, D_1 ignored).

        r(θ) = 1 + Σ_{n=2}^{N} D_n cos(nθ − δ_n), δ_n ~ U(0, 2π) drawn as in
        :meth:`from_descriptors`; e.g. a measured spectrum continued by
        :func:`grainforge.outline.spectra.extend_spectrum`.

        Parameters
        ----------
        D : (N + 1,) array_like of float
            Amplitudes D_0 … D_N relative to the mean radius (D_0 and D_1 are not used).
        n_angles : int, default 256
            Grid size, > 2N.
        rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
            Normalised by :func:`grainforge.rng.as_generator`; the phases δ_2 … δ_N are its first N − 1 uniform
            draws.

        Returns
        -------
        Contour
            ``source="spectrum"``.

        Raises
        ------
        ParameterError
            ``spectrum`` when some radius would fall to 5 % of the mean or below.

        Examples
        --------
        >>> D = descriptor_spectrum(0.15, 0.1, 0.03)
        >>> a, b = Contour.from_spectrum(D, rng=1), Contour.from_descriptors((0.15, 0.1, 0.03), rng=1)
        >>> bool(np.array_equal(a.radii, b.radii))
        True
        """
        D = np.asarray(D, dtype=np.float64)
        modes = len(D) - 1
        if modes < 2 or n_angles <= 2 * modes:
            raise ParameterError("spectrum", f"needs 2 <= N < n_angles/2 orders, got N = {modes}")
        delta = as_generator(rng).uniform(0.0, TWO_PI, size=modes - 1)
        try:
            radii = _radii_from_spectrum(D, delta, n_angles)
        except ParameterError as exc:
            raise ParameterError("spectrum", exc.reason) from None
        return cls(radii, source="spectrum")

    @classmethod
    def from_fractal(
        cls,
        *,
        fractal_dimension: float = 2.4,
        length_ratio: float = 2.0,
        amplitude: float = 0.06,
        ridges: int = 40,
        frequencies: int = 40,
        gamma: float = 1.5,
        modes: int = DEFAULT_MODES,
        n_angles: int = DEFAULT_ANGLES,
        rng: RNGLike = None,
    ) -> Contour:
        """A fractal profile around the circle: the 2D variant of the paper's Eq. 1.

        With θ held constant in Eq. 1 and ρ the arc angle φ on a unit circle,

            Z(φ) = Σ_m Σ_n w_n {cos ψ_mn − cos(h_mn φ + ψ_mn)},  w_n = (2πγ^(n−1)/L)^(D−3),

        where h_mn = round(k_n cos α_m), k_n = 2πγ^n/L, α_m = πm/M: the
        frequencies are rounded to integer harmonics so that the profile closes
        at 2π without a step or a kink (docs/design/algorithms.md §2c).  Harmonics above
        ``modes`` (and the grid's N/2 − 1) are dropped, as for a descriptor
        contour: finer ones could not be resolved by a mesh anyway.  r = 1 + K Z with K set
        so that the RMS of r − 1 is ``amplitude``.

        Parameters
        ----------
        fractal_dimension : float
            D in [2, 3), as for the surface of Eq. 1 (the profile's own
            dimension is D − 1).
        length_ratio : float
            L / R0 > 0.
        amplitude : float
            RMS of (r − r0)/r0.
        ridges, frequencies : int
            M and n_max.
        gamma : float
            γ > 1.
        modes : int
            Highest harmonic kept (default 64).
        n_angles : int
            Grid size.
        rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
            Normalised by :func:`grainforge.rng.as_generator`; ψ_mn ~ U(0, 2π), shape (M, n_max), drawn first.

        Returns
        -------
        Contour
            ``source="fractal"``.

        Raises
        ------
        ParameterError
            Naming ``fractal_dimension``, ``length_ratio`` or ``amplitude`` when out of range (or
            ``length_ratio`` so small that the wavenumbers overflow), and ``amplitude`` when some radius would
            fall to 5 % of the mean or below.

        Examples
        --------
        >>> c = Contour.from_fractal(rng=0)
        >>> round(float(np.std(c.radii * c.scale)), 3)
        0.06
        """
        if not 2.0 <= fractal_dimension < 3.0:
            raise ParameterError("fractal_dimension", f"must be in [2, 3), got {fractal_dimension!r}")
        if not length_ratio > 0:
            raise ParameterError("length_ratio", f"must be positive, got {length_ratio!r}")
        if not 0 <= amplitude <= 0.5:
            raise ParameterError("amplitude", f"must be in [0, 0.5], got {amplitude!r}")
        rng = as_generator(rng)
        M, Nf = int(ridges), int(frequencies)
        psi = rng.uniform(0.0, TWO_PI, size=(M, Nf))
        n = np.arange(1, Nf + 1, dtype=np.float64)
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            w = (TWO_PI * gamma ** (n - 1) / length_ratio) ** (fractal_dimension - 3.0)
            k = TWO_PI * gamma**n / length_ratio
        if not (np.isfinite(k).all() and np.isfinite(w).all()):  # e.g. L = 5e-324: 2πγ^n/L overflows
            raise ParameterError("length_ratio", f"is too small: the wavenumbers 2πγ^n/L overflow (L = {length_ratio!r})")
        alpha = np.pi * np.arange(1, M + 1) / M
        h = np.rint(np.cos(alpha)[:, None] * k[None, :])
        H = min(n_angles // 2 - 1, int(modes))
        keep = (np.abs(h) <= H) & (h != 0)
        hk = np.abs(h[keep]).astype(np.int64)
        # cos(hφ + ψ) with h < 0 is cos(|h|φ − ψ)
        phase = np.where(h[keep] > 0, psi[keep], -psi[keep])
        wk = np.broadcast_to(w, (M, Nf))[keep]
        spec = np.zeros(n_angles // 2 + 1, dtype=np.complex128)
        np.add.at(spec, hk, -wk * np.exp(1j * phase))
        spec[0] = float((wk * np.cos(psi[keep])).sum())
        # a profile value of Σ a_h cos(hφ + p_h) has rfft coefficient (N/2) a_h e^{i p_h}
        spec[1:] *= n_angles / 2.0
        spec[0] *= n_angles
        Z = np.fft.irfft(spec, n_angles)
        rms = float(np.sqrt(np.mean((Z - Z.mean()) ** 2)))
        K = amplitude / rms if rms > 0 else 0.0
        r = 1.0 + K * (Z - Z.mean())
        _check_radii(r, "amplitude")
        return cls(r, source="fractal")

    @classmethod
    def from_image(
        cls,
        image,
        *,
        threshold: float | None = None,
        foreground: str = "auto",
        n_angles: int = DEFAULT_ANGLES,
    ) -> Contour:
        """The contour of the largest grain in an image (docs/design/algorithms.md §2b).

        The image is thresholded (Otsu unless ``threshold`` is given), the
        largest connected component is kept with its holes filled, its
        boundary is traced (``skimage.measure.find_contours``) and rays are
        cast from the polygon's area centroid; each radius is the outermost
        crossing.

        Parameters
        ----------
        image : path or (H, W) / (H, W, C) array
            A grain image (PNG, TIFF, JPEG ...) or the pixel array.
        threshold : float, optional
            Grey level separating grain and background (default: Otsu).
        foreground : {"auto", "dark", "bright"}
            Which side of the threshold is grain; ``"auto"`` takes the side
            that covers fewer border pixels.
        n_angles : int
            Number of rays (default 256).

        Returns
        -------
        Contour
            ``source="image"``; ``scale`` in pixels and ``centroid`` in pixels as (column, −row).

        Raises
        ------
        ValueError
            If the image cannot be read or holds no grain.

        Examples
        --------
        >>> yy, xx = np.mgrid[:128, :128]
        >>> disc = ((xx - 60) ** 2 + (yy - 70) ** 2 < 40**2).astype(float)
        >>> c = Contour.from_image(disc, n_angles=128)
        >>> round(c.scale), np.round(c.centroid).tolist(), c.star_shaped
        (40, [60.0, -70.0], True)
        """
        from skimage.measure import label

        mask = grain_masks(load_image(image), threshold=threshold, foreground=foreground)

        lab = label(mask, connectivity=2)
        if lab.max() == 0:
            raise InputError("image holds no grain (nothing on the foreground side of the threshold)")
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        largest = lab == int(np.argmax(sizes))
        return mask_contour(largest, n_angles=n_angles)


# ------------------------------------------------------------------ helpers
def _resample(radii: np.ndarray, n: int) -> np.ndarray:
    N = len(radii)
    c = np.fft.rfft(radii) / N
    if n // 2 + 1 < len(c):
        c = c[: n // 2 + 1].copy()
        if n % 2 == 0:
            c[-1] = c[-1].real  # keep the Nyquist term real
    elif N % 2 == 0 and n > N:
        c = c.copy()
        c[-1] *= 0.5  # split the old Nyquist term between +N/2 and −N/2
    return np.fft.irfft(c * n, n)


@lru_cache(maxsize=64)
def _fine_cached(key: bytes, n: int) -> np.ndarray:
    fine = _resample(np.frombuffer(key, dtype=np.float64), n)
    fine.setflags(write=False)
    return fine


def _fine(contour: Contour) -> np.ndarray:
    """The contour resampled on a grid 16× finer (at least 2048), cached."""
    n = max(2048, 16 * contour.n_angles)
    return _fine_cached(contour.radii.tobytes(), n)


def _radii_from_spectrum(D: np.ndarray, delta: np.ndarray, n_angles: int) -> np.ndarray:
    """1 + Σ_{n≥2} D_n cos(nθ − δ_n) on n_angles points, via one inverse FFT."""
    spec = np.zeros(n_angles // 2 + 1, dtype=np.complex128)
    spec[0] = n_angles
    spec[2 : len(D)] = (n_angles / 2.0) * D[2:] * np.exp(-1j * delta)
    r = np.fft.irfft(spec, n_angles)
    _check_radii(r, "descriptors")
    return r


def resolve_descriptors(descriptors) -> tuple[float, float, float]:
    """(D2, D3, D8) from a triplet or a preset name; validated."""
    if isinstance(descriptors, str):
        try:
            return PRESETS[descriptors]
        except KeyError:
            raise ParameterError(
                "preset", f"must be one of {', '.join(PRESETS)}, got {descriptors!r}"
            ) from None
    try:
        d = tuple(float(x) for x in descriptors)
    except (TypeError, ValueError):
        raise ParameterError("descriptors", f"must be three numbers D2,D3,D8, got {descriptors!r}") from None
    if len(d) != 3:
        raise ParameterError("descriptors", f"must be three numbers D2,D3,D8, got {descriptors!r}")
    if not all(np.isfinite(d)) or min(d) < 0 or max(d) > 1:
        raise ParameterError("descriptors", f"must each be in [0, 1], got {descriptors!r}")
    return d


def polygon_contour(points, *, n_angles: int = DEFAULT_ANGLES, source: str = "polygon") -> Contour:
    """The :class:`Contour` of a closed polygon: radii from its area centroid (outermost crossings).

    Parameters
    ----------
    points : (P, 2) float
        Vertices (x, y) in order; the closing edge is implied (a repeated last point is fine).
    n_angles : int
        Rays θ_j = 2πj/n_angles.
    source : str
        Recorded in :attr:`Contour.source`.

    Returns
    -------
    Contour
        ``scale`` and ``centroid`` in the points' unit; ``star_shaped`` false when a ray crosses the
        polygon more than once.

    Raises
    ------
    ValueError
        If the polygon has fewer than 3 points, encloses no area, or some ray
        from its centroid meets no edge.

    Examples
    --------
    >>> sq = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    >>> c = polygon_contour(sq, n_angles=8)
    >>> np.round(c.radii * c.scale, 6).tolist()[:2], c.star_shaped  # radii are stored over their mean
    ([1.0, 1.414214], True)
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(p) > 1 and np.allclose(p[0], p[-1]):
        p = p[:-1]
    if len(p) < 3:
        raise InputError("an outline needs at least 3 points")
    cx, cy = area_centroid(p[:, 0], p[:, 1])
    radii, star = ray_cast(p[:, 0] - cx, p[:, 1] - cy, n_angles)
    return Contour(radii, 1.0, (cx, cy), star, source)


def mask_contour(
    mask: np.ndarray, *, n_angles: int = DEFAULT_ANGLES, offset=(0.0, 0.0), filled: bool = False
) -> Contour:
    """The :class:`Contour` of one connected component given as a boolean mask.

    Holes are filled, the boundary is traced at the 0.5 level, the origin is
    the polygon's area centroid and the radius along each of ``n_angles`` rays
    is the outermost crossing of the boundary.  Coordinates are (x, y) =
    (column, −row) so that angles run counter-clockwise as displayed;
    ``offset`` = (row0, col0) of the mask in a larger image; ``filled`` says
    that the holes are filled already.

    Parameters
    ----------
    mask : (H, W) array_like of bool
        One connected component (8-connected), True on the grain.
    n_angles : int, default 256
        Number of rays.
    offset : (row0, col0), default (0, 0)
        Where the mask's pixel (0, 0) lies in the image, in pixels.
    filled : bool, default False
        The holes are filled already (skip the filling).

    Returns
    -------
    Contour
        ``source="image"``, ``scale`` and ``centroid`` in pixels ((column, −row) of the image).

    Raises
    ------
    ValueError
        If the mask is empty or the boundary does not enclose its area centroid.

    Examples
    --------
    >>> yy, xx = np.mgrid[:64, :64]
    >>> c = mask_contour((xx - 30) ** 2 + (yy - 20) ** 2 < 15**2, n_angles=64)
    >>> round(c.scale), np.round(c.centroid).tolist()
    (15, [30.0, -20.0])
    """
    from scipy.ndimage import binary_fill_holes
    from skimage.measure import find_contours

    m = np.asarray(mask, dtype=bool)
    if not filled:
        m = binary_fill_holes(m)
    if not m.any():
        raise InputError("mask holds no grain")
    padded = np.pad(m, 1).astype(np.float64)
    loops = find_contours(padded, 0.5)
    loop = max(loops, key=len)
    x = loop[:, 1] - 1 + offset[1]
    y = -(loop[:, 0] - 1 + offset[0])
    return polygon_contour(np.stack([x, y], axis=1), n_angles=n_angles, source="image")


@dataclass(frozen=True)
class GrainScan:
    """The grains found in one image by :func:`scan_image`.

    Attributes
    ----------
    contours : list of Contour
        One per measured grain, in label order (row-major by first pixel);
        ``centroid`` is in pixels with (x, y) = (column, −row).
    areas : list of int
        Pixel areas of the measured grains (holes filled).
    border : int
        Grains skipped because they touch the image border.
    small : int
        Specks skipped because their area is below ``min_area``.
    unmeasurable : int
        Grains skipped because their area centroid lies outside them (no ray
        from it reaches the boundary in every direction).
    """

    contours: list
    areas: list
    border: int
    small: int
    unmeasurable: int = 0


def scan_image(
    image,
    *,
    min_area: int = 50,
    threshold: float | None = None,
    foreground: str = "auto",
    n_angles: int = 128,
) -> GrainScan:
    """Every grain of an image as a :class:`Contour` (for ``grainforge fourier``).

    The image is thresholded (Otsu by default), connected components are
    labelled (8-connectivity, ``skimage.measure.label``); components touching
    the border and those smaller than ``min_area`` pixels are skipped and
    counted; each remaining one gets its holes filled and its contour traced
    as in :meth:`Contour.from_image`.

    Parameters
    ----------
    image : path or (H, W) / (H, W, C) array_like
        An image file (PNG, TIFF, JPEG ...) or its pixels.
    min_area : int, default 50
        Smallest grain measured, in pixels (holes filled).
    threshold : float, optional
        Grey level separating grain and background (default: Otsu's).
    foreground : {"auto", "dark", "bright"}, default "auto"
        Which side of the threshold is grain; ``"auto"`` takes the side that covers fewer border pixels.
    n_angles : int, default 128
        Rays per contour.

    Returns
    -------
    GrainScan
        The contours (pixels) and the counts of grains skipped and why.

    Raises
    ------
    ValueError
        If the image cannot be read, is uniform, or ``min_area`` is negative.

    Examples
    --------
    >>> img = np.zeros((100, 100)); img[10:30, 10:40] = 1; img[50:90, 50:70] = 1; img[0:5, 0:5] = 1
    >>> img[95:97, 10:12] = 1
    >>> s = scan_image(img, min_area=10)
    >>> len(s.contours), s.areas, s.border, s.small
    (2, [600, 800], 1, 1)
    """
    if min_area < 0:
        raise InputError(f"min_area must be a non-negative number of pixels, got {min_area!r}")
    from skimage.measure import label, regionprops

    mask = grain_masks(load_image(image), threshold=threshold, foreground=foreground)
    lab = label(mask, connectivity=2)
    H, W = lab.shape
    contours, areas = [], []
    border = small = unmeasurable = 0
    for region in regionprops(lab):
        r0, c0, r1, c1 = region.bbox
        if r0 == 0 or c0 == 0 or r1 == H or c1 == W:
            border += 1
            continue
        filled = region.image_filled
        area = int(filled.sum())
        if area < min_area:
            small += 1
            continue
        try:
            contours.append(mask_contour(filled, n_angles=n_angles, offset=(r0, c0), filled=True))
        except ValueError:
            unmeasurable += 1
            continue
        areas.append(area)
    return GrainScan(contours, areas, border, small, unmeasurable)
