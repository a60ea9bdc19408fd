"""Contact-friction calibration: the μ at which a population reaches a measured bulk angle.

A DEM modeller calibrates the contact parameters on one laboratory test and
predicts the others with them.  :func:`search_friction` finds the contact
friction μ at which a virtual test (tilt table, angle of repose, or the
triaxial test's ultimate or peak friction angle: :func:`calibrated_angle`)
gives a target angle: a bounded search on the seed-averaged angle, which
rises with μ (docs/simulate.md).  It is a pure function of a callable ``angle_of(μ)`` —
the engine runs live in the command (``grainforge simulate calibrate``), the
search logic is tested with stand-in functions.

Notes
-----
The search first brackets the target: from ``start`` it doubles μ (angle
below the target) or halves it (above), clamped to ``[low, high]``; a bound
reached without bracketing the target means the target is out of reach (the
angles reached are in :class:`Unreachable`).  It then narrows the bracket by
the Illinois variant of the secant (false-position) method, which keeps a
bracket and does not stall on one side, until the bracket is narrower than
``friction_tolerance`` or ``max_evaluations`` are spent.  The first evaluated
angle within ``tolerance`` of the target ends the search at once, while
bracketing too.  The estimate is the secant root of the final bracket (linear
interpolation between its two ends), and the slope of that bracket is
reported; an angle within the tolerance before the target was bracketed is
the final bracket on its own (both ends): its friction is the estimate, the
bracket has no slope (NaN).

The seed-averaged angle is noisy: two runs at the same μ with other seeds
differ by the standard error of the mean, ``sd / sqrt(seeds)``.  That error,
divided by the local slope dangle/dμ, is the uncertainty of μ
(:func:`friction_uncertainty`).  The local slope is a least-squares line
through the evaluations near the estimate (:func:`local_slope`), not the
final bracket's secant: two close frictions differ by little more than their
noise.  A tolerance much below the standard error buys runs, not accuracy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["Evaluation", "FrictionSearch", "Unreachable", "search_friction", "calibration_estimate", "friction_uncertainty", "pooled_sd",
           "local_slope", "calibrated_angle", "calibration_seconds", "failed_calibration_runs",
           "run_calibration", "calibration_record", "write_calibration", "calibration_figure",
           "TARGET_RANGE", "FRICTION_RANGE", "TRIAXIAL_ANGLES", "check_target"]

#: target angles (degrees) a calibration accepts: bulk friction angles of granular materials
TARGET_RANGE = (5.0, 80.0)
#: the default bounds of the μ search
FRICTION_RANGE = (0.05, 1.5)
#: the friction angles of a triaxial run a calibration can reach (``--angle``): their columns of results.csv
TRIAXIAL_ANGLES = {"ultimate": "ultimate_friction_deg", "peak": "peak_friction_deg"}
#: the angle each gravity test measures (``angle_deg`` of its rows)
TEST_ANGLES = {"tilt": "tilt failure angle", "repose": "angle of repose"}


@dataclass(frozen=True)
class Evaluation:
    """One evaluated friction: μ and the (seed-averaged) angle in degrees."""

    friction: float
    angle: float


@dataclass(frozen=True)
class FrictionSearch:
    """The result of :func:`search_friction`.

    Attributes
    ----------
    friction : float
        The estimated μ: the secant root of the final bracket.
    slope : float
        dangle/dμ over the final bracket, degrees per unit μ.
    bracket : (Evaluation, Evaluation)
        The final bracket: angles below and above the target (or one at it).
    evaluations : tuple of Evaluation
        Every evaluation, in order.
    converged : bool
        Whether the search stopped on ``tolerance`` or ``friction_tolerance``
        (False: ``max_evaluations`` ran out; the estimate is still the
        bracket's interpolation, with a wider uncertainty).
    """

    friction: float
    slope: float
    bracket: tuple
    evaluations: tuple
    converged: bool


class Unreachable(InputError):
    """The target angle lies outside the angles reached in the μ range (``reached``: lowest, highest angle)."""

    def __init__(self, message: str, reached: tuple[float, float]):
        super().__init__(message)
        self.reached = reached


def check_target(target: float) -> None:
    """Refuse a target angle outside :data:`TARGET_RANGE` (``ValueError``, one line).

    Parameters
    ----------
    target : float
        The target angle, degrees.

    Raises
    ------
    ValueError
        If ``target`` is outside :data:`TARGET_RANGE`.

    Examples
    --------
    >>> check_target(38.0)
    >>> check_target(85.0)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: target angle 85° is outside 5–80°: bulk friction angles of granular materials lie there
    """
    lo, hi = TARGET_RANGE
    if not (math.isfinite(target) and lo <= target <= hi):
        raise InputError(f"target angle {target:g}° is outside {lo:g}–{hi:g}°: bulk friction angles of granular "
                         "materials lie there")


def calibrated_angle(test: str, angle: str | None = None) -> tuple[str, str]:
    """The angle a calibration on ``test`` reaches: the column of the test's rows it is read from, and its name.

    A tilt or repose run's ``angle_deg``; a triaxial run's ultimate friction angle (``angle`` None or
    ``"ultimate"``: from the mean stress ratio over the last 5 % of the axial strain) or its peak one
    (``"peak"``), as ``results.csv`` of ``grainforge simulate triaxial`` has them.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    angle : {"ultimate", "peak"}, optional
        A triaxial test's friction angle; None for the test's one angle (a triaxial test's ultimate).

    Returns
    -------
    column : str
        The column of the rows holding the angle (degrees).
    name : str
        The angle's name, as figures and ``calibration.json`` give it.

    Raises
    ------
    ValueError
        For an unknown test, or an ``angle`` of a test that measures only one.

    Examples
    --------
    >>> calibrated_angle("tilt")
    ('angle_deg', 'tilt failure angle')
    >>> calibrated_angle("triaxial")
    ('ultimate_friction_deg', 'ultimate friction angle')
    >>> calibrated_angle("triaxial", "peak")
    ('peak_friction_deg', 'peak friction angle')
    """
    if test == "triaxial":
        angle = "ultimate" if angle is None else angle
        if angle not in TRIAXIAL_ANGLES:
            raise InputError(f"angle must be one of {', '.join(TRIAXIAL_ANGLES)}, got {angle!r}")
        return TRIAXIAL_ANGLES[angle], f"{angle} friction angle"
    if test not in TEST_ANGLES:
        raise InputError(f"test must be one of {', '.join([*TEST_ANGLES, 'triaxial'])}, got {test!r}")
    if angle is not None:
        raise InputError(f"the {test} test measures one angle: no angle={angle!r}")
    return "angle_deg", TEST_ANGLES[test]


#: frictions a calibration usually tries before one is within the tolerance (the up-front estimate's count; its
#: longest is ``--max-frictions``): the secant search from μ = 0.5 brackets the target in two and lands within
#: 0.5° in one or two more (docs/benchmarks.md, *What the documented commands cost*)
TYPICAL_EVALUATIONS = 4


def calibration_seconds(test: str, settings, *, max_evaluations: int, available: int, make_seconds: float = 0.0,
                        pool: int | None = None, as_spheres: bool = False, workers: int = 1, shape: str = "clump",
                        spacing: float = 0.05, engine: str = "yade", longest: bool = False) -> float:
    """Estimated seconds of a calibration, at most: the templates once, then ``max_evaluations`` frictions of
    every seed (:func:`grainforge.simulate.check_size` of one friction's runs); refuse one beyond the limit.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    settings : Settings or TriaxialSettings
        The runs' settings (one friction's runs: ``settings.seeds`` of them).
    available, make_seconds : int, float
        From :func:`grainforge.simulate.check_inputs`: the grains the inputs hold and the seconds to make one.
    pool : int, optional
        Grains the templates are chosen from (:func:`grainforge.simulate.specimen.template_make_seconds`).
    max_evaluations, as_spheres, workers, shape, spacing, engine, longest
        As the calibration's and :func:`grainforge.simulate.check_size`'s.

    Returns
    -------
    float
        The estimated seconds.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        One friction's runs beyond the limits (:func:`grainforge.simulate.check_size`'s line), or the whole
        calibration beyond the time limit (the line names ``--max-frictions``, ``--grains`` and ``--seeds``).

    Examples
    --------
    >>> from .settings import Settings, check_size
    >>> one = check_size("tilt", Settings(), available=3)
    >>> one < calibration_seconds("tilt", Settings(), max_evaluations=8, available=3) < 8 * one
    True
    """
    from dataclasses import replace

    from ..runtime.estimate import SECONDS_LIMIT, TooLargeError, _limit, duration
    from .settings import check_size
    from .specimen import template_make_seconds

    per_grain = template_make_seconds(settings.templates, available, make_seconds, pool)
    size = dict(available=available, make_seconds=per_grain, as_spheres=as_spheres, workers=workers, shape=shape,
                spacing=spacing, engine=engine, longest=longest)
    one = check_size(test, settings, **size)
    # the templates are made once (the cost of a run of two grains and one seed); every friction runs every seed
    make = check_size(test, replace(settings, seeds=1, grains=2), **size)
    seconds = make + (one - make) * max_evaluations
    if seconds > SECONDS_LIMIT:
        raise TooLargeError(f"a calibration of up to {max_evaluations} frictions × {settings.seeds} seed(s) of "
                            f"{settings.grains} grains would take about {duration(seconds)} of computing (limit "
                            f"{_limit()}); lower --max-frictions, --grains or --seeds")
    return float(seconds)


def calibration_estimate(test: str, settings, *, max_evaluations: int, **cost) -> tuple[float, float]:
    """The seconds a calibration usually takes (:data:`TYPICAL_EVALUATIONS` frictions) and the most it may take
    (``max_evaluations``, a triaxial compaction to its time limit); refuse one whose longest is beyond the limit
    (:func:`calibration_seconds`).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    settings : Settings or TriaxialSettings
        One friction's runs' settings.
    max_evaluations : int
        The most frictions the search may try.
    **cost
        :func:`calibration_seconds`'s other arguments (``available``, ``make_seconds``, ``pool``, ...).

    Returns
    -------
    (float, float)
        The usual and the longest estimate, in seconds.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        As :func:`calibration_seconds`.

    Examples
    --------
    >>> from .settings import Settings
    >>> usual, most = calibration_estimate("tilt", Settings(), max_evaluations=8, available=3)
    >>> usual < most
    True
    """
    most = calibration_seconds(test, settings, max_evaluations=max_evaluations, longest=True, **cost)
    usual = calibration_seconds(test, settings, max_evaluations=min(TYPICAL_EVALUATIONS, max_evaluations), **cost)
    return usual, most


def search_friction(angle_of: Callable[[float], float], target: float, *, low: float = FRICTION_RANGE[0],
                    high: float = FRICTION_RANGE[1], start: float = 0.5, tolerance: float = 0.5,
                    friction_tolerance: float = 0.01, max_evaluations: int = 8,
                    progress: Callable[[Evaluation], None] | None = None) -> FrictionSearch:
    """The contact friction μ in ``[low, high]`` at which ``angle_of(μ)`` equals ``target``.

    Parameters
    ----------
    angle_of : callable
        ``angle_of(μ)`` → angle in degrees (seed-averaged), rising with μ. A NaN
        (no angle measured) stops the search with ``ValueError``.
    target : float
        Degrees.
    low, high : float
        Bounds of μ (0 ≤ low < high).
    start : float
        First μ tried (clamped into the bounds).
    tolerance : float
        Degrees: stop at the first evaluated angle this close to the target (while bracketing too: that
        friction is then the estimate).
    friction_tolerance : float
        Stop when the bracket is narrower than this in μ.
    max_evaluations : int
        At most this many calls of ``angle_of`` (≥ 2).
    progress : callable, optional
        Called with each :class:`Evaluation` as it is made.

    Returns
    -------
    FrictionSearch

    Raises
    ------
    Unreachable
        If the angle at a bound still falls short of (or exceeds) the target.
    ValueError
        For bad bounds, or an angle that could not be measured.

    Examples
    --------
    A stand-in angle that rises with μ as atan does, with a floor of 15°:

    >>> angle = lambda mu: 15.0 + math.degrees(math.atan(mu))
    >>> s = search_friction(angle, 40.0, tolerance=0.05)
    >>> round(s.friction, 2), s.converged, len(s.evaluations) <= 8
    (0.47, True, True)
    """
    if not (0.0 <= low < high and math.isfinite(high)):
        raise InputError(f"need 0 ≤ low < high, got low={low!r}, high={high!r}")
    if int(max_evaluations) < 2:
        raise InputError(f"max_evaluations must be ≥ 2, got {max_evaluations!r}")
    evaluations: list[Evaluation] = []

    def evaluate(mu: float) -> Evaluation:
        a = float(angle_of(mu))
        if not math.isfinite(a):
            raise InputError(f"no angle could be measured at friction {mu:.4g}")
        e = Evaluation(float(mu), a)
        evaluations.append(e)
        if progress is not None:
            progress(e)
        return e

    def done(lo: Evaluation, hi: Evaluation, converged: bool) -> FrictionSearch:
        slope = (hi.angle - lo.angle) / (hi.friction - lo.friction) if hi.friction != lo.friction else float("nan")
        if lo.angle == hi.angle:
            mu = 0.5 * (lo.friction + hi.friction)
        else:
            mu = lo.friction + (target - lo.angle) * (hi.friction - lo.friction) / (hi.angle - lo.angle)
        return FrictionSearch(float(min(max(mu, low), high)), float(slope), (lo, hi), tuple(evaluations), converged)

    # 1. bracket: double (angle too low) or halve (too high) from start, clamped to the bounds
    e = evaluate(min(max(start, low), high))
    below = above = None
    while True:
        if e.angle <= target:
            below = e if below is None or e.friction > below.friction else below
        if e.angle >= target:
            above = e if above is None or e.friction < above.friction else above
        if abs(e.angle - target) <= tolerance:  # the first friction within the tolerance ends the search, bracketed
            # or not (then the friction itself is the estimate: its bracket is the one evaluation)
            return done(e if below is None else below, e if above is None else above, True)
        if below is not None and above is not None:
            break
        if above is None and e.friction >= high or below is None and e.friction <= low:
            reached = (min(x.angle for x in evaluations), max(x.angle for x in evaluations))
            side = "highest" if above is None else "lowest"
            raise Unreachable(f"target angle {target:g}° is not reached for friction in [{low:g}, {high:g}]: the "
                              f"angles measured span {reached[0]:.1f}–{reached[1]:.1f}° (the {side} at friction "
                              f"{e.friction:g})", reached)
        if len(evaluations) >= max_evaluations:
            raise Unreachable(f"target angle {target:g}° not bracketed in {len(evaluations)} evaluations: the "
                              f"angles measured span {min(x.angle for x in evaluations):.1f}–"
                              f"{max(x.angle for x in evaluations):.1f}°",
                              (min(x.angle for x in evaluations), max(x.angle for x in evaluations)))
        e = evaluate(min(2.0 * e.friction, high) if above is None else max(0.5 * e.friction, low))
    # 2. narrow it: Illinois false position on f = angle - target
    fb, fa = below.angle - target, above.angle - target
    side = 0
    while len(evaluations) < max_evaluations:
        if above.friction - below.friction < friction_tolerance:
            return done(below, above, True)
        mu = below.friction - fb * (above.friction - below.friction) / (fa - fb) if fa != fb else \
            0.5 * (below.friction + above.friction)
        e = evaluate(mu)
        if abs(e.angle - target) <= tolerance:
            return done(e, above, True) if e.angle <= target else done(below, e, True)
        if e.angle < target:
            below, fb = e, e.angle - target
            fa = 0.5 * fa if side == -1 else above.angle - target
            side = -1
        else:
            above, fa = e, e.angle - target
            fb = 0.5 * fb if side == 1 else below.angle - target
            side = 1
    return done(below, above, False)


def friction_uncertainty(slope: float, angle_sd: float, seeds: int) -> float:
    """Standard uncertainty of the calibrated μ from the seed spread: ``(sd / sqrt(seeds)) / slope``.

    Parameters
    ----------
    slope : float
        dangle/dμ near the estimate, degrees per unit μ.
    angle_sd : float
        Standard deviation of one run's angle over seeds, degrees.
    seeds : int
        Seeds averaged at each μ.

    Returns
    -------
    float
        The standard uncertainty of μ (inf for a slope that is not positive; NaN for no slope, one friction
        tried).

    Examples
    --------
    >>> round(friction_uncertainty(20.0, 1.5, 3), 3)
    0.043
    >>> friction_uncertainty(0.0, 1.5, 3)
    inf
    >>> friction_uncertainty(float("nan"), 1.5, 3)
    nan
    """
    if math.isnan(slope):
        return float("nan")
    if not (math.isfinite(slope) and slope > 0):
        return float("inf")
    return float(angle_sd / math.sqrt(max(1, int(seeds))) / slope)


def local_slope(evaluations: Sequence[Evaluation], friction: float, *, window: float = 0.5) -> float:
    """dangle/dμ near ``friction``: the least-squares line through the evaluations within ``window`` of it.

    With fewer than three evaluations in the window, all of them are used.
    The seed-averaged angles are noisy: the secant of the final bracket —
    two close frictions — can be dominated by their noise, a line through
    the nearby evaluations much less.

    Parameters
    ----------
    evaluations : sequence of Evaluation
        The search's evaluations (μ and seed-averaged angle in degrees).
    friction : float
        The μ the slope is taken at.
    window : float
        Half-width of the window in μ.

    Returns
    -------
    float
        The slope, degrees per unit μ (NaN with fewer than two distinct μ).

    Examples
    --------
    >>> ev = [Evaluation(0.5, 30.0), Evaluation(1.0, 35.0), Evaluation(1.1, 35.4), Evaluation(1.5, 39.0)]
    >>> round(local_slope(ev, 1.05), 2)
    8.29
    """
    import numpy as np

    mu = np.array([e.friction for e in evaluations], dtype=np.float64)
    a = np.array([e.angle for e in evaluations], dtype=np.float64)
    near = np.abs(mu - friction) <= window
    if near.sum() >= 3:
        mu, a = mu[near], a[near]
    if len(mu) < 2 or np.ptp(mu) == 0:
        return float("nan")
    return float(np.polyfit(mu, a, 1)[0])


def pooled_sd(groups: Sequence[Sequence[float]]) -> float:
    """Pooled standard deviation of several groups of angles (NaN if no group has two values).

    Parameters
    ----------
    groups : sequence of sequence of float
        The angles (degrees) of each evaluation's seeds.

    Returns
    -------
    float
        The pooled standard deviation, degrees.

    Examples
    --------
    >>> round(pooled_sd([[30.0, 32.0], [40.0, 41.0, 42.0]]), 3)
    1.155
    """
    import numpy as np

    num = den = 0.0
    for g in groups:
        a = np.asarray([x for x in g if math.isfinite(x)], dtype=np.float64)
        if len(a) > 1:
            num += float(((a - a.mean()) ** 2).sum())
            den += len(a) - 1
    return math.sqrt(num / den) if den else float("nan")


def run_calibration(test: str, templates: Sequence, *, settings, target: float, out, low: float = FRICTION_RANGE[0],
                    high: float = FRICTION_RANGE[1], start: float = 0.5, tolerance: float = 0.5,
                    max_evaluations: int = 8, workers: int = 1, label: str = "",
                    progress: Callable[[int, int, float, str], None] | None = None,
                    evaluated: Callable[[Evaluation, list], None] | None = None, engine: str = "yade",
                    mpi: int | None = None, executor=None, journal=None,
                    angle: str | None = None) -> tuple[FrictionSearch, list]:
    """Calibrate μ on ``test`` with the engine: :func:`search_friction` over seed-averaged engine runs.

    Each evaluation runs ``settings.seeds`` seeds at friction μ into
    ``out/runs/e<k>-mu<μ>/`` (:func:`grainforge.simulate.run_test`; a triaxial run's folder also gets its
    ``triaxial.csv``, as ``simulate triaxial`` writes it).  The angle averaged over the seeds is
    :func:`calibrated_angle`'s, copied into each row's ``angle_deg``.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    templates : sequence of GrainTemplate
        The specimen's grains (:func:`grainforge.simulate.build_population`).
    settings : Settings or TriaxialSettings
        The runs' settings; its ``friction`` is replaced by each μ tried.
    target : float
        The angle to reach, degrees (:func:`check_target`).
    out : path
        The folder of the runs (``out/runs/``).
    low, high, start, tolerance, max_evaluations
        As :func:`search_friction` (μ's bounds and first value; the tolerance in degrees).
    workers : int
        Engine runs at once (as :func:`grainforge.simulate.run_test`).
    label : str
        Name of the population in the rows.
    progress : callable, optional
        ``progress(evaluation index, run index, fraction, phase)`` while a run goes on.
    evaluated : callable, optional
        ``evaluated(evaluation, rows)`` after each evaluation (its rows: one per seed).
    engine, mpi : str, int or None
        The engine of the runs and its MPI ranks (as :func:`grainforge.simulate.run_test`).
    executor, journal : optional
        A Dask executor for the runs and the journal of finished (friction, seed) runs
        (as :func:`grainforge.simulate.run_test`).
    angle : {"ultimate", "peak"}, optional
        A triaxial test's friction angle to reach (default ultimate; :func:`calibrated_angle`).

    Returns
    -------
    (FrictionSearch, list of dict)
        The search and every run's row (with ``friction`` and ``evaluation``).

    Raises
    ------
    Unreachable
        With the attribute ``rows`` (the runs made), if the target is out of reach.
    """
    from dataclasses import replace
    from pathlib import Path

    from .engine import run_test, summarise

    column, _ = calibrated_angle(test, angle)
    rows: list[dict] = []

    def angle_of(mu: float) -> float:
        k = len({r["evaluation"] for r in rows})
        report = None if progress is None else (lambda i, f, p: progress(k, i, f, p))
        s = replace(settings, friction=float(mu))
        folder = Path(out) / "runs" / f"e{k}-mu{mu:.4f}"
        got = run_test(test, templates, settings=s, out=folder, label=label, progress=report,
                       workers=workers, engine=engine, mpi=mpi, executor=executor, journal=journal)
        if test == "triaxial":  # each run's curve beside its result.json, as simulate triaxial writes it
            _write_curves(folder, got)
        got = [{"evaluation": k, "friction": float(mu), **r, "angle_deg": float(r[column])} for r in got]
        rows.extend(got)
        mean = summarise(got)["angle_mean_deg"]
        if evaluated is not None:
            evaluated(Evaluation(float(mu), mean), got)
        return mean

    try:
        search = search_friction(angle_of, target, low=low, high=high, start=start, tolerance=tolerance,
                                 max_evaluations=max_evaluations)
    except Unreachable as exc:
        exc.rows = rows
        raise
    return search, rows


def _write_curves(folder, rows: Sequence[dict]) -> None:
    """Each triaxial run's ``triaxial.csv`` in its folder ``folder/triaxial-seed<k>/``."""
    import json
    from pathlib import Path

    from .triaxial import write_triaxial_csv

    for r in rows:
        run = Path(folder) / f"triaxial-seed{r['seed']}"
        write_triaxial_csv(json.loads((run / "result.json").read_text()), run / "triaxial.csv")


#: the columns of calibration.csv: every test's, and a triaxial test's own
CALIBRATION_COLUMNS = ("evaluation", "friction", "seed", "angle_deg", "label", "grains", "inserted", "lost", "steps",
                       "dt_s", "simulated_time_s", "note")
TRIAXIAL_CALIBRATION_COLUMNS = ("peak_friction_deg", "ultimate_friction_deg", "max_dilatancy_deg", "packing",
                                "initial_void_ratio", "problems")


def failed_calibration_runs(rows: Sequence[dict]) -> list[str]:
    """The runs of a calibration that fail their own check (a triaxial run's ``problems``), one line each.

    Parameters
    ----------
    rows : sequence of dict
        The calibration's rows (with ``friction``, ``seed`` and, for a triaxial run, ``problems``).

    Returns
    -------
    list of str
        ``friction <μ>, seed <k>: <problems>`` for each failing run.

    Examples
    --------
    >>> failed_calibration_runs([{"friction": 0.5, "seed": 0, "problems": ""},
    ...                          {"friction": 0.25, "seed": 1, "problems": "no stress ratio recorded"}])
    ['friction 0.25, seed 1: no stress ratio recorded']
    >>> failed_calibration_runs([{"friction": 0.5, "seed": 0, "angle_deg": 30.0}])
    []
    """
    return [f"friction {float(r['friction']):.4g}, seed {r['seed']}: {r['problems']}" for r in rows
            if r.get("problems")]


def calibration_record(search: FrictionSearch, rows: Sequence[dict], *, target: float, test: str, settings,
                       command: str, low: float, high: float, angle: str | None = None) -> dict:
    """The ``calibration.json`` record: μ, its uncertainty from the seed spread and the local slope, the runs
    (``angle``: the angle reached, its name and column, :func:`calibrated_angle`; ``failed_runs``:
    :func:`failed_calibration_runs`).

    Parameters
    ----------
    search : FrictionSearch
        The finished search (:func:`run_calibration`).
    rows : sequence of dict
        Every run's row, with ``friction``, ``evaluation`` and ``angle_deg`` (degrees).
    target : float
        The target angle, degrees.
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    settings : Settings or TriaxialSettings
        The runs' settings (SI units; a triaxial test's stresses in kPa), recorded without ``friction``.
    command : str
        The command line that reproduces the calibrated runs.
    low, high : float
        The bounds of μ searched.
    angle : {"ultimate", "peak"}, optional
        A triaxial test's friction angle (:func:`calibrated_angle`).

    Returns
    -------
    dict
        ``friction`` and ``friction_sd``, ``friction_angle_deg`` (atan μ, degrees), the slopes (degrees per unit
        μ), ``angle_sd_deg``, the bracket, the runs' counts, ``settings``, ``command`` and ``failed_runs``.
    """
    from ..params import as_dict

    by_eval: dict[int, list[float]] = {}
    for r in rows:
        by_eval.setdefault(int(r["evaluation"]), []).append(float(r["angle_deg"]))
    sd = pooled_sd(list(by_eval.values()))
    slope = local_slope(search.evaluations, search.friction)
    mu_sd = friction_uncertainty(slope, sd, settings.seeds) if math.isfinite(sd) else float("nan")
    lo, hi = search.bracket
    column, name = calibrated_angle(test, angle)
    return {
        "test": test, "angle": name, "angle_column": column, "target_angle_deg": target, "friction": search.friction,
        "friction_sd": mu_sd, "friction_angle_deg": math.degrees(math.atan(search.friction)),
        "slope_deg_per_unit_friction": slope, "bracket_slope_deg_per_unit_friction": search.slope,
        "angle_sd_deg": sd, "seeds": settings.seeds,
        "evaluations": len(search.evaluations), "runs": len(rows), "converged": search.converged,
        "bracket": [[lo.friction, lo.angle], [hi.friction, hi.angle]], "friction_range": [low, high],
        "uncertainty": "friction_sd = (angle_sd / sqrt(seeds)) / slope: the standard error of a seed-averaged "
                       "angle (angle_sd pooled over the evaluations) over the local slope (a least-squares line "
                       "through the evaluations within 0.5 of the friction)",
        "settings": {k: v for k, v in as_dict(settings).items() if k != "friction"}, "command": command,
        "failed_runs": failed_calibration_runs(rows),
    }


def calibration_figure(search: FrictionSearch, rows: Sequence[dict], *, target: float, test: str, mu_sd: float,
                       angle: str | None = None, caption: str | None = None):
    """Angle against μ: every run, each evaluation's mean, the target, the estimate with its uncertainty.

    Parameters
    ----------
    search : FrictionSearch
        The finished search.
    rows : sequence of dict
        Every run's row (``friction``, ``angle_deg`` in degrees).
    target : float
        The target angle, degrees.
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    mu_sd : float
        The uncertainty of μ (:func:`friction_uncertainty`; a band when finite).
    angle : {"ultimate", "peak"}, optional
        A triaxial test's friction angle (:func:`calibrated_angle`), named on the y axis.
    caption : str, optional
        The line above the plot (:func:`grainforge.simulate.results.figure_caption`: engine, population, rate).

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(6.5, 4.2), dpi=120)
    mu = np.array([float(r["friction"]) for r in rows])
    a = np.array([float(r["angle_deg"]) for r in rows])
    ax.plot(mu, a, "o", color="0.5", ms=4, alpha=0.7, label="runs (one per seed)")
    ev = sorted(search.evaluations, key=lambda e: e.friction)
    ax.plot([e.friction for e in ev], [e.angle for e in ev], "s-", color="C0", ms=6, label="seed average")
    ax.axhline(target, color="C3", ls="--", lw=1, label=f"target {target:g}°")
    spread = f" ± {mu_sd:.3f}" if math.isfinite(mu_sd) else ""
    ax.axvline(search.friction, color="C2", lw=1.5, label=f"μ = {search.friction:.3f}{spread}")
    if math.isfinite(mu_sd):
        ax.axvspan(search.friction - mu_sd, search.friction + mu_sd, color="C2", alpha=0.15)
    ax.set_xlabel("contact friction μ")
    ax.set_ylabel(calibrated_angle(test, angle)[1] + " (°)")
    ax.set_title(f"calibration on the {test} test: {len(search.evaluations)} frictions, {len(rows)} runs")
    ax.legend(fontsize=8, loc="lower right")
    from .results import add_caption

    add_caption(fig, caption)
    return fig


def write_calibration(search: FrictionSearch, rows: Sequence[dict], *, target: float, test: str, settings,
                      command: str, out, low: float, high: float, angle: str | None = None,
                      caption: str | None = None) -> dict:
    """Write ``calibration.csv`` (every run; a triaxial run's angles too), ``calibration.json`` and
    ``calibration.png`` into ``out``; the record (:func:`calibration_record`).

    Parameters
    ----------
    search : FrictionSearch
        The finished search.
    rows : sequence of dict
        Every run's row.
    target : float
        The target angle, degrees.
    test : {"repose", "tilt", "triaxial"}
        The test calibrated on.
    settings : Settings or TriaxialSettings
        The runs' settings.
    command : str
        The command line that reproduces the calibrated runs.
    out : path
        The folder the three files are written into.
    low, high : float
        The bounds of μ searched.
    angle : {"ultimate", "peak"}, optional
        A triaxial test's friction angle (:func:`calibrated_angle`).
    caption : str, optional
        The figure's line naming the engine, the population and the rate
        (:func:`grainforge.simulate.results.figure_caption`), also the PNG's ``Description``.

    Returns
    -------
    dict
        The record written to ``calibration.json`` (:func:`calibration_record`).
    """
    import json
    from pathlib import Path

    from ..io import save_figure, write_csv

    out = Path(out)
    record = calibration_record(search, rows, target=target, test=test, settings=settings, command=command, low=low,
                                high=high, angle=angle)
    keep = CALIBRATION_COLUMNS[:4] + TRIAXIAL_CALIBRATION_COLUMNS + CALIBRATION_COLUMNS[4:-1] if test == "triaxial" \
        else CALIBRATION_COLUMNS
    write_csv(out / "calibration.csv", [{k: r.get(k, "") for k in keep} for r in rows])
    (out / "calibration.json").write_text(json.dumps(record, indent=1) + "\n")
    save_figure(calibration_figure(search, rows, target=target, test=test, mu_sd=record["friction_sd"], angle=angle,
                                   caption=caption), out / "calibration.png", description=caption)
    return record
