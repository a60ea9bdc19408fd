"""``grainforge simulate repose|tilt|triaxial INPUTS --out DIR``: virtual bulk tests in Yade or LIGGGHTS (under
mpirun; the triaxial test in a periodic cell in Yade, in a box of servo-controlled walls in LIGGGHTS)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..simulate.capabilities import ENGINE_NAMES, ENGINES, SHAPES, TILT_ONLY
from .help_style import option
from .options import (
    EXIT_CHECK_FAILED,
    FiniteFloatRange,
    build_params,
    clump_accuracy_option,
    overwrite_option,
    param_options,
    workers_option,
)
from .paths import OutPath, output_dir


def check_engine(engine: str, mpi: int | None, shape: str, test: str | None = None) -> None:
    """:func:`grainforge.simulate.capabilities.check_engine`'s refusal as one line, exit 2."""
    from ..simulate.capabilities import check_engine as check

    try:
        check(engine, mpi, shape, test)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None


def check_installed(engine: str, mpi: int | None) -> None:
    """Refuse, in one line, a run whose engine (or ``mpirun``, with ``--mpi``) is not installed.

    Called after every check of the user's input, so that bad input is named first on any machine.
    """
    from ..simulate import yade_executable
    from ..simulate.liggghts_scenes import liggghts_executable, mpirun_executable

    checks = {"yade": [yade_executable], "liggghts": [liggghts_executable]}[engine]
    if mpi is not None:
        checks.append(mpirun_executable)
    for check in checks:
        try:
            check()
        except FileNotFoundError as exc:
            raise click.UsageError(str(exc)) from None


def check_representation(shape: str, spacing: float | None, as_spheres: bool, spheres: int | None,
                         clump_accuracy: float | None = None, rolling_friction: float | None = None) -> None:
    """Refuse, in one line, options of another grain representation (as ``grainforge dem`` does).

    Raises
    ------
    click.UsageError
        For ``--spacing`` without ``--shape levelset``, or ``--spheres`` or
        ``--as-spheres`` with it; ``--clump-accuracy`` with a level set or
        ``--as-spheres`` (one sphere per grain, exactly); ``--rolling-friction`` above 0 with a level set (its
        contacts carry no rolling moment law).
    """
    if shape != "clump" and rolling_friction:
        raise click.UsageError("--rolling-friction acts at sphere contacts: use it with --shape clump (or "
                               "--as-spheres)")
    if clump_accuracy is not None and (shape != "clump" or as_spheres):
        raise click.UsageError("--clump-accuracy builds clumps to an accuracy: use it with --shape clump, "
                               "without --as-spheres")
    if shape != "levelset" and spacing is not None:
        raise click.UsageError("--spacing is the level set's grid: use it with --shape levelset")
    if shape == "levelset" and spheres is not None:
        raise click.UsageError("--spheres sets a clump's size: a level set has none (--spacing sets its grid)")
    if shape == "levelset" and as_spheres:
        raise click.UsageError("--as-spheres is the sphere baseline (one sphere per grain): use it without "
                               "--shape levelset")


def run_settings(test: str, values: dict, quick: bool, shape: str, clump_accuracy: float | None = None, *,
                 engine: str = "yade", mpi: int | None = None, workers: int | None = None,
                 scheduler: str | None = None):
    """The run's :class:`grainforge.simulate.Settings` from the options (``--quick`` filling what is not given).

    With ``clump_accuracy``, ``spheres`` is the cap of every clump: the one given, or ``--quick``'s, or
    :data:`grainforge.dem.clump.DEFAULT_SPHERE_CAP`.

    A triaxial test's settings are :class:`grainforge.simulate.TriaxialSettings` (``--quick``:
    :func:`grainforge.simulate.settings.quick_settings`).

    Raises
    ------
    click.BadParameter, click.UsageError
        For a setting out of its range, a level-set run Yade cannot set up, or a triaxial specimen too small
        for its periodic cell, or (LIGGGHTS) ``mpi`` ranks (× ``workers`` runs at once) beyond this machine's
        (:func:`check_ranks_here`; not with a ``scheduler``, whose workers decide) or too many for the
        specimen's walls (:func:`grainforge.simulate.liggghts_triaxial.check_ranks`): the ranks first, and
        each line's remedy passes the other check.
    """
    from ..simulate.levelset_scenes import check_levelset_run
    from ..simulate.settings import check_triaxial_run, quick_settings

    if clump_accuracy is not None and values.get("spheres") is None and not quick:
        from ..dem.clump import DEFAULT_SPHERE_CAP

        values = {**values, "spheres": DEFAULT_SPHERE_CAP}
    if quick:
        values = {**quick_settings(test, shape, engine), **{k: v for k, v in values.items() if v is not None}}
    settings = build_params(_settings_cls(test), values)
    try:
        check_levelset_run(test, shape, settings)
        if test == "triaxial":
            check_triaxial_run(settings, engine)
        available = None if scheduler is not None else check_ranks_here(test, engine, settings, mpi, workers)
        if test == "triaxial" and engine == "liggghts":
            from ..simulate.liggghts_triaxial import check_ranks

            check_ranks(settings, mpi, available)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    return settings


def local_workers(workers: int | None, mpi: int | None) -> int:
    """Engine runs at once on this machine: ``--workers``, else the cores divided by ``--mpi``."""
    import os

    return workers or max(1, (os.cpu_count() or 1) // (mpi or 1))


def check_ranks_here(test: str, engine: str, settings, mpi: int | None, workers: int | None) -> int | None:
    """Refuse (``ValueError``) ``mpi`` ranks × the runs at once beyond this machine's ranks
    (:func:`grainforge.simulate.process.check_mpi_ranks`; for a LIGGGHTS triaxial test the ``--mpi`` suggested is
    one its specimen can be cut among too); the ranks a run may have here (``None`` without ``mpi``)."""
    if mpi is None:
        return None
    from ..simulate.process import check_mpi_ranks, mpi_slots

    runs = local_workers(workers, mpi)
    usable = None
    if test == "triaxial" and engine == "liggghts":
        from ..simulate.liggghts_triaxial import largest_ranks

        def usable(n: int) -> int:
            return largest_ranks(settings, n)

    check_mpi_ranks(mpi, runs, usable=usable)
    return mpi_slots()[0] // runs


def choose_templates(inputs, settings, pool: int | None, workers: int):
    """The representative grains to make into templates (a progress bar while a pool is measured); prints the
    one line of the choice and its KS figures."""
    from tqdm import tqdm

    from ..simulate.specimen import choose_grains

    with tqdm(desc="choosing templates", unit="grain", disable=None, leave=False, dynamic_ncols=True) as bar:
        def step(done, total):
            bar.total = total
            bar.update(1)

        chosen = choose_grains(inputs, settings, pool=pool, workers=workers, progress=step)
    click.echo(chosen.summary() + "; templates.csv")  # on stdout with the result: stderr keeps errors alone
    return chosen


def make_templates(inputs, settings, as_spheres: bool, shape: str, spacing: float, chosen=None,
                   clump_accuracy: float | None = None) -> list:
    """The population's templates (clumps or level sets), with a progress bar."""
    from tqdm import tqdm

    from ..simulate import build_population

    with tqdm(desc="clumps" if shape == "clump" else "level sets", unit="grain", disable=None, leave=False,
              dynamic_ncols=True) as bar:
        def step(done, total):
            bar.total = total
            bar.update(1)

        return build_population(inputs, settings, as_spheres=as_spheres, progress=step, shape=shape,
                                spacing=spacing, chosen=chosen,
                                **({} if clump_accuracy is None else {"clump_accuracy": clump_accuracy}))


def clump_outputs(templates, settings, clump_accuracy: float | None, stage, out) -> str | None:
    """With an accuracy target: ``clumps.csv`` of the templates in ``stage`` and the warning line that names the
    clumps missing it (``None`` when all reach it, or without a target)."""
    if clump_accuracy is None:
        return None
    from ..dem.clump import clump_table
    from ..dem.deck import template_record
    from ..dem.template import accuracy_warning

    (Path(stage) / "clumps.csv").write_text(clump_table([template_record(t) for t in templates]))
    return accuracy_warning(templates, settings.spheres, Path(out) / "clumps.csv")


def engine_failed(exc, stage, out, journal=None) -> click.ClickException:
    """An engine failure (not an interrupt): its deck and log are kept in ``out``, and the one line that says where
    (and, with a ``journal`` holding finished runs, that ``--resume`` reuses them)."""
    import os

    from ..simulate import keep_failed

    kept = keep_failed(exc.deck, out)
    message = str(exc).replace(f"{stage}{os.sep}", "")
    return click.ClickException(f"{message}; its deck and log are in {kept}{journal_kept(journal)}")


def journal_kept(journal) -> str:
    """``"; N finished run(s) kept in DIR for --resume"`` when the sweep's journal keeps runs, else ``""``."""
    runs = [] if journal is None else journal.finished()
    return f"; {len(runs)} finished run(s) kept in {journal.folder} for --resume" if runs else ""


#: ``--scheduler`` of simulate and simulate calibrate
scheduler_option = option(
    "--scheduler", metavar="ADDRESS", default=None,
    help="Run each engine run (one seed at one friction) as a task on an existing Dask distributed cluster, e.g. "
   "tcp://host:8786 (needs grainforge[dask], and grainforge and the engine on the workers); the outputs are "
   "the local run's. With --mpi each task runs `mpirun -np N` on its worker: the cluster's workers decide "
   "the cores (the local check of --mpi against this machine's cores does not apply).")
#: ``--resume`` of simulate and simulate calibrate
resume_option = option(
    "--resume", is_flag=True,
    help="Continue an interrupted run from the engine runs it finished (kept in --out/.grainforge-sweep), with "
   "the same settings: those are not run again.")


def check_cluster_options(scheduler: str | None, workers: int | None, resume: bool, overwrite: bool) -> None:
    """Refuse, in one line and before any work, ``--scheduler`` with ``--workers``, a bad address, ``--resume``
    with ``--overwrite``."""
    if resume and overwrite:
        raise click.UsageError("--resume and --overwrite exclude each other")
    if scheduler is not None:
        from ..runtime.cluster import check_address

        if workers is not None:
            raise click.UsageError("--workers is for the local pool; the Dask cluster (--scheduler) decides its "
                                   "own workers")
        try:
            check_address(scheduler)
        except ValueError as exc:
            raise click.UsageError(str(exc)) from None


def open_sweep(out: Path, fingerprint: dict, resume: bool, overwrite: bool):
    """The sweep's journal (:func:`grainforge.simulate.sweep.open_journal`), refusals as one-line usage errors."""
    from ..simulate.sweep import open_journal

    try:
        return open_journal(out, fingerprint, resume=resume, overwrite=overwrite)
    except (FileExistsError, ValueError) as exc:
        raise click.UsageError(str(exc)) from None


def cluster_executor(scheduler: str):
    """A :class:`grainforge.runtime.cluster.DaskExecutor` open until the command ends (refused in one line: exit 2)."""
    from ..runtime.cluster import dask_executor

    try:
        return click.get_current_context().with_resource(dask_executor(scheduler))
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None


def engine_runners(scheduler: str | None, workers: int | None, mpi: int | None):
    """Who runs the engine: ``(executor, workers)`` — the cluster's (:func:`cluster_executor`; its threads size
    the estimate, and its workers decide how many ranks they hold), or ``(None, workers)`` on this machine's
    cores (default: the cores divided by ``mpi``), with MPI ranks beyond them refused in one line (exit 2)."""

    from ..simulate.process import check_mpi_ranks

    if scheduler is not None:
        executor = cluster_executor(scheduler)
        return executor, executor.workers
    workers = local_workers(workers, mpi)
    try:
        check_mpi_ranks(mpi, workers)  # before anything starts: ranks beyond the cores are refused
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    return None, workers


def scheduler_lost(exc, journal) -> click.ClickException:
    """The one line of a scheduler lost mid-run (exit 1): what the journal keeps for ``--resume``."""
    kept = journal_kept(journal)
    return click.ClickException(f"{exc}{kept}" if kept else f"{exc}; no run finished, nothing kept")


def _command(test: str, doc: str):
    @click.command(name=test, help=doc)
    @click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
    @option("--out", "out", required=True, type=OutPath(file_okay=False),
            help="Folder for the decks (one per seed), results.csv and the figure.")
    @option("--quick", is_flag=True,
            help="A few tens of grains (triaxial: 100, a short shearing at a larger strain rate), seconds to a "
                 "minute per run: checks the set-up, measures nothing meaningful.")
    @option("--as-spheres", is_flag=True,
            help="Replace every grain by its volume-equivalent sphere (the sphere baseline).")
    @option("--label", default=None, show_default="the inputs' names",
            help="Name of this population in results.csv.")
    @workers_option("Engine runs (seeds) at once, each on one core or on --mpi ranks.",
                    default_text="CPU count divided by --mpi")
    @option("--engine", type=click.Choice(ENGINES), default="yade", show_default=True,
            help="DEM engine of the runs: Yade, or LIGGGHTS (the same scenes as multisphere clumps; "
                 "docs/simulate.md says where the engines differ).")
    @option("--mpi", type=click.IntRange(min=1, max=4096), default=None,
            help="LIGGGHTS only: run each seed under `mpirun -np N` (the box cut into N columns; the triaxial box "
                 "into N parts). "
                 "Yade runs one process per seed: use --workers.")
    @option("--shape", type=click.Choice(SHAPES), default="clump", show_default=True,
            help="Grain representation: clump (--spheres sets its size) or, in Yade, levelset (the mesh's "
                 "signed distance field, as grainforge dem writes it).")
    @option("--spacing", type=FiniteFloatRange(min=0.0, max=0.5, min_open=True), default=None,
            show_default="0.05", help="Level set: grid spacing as a fraction of the equivalent diameter "
                                      "(as grainforge dem).")
    @overwrite_option("Replace an earlier result in --out.")
    @scheduler_option
    @resume_option
    @clump_accuracy_option
    @param_options(_settings_cls(test), exclude=TILT_ONLY if test == "repose" else ())
    def command(inputs, out, quick, as_spheres, label, workers, engine, mpi, shape, spacing, overwrite, scheduler,
                resume, clump_accuracy, **values):
        check_cluster_options(scheduler, workers, resume, overwrite)
        check_engine(engine, mpi, shape, test)
        check_representation(shape, spacing, as_spheres, values.get("spheres"), clump_accuracy,
                             values.get("rolling_friction"))
        _run(test, inputs, out, quick, as_spheres, label, workers, overwrite, values, engine=engine, mpi=mpi,
             shape=shape, spacing=0.05 if spacing is None else spacing, clump_accuracy=clump_accuracy,
             scheduler=scheduler, resume=resume)

    return command


def _settings_cls(test: str = "repose"):
    """The settings class of ``test``'s options and runs."""
    from ..simulate import Settings, TriaxialSettings

    return TriaxialSettings if test == "triaxial" else Settings


#: modules a run loads before any work (cli.interrupts.preload: a lazy import later could swallow a Ctrl-C)
HEAVY_MODULES = ("tqdm", "trimesh", "scipy.optimize", "scipy.ndimage", "scipy.spatial", "scipy.spatial.transform",
                 "grainforge.io", "grainforge.geometry.solid", "grainforge.methods", "grainforge.population",
                 "grainforge.fabrication.scale", "grainforge.dem.inputs", "grainforge.dem.template",
                 "grainforge.dem.clump", "grainforge.dem.enclosure", "grainforge.dem.yade", "grainforge.dem.deck",
                 "grainforge.dem.liggghts", "grainforge.simulate.liggghts_scenes", "grainforge.simulate.liggghts_triaxial",
                 "grainforge.simulate.results",
                 "matplotlib.pyplot", "matplotlib.collections", "scipy.stats", "grainforge.analysis",
                 "grainforge.runtime.workers", "grainforge.dem.representative", "grainforge.dem.template_choice")


def _seed_progress(test: str, engine: str, mpi, settings):
    """The progress bar of a test's seeds (per mille of the runs) and the callback the runs report to."""
    from tqdm import tqdm

    name = ENGINE_NAMES[engine] + (f", {mpi} MPI ranks" if mpi else "")
    runs = tqdm(total=settings.seeds * 1000, desc=f"{test} ({name})", unit="‰", disable=None, leave=False,
                dynamic_ncols=True, bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining} {postfix}")
    done = [0.0] * settings.seeds

    def progress(k, fraction, phase):
        done[k] = fraction
        runs.n = int(1000 * sum(done))
        runs.set_postfix_str(f"seed {settings.seed + k}: {phase}", refresh=False)
        runs.refresh()

    return runs, progress


def _run(test, inputs, out, quick, as_spheres, label, workers, overwrite, values, *, engine="yade", mpi=None,
         shape="clump", spacing=0.05, clump_accuracy=None, scheduler=None, resume=False):
    import os

    from ..runtime.cluster import SchedulerLost
    from ..runtime.estimate import TooLargeError
    from ..simulate import check_inputs, check_size
    from ..simulate.specimen import template_make_seconds
    from ..simulate.sweep import sweep_fingerprint
    from .interrupts import ready_for_work, say_short_estimate, signals_held

    settings = run_settings(test, values, quick, shape, clump_accuracy, engine=engine, mpi=mpi, workers=workers,
                            scheduler=scheduler)
    outputs = [out / "results.csv", out / f"{test}.png", out / "templates.csv"] + [
        out / f"{test}-seed{settings.seed + k}" for k in range(settings.seeds)]
    outputs += [out / "clumps.csv"] if clump_accuracy is not None else []
    out = output_dir(out, overwrite=overwrite, files=outputs)
    journal = open_sweep(out, sweep_fingerprint(test, inputs, settings, engine=engine, mpi=mpi, shape=shape,
                                                spacing=spacing, as_spheres=as_spheres,
                                                clump_accuracy=clump_accuracy), resume, overwrite)
    available, make_seconds = check_inputs(inputs)
    # the templates are chosen from a pool of grains generated or measured (--quick: 4 per template)
    pool = min(available, 4 * settings.templates) if quick else None
    make_seconds = template_make_seconds(settings.templates, available, make_seconds, pool)
    executor, workers = engine_runners(scheduler, workers, mpi)
    try:
        seconds = check_size(test, settings, available=available, make_seconds=make_seconds,
                             as_spheres=as_spheres, workers=workers, shape=shape, spacing=spacing,
                             engine=engine)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    if executor is None:  # on a cluster, the engine is the workers'
        check_installed(engine, mpi)
    ready_for_work(HEAVY_MODULES, seconds, bound="about")
    from ..simulate import (
        EngineFailed,
        commit_stage,
        run_test,
        staged,
    )
    from ..simulate.results import annotate_rows, failed_runs, figure_caption, result_line, write_report
    from ..simulate.sweep import JournalMismatch

    label = label or ("spheres from " if as_spheres else "") + ", ".join(Path(p).name for p in inputs)
    chosen = choose_templates(inputs, settings, pool, workers if executor is None else (os.cpu_count() or 1))
    templates = make_templates(inputs, settings, as_spheres, shape, spacing, chosen=chosen,
                               clump_accuracy=clump_accuracy)
    say_short_estimate(seconds)  # a job of 10 s to a minute, once its grains are read and made
    runs, progress = _seed_progress(test, engine, mpi, settings)
    # every output is made in a hidden staging folder and moved into --out when all are complete: an
    # interrupt or a failed run leaves nothing (a SIGKILL leaves the staging folder, which the next run removes)
    with staged(out) as stage:
        try:
            rows = run_test(test, templates, settings=settings, out=stage, label=label, progress=progress,
                            workers=workers, engine=engine, mpi=mpi, executor=executor, journal=journal.bind(stage))
        except EngineFailed as exc:
            raise engine_failed(exc, stage, out, journal) from None
        except SchedulerLost as exc:
            raise scheduler_lost(exc, journal) from None
        except JournalMismatch as exc:  # --resume: a kept run's deck is not this one's
            raise click.UsageError(str(exc)) from None
        finally:
            runs.close()
        rows = annotate_rows(rows, shape=shape, spacing=spacing, engine=engine, mpi=mpi, clump_accuracy=clump_accuracy)
        warning = clump_outputs(templates, settings, clump_accuracy, stage, out)
        caption = figure_caption(test, settings, templates=templates, label=label, engine=engine, mpi=mpi,
                                 spacing=spacing if shape == "levelset" else None, rows=rows)
        write_report(rows, stage, test=test, settings=settings, caption=caption)
        chosen.write_csv(stage / "templates.csv")
        with signals_held():  # the outputs appear together; the finished runs' journal is then no longer needed
            commit_stage(stage, out, overwrite=overwrite)
            journal.remove()
    if warning:
        click.echo(warning, err=True)
    click.echo(result_line(test, rows, label, out))
    failed = failed_runs(rows, settings.seed)
    if failed or warning:  # the outputs are written; the runs or the clumps fail their own check
        if failed:
            click.echo(f"check failed: {failed} (results.csv has every run)", err=True)
        sys.exit(EXIT_CHECK_FAILED)


repose = _command("repose", """Angle of repose: a cylinder of grains on a rough base is lifted and the heap measured.

    INPUTS: mesh files (mm), a generate/batch folder, a manifest, or one TOML recipe.
    --templates of their grains, chosen so that their shapes and sizes are distributed as the
    population's (the KS figures are printed and written to templates.csv), each becomes a clump
    with the mesh's exact mass and inertia (grainforge dem);
    Yade (or LIGGGHTS, --engine liggghts [--mpi N]) runs headless once per seed; the heap's slope is
    fitted in 8 sectors.  See docs/simulate.md.
    """)
tilt = _command("tilt", """Tilt table: a layer of grains on a rough plate is tilted until it slides.

    INPUTS as for `simulate repose`.  The layer is periodic (an infinite slope); failure is the
    tilt at which the layer's mean downslope displacement exceeds half a grain diameter.
    """)
triaxial = _command("triaxial", """Drained triaxial compression: a periodic cell (Yade) or a walled box (LIGGGHTS).

    In LIGGGHTS (--engine liggghts [--mpi N]) six servo-controlled walls close the box.

    INPUTS as for `simulate repose`.  The grains are compacted isotropically to --confining-kpa
    (dense: without friction; loose: with it), then the specimen is shortened in z at the strain rate
    of --inertial-number while x and y are held at the confining stress, to --axial-strain.
    Writes each seed's triaxial.csv (q/p', volumetric strain, void ratio, coordination against the
    axial strain), results.csv (peak and ultimate friction angles, largest dilatancy angle) and
    triaxial.png.  Stresses and strains compression positive.  See docs/simulate.md.
    """)


@click.group()
def simulate():
    """Virtual bulk tests in Yade or LIGGGHTS (angle of repose, tilt table, drained triaxial test): shape's effect
    on bulk friction."""


simulate.add_command(repose)
simulate.add_command(tilt)
simulate.add_command(triaxial)
