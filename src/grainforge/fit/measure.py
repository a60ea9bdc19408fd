"""Grains made and measured the Sand Atlas way: one by one, on a worker pool or on a Dask cluster.

:func:`measure_grain` measures grain ``index`` of a recipe exactly as
``batch`` makes it; :func:`measure_settings` one grain of given parameters
and seed; :class:`MeasurePool` runs many such jobs, each result in its job's
place, and counts the grains and CPU seconds they took.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from ..analysis.atlas import OPENING_RADIUS
from .sand import DESCRIPTORS


@lru_cache(maxsize=8)
def _recipe(text: str):
    from ..population import parse_recipe

    return parse_recipe(text, source="<fit>")


def measure_grain(text: str, index: int, voxel_size_um: float, convention: str = "atlas",
                  max_across: float | None = None) -> tuple[float, ...]:
    """Grain ``index`` of recipe ``text`` as ``batch`` makes it, measured the Atlas way.

    It is voxelised at ``voxel_size_um`` relative to its drawn equivalent
    diameter (at most ``max_across`` voxels across), in a random orientation
    drawn from its own seed; ``convention`` is true sphericity's
    (:func:`grainforge.analysis.atlas.voxel_descriptors`).  Returns (d_eq µm,
    sphericity, convexity, flatness, elongation, CPU seconds spent).
    """
    import time

    cpu = time.process_time()
    from ..population import draw_grain

    recipe = _recipe(text)
    seed, params, size_mm = draw_grain(recipe, index)
    across = size_mm * 1000.0 / voxel_size_um
    d = _measure(recipe.method, params, seed, min(across, max_across) if max_across else across, convention)
    return (size_mm * 1000.0, *d, time.process_time() - cpu)


def _measure(method: str, params: Any, seed: int, across: float, convention: str,
             opening: bool = False) -> tuple[float, ...]:
    from ..analysis.atlas import opening_fraction, voxel_descriptors, voxel_image
    from ..methods import generate

    grain = generate(method, params, seed)
    mask, h, _ = voxel_image(grain, voxels_across=across, rotation=np.random.default_rng([seed, 1]))
    d = voxel_descriptors(mask, h, convention=convention)
    return tuple(float(d[k]) for k in DESCRIPTORS) + ((opening_fraction(mask, OPENING_RADIUS * across),)
                                                      if opening else ())


def measure_settings(method: str, fixed: Mapping[str, Any], own: Mapping[str, Any], seed: int, across: float,
                     convention: str = "atlas", opening: bool = False) -> tuple[float, ...]:
    """One grain made with ``fixed`` and its ``own`` parameters and ``seed``, measured ``across`` voxels across.

    Returns the four descriptors (and, with ``opening``, the opening fraction of
    :data:`grainforge.fit.sand.OPENING_COLUMN`) and the CPU seconds; NaNs if the generator refuses these
    settings (a design corner, say).
    """
    import time

    from ..methods import get
    from ..params import ParameterError

    cpu = time.process_time()
    try:
        d = _measure(method, get(method).Params(**{**fixed, **own}), seed, across, convention, opening)
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
    ...     y = pool.run("rf", spec.fixed, [(spec.grain_params(np.full(5, 0.5)), 7, 12.0)], None)
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

    def __enter__(self):
        if self.own and self.workers > 1:
            from ..runtime.workers import process_pool

            self.ex = process_pool(self.workers, ["grainforge.fit", "grainforge.analysis.atlas",
                                                  "grainforge.population", "trimesh", "scipy.ndimage",
                                                  "skimage.measure"])
        return self

    def __exit__(self, exc_type, exc, tb):
        if self.ex is not None and self.own:
            from ..runtime.workers import close_pool

            # an error, Ctrl-C or SIGTERM: stop the workers now (waiting for them from inside an
            # interrupted as_completed could hang; seen with SIGTERM during a fit)
            close_pool(self.ex, abort=exc_type is not None)

    def run(self, method: str, fixed: Mapping[str, Any], jobs: Sequence[tuple[dict, int, float]],
            progress, opening: bool = False) -> np.ndarray:
        """Measure each job: a grain of ``method`` made with ``fixed`` and the job's own parameters and seed.

        Parameters
        ----------
        method : str
            Generator name.
        fixed : mapping
            Parameters every grain shares.
        jobs : sequence of (dict, int, float)
            Per grain: its own parameters, its seed and the voxels across it is measured at.
        progress : callable or None
            ``progress(iterable, total)`` wraps the results as they arrive (a bar).
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
        args = [(method, fixed, own, seed, across, self.convention, bool(opening)) for own, seed, across in jobs]
        if self.ex is None:
            it: Iterable = ((i, measure_settings(*a)) for i, a in enumerate(args))
        else:
            from concurrent.futures import as_completed

            from ..runtime.workers import single_threaded_children

            with single_threaded_children():
                futs = {self.ex.submit(measure_settings, *a): i for i, a in enumerate(args)}
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
