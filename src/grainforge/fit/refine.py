"""The twins' settings: started from the inverse model, refined, reseeded, and moved until the generator makes them.

Each twin starts at the settings the inverse model gives for its sand grain
(:func:`grainforge.fit.twins.invert`).  A twin more than :data:`REFINE_TOL`
off on any descriptor gets new settings from the model plus its own offset
(measured minus predicted: what its seed and orientation add) and is measured
again; each grain keeps its closest twin.  A twin still more than
:data:`grainforge.fit.acceptance.TWIN_TOL` off tries up to :data:`RESEED`
other seeds (:func:`grainforge.fit.recipes.reseed_seed`), and one the
generator refused at every settings tried is moved towards the middle of the
design box until it is made.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .acceptance import TWIN_TOL
from .made_grains import MeasurePool
from .recipes import grain_seed, reseed_seed
from .sand import Sand, measured_across
from .settings import MethodFit

#: a twin further than this from its sand grain on any descriptor, or than REFINE_SD of the sand's sd of
#: that descriptor, is refined (tighter than TWIN_TOL: the population's means and rank correlations need
#: twins that are close on the scale of the sand's own spread, not just inside the tolerance)
REFINE_TOL = 0.012
REFINE_SD = 0.3
#: extra tries, after the refinement, for a twin the generator refused to make at every settings tried so far
#: (each moves its settings a third of the way towards the middle of the design box)
REFUSED_TRIES = 6
#: twins still off by more than TWIN_TOL after the refinement try up to this many other seeds (``--reseed``)
RESEED = 6


@dataclass
class _Twins:
    """The fit's working state: per grain its target, resolution, seed, settings and best twin so far."""

    spec: MethodFit
    targets: np.ndarray  # (n, 4)
    across: np.ndarray  # (n,) measured at
    seeds: list[int]
    u: np.ndarray  # (n, p) settings being tried
    reach: np.ndarray  # (n,) the model's predicted miss at u
    tol: np.ndarray  # (4,) refinement tolerance per descriptor
    best_u: np.ndarray = None  # type: ignore[assignment]
    best_y: np.ndarray = None  # type: ignore[assignment]

    def error(self, y: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """Largest |measured − target| per grain (of ``idx``, default all); inf where unmeasured."""
        e = np.max(np.abs(y - (self.targets if idx is None else self.targets[idx])), axis=1)
        return np.where(np.isfinite(e), e, np.inf)

    def relative(self, y: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Largest |measured − target| / tolerance per grain of ``idx``: > 1 is refined."""
        e = np.max(np.abs(y - self.targets[idx]) / self.tol, axis=1)
        return np.where(np.isfinite(e), e, np.inf)

    def made(self) -> np.ndarray:
        """(n,) bool: the generator has made and measured the grain at some settings tried."""
        return np.all(np.isfinite(self.best_y), axis=1)

    def keep_reseeded(self, idx: np.ndarray, u: np.ndarray, y: np.ndarray, seeds: Sequence[int],
                      reach: np.ndarray) -> np.ndarray:
        """Keep, for twins ``idx``, the grains made with other ``seeds`` at settings ``u`` that come closer than
        their best so far; returns which were kept."""
        better = self.relative(y, idx) < self.relative(self.best_y[idx], idx)
        kept = idx[better]
        self.best_u[kept] = self.u[kept] = u[better]
        self.best_y[kept], self.reach[kept] = y[better], reach[better]
        for i, s in zip(kept, np.asarray(seeds)[better]):
            self.seeds[i] = int(s)
        return better

    def keep_best(self, idx: np.ndarray, y: np.ndarray) -> None:
        if self.best_y is None:
            self.best_u, self.best_y = self.u.copy(), np.full_like(self.targets, np.nan)
        better = self.relative(y, idx) < self.relative(self.best_y[idx], idx)
        self.best_u[idx[better]] = self.u[idx[better]]
        self.best_y[idx[better]] = y[better]


def _start_twins(spec: MethodFit, model, sand: Sand, rows: np.ndarray, across_cap: float | None,
                 seed: int) -> _Twins:
    """Each twin's first settings: the inverse model's, for its original at its resolution."""
    from .twins import invert

    targets = sand.table()[rows]
    across = measured_across(sand, across_cap)[rows]
    tol = np.minimum(REFINE_TOL, REFINE_SD * sand.table().std(axis=0))
    u, miss = invert(model, targets, across, scale=tol)
    return _Twins(spec, targets, across, [grain_seed(seed, i) for i in range(len(rows))], u, miss, tol)


def _measure_twins(tw: _Twins, pool: MeasurePool, idx: np.ndarray, progress) -> np.ndarray:
    jobs = [(tw.spec.grain_params(tw.u[i]), tw.seeds[i], float(tw.across[i])) for i in idx]
    y = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress=progress)
    tw.keep_best(idx, y)
    return y


def _refine(tw: _Twins, model, idx: np.ndarray, y: np.ndarray) -> None:
    """New settings for twins ``idx`` (last measured ``y``): the model plus each grain's own offset."""
    from .twins import invert

    pred = np.array([model.predict(tw.u[i], tw.across[i])[0] for i in idx])
    offsets = np.where(np.isfinite(y), y - pred, 0.0)
    u, miss = invert(model, tw.targets[idx], tw.across[idx], offsets=offsets, start=tw.u[idx], scale=tw.tol)
    # a grain the generator refused to make or measure at its settings (a corner of the design box, with its own
    # seed) is not re-solved, which would lead back to that corner: its settings move towards the middle
    refused = ~np.all(np.isfinite(y), axis=1)
    u[refused] = _toward_middle(tw.u[idx][refused])
    tw.u[idx] = u
    tw.reach[idx] = miss


def _reseed(tw: _Twins, model, pool: MeasurePool, root: int, tries: int, progress, note, name) -> None:
    """Twins still off by more than :data:`grainforge.fit.acceptance.TWIN_TOL` try other seeds: each is made at its best
    settings with a new seed, then once more at the settings the model gives with that seed's own offset, and keeps the
    closer of the two if it beats its best.  Where a grain's seed shapes a descriptor as much as a setting can (the
    angular method's sphericity and convexity), another seed can put the sand grain within reach."""
    from .twins import invert

    for k in range(tries):
        idx = np.flatnonzero(tw.error(tw.best_y) > TWIN_TOL)
        if not len(idx):
            return
        seeds = [reseed_seed(root, int(i), k) for i in idx]
        u0 = tw.best_u[idx].copy()
        name(f"reseed {k + 1}/{tries}")
        jobs = [(tw.spec.grain_params(u0[j]), seeds[j], float(tw.across[i])) for j, i in enumerate(idx)]
        y0 = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress=progress)
        pred = model.predict(u0, tw.across[idx])
        made = np.all(np.isfinite(y0), axis=1)
        u1, reach = invert(model, tw.targets[idx], tw.across[idx], offsets=np.where(made[:, None], y0 - pred, 0.0),
                           start=u0, scale=tw.tol)
        u1[~made] = u0[~made]
        jobs = [(tw.spec.grain_params(u1[j]), seeds[j], float(tw.across[i])) for j, i in enumerate(idx)]
        y1 = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress=progress)
        first = tw.relative(y0, idx) <= tw.relative(y1, idx)
        u = np.where(first[:, None], u0, u1)
        y = np.where(first[:, None], y0, y1)
        kept = tw.keep_reseeded(idx, u, y, seeds, np.where(first, tw.reach[idx], reach))
        note(f"reseed {k + 1}: {len(idx)} twins off by more than {TWIN_TOL} tried another seed, {int(kept.sum())} "
             f"came closer; {_twin_summary(tw)}")


def _toward_middle(u: np.ndarray) -> np.ndarray:
    """Unit-box settings moved a third of the way towards the middle of the box (where the generator makes every
    grain of the design)."""
    return 0.5 + (u - 0.5) * (2.0 / 3.0)


def _make_refused(tw: _Twins, pool: MeasurePool, progress, note, name) -> None:
    """Move the settings of twins never made so far towards the middle of the box until the generator makes them,
    so that every grain of the recipe can be built; a twin still refused after :data:`REFUSED_TRIES` is an error."""
    for k in range(REFUSED_TRIES):
        refused = np.flatnonzero(~tw.made())
        if not len(refused):
            return
        name(f"refused twins, try {k + 1}/{REFUSED_TRIES}")
        tw.u[refused] = _toward_middle(tw.u[refused])
        _measure_twins(tw, pool, refused, progress)
        note(f"refused twins: {len(refused)} the generator had refused at every settings tried, moved towards the "
             f"middle of the box; {int(tw.made()[refused].sum())} made")
    if not tw.made().all():
        raise InputError(f"{int((~tw.made()).sum())} twin(s) could not be made at any settings tried: the "
                         f"{tw.spec.method} generator refuses them; try another {{method}} or {{seed}}",
                         setting=("method", "seed"))


def _twin_summary(tw: _Twins) -> str:
    e = tw.error(tw.best_y)
    reach = tw.reach <= TWIN_TOL
    return (f"{np.mean(e <= TWIN_TOL):.1%} of twins within {TWIN_TOL} on every descriptor "
            f"({np.mean(e[reach] <= TWIN_TOL) if reach.any() else 0:.1%} of the {reach.sum()} reachable), "
            f"{np.mean(tw.relative(tw.best_y, np.arange(len(e))) <= 1):.1%} within the refinement tolerance "
            f"({', '.join(f'{t:.4f}' for t in tw.tol)}); median error {np.median(e):.4f}")
