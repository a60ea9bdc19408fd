"""The drained triaxial test in a periodic cell: its scene settings, the angles measured from its curve, its
table and figure (pure NumPy apart from the figure; no engine needed).

The source paper's bulk test is a conventional drained triaxial compression at an effective confining stress of
20 kPa, plotted as the stress ratio q/p′ and the volumetric strain against the axial strain.  The scene
(:data:`grainforge.simulate.yade_scenes.TRIAXIAL`) compacts the grains isotropically to the confining stress in a
periodic cell, then shortens the cell in z at a constant engineering strain rate while servo-controlling x and
y at the confining stress, and records the curve.  This module turns that record into the test's figures.

Conventions (every quantity here, in ``triaxial.csv`` and in ``results.csv``):

- stresses are effective (dry grains) and **compression positive**; σ₁ = σ_z is the axial stress,
  σ₃ = (σ_x + σ_y)/2 the lateral one;
- q = σ_z − (σ_x + σ_y)/2, p′ = (σ_x + σ_y + σ_z)/3;
- axial strain ε₁ = 1 − L_z/L_z0 and volumetric strain ε_v = 1 − V/V₀ (engineering strains from the start of
  the shearing), **compression positive**: a dilating specimen has a falling, then negative ε_v;
- friction angle from M = q/p′ in triaxial compression: sin φ = 3M/(6 + M);
- dilatancy angle from the rate d = dε_v/dε₁: sin ψ = −d/(2 − d), positive when the specimen dilates;
- void ratio e = (V − V_s)/V_s with V_s the grains' exact mesh volumes (not their clumps').
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from .settings import COMPACTION_INERTIAL_NUMBER, TriaxialSettings

__all__ = ["CSV_COLUMNS", "triaxial_scene_settings", "friction_angle", "dilatancy_angle", "local_slope",
           "TriaxialAngles", "triaxial_angles", "curve_table", "measure_triaxial", "write_triaxial_csv",
           "triaxial_figure", "summarise_triaxial", "COMPACTION_INERTIAL_NUMBER"]

#: the columns of each seed's ``triaxial.csv``
CSV_COLUMNS = ("axial_strain", "q_kpa", "p_kpa", "q_over_p", "volumetric_strain", "void_ratio", "coordination")
#: records of the curve over the shearing
RECORDS = 200


def triaxial_scene_settings(settings: TriaxialSettings, seed: int) -> dict:
    """The ``grains.json["scene"]`` dictionary the triaxial scene reads (no gravity; stresses in kPa).

    Parameters
    ----------
    settings : TriaxialSettings
        The run's settings (Young's modulus in Pa, confining stress in kPa, friction coefficient written as
        ``friction_deg`` in degrees).
    seed : int
        The run's seed number (``settings.seed + k``), written as ``seed`` (the Yade scene's own random seed) and
        the seed of the grains' orientations (:func:`grainforge.dem.deck.grain_orientations`).

    Returns
    -------
    dict
        The scene's settings: ``test`` (``"triaxial"``), ``seed``, ``grains``, the contact model's, ``gravity``
        (0), ``confining_kpa`` (kPa), the servo's and the compaction's controls, ``records`` and
        ``orientations`` (one unit quaternion ``(w, x, y, z)`` per grain).

    Examples
    --------
    >>> s = triaxial_scene_settings(TriaxialSettings(), 3)
    >>> s["test"], s["seed"], s["gravity"], s["confining_kpa"], s["packing"], len(s["orientations"])
    ('triaxial', 3, 0.0, 20.0, 'dense', 200)
    """
    from ..dem.deck import grain_orientations, orientation_rows

    return {
        "test": "triaxial", "seed": int(seed), "grains": settings.grains, "young": settings.young,
        "poisson": settings.poisson, "friction_deg": math.degrees(math.atan(settings.friction)),
        "damping": settings.damping, "gravity": 0.0, "dt_safety": 0.3,
        "confining_kpa": settings.confining_kpa, "axial_strain": settings.axial_strain, "packing": settings.packing,
        "inertial_number": settings.inertial_number, "compaction_inertial_number": COMPACTION_INERTIAL_NUMBER,
        # the servo, every 10 steps: the rate that would close the error in 10 steps at the affine modulus, plus
        # its integral at 0.3; the lateral strain rate at most 10 times the axial one
        "control_every": 10, "servo_gain": 1.0, "servo_integral": 0.3, "lateral_rate_factor": 10.0,
        # the compaction's servo: proportional only, 0.3 of that rate, still within half the tolerance of the goal;
        # Yade's local damping 0.7 while compacting (the set damping while shearing): a frictionless packing of
        # 1,000 rough spheres came to rest (mean net force under 1 %) in 21,150 steps, where at 0.3 it still had
        # 3 % after 69,330 (the time limit); the static state does not depend on damping, the void ratio reached
        # does a little (0.593 against 0.551, the latter not at rest); frictionless single spheres and 10-sphere
        # clumps of the rough angular grains still stop at 1.5-3 % (docs/simulate.md)
        "compaction_servo_gain": 0.3, "compaction_damping": 0.7,
        # the isotropic state: every normal stress within 1 % of the goal and the mean net force on a grain under
        # 1 % of the mean contact force, at three checks in a row; given up after 3/rate_c of simulated time
        # (the quick runs came to rest in about 0.9/rate_c)
        "stress_tolerance": 0.01, "unbalanced": 0.01, "compaction_time_factor": 3.0,
        "records": RECORDS,
        # written only when set, so that a deck without rolling resistance is as before
        **({"rolling_friction": settings.rolling_friction} if settings.rolling_friction > 0 else {}),
        # grain k of the scene is placed in orientation k (w, x, y, z): uniformly random, drawn here
        "orientations": orientation_rows(grain_orientations(settings.grains, seed)),
    }


def friction_angle(m):
    """Mobilised friction angle (degrees) of a stress ratio M = q/p′ in triaxial compression: sin φ = 3M/(6 + M).

    Parameters
    ----------
    m : float or array_like
        The stress ratio q/p′.

    Returns
    -------
    float64 ndarray
        φ in degrees, the shape of ``m`` (a 0-d array for a number).

    Examples
    --------
    >>> round(float(friction_angle(1.2)), 4)  # M = 6 sin φ / (3 − sin φ): φ = 30° gives M = 1.2
    30.0
    >>> float(friction_angle(0.0))
    0.0
    """
    m = np.asarray(m, dtype=np.float64)
    return np.degrees(np.arcsin(np.clip(3.0 * m / (6.0 + m), -1.0, 1.0)))


def dilatancy_angle(rate):
    """Dilatancy angle (degrees) from d = dε_v/dε₁ (ε_v, ε₁ compression positive): sin ψ = −d/(2 − d).

    Positive when the specimen dilates (ε_v falls as ε₁ grows), negative when it contracts; −90° from d = 1 on
    (a specimen collapsing so fast that its sides move inwards too: −d/(2 − d) leaves [−1, 1] there and, past
    d = 2, changes sign).

    Parameters
    ----------
    rate : float or array_like
        dε_v/dε₁.

    Returns
    -------
    float64 ndarray
        ψ in degrees, the shape of ``rate`` (a 0-d array for a number).

    Examples
    --------
    >>> float(dilatancy_angle(0.0)) == 0.0
    True
    >>> round(float(dilatancy_angle(-0.5)), 4)  # sin ψ = 0.5/2.5
    11.537
    >>> dilatancy_angle([1.0, 2.0, 2.5, np.nan]).tolist()  # a collapse is no dilation
    [-90.0, -90.0, -90.0, nan]
    """
    d = np.asarray(rate, dtype=np.float64)
    sin = -d / (2.0 - np.minimum(d, 1.0))  # from d = 1 on: −d ≤ −1, clipped to −90°; NaN stays NaN
    return np.degrees(np.arcsin(np.clip(sin, -1.0, 1.0))) + 0.0  # + 0.0: no -0.0


def local_slope(x, y, window: int):
    """Least-squares slope of y(x) over a centred window of ``window`` points at every point (shortened at the
    ends, never under 2 points), vectorised with cumulative sums.

    Parameters
    ----------
    x, y : (N,) array_like
        The curve's points.
    window : int
        Points of the centred window (an even count takes one more).

    Returns
    -------
    (N,) float64 ndarray
        dy/dx at each point; NaN where the window's x do not vary, all NaN under 2 points.

    Examples
    --------
    >>> x = np.linspace(0, 1, 11)
    >>> np.allclose(local_slope(x, 3 * x ** 2, 3)[1:-1], 6 * x[1:-1])
    True
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    n = len(x)
    if n < 2:
        return np.full(n, np.nan)
    half = max(1, int(window) // 2)
    i = np.arange(n)
    lo, hi = np.clip(i - half, 0, n - 1), np.clip(i + half, 0, n - 1) + 1
    c = lambda a: np.concatenate([[0.0], np.cumsum(a)])  # noqa: E731
    sx, sy, sxx, sxy = c(x), c(y), c(x * x), c(x * y)
    k = (hi - lo).astype(np.float64)
    mx, my = (sx[hi] - sx[lo]) / k, (sy[hi] - sy[lo]) / k
    vxx = (sxx[hi] - sxx[lo]) / k - mx * mx
    vxy = (sxy[hi] - sxy[lo]) / k - mx * my
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(vxx > 0, vxy / vxx, np.nan)


class TriaxialAngles(dict):
    """The angles of one triaxial curve (:func:`triaxial_angles`): a dict with attribute access."""

    __getattr__ = dict.__getitem__


def triaxial_angles(axial_strain, q_over_p, volumetric_strain, *, window: int = 5,
                    last: float = 0.05, slope_strain: float = 0.01) -> TriaxialAngles:
    """Peak and ultimate friction angles and the largest dilatancy angle of a triaxial curve.

    Parameters
    ----------
    axial_strain, q_over_p, volumetric_strain : (N,) array_like
        The curve, strains compression positive (ε_v falls when the specimen dilates), in increasing strain.
    window : int
        Points of the centred moving window: the stress ratio is averaged over it before its peak is taken (a
        single noisy record does not make the peak).
    last : float
        The ultimate state is the mean stress ratio over the last ``last`` fraction of the axial strain range
        (ε₁ ≥ (1 − last)·ε₁,end).
    slope_strain : float
        dε_v/dε₁ is the least-squares slope over a centred window of this much axial strain (and at least
        ``window`` records): over a few closely spaced records the noise of ε_v makes any slope, and a slope
        of −∞ is a dilatancy angle of 90°.

    Returns
    -------
    TriaxialAngles
        ``peak_friction_deg`` (and ``peak_strain``, where it is reached), ``ultimate_friction_deg``
        (``ultimate_q_over_p``), ``max_dilatancy_deg`` (and ``max_dilatancy_strain``), ``peak_q_over_p``.

    Raises
    ------
    ValueError
        If the three curves are not 1-D arrays of one length.

    Examples
    --------
    >>> e = np.linspace(0, 0.2, 201)
    >>> a = triaxial_angles(e, np.full_like(e, 1.2), -0.5 * e)  # M = 1.2 throughout; dε_v/dε₁ = −0.5
    >>> round(a.peak_friction_deg, 3), round(a.ultimate_friction_deg, 3), round(a.max_dilatancy_deg, 3)
    (30.0, 30.0, 11.537)
    """
    e = np.asarray(axial_strain, dtype=np.float64)
    m = np.asarray(q_over_p, dtype=np.float64)
    v = np.asarray(volumetric_strain, dtype=np.float64)
    if not (e.ndim == m.ndim == v.ndim == 1 and len(e) == len(m) == len(v)):
        raise InputError("axial_strain, q_over_p and volumetric_strain must be 1-D arrays of one length")
    ok = np.isfinite(e) & np.isfinite(m) & np.isfinite(v)
    e, m, v = e[ok], m[ok], v[ok]
    nan = float("nan")
    if len(e) < 3 or not e[-1] > e[0]:
        return TriaxialAngles(peak_friction_deg=nan, peak_q_over_p=nan, peak_strain=nan, ultimate_friction_deg=nan,
                              ultimate_q_over_p=nan, max_dilatancy_deg=nan, max_dilatancy_strain=nan)
    w = max(1, min(int(window), len(e)))
    kernel = np.ones(w) / w
    # a centred moving mean, shortened at the ends (divided by the points it holds)
    smooth = np.convolve(m, kernel, mode="same") / np.convolve(np.ones_like(m), kernel, mode="same")
    k = int(np.argmax(smooth))
    tail = e >= e[-1] - last * (e[-1] - e[0])
    ultimate = float(m[tail].mean())
    spacing = float(np.median(np.diff(e)))
    w_slope = max(w, min(len(e), int(round(slope_strain / spacing)) + 1 if spacing > 0 else w))
    psi = dilatancy_angle(local_slope(e, v, w_slope))
    j = int(np.nanargmax(psi)) if np.isfinite(psi).any() else 0
    return TriaxialAngles(peak_friction_deg=float(friction_angle(smooth[k])), peak_q_over_p=float(smooth[k]),
                          peak_strain=float(e[k]), ultimate_friction_deg=float(friction_angle(ultimate)),
                          ultimate_q_over_p=ultimate, max_dilatancy_deg=float(psi[j]) if np.isfinite(psi[j]) else nan,
                          max_dilatancy_strain=float(e[j]))


#: the end of a curve is a critical state when, over its last :data:`CRITICAL_WINDOW` fraction of axial strain,
#: the volume is steady (\|dε_v/dε₁\| at most :data:`CRITICAL_DILATANCY_RATE`, a dilatancy angle within about
#: ±1.5°) and so is the stress ratio (its least-squares trend changes q/p′ by at most
#: :data:`CRITICAL_STRESS_CHANGE` of its mean across the window)
CRITICAL_WINDOW = 0.2
CRITICAL_DILATANCY_RATE = 0.05
CRITICAL_STRESS_CHANGE = 0.05


def critical_state(axial_strain, q_over_p, volumetric_strain, void_ratio, *,
                   window: float = CRITICAL_WINDOW) -> dict:
    """Whether a triaxial curve ends at a critical state, and the void ratio there.

    Fits straight lines to ε_v(ε₁) and q/p′(ε₁) over the last ``window`` fraction of the axial strain range: the
    end is a critical state when both are steady (:data:`CRITICAL_DILATANCY_RATE`,
    :data:`CRITICAL_STRESS_CHANGE`). The critical void ratio e_cs is the mean void ratio over the last 5 % of the
    range (the window of the ultimate friction angle, :func:`triaxial_angles`), whether or not the end is steady:
    the flag says whether to read it as one.

    Parameters
    ----------
    axial_strain, q_over_p, volumetric_strain, void_ratio : (N,) array_like
        The curve, strains compression positive, in increasing strain.
    window : float
        The fraction of the axial strain range, at its end, that must be steady (0 < window ≤ 1).

    Returns
    -------
    dict
        ``critical_void_ratio`` (e_cs), ``final_dilatancy_rate`` (dε_v/dε₁ over the window, negative while the
        specimen dilates), ``final_stress_ratio_change`` (the fitted change of q/p′ across the window over its
        mean) and ``critical_state`` (bool); NaN and False for a curve of under 3 points.

    Raises
    ------
    InputError
        If ``window`` is not in (0, 1].

    Examples
    --------
    >>> e = np.linspace(0, 0.3, 301)
    >>> steady = critical_state(e, np.full_like(e, 1.2), -0.1 * np.minimum(e, 0.15), 0.7 + np.minimum(e, 0.15))
    >>> round(steady["critical_void_ratio"], 3), steady["critical_state"]
    (0.85, True)
    >>> critical_state(e, np.full_like(e, 1.2), -0.5 * e, 0.7 + e)["critical_state"]  # still dilating
    False
    """
    if not 0.0 < window <= 1.0:
        raise InputError(f"window must be in (0, 1], not {window}")
    e, m, v, void = (np.asarray(a, dtype=np.float64) for a in (axial_strain, q_over_p, volumetric_strain,
                                                             void_ratio))
    ok = np.isfinite(e) & np.isfinite(m) & np.isfinite(v) & np.isfinite(void)
    e, m, v, void = e[ok], m[ok], v[ok], void[ok]
    nan = float("nan")
    if len(e) < 3 or not e[-1] > e[0]:
        return {"critical_void_ratio": nan, "final_dilatancy_rate": nan, "final_stress_ratio_change": nan,
                "critical_state": False}
    span = e[-1] - e[0]
    tail = e >= e[-1] - window * span
    if tail.sum() < 3:
        tail[-3:] = True
    rate = float(np.polyfit(e[tail], v[tail], 1)[0])
    slope = float(np.polyfit(e[tail], m[tail], 1)[0])
    change = slope * (e[tail][-1] - e[tail][0]) / abs(float(m[tail].mean()))
    e_cs = float(void[e >= e[-1] - 0.05 * span].mean())
    steady = abs(rate) <= CRITICAL_DILATANCY_RATE and abs(change) <= CRITICAL_STRESS_CHANGE
    return {"critical_void_ratio": e_cs, "final_dilatancy_rate": rate, "final_stress_ratio_change": float(change),
            "critical_state": bool(steady)}


def curve_table(result: dict) -> np.ndarray:
    """The curve of a triaxial ``result.json`` as the (N, 7) array of :data:`CSV_COLUMNS` (stresses in kPa).

    Parameters
    ----------
    result : dict
        A triaxial run's ``result.json`` (stresses in Pa).

    Returns
    -------
    (N, 7) float64 ndarray
        One row per record, in the columns of :data:`CSV_COLUMNS`.
    """
    cols = result["columns"]
    rec = np.asarray(result["records"], dtype=np.float64).reshape(-1, len(cols))
    col = {name: rec[:, k] for k, name in enumerate(cols)}
    return np.column_stack([col["axial_strain"], 1e-3 * col["q"], 1e-3 * col["p"], col["q_over_p"],
                            col["volumetric_strain"], col["void_ratio"], col["coordination"]])


def measure_triaxial(result: dict) -> dict:
    """The row of ``results.csv`` of one finished triaxial run (its ``result.json``).

    The angles (:func:`triaxial_angles`), the void ratios reached, the strain rate and inertial number, how
    closely the servo held the lateral stress during the shearing (``lateral_stress_error_median`` and
    ``_max``: the median and largest |σ₃/σ′₃ − 1| over the records after the first 1 % of the axial strain
    range), the largest mean contact overlap over the grains' mean diameter (``overlap_over_d_max``), and
    ``problems``: why the run fails its own check (empty when it passes): a specimen not at rest at the confining
    stress when the shearing started, no curve, or a lateral stress off by more than 5 % in the median. Whether
    the compaction itself came to rest (a frictionless dense one of clumps may not) is ``compaction_at_rest``,
    the state sheared ``at_rest_before_shearing``.

    Parameters
    ----------
    result : dict
        A finished triaxial run's ``result.json``.

    Returns
    -------
    dict
        The row: ``test``, ``grains``, the angles in degrees (``peak_friction_deg``, ``ultimate_friction_deg``,
        ``max_dilatancy_deg``, ...), the void ratios, the rates, the servo's errors, ``overlap_over_d_max`` and
        ``problems``.
    """
    cols = result["columns"]
    rec = np.asarray(result["records"], dtype=np.float64).reshape(-1, len(cols))
    col = {name: rec[:, k] for k, name in enumerate(cols)}
    e = col["axial_strain"]
    angles = triaxial_angles(e, col["q_over_p"], col["volumetric_strain"])
    goal = float(result["confining"])
    lateral = 0.5 * (col["sigma_x"] + col["sigma_y"]) / goal - 1.0
    after = e > e[0] + 0.01 * (e[-1] - e[0]) if len(e) else np.zeros(0, dtype=bool)
    lateral_max = float(np.abs(lateral[after]).max()) if after.any() else float("nan")
    lateral_median = float(np.median(np.abs(lateral[after]))) if after.any() else float("nan")
    problems = []
    # a dense specimen is compacted without friction, which packings of clumps may never finish (they creep at a
    # net force of a few per cent: isostatic, no friction to hold them); what is sheared is the state after the
    # friction is back on, which must be at rest at the confining stress. Both flags are kept in the row.
    settled = bool(result.get("settled", result["compacted"]))
    if not settled:
        problems.append("the specimen was not at rest at the confining stress when the shearing started")
    if not np.isfinite(angles.peak_friction_deg):
        problems.append("no stress ratio recorded")
    if not (math.isfinite(lateral_median) and lateral_median <= 0.05):
        problems.append(f"the lateral stress strayed {100 * lateral_median:.0f} % (median) from the confining "
                        "stress")
    cs = critical_state(e, col["q_over_p"], col["volumetric_strain"], col["void_ratio"])
    e0 = float(result["void_ratio_initial"])
    # the same specimen's void ratio counted against its clumps' volume (the spheres' union, which covers less of
    # an angular grain than the mesh and spills a little past it) instead of the meshes'
    # (a run without the two volumes, e.g. recorded before they were: the meshes' void ratio for both)
    solid = result.get("solid_volume", 1.0)
    to_clumps = float(solid) / float(result.get("solid_volume_clumps", solid))
    row = {"test": "triaxial", "grains": result["grains"], "inserted": result["inserted"], "lost": result["lost"],
           "packing": result["packing"], "compaction_at_rest": bool(result["compacted"]),
           "at_rest_before_shearing": settled, "void_ratio_compacted": result["void_ratio_compacted"],
           "initial_void_ratio": e0, "initial_void_ratio_clumps": (1.0 + e0) * to_clumps - 1.0,
           "final_void_ratio": float(col["void_ratio"][-1]) if len(e) else float("nan"),
           "critical_void_ratio": cs["critical_void_ratio"],
           "critical_void_ratio_clumps": (1.0 + cs["critical_void_ratio"]) * to_clumps - 1.0,
           "state_parameter": e0 - cs["critical_void_ratio"], "critical_state": cs["critical_state"],
           "final_dilatancy_rate": cs["final_dilatancy_rate"],
           "final_stress_ratio_change": cs["final_stress_ratio_change"],
           "peak_friction_deg": angles.peak_friction_deg, "peak_q_over_p": angles.peak_q_over_p,
           "peak_axial_strain": angles.peak_strain, "ultimate_friction_deg": angles.ultimate_friction_deg,
           "ultimate_q_over_p": angles.ultimate_q_over_p, "max_dilatancy_deg": angles.max_dilatancy_deg,
           "max_dilatancy_axial_strain": angles.max_dilatancy_strain,
           "axial_strain_reached": float(e[-1]) if len(e) else float("nan"),
           "strain_rate_per_s": result["strain_rate"], "inertial_number": result["inertial_number"],
           "confining_kpa": 1e-3 * goal, "lateral_stress_error_median": lateral_median,
           "lateral_stress_error_max": lateral_max,
           "overlap_over_d_max": float(np.nanmax(col["overlap_over_d"])) if len(e) else float("nan"),
           "d_mean_mm": 1e3 * result["d_mean"], "grain_density": result["grain_density"],
           "steps": result["steps"], "dt_s": result["dt"], "simulated_time_s": result["time"],
           "problems": "; ".join(problems)}
    return row


def summarise_triaxial(rows: Sequence[dict]) -> str:
    """The one line of a finished triaxial run: packing, void ratio and angles, mean ± sd over the seeds.

    Parameters
    ----------
    rows : sequence of dict
        The seeds' rows (:func:`measure_triaxial`; angles in degrees).

    Returns
    -------
    str
        The line.

    Examples
    --------
    >>> rows = [{"packing": "dense", "initial_void_ratio": 0.55, "peak_friction_deg": 40.0,
    ...          "ultimate_friction_deg": 30.0, "max_dilatancy_deg": 12.0, "inertial_number": 1e-3},
    ...         {"packing": "dense", "initial_void_ratio": 0.57, "peak_friction_deg": 42.0,
    ...          "ultimate_friction_deg": 31.0, "max_dilatancy_deg": 14.0, "inertial_number": 1e-3}]
    >>> summarise_triaxial(rows)
    'dense, e0 0.560 ± 0.014: peak friction angle 41.0° ± 1.4°, ultimate 30.5° ± 0.7°, largest dilatancy angle 13.0° ± 1.4° (sd over 2 seeds; I = 0.001)'
    >>> rows = [{**r, "critical_void_ratio": 0.7, "critical_state": r is rows[0]} for r in rows]
    >>> summarise_triaxial(rows).split("; ", 2)[-1]
    'e at the end 0.700 ± 0.000, a critical state (steady volume and stress ratio) in 1 of 2'
    """

    def stat(key, fmt, unit=""):
        a = np.array([r[key] for r in rows], dtype=np.float64)
        a = a[np.isfinite(a)]
        if len(a) == 0:
            return "not measured"
        text = f"{a.mean():{fmt}}{unit}"
        return text + (f" ± {a.std(ddof=1):{fmt}}{unit}" if len(a) > 1 else "")

    seeds = f"sd over {len(rows)} seeds" if len(rows) > 1 else "one seed"
    inertial = max(float(r["inertial_number"]) for r in rows)
    line = (f"{rows[0]['packing']}, e0 {stat('initial_void_ratio', '.3f')}: peak friction angle "
            f"{stat('peak_friction_deg', '.1f', '°')}, ultimate {stat('ultimate_friction_deg', '.1f', '°')}, "
            f"largest dilatancy angle {stat('max_dilatancy_deg', '.1f', '°')} ({seeds}; I = {inertial:.2g})")
    if all("critical_state" in r for r in rows):
        steady = sum(bool(r["critical_state"]) for r in rows)
        line += (f"; e at the end {stat('critical_void_ratio', '.3f')}, a critical state (steady volume and stress "
                 f"ratio) in {steady} of {len(rows)}")
    return line


def write_triaxial_csv(result: dict, path: str | Path) -> Path:
    """Write one seed's ``triaxial.csv`` (:data:`CSV_COLUMNS`, stresses in kPa, strains compression positive).

    Parameters
    ----------
    result : dict
        The run's ``result.json``.
    path : path
        The CSV file to write.

    Returns
    -------
    Path
        The file written.
    """
    from ..io import write_csv

    table = curve_table(result)
    return write_csv(path, [dict(zip(CSV_COLUMNS, map(float, row))) for row in table])


def triaxial_figure(results: Sequence[dict], rows: Sequence[dict]):
    """The paper's triaxial figure: (a) q/p′ and (b) volumetric strain against axial strain, one curve per seed.

    Parameters
    ----------
    results : sequence of dict
        Each seed's ``result.json``.
    rows : sequence of dict
        Each seed's row (:func:`measure_triaxial`), for the legend's angles (degrees).

    Returns
    -------
    matplotlib.figure.Figure
        The figure (two panels, axial strain shared).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(6.5, 7.5), dpi=120, sharex=True)
    for k, (res, row) in enumerate(zip(results, rows)):
        t = curve_table(res)
        label = (f"seed {row['seed']}, {row['packing']}, e₀ = {row['initial_void_ratio']:.3f}: "
                 f"φ_peak {row['peak_friction_deg']:.1f}°, φ_ult {row['ultimate_friction_deg']:.1f}°")
        ax0.plot(100 * t[:, 0], t[:, 3], "-", color=f"C{k}", lw=1.2, label=label)
        ax1.plot(100 * t[:, 0], 100 * t[:, 4], "-", color=f"C{k}", lw=1.2)
    ax0.set_ylabel("stress ratio q/p′")
    ax0.set_title(f"(a) drained triaxial compression, σ′₃ = {rows[0]['confining_kpa']:g} kPa", fontsize=10)
    ax0.legend(loc="lower right", fontsize=7)
    ax0.set_ylim(bottom=0.0)
    ax1.set_xlabel("axial strain ε₁ (%)")
    ax1.set_ylabel("volumetric strain ε_v (%), compression positive")
    ax1.axhline(0.0, color="0.5", lw=0.8)
    ax1.set_title("(b) volumetric strain", fontsize=10)
    fig.tight_layout()
    return fig
