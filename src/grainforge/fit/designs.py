"""A method's design: grains spread over its settings and resolutions, measured once and cached on disk.

The design is the inverse model's data (:class:`Design`, whose
:meth:`Design.model` is :class:`grainforge.fit.twins.ForwardModel`): a few
hundred grains of the method, their per-grain settings and resolution spread
over the method's whole range (a Sobol design), each generated and measured
once; cached per method, convention and resolution range
(:func:`design_path`), so a second fit of any sand measures none.
:func:`setting_identifiability` tells from it how well a grain's four
descriptors determine each setting.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .made_grains import MeasurePool
from .recipes import grain_seed
from .sand import Sand
from .settings import FITS

#: grains of a method's design, and the smallest resolution it spans (voxels across)
DESIGN_GRAINS = 400
DESIGN_ACROSS_LOW = 10.0
#: root seed of every design (designs do not depend on the sand or the fit's seed); bump DESIGN_VERSION
#: when a generator or the measurement changes, so that cached designs are not reused
DESIGN_SEED = 20261202
#: 2: a grain's voxel size (d_eq / voxels across) and its d_eq are np.cbrt's (geometry.moments.sphere_diameter), not a power
#: of 1/3: the designs' measurements change in their last bits
DESIGN_VERSION = 2


def _design_high(sand: Sand, max_across: float | None) -> float:
    """Highest resolution a design spans: the cap, or (uncapped) the sand's largest grain's, on a 10 % grid."""
    if max_across:
        return float(max_across)
    top = float((sand.equivalent_diameter / sand.voxel_size).max())
    return float(f"{1.1 ** math.ceil(math.log(max(top, DESIGN_ACROSS_LOW * 1.1)) / math.log(1.1)):.4g}")


def design_path(method: str, convention: str, *, high: float, grains: int = DESIGN_GRAINS,
                cache: str | os.PathLike | None = None) -> Path:
    """Where a method's design is cached: under ``cache`` (default :func:`grainforge.runtime.cache.cache_dir`),
    keyed by everything that changes its grains.

    Parameters
    ----------
    method : str
        A method of :data:`grainforge.fit.settings.FITS`.
    convention : {"atlas", "whole"}
        How the design's true sphericity is measured.
    high : float
        The highest resolution the design spans, voxels across (keyword-only).
    grains : int
        Grains of the design.
    cache : str or os.PathLike, optional
        The cache folder; default :func:`grainforge.runtime.cache.cache_dir`.

    Returns
    -------
    pathlib.Path
        ``CACHE/fit-designs/METHOD-CONVENTION-HIGH-GRAINS-DIGEST.npz``, the digest of the design's version,
        grainforge's, :data:`DESIGN_SEED`, the method's settings and fixed parameters and the arguments (the
        file need not exist).

    Examples
    --------
    >>> p = design_path("rf", "atlas", high=40.0, grains=80, cache="/tmp/c")
    >>> p.parent.as_posix(), p.name.startswith("rf-atlas-40-80-"), p.suffix
    ('/tmp/c/fit-designs', True, '.npz')
    """
    from .._version import __version__
    from ..runtime.cache import cache_dir

    spec = FITS[method]
    key = repr((DESIGN_VERSION, __version__, DESIGN_SEED, method, spec.all_settings, sorted(spec.fixed.items()),
                convention, float(high), int(grains)))
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return Path(cache or cache_dir()) / "fit-designs" / f"{method}-{convention}-{high:g}-{grains}-{digest}.npz"


@dataclass(frozen=True)
class Design:
    """A method's design: unit-box settings ``u``, resolutions ``across`` and measured descriptors ``y``.

    Attributes
    ----------
    method : str
        The method's name.
    u : (n, p) numpy.ndarray
        Each design grain's settings in the unit box (one column per setting of its
        :attr:`grainforge.fit.settings.MethodFit.all_settings`).
    across : (n,) numpy.ndarray
        Voxels across each was measured at.
    y : (n, 4) numpy.ndarray
        Its measured descriptors (:data:`grainforge.fit.sand.DESCRIPTORS`); NaN rows where the generator
        refused the settings.
    """

    method: str
    u: np.ndarray
    across: np.ndarray
    y: np.ndarray  # NaN rows: the generator refused those settings

    def model(self):
        """The forward model fitted to the design's grains that were made.

        Returns
        -------
        grainforge.fit.twins.ForwardModel
            Settings and voxels across -> the four descriptors, fitted to the rows of ``y`` without NaN.
        """
        from .twins import ForwardModel

        ok = np.all(np.isfinite(self.y), axis=1)
        return ForwardModel.fit(self.u[ok], self.across[ok], self.y[ok])


def design(method: str, pool: MeasurePool, *, high: float, grains: int = DESIGN_GRAINS,
           cache: str | os.PathLike | None = None, progress=None) -> Design:
    """The cached design of ``method`` (measured, and cached atomically, if it is not yet).

    Its grains' settings and resolutions are a scrambled Sobol design (:func:`grainforge.fit.twins.design_points`,
    ``rng`` :data:`DESIGN_SEED`), their resolutions log-uniform from :data:`DESIGN_ACROSS_LOW` to ``high``,
    grain ``i`` made with the seed ``batch`` gives grain ``i`` of a recipe of root seed :data:`DESIGN_SEED`: a
    design does not depend on the sand or on the fit's seed.

    Parameters
    ----------
    method : str
        A method of :data:`grainforge.fit.settings.FITS`.
    pool : MeasurePool
        Where the grains are made and measured (its ``convention`` is part of the cache key).
    high : float
        The highest resolution the design spans, voxels across.
    grains : int
        Grains of the design.
    cache : str or os.PathLike, optional
        The cache folder (:func:`design_path`).
    progress : callable, optional
        ``progress(iterable, total)`` wraps the grains as they are measured (a bar).

    Returns
    -------
    Design
        Loaded from the cache when it is there, else measured and written to it.
    """
    from ..io import atomic_write
    from .twins import design_points

    spec = FITS[method]
    path = design_path(method, pool.convention, high=high, grains=grains, cache=cache)
    if path.exists():
        with np.load(path) as z:
            return Design(method, z["u"], z["across"], z["y"])
    pts = design_points(grains, len(spec.all_settings) + 1, rng=DESIGN_SEED)
    u, t = pts[:, :-1], pts[:, -1]
    across = DESIGN_ACROSS_LOW * (high / DESIGN_ACROSS_LOW) ** t
    jobs = [(spec.grain_params(u[i]), grain_seed(DESIGN_SEED, i), float(across[i])) for i in range(grains)]
    y = pool.run(method, spec.fixed, jobs, progress=progress)
    buf = io.BytesIO()
    np.savez(buf, u=u, across=across, y=y)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, buf.getvalue())
    return Design(method, u, across, y)


#: a setting predicted from a grain's descriptors with at least this cross-validated R² is called identifiable
IDENTIFIABLE_R2 = 0.9


def setting_identifiability(des: Design) -> dict[str, tuple[float, float]]:
    """Per setting of ``des``'s method: (R², rms error in the setting's units) of predicting it from a grain's
    four descriptors (:func:`grainforge.fit.twins.identifiability` on the design).

    What the fitted settings of a twin can say about its sand grain: with R² ≥ :data:`IDENTIFIABLE_R2` the
    descriptors determine the setting (a sand's setting is *acquired* from its scan, within the error);
    near 0 the grain's seed or another setting shapes the same descriptors, and the fitted value is one
    choice among many that measure alike.

    Parameters
    ----------
    des : Design
        A method's design (its rows with NaN left out).

    Returns
    -------
    dict of str to (float, float)
        Setting name (in the order of :attr:`grainforge.fit.settings.MethodFit.all_settings`) -> (cross-validated
        R², rms error in the setting's own units).
    """
    from .twins import identifiability

    ok = np.all(np.isfinite(des.y), axis=1)
    r2, rmse = identifiability(des.u[ok], des.across[ok], des.y[ok])
    return {st.name: (float(a), float(e * (st.high - st.low)))
            for st, a, e in zip(FITS[des.method].all_settings, r2, rmse)}
