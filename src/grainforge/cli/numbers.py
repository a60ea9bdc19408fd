"""The number types of the command line's options: lists of numbers, and floats that refuse ``nan`` and ``inf``."""

from __future__ import annotations

import math

import click

__all__ = ["FloatList", "FiniteFloatRange", "FiniteFloat", "FINITE_FLOAT"]


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
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


class FiniteFloat(click.ParamType):
    """A float option without a range that refuses ``nan``, ``inf`` and ``-inf`` (one line, exit code 2).

    Its help shows no range (``FiniteFloatRange()`` without bounds would show ``(-inf, inf)``); a number is read
    as ``click.FLOAT`` reads it.
    """

    name = "float"

    def convert(self, value, param, ctx):
        rv = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return rv


#: the type of a float option without a range
FINITE_FLOAT = FiniteFloat()
