"""Options shared by several commands, and options derived from parameter dataclasses.

The number types are in :mod:`grainforge.cli.numbers`, the help's style in :mod:`grainforge.cli.help_style`,
the voxel-size options in :mod:`grainforge.cli.voxel_size`; their names are offered here too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import click

from ..errors import InputError
from ..fabrication.scale import SIZE_DEFINITIONS
from ..io import FORMATS
from ..params import ParameterError, ParamSpec, specs
from .help_style import HelpOption, _first_sentence, apply_help_style, interval_of, option
from .numbers import FINITE_FLOAT, FiniteFloat, FiniteFloatRange, FloatList
from .paths import OutPath
from .voxel_size import VOXEL_FLAG, VOXEL_UNITS, renamed_option, voxel_size_flag, voxel_size_options

__all__ = [
    "workers_option", "overwrite_option", "seed_option", "count_option", "output_options", "param_options",
    "build_params", "bad_parameter", "clump_accuracy_option", "size_definition_option", "MAX_WORKERS",
    "SPHERES_RANGE", "PRINTER_KEY", "EXIT_CHECK_FAILED",
    # from the modules of a theme
    "option", "HelpOption", "apply_help_style", "interval_of", "_first_sentence",
    "FloatList", "FiniteFloatRange", "FiniteFloat", "FINITE_FLOAT",
    "renamed_option", "voxel_size_flag", "voxel_size_options", "VOXEL_UNITS", "VOXEL_FLAG",
]


#: most worker processes any command starts at once (``--workers``)
MAX_WORKERS = 256


def workers_option(help: str = "Worker processes.", default_text: str | None = None, default: int | None = None):
    """--workers, the same range for every command: 1 to :data:`MAX_WORKERS`.

    Parameters
    ----------
    help : str
        The command's help text (what the workers do).
    default_text : str, optional
        What the default is, in words (``"one per CPU"``), for a command whose default is computed
        (``default=None``).
    default : int, optional
        A fixed default (``tray``: 2), shown as such in the help.

    Returns
    -------
    callable
        The click option decorator.
    """
    show = default_text if default_text is not None else default is not None
    return option("--workers", type=click.IntRange(min=1, max=MAX_WORKERS), default=default,
                        show_default=show, help=help)


def overwrite_option(help: str = "Replace existing output files."):
    """--overwrite, the flag of every command that writes files (docs/cli-contract.md: an existing output is
    refused without it).

    Parameters
    ----------
    help : str
        What it replaces, for this command.

    Returns
    -------
    callable
        The click option decorator.
    """
    return option("--overwrite", is_flag=True, help=help)


def seed_option(help: str = "Seed S of the first grain.", default: int | None = 0, default_text: str | None = None):
    """--seed, a non-negative integer.

    Parameters
    ----------
    help : str
        What the seed seeds, for this command.
    default : int or None
        The default seed (``None``: the command picks it, described by ``default_text``).
    default_text : str, optional
        The default in words, shown in the help when ``default`` is None.

    Returns
    -------
    callable
        The click option decorator.
    """
    show = default_text if default_text is not None else default is not None
    return option("--seed", type=click.IntRange(min=0), default=default, show_default=show, help=help)


#: the spheres of a clump, ``--spheres`` of ``dem``, ``simulate`` and ``simulate calibrate`` alike (the simulation
#: settings declare it too, :class:`grainforge.simulate.settings.GrainSettings`; a test compares them): two at least,
#: since one sphere is not the grain's shape (the sphere baseline is ``simulate --as-spheres``, the volume-equivalent
#: sphere) and LIGGGHTS and LAMMPS refuse a rigid body of one sphere; 1,000 at most (``dem``'s clumps built to an
#: accuracy reach 130 spheres on angular grains; the time and memory estimates refuse what would not run)
SPHERES_RANGE = (2, 1000)
#: --clump-accuracy (``dem`` and ``simulate``): build each clump to an intersection over union instead of a
#: fixed sphere count
clump_accuracy_option = option(
    "--clump-accuracy", "clump_accuracy", type=FiniteFloatRange(0.0, 1.0, min_open=True, max_open=True), default=None,
    help="Clump: build each grain's clump to this intersection over union with the grain (e.g. 0.85): the fewest "
         "spheres that reach it, --spheres being then the most a clump may take (docs/dem.md).")


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
    on); the dataclass defaults apply and are shown in the help text, with the
    valid range and the unit, from the parameter's declaration.
    """

    def deco(f):
        for spec in reversed(specs(params_cls)):
            if not spec.cli or spec.name in exclude:
                continue
            text = spec.help + (f" (in {spec.unit})" if spec.unit else "")
            f = option(spec.option, spec.name, type=_click_type(spec), default=None, help=text, cls=HelpOption)(f)
            f.__click_params__[-1].default_text = spec.default_text()
            f.__click_params__[-1].interval_text = "" if spec.choices else spec.range_text()
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

#: exit status of a command that ran to its end and wrote its outputs, whose result fails its own check:
#: a fit that does not pass its criteria, clumps that miss their accuracy target, a virtual test that
#: measured no angle, did not settle or lost grains (docs/cli-contract.md). 0 is success, 2 a refusal.
EXIT_CHECK_FAILED = 3


def _remember_printer(ctx, param, value):
    if value is not None:
        from ..fabrication.printers import get_printer

        try:
            value = get_printer(value)
        except InputError as exc:
            raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
        ctx.meta[PRINTER_KEY] = value
    return value


def count_option(help="Number of grains; grain i uses seed S + i."):
    """--count (shared by ``generate`` and ``tray``)."""
    return option("--count", default=1, show_default=True, type=click.IntRange(min=1), help=help)


#: --size-definition, shared by ``generate`` and ``tray``
size_definition_option = option(
    "--size-definition", default="equivalent", show_default=True, type=click.Choice(list(SIZE_DEFINITIONS)),
    help="equivalent: sphere of equal volume; sieve: intermediate dimension I; longest: L.")


def output_options(f=None, *, printer: bool = True):
    """--out, --count, --seed, --size, --size-definition, --format, --overwrite and (``printer=True``) --printer.

    Use as ``@output_options`` or ``@output_options(printer=False)`` (methods
    without an icosphere ``subdivisions`` parameter: resolution matching does
    not apply to them, so the option is not offered).
    """
    if f is None:
        return lambda g: output_options(g, printer=printer)
    opts = [
        option("--out", "out", required=True, type=OutPath(file_okay=False),
                     help="Folder to write the grains and manifest.csv into."),
        count_option(),
        seed_option(),
        option("--size", default=10.0, show_default=True, type=FiniteFloatRange(min=1e-3, max=1e4),
                     help="Grain size in millimetres, 0.001 (1 µm) to 10000 (10 m) (see --size-definition)."),
        size_definition_option,
        option("--format", "fmt", default="stl", show_default=True, type=click.Choice(list(FORMATS)),
                     help="Mesh file format (binary STL, OBJ or binary PLY)."),
        overwrite_option(),
    ]
    if printer:
        opts.append(option(
            "--printer", "printer", default=None, expose_value=False, callback=_remember_printer,
            help="Match the mesh resolution (--subdivisions) to this printer (a built-in profile or "
                 "file.toml[#name]) at --size; see docs/printing.md."))
    for opt in reversed(opts):
        f = opt(f)
    return f


