"""``grainforge calibrate dpa``: the ε → D_A calibration curve of DPA aggregates."""

from __future__ import annotations

import click

from ..methods.dpa import PRIMITIVES
from ..params import ParameterError
from .help_style import option
from .options import bad_parameter, overwrite_option, seed_option, workers_option
from .paths import OutPath, output_dir
from .progress import progress_bar


@click.group()
def calibrate():
    """Calibration curves linking a method's parameters to measured properties."""


@calibrate.command(name="dpa")
@option("--primitive", default="cube", show_default=True,
        type=click.Choice(PRIMITIVES),
        help="Primary particle shape.")
@option("--primaries", default=200, show_default=True, type=click.IntRange(min=1, max=100_000),
        help="Number of primaries N per aggregate.")
@option("--exponents", default="0.5:10:0.5", show_default=True,
        help="The ε grid: A:B:STEP (inclusive) or a comma-separated list.")
@option("--repeats", default=10, show_default=True, type=click.IntRange(min=1),
        help="Aggregates (seeds) per ε.")
@seed_option("Root seed (aggregate k uses SeedSequence(seed).spawn(...)[k]).")
@workers_option("Worker processes; results do not depend on it.", default_text="one per CPU")
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder for calibration.csv and calibration.png.")
@overwrite_option()
def calibrate_dpa(primitive, primaries, exponents, repeats, seed, workers, out, overwrite):
    """Mean and spread of D_A (Eq. 5) and porosity over seeds, for each ε of a grid.

    Writes calibration.csv (exponent, D_A_mean, D_A_std, porosity_mean,
    porosity_std, R_g_mean_primary_sizes, R_g_std_primary_sizes, D_A_scaling_mean, D_A_scaling_std, ...)
    and calibration.png (the curves with ±1 s.d. bands).
    """
    from ..methods.dpa.calibration import calibrate as run_calibration
    from ..methods.dpa.calibration import parse_exponents

    try:
        grid = parse_exponents(exponents)
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    csv_path, png_path = out / "calibration.csv", out / "calibration.png"
    output_dir(out, overwrite=overwrite, files=[csv_path, png_path])
    _estimate(primitive, primaries, len(grid) * repeats, workers)
    try:
        cal = run_calibration(
            primitive, primaries, exponents=grid, repeats=repeats, rng=seed, workers=workers,
            progress=progress_bar(total=len(grid) * repeats, desc=f"calibrating dpa {primitive} N={primaries}"),
        )
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    from ..runtime.staging import commit_stage, staged
    from .work import signals_held

    with staged(out) as stage:  # the table and its figure appear together, or neither (an interrupt while drawing)
        cal.write_csv(stage / csv_path.name)
        cal.plot(stage / png_path.name)
        with signals_held():
            commit_stage(stage, out, overwrite=overwrite)
    e, m = cal.usable()
    if len(m):
        click.echo(f"mean D_A from {m.max():.3f} (ε = {e[0]:g}) to {m.min():.3f} (ε = {e[-1]:g})", err=True)
    click.echo(f"wrote {csv_path} and {png_path}", err=True)


def _estimate(primitive: str, primaries: int, count: int, workers) -> None:
    """Refuse a calibration beyond a day before any work (option: --repeats, or --primaries)."""
    from ..methods.dpa import Params
    from ..runtime.estimate import TooLargeError
    from ..runtime.workers import default_workers
    from .generate import announce_estimate

    try:
        announce_estimate("dpa", Params(primitive=primitive, primaries=primaries), count,
                          workers=default_workers(workers), count_option="--repeats (or the --exponents grid)")
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
