"""Declaring method parameters once.

Every generator describes its parameters as a frozen dataclass whose fields
are made with :func:`param`.  The field metadata (help text, unit, valid
range) is the single source of truth: validation (:func:`validate`), the CLI
options, recipe validation and the manifest columns are all derived from it.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Demo:
...     d: float = param(2.4, "fractal dimension", low=2, high=3, high_open=True)
...     def __post_init__(self):
...         validate(self)
>>> Demo(2.5).d
2.5
>>> Demo(3.0)
Traceback (most recent call last):
...
grainforge.params.ParameterError: d must be in [2, 3), got 3.0
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any

from .errors import InputError

__all__ = [
    "ParameterError",
    "ParamSpec",
    "param",
    "validate",
    "specs",
    "as_dict",
    "format_number",
]

_KEY = "grainforge"


class ParameterError(InputError):
    """A parameter value is out of range or malformed.

    Attributes
    ----------
    name : str
        The parameter's field name (``fractal_dimension``); the CLI turns it
        into the option name (``--fractal-dimension``).
    reason : str
        The message without the name.
    """

    def __init__(self, name: str, reason: str):
        self.name = name
        self.reason = reason
        super().__init__(f"{name} {reason}", setting=name)

    def __reduce__(self):
        """Rebuild from the constructor's arguments (a worker's error crosses a process pool intact).

        Examples
        --------
        >>> import pickle
        >>> e = pickle.loads(pickle.dumps(ParameterError("amplitude", "must be <= 0.3")))
        >>> e.name, e.reason
        ('amplitude', 'must be <= 0.3')
        """
        return (type(self), (self.name, self.reason))


@dataclass(frozen=True)
class ParamSpec:
    """Metadata of one parameter field."""

    name: str
    default: Any
    help: str
    unit: str = ""
    kind: str = "float"  # "float", "int", "str", "floats" (tuple of floats)
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None
    optional: bool = False
    cli: bool = True
    shown_default: str | None = None

    @property
    def option(self) -> str:
        """The CLI option name, e.g. ``--fractal-dimension``."""
        return "--" + self.name.replace("_", "-")

    def default_text(self) -> str:
        """The default as help text: ``2.4``, ``-5/3,-5/3``, ``cube``; ``shown_default`` when the field's
        default is None but a value applies (e.g. ``amplitude``: 0.1 unless ``k`` is given); ``""`` if none.

        Returns
        -------
        str

        Examples
        --------
        >>> ParamSpec("decay", (-5 / 3, -5 / 3), "").default_text()
        '-5/3,-5/3'
        >>> ParamSpec("d", 2.4, "").default_text(), ParamSpec("n", 40, "", kind="int").default_text()
        ('2.4', '40')
        """
        if self.shown_default is not None:
            return self.shown_default
        if self.default is None:
            return ""
        if isinstance(self.default, tuple):
            return ",".join(format_number(v) for v in self.default)
        return format_number(self.default)

    def range_text(self) -> str:
        """Human-readable valid range, e.g. ``[2, 3)``.

        Returns
        -------
        str
            ``[low, high]`` with ``(``/``)`` for open or missing bounds (``-inf``/``inf``), ``one of a, b``
            for choices, ``""`` when the value is unbounded.

        Examples
        --------
        >>> ParamSpec("d", 2.4, "", low=2, high=3, high_open=True).range_text()
        '[2, 3)'
        """
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.low is None and self.high is None:
            return ""
        lo = "-inf" if self.low is None else _fmt(self.low)
        hi = "inf" if self.high is None else _fmt(self.high)
        lb = "(" if (self.low_open or self.low is None) else "["
        rb = ")" if (self.high_open or self.high is None) else "]"
        return f"{lb}{lo}, {hi}{rb}"

    def check(self, value: Any) -> Any:
        """Return the normalised value or raise :class:`ParameterError`.

        Parameters
        ----------
        value : object
            The value given for the parameter: a number for ``kind="float"``/``"int"``, a string for
            ``"str"``, an iterable of numbers for ``"floats"``, or None.

        Returns
        -------
        float, int, str, tuple of float or None
            The value converted to the spec's kind (``None`` only for an optional parameter).

        Raises
        ------
        ParameterError
            If the value is missing but required, of the wrong type, not finite, not a whole number
            (``kind="int"``), outside the range, or not one of ``choices``.

        Examples
        --------
        >>> ParamSpec("n", 40, "", kind="int", low=1).check(12.0)
        12
        """
        if value is None:
            if self.optional:
                return None
            raise ParameterError(self.name, "is required")
        if self.kind == "str":
            if not isinstance(value, str):
                raise ParameterError(self.name, f"must be a string, got {value!r}")
            if self.choices and value not in self.choices:
                raise ParameterError(self.name, f"must be {self.range_text()}, got {value!r}")
            return value
        if self.kind == "floats":
            try:
                vals = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                raise ParameterError(self.name, f"must be a list of numbers, got {value!r}") from None
            for v in vals:
                self._check_number(v, value)
            return vals
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ParameterError(self.name, f"must be a number, got {value!r}")
        if self.kind == "int":
            if float(value) != int(value):
                raise ParameterError(self.name, f"must be a whole number, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        self._check_number(value, value)
        return value

    def _check_number(self, v: float, shown: Any) -> None:
        if not math.isfinite(v):
            raise ParameterError(self.name, f"must be finite, got {shown!r}")
        bad = (
            (self.low is not None and (v < self.low or (self.low_open and v == self.low)))
            or (self.high is not None and (v > self.high or (self.high_open and v == self.high)))
        )
        if bad:
            raise ParameterError(self.name, f"must be in {self.range_text()}, got {shown!r}")


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def format_number(x: Any) -> str:
    """A value as a person would write it: ``2.4``, ``10``, ``-5/3`` (a simple fraction when that is exact).

    Parameters
    ----------
    x : object
        A number (anything else, booleans included, is returned as ``str(x)``).

    Returns
    -------
    str
        An integer without decimals, else the 6-significant-digit form when it is exact to 1e-12,
        else a fraction of denominator at most 12 when that is exact, else the 6-digit form.

    Examples
    --------
    >>> [format_number(v) for v in (2.4, 10.0, -5 / 3, 1e-9, 0.1 + 0.2, "cube", 7)]
    ['2.4', '10', '-5/3', '1e-09', '0.3', 'cube', '7']
    """
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        return str(x)
    x = float(x)
    if not math.isfinite(x):
        return str(x)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    short = f"{x:.6g}"
    if math.isclose(float(short), x, rel_tol=1e-12):
        return short
    from fractions import Fraction

    frac = Fraction(x).limit_denominator(12)
    if math.isclose(float(frac), x, rel_tol=1e-12):
        return f"{frac.numerator}/{frac.denominator}"
    return short


def param(
    default: Any,
    help: str,
    *,
    unit: str = "",
    kind: str = "float",
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    choices: tuple[str, ...] | None = None,
    optional: bool = False,
    cli: bool = True,
    shown_default: str | None = None,
) -> Any:
    """Declare a parameter field with its metadata.

    Parameters
    ----------
    default : object
        Default value (``None`` for optional parameters).
    help : str
        One-line description used by ``--help``, the docs and the manifest.
    unit : str, optional
        Unit of the value (``""`` for dimensionless).
    kind : {"float", "int", "str", "floats"}
        Value type.
    low, high : float, optional
        Range bounds (``None``: unbounded on that side).
    low_open, high_open : bool, default False
        Make ``low`` / ``high`` exclusive.
    choices : tuple of str, optional
        Allowed values for ``kind="str"``.
    optional : bool
        Whether ``None`` is allowed.
    cli : bool
        Whether the CLI exposes the parameter as an option.
    shown_default : str, optional
        The default to show in help when ``default`` is None but a value
        applies unless another parameter is given (``amplitude`` vs ``k``).

    Returns
    -------
    dataclasses.Field
        The field to assign in the dataclass body; :func:`specs` reads its metadata back.
    """
    spec = dict(
        default=default, help=help, unit=unit, kind=kind, low=low, high=high,
        low_open=low_open, high_open=high_open, choices=choices,
        optional=optional or default is None, cli=cli, shown_default=shown_default,
    )
    return field(default=default, metadata={_KEY: spec})


def specs(cls_or_obj: Any) -> list[ParamSpec]:
    """The :class:`ParamSpec` of every declared field, in declaration order.

    Parameters
    ----------
    cls_or_obj : dataclass type or instance
        A method's ``Params`` class or one of its instances.

    Returns
    -------
    list of ParamSpec
        One per field made with :func:`param` (other fields are left out).
    """
    out = []
    for f in dataclasses.fields(cls_or_obj):
        meta = f.metadata.get(_KEY)
        if meta is not None:
            out.append(ParamSpec(name=f.name, **meta))
    return out


def validate(obj: Any) -> None:
    """Check and normalise every declared field of a frozen dataclass in place.

    Parameters
    ----------
    obj : dataclass instance
        A frozen dataclass whose fields were declared with :func:`param`; each such field is replaced by
        :meth:`ParamSpec.check`'s normalised value (ints as int, floats as float, lists as tuples).

    Raises
    ------
    ParameterError
        Naming the first field whose value is out of range or malformed.
    """
    for spec in specs(obj):
        value = spec.check(getattr(obj, spec.name))
        object.__setattr__(obj, spec.name, value)


def check_lengths(obj: Any, lengths: dict[str, int]) -> None:
    """Raise naming the first field of ``lengths`` that is set with the wrong number of values."""
    for name, n in lengths.items():
        value = getattr(obj, name)
        if value is not None and len(value) != n:
            raise ParameterError(name, f"must be {n} comma-separated numbers, got {value!r}")


def resolve_descriptors(obj: Any, presets: dict, default: str) -> None:
    """Set ``obj.descriptors`` from ``obj.preset`` (or the ``default`` preset when neither is given).

    Raises
    ------
    ParameterError
        If ``preset`` and ``descriptors`` are both given and disagree.
    """
    import numpy as np

    if obj.preset is not None:
        wanted = presets[obj.preset]
        if obj.descriptors is not None and not np.allclose(obj.descriptors, wanted):
            raise ParameterError("preset", f"{obj.preset} means descriptors {wanted}, which conflicts with {obj.descriptors}")
        object.__setattr__(obj, "descriptors", wanted)
    elif obj.descriptors is None:
        object.__setattr__(obj, "descriptors", presets[default])


def check_aspect(aspect, max_ratio: float) -> None:
    """Raise naming ``aspect`` unless it is None or ordered L ≥ I ≥ S with L/S ≤ ``max_ratio``.

    Examples
    --------
    >>> check_aspect((1.0, 0.5, 0.3), 100.0)
    >>> check_aspect((1.0, 0.3, 0.5), 100.0)
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: aspect must be ordered L >= I >= S, got 1:0.3:0.5
    """
    if aspect is None:
        return
    L, I, S = aspect
    if not L >= I >= S:
        raise ParameterError("aspect", f"must be ordered L >= I >= S, got {L:g}:{I:g}:{S:g}")
    if L > max_ratio * S:  # e.g. S = 5e-324 overflowed the stretching (found by the sweep)
        raise ParameterError("aspect", f"L/S must be at most {max_ratio:g}, got {L:g}:{I:g}:{S:g}")


def as_dict(obj: Any) -> dict[str, Any]:
    """The declared parameters of ``obj`` as a plain ``{name: value}`` dict.

    Parameters
    ----------
    obj : dataclass instance
        A method's parameters.

    Returns
    -------
    dict of str to object
        The fields made with :func:`param`, in declaration order.
    """
    return {s.name: getattr(obj, s.name) for s in specs(obj)}
