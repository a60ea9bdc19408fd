"""Hook of ``grainforge generate dpa`` (see :mod:`grainforge.cli.generate`): ``--target-fractal-dimension``,
which picks the exponent ε from the cached calibration curve (:mod:`grainforge.methods.dpa.calibration`)."""

from __future__ import annotations

import click

from ..params import ParameterError
from .help_style import option
from .options import FINITE_FLOAT, bad_parameter, build_params

OPTIONS = [
    option("--target-fractal-dimension", "target", type=FINITE_FLOAT, default=None,
           help="Aim at this aggregate fractal dimension D_A: ε is taken from the calibration curve of "
                "the primitive and N (cached; computed with a progress bar on first use). "
                "Exclusive with --exponent."),
]


def prepare(values: dict) -> dict:
    """Replace ``target`` by the calibrated ``exponent`` (and record the target)."""
    from ..methods.dpa import Params
    from ..methods.dpa.calibration import exponent_for_dimension
    from .progress import progress_bar

    values = dict(values)
    target = values.pop("target", None)
    if target is None:
        return values
    if values.get("exponent") is not None:
        raise click.UsageError("--target-fractal-dimension cannot be combined with --exponent")
    probe = build_params(Params, {**values, "exponent": 1.0, "target_fractal_dimension": target})
    try:
        eps = exponent_for_dimension(
            target, primitive=probe.primitive, primaries=probe.primaries,
            progress=progress_bar(desc=f"calibrating dpa {probe.primitive} N={probe.primaries}"),
        )
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    click.echo(f"target D_A = {target:g}: exponent ε = {eps:.4g} (from the calibration curve)", err=True)
    return {**values, "exponent": eps, "target_fractal_dimension": target}
