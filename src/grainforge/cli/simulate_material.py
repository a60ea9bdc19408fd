"""``grainforge simulate calibrate material INPUTS --target TEST=A [--target TEST=A ...] --out DIR``: the contact
friction μ and the rolling resistance μ_r fitted together to several measured angles
(:func:`grainforge.simulate.material.calibrate_material`); this module parses, calls and prints."""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path

import click

from ..errors import InputError
from .help_style import option
from .options import EXIT_CHECK_FAILED, FINITE_FLOAT, param_options
from .paths import OutPath, output_dir
from .simulate import check_options, settings_cls
from .simulate_options import Reporter, run_failures, run_options, run_settings

__all__ = ["material"]


#: what the search loads on its way (loaded before any work: a lazy import later could swallow a Ctrl-C)
SEARCH_MODULES = ("grainforge.simulate.surrogate", "scipy.stats.qmc", "sklearn.gaussian_process", "threadpoolctl")


class _Reporter(Reporter):
    """The calibration's progress: the seeds' bar names the point, a line after each point."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.modules += SEARCH_MODULES

    def __call__(self, event) -> None:
        from ..simulate.material import PointEvaluated

        if not isinstance(event, PointEvaluated):
            return super().__call__(event)
        self.done[:] = [0.0] * len(self.done)
        angles = ", ".join(f"{t} {a:.1f}°" for t, a in event.angles.items())
        self._runs().write(f"point {event.point}: friction {event.friction:.4g}, rolling friction "
                           f"{event.rolling_friction:.4g}: {angles}", file=sys.stderr)

    def _run(self, event) -> None:
        runs = self._runs()
        self.done[event.run] = event.fraction
        runs.n = int(1000 * sum(self.done))
        runs.set_description_str(f"calibrate material: point {event.evaluation + 1}/{self.max_frictions}",
                                 refresh=False)
        runs.set_postfix_str(f"seed {self.settings.seed + event.run}: {event.phase}", refresh=False)
        runs.refresh()


@click.command(name="calibrate material")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("--target", "targets", multiple=True, required=True, metavar="TEST=ANGLE[:SD]",
        help="A measured angle to reach, degrees (5 to 80), and its spread SD, 1 unless given: tilt=38, repose=34 or "
             "triaxial=37:1.5 (its ultimate friction angle, or --angle peak). Once per test.")
@option("--angle", type=click.Choice(["ultimate", "peak"]), default=None, show_default="ultimate",
        help="The triaxial target's friction angle: ultimate (results.csv's ultimate_friction_deg) or peak.")
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder for calibration.csv, calibration.json, calibration.png, templates-TEST.csv and the runs (runs/).")
@option("--friction-range", type=(FINITE_FLOAT, FINITE_FLOAT), default=(0.1, 1.5), show_default=True,
        help="Bounds of the contact friction μ searched (0 ≤ low < high ≤ 5).")
@option("--rolling-friction-range", type=(FINITE_FLOAT, FINITE_FLOAT), default=(0.0, 0.5), show_default=True,
        help="Bounds of the rolling resistance μ_r searched (0 ≤ low < high ≤ 1).")
@option("--budget", type=click.IntRange(min=2, max=60), default=16, show_default=True,
        help="At most this many points (μ, μ_r), each running every target's test, every seed.")
@option("--initial-points", type=click.IntRange(min=2, max=60), default=None, show_default="6, at most --budget",
        help="Points of the initial design (a Latin hypercube seeded by --seed).")
@run_options(calibration=True)
@param_options(settings_cls(), exclude=("friction", "rolling_friction"))
@param_options(settings_cls("triaxial"), exclude=tuple(f.name for f in fields(settings_cls())))
def material(inputs, targets, angle, out, friction_range, rolling_friction_range, budget, initial_points, quick,
             as_spheres, label, workers, engine, mpi, shape, spacing, overwrite, scheduler, resume, clump_accuracy,
             **values):
    """Fit the contact friction μ and the rolling resistance μ_r together to several measured angles.

    One --target TEST=ANGLE per test (tilt, repose, triaxial); INPUTS and the tests' options as for
    `simulate calibrate TEST`.  A surrogate-model search: a Latin hypercube of points, then points chosen by
    one Gaussian process per target (scikit-learn) over (μ, μ_r), each running every target's test, every
    seed.  Writes every run, (μ, μ_r) with the region within the noise, each target's predicted angle and a
    misfit map, and prints the `grainforge simulate` commands that use them; targets not reached together in
    the bounds are said so (exit 3).  See docs/simulate.md.
    """
    from ..simulate.material import calibrate_material, check_targets, material_outputs, parse_target

    try:
        parsed = check_targets([parse_target(t) for t in targets], angle)
    except InputError as exc:  # the message without its setting's name: click names --target
        text = str(exc)
        raise click.BadParameter(text.split(": ", 1)[1] if text.startswith(("--target: ", "targets: ")) else text,
                                 param_hint="--target") from None
    tests = [t.name for t in parsed]
    _check_test_options(tests, values, angle)
    options = dict(engine=engine, mpi=mpi, shape=shape, as_spheres=as_spheres, clump_accuracy=clump_accuracy,
                   scheduler=scheduler, workers=workers, resume=resume, overwrite=overwrite)
    settings = {}
    for test in tests:
        check_options(test, values, spacing=spacing, **options)
        own = {f.name for f in fields(settings_cls(test))}
        settings[test] = run_settings(test, {k: v for k, v in values.items() if k in own}, quick, shape,
                                      clump_accuracy, engine=engine, mpi=mpi, workers=workers, scheduler=scheduler)
    out = output_dir(out, overwrite=overwrite, files=material_outputs(out, tests, clump_accuracy))
    most = max(settings.values(), key=lambda s: s.seeds)
    with _Reporter("material", engine, mpi, most, max_frictions=budget) as reporter, run_failures():
        result = calibrate_material(inputs, out=out, targets=parsed, settings=settings, angle=angle,
                                    friction_range=friction_range, rolling_friction_range=rolling_friction_range,
                                    budget=budget, initial_points=initial_points, given=values, quick=quick,
                                    label=label, progress=reporter, **options)
    if result.clump_warning:
        click.echo(result.clump_warning, err=True)
    click.echo(result.line)
    if result.reached:
        for command in result.commands.values():
            click.echo(command)
    else:
        click.echo("check failed: the targets are not reached together in the bounds (calibration.png maps the "
                   "misfit); widen --friction-range or --rolling-friction-range, or check the targets", err=True)
    if result.failed_runs:
        click.echo(f"check failed: {'; '.join(result.failed_runs)} (calibration.csv has every run)", err=True)
    if not result.passed:
        sys.exit(EXIT_CHECK_FAILED)


def _check_test_options(tests: list[str], values: dict, angle: str | None) -> None:
    """Refuse, in one line, an option of a test that is not among the targets (``--tilt-step`` without a tilt
    target, ``--packing`` without a triaxial one)."""
    from .simulate_friction import _option, _test_options

    given = {k for k, v in {**values, "angle": angle}.items() if v is not None}
    for owners, names in _test_options().items():
        if set(tests) & set(owners) or not given & set(names):
            continue
        options = [_option(n) for n in names if n in given]
        owner = " and ".join(owners) + (" tests'" if len(owners) > 1 else " test's")
        raise click.UsageError(f"{', '.join(options)} {'is' if len(options) == 1 else 'are'} the {owner}: "
                               f"no {' or '.join(owners)} target among --target")
