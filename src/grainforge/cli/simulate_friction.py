"""``grainforge simulate calibrate tilt|repose INPUTS --target-angle A --out DIR``: the contact friction μ."""

from __future__ import annotations

import shlex
from pathlib import Path

import click

from .options import (
    FINITE_FLOAT,
    FiniteFloatRange,
    clump_accuracy_option,
    overwrite_option,
    param_options,
    workers_option,
)
from .paths import OutPath, output_dir
from .simulate import (
    ENGINE_NAMES,
    ENGINES,
    HEAVY_MODULES,
    SHAPES,
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
    sweep_fingerprint,
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
@click.argument("test", type=click.Choice(["tilt", "repose"]))
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--target-angle", type=FINITE_FLOAT, required=True,
              help="The measured angle to reach, degrees (5 to 80): a tilt failure angle or an angle of repose.")
@click.option("--out", "out", required=True, type=OutPath(file_okay=False),
              help="Folder for calibration.csv, calibration.json, calibration.png and the runs (runs/).")
@click.option("--friction-range", type=(FINITE_FLOAT, FINITE_FLOAT), default=(0.05, 1.5), show_default=True,
              help="Bounds of the μ search.")
@click.option("--start", type=FiniteFloatRange(min=0.0), default=0.5, show_default=True,
              help="First μ tried (inside --friction-range).")
@click.option("--tolerance", type=FiniteFloatRange(min=0.0, min_open=True), default=0.5, show_default=True,
              help="Stop when a seed-averaged angle is this close to the target, degrees.")
@click.option("--max-frictions", "max_evaluations", type=click.IntRange(min=2, max=30), default=8, show_default=True,
              help="At most this many frictions tried (each runs every seed).")
@click.option("--quick", is_flag=True,
              help="A few tens of grains, seconds per run: checks the set-up, calibrates nothing meaningful.")
@click.option("--as-spheres", is_flag=True, help="Replace every grain by its volume-equivalent sphere.")
@click.option("--label", default=None, show_default="the inputs' names", help="Name of the population.")
@workers_option("Engine runs (seeds) at once, each on one core or on --mpi ranks.",
                default_text="CPU count divided by --mpi")
@click.option("--engine", type=click.Choice(ENGINES), default="yade", show_default=True,
              help="DEM engine (as simulate tilt|repose).")
@click.option("--mpi", type=click.IntRange(min=1, max=4096), default=None,
              help="LIGGGHTS only: run each seed under `mpirun -np N`.")
@click.option("--shape", type=click.Choice(SHAPES), default="clump", show_default=True,
              help="Grain representation (as simulate tilt|repose).")
@click.option("--spacing", type=FiniteFloatRange(min=0.0, max=0.5, min_open=True), default=None,
              show_default="0.05", help="Level set: grid spacing as a fraction of the equivalent diameter.")
@overwrite_option("Replace an earlier calibration in --out.")
@scheduler_option
@resume_option
@clump_accuracy_option
@param_options(_settings_cls(), exclude=("friction",))
def calibrate(test, inputs, target_angle, out, friction_range, start, tolerance, max_evaluations, quick, as_spheres,
              label, workers, engine, mpi, shape, spacing, overwrite, scheduler, resume, clump_accuracy, **values):
    """Find the contact friction μ at which a population reaches a measured angle (tilt or repose).

    TEST is tilt or repose; INPUTS as for `simulate tilt`.  A bounded search on the seed-averaged angle
    (bracket, then secant steps: a few frictions, every seed at each), all other settings fixed.
    Writes every run, μ with its uncertainty (seed spread over the local slope) and a figure of angle
    against μ, and prints the `grainforge simulate` command that uses μ.  See docs/simulate.md.
    """
    import math
    import os
    import sys
    from dataclasses import replace

    from ..runtime.cluster import SchedulerLost
    from ..runtime.estimate import TooLargeError
    from ..simulate import check_inputs, check_size
    from ..simulate.friction_search import check_target
    from ..simulate.specimen import template_make_seconds
    from .interrupts import ready_for_work, signals_held

    try:
        check_target(target_angle)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--target-angle") from None
    low, high = friction_range
    if not (0.0 <= low < high <= 5.0):
        raise click.BadParameter(f"need 0 ≤ low < high ≤ 5, got {low:g} {high:g}", param_hint="--friction-range")
    if not low <= start <= high:  # the search starts inside its bounds (and a NaN is no μ)
        raise click.BadParameter(f"{start:g} is outside --friction-range {low:g} {high:g}", param_hint="--start")
    if test == "repose" and (values.get("tilt_step") is not None or values.get("tilt_start") is not None):
        raise click.UsageError("--tilt-step and --tilt-start are the tilt test's: calibrate repose takes neither")
    check_cluster_options(scheduler, workers, resume, overwrite)
    check_engine(engine, mpi, shape)
    check_representation(shape, spacing, as_spheres, values.get("spheres"), clump_accuracy)
    given = dict(values)
    settings = run_settings(test, values, quick, shape, clump_accuracy)
    outputs = OUTPUTS + (("clumps.csv",) if clump_accuracy is not None else ())
    out = output_dir(out, overwrite=overwrite, files=[out / name for name in outputs])
    ls_spacing = 0.05 if spacing is None else spacing
    # every (friction, seed) run is journaled; the search's settings decide which frictions are tried
    journal = open_sweep(out, sweep_fingerprint(f"calibrate {test}", inputs, settings, engine=engine, mpi=mpi,
                                                shape=shape, spacing=ls_spacing, as_spheres=as_spheres,
                                                clump_accuracy=clump_accuracy, target_angle=target_angle,
                                                friction_range=list(friction_range), start=start,
                                                tolerance=tolerance, max_frictions=max_evaluations),
                         resume, overwrite)
    available, make_seconds = check_inputs(inputs)
    # the templates are chosen from a pool of grains generated or measured (--quick: 4 per template)
    pool = min(available, 4 * settings.templates) if quick else None
    make_seconds = template_make_seconds(settings.templates, available, make_seconds, pool)
    executor, workers = engine_runners(scheduler, workers, mpi)
    from ..runtime.estimate import SECONDS_LIMIT, _limit, duration

    try:
        one = check_size(test, settings, available=available, make_seconds=make_seconds, as_spheres=as_spheres,
                         workers=workers, shape=shape, spacing=ls_spacing, engine=engine)
        # the templates are made once; every friction tried runs every seed
        make = check_size(test, replace(settings, seeds=1, grains=2), available=available,
                          make_seconds=make_seconds, as_spheres=as_spheres, workers=workers, shape=shape,
                          spacing=ls_spacing, engine=engine)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    seconds = make + (one - make) * max_evaluations
    if seconds > SECONDS_LIMIT:
        raise click.UsageError(f"a calibration of up to {max_evaluations} frictions × {settings.seeds} seed(s) of "
                               f"{settings.grains} grains would take about {duration(seconds)} of computing (limit "
                               f"{_limit()}); lower --max-frictions, --grains or --seeds")
    if executor is None:  # on a cluster, the engine is the workers'
        check_installed(engine, mpi)
    ready_for_work(HEAVY_MODULES + ("grainforge.simulate.friction_search",), seconds, bound="at most about")
    from tqdm import tqdm

    from ..simulate import EngineFailed, commit_stage, staged
    from ..simulate.friction_search import Unreachable, run_calibration, write_calibration
    from ..simulate.sweep import JournalMismatch

    label = label or ("spheres from " if as_spheres else "") + ", ".join(Path(p).name for p in inputs)
    chosen = choose_templates(inputs, settings, pool, workers if executor is None else (os.cpu_count() or 1))
    templates = make_templates(inputs, settings, as_spheres, shape, ls_spacing, chosen=chosen,
                               clump_accuracy=clump_accuracy)
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

    with staged(out) as stage:
        try:
            search, rows = run_calibration(test, templates, settings, target_angle, stage, low=low, high=high,
                                           start=start, tolerance=tolerance, max_evaluations=max_evaluations,
                                           workers=workers, label=label, progress=progress, evaluated=evaluated,
                                           engine=engine, mpi=mpi, executor=executor, journal=journal.bind(stage))
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
        record = write_calibration(search, rows, target_angle, test, settings, command, stage, low=low, high=high)
        chosen.write_csv(stage / "templates.csv")
        with signals_held():  # the outputs appear together; the finished runs' journal is then no longer needed
            commit_stage(stage, out, overwrite=overwrite)
            journal.remove()
    if warning:
        click.echo(warning, err=True)
    sd = record["friction_sd"]
    spread = f" ± {sd:.3f}" if math.isfinite(sd) else " (one seed: no spread)"
    note = "" if search.converged else f" (not converged in {max_evaluations} frictions: the bracket's interpolation)"
    click.echo(f"{label}: friction {search.friction:.3f}{spread} reaches {target_angle:g}° on the {test} test{note} "
               f"({len(rows)} runs); {out / 'calibration.json'}")
    click.echo(command)

