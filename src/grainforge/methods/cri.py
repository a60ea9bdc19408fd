"""Contour Rotation Interpolation (CRI): a 3D grain from three 2D contours.

Paper §2.2 (Mollon & Zhao 2012, 2013); the formulas are this package's
reconstruction (docs/design/algorithms.md §2d, ``docs/methods/cri.md``).  Axes: x longest,
y intermediate, z shortest.  C1 lies in the xy plane (angle from +x towards
+y), C2 in xz (from +x towards +z), C3 in yz (from +y towards +z).

1. Each contour is turned so that its longest diameter lies on its first axis
   and, if an aspect L:I:S is asked for, stretched to it.
2. Correction: the contours are made to agree at the six axis points (target =
   mean of the two contours meeting there) by multiplying each with the smooth
   factor f(θ) = a0 + a1 cos θ + b1 sin θ + a2 cos 2θ that equals the needed
   ratio at its four axis points.
3. Revolution: with θ the angle from +x and ψ the azimuth about x (from +y
   towards +z), r̃(θ, ψ) = cos²ψ · r1±(θ) + sin²ψ · r2±(θ), each half-contour
   taken on the side of ψ's quadrant.
4. Stretching/morphing: s(ψ) = r3(ψ)/r̃(π/2, ψ) and
   r(θ, ψ) = r̃(θ, ψ)·[1 + (s(ψ) − 1) sin^p θ].
5. r is sampled at the vertices of an icosphere, giving a star-shaped closed mesh
   whose three principal sections are the corrected C1, C2, C3.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache, lru_cache
from pathlib import Path

import numpy as np

from ..geometry.geodesic import icosphere
from ..outline.contours import (
    DEFAULT_DECAY,
    PRESETS,
    Contour,
    descriptors_of_radii,
)
from ..outline.spectra import extend_spectrum, read_spectra
from ..params import ParameterError, check_aspect, check_lengths, param, resolve_descriptors, validate
from ..rng import RNGLike, as_generator

__all__ = ["Params", "build", "cri", "construct", "load_image_contour", "Construction", "SOURCES", "PRESETS", "mesh_modes"]

NAME = "cri"
VALIDITY_PARAMETER = "descriptors"
#: vertices are unit directions times a positive radius (times a positive axis scaling): star-shaped
STAR_SHAPED = True
#: largest L/S of a requested aspect (the declared values run over (0, 100])
MAX_ASPECT_RATIO = 100.0


def validity_parameter(p: Params) -> str:
    """The option a user changes when the surface is not a valid solid: what shaped the contours."""
    if p.aspect is not None:
        return "aspect"
    return {"fractal": "fractal_amplitude", "image": "images", "given": "sections"}.get(p.contour, "descriptors")
#: contour sources: Fourier descriptors, fractal profiles, image files, a
#: measured spectrum table (``grainforge fourier`` CSV), or
#: :class:`~grainforge.outline.contours.Contour` objects given from Python.
SOURCES = ("fourier", "fractal", "image", "spectrum", "given")
#: default (D2, D3, D8) when neither descriptors nor a preset is given.
DEFAULT_PRESET = "rough-angular"
#: fine grid on which the contours are interpolated (periodic, linear).
GRID = 2048
PLANES = ("xy", "xz", "yz")
#: ways of making the three contours share one L:I:S (see :func:`construct`)
CONSISTENCY = ("spectral", "stretch")
#: where the roughness (modes n >= 3) comes from: "swept" from the contours (the method), or "field":
#: an isotropic random field with the contours' mean spectrum on the form the contours' modes 0-2 give
#: (docs/methods/cri.md, "Ridge-free roughness")
ROUGHNESS = ("swept", "field")
#: highest harmonic degree of the "field" roughness
FIELD_DEGREE = 32
#: icosphere level on which the extents are measured for a requested aspect
ASPECT_REFERENCE_SUBDIVISIONS = 5
MEASURED = (2, 3, 8)
#: generation outputs recorded in manifests: FDs (D2, D3, D8) of the three input
#: contours as given, and of the three principal sections (the corrected
#: contours), the harmonics kept (min(modes, 2^s)), the x:y:z diameters the
#: contours were stretched to, the final axis scaling (aspect), the largest
#: correction |f − 1|, and the extreme radii.
INFO_COLUMNS = tuple(
    f"{kind}_{plane}_D{n}" for kind in ("contour", "section") for plane in PLANES for n in MEASURED
) + ("modes_used", "target_aspect", "axis_scale", "correction", "min_radius", "max_radius")


def _triplet(name):
    return param(
        None, f"Fourier descriptors D2,D3,D8 of the {name} contour",
        kind="floats", low=0.0, high=1.0, shown_default="those of descriptors",
    )


@dataclass(frozen=True)
class Params:
    """Parameters of the CRI generator (paper §2.2)."""

    contour: str | None = param(
        None, "contour source: fourier, fractal, image or spectrum",
        kind="str", choices=SOURCES[:4],
        shown_default="fourier; image when images are given, spectrum when a spectrum table is",
    )
    preset: str | None = param(
        None, "named descriptors: rough-sphere = 0,0,0.02; rough-angular = 0.15,0.10,0.03",
        kind="str", choices=tuple(PRESETS),
    )
    descriptors: tuple[float, float, float] | None = param(
        None, "Fourier descriptors D2,D3,D8 (elongation, irregularity, roughness) of all three contours",
        kind="floats", low=0.0, high=1.0, shown_default=f"the {DEFAULT_PRESET} preset",
    )
    descriptors_xz: tuple[float, float, float] | None = _triplet("xz")
    descriptors_yz: tuple[float, float, float] | None = _triplet("yz")
    decay: tuple[float, float] = param(
        DEFAULT_DECAY, "decay exponents B1,B2: D_n = D3 (n/3)^B1 for n=4..7, D8 (n/8)^B2 for n>8",
        kind="floats", low=-10.0, high=0.0,
    )
    modes: int = param(64, "highest Fourier mode N of a descriptor or fractal contour", kind="int", low=8, high=120)
    fractal_dimension: float = param(
        2.4, "fractal contours: dimension D of Eq. 1 (profile dimension D - 1)", low=2.0, high=3.0, high_open=True
    )
    length_ratio: float = param(2.0, "fractal contours: stochastic length L/R0", low=0.0, low_open=True, high=100.0)
    fractal_amplitude: float = param(0.06, "fractal contours: RMS of (r - r0)/r0", low=0.0, high=0.5)
    images: str | None = param(None, "three grain images A,B,C for the xy, xz and yz contours", kind="str")
    spectrum: str | None = param(
        None, "a 'grainforge fourier' CSV: each grain takes the D2..D16 of one measured grain, drawn at random, "
        "for its three contours (above D16: decay B2)", kind="str",
    )
    aspect: tuple[float, float, float] | None = param(
        None, "target ratio L:I:S of the principal dimensions",
        kind="floats", low=0.0, low_open=True, high=100.0, shown_default="as the contours give it",
    )
    morph_exponent: float = param(2.0, "exponent p of the morphing weight sin^p(theta)", low=0.5, high=8.0)
    ridge_twist: float = param(
        30.0, "largest angle by which each roughness mode (n >= 3) of a contour is turned away from the "
        "direction the interpolation sweeps it in, as it leaves its plane (0 = the 2016 sweep, parallel ridges)", unit="deg",
        low=0.0, high=60.0,
    )
    consistency: str = param(
        "spectral", "how the three contours are given one L:I:S: spectral = set each contour's mode 2 and mean "
        "radius, keep every other mode (the descriptors survive); stretch = stretch each contour linearly "
        "(the 2016 reconstruction; lowers D8 by ~15 %)", kind="str", choices=CONSISTENCY,
    )
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)
    roughness: str = param(
        "swept", "swept = every roughness mode (n >= 3) swept from the contours (the method, with its ridges); "
        "field = the contours' form (modes 0-2) with an isotropic random-field roughness of the contours' mean "
        "spectrum (no ridges; the sections carry the descriptors on average, not exactly)", kind="str",
        choices=ROUGHNESS,
    )
    #: three :class:`~grainforge.outline.contours.Contour` (xy, xz, yz) given from Python
    sections: tuple[Contour, Contour, Contour] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        validate(self)
        source = self.contour
        if self.sections is not None:
            secs = tuple(self.sections)
            if len(secs) != 3 or not all(isinstance(c, Contour) for c in secs):
                raise ParameterError("sections", "must be three Contour objects (xy, xz, yz)")
            object.__setattr__(self, "sections", secs)
            if source is not None:
                raise ParameterError("contour", f"must be unset when sections are given, got {source!r}")
            if self.spectrum is not None:
                raise ParameterError("spectrum", "cannot be combined with sections: give one of them")
            source = "given"
        elif self.images is not None:
            if source not in (None, "image"):
                raise ParameterError("images", f"cannot be combined with contour={source!r}")
            if self.spectrum is not None:
                raise ParameterError("spectrum", "cannot be combined with images: give one of them")
            source = "image"
            paths = tuple(x.strip() for x in self.images.split(",") if x.strip())
            if len(paths) != 3:
                raise ParameterError("images", f"must name three image files A,B,C, got {self.images!r}")
            object.__setattr__(self, "images", ",".join(paths))
        elif source == "image":
            raise ParameterError("images", "are required with contour='image'")
        elif self.spectrum is not None:
            if source not in (None, "spectrum"):
                raise ParameterError("spectrum", f"cannot be combined with contour={source!r}")
            source = "spectrum"
            read_spectra(self.spectrum)  # fail early on a missing or malformed table
        elif source == "spectrum":
            raise ParameterError("spectrum", "is required with contour='spectrum'")
        source = source or "fourier"
        object.__setattr__(self, "contour", source)

        check_lengths(self, {"descriptors": 3, "descriptors_xz": 3, "descriptors_yz": 3, "decay": 2, "aspect": 3})
        if source == "fourier":
            resolve_descriptors(self, PRESETS, DEFAULT_PRESET)
        else:
            for name in ("preset", "descriptors", "descriptors_xz", "descriptors_yz"):
                if getattr(self, name) is not None:
                    raise ParameterError(name, f"applies to Fourier-descriptor contours, not contour={source!r}")
        check_aspect(self.aspect, MAX_ASPECT_RATIO)


# ------------------------------------------------------------------ geometry
@dataclass(frozen=True)
class _Geometry:
    """Per-direction constants of the CRI surface (cached per icosphere level)."""

    i1: np.ndarray  # (V,) fine-grid index of the C1 angle
    w1: np.ndarray
    i2: np.ndarray
    w2: np.ndarray
    i3: np.ndarray
    w3: np.ndarray
    cos2: np.ndarray  # cos²ψ
    sin2: np.ndarray  # sin²ψ
    y_pos: np.ndarray  # bool: y >= 0 (C1 at π/2, else 3π/2 for r̃(π/2, ψ))
    z_pos: np.ndarray
    sin_theta: np.ndarray  # sin θ = sqrt(y² + z²)


def _index(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.mod(angle, 2 * np.pi) * (GRID / (2 * np.pi))
    i = np.floor(x).astype(np.int64)
    w = x - i
    return i % GRID, w


def _geometry(unit: np.ndarray) -> _Geometry:
    ux, uy, uz = unit[:, 0], unit[:, 1], unit[:, 2]
    rho2 = uy * uy + uz * uz
    theta = np.arccos(np.clip(ux / np.sqrt(ux * ux + rho2), -1.0, 1.0))
    y_pos, z_pos = uy >= 0, uz >= 0
    a1 = np.where(y_pos, theta, 2 * np.pi - theta)
    a2 = np.where(z_pos, theta, 2 * np.pi - theta)
    a3 = np.arctan2(uz, uy)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos2 = np.where(rho2 > 0, uy * uy / rho2, 1.0)
    i1, w1 = _index(a1)
    i2, w2 = _index(a2)
    i3, w3 = _index(a3)
    return _Geometry(i1, w1, i2, w2, i3, w3, cos2, 1.0 - cos2, y_pos, z_pos, np.sin(theta))


@cache
def _sphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray, _Geometry]:
    unit, faces = icosphere(subdivisions)
    return unit, faces, _geometry(unit)


def _lookup(fine: np.ndarray, i: np.ndarray, w: np.ndarray) -> np.ndarray:
    j = i + 1
    j[j == GRID] = 0
    return fine[i] * (1.0 - w) + fine[j] * w


# ------------------------------------------------------------------ the construction
@dataclass(frozen=True)
class Construction:
    """The three contours of one CRI grain and the surface they define.

    Attributes
    ----------
    inputs : tuple of Contour
        The contours as generated or read (xy, xz, yz), before alignment.
    sections : (3, GRID) float64
        The corrected contours on the fine grid θ_j = 2πj/GRID: the principal
        sections of the grain (xy, xz, yz), in the grain's units.
    factors : (3, GRID) float64
        The correction factors f(θ) applied to the aligned and stretched contours.
    morph_exponent : float
    dims : (3,) float
        The diameters through the origin along x, y, z that the contours were
        stretched to (geometric mean 2): the requested aspect, or the
        least-squares ratio consistent with the three contours' own
        axis-diameter ratios.  The correction keeps them exactly.
    axis_scale : (3,) float
        Final scaling of x, y, z (1 unless an aspect is requested): it makes
        the extents of the surface (measured on a level-5 icosphere) exactly
        L:I:S, with the same geometric mean.  The principal sections of the
        grain are then the corrected contours stretched by these factors.
    """

    inputs: tuple[Contour, Contour, Contour]
    sections: np.ndarray
    factors: np.ndarray
    morph_exponent: float
    dims: tuple[float, float, float] = (2.0, 2.0, 2.0)
    axis_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    #: (3, n) tan of the turn of each mode of C1, C2, C3 (None: no twist), see :meth:`radius`
    twist: np.ndarray | None = None

    def section(self, plane: str) -> Contour:
        """The principal section ``"xy"``, ``"xz"`` or ``"yz"`` as a :class:`Contour` (scale kept).

        Parameters
        ----------
        plane : {"xy", "xz", "yz"}
            Which principal section.

        Returns
        -------
        Contour
            The corrected section (before ``axis_scale``), ``scale`` its mean radius in grain units.
        """
        return Contour(self.sections[PLANES.index(plane)])

    def points(self, unit: np.ndarray, geometry: _Geometry | None = None) -> np.ndarray:
        """Surface points (V, 3) along unit vectors: r(θ, ψ)·unit, scaled by ``axis_scale``."

        Parameters
        ----------
        unit : (V, 3) ndarray of float
            Unit vectors.
        geometry : optional
            The precomputed angles of ``unit`` (internal; computed when omitted).

        Returns
        -------
        (V, 3) float64
            Points of the grain's surface, in grain units.
        """
        pts = unit * self.radius(unit, geometry)[:, None]
        if self.axis_scale != (1.0, 1.0, 1.0):
            pts = pts * np.asarray(self.axis_scale)
        return pts

    def radius(self, unit: np.ndarray, geometry: _Geometry | None = None) -> np.ndarray:
        """r(θ, ψ) along unit vectors ``unit`` (V, 3)."

        Parameters
        ----------
        unit : (V, 3) ndarray of float
            Unit vectors.
        geometry : optional
            The precomputed angles of ``unit`` (internal; computed when omitted).

        Returns
        -------
        (V,) float64
            The radius of the surface along each vector, before ``axis_scale``.
        """
        g = geometry if geometry is not None else _geometry(np.asarray(unit, dtype=np.float64))
        c1, c2, c3 = self.sections
        r1 = _lookup(c1, g.i1, g.w1)
        r2 = _lookup(c2, g.i2, g.w2)
        r3 = _lookup(c3, g.i3, g.w3)
        q = GRID // 4
        mid = g.cos2 * np.where(g.y_pos, c1[q], c1[3 * q]) + g.sin2 * np.where(g.z_pos, c2[q], c2[3 * q])
        if self.twist is not None:
            r1, r2, r3, mid = self._twisted(np.asarray(unit, dtype=np.float64), g, r1, r2, r3, mid)
        blend = g.cos2 * r1 + g.sin2 * r2
        s = r3 / mid
        p = self.morph_exponent
        weight = g.sin_theta**2 if p == 2.0 else g.sin_theta**p
        return blend * (1.0 + (s - 1.0) * weight)


    def _twisted(self, unit, g: _Geometry, r1, r2, r3, mid):  # noqa: D417
        """C1, C2, C3 (and r̃(π/2, ψ)) with their roughness modes turned as they leave their planes.

        In the revolution, C1's mode n, 2|c_n| cos(nθ + φ_n), is swept around
        x into rings (θ fixed): a family of parallel ridges.  Here its phase
        also advances with the angle δ out of the xy plane,
        nθ + φ_n + n·t_n·sin θ cos²θ·δ (t_n = tan of a turn drawn uniformly in
        ±``ridge_twist``), so each mode's ridges run at their own angle to the
        rings.  sin θ keeps the x tips single-valued; cos²θ keeps C1 and C2
        unturned where they meet the yz plane, so that the morphing (which
        divides by their values there) still gives C3 as the yz section.  At
        δ = 0 nothing changes: the xy section is still C1.  Likewise C2 with
        the angle out of the xz plane.  C3, which the morphing sweeps along
        θ, is turned the same way with the angle out of the yz plane,
        π/2 − θ, times sin²2ψ, which keeps it unturned on the xy and xz
        planes (where the morphing factor must stay 1).  Modes 0–2 (the form)
        are not turned.
        """
        ux, uy, uz = unit[:, 0], unit[:, 1], unit[:, 2]
        st = g.sin_theta
        sin2psi2 = 4.0 * g.cos2 * g.sin2  # sin²(2ψ)
        elev = np.arcsin(np.clip(ux, -1.0, 1.0))  # π/2 − θ
        off1, off2 = np.arctan2(uz, np.abs(uy)), np.arctan2(uy, np.abs(uz))

        def delta(k, ang, off):
            spec = np.fft.rfft(self.sections[k]) / GRID
            n = np.arange(3, len(self.twist[k]))
            amp = 2.0 * np.abs(spec[n])
            keep = amp > 1e-12 * abs(spec[0])
            n, amp, phase, t = n[keep], amp[keep], np.angle(spec[n[keep]]), self.twist[k][n[keep]]
            base = np.outer(ang, n) + phase
            return (np.cos(base + np.outer(off, n * t)) - np.cos(base)) @ amp

        step = 2 * np.pi / GRID
        fade = st * (1.0 - st * st)  # sin θ cos² θ
        r1 = r1 + delta(0, (g.i1 + g.w1) * step, fade * off1)
        r2 = r2 + delta(1, (g.i2 + g.w2) * step, fade * off2)
        r3 = r3 + delta(2, (g.i3 + g.w3) * step, elev * sin2psi2)
        return r1, r2, r3, mid


def mesh_modes(subdivisions: int) -> int:
    """Highest contour harmonic a level-``s`` icosphere resolves: 2^s.

    A principal great circle of the icosphere carries 4·2^s vertices, so
    harmonic 2^s has four vertices per wavelength; above it, linear
    interpolation between vertices (and aliasing) would misrepresent the
    contour.  Contours are band-limited to this, so a coarse grain is the
    low-pass version of the fine grain with the same seed.

    Parameters
    ----------
    subdivisions : int
        Icosphere level s.

    Returns
    -------
    int
        2^s.

    Examples
    --------
    >>> mesh_modes(5)
    32
    """
    return 2 ** int(subdivisions)


def _band_limit(fine: np.ndarray, modes: int) -> np.ndarray:
    """The grid functions (last axis) with every harmonic above ``modes`` removed."""
    spec = np.fft.rfft(fine, axis=-1)
    spec[..., modes + 1:] = 0.0
    return np.fft.irfft(spec, GRID, axis=-1)


def _fine(radii: np.ndarray, modes: int) -> np.ndarray:
    """Radii (last axis, any regular grid) on the fine grid, band-limited to ``modes`` harmonics.

    Descriptor and fractal contours have nothing above ``modes`` anyway; an
    image contour loses its pixel-scale noise, which no mesh could resolve.
    """
    n = radii.shape[-1]
    spec = np.fft.rfft(radii, axis=-1)[..., : min(modes, (n - 1) // 2) + 1]
    out = np.zeros(radii.shape[:-1] + (GRID // 2 + 1,), dtype=np.complex128)
    out[..., : spec.shape[-1]] = spec * (GRID / n)
    return np.fft.irfft(out, GRID, axis=-1)


_T = 2 * np.pi * np.arange(GRID) / GRID
_COS, _SIN, _COS2 = np.cos(_T), np.sin(_T), np.cos(2 * _T)


def _aligned(fine: np.ndarray) -> np.ndarray:
    """The contour turned (by a whole number of grid steps) so that its longest diameter is along θ = 0."""
    h = GRID // 2
    k = int(np.argmax(fine[:h] + fine[h:]))
    return np.concatenate([fine[k:], fine[:k]])


def _stretch(fine: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """Radii on the grid of the contour with x scaled by ``ax`` and y by ``ay``.

    A linear map with positive factors keeps θ = 0 fixed and maps angles
    monotonically, so the new radii are a periodic 1D interpolation.
    """
    x, y = ax * fine * _COS, ay * fine * _SIN
    a = np.arctan2(y, x)
    a[a < 0] += 2 * np.pi
    a[0] = 0.0
    return np.interp(_T, np.r_[a, 2 * np.pi], np.r_[np.hypot(x, y), fine[0] * ax])


#: how each orientation permutes the values at (0, π/2, π, 3π/2): identity, turned by π,
#: mirrored (θ → −θ), mirrored and turned.  Each keeps the longest diameter on the first axis.
_PERMUTATIONS = np.array([[0, 1, 2, 3], [2, 3, 0, 1], [0, 3, 2, 1], [2, 1, 0, 3]])


def _variant(fine: np.ndarray, i: int) -> np.ndarray:
    if i in (2, 3):
        fine = np.concatenate([fine[:1], fine[:0:-1]])  # r(−θ)
    if i in (1, 3):
        h = GRID // 2
        fine = np.concatenate([fine[h:], fine[:h]])  # r(θ − π)
    return fine


def _best_orientation(fines: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Of the 4³ orientations of the three contours, the one with the smallest axis mismatch.

    Turning a contour by π or mirroring it changes neither its shape nor its
    descriptors, but changes which radii meet at the six axis points; picking
    the best combination makes the correction (step 1) as small as it can be.
    """
    q = GRID // 4
    axis = np.array([f[[0, q, 2 * q, 3 * q]] for f in fines])  # (3, 4)
    v = axis[:, _PERMUTATIONS]  # (3 contours, 4 variants, 4 axis values)
    a, b, c = v[0][:, None, None, :], v[1][None, :, None, :], v[2][None, None, :, :]
    # pairs: C1(0)~C2(0), C1(π)~C2(π), C1(π/2)~C3(0), C1(3π/2)~C3(π), C2(π/2)~C3(π/2), C2(3π/2)~C3(3π/2)
    cost = (
        (a[..., 0] - b[..., 0]) ** 2 + (a[..., 2] - b[..., 2]) ** 2
        + (a[..., 1] - c[..., 0]) ** 2 + (a[..., 3] - c[..., 2]) ** 2
        + (b[..., 1] - c[..., 1]) ** 2 + (b[..., 3] - c[..., 3]) ** 2
    )
    choice = np.unravel_index(int(np.argmin(cost)), cost.shape)
    return [_variant(f, int(i)) for f, i in zip(fines, choice)]


def _correct(fines: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Make the three contours agree at the six axis points (docs/design/algorithms.md §2d step 1)."""
    c1, c2, c3 = fines
    q = GRID // 4
    # values at 0, π/2, π, 3π/2 of each contour
    v1 = c1[[0, q, 2 * q, 3 * q]]
    v2 = c2[[0, q, 2 * q, 3 * q]]
    v3 = c3[[0, q, 2 * q, 3 * q]]
    xp, xm = (v1[0] + v2[0]) / 2, (v1[2] + v2[2]) / 2
    yp, ym = (v1[1] + v3[0]) / 2, (v1[3] + v3[2]) / 2
    zp, zm = (v2[1] + v3[1]) / 2, (v2[3] + v3[3]) / 2
    targets = np.array([[xp, yp, xm, ym], [xp, zp, xm, zm], [yp, zp, ym, zm]])
    ratio = targets / np.stack([v1, v2, v3])  # (3, 4): a(0), a(π/2), a(π), a(3π/2)
    a0 = ratio.mean(axis=1)
    a1 = (ratio[:, 0] - ratio[:, 2]) / 2
    b1 = (ratio[:, 1] - ratio[:, 3]) / 2
    a2 = (ratio[:, 0] - ratio[:, 1] + ratio[:, 2] - ratio[:, 3]) / 4
    f = a0[:, None] + a1[:, None] * _COS + b1[:, None] * _SIN + a2[:, None] * _COS2
    out = np.stack(fines) * f
    # the axis values are the targets exactly (removes rounding of the products)
    out[:, [0, q, 2 * q, 3 * q]] = targets
    return out, f


@lru_cache(maxsize=16)
def _image_contour(path: str, mtime_ns: int, size: int) -> Contour:
    return Contour.from_image(path)


def load_image_contour(path: str) -> Contour:
    """The outline of the grain in image ``path`` (cached by path, modification time and size).

    Parameters
    ----------
    path : str
        A grain image (PNG, TIFF, JPEG ...).

    Returns
    -------
    Contour
        The largest grain's outline (:meth:`grainforge.outline.contours.Contour.from_image`), pixels.

    Raises
    ------
    ParameterError
        Naming ``images`` when the file does not exist or holds no grain outline.
    """
    p = Path(path)
    if not p.is_file():
        raise ParameterError("images", f"{path}: no such image file")
    st = p.stat()
    return _image_contour(str(p.resolve()), st.st_mtime_ns, st.st_size)


def input_contours(p: Params, rng: np.random.Generator) -> tuple[Contour, Contour, Contour]:
    """The three contours (xy, xz, yz) a grain is built from, drawn in that order from ``rng``."""
    if p.contour == "given":
        return p.sections
    if p.contour == "image":
        return tuple(load_image_contour(x) for x in p.images.split(","))
    if p.contour == "spectrum":
        table = read_spectra(p.spectrum)
        D = extend_spectrum(table.D[table.draw(rng)], p.decay[1], p.modes)
        return tuple(Contour.from_spectrum(D, rng=rng) for _ in range(3))
    if p.contour == "fractal":
        try:
            return tuple(
                Contour.from_fractal(
                    fractal_dimension=p.fractal_dimension, length_ratio=p.length_ratio,
                    amplitude=p.fractal_amplitude, modes=p.modes, rng=rng,
                )
                for _ in range(3)
            )
        except ParameterError as exc:  # Contour names its own argument `amplitude`
            raise ParameterError("fractal_amplitude" if exc.name == "amplitude" else exc.name, exc.reason) from None
    sets = (p.descriptors, p.descriptors_xz or p.descriptors, p.descriptors_yz or p.descriptors)
    out = []
    for name, d in zip(("descriptors", "descriptors_xz", "descriptors_yz"), sets):
        try:
            out.append(Contour.from_descriptors(d, decay=p.decay, modes=p.modes, rng=rng))
        except ParameterError as exc:
            raise ParameterError(name, exc.reason) from None
    return tuple(out)


def _stretch_consistency(fines, p: Params):
    """2016 reconstruction: each aligned contour stretched linearly to least-squares X:Y:Z diameters."""
    h, q = GRID // 2, GRID // 4
    # diameters through the origin along each contour's first and second axis
    ext = np.array([[f[0] + f[h], f[q] + f[3 * q]] for f in fines])
    if p.aspect is not None:
        logs = np.log(np.asarray(p.aspect, dtype=np.float64))
    else:
        # least-squares X:Y:Z consistent with the three contours' own axis-diameter ratios
        a, b, c = np.log(ext[:, 0] / ext[:, 1])
        logs = np.array([a + b, c - a, -b - c]) / 3.0
    dims = 2.0 * np.exp(logs - logs.mean())  # geometric mean 2: equal-volume diameter about 2
    X, Y, Z = dims
    stretched = [_stretch(f, u / e[0], v / e[1]) for f, e, (u, v) in zip(fines, ext, ((X, Y), (X, Z), (Y, Z)))]
    return stretched, dims


#: the planes' (first, second) axes among x, y, z
_PLANE_AXES = ((0, 1), (0, 2), (1, 2))


#: passes of :func:`_own_centre`
CENTRE_PASSES = 4


def _own_centre(fine: np.ndarray, spec: np.ndarray) -> np.ndarray:
    """The contour re-described about its own area centroid, with its descriptors kept.

    Descriptors are measured about a contour's area centroid (docs/design/algorithms.md
    §2b), which is not the origin a Fourier contour is synthesised about; the
    shift alone lowers D3 and D8 by ~10 % for D2 = 0.3.  So the radii are
    re-cast from the area centroid (``contours.polygon_contour``), every mode
    n ≥ 2 gets back its amplitude |c_n| (keeping the new phase; mode 2 is
    kept real, on the first axis) and c_0 its value; mode 1 is left free.
    A few passes make the area centroid the origin to ~1e-4 r0.  A contour
    that stops being star-shaped about its centroid (extreme descriptors) is
    left as synthesised.
    """
    from ..outline.contours import polygon_contour

    target = np.abs(spec)
    n = len(spec)
    for _ in range(CENTRE_PASSES):
        try:
            c = polygon_contour(np.column_stack([fine * _COS, fine * _SIN]), n_angles=GRID)
        except ValueError:
            break
        if not c.star_shaped:
            break
        cur = np.fft.rfft(c.radii * c.scale) / GRID
        mag = np.abs(cur[2:n])
        cur[2:n] = np.where(mag > 0, cur[2:n] * (target[2:] / np.where(mag > 0, mag, 1.0)), target[2:])
        cur[2] = spec[2]
        cur[0] = spec[0]
        cur[n:] = 0.0
        new = np.fft.irfft(cur * GRID, GRID)
        if new.min() <= 0:
            break
        fine = new
    return fine


def _spectral_consistency(inputs, p: Params):
    """Contours that share one L:I:S while keeping every Fourier mode but 0 and 2.

    Each contour's spectrum c_n (radii over their mean) is turned so that its
    mode 2 is real and positive (elongation along the first axis; a rotation,
    so every |c_n| is kept).  The three elongations give log-ratios
    ℓ = ln((1 + D2)/(1 − D2)) of x/y, x/z, y/z; their least-squares
    consistent values (ℓ_xz = ℓ_xy + ℓ_yz) are scaled by the factor t that
    keeps the mean D2 of the three contours (least squares alone shrinks it
    by ~10 %), unless an ``aspect`` fixes them.  Each contour then gets mode 2
    = tanh(ℓ'/2) and the mean radius that gives it the diameters of the
    consistent X:Y:Z along its two axes (to first order in the other modes).
    Modes ≥ 3 — D3, D8 and the roughness — are the contour's own: nothing
    is stretched, so no angle is remapped (a linear stretch frequency-modulates
    mode n by ~n·ℓ/4 rad, which took ~15 % off D8).
    """
    n_keep = p.modes
    specs = []
    for c in inputs:
        r = np.asarray(c.radii, dtype=np.float64)
        spec = np.fft.rfft(r) / len(r)
        spec = spec[: min(n_keep, (len(r) - 1) // 2) + 1] / spec[0].real
        if len(spec) > 2 and abs(spec[2]) > 0:
            phi0 = -np.angle(spec[2]) / 2.0  # r'(θ) = r(θ + φ0) has c'_n = c_n e^{i n φ0}
            spec = spec * np.exp(1j * np.arange(len(spec)) * phi0)
        specs.append(spec)
    d2 = np.array([2.0 * abs(sp[2]) if len(sp) > 2 else 0.0 for sp in specs])
    if p.aspect is not None:
        logs = np.log(np.asarray(p.aspect, dtype=np.float64))
    else:
        a, b, c = np.log((1.0 + d2) / (1.0 - d2))
        logs = np.array([a + b, c - a, -b - c]) / 3.0
        pair = np.array([logs[i] - logs[j] for i, j in _PLANE_AXES])
        target = d2.mean()
        if target > 0 and np.abs(pair).max() > 0:
            lo, hi = 0.0, 1.0
            while np.mean(np.abs(np.tanh(hi * pair / 2.0))) < target and hi < 64:
                hi *= 2.0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if np.mean(np.abs(np.tanh(mid * pair / 2.0))) < target else (lo, mid)
            logs = logs * 0.5 * (lo + hi)
    logs = logs - logs.mean()
    dims = 2.0 * np.exp(logs)  # diameters, geometric mean 2
    out = []
    for sp, (i, j) in zip(specs, _PLANE_AXES):
        e = np.tanh((logs[i] - logs[j]) / 2.0)
        r0 = (dims[i] + dims[j]) / 4.0
        full = np.zeros(GRID // 2 + 1, dtype=np.complex128)
        full[: len(sp)] = sp
        full[0] = 1.0
        full[1] = 0.0 if len(sp) < 2 else sp[1]
        if len(sp) > 2:
            full[2] = e / 2.0
        fine = np.fft.irfft(full * (GRID * r0), GRID)
        if fine.min() > 0:
            fine = _own_centre(fine, full * r0)
        out.append(fine)
    if min(float(f.min()) for f in out) <= 0:
        raise ParameterError(VALIDITY_PARAMETER, "give a contour with non-positive radii after the L:I:S step")
    return out, dims


def construct(p: Params, rng: RNGLike = None) -> Construction:
    """Contours, alignment, stretching and correction of one CRI grain.

    Parameters
    ----------
    p : Params
        The grain's parameters.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The contours'
        draws first (xy, xz, yz), then the ridge twist's.

    Returns
    -------
    Construction

    Examples
    --------
    >>> c = construct(Params(preset="rough-angular"), rng=0)
    >>> [round(float(c.sections[i][0]), 9) == round(float(c.sections[j][0]), 9) for i, j in [(0, 1)]]
    [True]
    """
    rng = as_generator(rng)
    inputs = input_contours(p, rng)
    if p.consistency == "spectral":
        prepared, dims = _spectral_consistency(inputs, p)
    else:
        prepared, dims = _stretch_consistency([_aligned(_fine(c.radii, p.modes)) for c in inputs], p)
    keep = min(p.modes, mesh_modes(p.subdivisions))
    sections, factors = _correct(_best_orientation(list(_band_limit(np.stack(prepared), keep))))
    twist = None
    if p.ridge_twist > 0:
        twist = np.tan(np.deg2rad(p.ridge_twist) * rng.uniform(-1.0, 1.0, size=(3, keep + 1)))
    con = Construction(tuple(inputs), sections, factors, p.morph_exponent, tuple(float(d) for d in dims),
                       twist=twist)
    if p.aspect is not None:
        unit, _, geom = _sphere(ASPECT_REFERENCE_SUBDIVISIONS)
        ext = np.ptp(con.points(unit, geom), axis=0)
        want = np.asarray(p.aspect, dtype=np.float64)
        want = want / want.max()  # a ratio: scale-free (tiny values such as 5e-324 would underflow)
        k = want / ext
        k /= np.exp(np.log(k).mean())
        con = dataclasses.replace(con, axis_scale=tuple(float(x) for x in k))
    return con


def _field_roughness(con: Construction, unit: np.ndarray, geom: _Geometry, subdivisions: int,
                     rng: np.random.Generator) -> np.ndarray:
    """r = r_form (1 + f): the contours' form with an isotropic random-field roughness instead of the swept one.

    r_form is the same construction from the contours' modes 0–2 only (the
    form: elongation and the L:I:S, no roughness); f is an isotropic random
    field (:mod:`grainforge.methods.rf`, fixed amplitudes, degrees 3…32)
    whose central sections carry on average the three contours' mean
    D3…D32 (D0…D2 set to 0: the form carries those).  Nothing is swept, so
    the roughness has no ridges; the principal sections carry the contours'
    descriptors on average over grains, no longer exactly.
    """
    from . import rf

    L = FIELD_DEGREE
    spec = np.abs(np.fft.rfft(np.stack(con.sections), axis=1))[:, : L + 1]
    D = (2.0 * spec / spec[:, :1]).mean(axis=0)
    D[:3] = 0.0
    C = rf.angular_spectrum(D, "fixed")
    C[:3] = 0.0
    f = rf.field(rf.coefficients(C, rng, "fixed"), L, subdivisions)
    form = dataclasses.replace(con, sections=tuple(_band_limit(np.stack(con.sections), 2)), twist=None,
                               axis_scale=(1.0, 1.0, 1.0))
    return form.radius(unit, geom) * (1.0 + f)


def build(p: Params, rng: RNGLike):
    """Vertices, faces and info of one CRI grain (not yet centred).

    Parameters
    ----------
    p : Params
        The grain's parameters (validated).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  As
        :func:`construct`, then the roughness field's.

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
    con = construct(p, rng)
    unit, faces, geom = _sphere(p.subdivisions)
    if p.roughness == "field":
        R = _field_roughness(con, unit, geom, p.subdivisions, rng)
    else:
        R = con.radius(unit, geom)
    if not np.isfinite(R).all() or R.min() <= 0:
        raise ParameterError(validity_parameter(p), "gives a surface with non-positive radii")
    vertices = unit * R[:, None]
    if con.axis_scale != (1.0, 1.0, 1.0):
        vertices *= np.asarray(con.axis_scale)
    info: dict[str, float] = {}
    D_in = [c.descriptors(8) for c in con.inputs]
    D_sec = descriptors_of_radii(con.sections, 8)
    for k, plane in enumerate(PLANES):
        for n in MEASURED:
            info[f"contour_{plane}_D{n}"] = float(D_in[k][n])
    for k, plane in enumerate(PLANES):
        for n in MEASURED:
            info[f"section_{plane}_D{n}"] = float(D_sec[k][n])
    info["correction"] = float(np.abs(con.factors - 1.0).max())
    info["modes_used"] = min(p.modes, mesh_modes(p.subdivisions))
    info["target_aspect"] = tuple(round(d / con.dims[2], 6) for d in con.dims)
    info["axis_scale"] = con.axis_scale
    info["min_radius"] = float(R.min())
    info["max_radius"] = float(R.max())
    return vertices, np.array(faces), info


def cri(
    *,
    descriptors: Sequence[float] | None = None,
    preset: str | None = None,
    descriptors_xz: Sequence[float] | None = None,
    descriptors_yz: Sequence[float] | None = None,
    decay: Sequence[float] = DEFAULT_DECAY,
    modes: int = 64,
    contour: str | None = None,
    fractal_dimension: float = 2.4,
    length_ratio: float = 2.0,
    fractal_amplitude: float = 0.06,
    images: str | Sequence[str | Path] | None = None,
    spectrum: str | Path | None = None,
    contours: Sequence[Contour] | None = None,
    aspect: Sequence[float] | None = None,
    morph_exponent: float = 2.0,
    ridge_twist: float = 30.0,
    consistency: str = "spectral",
    subdivisions: int = 5,
    roughness: str = "swept",
    rng: RNGLike = None,
):
    """Generate one grain by Contour Rotation Interpolation (paper §2.2).

    Parameters
    ----------
    descriptors : (D2, D3, D8), optional
        Fourier descriptors of all three contours (default: the
        ``rough-angular`` preset 0.15, 0.10, 0.03).
    preset : {"rough-sphere", "rough-angular"}, optional
        Named descriptors from the paper: (0, 0, 0.02) and (0.15, 0.10, 0.03).
    descriptors_xz, descriptors_yz : (D2, D3, D8), optional
        Separate descriptors for the xz and yz contours (anisotropy).
    decay : (β1, β2)
        Regression exponents for the other modes (default −5/3, −5/3).
    modes : int
        Highest Fourier mode N (default 64).
    contour : {"fourier", "fractal", "image", "given"}, optional
        Contour source (default: fourier; image with ``images``; given with ``contours``).
    fractal_dimension, length_ratio, fractal_amplitude : float
        Fractal-profile contours (2D variant of Eq. 1): D in [2, 3), L/R0, RMS of (r − r0)/r0.
    images : str or sequence of three paths, optional
        Grain images for the xy, xz and yz contours.
    spectrum : str or Path, optional
        A CSV written by ``grainforge fourier``: each grain draws one
        measured grain's D2…D16 (continued above 16 with ``decay[1]``) for
        its three contours.
    contours : sequence of three Contour, optional
        Contours for the xy, xz and yz planes.
    aspect : (L, I, S), optional
        Target ratio of the principal dimensions (L ≥ I ≥ S).
    morph_exponent : float
        p in the morphing weight sin^p θ (default 2).
    ridge_twist : float
        Largest turn (degrees, 0–60, default 30) of each roughness mode of a
        contour away from the direction the interpolation sweeps it in, as it
        leaves its plane; 0 gives the 2016 reconstruction's parallel ridges.
        The principal sections are unaffected.
    consistency : {"spectral", "stretch"}
        How the contours are given one L:I:S: ``spectral`` (default) sets
        each contour's mode 2 and mean radius and keeps every other mode;
        ``stretch`` stretches each contour linearly (the earlier
        reconstruction, which lowers D8 by about 15 %).
    subdivisions : int
        Icosphere level 0–8 (default 5: 10,242 vertices).
    roughness : {"swept", "field"}
        ``swept`` (default): the method's roughness, swept from the contours.
        ``field``: the contours' form (modes 0–2) with an isotropic
        random-field roughness of the contours' mean spectrum: no ridges; the
        principal sections carry the descriptors on average, not exactly.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seed or generator (:mod:`grainforge.rng`).  An int, a plain SeedSequence's entropy, or the seed
        drawn for None is recorded as ``Grain.seed``; a Generator leaves it None.

    Returns
    -------
    Grain
        Centred on its volume centroid, mean contour radius about 1.

    Raises
    ------
    ValueError
        For an out-of-range or conflicting parameter (named), unreadable
        images, or descriptors so large that a contour radius reaches 5 % of
        its mean or less.

    References
    ----------
    Hanaor et al., *3D printable geomaterials*, Géotechnique (2016), §2.2;
    Mollon & Zhao, Granular Matter 14 (2012) 621–638.

    Examples
    --------
    >>> import grainforge
    >>> g = grainforge.cri(preset="rough-angular", subdivisions=3, rng=0)
    >>> len(g.vertices), bool(g.mesh.is_watertight)
    (642, True)
    >>> grainforge.cri(descriptors=(0.15, 0.1))
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: descriptors must be 3 comma-separated numbers, got (0.15, 0.1)
    """
    from . import generate

    if images is not None and not isinstance(images, str):
        images = ",".join(str(x) for x in images)
    p = Params(
        contour=contour, preset=preset,
        descriptors=None if descriptors is None else tuple(descriptors),
        descriptors_xz=None if descriptors_xz is None else tuple(descriptors_xz),
        descriptors_yz=None if descriptors_yz is None else tuple(descriptors_yz),
        decay=tuple(decay), modes=modes, fractal_dimension=fractal_dimension, length_ratio=length_ratio,
        fractal_amplitude=fractal_amplitude, images=images,
        spectrum=None if spectrum is None else str(spectrum), aspect=None if aspect is None else tuple(aspect),
        morph_exponent=morph_exponent, ridge_twist=ridge_twist, consistency=consistency, subdivisions=subdivisions,
        roughness=roughness, sections=None if contours is None else tuple(contours),
    )
    return generate(NAME, p, rng)
