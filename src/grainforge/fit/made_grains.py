"""Grains made and measured the Sand Atlas way: one by one, on a worker pool or on a Dask cluster.

:func:`measure_made_grain` measures grain ``index`` of a recipe exactly as
``batch`` makes it; :func:`measure_settings` one grain of given parameters
and ``rng`` (the grain's seed); :class:`MeasurePool` runs many such jobs, each
result in its job's place, and counts the grains and CPU seconds they took.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from ..analysis.atlas import OPENING_RADIUS
from ..rng import RNGLike, as_generator, resolve_rng
from .sand import DESCRIPTORS


@lru_cache(maxsize=8)
def _recipe(text: str):
    from ..population import parse_recipe

    return parse_recipe(text, source="<fit>")


def measure_made_grain(text: str, index: int, *, voxel_size_um: float, convention: str = "atlas",
                  max_across: float | None = None) -> tuple[float, ...]:
    """Grain ``index`` of recipe ``text`` as ``batch`` makes it, measured the Atlas way.

    It is voxelised at ``voxel_size_um`` relative to its drawn equivalent
    diameter (at most ``max_across`` voxels across), in a random orientation
    drawn from its own seed; ``convention`` is true sphericity's
    (:func:`grainforge.analysis.atlas.voxel_descriptors`).

    Parameters
    ----------
    text : str
        A ``grainforge batch`` recipe's TOML text (parsed once and cached).
    index : int
        The grain's index in the recipe, from 0.
    voxel_size_um : float
        The sand's voxel size, µm: the grain is measured ``d_eq / voxel_size_um`` voxels across (keyword-only).
    convention : {"atlas", "whole"}
        How true sphericity is measured.
    max_across : float, optional
        Measured at most this many voxels across; None: uncapped.

    Returns
    -------
    tuple of float
        (d_eq µm, sphericity, convexity, flatness, elongation, CPU seconds spent).

    Raises
    ------
    grainforge.population.recipe.RecipeError
        If ``text`` is not a valid recipe.
    ValueError
        If the grain's drawn parameters cannot be made.

    Examples
    --------
    >>> text = 'method = "rf"\\ncount = 2\\nseed = 1\\n[params]\\nsubdivisions = 3\\n[size]\\nmm = 0.12\\n'
    >>> d = measure_made_grain(text, 1, voxel_size_um=10.0)
    >>> round(d[0], 6), len(d), bool(0.5 < d[1] < 1.1)
    (120.0, 6, True)
    """
    import time

    cpu = time.process_time()
    from ..population import draw_grain

    recipe = _recipe(text)
    seed, params, size_mm = draw_grain(recipe, index)
    across = size_mm * 1000.0 / voxel_size_um
    d = _measure(recipe.method, params, seed, min(across, max_across) if max_across else across, convention)
    return (size_mm * 1000.0, *d, time.process_time() - cpu)


def _salted(rng: RNGLike, *salt: int) -> tuple[np.random.Generator, np.random.Generator]:
    """(the stream of ``rng``, a second stream): for an int seed ``s`` (or a plain SeedSequence of it, or None's
    entropy) ``default_rng(s)`` and ``default_rng([s, *salt])``, the streams a seed has always given; for a
    Generator (or a spawned SeedSequence) the one Generator twice, its draws continuing."""
    generator, seed = resolve_rng(rng)
    return generator, (generator if seed is None else as_generator(np.random.SeedSequence([seed, *salt])))


def _measure(method: str, params: Any, rng: RNGLike, across: float, convention: str,
             opening: bool = False) -> tuple[float, ...]:
    from ..analysis.atlas import opening_fraction, voxel_descriptors, voxel_image
    from ..methods import generate

    shape, turn = _salted(rng, 1)
    grain = generate(method, params, shape)
    mask, h, _ = voxel_image(grain, voxels_across=across, rotation=turn)
    d = voxel_descriptors(mask, h, convention=convention)
    return tuple(float(d[k]) for k in DESCRIPTORS) + ((opening_fraction(mask, OPENING_RADIUS * across),)
                                                      if opening else ())


def measure_settings(method: str, fixed: Mapping[str, Any], *, own: Mapping[str, Any], rng: RNGLike,
                     across: float, convention: str = "atlas", opening: bool = False) -> tuple[float, ...]:
    """One grain made with ``fixed`` and its ``own`` parameters and ``rng``, measured ``across`` voxels across.

    Parameters
    ----------
    method : str
        The generator's name.
    fixed : mapping
        Parameters every grain shares (a recipe's ``[params]``).
    own : mapping
        The grain's own parameters (a recipe's ``[grains]`` row); they override ``fixed``.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The grain's randomness, normalised by :func:`grainforge.rng.resolve_rng`.  An int seed ``s`` is the
        grain's seed as ``batch`` gives it (``generate(method, params, s)``), its orientation drawn from
        ``SeedSequence([s, 1])``: the same grain and numbers as ever; a Generator makes the grain and then
        draws the orientation, advanced by both.
    across : float
        Voxels across the grain is measured at (its equivalent diameter over the voxel size).
    convention : {"atlas", "whole"}
        How true sphericity is measured (:func:`grainforge.analysis.atlas.voxel_descriptors`).
    opening : bool
        Measure the opening fraction too (:data:`grainforge.fit.sand.OPENING_COLUMN`).

    Returns
    -------
    tuple of float
        The four descriptors of :data:`grainforge.fit.sand.DESCRIPTORS` (and, with ``opening``, the opening
        fraction), then the CPU seconds spent; NaNs for the measurements if the generator refuses these
        settings (a design corner, say).

    Examples
    --------
    >>> from grainforge.fit import FITS
    >>> spec = FITS["rf"]
    >>> own = spec.grain_params(np.full(5, 0.5))
    >>> d = measure_settings("rf", spec.fixed, own=own, rng=7, across=12.0)
    >>> len(d), bool(all(0 < x < 1.2 for x in d[:4]))
    (5, True)
    >>> d[:4] == measure_settings("rf", spec.fixed, own=own, rng=np.random.SeedSequence(7), across=12.0)[:4]
    True
    """
    import time

    from ..methods import get
    from ..params import ParameterError

    cpu = time.process_time()
    try:
        d = _measure(method, get(method).Params(**{**fixed, **own}), rng, across, convention, opening)
    except (ParameterError, ValueError):
        d = (math.nan,) * (len(DESCRIPTORS) + bool(opening))
    return (*d, time.process_time() - cpu)


class MeasurePool:
    """Runs :func:`measure_settings` jobs, in this process, on a worker pool or on the caller's ``executor``.

    The same jobs and seeds give the same descriptors wherever they run, each result in its job's place.
    Use it as a context manager: a pool of its own (``workers`` > 1, no ``executor``) is started on entering
    and closed on leaving (at once on an error or interrupt); the caller's ``executor`` is left open.

    Parameters
    ----------
    workers : int
        Processes measuring grains; 1 measures them in this process.
    convention : {"atlas", "whole"}
        How true sphericity is measured (:func:`grainforge.analysis.atlas.voxel_descriptors`).
    executor : concurrent.futures.Executor, optional
        Measure on it instead (a :class:`grainforge.runtime.cluster.DaskExecutor`: a Dask cluster);
        ``workers`` is then not used.

    Attributes
    ----------
    cpu : float
        CPU seconds the jobs run so far spent generating and measuring (summed over the workers).
    grains : int
        Grains measured so far.

    Examples
    --------
    >>> from grainforge.fit import FITS
    >>> spec = FITS["rf"]
    >>> with MeasurePool(1) as pool:
    ...     y = pool.run("rf", spec.fixed, [(spec.grain_params(np.full(5, 0.5)), 7, 12.0)])
    >>> y.shape, pool.grains, bool(np.all((y > 0) & (y < 1.2)))
    ((1, 4), 1, True)
    """

    def __init__(self, workers: int, convention: str = "atlas", executor=None):
        self.workers = workers
        self.convention = convention
        self.ex = executor
        self.own = executor is None  # a pool of our own is closed on leaving; the caller's executor is not
        self.cpu = 0.0  # CPU seconds the workers spent generating and measuring
        self.grains = 0
        self.pool_block = contextlib.ExitStack()  # the pool of our own, left with this block

    def __enter__(self):
        if self.own and self.workers > 1:
            from ..runtime.workers import process_pool

            self.ex = self.pool_block.enter_context(process_pool(
                self.workers, ["grainforge.fit", "grainforge.analysis.atlas", "grainforge.population", "trimesh",
                               "scipy.ndimage", "skimage.measure"]))
        return self

    def __exit__(self, exc_type, exc, tb):
        # the pool's own exit: an error, Ctrl-C or SIGTERM stops the workers now (waiting for them from inside
        # an interrupted as_completed could hang; seen with SIGTERM during a fit)
        return self.pool_block.__exit__(exc_type, exc, tb)

    def run(self, method: str, fixed: Mapping[str, Any], jobs: Sequence[tuple[dict, int, float]], *,
            progress: Callable[[Iterable, int], Iterable] | None = None, opening: bool = False) -> np.ndarray:
        """Measure each job: a grain of ``method`` made with ``fixed`` and the job's own parameters and seed.

        Parameters
        ----------
        method : str
            Generator name.
        fixed : mapping
            Parameters every grain shares.
        jobs : sequence of (dict, int, float)
            Per grain: its own parameters, its seed (the ``rng`` of :func:`measure_settings`) and the voxels
            across it is measured at.
        progress : callable, optional
            ``progress(iterable, total)`` wraps the results as they arrive (a bar); keyword-only.
        opening : bool
            Measure the opening fraction too (:data:`grainforge.fit.sand.OPENING_COLUMN`).

        Returns
        -------
        numpy.ndarray
            (n, 4) descriptors of the jobs, in job order; NaN rows where the generator refused the
            settings.  With ``opening``, (n, 5): the opening fraction last.
        """
        width = len(DESCRIPTORS) + bool(opening)
        out = np.empty((len(jobs), width))
        args = [dict(own=own, rng=seed, across=across, convention=self.convention, opening=bool(opening))
                for own, seed, across in jobs]
        if self.ex is None:
            it: Iterable = ((i, measure_settings(method, fixed, **a)) for i, a in enumerate(args))
        else:
            from concurrent.futures import as_completed

            futs = {self.ex.submit(measure_settings, method, fixed, **a): i for i, a in enumerate(args)}
            it = ((futs[f], f.result()) for f in as_completed(futs))
        if progress is not None and jobs:
            it = progress(it, len(jobs))
        done = False
        try:
            for i, row in it:
                out[i] = row[:width]
                self.cpu += row[width]
                self.grains += 1
            done = True
        finally:
            if not done and self.ex is not None:  # an error or interrupt: drop the jobs not started
                for f in futs:
                    f.cancel()
        return out
