"""Population recipes: TOML text parsed and checked into a :class:`Recipe` (docs/populations.md).

A *recipe* describes a population: the method, each parameter either fixed or
drawn from a distribution, a size distribution (a grading curve given as sieve
sizes and percent passing, a lognormal, or one fixed size), the count, the
root seed and the output format::

    method = "fso"
    count = 200
    seed = 2024
    format = "stl"

    [params]
    fractal_dimension = { distribution = "uniform", low = 2.2, high = 2.6 }
    length_ratio = 7.0
    subdivisions = 4
    # a ratio L:I:S = 1 : e : e·f drawn per grain from Zingg ratios e = I/L, f = S/I
    aspect = { distribution = "zingg", elongation = { distribution = "truncnormal", mean = 0.75, sd = 0.1, low = 0.4, high = 1.0 }, flatness = 0.8 }

    [size]
    definition = "sieve"            # equivalent | sieve | longest
    sieves_mm = [0.15, 0.3, 0.6, 1.18, 2.36]
    percent_passing = [0, 10, 50, 90, 100]
    basis = "mass"                  # mass (as a sieve analysis reports) | count

Parameter ranges are never repeated here: every value and every distribution
bound is checked against the method's ``Params`` specs
(:func:`grainforge.params.specs`).  Errors (:class:`RecipeError`) name the TOML
field and its line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..fabrication.scale import SIZE_DEFINITIONS
from ..io import FORMATS
from ..params import ParameterError, ParamSpec, specs
from .distributions import Distribution, FixedSize, GradingCurve, LognormalSize

DISTRIBUTIONS = ("uniform", "normal", "truncnormal", "lognormal", "choice", "zingg")
_DIST_KEYS = {
    "uniform": ("low", "high"),
    "normal": ("mean", "sd"),
    "truncnormal": ("mean", "sd", "low", "high"),
    "lognormal": ("median", "sigma"),
    "choice": ("values",),
    "zingg": ("elongation", "flatness"),
}
_TOP_KEYS = ("method", "count", "seed", "format", "params", "size", "grains")


class RecipeError(InputError):
    """A recipe field is missing or invalid.

    Attributes
    ----------
    field : str
        Dotted TOML path, e.g. ``params.fractal_dimension.high``.
    line : int or None
        1-based line of the field in the recipe file (``None`` if absent).
    """

    def __init__(self, source: str, field: str, reason: str, line: int | None = None):
        self.source = source
        self.field = field
        self.reason = reason
        self.line = line
        where = f"{source}:{line}" if line else source
        super().__init__(f"{where}: {field}: {reason}")

    def __reduce__(self):
        """Rebuild from the constructor's arguments: a worker's error crosses the process pool intact.

        Examples
        --------
        >>> import pickle
        >>> e = pickle.loads(pickle.dumps(RecipeError("r.toml", "count", "too big", 2)))
        >>> str(e), e.field, e.line
        ('r.toml:2: count: too big', 'count', 2)
        """
        return (type(self), (self.source, self.field, self.reason, self.line))


_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*((?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*')(?:\s*\.\s*(?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*'))*)\s*=""")


def _split_key(text: str) -> tuple[str, ...]:
    parts = re.findall(r"""[A-Za-z0-9_-]+|"[^"]*"|'[^']*'""", text)
    return tuple(p.strip("\"'") for p in parts)


def field_line(text: str, path: Sequence[str]) -> int | None:
    """The 1-based line of the TOML field ``path`` (or of its nearest enclosing key).

    ``tomllib`` keeps no positions, so the source is scanned: table headers
    set the current table, ``key =`` lines define keys, and the line whose
    full key is the longest prefix of ``path`` wins (a field inside an inline
    table is reported at its key's line).

    Parameters
    ----------
    text : str
        The recipe's TOML text.
    path : sequence of str
        The field's dotted path, one key per element (``["params", "D", "low"]``).

    Returns
    -------
    int or None
        The line, from 1; None where no key of the path is in the text.

    Examples
    --------
    >>> src = 'method = "fso"\\n[params]\\nD = { distribution = "uniform", low = 2 }\\n'
    >>> field_line(src, ["params", "D", "low"]), field_line(src, ["method"]), field_line(src, ["count"])
    (3, 1, None)
    """
    path = tuple(path)
    table: tuple[str, ...] = ()
    best, best_len = None, 0
    for no, line in enumerate(text.splitlines(), start=1):
        m = _HEADER.match(line)
        if m and "=" not in m.group(1):
            table = _split_key(m.group(1))
            full = table
        else:
            m = _KEY.match(line)
            if not m:
                continue
            full = table + _split_key(m.group(1))
        n = len(full)
        if n > best_len and path[:n] == full:
            best, best_len = no, n
    return best


@dataclass(frozen=True)
class Recipe:
    """A validated population recipe (see the module docstring for the format)."""

    method: str
    count: int
    seed: int
    format: str
    params: Mapping[str, Any]  # name -> fixed value or Distribution
    size: Any  # FixedSize | LognormalSize | GradingCurve
    size_definition: str
    sampling: str = "quasi"
    text: str = field(default="", repr=False)
    source: str = "<recipe>"
    #: ``[grains]``: parameter name (or ``size_mm``) -> one fixed value per grain, in grain order
    grains: Mapping[str, tuple] = field(default_factory=dict, repr=False)

    @property
    def digest(self) -> str:
        """SHA-256 of the recipe text (identifies the batch for ``--resume``)."""
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()

    def file_name(self, index: int) -> str:
        """The file grain ``index`` is written to.

        Parameters
        ----------
        index : int
            The grain's index, from 0.

        Returns
        -------
        str
            ``METHOD-NNNN.FORMAT`` (:func:`grainforge.population.generate.grain_file_name`).
        """
        from .generate import grain_file_name

        return grain_file_name(self.method, index, self.format)


def load_recipe(path: str | os.PathLike) -> Recipe:
    """Read and validate a TOML recipe file.

    Parameters
    ----------
    path : str or os.PathLike
        The recipe file (UTF-8 TOML).

    Returns
    -------
    Recipe
        Its ``source`` the path, its ``text`` the file's text.

    Raises
    ------
    RecipeError
        Naming the field (dotted TOML path) and its line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read recipe ({exc})") from None
    return parse_recipe(text, source=str(path))


def parse_recipe(text: str, source: str = "<recipe>") -> Recipe:
    """Validate recipe ``text``; see :func:`load_recipe`.

    Parameters
    ----------
    text : str
        The recipe's TOML text (the format: the module's docstring).
    source : str
        What errors name as the recipe (a file's path).

    Returns
    -------
    Recipe

    Raises
    ------
    RecipeError
        Naming the field (dotted TOML path) and its line.

    Examples
    --------
    >>> r = parse_recipe('method = "fso"\\ncount = 3\\nseed = 1\\n[size]\\nmm = 2.0\\n')
    >>> r.method, r.count, r.size
    ('fso', 3, FixedSize(mm=2.0))
    >>> parse_recipe('method = "fso"\\ncount = 0\\nseed = 1\\n')
    Traceback (most recent call last):
    ...
    grainforge.population.recipe.RecipeError: <recipe>:2: count: must be a whole number >= 1, got 0
    """
    from ..methods import METHODS, get

    def fail(path: Sequence[str], reason: str):
        raise RecipeError(source, ".".join(path), reason, field_line(text, path))

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise RecipeError(source, "TOML", str(exc), int(m.group(1)) if m else None) from None

    for key in data:
        if key not in _TOP_KEYS:
            fail([key], f"unknown field (expected {', '.join(_TOP_KEYS)})")
    if "method" not in data:
        fail(["method"], f"is required (one of {', '.join(sorted(METHODS))})")
    method = data["method"]
    if not isinstance(method, str) or method not in METHODS:
        fail(["method"], f"must be one of {', '.join(sorted(METHODS))}, got {method!r}")
    count = _whole(data, "count", 1, fail, required=True)
    seed = _whole(data, "seed", 0, fail, required=True)
    fmt = data.get("format", "stl")
    if fmt not in FORMATS:
        fail(["format"], f"must be one of {', '.join(FORMATS)}, got {fmt!r}")

    module = get(method)
    pspecs = {s.name: s for s in specs(module.Params)}
    raw_params = data.get("params", {})
    if not isinstance(raw_params, dict):
        fail(["params"], "must be a table of parameter = value or { distribution = ... }")
    params: dict[str, Any] = {}
    for name, value in raw_params.items():
        if name not in pspecs:
            fail(["params", name], f"is not a {method} parameter (expected one of {', '.join(pspecs)})")
        params[name] = _param_value(pspecs[name], value, ["params", name], fail)
    typical = {k: (v.typical() if isinstance(v, Distribution) else v) for k, v in params.items()}
    try:
        module.Params(**typical)
    except ParameterError as exc:
        bad = exc.name if exc.name in params else next(iter(params), exc.name)
        fail(["params", bad], exc.reason)
    grains = _grains(data.get("grains"), pspecs, typical, module.Params, count, method, fail)

    raw_size = data.get("size")
    if "size_mm" in grains:  # sizes per grain: [size] may only say what the sizes mean
        if not isinstance(raw_size, (dict, type(None))) or set(raw_size or {}) - {"definition"}:
            fail(["size"], "with grains.size_mm, [size] may only give definition")
        size, definition = _size({"mm": 1.0, **(raw_size or {})}, fail)
    else:
        size, definition = _size(raw_size, fail)
    sampling = (data.get("size") or {}).get("sampling", "quasi")
    if sampling not in ("quasi", "random"):
        fail(["size", "sampling"], f"must be \"quasi\" or \"random\", got {sampling!r}")
    return Recipe(method=method, count=count, seed=seed, format=fmt, params=params, size=size,
                  size_definition=definition, sampling=sampling, text=text, source=source, grains=grains)


#: ``[grains]`` columns that are not generator parameters: each grain's size, and its own seed (instead of the
#: one drawn from the recipe's root seed; ``grainforge fit`` writes it for twins it made with another seed)
GRAIN_COLUMNS = ("size_mm", "seed")


def _grains(raw, pspecs, typical, params_type, count, method, fail) -> dict[str, tuple]:
    """``[grains]``: one fixed value per grain for some parameters (and ``size_mm``), each checked,
    and each grain's whole parameter set checked by the method (as ``grainforge fit`` writes twins)."""
    if raw is None:
        return {}
    if not isinstance(raw, dict) or not raw:
        fail(["grains"], "must be a table of name = [one value per grain]")
    from ..fabrication.scale import MAX_SIZE_MM, MIN_SIZE_MM

    out: dict[str, tuple] = {}
    for name, values in raw.items():
        if name not in GRAIN_COLUMNS and name not in pspecs:
            fail(["grains", name], f"is not a {method} parameter, size_mm or seed (expected one of "
                                   f"{', '.join(list(pspecs) + list(GRAIN_COLUMNS))})")
        if not isinstance(values, list) or len(values) != count:
            fail(["grains", name], f"must be a list of count = {count} values, one per grain, got "
                                   f"{len(values) if isinstance(values, list) else type(values).__name__}")
        checked = []
        for i, v in enumerate(values):
            if isinstance(v, dict) or (isinstance(v, list) and any(isinstance(x, dict) for x in v)):
                fail(["grains", name], f"grain {i}: must be a fixed value, not a distribution")
            if name == "size_mm":
                if not (_number(v) and MIN_SIZE_MM <= v <= MAX_SIZE_MM):
                    fail(["grains", name], f"grain {i}: must be in [{MIN_SIZE_MM:g}, {MAX_SIZE_MM:g}] mm, got {v!r}")
                checked.append(float(v))
            elif name == "seed":
                if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**63):
                    fail(["grains", name], f"grain {i}: must be a whole number in [0, 2^63), got {v!r}")
                checked.append(int(v))
            else:
                try:
                    checked.append(pspecs[name].check(v))
                except ParameterError as exc:
                    fail(["grains", name], f"grain {i}: {exc.reason}")
        out[name] = tuple(checked)
    names = [n for n in out if n not in GRAIN_COLUMNS]
    for i in range(count if names else 0):
        try:
            params_type(**{**typical, **{n: out[n][i] for n in names}})
        except ParameterError as exc:
            fail(["grains", exc.name if exc.name in out else names[0]], f"grain {i}: {exc.reason}")
    return out


def _whole(data, key, low, fail, required=False):
    if key not in data:
        if required:
            fail([key], "is required")
        return None
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        fail([key], f"must be a whole number >= {low}, got {v!r}")
    return v


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _param_value(spec: ParamSpec, value: Any, path: list[str], fail) -> Any:
    if spec.kind == "floats" and isinstance(value, list) and any(isinstance(x, dict) for x in value):
        return _each(spec, value, path, fail)
    if not isinstance(value, dict):
        try:
            return spec.check(value)
        except ParameterError as exc:
            fail(path, exc.reason)
    kind = value.get("distribution")
    if kind not in DISTRIBUTIONS:
        fail(path + ["distribution"], f"must be one of {', '.join(DISTRIBUTIONS)}, got {kind!r}")
    expected = _DIST_KEYS[kind] + (("weights",) if kind == "choice" else ())
    for k in value:
        if k != "distribution" and k not in expected:
            fail(path + [k], f"is not a field of a {kind} distribution (expected {', '.join(expected)})")
    for k in _DIST_KEYS[kind]:
        if k not in value:
            fail(path + [k], f"is required for a {kind} distribution")
    if kind == "choice":
        return _choice(spec, value, path, fail)
    if kind == "zingg":
        return _zingg(spec, value, path, fail)
    if spec.kind in ("str", "floats") or (spec.kind == "int" and kind != "uniform"):
        fail(path + ["distribution"], f"{spec.name} is {spec.kind}-valued: use a fixed value or choice"
             + (" or uniform" if spec.kind == "int" else "") + (" or zingg" if spec.kind == "floats" else ""))
    args = {}
    for k in _DIST_KEYS[kind]:
        v = value[k]
        if not _number(v):
            fail(path + [k], f"must be a finite number, got {v!r}")
        args[k] = float(v) if spec.kind != "int" else v
    if spec.kind == "int":
        for k in ("low", "high"):
            if not isinstance(args[k], int):
                fail(path + [k], f"must be a whole number ({spec.name} is an integer), got {args[k]!r}")
    if kind in ("uniform", "truncnormal") and not args["low"] < args["high"]:
        fail(path + ["high"], f"must be greater than low ({args['low']!r}), got {args['high']!r}")
    for k in ("sd", "sigma"):
        if k in args and not args[k] > 0:
            fail(path + [k], f"must be positive, got {args[k]!r}")
    if kind == "lognormal" and not args["median"] > 0:
        fail(path + ["median"], f"must be positive, got {args['median']!r}")
    if kind == "truncnormal" and not args["low"] <= args["mean"] <= args["high"]:
        fail(path + ["mean"], f"must lie in [low, high] = [{args['low']}, {args['high']}], got {args['mean']!r}")
    dist = Distribution(kind, args, integer=spec.kind == "int")
    lo, hi = dist.support()
    for bound, key in ((lo, "low"), (hi, "high")):
        if math.isfinite(bound):
            try:
                spec.check(bound)
            except ParameterError as exc:
                fail(path + [key] if key in args else path, exc.reason)
        elif (key == "low" and spec.low is not None) or (key == "high" and spec.high is not None):
            fail(path + ["distribution"], f"{kind} is unbounded but {spec.name} must be in {spec.range_text()}: "
                 "use truncnormal with low/high inside that range")
    if kind == "lognormal" and spec.low is not None and spec.low > 0:
        fail(path + ["distribution"], f"lognormal reaches 0 but {spec.name} must be in {spec.range_text()}")
    return dist


#: the support of a Zingg ratio (elongation I/L, flatness S/I)
_RATIO = {"low": 0.0, "high": 1.0, "low_open": True, "kind": "float", "default": None, "help": "Zingg ratio"}


def _zingg(spec: ParamSpec, value: Mapping, path: list[str], fail) -> Distribution:
    """``{ distribution = "zingg", elongation = ..., flatness = ... }`` for a three-number ratio L:I:S.

    Each ratio is a number in (0, 1] or a (non-choice) distribution whose
    support lies in (0, 1]; the extreme ratios 1 : e : e·f are checked
    against ``spec``'s range before anything is generated.
    """
    if spec.kind != "floats":
        fail(path + ["distribution"], f"zingg gives a ratio L:I:S; {spec.name} is {spec.kind}-valued")
    parts = {}
    for key in ("elongation", "flatness"):
        v = value[key]
        if isinstance(v, dict) and v.get("distribution") in ("choice", "zingg"):
            fail(path + [key, "distribution"], f"must be one of uniform, normal, truncnormal, lognormal, got "
                 f"{v.get('distribution')!r}")
        parts[key] = _param_value(ParamSpec(name=key, **_RATIO), v, path + [key], fail)
    bounds = {k: (v.support() if isinstance(v, Distribution) else (v, v)) for k, v in parts.items()}
    (e_lo, e_hi), (f_lo, f_hi) = bounds["elongation"], bounds["flatness"]
    for e, f in ((e_lo, f_lo), (e_hi, f_hi), (e_lo, f_hi), (e_hi, f_lo)):
        try:
            spec.check((1.0, e, e * f))
        except ParameterError as exc:
            fail(path, f"the ratio 1:{e:g}:{e * f:g} reachable from these distributions is invalid: {exc.reason}")
    return Distribution("zingg", parts)


def _each(spec: ParamSpec, value: list, path: list[str], fail) -> Distribution:
    """A list of numbers drawn element by element: each a number or a scalar distribution in ``spec``'s range."""
    items = []
    for i, v in enumerate(value):
        if isinstance(v, dict) and v.get("distribution") in ("choice", "zingg"):
            fail(path + [str(i), "distribution"], "an element must be one of uniform, normal, truncnormal, lognormal, "
                 f"got {v.get('distribution')!r}")
        element = dataclasses.replace(spec, name=f"{spec.name}[{i}]", kind="float", default=None)
        items.append(_param_value(element, v, path + [str(i)], fail))
    return Distribution("each", {"items": tuple(items)})


def _choice(spec: ParamSpec, value: Mapping, path: list[str], fail) -> Distribution:
    values = value["values"]
    if not isinstance(values, list) or not values:
        fail(path + ["values"], "must be a non-empty list")
    checked = []
    for v in values:
        try:
            checked.append(spec.check(v))
        except ParameterError as exc:
            fail(path + ["values"], exc.reason)
    weights = value.get("weights", [1.0] * len(values))
    if (not isinstance(weights, list) or len(weights) != len(values)
            or not all(_number(w) and w >= 0 for w in weights) or sum(weights) <= 0):
        fail(path + ["weights"], f"must be {len(values)} non-negative numbers with a positive sum, got {weights!r}")
    total = float(sum(weights))
    return Distribution("choice", {"values": tuple(checked), "weights": tuple(float(w) / total for w in weights)})


#: largest lognormal sigma of a size distribution (sizes spread over a factor e^(±8.3σ) at the extreme quantiles)
MAX_SIGMA = 1.5


def _size(raw, fail):
    if raw is None:
        return FixedSize(10.0), "equivalent"
    if not isinstance(raw, dict):
        fail(["size"], "must be a table")
    allowed = ("definition", "mm", "distribution", "median_mm", "sigma", "sieves_mm", "percent_passing", "basis",
               "sampling")
    for k in raw:
        if k not in allowed:
            fail(["size", k], f"unknown field (expected {', '.join(allowed)})")
    definition = raw.get("definition", "equivalent")
    if definition not in SIZE_DEFINITIONS:
        fail(["size", "definition"], f"must be one of {', '.join(SIZE_DEFINITIONS)}, got {definition!r}")
    modes = [m for m in ("mm", "distribution", "sieves_mm") if m in raw]
    if len(modes) != 1:
        fail(["size"], "give exactly one of mm (fixed), distribution = \"lognormal\", or sieves_mm + percent_passing")
    from ..fabrication.scale import MAX_SIZE_MM, MIN_SIZE_MM

    def in_size_range(key, value):
        if not MIN_SIZE_MM <= value <= MAX_SIZE_MM:
            fail(["size", key], f"must be in [{MIN_SIZE_MM:g}, {MAX_SIZE_MM:g}] mm, got {value!r}")

    if "mm" in raw:
        if not (_number(raw["mm"]) and raw["mm"] > 0):
            fail(["size", "mm"], f"must be a positive number of millimetres, got {raw['mm']!r}")
        in_size_range("mm", raw["mm"])
        return FixedSize(float(raw["mm"])), definition
    if "distribution" in raw:
        if raw["distribution"] != "lognormal":
            fail(["size", "distribution"], f"must be \"lognormal\" (or use sieves_mm), got {raw['distribution']!r}")
        for k in ("median_mm", "sigma"):
            if k not in raw:
                fail(["size", k], "is required for a lognormal size")
            if not (_number(raw[k]) and raw[k] > 0):
                fail(["size", k], f"must be a positive number, got {raw[k]!r}")
        in_size_range("median_mm", raw["median_mm"])
        if raw["sigma"] > MAX_SIGMA:
            fail(["size", "sigma"], f"must be at most {MAX_SIGMA:g} (a spread of e^sigma), got {raw['sigma']!r}")
        return LognormalSize(float(raw["median_mm"]), float(raw["sigma"])), definition
    sieves, passing = raw["sieves_mm"], raw.get("percent_passing")
    if passing is None:
        fail(["size", "percent_passing"], "is required with sieves_mm")
    if not isinstance(sieves, list) or len(sieves) < 2 or not all(_number(s) and s > 0 for s in sieves):
        fail(["size", "sieves_mm"], f"must be a list of at least 2 positive sizes, got {sieves!r}")
    if any(b <= a for a, b in zip(sieves, sieves[1:])):
        fail(["size", "sieves_mm"], "must be strictly increasing")
    for v in (sieves[0], sieves[-1]):
        in_size_range("sieves_mm", v)
    if not isinstance(passing, list) or len(passing) != len(sieves) or not all(_number(p) for p in passing):
        fail(["size", "percent_passing"], f"must be {len(sieves)} numbers, one per sieve, got {passing!r}")
    if any(b < a for a, b in zip(passing, passing[1:])):
        fail(["size", "percent_passing"], "must not decrease with sieve size")
    if passing[0] != 0 or passing[-1] != 100:
        fail(["size", "percent_passing"], "must start at 0 and end at 100 (add the sieves that pass none and all)")
    basis = raw.get("basis", "mass")
    if basis not in ("mass", "count"):
        fail(["size", "basis"], f"must be \"mass\" or \"count\", got {basis!r}")
    return GradingCurve(tuple(float(s) for s in sieves), tuple(float(p) for p in passing), basis), definition
