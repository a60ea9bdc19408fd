"""``grainforge simulate calibrate tilt|repose|triaxial INPUTS --target-angle A --out DIR``: the contact friction μ."""

from __future__ import annotations

import math
import os
import shlex
import sys
from dataclasses import fields
from pathlib import Path

import click

from ..simulate.capabilities import ENGINE_NAMES, ENGINES, SHAPES, TILT_ONLY
from .help_style import option
from .options import (
    EXIT_CHECK_FAILED,
    FINITE_FLOAT,
    FiniteFloatRange,
    clump_accuracy_option,
    overwrite_option,
    param_options,
    workers_option,
)
from .paths import OutPath, output_dir
from .simulate import (
    HEAVY_MODULES,
    _settings_cls,
    check_cluster_options,
    check_engine,
    check_installed,
    check_representation,
    choose_templates,
    clump_outputs,
    engine_failed,
    engine_runners,
    make_templates,
    open_sweep,
    resume_option,
    run_settings,
    scheduler_lost,
    scheduler_option,
)

#: outputs of a calibration in --out (its runs go to runs/)
OUTPUTS = ("calibration.csv", "calibration.json", "calibration.png", "templates.csv", "runs")


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def use_command(test: str, inputs, friction: float, given: dict, *, quick: bool, as_spheres: bool, shape: str,
                spacing: float | None, engine: str = "yade", mpi: int | None = None,
                clump_accuracy: float | None = None) -> str:
    """The ``grainforge simulate TEST ... --friction μ`` command that uses a calibrated μ (same options).

    Examples
    --------
    >>> use_command("tilt", ["a b.toml"], 0.61234, {"grains": 100, "friction": None}, quick=False,
    ...             as_spheres=False, shape="clump", spacing=None)
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


@click.command(name="calibrate")
@click.argument("test", type=click.Choice(["tilt", "repose", "triaxial"]))
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("--target-angle", type=FINITE_FLOAT, required=True,
        help="The measured angle to reach, degrees (5 to 80): a tilt failure angle, an angle of repose, or a "
             "triaxial friction angle (--angle).")
@option("--angle", type=click.Choice(["ultimate", "peak"]), default=None,
        show_default="ultimate", help="Triaxial only: the friction angle --target-angle is: ultimate (from "
                                      "the mean q/p′ over the last 5 % of the axial strain, results.csv's "
                                      "ultimate_friction_deg) or peak.")
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder for calibration.csv, calibration.json, calibration.png and the runs (runs/).")
@option("--friction-range", type=(FINITE_FLOAT, FINITE_FLOAT), default=(0.05, 1.5), show_default=True,
        help="Bounds of the μ search.")
@option("--start", type=FiniteFloatRange(min=0.0), default=0.5, show_default=True,
        help="First μ tried (inside --friction-range).")
@option("--tolerance", type=FiniteFloatRange(min=0.0, min_open=True), default=0.5, show_default=True,
        help="Stop when a seed-averaged angle is this close to the target, degrees.")
@option("--max-frictions", "max_evaluations", type=click.IntRange(min=2, max=30), default=8, show_default=True,
        help="At most this many frictions tried (each runs every seed).")
@option("--quick", is_flag=True,
        help="A few tens of grains (triaxial: 100, a short shearing), seconds to a minute per run: checks the "
             "set-up, calibrates nothing meaningful.")
@option("--as-spheres", is_flag=True, help="Replace every grain by its volume-equivalent sphere.")
@option("--label", default=None, show_default="the inputs' names", help="Name of the population.")
@workers_option("Engine runs (seeds) at once, each on one core or on --mpi ranks.",
                default_text="CPU count divided by --mpi")
@option("--engine", type=click.Choice(ENGINES), default="yade", show_default=True,
        help="DEM engine (as simulate tilt|repose|triaxial).")
@option("--mpi", type=click.IntRange(min=1, max=4096), default=None,
        help="LIGGGHTS only: run each seed under `mpirun -np N`.")
@option("--shape", type=click.Choice(SHAPES), default="clump", show_default=True,
        help="Grain representation (as simulate tilt|repose; triaxial: clump only).")
@option("--spacing", type=FiniteFloatRange(min=0.0, max=0.5, min_open=True), default=None,
        show_default="0.05", help="Level set: grid spacing as a fraction of the equivalent diameter.")
@overwrite_option("Replace an earlier calibration in --out.")
@scheduler_option
@resume_option
@clump_accuracy_option
@param_options(_settings_cls(), exclude=("friction",))
@param_options(_settings_cls("triaxial"), exclude=tuple(f.name for f in fields(_settings_cls())))
def calibrate(test, inputs, target_angle, angle, out, friction_range, start, tolerance, max_evaluations, quick,
              as_spheres, label, workers, engine, mpi, shape, spacing, overwrite, scheduler, resume, clump_accuracy,
              **values):
    """Find the contact friction μ at which a population reaches a measured angle (tilt, repose or triaxial).

    TEST is tilt, repose or triaxial (its ultimate friction angle, or --angle peak); INPUTS as for
    `simulate tilt`; the test's options as for `simulate TEST`.  A bounded search on the seed-averaged
    angle (bracket, then secant steps: a few frictions, every seed at each), all other settings fixed.
    Writes every run, μ with its uncertainty (seed spread over the local slope) and a figure of angle
    against μ, and prints the `grainforge simulate` command that uses μ.  See docs/simulate.md.
    """
    from ..runtime.cluster import SchedulerLost
    from ..runtime.estimate import TooLargeError
    from ..simulate import check_inputs
    from ..simulate.friction_search import calibration_estimate
    from ..simulate.sweep import sweep_fingerprint
    from .interrupts import ready_for_work, say_short_estimate, signals_held

    low, high = _check_search(target_angle, friction_range, start)
    _check_test_options(test, values, angle)
    check_cluster_options(scheduler, workers, resume, overwrite)
    check_engine(engine, mpi, shape, test)
    check_representation(shape, spacing, as_spheres, values.get("spheres"), clump_accuracy, values.get("rolling_friction"))
    given = dict(values)
    settings = run_settings(test, values, quick, shape, clump_accuracy, engine=engine, mpi=mpi, workers=workers,
                            scheduler=scheduler)
    out = output_dir(out, overwrite=overwrite, files=[out / n for n in OUTPUTS + ("clumps.csv",) * (clump_accuracy is not None)])
    ls_spacing = 0.05 if spacing is None else spacing
    # every (friction, seed) run is journaled; the search's settings decide which frictions are tried
    search_options = dict(target_angle=target_angle, friction_range=list(friction_range), start=start,
                          tolerance=tolerance, max_frictions=max_evaluations,
                          **({"angle": angle or "ultimate"} if test == "triaxial" else {}))
    journal = open_sweep(out, sweep_fingerprint(f"calibrate {test}", inputs, settings, engine=engine, mpi=mpi,
                                                shape=shape, spacing=ls_spacing, as_spheres=as_spheres,
                                                clump_accuracy=clump_accuracy, **search_options), resume, overwrite)
    available, make_seconds = check_inputs(inputs)
    # the templates are chosen from a pool of grains generated or measured (--quick: 4 per template)
    pool = min(available, 4 * settings.templates) if quick else None
    executor, workers = engine_runners(scheduler, workers, mpi)
    try:
        seconds, most = calibration_estimate(test, settings, max_evaluations=max_evaluations, available=available,
                                             make_seconds=make_seconds, pool=pool, as_spheres=as_spheres,
                                             workers=workers, shape=shape, spacing=ls_spacing, engine=engine)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    if executor is None:  # on a cluster, the engine is the workers'
        check_installed(engine, mpi)
    ready_for_work(HEAVY_MODULES + ("grainforge.simulate.friction_search",), seconds, most=most)
    from ..simulate import EngineFailed, commit_stage, staged
    from ..simulate.friction_search import Unreachable, run_calibration, write_calibration
    from ..simulate.results import figure_caption
    from ..simulate.sweep import JournalMismatch

    label = label or ("spheres from " if as_spheres else "") + ", ".join(Path(p).name for p in inputs)
    chosen = choose_templates(inputs, settings, pool, workers if executor is None else (os.cpu_count() or 1))
    templates = make_templates(inputs, settings, as_spheres, shape, ls_spacing, chosen=chosen,
                               clump_accuracy=clump_accuracy)
    say_short_estimate(seconds, most=most)  # a job of 10 s to a minute, once its grains are read and made
    runs, progress, evaluated = _progress(test, engine, settings, max_evaluations)
    with staged(out) as stage:
        try:
            search, rows = run_calibration(test, templates, settings=settings, target=target_angle, out=stage, low=low, high=high,
                                           start=start, tolerance=tolerance, max_evaluations=max_evaluations,
                                           workers=workers, label=label, progress=progress, evaluated=evaluated,
                                           engine=engine, mpi=mpi, executor=executor, journal=journal.bind(stage),
                                           angle=angle)
        except EngineFailed as exc:
            raise engine_failed(exc, stage, out, journal) from None
        except SchedulerLost as exc:
            raise scheduler_lost(exc, journal) from None
        except JournalMismatch as exc:  # --resume: a kept run's deck is not this one's
            raise click.UsageError(str(exc)) from None
        except Unreachable as exc:
            journal.remove()  # an answer, not an interruption: nothing to resume
            raise click.UsageError(f"{exc}; {len(exc.rows)} run(s) made, nothing kept") from None
        except ValueError as exc:  # an angle that could not be measured
            journal.remove()
            raise click.ClickException(f"{exc}; nothing kept") from None
        finally:
            runs.close()
        command = use_command(test, inputs, search.friction, given, quick=quick, as_spheres=as_spheres,
                              shape=shape, spacing=spacing, engine=engine, mpi=mpi, clump_accuracy=clump_accuracy)
        warning = clump_outputs(templates, settings, clump_accuracy, stage, out)
        caption = figure_caption(test, settings, templates=templates, label=label, engine=engine, mpi=mpi,
                                 spacing=ls_spacing if shape == "levelset" else None, rows=rows, friction=False)
        record = write_calibration(search, rows, target=target_angle, test=test, settings=settings, command=command,
                                   out=stage, low=low, high=high, angle=angle, caption=caption)
        chosen.write_csv(stage / "templates.csv")
        with signals_held():  # the outputs appear together; the finished runs' journal is then no longer needed
            commit_stage(stage, out, overwrite=overwrite)
            journal.remove()
    _report(record, search, rows, label, out, warning, max_evaluations)


# the gravity tests' default --young is Settings'; the triaxial test's is a hundred times stiffer
next(p for p in calibrate.params if p.name == "young").default_text += " (triaxial: 100000000)"


def _check_search(target_angle: float, friction_range: tuple[float, float], start: float) -> tuple[float, float]:
    """Refuse, in one line, a target angle out of range or a bad search interval; the interval's bounds."""
    from ..simulate.friction_search import check_target

    try:
        check_target(target_angle)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--target-angle") from None
    low, high = friction_range
    if not (0.0 <= low < high <= 5.0):
        raise click.BadParameter(f"need 0 ≤ low < high ≤ 5, got {low:g} {high:g}", param_hint="--friction-range")
    if not low <= start <= high:  # the search starts inside its bounds (and a NaN is no μ)
        raise click.BadParameter(f"{start:g} is outside --friction-range {low:g} {high:g}", param_hint="--start")
    return low, high


def _test_options() -> dict[tuple[str, ...], tuple[str, ...]]:
    """The options of some tests only, by the tests that take them (the settings classes' fields)."""
    gravity = [f.name for f in fields(_settings_cls())]
    triaxial = [f.name for f in fields(_settings_cls("triaxial"))]
    return {("tilt",): TILT_ONLY,
            ("tilt", "repose"): tuple(n for n in gravity if n not in triaxial and n not in TILT_ONLY),
            ("triaxial",): tuple(n for n in triaxial if n not in gravity) + ("angle",)}


def _check_test_options(test: str, values: dict, angle: str | None) -> None:
    """Refuse, in one line, an option of another test (``--tilt-step`` in a repose or triaxial calibration,
    ``--packing`` or ``--angle`` in a tilt one, ...)."""
    given = {k for k, v in {**values, "angle": angle}.items() if v is not None}
    for tests, names in _test_options().items():
        if test in tests or not given & set(names):
            continue
        options = [_option(n) for n in names]
        listed = options[0] if len(options) == 1 else ", ".join(options[:-1]) + " and " + options[-1]
        owner = " and ".join(tests) + (" tests'" if len(tests) > 1 else " test's")
        takes = {1: "does not take it", 2: "takes neither"}.get(len(options), "takes none of them")
        raise click.UsageError(f"{listed} {'is' if len(options) == 1 else 'are'} the {owner}: "
                               f"calibrate {test} {takes}")


def _progress(test: str, engine: str, settings, max_evaluations: int):
    """The calibration's progress bar and its two callbacks: ``progress(k, i, fraction, phase)`` while a run
    goes on, ``evaluated(evaluation, rows)`` (a line on stderr) after each friction."""
    from tqdm import tqdm

    runs = tqdm(total=settings.seeds * 1000, desc=f"calibrate {test} ({ENGINE_NAMES[engine]})", unit="‰", disable=None,
                leave=False, dynamic_ncols=True, bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed} {postfix}")
    done = [0.0] * settings.seeds

    def progress(k, i, fraction, phase):
        done[i] = fraction
        runs.n = int(1000 * sum(done))
        runs.set_description_str(f"calibrate {test}: friction {k + 1}/{max_evaluations}", refresh=False)
        runs.set_postfix_str(f"seed {settings.seed + i}: {phase}", refresh=False)
        runs.refresh()

    def evaluated(e, rows):
        done[:] = [0.0] * settings.seeds
        angles = ", ".join(f"{r['angle_deg']:.1f}" for r in rows)
        runs.write(f"friction {e.friction:.4g}: {e.angle:.1f}° (seeds: {angles})", file=sys.stderr)

    return runs, progress, evaluated


def _report(record: dict, search, rows, label: str, out: Path, warning: str | None, max_evaluations: int) -> None:
    """The lines of a finished calibration: μ with its spread, the command that uses it; the runs that fail their
    own check (exit 3: the outputs are written)."""
    if warning:
        click.echo(warning, err=True)
    sd = record["friction_sd"]
    if math.isfinite(sd):
        spread = f" ± {sd:.3f}"
    elif record["evaluations"] < 2:  # the first friction was within the tolerance: no slope to carry a spread
        spread = " (one friction tried: no slope, no uncertainty)"
    elif math.isinf(sd):  # the angles do not rise with μ near it
        spread = " (the angle does not rise with friction near it: no uncertainty)"
    else:
        spread = " (one seed: no spread)"
    note = "" if search.converged else f" (not converged in {max_evaluations} frictions: the bracket's interpolation)"
    test, target = record["test"], record["target_angle_deg"]
    of = f" ({record['angle']})" if test == "triaxial" else ""
    click.echo(f"{label}: friction {search.friction:.3f}{spread} reaches {target:g}°{of} on the {test} test{note} "
               f"({len(rows)} runs); {out / 'calibration.json'}")
    click.echo(record["command"])
    if record["failed_runs"]:
        click.echo(f"check failed: {'; '.join(record['failed_runs'])} (calibration.csv has every run)", err=True)
        sys.exit(EXIT_CHECK_FAILED)
