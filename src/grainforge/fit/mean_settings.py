"""The sand's mean settings, estimated from the means of its descriptors (:func:`population_settings`).

One grain's descriptors cannot always say which settings made it (its seed
shapes them too); the mean settings of the sand's whole population are known
far better, since the seed's share averages out over the grains.  A
population of twins is shifted, round by round, until its mean descriptors
are the sand's; the estimate comes with standard errors, how well the means
determine each setting, and its sensitivity to the settings' spread
(docs/fit.md, "The sand's mean settings").
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .designs import IDENTIFIABLE_R2
from .made_grains import MeasurePool
from .sand import DESCRIPTORS, Sand
from .settings import MethodFit
from .twins import ForwardModel, population_error, population_step

#: with the opening fraction the estimate's rounds are more and shorter: its response to edge rounding saturates
#: (it hardly moves once the edges are rounder than the ball), so slopes measured at the twins' starting
#: population are too flat; each round's step is held to OPENING_TRUST of the unit box and the slopes are
#: updated from how the means moved (docs/fit.md, "What a scan's images add")
OPENING_ROUNDS = 4
OPENING_TRUST = 0.1
#: the slopes are updated from a round's move only where some setting's mean moved this much (unit box)
OPENING_SECANT_MIN = 0.02
#: the population estimate of the sand's mean settings remakes the first this many twins, this many rounds
POPULATION_GRAINS = 300
POPULATION_ROUNDS = 2
#: the slopes the population estimate steps through: "measured" on the grains, the design "model"'s, or "auto":
#: measured from SLOPES_MEASURED_FROM grains remade per round (where the means' noise falls below what the
#: model's slopes leave of the gap), the model's below
POPULATION_SLOPES = "auto"
SLOPE_CHOICES = ("auto", "measured", "model")
SLOPES_MEASURED_FROM = 1000
#: with measured slopes (``slopes="measured"``), this many of the population's grains are each remade with one
#: unit-box setting raised and lowered by SLOPE_STEP under their own seed
SLOPE_GRAINS = 300
SLOPE_STEP = 0.05
#: how much wider the sand's spread of a setting its grains' descriptors do not determine may be than the made
#: population's: the estimate's sensitivity to that is measured (SLOPE_GRAINS grains remade with the setting's
#: spread this much wider) and stated beside its standard error.  0.4: on the synthetic angular sand the shrunk
#: twins' spread of dent depth is 40 % off the known one (docs/fit.md, "The spread of the settings")
SPREAD_DOUBT = 0.4


def slopes_for(slopes: str, grains: int) -> str:
    """The slopes a population estimate of ``grains`` grains a round steps through: ``slopes`` itself, or for
    ``"auto"`` measured from :data:`SLOPES_MEASURED_FROM` grains, the design model's below.

    Parameters
    ----------
    slopes : {"auto", "measured", "model"}
        The choice asked for (``fit --population-slopes``).
    grains : int
        Grains remade per round of the estimate.

    Returns
    -------
    {"measured", "model"}
        The slopes stepped through.

    Raises
    ------
    ValueError
        If ``slopes`` is not one of :data:`SLOPE_CHOICES`.

    Examples
    --------
    >>> slopes_for("auto", 300), slopes_for("auto", 2000), slopes_for("measured", 300)
    ('model', 'measured', 'measured')
    """
    if slopes not in SLOPE_CHOICES:
        raise InputError(f"slopes must be one of {', '.join(SLOPE_CHOICES)}, got {slopes!r}")
    if slopes == "auto":
        return "measured" if grains >= SLOPES_MEASURED_FROM else "model"
    return slopes


#: a setting whose axis the descriptors' means see less than this much is "not determined by the means": a
#: combination of it with other settings that leaves all four means as they are moves it (more settings than
#: descriptors: rf's three surface settings), so its estimate is the starting population's, not the sand's
DETERMINED_MIN = 0.98


@dataclass(frozen=True)
class Population:
    """The sand's mean settings, estimated from the means of its four descriptors (:func:`population_settings`).

    Per setting (its own units): ``mean``, its standard error ``se`` (the sand's finite table and the made
    grains' scatter, to first order) and ``determined`` (1: the four means pin it down; towards 0: another
    setting trades with it at equal means, and its mean is the twins' starting one).
    """

    mean: dict[str, float]
    se: dict[str, float]
    determined: dict[str, float]
    grains: int  # grains made per round
    #: per setting: how far the estimate moves when the made population's spread of a setting a grain's
    #: descriptors do not determine is SPREAD_DOUBT wider (all such settings' moves added in quadrature)
    spread: dict[str, float] = field(default_factory=dict)

    def text(self) -> str:
        """One line: each setting's mean ± standard error (and ± its sensitivity to the settings' spread), the
        undetermined ones named.

        Returns
        -------
        str
            ``"NAME MEAN ± SE[ (± SPREAD spread)], ...[; not determined by the means: NAME, ...]"``, in the
            settings' own units.

        Examples
        --------
        >>> Population({"a": 0.5, "b": 2.0}, {"a": 0.01, "b": 0.3}, {"a": 1.0, "b": 0.2}, grains=300).text()
        'a 0.5 ± 0.01; not determined by the means: b'
        """
        sure = [f"{k} {self.mean[k]:.4g} ± {self.se[k]:.2g}"
                + (f" (± {self.spread[k]:.2g} spread)" if self.spread.get(k, 0.0) > 0 else "") for k in self.mean
                if self.determined[k] >= DETERMINED_MIN]
        loose = [k for k in self.mean if self.determined[k] < DETERMINED_MIN]
        return ", ".join(sure) + (f"; not determined by the means: {', '.join(loose)}" if loose else "")


def _mean_jacobian(model, u: np.ndarray, across: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """(4, p): d(mean predicted descriptors) / d(a shift of every grain's unit-box settings), from the model."""
    cols = []
    for k in range(u.shape[1]):
        e = np.zeros(u.shape[1])
        e[k] = h
        cols.append((model.predict(u + e, across) - model.predict(u - e, across)).mean(axis=0) / (2 * h))
    return np.column_stack(cols)


def _measured_mean_jacobian(spec: MethodFit, pool: MeasurePool, u: np.ndarray, seeds: Sequence[int], across: np.ndarray,
                            progress=None, step: float | np.ndarray = SLOPE_STEP, opening: bool = False) -> np.ndarray:
    """(4, p), with ``opening`` (5, p): d(mean measured descriptors) / d(a shift of every grain's unit-box settings),
    measured on the first :data:`SLOPE_GRAINS` grains: each remade with one setting raised and lowered by ``step`` (one
    for all settings, or one each; kept in the box) under its own seed, so that the difference is the setting's and not
    the seed's."""
    n = min(len(u), SLOPE_GRAINS)
    steps = np.broadcast_to(np.asarray(step, np.float64), (u.shape[1],))
    cols = []
    for k in range(u.shape[1]):
        up, down = u[:n].copy(), u[:n].copy()
        up[:, k] = np.clip(up[:, k] + steps[k], 0.0, 1.0)
        down[:, k] = np.clip(down[:, k] - steps[k], 0.0, 1.0)
        jobs = [(spec.grain_params(v[i]), seeds[i], float(across[i])) for v in (up, down) for i in range(n)]
        y = pool.run(spec.method, spec.fixed, jobs, progress=progress, opening=opening)
        ok = np.all(np.isfinite(y[:n]), axis=1) & np.all(np.isfinite(y[n:]), axis=1)
        dy, du = (y[:n] - y[n:])[ok], (up[:, k] - down[:, k])[ok]
        cols.append(dy.sum(axis=0) / max(float(du.sum()), 1e-12))
    return np.column_stack(cols)


def population_settings(spec: MethodFit, sand: Sand, *, model: ForwardModel, pool: MeasurePool, u0: np.ndarray,
                        y0: np.ndarray, seeds: Sequence[int], across: np.ndarray,
                        shrink: Sequence[float] | None = None, grains: int = POPULATION_GRAINS,
                        slopes: str = POPULATION_SLOPES, start: np.ndarray | None = None, opening: bool = False,
                        progress: Callable[[Iterable, int], Iterable] | None = None,
                        log: Callable[[str], None] | None = None,
                        desc: Callable[[str], None] | None = None) -> Population:
    """Estimate the sand's **mean** settings: shift a population until its mean descriptors are the sand's.

    A twin's settings are not its sand grain's: where the seed shapes a descriptor as much as a setting does, one
    grain's descriptors cannot say which setting made it (:func:`grainforge.fit.designs.setting_identifiability`), and
    the twins' mean is pulled towards the middle of the design box.  The *population*'s mean setting is known far
    better: the seed's share averages out over the sand's grains.  Starting from the first ``grains`` twins' first
    settings ``u0`` (measured as ``y0``; :data:`POPULATION_GRAINS` in a fit at its defaults; each setting's spread about
    the mean shrunk by ``shrink``), every grain's settings are shifted by one common step (the slopes of the mean
    descriptors, solved for the gap between the sand's mean descriptors and the made grains'), remade with its own seed
    and measured, :data:`POPULATION_ROUNDS` times (a Newton iteration on measured means).  The estimate is the mean
    settings of the round whose means came closest to the sand's, plus a last linear step for the gap left; its standard
    error propagates the sand's and the made grains' scatter of their means through the same step
    (:func:`grainforge.fit.twins.population_error`).

    ``slopes="measured"`` measures the slopes on the grains (:func:`_measured_mean_jacobian`, 2 × settings ×
    up to :data:`SLOPE_GRAINS` grains more); ``"model"`` takes the design model's, which cost nothing but are
    off where the model is (the angular method's surface settings: its rounds then leave a gap in the means
    that counts once their noise is smaller, from about a thousand grains); ``"auto"`` (the default) chooses
    by the grains remade (:func:`slopes_for`).

    ``start`` (unit-box settings, one row per grain remade) replaces the shrunk twins as the population the
    common shift moves: the settings' *spread* about their mean is then the caller's.

    ``opening`` (the sand has the :data:`grainforge.fit.sand.OPENING_COLUMN`; :func:`grainforge.fit.sand.uses_opening`):
    the opening fraction is a fifth descriptor.  The starting grains are measured again with it (``grains`` more), the
    slopes are measured (the design model has none for it), the means' misfit is weighed by the sand's covariance
    (generalised least squares, :func:`grainforge.fit.twins.population_step`), and, since its response to edge rounding
    saturates, :data:`OPENING_ROUNDS` rounds are made, each step held to :data:`OPENING_TRUST` of the unit box and the
    slopes updated after each from how the means moved (Broyden's secant update).

    Which mean settings match the sand's means depends on that spread (the descriptors respond to the settings with
    curvature), and the table does not give the spread of a setting that a grain's descriptors do not determine
    (``shrink`` below :data:`grainforge.fit.designs.IDENTIFIABLE_R2`).  For each such setting whose mean the means
    determine (its estimate is reported; for methods of at most four settings, so that the cost is known up front), the
    first :data:`SLOPE_GRAINS` grains of the estimate's round are remade with its spread :data:`SPREAD_DOUBT` wider,
    under their own seeds, and the estimate's move is ``Population.spread`` (in quadrature over those settings): a
    systematic error stated beside the standard error, which does not shrink with the table.

    Parameters
    ----------
    spec : MethodFit
        The method fitted.
    sand : Sand
        The sand whose mean descriptors (and, with ``opening``, mean opening fraction) are matched.
    model : grainforge.fit.twins.ForwardModel
        The design's model (its slopes are stepped through where they are not measured).
    pool : MeasurePool
        Where the grains are remade and measured.
    u0, y0 : (n, p), (n, 4) numpy.ndarray
        The twins' unit-box settings and their measured descriptors.
    seeds : sequence of int
        Each twin's seed (every grain is remade under its own).
    across : (n,) numpy.ndarray
        Voxels across each twin is measured at.
    shrink : sequence of float, optional
        Per setting, the share of the twins' spread about the mean the population keeps (the design's R² of
        the setting from a grain's descriptors, :func:`grainforge.fit.designs.setting_identifiability`);
        None keeps it all.
    grains : int
        Twins remade each round (the first ones, at most ``n``).
    slopes : {"auto", "measured", "model"}
        The slopes stepped through (:func:`slopes_for`).
    start : (grains, p) numpy.ndarray, optional
        The population the common shift moves, instead of the shrunk twins.
    opening : bool
        Match the sand's opening fraction too (:func:`grainforge.fit.sand.uses_opening`).
    progress : callable, optional
        ``progress(iterable, total)`` wraps each round's grains (a bar).
    log, desc : callable, optional
        ``log(line)`` gets one line per round; ``desc(text)`` names the round measured next.

    Returns
    -------
    Population
    """
    say, label = log or (lambda s: None), desc or (lambda s: None)
    m = min(len(u0), int(grains))
    u, y, across = np.asarray(u0[:m], np.float64), np.asarray(y0[:m], np.float64), np.asarray(across[:m])

    def remake(v: np.ndarray) -> np.ndarray:  # the m grains at settings v, each under its own seed
        return pool.run(spec.method, spec.fixed, [(spec.grain_params(v[i]), seeds[i], float(across[i]))
                                                  for i in range(m)], progress=progress, opening=opening)

    table, weight, short = _matched_table(sand, opening)
    if opening:
        label("population start")
        y = remake(u)
        say(f"population: the table's opening fraction is a fifth descriptor; {m} grains measured again with it")
    target, cov_sand, scale = table.mean(axis=0), np.cov(table.T) / len(table), table.std(axis=0)
    rounds = []  # (settings, measured, gap, largest gap in the sand's sds)

    def record(u: np.ndarray, y: np.ndarray) -> np.ndarray:
        ok = np.all(np.isfinite(y), axis=1)
        gap = target - y[ok].mean(axis=0)
        rounds.append((u, y, gap, float(np.max(np.abs(gap) / scale))))
        return gap

    gap = record(u, y)
    start = _start_settings(u, m, shrink, start)
    if opening or slopes_for(slopes, m) == "measured":  # the design model does not predict the opening fraction
        label("population slopes")
        jac = _measured_mean_jacobian(spec, pool, start, seeds, across, progress, opening=opening)
        say(f"population slopes: measured on {min(m, SLOPE_GRAINS)} grains, each setting raised and lowered by "
            f"{SLOPE_STEP:g} of its range under the grain's own seed")
    else:
        jac = _mean_jacobian(model, start, across)
    # with the opening fraction, whose response to rounding is curved (it saturates once the edges are rounder
    # than the ball), the slopes measured at the start are updated after each round from how the means moved
    # (Broyden's secant update), each step is held to OPENING_TRUST of the unit box, and there are
    # OPENING_ROUNDS rounds
    shift = np.zeros(u.shape[1])
    prev = None
    total = OPENING_ROUNDS if opening else POPULATION_ROUNDS
    for r in range(1, total + 1):
        step = population_step(jac, gap, weight)[0]
        if opening:
            step = step * min(1.0, OPENING_TRUST / max(float(np.max(np.abs(step))), 1e-12))
        shift = shift + step
        new_u = np.clip(start + shift, 0.0, 1.0)
        label(f"population {r}/{total}")
        new_y = remake(new_u)
        gap = record(new_u, new_y)
        if opening and prev is not None:
            jac = _secant_update(jac, prev, new_u, new_y)
        prev = (new_u, new_y)
        refused = int(np.sum(~np.all(np.isfinite(rounds[-1][1]), axis=1)))
        say(f"population {r}: {m} grains remade" + (f" ({refused} refused by the generator, left out)"
                                                     if refused else "")
            + "; mean descriptors off the sand's by " + ", ".join(f"{k[:5]} {g:+.4f}" for k, g in zip(short, gap))
            + "; mean settings " + ", ".join(f"{k} {v:.4g}" for k, v in spec.values(new_u.mean(axis=0)).items()))
    # the round whose means came closest (a step may overshoot where the model's slopes are not the grains')
    u, y, gap, _ = min(rounds, key=lambda r: r[3])
    ok = np.all(np.isfinite(y), axis=1)
    step, pinv = population_step(jac, gap, weight)
    est = np.clip(u[ok].mean(axis=0) + step, 0.0, 1.0)
    se, determined = population_error(pinv, cov_sand + np.cov(y[ok].T) / max(int(ok.sum()), 1))
    width = np.array([st.high - st.low for st in spec.all_settings])
    names = [st.name for st in spec.all_settings]
    # settings whose mean is reported (the means determine it) but whose spread the table does not give
    loose = [] if shrink is None or not spec.spread_step else [
        k for k, r2 in enumerate(shrink) if r2 < IDENTIFIABLE_R2 and determined[k] >= DETERMINED_MIN]
    spread = _spread_sensitivity(spec, pool, u, y, seeds, across, pinv, loose, progress, label, opening)
    if loose:
        say(f"population spread: the estimate's move with the spread of {', '.join(names[k] for k in loose)} "
            f"{SPREAD_DOUBT:.0%} wider (on {min(int(ok.sum()), SLOPE_GRAINS)} grains remade each): "
            + ", ".join(f"{k} {v:.2g}" for k, v in zip(names, spread * width)))
    return Population(mean=spec.values(est), se={k: float(e) for k, e in zip(names, se * width)},
                      determined={k: float(d) for k, d in zip(names, determined)}, grains=m,
                      spread={k: float(v) for k, v in zip(names, spread * width)})


def _matched_table(sand: Sand, opening: bool) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """The sand's table whose means are matched (with ``opening``, its opening fraction a fifth column), the
    misfit's weight and the columns' short names.  The weight is None (each column as it is) without the
    opening fraction; with it, generalised least squares: the misfit in the sand's own scatter, correlations
    included (the inverse Cholesky factor of its covariance; its sds where that is singular)."""
    table, weight, short = sand.table(), None, list(DESCRIPTORS)
    if opening:
        table, short = np.column_stack([table, sand.opening]), short + ["opening"]
        try:
            weight = np.linalg.inv(np.linalg.cholesky(np.cov(table.T)))
        except np.linalg.LinAlgError:
            weight = np.diag(1.0 / np.maximum(table.std(axis=0), 1e-12))
    return table, weight, short


def _start_settings(u: np.ndarray, m: int, shrink: Sequence[float] | None,
                    start: np.ndarray | None) -> np.ndarray:
    """The population the estimate's common shift moves: the caller's ``start`` (its first ``m`` rows), or the
    twins' settings ``u`` with each setting's spread about its mean shrunk by ``shrink`` (each twin's settings
    carry its own seed's share: keep only what the descriptors know)."""
    if start is not None:
        return np.asarray(start, np.float64)[:m]
    if shrink is None:
        return u
    return u.mean(axis=0) + (u - u.mean(axis=0)) * np.clip(np.asarray(shrink, np.float64), 0.0, 1.0)


def _secant_update(jac: np.ndarray, prev: tuple[np.ndarray, np.ndarray], new_u: np.ndarray,
                   new_y: np.ndarray) -> np.ndarray:
    """The slopes ``jac`` updated from how the means moved between the round ``prev`` (settings, measured) and
    this one (Broyden's secant update); as they were where no setting's mean moved
    :data:`OPENING_SECANT_MIN` (a short move's difference is mostly the voxels' quantisation, not the slope)."""
    both = np.all(np.isfinite(prev[1]), axis=1) & np.all(np.isfinite(new_y), axis=1)
    du = (new_u[both] - prev[0][both]).mean(axis=0)
    dy = (new_y[both] - prev[1][both]).mean(axis=0)
    if float(np.max(np.abs(du))) >= OPENING_SECANT_MIN:
        return jac + np.outer(dy - jac @ du, du) / float(du @ du)
    return jac


def _spread_sensitivity(spec: MethodFit, pool: MeasurePool, u: np.ndarray, y: np.ndarray, seeds: Sequence[int],
                        across: np.ndarray, pinv: np.ndarray, loose: Sequence[int], progress=None,
                        label=None, opening: bool = False) -> np.ndarray:
    """(p,) unit-box: how far a population estimate (``pinv``, at settings ``u`` measured as ``y``) moves when the
    spread of each of the settings ``loose`` about its mean is :data:`SPREAD_DOUBT` wider; the moves of the
    settings added in quadrature.  Measured on the first :data:`SLOPE_GRAINS` grains made, each remade under its
    own seed, so that the difference is the spread's and not the seeds'."""
    total = np.zeros(u.shape[1])
    idx = np.flatnonzero(np.all(np.isfinite(y), axis=1))[:SLOPE_GRAINS]
    for k in loose:
        (label or (lambda s: None))(f"population spread {spec.all_settings[k].name}")
        wide = u[idx].copy()
        centre = wide[:, k].mean()
        wide[:, k] = np.clip(centre + (wide[:, k] - centre) * (1.0 + SPREAD_DOUBT), 0.0, 1.0)
        yw = pool.run(spec.method, spec.fixed, [(spec.grain_params(wide[j]), seeds[i], float(across[i]))
                                                for j, i in enumerate(idx)], progress=progress, opening=opening)
        both = np.all(np.isfinite(yw), axis=1)
        if not both.any():
            continue
        # the settings' mean moves too where the wider spread is clipped at the box; the means' match moves back
        move = (wide[both] - u[idx][both]).mean(axis=0) - pinv @ (yw[both] - y[idx][both]).mean(axis=0)
        total += move**2
    return np.sqrt(total)
