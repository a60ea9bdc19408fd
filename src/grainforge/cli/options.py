"""Options shared by several commands, and options derived from parameter dataclasses."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import click

from ..fabrication.scale import SIZE_DEFINITIONS
from ..io import FORMATS
from ..params import ParameterError, ParamSpec, format_number, specs
from .paths import OutPath


class FloatList(click.ParamType):
    """Comma-separated numbers, e.g. ``0.15,0.10,0.03`` (also accepted: ``;`` or ``:``, as in ``2:1.5:1``)."""

    name = "LIST"

    def __init__(self, length: int | None = None):
        self.length = length

    def convert(self, value, param, ctx):
        if isinstance(value, (tuple, list)):
            return tuple(float(v) for v in value)
        try:
            vals = tuple(float(x) for x in str(value).replace(";", ",").replace(":", ",").split(",") if x.strip())
        except ValueError:
            self.fail(f"expected comma-separated numbers, got {value!r}", param, ctx)
        if self.length is not None and len(vals) != self.length:
            self.fail(f"expected {self.length} comma-separated numbers, got {value!r}", param, ctx)
        return vals


class FiniteFloatRange(click.FloatRange):
    """``click.FloatRange`` that also refuses ``nan`` (which compares false with both bounds, so the range lets it
    through) and ``inf`` or ``-inf`` on a side without a bound: one line, exit code 2, as for a number out of the
    range.

    Every float option of the command line has this type (or :class:`FiniteFloat` where it has no range), so
    ``nan``, ``inf`` and ``-inf`` are refused by click, before the command does any work.
    """

    def convert(self, value, param, ctx):
        import math

        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


class FiniteFloat(click.types.FloatParamType):
    """A float option without a range that refuses ``nan``, ``inf`` and ``-inf`` (one line, exit code 2).

    Its help shows no range (``FiniteFloatRange()`` without bounds would show ``(-inf, inf)``).
    """

    def convert(self, value, param, ctx):
        import math

        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


#: the type of a float option without a range
FINITE_FLOAT = FiniteFloat()

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
    return click.option("--workers", type=click.IntRange(min=1, max=MAX_WORKERS), default=default,
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
    return click.option("--overwrite", is_flag=True, help=help)


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
    return click.option("--seed", type=click.IntRange(min=0), default=default, show_default=show, help=help)


#: the spheres of a clump, ``--spheres`` of ``dem``, ``simulate`` and ``simulate calibrate`` alike (the simulation
#: settings declare it too, :class:`grainforge.simulate.settings.GrainSettings`; a test compares them): two at least,
#: since one sphere is not the grain's shape (the sphere baseline is ``simulate --as-spheres``, the volume-equivalent
#: sphere) and LIGGGHTS and LAMMPS refuse a rigid body of one sphere; 1,000 at most (``dem``'s clumps built to an
#: accuracy reach 130 spheres on angular grains; the time and memory estimates refuse what would not run)
SPHERES_RANGE = (2, 1000)
#: --clump-accuracy (``dem`` and ``simulate``): build each clump to an intersection over union instead of a
#: fixed sphere count
clump_accuracy_option = click.option(
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


class HelpOption(click.Option):
    """An option whose help ends in one style everywhere: ``[default: 2.4; range: [2, 3); required]``.

    Defaults are written as a person would (``10``, ``-5/3``), ranges as
    intervals (``[1, inf)``, ``(0, 100]``), for parameter-derived options and
    for click's own ranges alike.  :func:`apply_help_style` gives every option
    of the CLI this class.
    """

    #: set by :func:`param_options` (parameter-derived options have no click default)
    default_text: str | None = None
    interval_text: str | None = None

    def get_help_record(self, ctx):
        if self.hidden:
            return None
        extra = self.get_help_extra(ctx)
        items = []
        default = self.default_text
        if default is None and isinstance(self.show_default, str):
            default = self.show_default
        elif default is None and "default" in extra:
            value = self.default
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                default = format_number(value)
            else:
                default = str(extra["default"])
        if default:
            items.append(f"default: {default}")
        interval = self.interval_text if self.interval_text is not None else interval_of(self.type)
        if interval:
            items.append(f"range: {interval}")
        if self.required:
            items.append("required")
        text = self.help or ""
        if items:
            text = f"{text}  [{'; '.join(items)}]" if text else f"[{'; '.join(items)}]"
        return self.get_help_spec(ctx), text


def interval_of(type_) -> str:
    """``[1, inf)`` for ``click.IntRange(min=1)``; ``""`` for types without a range."""
    if not isinstance(type_, click.types._NumberRangeBase):
        return ""
    lo = "-inf" if type_.min is None else format_number(type_.min)
    hi = "inf" if type_.max is None else format_number(type_.max)
    lb = "(" if (type_.min is None or type_.min_open) else "["
    rb = ")" if (type_.max is None or type_.max_open) else "]"
    return f"{lb}{lo}, {hi}{rb}"


def _first_sentence(text: str) -> str:
    """The first sentence of a help text, not cut inside parentheses (``(Eq. 5)``)."""
    para = " ".join(text.strip().split("\n\n")[0].split())
    depth = 0
    for i, ch in enumerate(para):
        depth += (ch == "(") - (ch == ")")
        if ch == "." and depth == 0 and (i + 1 == len(para) or para[i + 1] == " "):
            return para[: i + 1]
    return para


def apply_help_style(command: click.Command) -> None:
    """Give every option under ``command`` the :class:`HelpOption` style, and every subcommand a
    short help that is its first whole sentence (click cuts at the first period, e.g. inside ``(Eq. 5)``)."""
    for param in command.params:
        if type(param) is click.Option:
            param.__class__ = HelpOption
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            if sub.short_help is None and sub.help:
                sub.short_help = _first_sentence(sub.help)
            apply_help_style(sub)


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
            f = click.option(spec.option, spec.name, type=_click_type(spec), default=None, help=text, cls=HelpOption)(f)
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
        except ValueError as exc:
            raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
        ctx.meta[PRINTER_KEY] = value
    return value


def count_option(help="Number of grains; grain i uses seed S + i."):
    """--count (shared by ``generate`` and ``tray``)."""
    return click.option("--count", default=1, show_default=True, type=click.IntRange(min=1), help=help)


#: --size-definition, shared by ``generate`` and ``tray``
size_definition_option = click.option(
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
        click.option("--out", "out", required=True, type=OutPath(file_okay=False),
                     help="Folder to write the grains and manifest.csv into."),
        count_option(),
        seed_option(),
        click.option("--size", default=10.0, show_default=True, type=FiniteFloatRange(min=1e-3, max=1e4),
                     help="Grain size in millimetres, 0.001 (1 µm) to 10000 (10 m) (see --size-definition)."),
        size_definition_option,
        click.option("--format", "fmt", default="stl", show_default=True, type=click.Choice(list(FORMATS)),
                     help="Mesh file format (binary STL, OBJ or binary PLY)."),
        overwrite_option(),
    ]
    if printer:
        opts.append(click.option(
            "--printer", "printer", default=None, expose_value=False, callback=_remember_printer,
            help="Match the mesh resolution (--subdivisions) to this printer (a built-in profile or "
                 "file.toml[#name]) at --size; see docs/printing.md."))
    for opt in reversed(opts):
        f = opt(f)
    return f


def renamed_option(old: str, new: str, what: str) -> Callable:
    """A hidden option ``old`` that refuses in one line, naming ``new`` (the option's new name).

    For an option renamed to carry its unit (``--voxel-size`` → ``--voxel-size-um``):
    an old command line stops with exit code 2 rather than reading a number in the wrong unit.
    """

    def refuse(ctx, param, value):
        if value is not None:
            raise click.UsageError(f"{old} is now {new} ({what}); write {new} {value}")
        return value

    return click.option(old, "_renamed_" + old.lstrip("-").replace("-", "_"), hidden=True, default=None,
                        expose_value=False, callback=refuse, is_eager=True)


#: a voxel size's unit, as its option spells it -> its µm as a decimal (a value is scaled by a power of ten in
#: decimal, so ``--voxel-size-mm 0.0029`` is exactly the number ``--voxel-size-um 2.9`` is, not 2.9000000000000004)
VOXEL_UNITS = {"um": "1", "mm": "1000"}
#: key of the click context's ``meta``: the voxel-size flag the user gave (:func:`voxel_size_flag`)
VOXEL_FLAG = "grainforge.voxel_size_flag"


def voxel_size_flag(default: str = "--voxel-size-um") -> str:
    """The voxel-size flag the running command was given (``--voxel-size-um`` or ``--voxel-size-mm``), for its
    messages; ``default`` when none was given or outside a command.

    Parameters
    ----------
    default : str
        The flag named when the user gave none.

    Returns
    -------
    str
    """
    ctx = click.get_current_context(silent=True)
    return ctx.meta.get(VOXEL_FLAG, default) if ctx is not None else default


def voxel_size_options(unit: str, help: str, name: str = "voxel_size") -> Callable:
    """``--voxel-size-um`` and ``--voxel-size-mm``: one voxel size in either unit, the same pair in every command
    that takes one (``analyse``, ``scan``, ``fit``); the command receives it in its own ``unit`` as ``name``.

    Parameters
    ----------
    unit : {"um", "mm"}
        The unit the command works in (the other option's value is converted).
    help : str
        The help of the option in ``unit`` (the other's says it is the same in its unit).
    name : str, default "voxel_size"
        The command function's parameter.

    Returns
    -------
    callable
        The decorator (below ``click.command``).
    """
    words = {"um": "µm", "mm": "mm"}

    def deco(f):
        import functools
        from decimal import Decimal

        @functools.wraps(f)
        def command(*args, voxel_size_um=None, voxel_size_mm=None, **kwargs):
            if voxel_size_um is not None and voxel_size_mm is not None:
                raise click.UsageError("give --voxel-size-um or --voxel-size-mm, not both (the same voxel size in "
                                       "µm or in mm)")
            given = [(v, u) for v, u in ((voxel_size_um, "um"), (voxel_size_mm, "mm")) if v is not None]
            value = None
            if given:
                (v, u), = given
                value = float(Decimal(repr(v)) * Decimal(VOXEL_UNITS[u]) / Decimal(VOXEL_UNITS[unit]))
                if not 0 < value < math.inf:
                    raise click.BadParameter(f"{v:g} {words[u]} is {value:g} {words[unit]}, not a usable voxel size",
                                             param_hint=f"'--voxel-size-{u}'")
            kwargs[name] = value
            if given:
                click.get_current_context().meta[VOXEL_FLAG] = f"--voxel-size-{given[0][1]}"
            return f(*args, **kwargs)

        other = "mm" if unit == "um" else "um"
        for u in (other, unit):  # (click lists them in the reverse order of the decorators)
            text = help if u == unit else f"As --voxel-size-{unit}, in {words[u]} (give one of the two)."
            command = click.option(f"--voxel-size-{u}", f"voxel_size_{u}", type=FiniteFloatRange(min=0, min_open=True),
                                   default=None, help=text)(command)
        return command

    return deco
