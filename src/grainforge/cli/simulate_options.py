"""What ``grainforge simulate TEST`` and ``grainforge simulate calibrate`` share: their run options (declared
once), the settings from the options, the progress a run reports (bars and lines) and its failures' lines.

The work itself is the library's (:func:`grainforge.simulate.pipeline.run_virtual_test`,
:func:`grainforge.simulate.calibration.calibrate_friction`); this module only speaks to the terminal.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager

import click

from ..errors import InputError
from ..simulate.capabilities import ENGINE_NAMES, ENGINES, SHAPES
from .help_style import option
from .options import FiniteFloatRange, bad_parameter, clump_accuracy_option, overwrite_option, workers_option

__all__ = ["HEAVY_MODULES", "run_options", "scheduler_option", "resume_option", "run_settings", "Reporter",
           "run_failures"]

#: modules a run loads before any work (cli.work.preload: a lazy import later could swallow a Ctrl-C)
HEAVY_MODULES = ("tqdm", "trimesh", "scipy.optimize", "scipy.ndimage", "scipy.spatial", "scipy.spatial.transform",
                 "grainforge.io", "grainforge.geometry.solid", "grainforge.methods", "grainforge.population",
                 "grainforge.fabrication.scale", "grainforge.dem.inputs", "grainforge.dem.template",
                 "grainforge.dem.clump", "grainforge.dem.enclosure", "grainforge.dem.yade", "grainforge.dem.deck",
                 "grainforge.dem.liggghts", "grainforge.simulate.liggghts_scenes", "grainforge.simulate.liggghts_triaxial",
                 "grainforge.simulate.results",
                 "matplotlib.pyplot", "matplotlib.collections", "scipy.stats", "grainforge.analysis",
                 "grainforge.runtime.workers", "grainforge.dem.representative", "grainforge.dem.template_choice")

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

#: the help of the run options: a virtual test's, and a calibration's where it differs
_HELP = {
    "quick": ("A few tens of grains (triaxial: 100, a short shearing at a larger strain rate), seconds to a minute per "
              "run: checks the set-up, measures nothing meaningful.",
              "A few tens of grains (triaxial: 100, a short shearing), seconds to a minute per run: checks the "
              "set-up, calibrates nothing meaningful."),
    "as_spheres": ("Replace every grain by its volume-equivalent sphere (the sphere baseline).",
                   "Replace every grain by its volume-equivalent sphere."),
    "label": ("Name of this population in results.csv.", "Name of the population."),
    "engine": ("DEM engine of the runs: Yade, or LIGGGHTS (the same scenes as multisphere clumps; docs/simulate.md "
               "says where the engines differ).", "DEM engine (as simulate tilt|repose|triaxial)."),
    "mpi": ("LIGGGHTS only: run each seed under `mpirun -np N` (the box cut into N columns; the triaxial box into N "
            "parts). Yade runs one process per seed: use --workers.",
            "LIGGGHTS only: run each seed under `mpirun -np N`."),
    "shape": ("Grain representation: clump (--spheres sets its size) or, in Yade, levelset (the mesh's signed "
              "distance field, as grainforge dem writes it).",
              "Grain representation (as simulate tilt|repose; triaxial: clump only)."),
    "spacing": ("Level set: grid spacing as a fraction of the equivalent diameter (as grainforge dem).",
                "Level set: grid spacing as a fraction of the equivalent diameter."),
    "overwrite": ("Replace an earlier result in --out.", "Replace an earlier calibration in --out."),
}


def run_options(calibration: bool = False):
    """The options of an engine run, from ``--quick`` to ``--clump-accuracy`` (a calibration's help where it
    differs), as one decorator."""
    help = {k: v[calibration] for k, v in _HELP.items()}
    decorators = [
        option("--quick", is_flag=True, help=help["quick"]),
        option("--as-spheres", is_flag=True, help=help["as_spheres"]),
        option("--label", default=None, show_default="the inputs' names", help=help["label"]),
        workers_option("Engine runs (seeds) at once, each on one core or on --mpi ranks.",
                       default_text="CPU count divided by --mpi"),
        option("--engine", type=click.Choice(ENGINES), default="yade", show_default=True, help=help["engine"]),
        option("--mpi", type=click.IntRange(min=1, max=4096), default=None, help=help["mpi"]),
        option("--shape", type=click.Choice(SHAPES), default="clump", show_default=True, help=help["shape"]),
        option("--spacing", type=FiniteFloatRange(min=0.0, max=0.5, min_open=True), default=None,
               show_default="0.05", help=help["spacing"]),
        overwrite_option(help["overwrite"]),
        scheduler_option,
        resume_option,
        clump_accuracy_option,
    ]

    def decorate(f):
        for d in reversed(decorators):
            f = d(f)
        return f

    return decorate


def run_settings(test: str, values: dict, quick: bool, shape: str, clump_accuracy: float | None = None, *,
                 engine: str = "yade", mpi: int | None = None, workers: int | None = None,
                 scheduler: str | None = None):
    """The run's settings from the options (:func:`grainforge.simulate.pipeline.settings_for`), checked
    (:func:`grainforge.simulate.pipeline.check_run`).

    Raises
    ------
    click.BadParameter, click.UsageError
        For a setting out of its range (naming its option), or a run the engine cannot set up.
    """
    from ..params import ParameterError
    from ..simulate.pipeline import check_run, settings_for

    try:
        settings = settings_for(test, quick, shape=shape, engine=engine, clump_accuracy=clump_accuracy, **values)
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    try:
        check_run(test, settings, engine=engine, mpi=mpi, workers=workers, shape=shape, scheduler=scheduler)
    except InputError as exc:
        raise click.UsageError(str(exc)) from None
    return settings


@contextmanager
def run_failures():
    """A run that failed once started (an engine run, the Dask scheduler, a calibration's angle): its one line,
    exit 1.  Refusals (``ValueError``, ``FileExistsError``...) are the ``grainforge`` group's: exit 2."""
    from ..runtime.cluster import SchedulerLost
    from ..simulate.calibration import CalibrationFailed
    from ..simulate.process import EngineFailed

    try:
        yield
    except (EngineFailed, SchedulerLost, CalibrationFailed) as exc:
        raise click.ClickException(str(exc)) from None


class Reporter:
    """The terminal's side of a run's progress events (:mod:`grainforge.simulate.pipeline`): the estimate on
    stderr (and the modules loaded before any work), the templates' line on stdout, and progress bars.

    Parameters
    ----------
    test, engine, mpi : str, str, int or None
        The run (the seeds' bar names them).
    settings : Settings or TriaxialSettings
        The runs' settings (``seeds``, ``seed``).
    max_frictions : int, optional
        A calibration's most frictions (its bar counts them; a line after each friction).
    """

    def __init__(self, test: str, engine: str, mpi: int | None, settings, max_frictions: int | None = None):
        self.test, self.settings, self.max_frictions = test, settings, max_frictions
        self.modules = HEAVY_MODULES + ("grainforge.simulate.friction_search",) * (max_frictions is not None)
        if max_frictions is None:
            self.desc = f"{test} ({ENGINE_NAMES[engine]}" + (f", {mpi} MPI ranks" if mpi else "") + ")"
        else:
            self.desc = f"calibrate {test} ({ENGINE_NAMES[engine]})"
        self.bar, self.bar_desc, self.runs, self.done = None, None, None, [0.0] * settings.seeds

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._close()
        if self.runs is not None:
            self.runs.close()

    def _close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __call__(self, event) -> None:
        from ..simulate import pipeline as p
        from . import work

        if isinstance(event, p.Estimate) and not event.inputs_read:
            work.ready_for_work(self.modules, event.seconds, bound="about", most=event.most)
        elif isinstance(event, p.Estimate):
            self._close()
            work.say_short_estimate(event.seconds, most=event.most)
        elif isinstance(event, p.Count):
            self._count(event)
        elif isinstance(event, p.Note):
            self._close()
            click.echo(event.text)  # on stdout with the result: stderr keeps errors alone
        elif isinstance(event, p.RunProgress):
            self._run(event)
        elif isinstance(event, p.Evaluated):
            self.done[:] = [0.0] * self.settings.seeds
            angles = ", ".join(f"{r['angle_deg']:.1f}" for r in event.rows)
            self._runs().write(f"friction {event.friction:.4g}: {event.angle:.1f}° (seeds: {angles})", file=sys.stderr)

    def _count(self, event) -> None:
        from tqdm import tqdm

        desc = "choosing templates" if event.what == "grains" else event.what
        if self.bar is not None and self.bar_desc != desc:
            self._close()
        if self.bar is None:
            self.bar, self.bar_desc = tqdm(desc=desc, unit="grain", disable=None, leave=False, dynamic_ncols=True), desc
        self.bar.total = event.total
        self.bar.update(1)

    def _runs(self):
        """The seeds' bar (per mille of the runs)."""
        from tqdm import tqdm

        if self.runs is None:
            remaining = "<{remaining}" if self.max_frictions is None else ""
            self.runs = tqdm(total=self.settings.seeds * 1000, desc=self.desc, unit="‰", disable=None, leave=False,
                             dynamic_ncols=True,
                             bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}" + remaining + " {postfix}")
        return self.runs

    def _run(self, event) -> None:
        runs = self._runs()
        self.done[event.run] = event.fraction
        runs.n = int(1000 * sum(self.done))
        if event.evaluation is not None:
            runs.set_description_str(f"calibrate {self.test}: friction {event.evaluation + 1}/{self.max_frictions}",
                                     refresh=False)
        runs.set_postfix_str(f"seed {self.settings.seed + event.run}: {event.phase}", refresh=False)
        runs.refresh()

