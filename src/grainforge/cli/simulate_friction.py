"""``grainforge simulate calibrate tilt|repose|triaxial INPUTS --target-angle A --out DIR``: the contact friction μ."""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path

import click

from ..errors import InputError
from ..simulate.calibration import use_command
from ..simulate.capabilities import TILT_ONLY
from .help_style import option
from .options import EXIT_CHECK_FAILED, FINITE_FLOAT, FiniteFloatRange, param_options
from .paths import OutPath, output_dir
from .simulate import check_options, settings_cls
from .simulate_options import Reporter, run_failures, run_options, run_settings

__all__ = ["calibrate", "use_command"]


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


@click.command(name="calibrate")
@click.argument("test", type=click.Choice(["tilt", "repose", "triaxial", "material"]))
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
@run_options(calibration=True)
@param_options(settings_cls(), exclude=("friction",))
@param_options(settings_cls("triaxial"), exclude=tuple(f.name for f in fields(settings_cls())))
def calibrate(test, inputs, target_angle, angle, out, friction_range, start, tolerance, max_evaluations, quick,
              as_spheres, label, workers, engine, mpi, shape, spacing, overwrite, scheduler, resume, clump_accuracy,
              **values):
    """Find the contact friction μ at which a population reaches a measured angle (tilt, repose or triaxial).

    TEST is tilt, repose or triaxial (its ultimate friction angle, or --angle peak); INPUTS as for
    `simulate tilt`; the test's options as for `simulate TEST`.  A bounded search on the seed-averaged
    angle (bracket, then secant steps: a few frictions, every seed at each), all other settings fixed.
    Writes every run, μ with its uncertainty (seed spread over the local slope) and a figure of angle
    against μ, and prints the `grainforge simulate` command that uses μ.  `simulate calibrate material`
    fits μ and the rolling resistance μ_r together to several tests' angles (its own --help).  See
    docs/simulate.md.
    """
    from ..simulate.calibration import calibrate_friction, calibration_outputs

    if test == "material":  # `simulate calibrate material ...` is its own command: TEST was not right after calibrate
        raise click.UsageError("calibrate material takes its own options (--target TEST=ANGLE): write material "
                               "right after calibrate (grainforge simulate calibrate material --help)")
    _check_search(target_angle, friction_range, start)
    _check_test_options(test, values, angle)
    options = dict(engine=engine, mpi=mpi, shape=shape, spacing=spacing, as_spheres=as_spheres,
                   clump_accuracy=clump_accuracy, scheduler=scheduler, workers=workers, resume=resume,
                   overwrite=overwrite)
    check_options(test, values, **options)
    settings = run_settings(test, values, quick, shape, clump_accuracy, engine=engine, mpi=mpi, workers=workers,
                            scheduler=scheduler)
    out = output_dir(out, overwrite=overwrite, files=calibration_outputs(out, clump_accuracy))
    with Reporter(test, engine, mpi, settings, max_frictions=max_evaluations) as reporter, run_failures():
        result = calibrate_friction(test, inputs, out=out, target_angle=target_angle, settings=settings, angle=angle,
                                    friction_range=friction_range, start=start, tolerance=tolerance,
                                    max_frictions=max_evaluations, given=values, quick=quick, label=label,
                                    progress=reporter, **options)
    if result.clump_warning:
        click.echo(result.clump_warning, err=True)
    click.echo(result.line)
    click.echo(result.command)
    if result.failed_runs:
        click.echo(f"check failed: {'; '.join(result.failed_runs)} (calibration.csv has every run)", err=True)
        sys.exit(EXIT_CHECK_FAILED)


# the gravity tests' default --young is Settings'; the triaxial test's is a hundred times stiffer
next(p for p in calibrate.params if p.name == "young").default_text += " (triaxial: 100000000)"


def _check_search(target_angle: float, friction_range: tuple[float, float], start: float) -> tuple[float, float]:
    """Refuse, in one line, a target angle out of range or a bad search interval; the interval's bounds."""
    from ..simulate.friction_search import check_target

    try:
        check_target(target_angle)
    except InputError as exc:
        raise click.BadParameter(str(exc), param_hint="--target-angle") from None
    low, high = friction_range
    if not (0.0 <= low < high <= 5.0):
        raise click.BadParameter(f"need 0 ≤ low < high ≤ 5, got {low:g} {high:g}", param_hint="--friction-range")
    if not low <= start <= high:  # the search starts inside its bounds (and a NaN is no μ)
        raise click.BadParameter(f"{start:g} is outside --friction-range {low:g} {high:g}", param_hint="--start")
    return low, high


def _test_options() -> dict[tuple[str, ...], tuple[str, ...]]:
    """The options of some tests only, by the tests that take them (the settings classes' fields)."""
    gravity = [f.name for f in fields(settings_cls())]
    triaxial = [f.name for f in fields(settings_cls("triaxial"))]
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
