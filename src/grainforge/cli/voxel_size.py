"""The voxel-size options (``--voxel-size-um`` or ``--voxel-size-mm``, the same pair in every command that takes
one) and options renamed to carry their unit."""

from __future__ import annotations

import math
from collections.abc import Callable

import click

from .help_style import option
from .numbers import FiniteFloatRange

__all__ = ["renamed_option", "voxel_size_flag", "voxel_size_options", "VOXEL_UNITS", "VOXEL_FLAG"]


def renamed_option(old: str, new: str, what: str) -> Callable:
    """A hidden option ``old`` that refuses in one line, naming ``new`` (the option's new name).

    For an option renamed to carry its unit (``--voxel-size`` → ``--voxel-size-um``):
    an old command line stops with exit code 2 rather than reading a number in the wrong unit.
    """

    def refuse(ctx, param, value):
        if value is not None:
            raise click.UsageError(f"{old} is now {new} ({what}); write {new} {value}")
        return value

    return option(old, "_renamed_" + old.lstrip("-").replace("-", "_"), hidden=True, default=None,
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
            command = option(f"--voxel-size-{u}", f"voxel_size_{u}", type=FiniteFloatRange(min=0, min_open=True),
                                   default=None, help=text)(command)
        return command

    return deco
