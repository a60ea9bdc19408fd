"""Options shared by several commands, and options derived from parameter dataclasses."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import click

from ..fabrication.scale import SIZE_DEFINITIONS
from ..io import FORMATS
from ..params import ParameterError, ParamSpec, specs


class FloatList(click.ParamType):
    """Comma-separated numbers, e.g. ``0.15,0.10,0.03``."""

    name = "LIST"

    def __init__(self, length: int | None = None):
        self.length = length

    def convert(self, value, param, ctx):
        if isinstance(value, (tuple, list)):
            return tuple(float(v) for v in value)
        try:
            vals = tuple(float(x) for x in str(value).replace(";", ",").split(",") if x.strip())
        except ValueError:
            self.fail(f"expected comma-separated numbers, got {value!r}", param, ctx)
        if self.length is not None and len(vals) != self.length:
            self.fail(f"expected {self.length} comma-separated numbers, got {value!r}", param, ctx)
        return vals


def _click_type(spec: ParamSpec):
    if spec.kind == "int":
        return click.INT
    if spec.kind == "str":
        return click.Choice(spec.choices) if spec.choices else click.STRING
    if spec.kind == "floats":
        return FloatList()
    return click.FLOAT


def param_options(params_cls, exclude: tuple[str, ...] = ()) -> Callable:
    """Decorator adding one option per declared parameter of ``params_cls``.

    Defaults are *not* given to click (so only what the user typed is passed
    on); the dataclass defaults apply and are shown in the help text.
    """

    def deco(f):
        for spec in reversed(specs(params_cls)):
            if not spec.cli or spec.name in exclude:
                continue
            extra = []
            if spec.default is not None:
                d = ",".join(map(str, spec.default)) if isinstance(spec.default, tuple) else spec.default
                extra.append(f"default {d}")
            if spec.range_text() and not spec.choices:
                extra.append(f"range {spec.range_text()}")
            if spec.unit:
                extra.append(spec.unit)
            text = spec.help + (f" [{'; '.join(extra)}]" if extra else "")
            f = click.option(spec.option, spec.name, type=_click_type(spec), default=None, help=text)(f)
        return f

    return deco


def build_params(params_cls, values: dict[str, Any]):
    """Instantiate ``params_cls`` from option values (``None`` = not given).

    A :class:`ParameterError` becomes a :class:`click.BadParameter` naming the option.
    """
    given = {k: v for k, v in values.items() if v is not None}
    try:
        return params_cls(**given)
    except ParameterError as exc:
        raise bad_parameter(exc) from None


def bad_parameter(exc: ParameterError) -> click.BadParameter:
    """The CLI form of a :class:`ParameterError`: names the option."""
    option = "--" + exc.name.replace("_", "-")
    return click.BadParameter(exc.reason, param_hint=f"'{option}'")


PRINTER_KEY = "grainforge.printer"


def _remember_printer(ctx, param, value):
    if value is not None:
        from ..fabrication.printers import get_printer

        try:
            value = get_printer(value)
        except ValueError as exc:
            raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
        ctx.meta[PRINTER_KEY] = value
    return value


def count_option(help="Number of grains; grain i uses seed S + i."):
    """--count (shared by ``generate`` and ``tray``)."""
    return click.option("--count", default=1, show_default=True, type=click.IntRange(min=1), help=help)


#: --seed, --size-definition and --overwrite, shared by ``generate`` and ``tray``
seed_option = click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
                           help="Seed S of the first grain.")
size_definition_option = click.option(
    "--size-definition", default="equivalent", show_default=True, type=click.Choice(list(SIZE_DEFINITIONS)),
    help="equivalent: sphere of equal volume; sieve: intermediate dimension I; longest: L.")
overwrite_option = click.option("--overwrite", is_flag=True, help="Replace existing output files.")


def output_options(f):
    """--out, --count, --seed, --size, --size-definition, --format, --overwrite, --printer."""
    opts = [
        click.option("--out", "out", required=True, type=click.Path(file_okay=False, path_type=Path),
                     help="Folder to write the grains and manifest.csv into."),
        count_option(),
        seed_option,
        click.option("--size", default=10.0, show_default=True, type=click.FloatRange(min=1e-3, max=1e4),
                     help="Grain size in millimetres, 0.001 (1 µm) to 10000 (10 m) (see --size-definition)."),
        size_definition_option,
        click.option("--format", "fmt", default="stl", show_default=True, type=click.Choice(list(FORMATS)),
                     help="Mesh file format (binary STL, OBJ or binary PLY)."),
        overwrite_option,
        click.option("--printer", "printer", default=None, expose_value=False, callback=_remember_printer,
                     help="Match the mesh resolution to this printer (a built-in profile or file.toml[#name]) "
                          "at --size: chooses --subdivisions (fso, cri); see docs/printing.md."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f
