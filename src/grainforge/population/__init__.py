"""Populations of grains: TOML recipes, per-grain seeds, and executors (local, Dask).

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
(:func:`grainforge.params.specs`).  Errors name the TOML field and its line.

Seeds
-----
Grain ``i`` owns the stream ``default_rng(SeedSequence(root, spawn_key=(i,)))``
— the ``i``-th child of ``SeedSequence(root).spawn(...)`` — which depends on
the root seed and ``i`` alone.  From it, in this order: the grain's own 63-bit
seed (recorded in the manifest; ``grainforge.generate(method, params, seed)``
regenerates the grain), then one draw for each distributed parameter in the
order of the method's ``Params`` fields (two for a ``zingg`` ratio:
elongation, then flatness), then the size.  So outputs do not
depend on the number of workers or on the executor.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import re
import shutil
import tomllib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..fabrication.scale import SIZE_DEFINITIONS
from ..io import FORMATS, atomic_write, write_csv
from ..params import ParameterError, ParamSpec, specs
from .distributions import Distribution, FixedSize, GradingCurve, LognormalSize

__all__ = [
    "RecipeError",
    "Distribution",
    "GradingCurve",
    "LognormalSize",
    "FixedSize",
    "Recipe",
    "load_recipe",
    "parse_recipe",
    "grain_stream",
    "draw_grain",
    "make_grain",
    "run_batch",
    "JOURNAL",
]

#: hidden folder inside the output folder: recipe copy and one sidecar per finished grain.
JOURNAL = ".grainforge-batch"
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


class RecipeError(ValueError):
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


# --------------------------------------------------------------------------- line numbers
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


# --------------------------------------------------------------------------- recipe
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
        from .generate import grain_file_name

        return grain_file_name(self.method, index, self.format)


def load_recipe(path: str | os.PathLike) -> Recipe:
    """Read and validate a TOML recipe file.

    Raises
    ------
    RecipeError
        Naming the field (dotted TOML path) and its line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read recipe ({exc})") from None
    return parse_recipe(text, source=str(path))


def parse_recipe(text: str, source: str = "<recipe>") -> Recipe:
    """Validate recipe ``text``; see :func:`load_recipe`.

    Examples
    --------
    >>> r = parse_recipe('method = "fso"\\ncount = 3\\nseed = 1\\n[size]\\nmm = 2.0\\n')
    >>> r.method, r.count, r.size
    ('fso', 3, FixedSize(mm=2.0))
    >>> parse_recipe('method = "fso"\\ncount = 0\\nseed = 1\\n')
    Traceback (most recent call last):
    ...
    grainforge.population.RecipeError: <recipe>:2: count: must be a whole number >= 1, got 0
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


# --------------------------------------------------------------------------- per-grain work
def grain_stream(root_seed: int, index: int) -> np.random.Generator:
    """Grain ``index``'s own random stream: child ``index`` of ``SeedSequence(root_seed)``.

    Examples
    --------
    >>> a = grain_stream(7, 3).random()
    >>> b = np.random.default_rng(np.random.SeedSequence(7).spawn(4)[3]).random()
    >>> a == b
    True
    """
    return np.random.default_rng(np.random.SeedSequence(root_seed, spawn_key=(index,)))


def draw_grain(recipe: Recipe, index: int) -> tuple[int, Any, float]:
    """Grain ``index``'s seed, Params and size (mm), from its own stream only."""
    from ..methods import get

    params_type = get(recipe.method).Params
    rng = grain_stream(recipe.seed, index)
    seed = int(rng.integers(0, 2**63))
    values = {}
    for spec in specs(params_type):
        v = recipe.params.get(spec.name)
        if spec.name in recipe.grains:  # one value per grain ([grains]): nothing drawn
            values[spec.name] = recipe.grains[spec.name][index]
        elif isinstance(v, Distribution):
            values[spec.name] = v.draw(rng)
        elif spec.name in recipe.params:
            values[spec.name] = v
    size = recipe.size.sample(size_quantile(recipe, index, float(rng.random())))
    if "size_mm" in recipe.grains:
        size = recipe.grains["size_mm"][index]
    if "seed" in recipe.grains:  # the grain's own seed; the stream above is still drawn, so nothing else moves
        seed = recipe.grains["seed"][index]
    try:
        params = params_type(**values)
    except ParameterError as exc:
        raise ValueError(f"grain {index}: drawn params.{exc.name} {exc.reason}") from None
    return seed, params, size


_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def size_quantile(recipe: Recipe, index: int, u: float) -> float:
    """The size quantile of grain ``index`` given its own uniform draw ``u``.

    With ``sampling = "random"`` it is ``u`` (independent draws).  With
    ``sampling = "quasi"`` (the default) it is ``frac(c + index·g + u/count)``
    where ``g = (√5 − 1)/2`` and ``c`` comes from the root seed: a jittered
    golden-ratio (Kronecker) sequence, whose every prefix covers [0, 1]
    evenly, so the achieved grading follows the target far more closely
    than independent draws do (error ~1/count instead of ~1/√count).  It
    still depends only on the root seed, ``index``, ``count`` and grain
    ``index``'s own stream.

    Examples
    --------
    >>> r = parse_recipe('method = "fso"\\ncount = 4\\nseed = 3\\n[size]\\nmm = 1.0\\n')
    >>> qs = [size_quantile(r, i, 0.5) for i in range(4)]
    >>> sorted(int(q * 4) for q in qs)
    [0, 1, 2, 3]
    """
    if recipe.sampling == "random":
        return u
    c = int(np.random.SeedSequence(recipe.seed).generate_state(1, np.uint64)[0]) / 2.0**64
    return math.fmod(c + math.fmod(index * _GOLDEN, 1.0) + u / recipe.count, 1.0)


@dataclass(frozen=True)
class GrainResult:
    """What a worker sends back: the file name, its bytes and its manifest row."""

    index: int
    name: str
    data: bytes
    row: dict


def make_grain(recipe: Recipe, index: int) -> GrainResult:
    """Generate, scale, measure and encode grain ``index`` (pure: writes nothing).

    Runs in a worker process (local pool or Dask); the client writes the file.
    """
    from .generate import encode_grain

    seed, params, size = draw_grain(recipe, index)
    name = recipe.file_name(index)
    try:
        data, row = encode_grain(recipe.method, params, seed, name, fmt=recipe.format, size=size,
                                 size_definition=recipe.size_definition)
    except ParameterError as exc:
        raise ValueError(f"grain {index} (seed {seed}): params.{exc.name} {exc.reason}") from None
    row["sha256"] = hashlib.sha256(data).hexdigest()
    # JSON round trip: a row read back from a sidecar is identical to a fresh one.
    return GrainResult(index, name, data, json.loads(json.dumps(row)))


# --------------------------------------------------------------------------- journal
def _sidecar(out: Path, index: int) -> Path:
    return out / JOURNAL / f"grain-{index:06d}.json"


def _intact_row(out: Path, recipe: Recipe, index: int) -> dict | None:
    """The recorded row of grain ``index`` if its file is complete and intact, else None."""
    try:
        rec = json.loads(_sidecar(out, index).read_text(encoding="utf-8"))
        path = out / rec["row"]["file"]
        if rec["row"]["file"] != recipe.file_name(index) or path.stat().st_size != rec["bytes"]:
            return None
        if hashlib.sha256(path.read_bytes()).hexdigest() != rec["row"]["sha256"]:
            return None
        return rec["row"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _record(out: Path, res: GrainResult) -> None:
    atomic_write(out / res.name, res.data)
    atomic_write(_sidecar(out, res.index), json.dumps({"bytes": len(res.data), "row": res.row}, sort_keys=True))


# --------------------------------------------------------------------------- executors
def _local_results(recipe: Recipe, todo: Sequence[int], workers: int, in_process: bool) -> Iterable[GrainResult]:
    if in_process:
        for i in todo:
            yield make_grain(recipe, i)
        return
    from ..methods import METHODS
    from ..runtime.workers import close_pool, process_pool

    ex = process_pool(workers, ["grainforge.population", METHODS[recipe.method], "grainforge.population.generate",
                                "trimesh", "scipy.special"])
    ok = False
    try:
        yield from _executor_results(ex, recipe, todo, workers)
        ok = True
    finally:
        close_pool(ex, abort=not ok)


def _dask_results(recipe: Recipe, todo: Sequence[int], scheduler: str) -> Iterable[GrainResult]:
    from ..runtime.cluster import dask_executor

    with dask_executor(scheduler) as ex:
        yield from _executor_results(ex, recipe, todo, ex.workers)


def _executor_results(ex, recipe: Recipe, todo: Sequence[int], workers: int) -> Iterable[GrainResult]:
    """:func:`make_grain` of each of ``todo`` on executor ``ex`` (a process pool or a Dask cluster), in the order
    they finish, ``4 × workers`` in flight (memory does not grow with the count); the owner closes ``ex``."""
    from concurrent.futures import FIRST_COMPLETED, wait

    from ..runtime.workers import single_threaded_children

    it = iter(todo)
    ahead = 4 * workers
    pending: set = set()
    try:
        with single_threaded_children():  # local workers (and the fork server) start during submit
            pending = {ex.submit(make_grain, recipe, i) for i in itertools.islice(it, ahead)}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            pending |= {ex.submit(make_grain, recipe, i) for i in itertools.islice(it, len(done))}
            for f in sorted(done, key=lambda f: f.exception() is None):
                yield f.result()
    finally:
        for f in pending:  # an error or interrupt: the grains not started are dropped
            f.cancel()


def check_recipe_size(recipe: Recipe, workers: int = 1) -> float:
    """Refuse a recipe whose population would take more than a day (estimated from grain 0's parameters)."""
    from ..runtime.estimate import check_job, grain_seconds

    _, params, _ = draw_grain(recipe, 0)
    return check_job(recipe.count, grain_seconds(recipe.method, params),
                     what=f"{recipe.source}: {recipe.count} {recipe.method} grains",
                     option="count (or split the population into several batches)", workers=workers)


#: grains made at the ends of every distribution before a batch starts
PILOTS = 3


def check_extremes(recipe: Recipe) -> None:
    """Make grains 0, 1, 2 with each distributed parameter at each end of its range (pilot grains, nothing written).

    A parameter's declared range is checked when the recipe is read; some
    limits depend on the grain itself (e.g. an FSO amplitude too large for
    the grain to stay star-shaped).  This catches a distribution reaching such
    values before any work, instead of failing at grain 517.

    Raises
    ------
    RecipeError
        Naming ``params.NAME``, the value and the reason.
    """
    import dataclasses

    from ..methods import generate

    varying = {k: v for k, v in recipe.params.items() if isinstance(v, Distribution)}
    if not varying:
        return
    for index in range(min(PILOTS, recipe.count)):
        make_grain(recipe, index)  # the grain as drawn: its own error (fixed parameters) names it
        seed, params, _ = draw_grain(recipe, index)
        for name, dist in varying.items():
            for value in _extremes(dist):
                try:
                    generate(recipe.method, dataclasses.replace(params, **{name: value}), seed)
                except ParameterError as exc:
                    raise RecipeError(recipe.source, f"params.{name}",
                                      f"the distribution reaches {value!r}, where grain {index} cannot be made "
                                      f"({exc.reason}); narrow the distribution") from None


def _extremes(dist: Distribution) -> list:
    """The finite extreme values ``dist`` can draw: a choice's values, an interval's ends, and for
    ``zingg`` and ``each`` every combination of their parts' ends (infinite ends left out).

    Examples
    --------
    >>> e = Distribution("uniform", {"low": 0.5, "high": 0.9})
    >>> _extremes(Distribution("zingg", {"elongation": e, "flatness": 0.8}))
    [(1.0, 0.5, 0.4), (1.0, 0.9, 0.7200000000000001)]
    >>> _extremes(Distribution("each", {"items": (0.0, e)}))
    [(0.0, 0.5), (0.0, 0.9)]
    """
    import itertools

    def ends(x) -> list:
        if not isinstance(x, Distribution):
            return [x]
        if x.kind == "choice":
            return list(x.args["values"])
        return [v for v in x.support() if math.isfinite(v)]

    if dist.kind == "zingg":
        combos = itertools.product(ends(dist.args["elongation"]), ends(dist.args["flatness"]))
        values = [(1.0, e, e * f) for e, f in combos]
    elif dist.kind == "each":
        values = list(itertools.product(*(ends(x) for x in dist.args["items"])))
    else:
        values = ends(dist)
    return list(dict.fromkeys(values))


def existing_grains(out: Path, recipe: Recipe) -> bool:
    """Whether ``out`` holds a grain file of this recipe's naming (listing the folder, not every name)."""
    from .generate import existing_outputs

    return any(p.name != "manifest.csv" for p in existing_outputs(out, recipe.method, recipe.count, recipe.format))


def run_batch(
    recipe: Recipe,
    out: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: Callable[[Iterable], Iterable] | None = None,
    report: bool = True,
    in_process: bool | None = None,
) -> dict[str, Any]:
    """Generate the population of ``recipe`` into ``out``.

    Every grain is generated by :func:`make_grain` in a worker (a local
    process pool of ``workers`` processes, default the CPU count, or the Dask
    cluster at ``scheduler``), then written atomically by this process
    together with a sidecar (byte size and SHA-256) in ``out/.grainforge-batch``.
    At the end ``manifest.csv`` (rows in grain order), its companion
    ``manifest.json`` (summary statistics) and ``population.png`` are written.

    Parameters
    ----------
    resume : bool
        Keep every grain whose file matches its sidecar; generate the rest.
        The recipe must be the one the interrupted batch used.
    overwrite : bool
        Replace existing outputs (regenerates everything).
    in_process : bool, optional
        Generate in this process instead of a pool (default: only when
        ``workers`` is 1).  The bytes are the same either way; a pool worker
        runs NumPy's BLAS single-threaded, this process does not.

    Returns
    -------
    dict
        ``{"generated": n, "reused": m, "rows": [...], "summary": {...}}``.

    Raises
    ------
    FileExistsError
        If outputs exist and neither ``resume`` nor ``overwrite`` is given.
    ValueError
        For a recipe that does not match the interrupted batch, an unreachable
        scheduler, or a grain that cannot be made (named by index and seed).
    grainforge.runtime.cluster.SchedulerLost
        The Dask scheduler lost mid-run: the grains recorded so far stay, with
        their journal, for ``resume``.
    """
    from .generate import MANIFEST

    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    out = Path(out)
    journal = out / JOURNAL
    n_workers = 1 if scheduler else min(workers or os.cpu_count() or 1, recipe.count)
    check_recipe_size(recipe, n_workers)  # before anything: a job beyond a day is refused
    check_extremes(recipe)  # every distribution's range can make a grain (pilot grains, nothing written)
    if not resume and journal.is_dir() and not any(journal.glob("grain-*.json")) \
            and not (out / "manifest.csv").exists() \
            and not existing_grains(out, recipe):
        shutil.rmtree(journal, ignore_errors=True)  # a failed start recorded nothing: it blocks nothing
    names = [recipe.file_name(i) for i in range(recipe.count)]
    saved = journal / "recipe.toml"
    if resume and saved.exists():
        if saved.read_text(encoding="utf-8") != recipe.text:
            raise ValueError(f"{recipe.source} differs from the recipe of the batch in {out}; "
                             "resume with the same recipe or use --overwrite")
    elif not overwrite:
        existing = [out / n for n in names + [MANIFEST] if (out / n).exists()]
        if existing or journal.exists():
            first = existing[0] if existing else journal
            hint = "use --overwrite (no batch journal to resume from)" if resume else "use --resume or --overwrite"
            raise FileExistsError(f"{first} exists (not made by this batch); {hint}" if resume
                                  else f"{first} exists (a batch is already in {out}); {hint}")
    created = [q for q in [out, *out.parents] if not q.exists()]
    try:  # armed before the folder is made: a signal while it is made leaves none behind
        out.mkdir(parents=True, exist_ok=True)
        return _run_batch(recipe, out, names, workers=workers, scheduler=scheduler, resume=resume,
                          overwrite=overwrite, progress=progress, report=report, in_process=in_process)
    except BaseException:
        # a start that recorded no grain leaves nothing behind, so it never blocks a corrected rerun
        if not resume and not any(journal.glob("grain-*.json")):
            shutil.rmtree(journal, ignore_errors=True)
            for q in created:
                try:
                    q.rmdir()
                except OSError:
                    break
        raise


def _run_batch(recipe, out, names, *, workers, scheduler, resume, overwrite, progress, report, in_process):
    from .generate import MANIFEST, manifest_columns

    journal = out / JOURNAL
    saved = journal / "recipe.toml"
    for name in names + [MANIFEST]:  # leftovers of atomic writes interrupted by a kill
        for tmp in out.glob(f".{name}.*.tmp"):
            tmp.unlink(missing_ok=True)
    for tmp in journal.glob(".*.tmp"):  # the journal's own (sidecars, recipe copy): all ours
        tmp.unlink(missing_ok=True)
    if overwrite and journal.exists():
        for p in journal.glob("grain-*.json"):
            p.unlink()
    atomic_write(saved, recipe.text)

    rows: dict[int, dict] = {}
    if resume:
        for i in range(recipe.count):
            row = _intact_row(out, recipe, i)
            if row is not None:
                rows[i] = row
    reused = len(rows)
    todo = [i for i in range(recipe.count) if i not in rows]
    if scheduler:
        results = _dask_results(recipe, todo, scheduler)
    else:
        n = workers or os.cpu_count() or 1
        n = min(n, max(len(todo), 1))
        results = _local_results(recipe, todo, n, n == 1 if in_process is None else in_process)
    stream = results
    if progress is not None:
        results = progress(results)
    try:
        for res in results:
            _record(out, res)
            rows[res.index] = res.row
    finally:
        stream.close()  # on an error or interrupt: stop the workers now
    ordered = [rows[i] for i in range(recipe.count)]
    write_csv(out / MANIFEST, ordered, manifest_columns(recipe.method, ("sha256",)), units=True)
    summary = None
    if report:
        from .report import population_report

        summary = population_report(recipe, ordered, out)
    return {"generated": len(todo), "reused": reused, "rows": ordered, "summary": summary}
