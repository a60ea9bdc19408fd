"""What a fit costs, estimated before any work: the grains it measures, its time and its memory.

:func:`fit_grains` counts the grains a fit measures (expected, and at most),
:func:`measured_grain_seconds` prices one, and :func:`check_fit_size` refuses a fit
estimated over ``--max-minutes``, a day or the machine's memory, in one line
naming what to change (docs/fit.md).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

import numpy as np

from .designs import DESIGN_ACROSS_LOW, DESIGN_GRAINS, _design_high, design_path
from .mean_settings import (
    OPENING_ROUNDS,
    POPULATION_GRAINS,
    POPULATION_ROUNDS,
    POPULATION_SLOPES,
    SLOPE_GRAINS,
    slopes_for,
)
from .refine import RESEED
from .sand import Sand, measured_across, uses_opening
from .settings import FITS, MAX_VOXELS_ACROSS, METHOD_CAP, resolve_cap

#: the share of twins expected to be reseeded, and the most counted, for the up-front estimate
RESEED_SHARE = 0.05
RESEED_MOST = 0.5
#: per-grain cost of a fit (s, one core): a fixed part, making the grain (:data:`FIT_MAKE_SECONDS`, the
#: method's), and voxelising and measuring it, which grows with the cube of the voxels across (0.05 s at
#: Ottawa's 69; docs/benchmarks.md, ``benchmarks/bench_estimates.py``)
FIT_GRAIN_SECONDS, FIT_VOXEL_SECONDS, FIT_ACROSS_REF = 0.085, 0.05, 69.0
#: CPU seconds to make one grain of each fitted method at its fit resolution (subdivisions 5; median of 5
#: seeds, ``benchmarks/bench_estimates.py``): a seamless FSO grain is ten times an rf grain, which made the
#: estimate of an FSO fit about half its time when one figure stood for every method
FIT_MAKE_SECONDS = {"rf": 0.015, "cri": 0.077, "fso": 0.159, "angular": 0.048}
#: measurements per twin the estimate expects (the first, and the refinements of the twins that miss;
#: the Ottawa rf fit measured 3.17 per twin, docs/fit.md)
EXPECTED_MEASUREMENTS = 3.2
#: memory of one grain's measurement, per cubed voxel across (bytes; 330 MB at 250 across, for an elongated
#: grain's larger box a factor 2 more)
FIT_VOXEL_BYTES = 48.0
#: memory the fit keeps per grain measured (its cached row)
FIT_ROW_BYTES = 300.0
#: a fit estimated beyond this is refused up front (``--max-minutes``)
MAX_MINUTES = 60.0


def fit_grains(method: str, *, count: int, design_grains: int, refine: int, reseed: int = 0,
               population_grains: int = POPULATION_GRAINS, population_slopes: str = POPULATION_SLOPES,
               cached: Callable[[str], bool] = lambda m: False, opening: bool = False) -> tuple[int, int]:
    """Grains a fit of ``method`` measures: (expected, at most).

    The design's grains (none when it is cached), the population estimate's
    (:data:`grainforge.fit.mean_settings.POPULATION_ROUNDS` × up to ``population_grains``, plus with measured slopes 2 ×
    settings × up to :data:`grainforge.fit.mean_settings.SLOPE_GRAINS`: :func:`grainforge.fit.mean_settings.slopes_for`; plus,
    for its sensitivity to the spread, up to :data:`grainforge.fit.mean_settings.SLOPE_GRAINS` per setting besides the
    aspect where the four means can determine every setting, counted here for each although only those a grain's
    descriptors do not determine are remade; with ``opening``, the sand's opening fraction used
    (:func:`grainforge.fit.sand.uses_opening`), the starting grains measured again, the slopes always measured and
    :data:`grainforge.fit.mean_settings.OPENING_ROUNDS` rounds), then each twin once, plus refinements:
    :data:`EXPECTED_MEASUREMENTS` per twin expected, ``1 + refine`` at most, plus two per reseeded twin and try
    (:data:`RESEED_SHARE` of the twins expected, :data:`RESEED_MOST` at most: the twins still off after the refinement;
    a third of them on a sand the method reaches only with other seeds). ``"auto"`` measures every method's design.

    Parameters
    ----------
    method : str
        A method of :data:`grainforge.fit.settings.FITS`, or ``"auto"`` (every method's design, the dearest
        method's population estimate).
    count : int
        Twins of the fit (grains of its recipe).
    design_grains : int
        Grains of each method's design.
    refine : int
        Rounds of refinement (``fit --refine``).
    reseed : int
        Other seeds tried per twin still off after the refinement (``fit --reseed``).
    population_grains : int
        Twins remade in each round of the mean-settings estimate (at most ``count``).
    population_slopes : {"auto", "measured", "model"}
        The estimate's slopes (:func:`grainforge.fit.mean_settings.slopes_for`).
    cached : callable
        ``cached(method)``: whether that method's design is already cached (then none of its grains is counted).
    opening : bool
        The sand's opening fraction is used (:func:`grainforge.fit.sand.uses_opening`).

    Returns
    -------
    expected : int
        Grains the fit is expected to measure.
    most : int
        Grains it measures at most (every twin refined ``refine`` times, :data:`RESEED_MOST` reseeded).

    Examples
    --------
    >>> fit_grains("rf", count=500, design_grains=400, refine=3)
    (2600, 3000)
    >>> fit_grains("rf", count=500, design_grains=400, refine=3, population_grains=500)
    (3000, 3400)
    >>> fit_grains("rf", count=500, design_grains=400, refine=3, population_slopes="measured")
    (5600, 6000)
    >>> fit_grains("angular", count=500, design_grains=400, refine=3)   # rounding's and dent depth's spread
    (3200, 3600)
    >>> fit_grains("angular", count=500, design_grains=400, refine=3, opening=True)   # + 300 + 2 × 4 × 300 + 2 × 300
    (6500, 6900)
    """
    methods = list(FITS) if method == "auto" else [method]
    designs = sum(0 if cached(m) else design_grains for m in methods)
    designs += (OPENING_ROUNDS if opening else POPULATION_ROUNDS) * min(count, population_grains)
    designs += max(len(FITS[m].settings) if FITS[m].spread_step else 0
                   for m in methods) * min(count, population_grains, SLOPE_GRAINS)
    if opening:
        designs += min(count, population_grains)
    if opening or slopes_for(population_slopes, min(count, population_grains)) == "measured":
        p = max(len(FITS[m].all_settings) for m in methods)  # the dearest method's settings (rf's five)
        designs += 2 * p * min(count, population_grains, SLOPE_GRAINS)
    expected = designs + int(round(count * (min(EXPECTED_MEASUREMENTS, 1 + refine) + 2 * reseed * RESEED_SHARE)))
    return expected, designs + count * (1 + refine) + int(round(count * 2 * reseed * RESEED_MOST))


def check_fit_size(sand: Sand, method: str, *, count: int, design_grains: int = DESIGN_GRAINS, refine: int = 4,
                   reseed: int = RESEED, population_grains: int = POPULATION_GRAINS,
                   population_slopes: str = POPULATION_SLOPES,
                   max_across: float | str | None = METHOD_CAP, workers: int = 1,
                   max_minutes: float = MAX_MINUTES, convention: str = "atlas",
                   cache: str | os.PathLike | None = None, cores: int | None = None) -> float:
    """Expected wall-clock seconds of a fit; refuse one over ``max_minutes``, a day or the machine's memory.

    ``workers`` processes share this machine's cores and memory; ``cores``
    (a Dask cluster's worker threads, each with its own memory) divides the
    time instead, and the memory is then checked for one worker.

    Parameters
    ----------
    sand : grainforge.fit.sand.Sand
        The sand to fit (its grains' voxels across set each grain's cost).
    method : str
        A method of :data:`grainforge.fit.settings.FITS`, or ``"auto"`` (costed at its dearest method).
    count : int
        Twins of the fit.
    design_grains : int
        Grains of each method's design (counted only when it is not cached under ``cache``).
    refine : int
        Rounds of refinement.
    reseed : int
        Other seeds tried per twin still off after the refinement.
    population_grains : int
        Twins remade in each round of the mean-settings estimate.
    population_slopes : {"auto", "measured", "model"}
        The estimate's slopes.
    max_across : float, str or None
        The resolution cap (voxels across), :data:`grainforge.fit.settings.METHOD_CAP` for the method's own,
        None for none (:func:`grainforge.fit.settings.resolve_cap`).
    workers : int
        Local worker processes (their memory adds up on this machine).
    max_minutes : float
        The longest fit accepted, in minutes of wall clock.
    convention : {"atlas", "whole"}
        How true sphericity is measured (part of the design's cache key).
    cache : str or os.PathLike, optional
        Where designs are cached (default :func:`grainforge.runtime.cache.cache_dir`).
    cores : int, optional
        A Dask cluster's worker threads: the time is divided by them and ``workers`` is not used.

    Returns
    -------
    float
        The expected wall-clock seconds of the fit.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        One line with the estimate and what to change.
    """
    from ..runtime.estimate import TooLargeError, check_job, check_memory, duration

    methods = list(FITS) if method == "auto" else [method]
    # per method (each has its own resolution cap): the design's top resolution, the twins' resolutions, and
    # the cost of one grain; "auto" is costed at its dearest method
    caps = {m: resolve_cap(m, max_across) for m in methods}
    highs = {m: _design_high(sand, caps[m]) for m in methods}
    acrosses = {m: measured_across(sand, caps[m]) for m in methods}
    costs = {m: measured_grain_seconds(m, acrosses[m]) for m in methods}
    dear = max(methods, key=lambda m: costs[m])
    across, each, design_high, max_across = acrosses[dear], costs[dear], highs[dear], caps[dear]
    fresh = [m for m in methods
             if not design_path(m, convention, high=highs[m], grains=design_grains, cache=cache).exists()]
    expected, most = fit_grains(method, count=count, design_grains=design_grains, refine=refine, reseed=reseed,
                                population_grains=population_grains, population_slopes=population_slopes,
                                cached=lambda m: m not in fresh,
                                opening=any(uses_opening(sand, caps[m]) for m in methods))
    option = "--count" + (" or fit one --method" if method == "auto" else "")
    if cores is None:
        from ..runtime.workers import default_workers

        cores = max(1, min(int(workers), default_workers()))
    else:
        cores, workers = max(1, int(cores)), 1
    check_job(most, each, what=f"fit --method {method}, measuring up to {most} grains,", option=option, workers=cores)
    per_worker = FIT_VOXEL_BYTES * float(max(across.max(), design_high)) ** 3
    check_memory(per_worker * max(1, int(workers)) + FIT_ROW_BYTES * most,
                 what=f"fit --method {method} on {workers} worker(s), measuring grains {across.max():.0f} voxels "
                      "across,", option=f"{option}, --max-voxels-across or --workers")
    # the design's grains are spread log-uniformly from DESIGN_ACROSS_LOW to its top resolution: most are far
    # cheaper than the twins (the mean of across³ over that spread)
    design_seconds = sum(design_grains * (FIT_GRAIN_SECONDS + _make_seconds(m) + FIT_VOXEL_SECONDS
                                          * _log_uniform_cube_mean(DESIGN_ACROSS_LOW, highs[m]) / FIT_ACROSS_REF**3)
                         for m in fresh)
    seconds = ((expected - design_grains * len(fresh)) * each + design_seconds) / cores
    if seconds > 60 * max_minutes:
        cap = (f" or --max-voxels-across (now {max_across:g})" if max_across
               else f" or set --max-voxels-across (e.g. {MAX_VOXELS_ACROSS:g})")
        raise TooLargeError(
            f"fit --method {method} would take about {duration(seconds)} on {cores} core(s) (about {expected} "
            f"grains at {duration(each) if each >= 1 else f'{each * 1000:.2g} ms'} each, {across.mean():.0f} "
            f"voxels across), over --max-minutes {max_minutes:g}: raise --max-minutes, lower {option}{cap}")
    return seconds


def measured_grain_seconds(method: str, across) -> float:
    """The estimate's CPU seconds for one grain of ``method`` measured at ``across`` voxels across (the mean over
    an array): :data:`FIT_GRAIN_SECONDS` + the method's :data:`FIT_MAKE_SECONDS` + :data:`FIT_VOXEL_SECONDS` ×
    (across / :data:`FIT_ACROSS_REF`)³. A method without a measured making time is costed at the dearest's.

    Parameters
    ----------
    method : str
        The generator's name.
    across : float or array_like
        Voxels across the grain is measured at (an array: the grains of a fit, averaged).

    Returns
    -------
    float
        CPU seconds on one core.

    Examples
    --------
    >>> round(measured_grain_seconds("rf", 69.0), 3), round(measured_grain_seconds("fso", 69.0), 3)
    (0.15, 0.294)
    """
    return FIT_GRAIN_SECONDS + _make_seconds(method) + FIT_VOXEL_SECONDS * float(np.mean(
        (np.asarray(across, dtype=float) / FIT_ACROSS_REF) ** 3))


def _make_seconds(method: str) -> float:
    """:data:`FIT_MAKE_SECONDS` of ``method``; the dearest's for a method not measured."""
    return FIT_MAKE_SECONDS.get(method, max(FIT_MAKE_SECONDS.values()))


def _log_uniform_cube_mean(low: float, high: float) -> float:
    """The mean of a³ for a log-uniform on [low, high]: (high³ − low³) / (3 ln(high / low)).

    Examples
    --------
    >>> round(_log_uniform_cube_mean(10.0, 150.0) / 150.0**3, 3)
    0.123
    """
    if high <= low:
        return float(low) ** 3
    return (high**3 - low**3) / (3.0 * math.log(high / low))
