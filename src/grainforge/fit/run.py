"""Fit a generated population to a real sand, grain by grain: :func:`fit_sand` (docs/design/algorithms.md §8).

:func:`fit_sand` makes every generated grain the **twin** of one sand grain:
it has that grain's equivalent diameter, and generator settings chosen so
that, measured the same way (:func:`grainforge.analysis.atlas.atlas_descriptors`
at the same voxel size relative to its size), it has that grain's four
descriptors.  The population so inherits the sand's joint distribution —
its marginals, the correlations between descriptors and between size and
shape — instead of matching four marginals made of independent draws.

How
---
1. **Design** (:func:`grainforge.fit.designs.design`): a few hundred grains
   of the method, measured once and cached.
2. **Inverse model** (:mod:`grainforge.fit.twins`): a cubic least-squares model
   from settings and log(voxels across) to the four descriptors, solved,
   bounded, per sand grain for the settings it predicts to measure like it.
3. **Twins**: grain ``i`` of the recipe (its own seed, as ``batch`` makes it)
   gets its sand grain's size and the model's settings, and is measured.
4. **The sand's mean settings**
   (:func:`grainforge.fit.mean_settings.population_settings`): from the means of
   its descriptors, with standard errors.
5. **Refinement** and 6. **reseeding** (:mod:`grainforge.fit.refine`): twins
   that miss get new settings, then other seeds.

The result (:class:`FitResult`) is compared with the sand by
:func:`grainforge.fit.acceptance.compare` and written by
:func:`grainforge.fit.outputs.write_outputs`.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, resolve_rng
from .acceptance import CORR_TOL, KS_MAX, MEAN_TOL, TWIN_SHARE, TWIN_TOL, compare
from .designs import DESIGN_GRAINS, IDENTIFIABLE_R2, _design_high, design, setting_identifiability
from .made_grains import MeasurePool, _salted
from .mean_settings import (
    POPULATION_GRAINS,
    POPULATION_SLOPES,
    SPREAD_DOUBT,
    Population,
    population_settings,
    slopes_for,
)
from .recipes import twin_recipe_text
from .refine import RESEED, _make_refused, _measure_twins, _refine, _reseed, _start_twins, _twin_summary, _Twins
from .sand import DESCRIPTORS, Sand, check_sand, measured_across, uses_opening
from .settings import FITS, METHOD_CAP, MethodFit, _written, resolve_cap


@dataclass
class FitResult:
    """What :func:`fit_sand` found: one twin per generated grain."""

    method: str
    recipe: str  # TOML text of the final recipe
    stats: dict[str, Any]  # compare(sand rows, twins)
    generated: np.ndarray  # (count, 5): d_eq µm + DESCRIPTORS, as measured
    sand_rows: np.ndarray  # (count,): index into the sand of each grain's original
    settings: list[dict[str, float]]  # each grain's setting values
    reachable: np.ndarray  # (count,) bool: the model's closest setting predicts a twin within TWIN_TOL
    history: list[str] = field(default_factory=list)
    seconds: float = 0.0  # wall clock
    cpu_seconds: float = 0.0  # generating and measuring, summed over the workers
    grains_measured: int = 0

    @property
    def twin_error(self) -> np.ndarray:
        """(count,) largest |twin − original| over the four descriptors."""
        return np.max(np.abs(self.generated[:, 1:] - self.targets), axis=1)

    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # (count, 4) the originals'
    #: setting -> (cross-validated R², rms error in the setting's units) of predicting it from a grain's four
    #: descriptors on the method's design (:func:`grainforge.fit.designs.setting_identifiability`)
    identifiable: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: the sand's mean settings estimated from its descriptors' means
    #: (:func:`grainforge.fit.mean_settings.population_settings`)
    population: Population | None = None
    #: each grain's seed (as the recipe makes it)
    seeds: list[int] = field(default_factory=list)


def choose_rows(n: int, count: int | None, rng: RNGLike) -> np.ndarray:
    """Sand rows the twins copy: all (``count`` None), a random ``count`` of them without replacement, or with
    replacement beyond all ``n`` (all rows, then random repeats).

    Parameters
    ----------
    n : int
        Rows of the sand's table.
    count : int or None
        Twins wanted; None: every row once.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Which rows, normalised by :func:`grainforge.rng.resolve_rng`: an int seed ``s`` (a fit's root seed)
        draws from ``SeedSequence([s, 7])``, the rows it has always chosen; a Generator is drawn from (advanced).

    Returns
    -------
    (count,) numpy.ndarray of int
        Row indices from 0: increasing without replacement; with replacement every row once, then the repeats.

    Examples
    --------
    >>> choose_rows(5, None, 1).tolist(), len(set(choose_rows(100, 60, 1).tolist())), len(choose_rows(5, 8, 1))
    ([0, 1, 2, 3, 4], 60, 8)
    >>> bool(np.array_equal(choose_rows(100, 60, 3), choose_rows(100, 60, np.random.SeedSequence(3))))
    True
    """
    rng = _salted(rng, 7)[1]
    if count is None or count == n:
        return np.arange(n)
    if count < n:
        return np.sort(rng.choice(n, size=count, replace=False))
    return np.concatenate([np.arange(n), rng.choice(n, size=count - n, replace=True)])


def choose_method(sand: Sand, pool: MeasurePool, *, max_across: float | str | None, grains: int, cache, progress, say,
                  name) -> str:
    """``auto``: the method whose inverse model reaches the most of the sand (ties: the smaller median miss).

    Each method's design is loaded (or measured) and its model inverted for up to 300 of the sand's rows
    (the same rows whatever the fit's seed).

    Parameters
    ----------
    sand : Sand
        The sand to fit.
    pool : MeasurePool
        Where designs not cached are measured.
    max_across : float, str or None
        The resolution cap (:func:`grainforge.fit.settings.resolve_cap`).
    grains : int
        Grains of each design.
    cache : str or os.PathLike or None
        Where designs are cached.
    progress : callable or None
        ``progress(iterable, total)`` wraps a design's grains (a bar).
    say : callable
        ``say(line)`` gets one line per method.
    name : callable
        ``name(text)`` names the design measured next.

    Returns
    -------
    str
        The chosen method's name.
    """
    from .twins import invert

    table = sand.table()
    rows = choose_rows(sand.count, min(sand.count, 300), 0)
    best = None
    for m in FITS:
        cap = resolve_cap(m, max_across)
        name(f"design {m}")
        model = design(m, pool, high=_design_high(sand, cap), grains=grains, cache=cache, progress=progress).model()
        _, miss = invert(model, table[rows], measured_across(sand, cap)[rows])
        key = (float(np.mean(miss <= TWIN_TOL)), -float(np.median(miss)))
        say(f"auto: {m} reaches {key[0]:.1%} of the sand (model's median miss {-key[1]:.4f})")
        best = max(best or (key, m), (key, m))
    return best[1]


def fit_sand(
    sand: Sand,
    method: str = "rf",
    *,
    count: int | None = 500,
    refine: int = 4,
    reseed: int = RESEED,
    population_grains: int = POPULATION_GRAINS,
    population_slopes: str = POPULATION_SLOPES,
    rng: RNGLike = 2024,
    workers: int = 1,
    sphericity: str = "atlas",
    max_across: float | str | None = METHOD_CAP,
    design_grains: int = DESIGN_GRAINS,
    cache: str | os.PathLike | None = None,
    progress: Callable[[Iterable, int], Iterable] | None = None,
    log: Callable[[str], None] | None = None,
    desc: Callable[[str], None] | None = None,
    executor: Any = None,
) -> FitResult:
    """Make ``count`` twins of ``sand``'s grains with ``method``; see the module docstring.

    Parameters
    ----------
    sand : Sand
        The sand to fit (at least :data:`grainforge.fit.sand.MIN_GRAINS` grains with a spread of sizes and
        shapes: :func:`grainforge.fit.sand.check_sand`).
    method : str
        A method of :data:`grainforge.fit.settings.FITS`, or ``"auto"`` (:func:`choose_method`).
    count : int or None
        Grains of the recipe, each the twin of one sand row (:func:`choose_rows`;
        None: every row once).
    refine : int
        Rounds of per-grain refinement of the twins that miss by more than
        :data:`grainforge.fit.refine.REFINE_TOL`.
    reseed : int
        Other seeds tried by each twin still off by more than :data:`grainforge.fit.acceptance.TWIN_TOL`
        after the refinement (:func:`grainforge.fit.recipes.reseed_seed`; a kept seed is written to
        the recipe's ``[grains] seed``).
    population_grains : int
        Twins remade in each round of the estimate of the sand's mean
        settings (:func:`grainforge.fit.mean_settings.population_settings`; at most ``count``): its
        standard errors shrink as one over the square root of the grains,
        down to what the sand's own grain count allows.
    population_slopes : {"auto", "measured", "model"}
        The slopes the estimate steps through: measured on the grains, the
        design model's, or (``"auto"``) measured from
        :data:`grainforge.fit.mean_settings.SLOPES_MEASURED_FROM` grains remade per round
        (:func:`grainforge.fit.mean_settings.population_settings`).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The fit's randomness, resolved to the recipe's root seed ``S``: an int is ``S`` itself (the default
        2024; the same int, the same files); None, a Generator or a spawned SeedSequence gives ``S`` as one
        draw in [0, 2⁶³) (:func:`grainforge.rng.resolve_rng`).  Everything random follows from ``S``, which the
        recipe records as its ``seed``: the sand rows copied (:func:`choose_rows`), each twin's seed (the one
        ``batch`` gives its grain, :func:`grainforge.fit.recipes.grain_seed`) and the reseed tries
        (:func:`grainforge.fit.recipes.reseed_seed`).
    workers : int
        Processes measuring grains (1: this process).
    executor : concurrent.futures.Executor, optional
        Measure the grains on it instead (a :class:`grainforge.runtime.cluster.DaskExecutor`:
        a Dask cluster); the same jobs and seeds, so the same result.  The
        caller opens and closes it.
    sphericity : {"atlas", "whole"}
        How the generated grains' true sphericity is measured: as the Sand
        Atlas did (spam's cube, the default) or on the whole grain
        (:func:`grainforge.analysis.atlas.voxel_descriptors`).
    max_across : float, None or :data:`grainforge.fit.settings.METHOD_CAP`
        Generated grains are measured at most this many voxels across (None:
        at the sand's resolution, however fine; :data:`grainforge.fit.settings.METHOD_CAP`: the
        method's own cap, :attr:`grainforge.fit.settings.MethodFit.max_across`).
    design_grains : int
        Grains of the method's design (cached under ``cache``).
    cache : str or os.PathLike, optional
        Where designs are cached (default :func:`grainforge.runtime.cache.cache_dir`).
    progress : callable, optional
        ``progress(iterable, total)`` wraps each phase's grains (a bar).
    log, desc : callable, optional
        ``log(line)`` gets one line per phase; ``desc(text)`` names the
        phase measured next.

    Returns
    -------
    FitResult
        The twins, their measurements beside their sand rows, the recipe's text and the statistics.

    Raises
    ------
    ValueError
        An unknown ``method`` or ``population_slopes``, a sand :func:`grainforge.fit.sand.check_sand` refuses,
        an ``rng`` of another kind, or twins the generator refuses at every settings tried.
    """
    import time

    if method != "auto" and method not in FITS:
        raise InputError(f"method must be one of {', '.join(list(FITS) + ['auto'])}, got {method!r}")
    slopes_for(population_slopes, 0)  # refuses an unknown choice before any work
    check_sand(sand)
    seed = _root_seed(rng)
    say, name = log or (lambda s: None), desc or (lambda s: None)
    t0 = time.perf_counter()
    history: list[str] = []

    def note(line: str) -> None:
        history.append(line)
        say(line)

    with MeasurePool(max(1, int(workers)), sphericity, executor) as pool:
        if method == "auto":
            method = choose_method(sand, pool, max_across=max_across, grains=design_grains, cache=cache,
                                   progress=progress, say=note, name=name)
            note(f"auto: chose {method}")
        spec = FITS[method]
        cap = resolve_cap(method, max_across)
        name(f"design {method}")
        des = design(method, pool, high=_design_high(sand, cap), grains=design_grains, cache=cache,
                     progress=progress)
        model = des.model()
        note(f"design {method}: model rms " + ", ".join(f"{k[:5]} {r:.4f}" for k, r in zip(DESCRIPTORS, model.rms)))
        known = setting_identifiability(des)
        note(f"design {method}: each setting from a grain's 4 descriptors (R², rms error): " + ", ".join(
            f"{k} {r2:.2f} ±{e:.3g}" for k, (r2, e) in known.items()))
        opening = uses_opening(sand, cap)
        if sand.opening is not None and not opening:
            note(f"population: the table's opening fraction is not used: {method}'s twins of its grains over "
                 f"{cap:g} voxels across are measured at {cap:g}, where their opening fraction is not the sand "
                 "grain's (--max-voxels-across 0 measures every grain at the sand's resolution)")
        rows = choose_rows(sand.count, count, seed)
        tw = _start_twins(spec, model, sand, rows, cap, seed)
        idx = np.arange(len(rows))
        population = None
        for r in range(refine + 1):
            name("twins" if r == 0 else f"refine {r}/{refine}")
            y = _measure_twins(tw, pool, idx, progress)
            note(f"{'twins' if r == 0 else f'refine {r}'}: {len(idx)} grains measured; {_twin_summary(tw)}")
            if r == 0:
                population = population_settings(spec, sand, model=model, pool=pool, u0=tw.u, y0=y, seeds=tw.seeds,
                                                 across=tw.across, shrink=[r2 for r2, _ in known.values()],
                                                 grains=population_grains, slopes=population_slopes,
                                                 opening=opening, progress=progress, log=note, desc=name)
                note(f"population: the sand's mean settings from its descriptors' means"
                     f"{' and its opening fraction' if opening else ''} (± standard error; "
                     f"{sand.count} sand grains, {population.grains} made): {population.text()}")
            keep = tw.relative(tw.best_y[idx], idx) > 1
            if r == refine or not keep.any():
                break
            idx, y = idx[keep], y[keep]
            _refine(tw, model, idx, y)
        _reseed(tw, model, pool, seed, reseed, progress, note, name)
        _make_refused(tw, pool, progress, note, name)
    return _result(sand, spec, tw, rows, seed, history, time.perf_counter() - t0, pool, known, population)


def _root_seed(rng: RNGLike) -> int:
    """The fit's root seed (the recipe's ``seed``): an int ``rng`` itself, else one draw in [0, 2⁶³).

    Examples
    --------
    >>> _root_seed(7), _root_seed(np.random.SeedSequence(7))
    (7, 7)
    >>> _root_seed(np.random.default_rng(1)) == _root_seed(np.random.default_rng(1))
    True
    """
    generator, seed = resolve_rng(rng)
    # a Generator or a spawned SeedSequence has no seed, None's entropy is 128 bits: one draw is the root seed
    if seed is None or (seed >= 2**63 and not isinstance(rng, (int, np.integer))):
        seed = int(generator.integers(0, 2**63))
    return seed


def _result(sand: Sand, spec: MethodFit, tw: _Twins, rows: np.ndarray, seed: int, history: list[str],
            seconds: float, pool: MeasurePool, known: dict[str, tuple[float, float]],
            population: Population | None = None) -> FitResult:
    """The fit's result from its twins: each grain's closest measurement, its settings and the recipe."""
    ok = tw.made()
    err = tw.error(tw.best_y)
    reachable = (tw.reach <= TWIN_TOL) | (err <= TWIN_TOL)
    within = float(np.mean(err[reachable] <= TWIN_TOL)) if reachable.any() else 0.0
    st = compare(tw.targets[ok], tw.best_y[ok], twin_within=within)
    st["reachable"] = float(np.mean(reachable))
    st["unreachable_by"] = _unreachable_by(tw, ~reachable)
    st["refused"] = int((~ok).sum())
    size_mm = [_written(float(d) / 1000.0) for d in sand.equivalent_diameter[rows]]
    gen = np.column_stack([np.asarray(size_mm) * 1000.0, tw.best_y])
    header = _recipe_header(sand, spec.method, st, len(rows), known, population)
    own = [spec.grain_params(u) for u in tw.best_u]
    text = twin_recipe_text(spec, own, size_mm=size_mm, seed=seed, header=header, seeds=tw.seeds)
    return FitResult(method=spec.method, recipe=text, stats=st, generated=gen, sand_rows=rows,
                     settings=[spec.values(u) for u in tw.best_u], reachable=reachable, history=history,
                     seconds=seconds, cpu_seconds=pool.cpu, grains_measured=pool.grains, targets=tw.targets,
                     identifiable=known, population=population, seeds=list(tw.seeds))


def _unreachable_by(tw: _Twins, out: np.ndarray) -> dict[str, int]:
    """Unreachable grains counted by the descriptor their closest twin misses most."""
    if not out.any():
        return {}
    worst = np.nanargmax(np.abs(np.nan_to_num(tw.best_y[out], nan=9.0) - tw.targets[out]), axis=1)
    return {DESCRIPTORS[k]: int(np.sum(worst == k)) for k in range(4) if np.any(worst == k)}


def _recipe_header(sand: Sand, method: str, st: dict, n: int, known: dict[str, tuple[float, float]],
                   population: Population | None = None) -> str:
    lines = [f"grainforge fit: {n} {method} grains, each the twin of one grain of {sand.name} "
             f"({sand.count} grains, voxel {sand.voxel_size:g} µm)"]
    lines += [f"{k}: sand {p['sand_mean']:.3f} generated {p['gen_mean']:.3f} KS {p['ks']:.3f}"
              for k, p in st["per"].items()]
    lines += ["Spearman " + ", ".join(f"{k} {a:+.2f}/{b:+.2f}" for k, (a, b) in st["corr"].items())]
    lines += [f"{st['twin_within']:.1%} of reachable twins within {TWIN_TOL}; {1 - st['reachable']:.1%} "
              "unreachable"]
    lines += [f"{'passes' if st['pass'] else 'does NOT pass'}: KS <= {KS_MAX}, |mean diff| <= {MEAN_TOL}, "
              f"|Spearman diff| <= {CORR_TOL}, twins within {TWIN_TOL} for >= {TWIN_SHARE:.0%}"]
    sure = [f"{k} (±{e:.2g})" for k, (r2, e) in known.items() if r2 >= IDENTIFIABLE_R2]
    loose = [f"{k} (R² {r2:.2f})" for k, (r2, e) in known.items() if r2 < IDENTIFIABLE_R2]
    lines += [f"settings a grain's descriptors determine: {', '.join(sure) or 'none'}; "
              f"not determined (seed or another setting shapes the same descriptors): {', '.join(loose) or 'none'}"]
    if population is not None:
        why = (f"; ± spread: the estimate's move with a {SPREAD_DOUBT:.0%} wider spread of the settings a grain's "
               "descriptors do not determine" if any(population.spread.values()) else "")
        lines += [f"the sand's mean settings (± standard error{why}): {population.text()}"]
    return "\n".join(lines)
