"""Fit a generated population to a real sand's measured shape statistics (docs/design/algorithms.md §8).

A *sand* is a table of per-grain measurements in the Sand Atlas format
(:func:`read_sand`): equivalent diameter, true sphericity, convexity,
flatness and elongation, measured on μCT voxel images of a known voxel size.
:func:`fit_sand` finds a recipe (:mod:`grainforge.population`) whose grains,
measured the same way (:func:`grainforge.analysis.atlas.atlas_descriptors`
at the same voxel size relative to each grain), match the sand: for each of
the four descriptors the two-sample Kolmogorov–Smirnov statistic
(:func:`scipy.stats.ks_2samp`) ≤ 0.1 and the mean within 0.01.

What is fitted
--------------
- **Size**: the sand's equivalent diameters become the recipe's grading
  (``[size]`` by count, equivalent definition), so every generated grain is
  voxelised at the sand's resolution for its size.
- **Aspect** (every method with an ``aspect`` L:I:S parameter): drawn per
  grain as ``{ distribution = "zingg" }`` with truncated-normal elongation
  I/L and flatness S/I; their two means and two sds are unknowns.
- **Surface knobs** (per method, :data:`FITS`): a few numbers, each with a
  mean and a per-grain spread (e.g. CRI's irregularity and roughness
  descriptors), that steer the means and spreads of sphericity and convexity.

All unknowns are solved for jointly against all eight statistics
(:data:`STATISTICS`: the mean and sd of each descriptor): a rougher grain
also measures less elongated, a flatter one less spherical, and a per-grain
spread of irregularity widens sphericity and convexity alike, so no knob can
be matched to one statistic alone.  Damped Gauss–Newton steps in a trust
region, on a finite-difference Jacobian (measured once, then Broyden
updates), with each misfit weighted by what it does to the criteria
(:func:`_weights`: a spread misfit of a narrow descriptor costs more KS than
one of a wide descriptor), on a *pilot* population whose grains keep their
seeds from round to round (common random numbers), so that the statistics
change smoothly with the settings.

A final population of ``count`` (≥ 500) grains verifies the fit; if it
misses, a correction is made from it and it is measured again
(``final_rounds`` times at most; the best is kept).

Adding a method is a few lines: :func:`register` a :class:`MethodFit` that
names its knobs and turns knob values into the recipe's ``[params]`` table.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "DESCRIPTORS", "COLUMNS", "Sand", "read_sand", "Knob", "MethodFit", "FITS", "register", "fit_sand",
    "compare", "recipe_text", "FitResult", "write_outputs", "KS_MAX", "MEAN_TOL", "STATISTICS",
    "check_sand", "fit_grains", "check_fit_size", "MIN_GRAINS", "VOXELS_ACROSS", "SPHERICITY_MAX",
]

#: the four descriptors that are matched
DESCRIPTORS = ("sphericity", "convexity", "flatness", "elongation")
#: Sand Atlas column of each quantity (units in the header; lengths in µm)
COLUMNS = {
    "equivalent_diameter": "Equivalent Diameter (µm)",
    "sphericity": "True Sphericity (-)",
    "convexity": "Convexity (-)",
    "flatness": "Flatness (-)",
    "elongation": "Elongation (-)",
}
#: optional column giving the voxel size (µm) of each grain's scan
VOXEL_COLUMN = "Voxel Size (µm)"
#: acceptance: two-sample KS statistic and |mean difference| per descriptor
KS_MAX = 0.1
MEAN_TOL = 0.01
#: finite-difference step (and trust-region unit) of the fitted aspect means
ASPECT_STEP = 0.03
#: finite-difference step and range of the fitted aspect standard deviations
ASPECT_SD_STEP = 0.02
ASPECT_SD_LOW, ASPECT_SD_HIGH = 0.005, 0.5
#: largest true sphericity accepted: measured on voxels it can exceed 1 a little (Ottawa's largest is 1.02)
SPHERICITY_MAX = 1.2
#: fewest grains a sand must have to be fitted: two samples of 50 grains of one sand already differ by a
#: KS statistic of about 0.17 (0.87·√(2/50)), beyond the 0.1 criterion; fewer grains say too little
MIN_GRAINS = 50
#: range of grain sizes, in voxels across (d_eq / voxel size), the fit measures: fewer than 5 voxels across
#: describe no shape; at 1,000 one grain's voxel image holds 10⁹ voxels
VOXELS_ACROSS = (5.0, 1000.0)
#: per-grain cost of a fit (s, one core): making the grain, plus voxelising and measuring it, which grows
#: with the cube of the voxels across (0.05 s at Ottawa's 69; docs/benchmarks.md)
FIT_GRAIN_SECONDS, FIT_VOXEL_SECONDS, FIT_ACROSS_REF = 0.1, 0.05, 69.0
#: memory of one grain's measurement, per cubed voxel across (bytes; 330 MB at 250 across, for an elongated
#: grain's larger box a factor 2 more)
FIT_VOXEL_BYTES = 48.0
#: memory the fit keeps per grain measured (its cached row)
FIT_ROW_BYTES = 300.0
#: the statistics the search matches: mean and sd of each descriptor
STATISTICS = tuple(f"{q} {k}" for k in DESCRIPTORS for q in ("mean", "sd"))


# --------------------------------------------------------------------------- the sand
@dataclass(frozen=True)
class Sand:
    """Per-grain measurements of a sand (lengths in µm)."""

    name: str
    voxel_size: float  # µm
    equivalent_diameter: np.ndarray
    values: Mapping[str, np.ndarray]  # descriptor -> (n,)

    @property
    def count(self) -> int:
        return len(self.equivalent_diameter)

    def table(self) -> np.ndarray:
        """(n, 4) array of :data:`DESCRIPTORS`."""
        return np.column_stack([self.values[k] for k in DESCRIPTORS])


def _norm(header: str) -> str:
    return " ".join(header.replace("\u03bc", "\u00b5").replace("\ufeff", "").split()).lower()


def read_sand(path: str | os.PathLike, voxel_size: float | None = None) -> Sand:
    """Read a Sand Atlas CSV (one row per grain; columns as in :data:`COLUMNS`).

    Parameters
    ----------
    path : path
    voxel_size : float, optional
        Voxel size of the scan (µm); required unless the file has a
        ``Voxel Size (µm)`` column (then its median is used).

    Raises
    ------
    ValueError
        One line naming the file and the problem: unreadable, empty, missing
        columns (another format), a value that is not a positive finite
        number, or no voxel size.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = p.write_text("Equivalent Diameter (µm),True Sphericity (-),Convexity (-),Flatness (-),Elongation (-)\\n"
    ...                  "500,0.9,0.95,0.8,0.7\\n", encoding="utf-8")
    >>> s = read_sand(p, voxel_size=7.3)
    >>> s.count, float(s.values["flatness"][0]), round(float(s.equivalent_diameter[0] / s.voxel_size), 1)
    (1, 0.8, 68.5)
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    rows = list(csv.reader(text.splitlines()))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{path}: empty file (expected a Sand Atlas CSV with a header row)")
    header = {_norm(h): i for i, h in enumerate(rows[0])}
    want = dict(COLUMNS)
    missing = [c for c in want.values() if _norm(c) not in header]
    if missing:
        raise ValueError(f"{path}: not a Sand Atlas CSV: missing column(s) {', '.join(repr(c) for c in missing)}")
    if len(rows) < 2:
        raise ValueError(f"{path}: no grains (only a header row)")
    if _norm(VOXEL_COLUMN) in header:
        want["voxel_size"] = VOXEL_COLUMN
    data: dict[str, list[float]] = {k: [] for k in want}
    for line, row in enumerate(rows[1:], start=2):
        for key, col in want.items():
            i = header[_norm(col)]
            cell = row[i].strip() if i < len(row) else ""
            try:
                x = float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {col!r}: not a number: {cell!r}") from None
            high = SPHERICITY_MAX if key == "sphericity" else 1 + 1e-6 if key in DESCRIPTORS else math.inf
            if not (math.isfinite(x) and 0 < x <= high):
                limit = f" (at most {SPHERICITY_MAX:g})" if key == "sphericity" else \
                    " (at most 1)" if key in DESCRIPTORS else ""
                raise ValueError(f"{path}: line {line}, column {col!r}: out of range{limit}: {cell!r}")
            data[key].append(x)
    if voxel_size is None:
        if "voxel_size" not in data:
            raise ValueError(f"{path}: no {VOXEL_COLUMN!r} column: give the scan's voxel size (--voxel-size-um)")
        voxel_size = float(np.median(data["voxel_size"]))
    if not (math.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"{path}: the voxel size must be a positive number of µm, got {voxel_size!r}")
    across = np.asarray(data["equivalent_diameter"]) / voxel_size
    lo, hi = VOXELS_ACROSS
    if not (np.all(np.isfinite(across)) and across.min() >= lo and across.max() <= hi):
        raise ValueError(f"{path}: at a voxel size of {voxel_size:g} µm its grains are {across.min():.3g} to "
                         f"{across.max():.3g} voxels across; the fit measures grains {lo:g} to {hi:g} voxels "
                         "across (is the voxel size in µm?)")
    return Sand(name=path.name, voxel_size=float(voxel_size),
                equivalent_diameter=np.asarray(data["equivalent_diameter"]),
                values={k: np.asarray(data[k]) for k in DESCRIPTORS})


def check_sand(sand: Sand) -> None:
    """Refuse a sand that cannot be fitted: fewer than :data:`MIN_GRAINS` grains, or a column without spread.

    A fit matches distributions; identical grains (every value of a column
    the same) have none to match, and their single size makes no grading.

    Raises
    ------
    ValueError
        One line naming the sand and the problem.

    Examples
    --------
    >>> one = np.full(60, 0.8)
    >>> s = Sand("s.csv", 7.3, np.linspace(300, 500, 60), {k: one for k in DESCRIPTORS})
    >>> check_sand(s)
    Traceback (most recent call last):
    ...
    ValueError: s.csv: every grain has the same sphericity (0.8): a fit needs a spread of sizes and shapes to match
    """
    if sand.count < MIN_GRAINS:
        raise ValueError(f"{sand.name}: {sand.count} grain(s); a fit needs at least {MIN_GRAINS} "
                         "(fewer grains say too little about the sand's distributions)")
    for key, col in [("equivalent diameter", sand.equivalent_diameter)] + [(k, sand.values[k]) for k in DESCRIPTORS]:
        if float(np.ptp(col)) <= 1e-9 * float(np.max(np.abs(col))):
            raise ValueError(f"{sand.name}: every grain has the same {key} ({float(col[0]):g}): a fit needs a "
                             "spread of sizes and shapes to match")


def fit_grains(method: str, *, count: int, pilot: int, rounds: int, final_rounds: int) -> tuple[int, int]:
    """Most grains a fit of ``method`` measures: (search grains, final-population grains).

    The search measures the pilot at the start, half of it once per unknown
    (the Jacobian), and once per round; the final population is measured up
    to ``final_rounds`` times.  ``"auto"`` fits every method.

    Examples
    --------
    >>> fit_grains("rf", count=500, pilot=200, rounds=6, final_rounds=3)
    (2200, 1500)
    """
    if method == "auto":
        parts = [fit_grains(m, count=count, pilot=pilot, rounds=rounds, final_rounds=final_rounds) for m in FITS]
        return sum(p[0] for p in parts), sum(p[1] for p in parts)
    pilot = min(pilot, count)
    unknowns = len(FITS[method].knobs) + 4
    return pilot * (1 + rounds) + unknowns * max(2, pilot // 2), final_rounds * count


def check_fit_size(sand: Sand, method: str, *, count: int, pilot: int, rounds: int, final_rounds: int,
                   workers: int = 1) -> float:
    """Estimated seconds of a fit; refuse one beyond a day or the machine's memory, naming the option to lower.

    Raises
    ------
    grainforge.estimate.TooLargeError
    """
    from .estimate import check_job, check_memory

    search, final = fit_grains(method, count=count, pilot=pilot, rounds=rounds, final_rounds=final_rounds)
    across = sand.equivalent_diameter / sand.voxel_size
    each = FIT_GRAIN_SECONDS + FIT_VOXEL_SECONDS * float(np.mean((across / FIT_ACROSS_REF) ** 3))
    option = "--count" if final >= search else "--pilot (or --rounds)"
    if method == "auto":
        option += " or fit one --method"
    cores = max(1, min(int(workers), os.cpu_count() or 1))
    total = check_job(search + final, each, what=f"fit --method {method}, measuring up to {search + final} grains,",
                      option=option, workers=cores)
    per_worker = FIT_VOXEL_BYTES * float(across.max()) ** 3
    check_memory(per_worker * max(1, int(workers)) + FIT_ROW_BYTES * (search + final),
                 what=f"fit --method {method} on {workers} worker(s), measuring up to {search + final} grains "
                      f"{across.max():.0f} voxels across,", option=f"{option} or --workers")
    return total


# --------------------------------------------------------------------------- per-method knobs
@dataclass(frozen=True)
class Knob:
    """One fitted number: start value, bounds and the finite-difference step (also its scale)."""

    name: str
    start: float
    low: float
    high: float
    step: float


@dataclass(frozen=True)
class MethodFit:
    """How to fit one generator.

    Attributes
    ----------
    method : str
        Generator name (must have an ``aspect`` L:I:S parameter).
    knobs : tuple of Knob
        Fitted numbers besides the aspect distribution.
    targets : tuple of str
        The statistics the knobs mainly steer, as many as knobs: ``"mean X"``
        or ``"sd X"`` for X in :data:`DESCRIPTORS` (documentation: the search
        solves every knob against all of :data:`STATISTICS`).
    params : callable
        Knob values (dict) -> the recipe's ``[params]`` table (numbers,
        lists, or distribution tables such as :func:`truncnormal`), without
        ``aspect``.
    """

    method: str
    knobs: tuple[Knob, ...]
    targets: tuple[str, ...]
    params: Callable[[Mapping[str, float]], dict]

    def __post_init__(self):
        if len(self.knobs) != len(self.targets):
            raise ValueError(f"{self.method}: {len(self.knobs)} knobs need as many targets, got {self.targets}")


#: method name -> its :class:`MethodFit` (``fit --method``)
FITS: dict[str, MethodFit] = {}


def register(spec: MethodFit) -> MethodFit:
    """Make ``spec`` available to :func:`fit_sand` (replaces an earlier one of the same method)."""
    FITS[spec.method] = spec
    return spec


#: a fitted normal is truncated this many standard deviations from its mean (inside the knob's range)
TRUNCATE_SD = 4.0


def truncnormal(mean: float, sd: float, low: float, high: float) -> dict:
    """A recipe ``truncnormal`` table: the mean clipped into [low, high], the
    range narrowed to mean ± :data:`TRUNCATE_SD` sd within [low, high].

    The narrowing keeps the recipe runnable: ``batch`` makes pilot grains at
    each end of every distribution before it starts
    (:func:`grainforge.population.check_extremes`), and a draw beyond 4 sd
    has a probability of 6e-5, so the normal is practically unchanged.

    Examples
    --------
    >>> t = truncnormal(1.2, 0.1, 0.0, 1.0)
    >>> t["mean"], round(t["low"], 12), t["high"]
    (1.0, 0.6, 1.0)
    """
    m, sd = float(min(max(mean, low), high)), float(max(sd, 1e-4))
    lo, hi = max(float(low), m - TRUNCATE_SD * sd), min(float(high), m + TRUNCATE_SD * sd)
    return {"distribution": "truncnormal", "mean": m, "sd": sd, "low": lo, "high": hi}


def _descriptor_knobs(irregularity: float, roughness: float, high: float) -> tuple[Knob, ...]:
    """Irregularity D3 and roughness D8, each drawn per grain (mean and sd fitted)."""
    return (Knob("irregularity", irregularity, 0.0, high, 0.02), Knob("roughness", roughness, 0.0, 0.05, 0.004),
            Knob("irregularity_sd", 0.04, 0.002, 0.15, 0.015), Knob("roughness_sd", 0.004, 0.0005, 0.03, 0.003))


def _descriptor_params(k: Mapping[str, float], high: float) -> dict:
    # D2 = 0: the aspect alone sets the form; D3 (irregularity) and D8 (roughness) drawn per grain
    return {"descriptors": [0.0, truncnormal(k["irregularity"], k["irregularity_sd"], 0.0, high),
                            truncnormal(k["roughness"], k["roughness_sd"], 0.0, 0.1)],
            "subdivisions": 5}


_SHAPE_TARGETS = ("mean sphericity", "mean convexity", "sd sphericity", "sd convexity")

register(MethodFit("cri", knobs=_descriptor_knobs(0.10, 0.006, 0.4), targets=_SHAPE_TARGETS,
                   params=lambda k: _descriptor_params(k, 0.4)))
register(MethodFit("rf", knobs=_descriptor_knobs(0.06, 0.006, 0.3), targets=_SHAPE_TARGETS,
                   params=lambda k: _descriptor_params(k, 0.3)))
register(MethodFit(
    "fso",
    knobs=(Knob("amplitude", 0.06, 0.0, 0.3, 0.01), Knob("fractal_dimension", 2.3, 2.0, 2.9, 0.1),
           Knob("amplitude_sd", 0.015, 0.001, 0.1, 0.008), Knob("fractal_dimension_sd", 0.05, 0.005, 0.3, 0.05)),
    targets=_SHAPE_TARGETS,
    params=lambda k: {"amplitude": truncnormal(k["amplitude"], k["amplitude_sd"], 0.0, 0.3),
                      "fractal_dimension": truncnormal(k["fractal_dimension"], k["fractal_dimension_sd"], 2.0, 2.9),
                      "surface": "seamless", "subdivisions": 5},
))


register(MethodFit(
    # angular grains: edge rounding steers sphericity, dent depth convexity (6 dents of width 0.5 rad,
    # 16 facets, a fine texture); both drawn per grain, mean and sd fitted
    "angular",
    knobs=(Knob("rounding", 0.15, 0.0, 0.9, 0.05), Knob("dent_depth", 0.35, 0.0, 0.7, 0.05),
           Knob("rounding_sd", 0.08, 0.005, 0.4, 0.03), Knob("dent_depth_sd", 0.1, 0.005, 0.3, 0.03)),
    targets=_SHAPE_TARGETS,
    params=lambda k: {"facets": 16, "rounding": truncnormal(k["rounding"], k["rounding_sd"], 0.0, 0.9),
                      "dents": 6, "dent_width": 0.5,
                      "dent_depth": truncnormal(k["dent_depth"], k["dent_depth_sd"], 0.0, 0.7),
                      "roughness": 0.005, "length_ratio": 2.0, "subdivisions": 5},
))


# --------------------------------------------------------------------------- recipes
def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(float(f"{v:.6g}"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} to TOML")


#: percent passing at which the sand's size quantiles become the recipe's sieves (finer in the tails,
#: where a log-linear grading between few sieves would spread grains over sizes the sand barely has)
GRADING_PERCENTS = (0, 0.5, 1, 2, 3, 5, 7.5, *range(10, 95, 5), 92.5, 95, 97, 98, 99, 99.5, 100)


def grading(d_eq_um: np.ndarray, percents: Sequence[float] = GRADING_PERCENTS) -> tuple[list[float], list[float]]:
    """Sieves (mm) and count percent passing at the sizes' quantiles ``percents`` (duplicates dropped).

    Examples
    --------
    >>> grading(np.array([100.0, 200.0, 300.0, 400.0, 500.0]), (0, 50, 100))
    ([0.1, 0.3, 0.5], [0.0, 50.0, 100.0])
    """
    q = np.asarray(percents, dtype=np.float64)
    sieves = np.percentile(np.asarray(d_eq_um) / 1000.0, q)
    keep = np.r_[True, np.diff(sieves) > 1e-9 * sieves[-1]]
    sieves, q = sieves[keep], q[keep]
    q[-1] = 100.0
    return [float(f"{s:.6g}") for s in sieves], [float(x) for x in q]


def recipe_text(method: str, params: Mapping[str, Any], sand: Sand, *, count: int, seed: int,
                fmt: str = "stl", header: str = "") -> str:
    """A ``grainforge batch`` recipe: ``params`` and the sand's size distribution as a count grading."""
    sieves, passing = grading(sand.equivalent_diameter)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(method)}", f"count = {int(count)}", f"seed = {int(seed)}", f"format = {_toml(fmt)}",
              "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in params.items()]
    lines += ["", "[size]", 'definition = "equivalent"', f"sieves_mm = {_toml(sieves)}",
              f"percent_passing = {_toml(passing)}", 'basis = "count"', ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- measuring a population
@lru_cache(maxsize=8)
def _recipe(text: str):
    from .population import parse_recipe

    return parse_recipe(text, source="<fit>")


def measure_grain(text: str, index: int, voxel_size_um: float, convention: str = "atlas") -> tuple[float, ...]:
    """Grain ``index`` of recipe ``text`` as ``batch`` makes it, measured the Atlas way.

    It is voxelised at ``voxel_size_um`` relative to its drawn equivalent
    diameter, in a random orientation drawn from its own seed; ``convention``
    is true sphericity's (:func:`grainforge.analysis.atlas.voxel_descriptors`).  Returns
    (d_eq µm, sphericity, convexity, flatness, elongation, CPU seconds spent).
    """
    import time

    cpu = time.process_time()
    from .analysis.atlas import atlas_descriptors
    from .methods import generate
    from .population import draw_grain

    recipe = _recipe(text)
    seed, params, size_mm = draw_grain(recipe, index)
    grain = generate(recipe.method, params, seed)
    across = size_mm * 1000.0 / voxel_size_um
    d = atlas_descriptors(grain, voxels_across=across, rotation=np.random.default_rng([seed, 1]),
                          convention=convention)
    return (d["equivalent_diameter"] / d["voxel_size"] * voxel_size_um, *(d[k] for k in DESCRIPTORS),
            time.process_time() - cpu)


class _Pool:
    """Runs :func:`measure_grain` over indices, in this process or on a worker pool."""

    def __init__(self, workers: int, convention: str = "atlas"):
        self.workers = workers
        self.convention = convention
        self.ex = None
        self.cache: dict[tuple[str, int], tuple[float, ...]] = {}  # (recipe text, index) -> measurement
        self.cpu = 0.0  # CPU seconds the workers spent generating and measuring
        self.grains = 0

    def __enter__(self):
        if self.workers > 1:
            from .workers import process_pool

            self.ex = process_pool(self.workers, ["grainforge.fit", "grainforge.analysis.atlas",
                                                  "grainforge.population", "trimesh", "scipy.ndimage",
                                                  "skimage.measure"])
        return self

    def __exit__(self, exc_type, exc, tb):
        if self.ex is not None:
            from .workers import close_pool

            # an error, Ctrl-C or SIGTERM: stop the workers now (waiting for them from inside an
            # interrupted as_completed could hang; seen with SIGTERM during a fit)
            close_pool(self.ex, abort=exc_type is not None)

    def run(self, text: str, count: int, voxel: float, progress) -> np.ndarray:
        out = np.empty((count, 5))
        todo = [i for i in range(count) if (text, i) not in self.cache]
        if self.ex is None:
            it: Iterable = ((i, measure_grain(text, i, voxel, self.convention)) for i in todo)
        else:
            from concurrent.futures import as_completed

            from .workers import single_threaded_children

            with single_threaded_children():
                futs = {self.ex.submit(measure_grain, text, i, voxel, self.convention): i for i in todo}
            it = ((futs[f], f.result()) for f in as_completed(futs))
        if progress is not None and todo:
            it = progress(it, len(todo))
        for i, row in it:
            self.cache[(text, i)] = row[:5]
            self.cpu += row[5]
            self.grains += 1
        for i in range(count):
            out[i] = self.cache[(text, i)]
        return out


# --------------------------------------------------------------------------- comparing
def compare(sand: np.ndarray, gen: np.ndarray) -> dict[str, Any]:
    """Statistics of two (n, 4) descriptor tables: means, sds, KS per descriptor; correlations.

    ``score`` is the largest of KS/0.1 and |Δmean|/0.01 over the four
    descriptors: the fit passes when it is ≤ 1.
    """
    from scipy.stats import ks_2samp

    out: dict[str, Any] = {"per": {}, "corr": {}}
    worst = 0.0
    for j, k in enumerate(DESCRIPTORS):
        a, b = sand[:, j], gen[:, j]
        ks = float(ks_2samp(a, b).statistic)
        dm = float(b.mean() - a.mean())
        out["per"][k] = {"sand_mean": float(a.mean()), "gen_mean": float(b.mean()), "sand_sd": float(a.std(ddof=1)),
                         "gen_sd": float(b.std(ddof=1)), "ks": ks, "mean_diff": dm,
                         "pass": ks <= KS_MAX and abs(dm) <= MEAN_TOL}
        worst = max(worst, ks / KS_MAX, abs(dm) / MEAN_TOL)
    cs, cg = np.corrcoef(sand.T), np.corrcoef(gen.T)
    for i in range(4):
        for j in range(i + 1, 4):
            out["corr"][f"{DESCRIPTORS[i]}-{DESCRIPTORS[j]}"] = (float(cs[i, j]), float(cg[i, j]))
    out["score"] = worst
    out["pass"] = all(v["pass"] for v in out["per"].values())
    return out


def _weights(sand: np.ndarray) -> np.ndarray:
    """Weight of each of :data:`STATISTICS`' misfits: what it does to the criteria, for sand sds σ.

    For two normal distributions of sd σ whose means differ by δ, the KS
    statistic is 2Φ(δ/2σ) − 1 ≈ δ/(σ√(2π)); for equal means and sds σ and
    σ(1 + ε) it is max |Φ(x) − Φ(x/(1 + ε))| ≈ ε·φ(1).  So a mean misfit
    counts against both its tolerance and the KS limit,
    ``√(1/MEAN_TOL² + (1/(σ√(2π) KS_MAX))²)``, and a spread misfit against
    the KS limit, ``φ(1)/(σ KS_MAX)``: a narrow descriptor (Ottawa's
    convexity, σ = 0.026) is weighted more than a wide one (flatness, 0.107).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> w = dict(zip(STATISTICS, _weights(rng.normal(0.8, [0.025, 0.025, 0.1, 0.1], size=(4000, 4)))))
    >>> round(float(w["sd convexity"] / w["sd flatness"]), 1), round(float(w["mean convexity"] / w["mean flatness"]), 1)
    (4.0, 1.8)
    """
    sd = np.maximum(np.asarray(sand, dtype=np.float64).std(axis=0, ddof=1), 1e-6)
    phi1 = math.exp(-0.5) / math.sqrt(2 * math.pi)
    out = []
    for t in STATISTICS:
        kind, desc = t.split()
        s = float(sd[DESCRIPTORS.index(desc)])
        if kind == "mean":
            out.append(math.hypot(1 / MEAN_TOL, 1 / (s * math.sqrt(2 * math.pi) * KS_MAX)))
        else:
            out.append(phi1 / (s * KS_MAX))
    return np.array(out)


def _stat(table: np.ndarray, name: str) -> float:
    kind, desc = name.split()
    col = table[:, DESCRIPTORS.index(desc)]
    return float(col.mean() if kind == "mean" else col.std(ddof=1))


# --------------------------------------------------------------------------- the fit
@dataclass
class FitResult:
    """What :func:`fit_sand` found."""

    method: str
    recipe: str  # TOML text of the final recipe
    stats: dict[str, Any]  # compare(sand, final population)
    generated: np.ndarray  # (count, 5): d_eq µm + DESCRIPTORS
    knobs: dict[str, float]
    aspect: dict[str, float]
    history: list[dict] = field(default_factory=list)
    seconds: float = 0.0  # wall clock
    cpu_seconds: float = 0.0  # generating and measuring, summed over the workers
    grains_measured: int = 0


def _aspect_table(a: Mapping[str, float], low: float) -> dict:
    return {"distribution": "zingg",
            "elongation": truncnormal(a["elongation_mean"], a["elongation_sd"], low, 1.0),
            "flatness": truncnormal(a["flatness_mean"], a["flatness_sd"], low, 1.0)}


def fit_sand(
    sand: Sand,
    method: str = "rf",
    *,
    count: int = 500,
    pilot: int = 200,
    rounds: int = 6,
    final_rounds: int = 3,
    seed: int = 2024,
    workers: int = 1,
    sphericity: str = "atlas",
    progress: Callable[[Iterable, int], Iterable] | None = None,
    log: Callable[[str], None] | None = None,
    desc: Callable[[str], None] | None = None,
) -> FitResult:
    """Fit ``method``'s settings to ``sand``; see the module docstring.

    Parameters
    ----------
    count : int
        Grains of the final (verification) population and of the recipe.
    pilot : int
        Grains of each search round.
    rounds : int
        Newton rounds on the pilot after the finite-difference Jacobian.
    final_rounds : int
        Measurements of the whole population (each after a correction
        made from the previous one); the best is kept.
    workers : int
        Processes measuring grains (1: this process).
    sphericity : {"atlas", "whole"}
        How the generated grains' true sphericity is measured: as the Sand
        Atlas did (spam's cube, the default, for tables measured that way) or
        on the whole grain (:func:`grainforge.analysis.atlas.voxel_descriptors`).
    progress : callable, optional
        ``progress(iterable, total)`` wraps each population's grains (a bar).
    log, desc : callable, optional
        ``log(line)`` gets one line per round; ``desc(text)`` names the
        population being measured next.
    """
    import time

    if method == "auto":
        results = []
        for m in FITS:
            (log or (lambda s: None))(f"auto: fitting {m}")
            results.append(fit_sand(sand, m, count=count, pilot=pilot, rounds=rounds, final_rounds=final_rounds,
                                    seed=seed, workers=workers, progress=progress, log=log, desc=desc))
        return min(results, key=lambda r: r.stats["score"])
    if method not in FITS:
        raise ValueError(f"method must be one of {', '.join(list(FITS) + ['auto'])}, got {method!r}")
    from .methods import METHODS

    if method not in METHODS:
        raise ValueError(f"method {method!r} is not available in this grainforge")
    if count < 2 or not 2 <= pilot:
        raise ValueError("count and pilot must be at least 2")
    check_sand(sand)
    pilot = min(pilot, count)
    spec = FITS[method]
    say = log or (lambda s: None)
    name = desc or (lambda s: None)
    t0 = time.perf_counter()
    target = sand.table()
    sv = sand.values
    low = float(max(0.05, min(sv["elongation"].min(), sv["flatness"].min()) - 0.1))
    aspect = {"elongation_mean": float(sv["elongation"].mean()), "elongation_sd": float(sv["elongation"].std()),
              "flatness_mean": float(sv["flatness"].mean()), "flatness_sd": float(sv["flatness"].std())}
    # The unknowns: the method's knobs (each steering means and/or spreads) and the aspect distribution's
    # two means and two sds.  All are solved for jointly against all eight measured statistics (the mean
    # and sd of each descriptor): a rougher grain also measures less elongated, a flatter one less
    # spherical, and one per-grain spread (irregularity's, say) widens both sphericity and convexity.
    # Gauss-Newton steps on a finite-difference Jacobian, the residuals weighted by what they do to the
    # criteria (_weights: a mean error counts against its 0.01 and, with a spread error, against the KS).
    nk = len(spec.knobs)
    knames = [k.name for k in spec.knobs]
    anames = ["elongation_mean", "flatness_mean", "elongation_sd", "flatness_sd"]
    x = np.array([k.start for k in spec.knobs] + [aspect[a] for a in anames])
    lo_b = np.array([k.low for k in spec.knobs] + [low, low, ASPECT_SD_LOW, ASPECT_SD_LOW])
    hi_b = np.array([k.high for k in spec.knobs] + [1.0, 1.0, ASPECT_SD_HIGH, ASPECT_SD_HIGH])
    steps = np.array([k.step for k in spec.knobs] + [ASPECT_STEP, ASPECT_STEP, ASPECT_SD_STEP, ASPECT_SD_STEP])
    targets = STATISTICS
    y_star = np.array([_stat(target, t) for t in targets])
    weights = _weights(target)
    history: list[dict] = []

    def unpack(xv):
        knobs = dict(zip(knames, map(float, xv[:nk])))
        asp = dict(zip(anames, map(float, xv[nk:])))
        return knobs, asp

    def text_for(xv, n, s=seed):
        knobs, asp = unpack(xv)
        params = spec.params(knobs)
        params["aspect"] = _aspect_table(asp, low)
        return recipe_text(method, params, sand, count=n, seed=s)

    def stats(gen):
        return np.array([_stat(gen[:, 1:], t) for t in targets])

    def evaluate(xv, n, label):
        # always the final recipe: a pilot is its first n grains (same seeds, sizes and draws)
        name(label)
        gen = pool.run(text_for(xv, count), n, sand.voxel_size, progress)
        st = compare(target, gen[:, 1:])
        knobs, asp = unpack(xv)
        history.append({"label": label, "knobs": knobs, "aspect": asp, "score": st["score"],
                        "merit": merit(gen),
                        **{f"{k}_{q}": st["per"][k][q] for k in DESCRIPTORS for q in ("gen_mean", "gen_sd", "ks")}})
        say(f"{label}: score {st['score']:.2f} (<= 1 passes), misfit {merit(gen):.2f}; "
            + ", ".join(f"{k[:5]} {st['per'][k]['gen_mean']:.3f}±{st['per'][k]['gen_sd']:.3f} KS {st['per'][k]['ks']:.2f}"
                        for k in DESCRIPTORS)
            + "; " + ", ".join(f"{k} {v:.4g}" for k, v in knobs.items())
            + ", aspect " + ", ".join(f"{a} {asp[a]:.3f}" for a in anames))
        return gen, st

    def merit(gen):
        # what a round is judged by: the weighted misfit of means and spreads (a KS statistic of a pilot
        # is mostly sampling noise)
        return float(np.sum((weights * (stats(gen) - y_star)) ** 2))

    def newton(xv, J, gen, trust):
        # bounded, damped weighted least squares in step units: each unknown moves at most `trust` steps
        # and stays within its range (a bound is honoured in the solve, not by clipping its result
        # afterwards, which would throw away the compensation the other unknowns were making); the
        # damping keeps the step small along nearly singular directions (irregularity and roughness, and
        # their spreads, lower or widen sphericity and convexity in similar proportions)
        from scipy.optimize import lsq_linear

        n = len(xv)
        Js = weights[:, None] * J * steps[None, :]
        r = weights * (y_star - stats(gen))
        lam = 0.05 * np.trace(Js.T @ Js) / n + 1e-12
        A = np.vstack([Js, math.sqrt(lam) * np.eye(n)])
        b = np.concatenate([r, np.zeros(n)])
        lo = np.maximum(-trust, (lo_b - xv) / steps)
        hi = np.minimum(trust, (hi_b - xv) / steps)
        hi = np.maximum(hi, lo + 1e-12)
        dz = lsq_linear(A, b, bounds=(lo, hi)).x
        return np.clip(xv + dz * steps, lo_b, hi_b)

    def broyden(J, dx, dy):
        if np.any(dx):
            J += np.outer(dy - J @ dx, dx) / float(dx @ dx)

    with _Pool(max(1, int(workers)), sphericity) as pool:
        gen, st = evaluate(x, pilot, "pilot 0 (start)")
        # finite-difference Jacobian on the first half of the pilot (same grains: differences, not noise)
        nj = max(2, pilot // 2)
        y0 = stats(gen[:nj])
        J = np.zeros((len(targets), len(x)))
        labels = knames + anames
        for i in range(len(x)):
            xi = x.copy()
            xi[i] = xi[i] + steps[i] if xi[i] + steps[i] <= hi_b[i] else xi[i] - steps[i]
            gi, _ = evaluate(xi, nj, f"jacobian {i + 1}/{len(x)} ({labels[i]})")
            J[:, i] = (stats(gi) - y0) / (xi[i] - x[i])
        trust = 2.0  # trust region, in steps: halved after a round that makes things worse
        best = (merit(gen), x.copy(), gen, st)
        for r in range(1, rounds + 1):
            x_new = newton(x, J, gen, trust)
            gen_new, st_new = evaluate(x_new, pilot, f"pilot {r}")
            broyden(J, x_new - x, stats(gen_new) - stats(gen))
            if merit(gen_new) < best[0]:
                best = (merit(gen_new), x_new.copy(), gen_new, st_new)
                trust = min(1.5 * trust, 4.0)
            else:  # worse: go back to the best settings with a smaller step
                trust *= 0.5
            _, x, gen, st = best
            x = x.copy()
            if st["score"] <= 0.6:
                break
        final = None
        cost = pool
        prev = None
        trust = 1.5
        for attempt in range(final_rounds):
            gen, st = evaluate(x, count, f"final {count} grains" + (f" (correction {attempt})" if attempt else ""))
            if prev is not None:  # secant from two measurements of the same grains
                broyden(J, x - prev[0], stats(gen) - stats(prev[1]))
            if final is None or st["score"] < final[1]["score"]:
                final = (gen, st, x.copy())
            else:
                trust *= 0.5
            if st["pass"]:
                break
            # corrections from the best final population (its own seeds: no sampling noise between rounds)
            gen, st, x = final[0], final[1], final[2].copy()
            prev = (x.copy(), gen)
            x = newton(x, J, gen, trust)
    gen, st, x = final
    knobs, aspect = unpack(x)
    header = (f"grainforge fit: {method} grains matched to {sand.name} ({sand.count} grains, voxel "
              f"{sand.voxel_size:g} µm)\n" + "\n".join(
                  f"{k}: sand {st['per'][k]['sand_mean']:.3f} generated {st['per'][k]['gen_mean']:.3f} "
                  f"KS {st['per'][k]['ks']:.3f}" for k in DESCRIPTORS)
              + f"\n{'passes' if st['pass'] else 'does NOT pass'}: KS <= {KS_MAX} and |mean diff| <= {MEAN_TOL} "
              f"on {count} grains")
    params = spec.params(knobs)
    params["aspect"] = _aspect_table(aspect, low)
    text = recipe_text(method, params, sand, count=count, seed=seed, header=header)
    return FitResult(method=method, recipe=text, stats=st, generated=gen,
                     knobs=knobs, aspect=aspect,
                     history=history, seconds=time.perf_counter() - t0, cpu_seconds=cost.cpu,
                     grains_measured=cost.grains)


# --------------------------------------------------------------------------- outputs
def fit_rows(result: FitResult) -> list[dict[str, Any]]:
    """The rows of ``fit.csv``: per-descriptor means, sds and KS, then correlations, sand vs generated."""
    rows = []
    for k in DESCRIPTORS:
        p = result.stats["per"][k]
        rows.append({"statistic": "mean", "quantity": k, "sand": p["sand_mean"], "generated": p["gen_mean"],
                     "difference": p["mean_diff"], "criterion": f"|difference| <= {MEAN_TOL}",
                     "pass": abs(p["mean_diff"]) <= MEAN_TOL})
        rows.append({"statistic": "sd", "quantity": k, "sand": p["sand_sd"], "generated": p["gen_sd"],
                     "difference": p["gen_sd"] - p["sand_sd"], "criterion": "", "pass": ""})
        rows.append({"statistic": "ks", "quantity": k, "sand": "", "generated": "", "difference": p["ks"],
                     "criterion": f"KS statistic <= {KS_MAX}", "pass": p["ks"] <= KS_MAX})
    for pair, (a, b) in result.stats["corr"].items():
        rows.append({"statistic": "correlation", "quantity": pair, "sand": a, "generated": b, "difference": b - a,
                     "criterion": "reported", "pass": ""})
    return rows


FIT_COLUMNS = ("statistic", "quantity", "sand", "generated", "difference", "criterion", "pass")


def fit_figure(sand: Sand, result: FitResult, path: Path) -> None:
    """``fit.png``: histograms of the four descriptors and flatness vs elongation, sand vs generated."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import save_figure

    gen = result.generated[:, 1:]
    st = sand.table()
    fig, axes = plt.subplots(2, 3, figsize=(12.6, 7.2))
    for ax, j in zip(axes.flat, range(4)):
        k = DESCRIPTORS[j]
        lo = min(st[:, j].min(), gen[:, j].min())
        hi = max(st[:, j].max(), gen[:, j].max(), lo + 1e-6)
        bins = np.linspace(lo, hi, 36)
        ax.hist(st[:, j], bins=bins, density=True, alpha=0.55, color="0.35", label=f"sand (n={sand.count})")
        ax.hist(gen[:, j], bins=bins, density=True, alpha=0.55, color="tab:orange",
                label=f"{result.method} (n={len(gen)})")
        p = result.stats["per"][k]
        ax.set_title(f"{k}: mean {p['sand_mean']:.3f} vs {p['gen_mean']:.3f}, KS {p['ks']:.3f}", fontsize=9)
        ax.legend(fontsize=7)
    ax = axes.flat[4]
    ax.scatter(st[:, 3], st[:, 2], s=3, alpha=0.35, color="0.35", label="sand")
    ax.scatter(gen[:, 3], gen[:, 2], s=3, alpha=0.5, color="tab:orange", label=result.method)
    c = result.stats["corr"]["flatness-elongation"]
    ax.set_xlabel("elongation (middle/major)")
    ax.set_ylabel("flatness (minor/middle)")
    ax.set_title(f"flatness vs elongation: r = {c[0]:.2f} (sand), {c[1]:.2f} ({result.method})", fontsize=9)
    ax.legend(fontsize=7, markerscale=3)
    ax = axes.flat[5]
    bins = np.linspace(min(sand.equivalent_diameter.min(), result.generated[:, 0].min()),
                       max(sand.equivalent_diameter.max(), result.generated[:, 0].max()), 36)
    ax.hist(sand.equivalent_diameter, bins=bins, density=True, alpha=0.55, color="0.35", label="sand")
    ax.hist(result.generated[:, 0], bins=bins, density=True, alpha=0.55, color="tab:orange", label=result.method)
    ax.set_xlabel("equivalent diameter (µm)")
    ax.set_title("size (the recipe's grading)", fontsize=9)
    ax.legend(fontsize=7)
    verdict = "passes" if result.stats["pass"] else "does NOT pass"
    fig.suptitle(f"{sand.name} vs {len(gen)} {result.method} grains measured the Atlas way "
                 f"({sand.voxel_size:g} µm voxels): {verdict} KS <= {KS_MAX}, |Δmean| <= {MEAN_TOL}", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def write_outputs(sand: Sand, result: FitResult, out: str | os.PathLike) -> list[Path]:
    """Write ``recipe.toml``, ``fit.csv`` and ``fit.png`` into ``out`` (atomically); return the paths."""
    from .io import atomic_write, write_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "recipe.toml", out / "fit.csv", out / "fit.png"]
    atomic_write(paths[0], result.recipe)
    write_csv(paths[1], fit_rows(result), FIT_COLUMNS)
    fit_figure(sand, result, paths[2])
    return paths


OUTPUTS = ("recipe.toml", "fit.csv", "fit.png")
