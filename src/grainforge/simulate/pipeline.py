"""A whole virtual test from Python, as ``grainforge simulate repose|tilt|triaxial`` runs it.

:func:`run_virtual_test` takes the inputs (grain files, a run folder, a manifest or one TOML recipe), the
test, its settings (:func:`settings_for`) and an output folder, and does every step of the command: the
checks before any work, the sweep's journal (``--resume``), the estimate, the representative templates,
the engine runs (:func:`grainforge.simulate.run_test`, the lower-level runner that takes templates), and
``results.csv``, the figure and ``templates.csv``, all moved into the folder together.  It returns a
:class:`VirtualTestResult`; it prints nothing: what a command prints as it goes (the estimate, the
templates chosen, the progress of the runs) is passed to a ``progress`` callback as the events below.

The friction calibration (``grainforge simulate calibrate``) is :func:`grainforge.simulate.calibration.calibrate_friction`,
made of the same steps.

Examples
--------
>>> settings = settings_for("tilt", quick=True)
>>> settings.grains, settings.seeds
(30, 1)
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError, OutputExistsError

__all__ = ["Estimate", "Note", "Count", "RunProgress", "Evaluated", "VirtualTestResult", "settings_for", "check_options",
           "check_run", "check_installed", "local_workers", "virtual_test_outputs", "run_virtual_test"]


# ---- what a run reports on its way (the argument of ``progress``) ----------------------------------------------

@dataclass(frozen=True)
class Estimate:
    """The job's estimated time, said twice: before any work (``inputs_read`` False: the inputs are checked, the
    engine found; a command loads its modules then) and when the templates are made (``inputs_read`` True: the
    engine runs start).

    Attributes
    ----------
    seconds : float
        The usual estimate.
    most : float or None
        The longest the job may take, where it differs (a calibration that needs every friction it may try).
    inputs_read : bool
        Whether the templates are made.
    """

    seconds: float
    most: float | None = None
    inputs_read: bool = False


@dataclass(frozen=True)
class Note:
    """A line for the user: the templates chosen and how well they match the population (``templates.csv``)."""

    text: str


@dataclass(frozen=True)
class Count:
    """``done`` of ``total`` grains measured (``what`` ``"grains"``) or templates made (``"clumps"``, ``"level sets"``)."""

    what: str
    done: int
    total: int


@dataclass(frozen=True)
class RunProgress:
    """Engine run ``run`` (0 for the first seed) at ``fraction`` of its work, in ``phase``; in a calibration,
    of friction number ``evaluation`` (0 for the first)."""

    run: int
    fraction: float
    phase: str
    evaluation: int | None = None


@dataclass(frozen=True)
class Evaluated:
    """A calibration's friction tried: μ, the seed-averaged angle (degrees) and its runs' rows."""

    friction: float
    angle: float
    rows: tuple


# ---- the result --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class VirtualTestResult:
    """A finished virtual test (:func:`run_virtual_test`); its outputs are in ``out``.

    Attributes
    ----------
    test : str
        ``"repose"``, ``"tilt"`` or ``"triaxial"``.
    out : Path
        The output folder: ``results.csv``, ``<test>.png``, ``templates.csv`` and one deck per seed.
    rows : tuple of dict
        ``results.csv``'s rows, one per seed (``angle_deg`` in degrees; a triaxial run's friction angles).
    line : str
        The line ``grainforge simulate`` prints: the angle over the seeds and where the outputs are.
    failed_runs : str
        The runs that fail their own check (no angle, a heap not at rest, grains lost), ``""`` when none.
    clump_warning : str or None
        With ``clump_accuracy``: the clumps that miss it (``clumps.csv`` lists every clump); None when all reach it.
    label : str
        The population's name in the rows.
    """

    test: str
    out: Path
    rows: tuple
    line: str
    failed_runs: str
    clump_warning: str | None
    label: str

    @property
    def passed(self) -> bool:
        """Whether every run and every clump passes its own check (the command exits 3 otherwise)."""
        return not self.failed_runs and not self.clump_warning


# ---- settings and checks -----------------------------------------------------------------------------------------

def settings_for(test: str, quick: bool = False, *, shape: str = "clump", engine: str = "yade",
                 clump_accuracy: float | None = None, **values):
    """The settings of a virtual test, as ``grainforge simulate TEST`` makes them from its options.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test (a triaxial test's settings are :class:`~grainforge.simulate.TriaxialSettings`).
    quick : bool
        ``--quick``: a few tens of grains (:func:`grainforge.simulate.settings.quick_settings`) where ``values``
        gives no other.
    shape, engine : str
        The grains' representation and the engine (their quick settings differ).
    clump_accuracy : float, optional
        A clump accuracy target: ``spheres`` is then the cap of every clump (the one given, or ``--quick``'s,
        or :data:`grainforge.dem.clump.DEFAULT_SPHERE_CAP`).
    **values
        Settings by name (``grains=100``, ``friction=0.4``, ...); None is not given.

    Returns
    -------
    Settings or TriaxialSettings
        The settings.

    Raises
    ------
    grainforge.params.ParameterError
        For a setting out of its range (a ``ValueError``).

    Examples
    --------
    >>> settings_for("tilt", friction=0.4).friction, settings_for("triaxial", quick=True).grains
    (0.4, 100)
    """
    from .settings import Settings, TriaxialSettings, quick_settings

    if clump_accuracy is not None and values.get("spheres") is None and not quick:
        from ..dem.clump import DEFAULT_SPHERE_CAP

        values = {**values, "spheres": DEFAULT_SPHERE_CAP}
    given = {k: v for k, v in values.items() if v is not None}
    if quick:
        given = {**quick_settings(test, shape, engine), **given}
    return (TriaxialSettings if test == "triaxial" else Settings)(**given)


def check_options(test: str | None, *, engine: str = "yade", mpi: int | None = None, shape: str = "clump",
                  spacing: float | None = None, as_spheres: bool = False, spheres: int | None = None,
                  clump_accuracy: float | None = None, rolling_friction: float | None = None,
                  scheduler: str | None = None, workers: int | None = None, resume: bool = False,
                  overwrite: bool = False) -> None:
    """Refuse, in one line, options that do not go together, before any work.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"} or None
        The virtual test (None: any).
    engine, mpi, shape : str, int or None, str
        The engine, its MPI ranks and the grains' representation
        (:func:`grainforge.simulate.capabilities.check_engine`).
    spacing, as_spheres, spheres, clump_accuracy, rolling_friction
        Options of one representation only: a level set's ``spacing``; ``spheres``, ``as_spheres``,
        ``clump_accuracy`` and a ``rolling_friction`` above 0 of clumps (None: not given).
    scheduler, workers : str or None, int or None
        A Dask scheduler's address (checked), which decides its own workers: not with ``workers``.
    resume, overwrite : bool
        Exclude each other.

    Raises
    ------
    ValueError
        The first refusal, in one line naming the options.
    """
    from .capabilities import check_engine

    if resume and overwrite:
        raise InputError("{resume} and {overwrite} exclude each other", setting=("resume", "overwrite"))
    if scheduler is not None:
        from ..runtime.cluster import check_address

        if workers is not None:
            raise InputError("{workers} is for the local pool; the Dask cluster ({scheduler}) decides its own workers",
                             setting=("workers", "scheduler"))
        check_address(scheduler)
    check_engine(engine, mpi, shape, test)
    if shape != "clump" and rolling_friction:
        raise InputError("{rolling_friction} acts at sphere contacts: use it with {shape} clump (or {as_spheres})",
                         setting=("rolling_friction", "shape", "as_spheres"))
    if clump_accuracy is not None and (shape != "clump" or as_spheres):
        raise InputError("{clump_accuracy} builds clumps to an accuracy: use it with {shape} clump, without "
                         "{as_spheres}", setting=("clump_accuracy", "shape", "as_spheres"))
    if shape != "levelset" and spacing is not None:
        raise InputError("{spacing} is the level set's grid: use it with {shape} levelset", setting=("spacing", "shape"))
    if shape == "levelset" and spheres is not None:
        raise InputError("{spheres} sets a clump's size: a level set has none ({spacing} sets its grid)",
                         setting=("spheres", "spacing"))
    if shape == "levelset" and as_spheres:
        raise InputError("{as_spheres} is the sphere baseline (one sphere per grain): use it without {shape} levelset",
                         setting=("as_spheres", "shape"))


def local_workers(workers: int | None, mpi: int | None) -> int:
    """Engine runs at once on this machine.

    Parameters
    ----------
    workers : int or None
        The runs asked for.
    mpi : int or None
        The ranks of each run.

    Returns
    -------
    int
        ``workers``, else the cores divided by ``mpi``.
    """
    from ..runtime.workers import default_workers

    return workers or max(1, default_workers() // (mpi or 1))


def _ranks_here(test: str, engine: str, settings, mpi: int | None, workers: int | None) -> int | None:
    """Refuse (``ValueError``) ``mpi`` ranks × the runs at once beyond this machine's ranks
    (:func:`grainforge.simulate.process.check_mpi_ranks`; for a LIGGGHTS triaxial test the ``--mpi`` suggested is
    one its specimen can be cut among too); the ranks a run may have here (``None`` without ``mpi``)."""
    if mpi is None:
        return None
    from .process import check_mpi_ranks, mpi_slots

    runs = local_workers(workers, mpi)
    usable = None
    if test == "triaxial" and engine == "liggghts":
        from .liggghts_triaxial import largest_ranks

        def usable(n: int) -> int:
            return largest_ranks(settings, n)

    check_mpi_ranks(mpi, runs, usable=usable)
    return mpi_slots()[0] // runs


def check_run(test: str, settings, *, engine: str = "yade", mpi: int | None = None, workers: int | None = None,
              shape: str = "clump", scheduler: str | None = None) -> None:
    """Refuse a run the engine cannot set up, before any work.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The runs' settings.
    engine, mpi, workers, shape
        The engine, each run's MPI ranks, the runs at once and the grains' representation.
    scheduler : str, optional
        A Dask scheduler: its workers decide the ranks (this machine's are not checked).

    Raises
    ------
    ValueError
        A level-set run Yade cannot set up; a triaxial specimen too small for its cell; ``mpi`` ranks
        (× ``workers`` runs at once) beyond this machine's, or too many for a LIGGGHTS triaxial specimen's walls
        (the ranks first: each line's remedy passes the other check).
    """
    from .levelset_scenes import check_levelset_run
    from .settings import check_triaxial_run

    check_levelset_run(test, shape, settings)
    if test == "triaxial":
        check_triaxial_run(settings, engine)
    available = None if scheduler is not None else _ranks_here(test, engine, settings, mpi, workers)
    if test == "triaxial" and engine == "liggghts":
        from .liggghts_triaxial import check_ranks

        check_ranks(settings, mpi, available)


def check_installed(engine: str, mpi: int | None) -> None:
    """Refuse a run whose engine (or ``mpirun``, with ``mpi``) is not installed on this machine.

    Parameters
    ----------
    engine : {"yade", "liggghts"}
        The engine.
    mpi : int or None
        Ranks under ``mpirun`` (LIGGGHTS).

    Raises
    ------
    FileNotFoundError
        Naming what is missing and how to install it.
    """
    from .engine import yade_executable
    from .liggghts_scenes import liggghts_executable, mpirun_executable

    checks = {"yade": [yade_executable], "liggghts": [liggghts_executable]}[engine]
    for check in checks + ([mpirun_executable] if mpi is not None else []):
        check()


def virtual_test_outputs(test: str, settings, out: str | os.PathLike, clump_accuracy: float | None = None) -> list[Path]:
    """The paths a virtual test writes into ``out`` (refused when they exist, without ``overwrite``).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The runs' settings (one deck per seed).
    out : path
        The output folder.
    clump_accuracy : float, optional
        With an accuracy target, ``clumps.csv`` too.

    Returns
    -------
    list of Path
        ``results.csv``, the figure, ``templates.csv``, the seeds' decks (and ``clumps.csv``).
    """
    out = Path(out)
    outputs = [out / "results.csv", out / f"{test}.png", out / "templates.csv"]
    outputs += [out / f"{test}-seed{settings.seed + k}" for k in range(settings.seeds)]
    return outputs + ([out / "clumps.csv"] if clump_accuracy is not None else [])


def _check_out(out: str | os.PathLike, outputs: Sequence[Path], overwrite: bool) -> Path:
    """The output folder: not a file; none of ``outputs`` there unless ``overwrite``."""
    if str(out).strip() == "":
        raise InputError("the output folder's path is empty; give a folder name")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out} is a file, not a folder")
    existing = [p for p in outputs if p.exists()] if not overwrite else []
    if existing:
        more = f" ({len(existing)} output files would be replaced)" if len(existing) > 1 else ""
        raise OutputExistsError(f"{existing[0]} exists{more}; use {{overwrite}}", setting="overwrite")
    return out


# ---- the steps every run shares ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Options:
    """A run's options, checked (``spacing`` the level set's, 0.05 when not given)."""

    test: str
    inputs: tuple
    settings: object
    engine: str
    mpi: int | None
    workers: int | None
    scheduler: str | None
    shape: str
    spacing: float
    as_spheres: bool
    clump_accuracy: float | None
    quick: bool
    resume: bool
    overwrite: bool
    label: str
    progress: Callable | None

    def say(self, event) -> None:
        if self.progress is not None:
            self.progress(event)


def _options(test, inputs, settings, *, engine="yade", mpi=None, workers=None, scheduler=None, shape="clump",
             spacing=None, as_spheres=False, clump_accuracy=None, quick=False, resume=False, overwrite=False,
             label=None, progress=None) -> _Options:
    """The run's options, refused in one line (``ValueError``) where they do not go together."""
    inputs = tuple(inputs)
    check_options(test, engine=engine, mpi=mpi, shape=shape, spacing=spacing, as_spheres=as_spheres,
                  clump_accuracy=clump_accuracy, rolling_friction=getattr(settings, "rolling_friction", None),
                  scheduler=scheduler, workers=workers, resume=resume, overwrite=overwrite)
    check_run(test, settings, engine=engine, mpi=mpi, workers=workers, shape=shape, scheduler=scheduler)
    label = label or ("spheres from " if as_spheres else "") + ", ".join(Path(p).name for p in inputs)
    return _Options(test, inputs, settings, engine, mpi, workers, scheduler, shape, 0.05 if spacing is None else spacing,
                    as_spheres, clump_accuracy, quick, resume, overwrite, label, progress)


@dataclass(frozen=True)
class _Job:
    """A run ready for its engine runs: the folder, the journal, who runs the engine, the templates."""

    out: Path
    journal: object
    executor: object
    workers: int
    chosen: object
    templates: list
    seconds: float
    most: float | None


def _engine_runners(o: _Options, stack: ExitStack):
    """Who runs the engine: ``(executor, workers)``: a Dask cluster's (open until ``stack`` closes; its threads
    size the estimate), or ``(None, workers)`` on this machine's cores, MPI ranks beyond them refused."""
    if o.scheduler is not None:
        from ..runtime.cluster import dask_executor

        executor = stack.enter_context(dask_executor(o.scheduler))
        return executor, executor.workers
    from .process import check_mpi_ranks

    workers = local_workers(o.workers, o.mpi)
    check_mpi_ranks(o.mpi, workers)  # before anything starts: ranks beyond the cores are refused
    return None, workers


def _prepare(o: _Options, stack: ExitStack, *, kind: str, out, outputs: Sequence[Path], estimate: Callable,
             search: dict | None = None) -> _Job:
    """Every step before the engine runs: the folder and the journal, the inputs, the estimate (said before any
    work), the templates (chosen, then made).  ``estimate(available=, make_seconds=, pool=, workers=)`` gives
    ``(seconds, most)``; ``kind`` and ``search`` name the sweep in its journal."""
    from .specimen import check_inputs
    from .sweep import open_journal, sweep_fingerprint

    out = _check_out(out, outputs, o.overwrite)
    fingerprint = sweep_fingerprint(kind, o.inputs, o.settings, engine=o.engine, mpi=o.mpi, shape=o.shape,
                                    spacing=o.spacing, as_spheres=o.as_spheres, clump_accuracy=o.clump_accuracy,
                                    **(search or {}))
    journal = open_journal(out, fingerprint, resume=o.resume, overwrite=o.overwrite)
    available, make_seconds = check_inputs(o.inputs)
    # the templates are chosen from a pool of grains generated or measured (quick: 4 per template)
    pool = min(available, 4 * o.settings.templates) if o.quick else None
    executor, workers = _engine_runners(o, stack)
    seconds, most = estimate(available=available, make_seconds=make_seconds, pool=pool, workers=workers)
    if executor is None:  # on a cluster, the engine is the workers'
        check_installed(o.engine, o.mpi)
    o.say(Estimate(seconds, most))
    from ..runtime.workers import default_workers
    from .specimen import build_population, choose_grains

    chosen = choose_grains(o.inputs, o.settings, pool=pool, workers=workers if executor is None else default_workers(),
                           progress=lambda done, total: o.say(Count("grains", done, total)))
    o.say(Note(chosen.summary() + "; templates.csv"))
    what = "clumps" if o.shape == "clump" else "level sets"
    templates = build_population(o.inputs, o.settings, as_spheres=o.as_spheres, shape=o.shape, spacing=o.spacing,
                                 chosen=chosen, progress=lambda done, total: o.say(Count(what, done, total)),
                                 **({} if o.clump_accuracy is None else {"clump_accuracy": o.clump_accuracy}))
    o.say(Estimate(seconds, most, inputs_read=True))
    return _Job(out, journal, executor, workers, chosen, templates, seconds, most)


def _journal_kept(journal) -> str:
    """``"; N finished run(s) kept in DIR for --resume"`` when the sweep's journal keeps runs, else ``""``."""
    runs = journal.finished()
    return f"; {len(runs)} finished run(s) kept in {journal.folder} for --resume" if runs else ""


@contextmanager
def _engine_errors(stage: Path, job: _Job):
    """A failed engine run's deck and log kept in the output folder, and the scheduler lost, each said in its
    exception's one line with what the journal keeps for ``--resume``."""
    from ..runtime.cluster import SchedulerLost
    from .process import EngineFailed
    from .run_folders import keep_failed

    try:
        yield
    except EngineFailed as exc:
        kept = keep_failed(exc.deck, job.out)
        message = str(exc).replace(f"{stage}{os.sep}", "")
        raise EngineFailed(f"{message}; its deck and log are in {kept}{_journal_kept(job.journal)}", kept) from None
    except SchedulerLost as exc:
        kept = _journal_kept(job.journal)
        exc.args = (f"{exc}{kept}" if kept else f"{exc}; no run finished, nothing kept",)
        raise


def _finish(stage: Path, o: _Options, job: _Job) -> str | None:
    """``templates.csv`` (and ``clumps.csv``) into the stage, then every output moved into the folder at once;
    the clump warning line (None without one)."""
    from ..runtime.staging import signals_held
    from .run_folders import commit_stage

    warning = None
    if o.clump_accuracy is not None:
        from ..dem.clump import clump_table
        from ..dem.deck import template_record
        from ..dem.template import accuracy_warning

        (stage / "clumps.csv").write_text(clump_table([template_record(t) for t in job.templates]))
        warning = accuracy_warning(job.templates, o.settings.spheres, job.out / "clumps.csv")
    job.chosen.write_csv(stage / "templates.csv")
    with signals_held():  # the outputs appear together; the finished runs' journal is then no longer needed
        commit_stage(stage, job.out, overwrite=o.overwrite)
        job.journal.remove()
    return warning


def _caption(o: _Options, job: _Job, rows, friction: bool = True) -> str:
    from .results import figure_caption

    return figure_caption(o.test, o.settings, templates=job.templates, label=o.label, engine=o.engine, mpi=o.mpi,
                          spacing=o.spacing if o.shape == "levelset" else None, rows=rows, friction=friction)


# ---- the virtual test --------------------------------------------------------------------------------------------

def run_virtual_test(test: str, inputs: Sequence[str | os.PathLike], *, out: str | os.PathLike, settings,
                     engine: str = "yade", mpi: int | None = None, workers: int | None = None,
                     scheduler: str | None = None, shape: str = "clump", spacing: float | None = None,
                     as_spheres: bool = False, clump_accuracy: float | None = None, quick: bool = False,
                     resume: bool = False, overwrite: bool = False, label: str | None = None,
                     progress: Callable[[object], None] | None = None) -> VirtualTestResult:
    """Run a virtual test of a population from its grains to ``results.csv``, as ``grainforge simulate TEST``.

    Every output is made in a hidden staging folder and moved into ``out`` when all are complete: an interrupt or
    a failed run leaves none of them (the engine runs finished are kept for ``resume``).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    inputs : sequence of path
        Mesh files (mm), run folders, manifests, or one TOML recipe.
    out : path
        The output folder (made).
    settings : Settings or TriaxialSettings
        The runs' settings (:func:`settings_for`).
    engine, mpi : str, int or None
        The engine (``"yade"`` or ``"liggghts"``) and, in LIGGGHTS, each run's ranks under ``mpirun``.
    workers : int, optional
        Engine runs at once on this machine (default: the cores divided by ``mpi``).
    scheduler : str, optional
        A Dask scheduler's address: each engine run a task on its workers (not with ``workers``).
    shape, spacing : str, float or None
        The grains' representation: ``"clump"``, or ``"levelset"`` (Yade) of grid ``spacing`` (default 0.05).
    as_spheres : bool
        Every grain its volume-equivalent sphere (the sphere baseline).
    clump_accuracy : float, optional
        Build every clump to this intersection over union with its grain (``settings.spheres`` the cap).
    quick : bool
        Choose the templates from a pool of 4 grains per template (as ``--quick``; its settings are
        ``settings_for(test, quick=True)``).
    resume, overwrite : bool
        Reuse the engine runs an interrupted run with the same settings kept in ``out``; or replace earlier
        outputs (and such a journal).
    label : str, optional
        The population's name in the rows (default: the inputs' names).
    progress : callable, optional
        Called with each :class:`Estimate`, :class:`Note`, :class:`Count` and :class:`RunProgress` on the way.

    Returns
    -------
    VirtualTestResult
        The rows, the result line, the runs and clumps that fail their own check.

    Raises
    ------
    ValueError
        Options that do not go together, settings the engine cannot set up, inputs that hold no grain or a
        grain that is no valid solid (named); a job beyond a day (``TooLargeError``); ``resume`` with other
        settings or decks (``JournalMismatch``).
    FileExistsError
        Outputs in ``out`` without ``overwrite``, or an interrupted run's journal without ``resume``.
    FileNotFoundError
        The engine is not installed.
    EngineFailed
        An engine run failed: its deck and log are kept in ``out/failed-<run>`` (the line says where).
    grainforge.runtime.cluster.SchedulerLost
        The Dask scheduler was lost (the line says what is kept for ``resume``).
    """
    from .settings import check_size
    from .specimen import template_make_seconds

    o = _options(test, inputs, settings, engine=engine, mpi=mpi, workers=workers, scheduler=scheduler, shape=shape,
                 spacing=spacing, as_spheres=as_spheres, clump_accuracy=clump_accuracy, quick=quick, resume=resume,
                 overwrite=overwrite, label=label, progress=progress)

    def estimate(*, available, make_seconds, pool, workers):
        make = template_make_seconds(settings.templates, available, make_seconds, pool)
        size = dict(available=available, make_seconds=make, as_spheres=as_spheres, workers=workers, shape=shape,
                    spacing=o.spacing, engine=engine)
        usual = check_size(test, settings, **size)
        # a triaxial compaction may run to its time limit (angular clumps that creep): the most it may take
        return usual, (check_size(test, settings, longest=True, **size) if test == "triaxial" else None)

    with ExitStack() as stack:
        job = _prepare(o, stack, kind=test, out=out, outputs=virtual_test_outputs(test, settings, out, clump_accuracy),
                       estimate=estimate)
        return _run_stages(o, job)


def _run_stages(o: _Options, job: _Job) -> VirtualTestResult:
    """The engine runs, ``results.csv`` and the figure in a staging folder, then moved into the output folder."""
    from .engine import run_test
    from .results import annotate_rows, failed_runs, result_line, write_report
    from .run_folders import staged

    def report(k, fraction, phase):
        o.say(RunProgress(k, fraction, phase))

    with staged(job.out) as stage:
        with _engine_errors(stage, job):
            rows = run_test(o.test, job.templates, settings=o.settings, out=stage, label=o.label, progress=report,
                            workers=job.workers, engine=o.engine, mpi=o.mpi, executor=job.executor,
                            journal=job.journal.bind(stage))
        rows = annotate_rows(rows, shape=o.shape, spacing=o.spacing, engine=o.engine, mpi=o.mpi,
                             clump_accuracy=o.clump_accuracy)
        write_report(rows, stage, test=o.test, settings=o.settings, caption=_caption(o, job, rows))
        warning = _finish(stage, o, job)
    return VirtualTestResult(o.test, job.out, tuple(rows), result_line(o.test, rows, o.label, job.out),
                             failed_runs(rows, o.settings.seed), warning, o.label)
