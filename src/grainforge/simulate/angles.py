"""Angles measured from a finished virtual test (pure NumPy, no engine needed).

The heap of a repose test is measured as a person with a protractor would, but
in every direction: the top surface of the grains (the highest sphere top in
each ring of width ``bin_width`` around the heap's axis, per azimuthal
sector) is fitted with one straight line on the slope between 20 % and 80 % of
the heap's height; the angle of repose is the arctangent of its slope.  The
sectors are also fitted one by one: their spread says how round the heap is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["HeapAngle", "heap_angle", "tilt_failure_angle", "tilt_curve", "TILT_FAILURE"]

#: the tilt test's failure threshold: a mean downslope displacement of half a grain diameter
TILT_FAILURE = 0.5


@dataclass(frozen=True)
class HeapAngle:
    """The measured angle of a heap.

    Attributes
    ----------
    angle : float
        Degrees: the slope of one line fitted to every sector's surface points on the slope.
    spread : float
        Standard deviation of the sectors' own angles, degrees (how round the heap is).
    sectors : (S,) float64
        Angle per azimuthal sector, degrees (NaN where a sector had too few points).
    foot : float
        Foot radius of the heap (where the surface reaches the base), same unit as the input.
    height : float
        Height of the heap's top above the base.
    profile : (B, 2) float64
        Ring radius and mean surface height over sectors, for plotting.
    fit : tuple of float
        Intercept and slope of the line fitted to all sectors' points (height = a + b r).
    fitted : tuple of float
        Innermost and outermost ring radius of the fitted slope.
    """

    angle: float
    spread: float
    sectors: np.ndarray
    foot: float
    height: float
    profile: np.ndarray
    fit: tuple
    fitted: tuple


def heap_angle(spheres: np.ndarray, *, bin_width: float, grain_size: float, sectors: int = 8,
               band: tuple[float, float] = (0.2, 0.8), base: float = 0.0) -> HeapAngle:
    """Angle of repose of a heap of spheres standing on ``z = base`` around its own vertical axis.

    The heap's top surface is the highest sphere top in each ring of width
    ``bin_width`` around the axis (through the heap's centroid), per azimuthal
    sector.  The slope is fitted on the rings outside the crest whose mean
    surface height lies in ``band`` (fractions of the heap height, and never
    below one grain): the flat top a lifted cylinder leaves and the toe of
    single grains are left out.

    Parameters
    ----------
    spheres : (N, 4) float64
        x, y, z, r of every sphere of the heap (any further columns are ignored).
    bin_width : float
        Width of the radial rings (about half a grain diameter).
    grain_size : float
        Mean grain diameter.  The foot of the heap is where its surface falls
        to one grain above the base.
    sectors : int
        Number of azimuthal sectors measured separately (≥ 1).
    band : (float, float)
        Lower and upper surface heights of the fitted slope, as fractions of the
        heap's height (0 ≤ low < high ≤ 1).
    base : float
        Height of the base the heap stands on.

    Returns
    -------
    HeapAngle

    Raises
    ------
    ValueError
        If there are no spheres or the heap is too small to fit.

    Examples
    --------
    A cone of 30° made of small spheres:

    >>> rng = np.random.default_rng(0)
    >>> r = np.sqrt(rng.random(20000)) * 10.0
    >>> a = rng.random(20000) * 2 * np.pi
    >>> z = (10.0 - r) * np.tan(np.radians(30.0)) * rng.random(20000) ** 0.05
    >>> pts = np.column_stack([r * np.cos(a), r * np.sin(a), z, np.full(20000, 0.01)])
    >>> round(heap_angle(pts, bin_width=0.5, grain_size=0.02).angle)
    30
    """
    s = np.asarray(spheres, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] < 4 or len(s) == 0:
        raise InputError("spheres must be an (N, 4) array of x, y, z, r with N ≥ 1")
    lo_f, hi_f = band
    if not (bin_width > 0 and grain_size > 0 and sectors >= 1 and 0 <= lo_f < hi_f <= 1):
        raise InputError("need bin_width > 0, grain_size > 0, sectors ≥ 1 and 0 ≤ band[0] < band[1] ≤ 1")
    xy = s[:, :2] - np.average(s[:, :2], axis=0, weights=s[:, 3] ** 3)
    rad = np.hypot(xy[:, 0], xy[:, 1])
    top = s[:, 2] + s[:, 3] - base
    sector = np.minimum((np.arctan2(xy[:, 1], xy[:, 0]) + np.pi) / (2 * np.pi) * sectors, sectors - 1).astype(np.int64)
    ring = (rad // bin_width).astype(np.int64)
    nr = int(ring.max()) + 1
    surface = np.full((sectors, nr), -np.inf)
    np.maximum.at(surface, (sector, ring), top)
    surface[~np.isfinite(surface)] = np.nan
    centres = (np.arange(nr) + 0.5) * bin_width
    filled = np.isfinite(surface).any(axis=0)
    mean_profile = np.full(nr, np.nan)
    mean_profile[filled] = np.nanmean(surface[:, filled], axis=0)
    height = float(np.nanmax(mean_profile))
    crest = int(np.nanargmax(mean_profile))
    lo, hi = max(grain_size, lo_f * height), hi_f * height
    if not hi > lo:
        raise InputError("the heap is too flat or too small to measure an angle (lower than two grains)")
    # the slope: from the first ring past the crest below hi, outwards while the surface stays above lo
    outside = np.arange(nr) > crest
    start = np.nonzero(outside & (mean_profile <= hi))[0]
    if len(start) == 0:
        raise InputError("the heap is too flat or too small to measure an angle (no slope)")
    i1 = int(start[0])
    below = np.nonzero((np.arange(nr) >= i1) & ~(mean_profile >= lo))[0]
    i2 = int(below[0]) if len(below) else nr
    sel = np.zeros(nr, dtype=bool)
    sel[i1:i2] = True
    if sel.sum() < 2:
        raise InputError("the heap is too flat or too small to measure an angle (fewer than two rings "
                         "of width bin_width on the slope)")
    feet = np.nonzero(outside & ~(mean_profile > grain_size))[0]
    foot = float(centres[feet[0]] - 0.5 * bin_width) if len(feet) else float(centres[-1] + 0.5 * bin_width)
    per_sector = np.full(sectors, np.nan)
    for k in range(sectors):
        ok = sel & np.isfinite(surface[k])
        if ok.sum() >= 2:
            slope = np.polyfit(centres[ok], surface[k, ok], 1)[0]
            per_sector[k] = np.degrees(np.arctan(-slope))
    ok_all = sel[None, :] & np.isfinite(surface)
    rr = np.broadcast_to(centres, surface.shape)[ok_all]
    b, a = np.polyfit(rr, surface[ok_all], 1)
    if not b < 0:  # the fitted surface does not fall outwards: a pile of a few grains, no slope to speak of
        raise InputError("the heap is too flat or too small to measure an angle (its surface does not fall "
                         "outwards)")
    if -b * (centres[i2 - 1] - centres[i1]) < 0.25 * (hi - lo):
        # the rings chosen stand on a shelf of the heap: the line falls by less than a quarter of the band it was
        # meant to span (a heap of two grain layers measured a "slope" of 0.3 degrees this way, falling by 1 % of
        # it; a default heap of 200 grains whose slope has three rings in the band falls by 48 % of it)
        raise InputError("the heap is too flat or too small to measure an angle (the fitted rings are a shelf, "
                         "not a slope)")
    prof = np.column_stack([centres, mean_profile])
    return HeapAngle(angle=float(np.degrees(np.arctan(-b))), spread=float(np.nanstd(per_sector)),
                     sectors=per_sector, foot=foot, height=height, profile=prof[np.isfinite(prof[:, 1])],
                     fit=(float(a), float(b)), fitted=(float(centres[i1]), float(centres[i2 - 1])))


def _tilt_record(history) -> np.ndarray:
    """A tilt record as a (T, 2+) float64 array, or ``ValueError``."""
    h = np.asarray(history, dtype=np.float64)
    if h.ndim != 2 or h.shape[1] < 2:
        raise InputError("history must be a (T, 2) array of angle, displacement")
    return h


def tilt_failure_angle(history: np.ndarray, *, displacement: float = 0.5) -> float:
    """The tilt angle at which the layer's mean downslope displacement first exceeds ``displacement``.

    Parameters
    ----------
    history : (T, 2+) float64
        Tilt angle (degrees) and mean downslope displacement (in grain
        diameters) after each tilt increment.
    displacement : float
        Failure threshold in grain diameters.

    Returns
    -------
    float
        Degrees, interpolated linearly (displacement linear in the tilt angle)
        between the two increments that bracket the threshold; NaN if the layer
        never failed, or if it had already failed at the first angle (start the
        tilt lower).  :func:`tilt_curve` draws the record with the same
        interpolation.

    Raises
    ------
    ValueError
        If ``history`` is not a (T, 2+) array.

    Examples
    --------
    >>> h = np.array([[20, 0.0], [21, 0.01], [22, 0.1], [23, 0.9]])
    >>> round(tilt_failure_angle(h), 2)
    22.5
    """
    h = _tilt_record(history)
    over = np.nonzero(h[:, 1] > displacement)[0]
    if len(over) == 0:
        return float("nan")
    k = int(over[0])
    if k == 0:
        return float("nan")
    a0, d0 = h[k - 1, :2]
    a1, d1 = h[k, :2]
    return float(a0 + (a1 - a0) * (displacement - d0) / (d1 - d0))


def tilt_curve(history: np.ndarray, *, displacement: float = 0.5, samples: int = 16):
    """The line ``tilt.png`` draws of a tilt record: the interpolation :func:`tilt_failure_angle` reads its angle
    from, sampled.

    Between two increments the displacement is linear in the tilt angle (a curve on a log axis, so it is drawn
    as ``samples`` short segments per increment), and the point where it first exceeds ``displacement`` — the
    failure angle — is one of the line's vertices: the line crosses the threshold exactly at the reported angle.

    Parameters
    ----------
    history : (T, 2+) float64
        Tilt angle (degrees) and mean downslope displacement (grain diameters) after each increment.
    displacement : float
        Failure threshold in grain diameters.
    samples : int
        Segments drawn per increment (≥ 1).

    Returns
    -------
    angles, displacements : (M,) float64
        The line's vertices, in increasing tilt.
    increments : (T,) int64
        The indices of the record's own increments among the vertices (where markers go).

    Raises
    ------
    ValueError
        If ``history`` is not a (T, 2+) array.

    Examples
    --------
    >>> h = np.array([[20, 0.0], [21, 0.01], [22, 0.1], [23, 0.9]])
    >>> a, d, marks = tilt_curve(h, samples=2)
    >>> a.tolist()
    [20.0, 20.5, 21.0, 21.5, 22.0, 22.5, 22.5, 23.0]
    >>> d[marks].tolist() == h[:, 1].tolist(), float(d[a == tilt_failure_angle(h)][0])
    (True, 0.5)
    """
    h = _tilt_record(history)
    a0, d0 = h[:-1, 0], h[:-1, 1]
    t = np.arange(max(1, int(samples))) / max(1, int(samples))
    angles = np.append((a0[:, None] + t * (h[1:, 0] - a0)[:, None]).ravel(), h[-1:, 0])
    disp = np.append((d0[:, None] + t * (h[1:, 1] - d0)[:, None]).ravel(), h[-1:, 1])
    increments = np.arange(len(h)) * len(t)
    failure = tilt_failure_angle(h, displacement=displacement)
    if np.isfinite(failure):  # the crossing, a vertex of its own: after every vertex at or below its angle
        at = int(np.searchsorted(angles, failure, side="right"))
        angles, disp = np.insert(angles, at, failure), np.insert(disp, at, displacement)
        increments = increments + (increments >= at)
    return angles, disp, increments
