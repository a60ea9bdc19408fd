"""A friction calibration from Python, as ``grainforge simulate calibrate TEST`` runs it.

:func:`calibrate_friction` finds the contact friction μ at which a population reaches a measured angle on a
virtual test: the steps of :func:`grainforge.simulate.pipeline.run_virtual_test` (checks, journal, estimate,
templates, staged outputs) around the search of :func:`grainforge.simulate.friction_search.run_calibration`.
It writes ``calibration.csv``, ``calibration.json``, ``calibration.png``, ``templates.csv`` and every run
(``runs/``), and returns a :class:`CalibrationResult`.
"""

from __future__ import annotations

import math
import os
import shlex
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .pipeline import Evaluated, RunProgress, _caption, _engine_errors, _finish, _Job, _Options, _options, _prepare

__all__ = ["CalibrationResult", "CalibrationFailed", "calibration_outputs", "check_search", "use_command",
           "calibration_line", "calibrate_friction"]

#: outputs of a calibration in its folder (its runs go to runs/)
OUTPUTS = ("calibration.csv", "calibration.json", "calibration.png", "templates.csv", "runs")


class CalibrationFailed(RuntimeError):
    """The search could not go on: an angle that could not be measured (nothing is kept)."""


@dataclass(frozen=True)
class CalibrationResult:
    """A finished calibration (:func:`calibrate_friction`); its outputs are in ``out``.

    Attributes
    ----------
    test : str
        The test calibrated on.
    out : Path
        The output folder (``calibration.json`` holds :attr:`record`).
    friction, friction_sd : float
        μ found and its uncertainty (NaN or inf where the runs give none; :attr:`line` says why).
    converged : bool
        Whether the search stopped on its tolerance (False: the frictions ran out).
    evaluations : tuple of Evaluation
        Every friction tried, with its seed-averaged angle (degrees), in order.
    rows : tuple of dict
        Every run's row (``calibration.csv``).
    record : dict
        ``calibration.json``'s record.
    command : str
        The ``grainforge simulate`` command that uses μ.
    line : str
        The line the command prints: μ, its spread, the target.
    failed_runs : tuple of str
        The runs that fail their own check (a triaxial run's problems).
    clump_warning : str or None
        With ``clump_accuracy``: the clumps that miss it.
    """

    test: str
    out: Path
    friction: float
    friction_sd: float
    converged: bool
    evaluations: tuple
    rows: tuple
    record: dict
    command: str
    line: str
    failed_runs: tuple
    clump_warning: str | None

    @property
    def passed(self) -> bool:
        """Whether every run and every clump passes its own check (the command exits 3 otherwise)."""
        return not self.failed_runs and not self.clump_warning


def calibration_outputs(out: str | os.PathLike, clump_accuracy: float | None = None) -> list[Path]:
    """The paths a calibration writes into ``out`` (refused when they exist, without ``overwrite``).

    Parameters
    ----------
    out : path
        The output folder.
    clump_accuracy : float, optional
        With an accuracy target, ``clumps.csv`` too.

    Returns
    -------
    list of Path
        The outputs of :data:`OUTPUTS` (and ``clumps.csv``).
    """
    return [Path(out) / n for n in OUTPUTS + ("clumps.csv",) * (clump_accuracy is not None)]


def check_search(target_angle: float, friction_range: tuple[float, float], start: float) -> None:
    """Refuse a target angle out of range or a bad search interval.

    Parameters
    ----------
    target_angle : float
        Degrees (:func:`grainforge.simulate.friction_search.check_target`).
    friction_range : (float, float)
        The bounds of μ searched: 0 ≤ low < high ≤ 5.
    start : float
        The first μ tried, inside them.

    Raises
    ------
    ValueError
        The first refusal, in one line.
    """
    from .friction_search import check_target

    check_target(target_angle)
    low, high = friction_range
    if not (0.0 <= low < high <= 5.0):
        raise InputError(f"friction range: need 0 ≤ low < high ≤ 5, got {low:g} {high:g}")
    if not low <= start <= high:  # the search starts inside its bounds (and a NaN is no μ)
        raise InputError(f"start: {start:g} is outside the friction range {low:g} {high:g}")


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def use_command(test: str, inputs, *, friction: float, given: dict, quick: bool = False, as_spheres: bool = False,
                shape: str = "clump", spacing: float | None = None, engine: str = "yade", mpi: int | None = None,
                clump_accuracy: float | None = None) -> str:
    """The ``grainforge simulate TEST ... --friction μ`` command that uses a calibrated μ (same options).

    Parameters
    ----------
    test : str
        The test calibrated on.
    inputs : sequence of path
        The population's inputs.
    friction : float
        μ found.
    given : dict
        The settings given, by name (None: not given; ``friction`` is left out).
    quick, as_spheres, shape, spacing, engine, mpi, clump_accuracy
        The run's options (those at their default are left out).

    Returns
    -------
    str
        The command line, quoted for a POSIX shell.

    Examples
    --------
    >>> use_command("tilt", ["a b.toml"], friction=0.61234, given={"grains": 100, "friction": None})
    "grainforge simulate tilt 'a b.toml' --friction 0.612 --grains 100 --out out/tilt-calibrated"
    """
    words = ["grainforge", "simulate", test, *map(str, inputs), "--friction", f"{friction:.3g}"]
    words += [w for k, v in given.items() if v is not None and k != "friction" for w in (_option(k), str(v))]
    words += ["--quick"] * quick + ["--as-spheres"] * as_spheres
    if engine != "yade":
        words += ["--engine", engine] + (["--mpi", str(mpi)] if mpi else [])
    if shape != "clump":
        words += ["--shape", shape] + (["--spacing", f"{spacing:g}"] if spacing is not None else [])
    if clump_accuracy is not None:
        words += ["--clump-accuracy", repr(float(clump_accuracy))]
    return shlex.join(words + ["--out", f"out/{test}-calibrated"])


def calibration_line(record: dict, label: str, out: str | os.PathLike, max_frictions: int) -> str:
    """The line a finished calibration prints: μ with its spread, the target, the runs and ``calibration.json``.

    Parameters
    ----------
    record : dict
        ``calibration.json``'s record (:func:`grainforge.simulate.friction_search.calibration_record`).
    label : str
        The population's name.
    out : path
        The output folder.
    max_frictions : int
        The most frictions the search could try (named when it did not converge).

    Returns
    -------
    str
        The line; a spread that cannot be given says why.
    """
    sd = record["friction_sd"]
    if math.isfinite(sd):
        spread = f" ± {sd:.3f}"
    elif record["evaluations"] < 2:  # the first friction was within the tolerance: no slope to carry a spread
        spread = " (one friction tried: no slope, no uncertainty)"
    elif math.isinf(sd):  # the angles do not rise with μ near it
        spread = " (the angle does not rise with friction near it: no uncertainty)"
    else:
        spread = " (one seed: no spread)"
    note = "" if record["converged"] else f" (not converged in {max_frictions} frictions: the bracket's interpolation)"
    test, target = record["test"], record["target_angle_deg"]
    of = f" ({record['angle']})" if test == "triaxial" else ""
    return (f"{label}: friction {record['friction']:.3f}{spread} reaches {target:g}°{of} on the {test} test{note} "
            f"({record['runs']} runs); {Path(out) / 'calibration.json'}")


def calibrate_friction(test: str, inputs: Sequence[str | os.PathLike], *, out: str | os.PathLike,
                       target_angle: float, settings, angle: str | None = None,
                       friction_range: tuple[float, float] = (0.05, 1.5), start: float = 0.5, tolerance: float = 0.5,
                       max_frictions: int = 8, given: dict | None = None, engine: str = "yade",
                       mpi: int | None = None, workers: int | None = None, scheduler: str | None = None,
                       shape: str = "clump", spacing: float | None = None, as_spheres: bool = False,
                       clump_accuracy: float | None = None, quick: bool = False, resume: bool = False,
                       overwrite: bool = False, label: str | None = None,
                       progress: Callable[[object], None] | None = None) -> CalibrationResult:
    """Find the contact friction μ at which a population reaches ``target_angle`` on ``test``, as
    ``grainforge simulate calibrate``.

    A bounded search on the seed-averaged angle (bracket, then secant steps: a few frictions, every seed at each),
    all other settings fixed; every output appears in ``out`` together, or none.

    Parameters
    ----------
    test : {"tilt", "repose", "triaxial"}
        The test calibrated on.
    inputs : sequence of path
        Mesh files (mm), run folders, manifests, or one TOML recipe.
    out : path
        The output folder (made).
    target_angle : float
        The angle to reach, degrees (5 to 80).
    settings : Settings or TriaxialSettings
        The runs' settings (:func:`grainforge.simulate.pipeline.settings_for`); ``friction`` is searched.
    angle : {"ultimate", "peak"}, optional
        Triaxial only: the friction angle to reach (default ultimate).
    friction_range, start, tolerance, max_frictions
        μ's bounds and first value, the tolerance on the angle (degrees), the most frictions tried.
    given : dict, optional
        The settings given by name, repeated in the command that uses μ (default: none).
    engine, mpi, workers, scheduler, shape, spacing, as_spheres, clump_accuracy, quick, resume, overwrite, label
        As :func:`grainforge.simulate.pipeline.run_virtual_test`.
    progress : callable, optional
        Called with each :class:`~grainforge.simulate.pipeline.Estimate` (with the longest time),
        ``Note``, ``Count``, ``RunProgress`` (with its ``evaluation``) and, after each friction,
        :class:`~grainforge.simulate.pipeline.Evaluated`.

    Returns
    -------
    CalibrationResult
        μ, its uncertainty, every friction and run, the line and the command that uses μ.

    Raises
    ------
    ValueError
        As :func:`~grainforge.simulate.pipeline.run_virtual_test`, and a target or search interval out of range;
        ``Unreachable`` (a ValueError) when the target lies outside the angles reached (nothing kept).
    FileExistsError, FileNotFoundError, EngineFailed, grainforge.runtime.cluster.SchedulerLost
        As :func:`~grainforge.simulate.pipeline.run_virtual_test`.
    CalibrationFailed
        An angle could not be measured (nothing kept).
    """
    from .friction_search import calibration_estimate

    check_search(target_angle, friction_range, start)
    if angle is not None and test != "triaxial":
        raise InputError(f"{{angle}} is the triaxial test's: calibrate {test} does not take it", setting="angle")
    o = _options(test, inputs, settings, engine=engine, mpi=mpi, workers=workers, scheduler=scheduler, shape=shape,
                 spacing=spacing, as_spheres=as_spheres, clump_accuracy=clump_accuracy, quick=quick, resume=resume,
                 overwrite=overwrite, label=label, progress=progress)
    # every (friction, seed) run is journaled; the search's settings decide which frictions are tried
    search = dict(target_angle=target_angle, friction_range=list(friction_range), start=start, tolerance=tolerance,
                  max_frictions=max_frictions, **({"angle": angle or "ultimate"} if test == "triaxial" else {}))

    def estimate(*, available, make_seconds, pool, workers):
        return calibration_estimate(test, settings, max_evaluations=max_frictions, available=available,
                                    make_seconds=make_seconds, pool=pool, as_spheres=as_spheres, workers=workers,
                                    shape=shape, spacing=o.spacing, engine=engine)

    command = lambda mu: use_command(test, o.inputs, friction=mu, given=dict(given or {}), quick=quick, as_spheres=as_spheres,
                                     shape=shape, spacing=spacing, engine=engine, mpi=mpi,
                                     clump_accuracy=clump_accuracy)
    with ExitStack() as stack:
        job = _prepare(o, stack, kind=f"calibrate {test}", out=out, outputs=calibration_outputs(out, clump_accuracy),
                       estimate=estimate, search=search)
        return _search_stages(o, job, search, command)


def _search_stages(o: _Options, job: _Job, search: dict, command: Callable[[float], str]) -> CalibrationResult:
    """The search's engine runs and the calibration's files in a staging folder, then moved into the folder."""
    from .friction_search import Unreachable, run_calibration, write_calibration
    from .run_folders import staged
    from .sweep import JournalMismatch

    low, high = search["friction_range"]
    angle = search.get("angle")
    with staged(job.out) as stage:
        try:
            with _engine_errors(stage, job):
                found, rows = run_calibration(
                    o.test, job.templates, settings=o.settings, target=search["target_angle"], out=stage, low=low,
                    high=high, start=search["start"], tolerance=search["tolerance"],
                    max_evaluations=search["max_frictions"], workers=job.workers, label=o.label,
                    progress=lambda k, i, f, p: o.say(RunProgress(i, f, p, evaluation=k)),
                    evaluated=lambda e, got: o.say(Evaluated(e.friction, e.angle, tuple(got))), engine=o.engine,
                    mpi=o.mpi, executor=job.executor, journal=job.journal.bind(stage), angle=angle)
        except Unreachable as exc:
            job.journal.remove()  # an answer, not an interruption: nothing to resume
            raise _unreachable(exc) from None
        except JournalMismatch:  # --resume: a kept run's deck is not this one's (the user's to decide)
            raise
        except ValueError as exc:  # an angle that could not be measured
            job.journal.remove()
            raise CalibrationFailed(f"{exc}; nothing kept") from None
        caption = _caption(o, job, rows, friction=False)
        record = write_calibration(found, rows, target=search["target_angle"], test=o.test, settings=o.settings,
                                   command=command(found.friction), out=stage, low=low, high=high, angle=angle,
                                   caption=caption)
        warning = _finish(stage, o, job)
    line = calibration_line(record, o.label, job.out, search["max_frictions"])
    return CalibrationResult(o.test, job.out, found.friction, record["friction_sd"], found.converged,
                             tuple(found.evaluations), tuple(rows), record, record["command"], line,
                             tuple(record["failed_runs"]), warning)


def _unreachable(exc):
    """The target out of reach, its line saying what is kept (``rows``: the runs made)."""
    from .friction_search import Unreachable

    out = Unreachable(f"{exc}; {len(exc.rows)} run(s) made, nothing kept", exc.reached)
    out.rows = exc.rows
    return out
