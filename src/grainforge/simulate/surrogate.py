"""A surrogate-model search for the contact friction μ and the rolling resistance μ_r that reach several measured
angles at once (``grainforge simulate calibrate material``).

:func:`search_material` is a pure function of a callable ``angles_of(k, μ, μ_r)`` that returns every seed's angle
of every target's test at one point: the engine runs live in :mod:`grainforge.simulate.material`, the search is
tested with stand-in functions.

Notes
-----
The search (docs/simulate.md, *Calibrating μ and μ_r together*):

1. **Initial design**: ``initial_points`` points of a scrambled Latin hypercube over the bounds
   (:class:`scipy.stats.qmc.LatinHypercube`, seeded from ``rng``: the same arguments give the same points).
2. **Surrogates**: after each point, one Gaussian process per target over (μ, μ_r) in the unit square
   (scikit-learn's :class:`~sklearn.gaussian_process.GaussianProcessRegressor`; a constant × anisotropic RBF
   kernel plus a :class:`~sklearn.gaussian_process.kernels.WhiteKernel` for the seed-to-seed noise), fitted to
   every seed's angle (:func:`fit_surrogates`).
3. **Misfit**: the standardized misfit ``M = Σ ((angle_pred − target) / σ_target)²`` on a grid of
   :data:`GRID` × :data:`GRID` points over the bounds; σ_target is the measurement's spread
   (:data:`DEFAULT_SD` when not given).
4. **Next point**: the grid point of least optimistic misfit, each target's residual shrunk by
   :data:`KAPPA` posterior standard deviations (a lower confidence bound: it explores where the surrogate is
   unsure), among those farther than :data:`MIN_SPACING` from the points run.
5. **Stop**: when ``budget`` points are run, or when the best point's predicted misfit is within the noise
   (``M ≤`` :func:`noise_misfit`, the 95 % quantile of χ² with one degree per target) and every surrogate's
   posterior standard deviation there is below half its σ_target.

The result is the grid point of least predicted misfit; its uncertainty is the extent of the region within
the noise: the grid points whose misfit, each σ_target widened by the surrogate's posterior standard deviation
there, is at most :func:`noise_misfit` (or within :data:`REGION_DELTA`, Δχ² of a 68 % region of two
parameters, of the best's when that is larger): μ's and μ_r's lowest and highest there.  A best point whose misfit is above :func:`noise_misfit` is not a fit: the targets are not reached
together within the bounds (``reached`` False).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Target", "Point", "MaterialSearch", "design_points", "fit_surrogates", "predict", "noise_misfit",
           "search_material", "check_search", "DEFAULT_SD", "GRID", "KAPPA", "MIN_SPACING", "REGION_DELTA"]

#: σ_target of a target given without its spread, degrees
DEFAULT_SD = 1.0
#: points per side of the grid the misfit is evaluated on
GRID = 81
#: posterior standard deviations each residual is shrunk by when choosing the next point (exploration)
KAPPA = 2.0
#: closest a new point may lie to a point run, as a fraction of each range
MIN_SPACING = 0.03
#: Δχ² of the uncertainty region: 68 % of a two-parameter fit
REGION_DELTA = 2.30


@dataclass(frozen=True)
class Target:
    """A measured angle to reach: ``name`` (the test: ``"tilt"``, ``"repose"``, ``"triaxial"``), ``angle`` and
    its spread ``sd`` (σ_target), degrees."""

    name: str
    angle: float
    sd: float = DEFAULT_SD


@dataclass(frozen=True)
class Point:
    """One point run: its index, μ, μ_r and every target's seed angles (degrees), by target name."""

    index: int
    friction: float
    rolling_friction: float
    angles: Mapping[str, tuple]

    def mean(self, name: str) -> float:
        """The seed-averaged angle of a target.

        Parameters
        ----------
        name : str
            The target's name.

        Returns
        -------
        float
            The mean of its seeds' angles, degrees.
        """
        return float(np.mean(self.angles[name]))


@dataclass(frozen=True)
class MaterialSearch:
    """The result of :func:`search_material`.

    Attributes
    ----------
    friction, rolling_friction : float
        The best point: the grid point of least predicted misfit.
    friction_bounds, rolling_friction_bounds : (float, float)
        The extent of the uncertainty region (see the module's notes).
    misfit : float
        The predicted misfit at the best point.
    threshold : float
        :func:`noise_misfit` of the targets: a best misfit above it is no fit.
    reached : bool
        Whether the best misfit is within the threshold.
    converged : bool
        Whether the search stopped on its rule before the budget ran out.
    predicted : dict
        Each target's predicted angle and its posterior standard deviation at the best point, by name.
    noise_sd : dict
        Each target's seed-to-seed standard deviation, as its surrogate's white noise fitted it (degrees).
    points : tuple of Point
        Every point run, in order.
    grid : dict
        The surrogates on the grid, for the figure: ``friction`` and ``rolling_friction`` (1-D axes), ``misfit``
        and ``region`` (2-D, μ_r along the first axis), ``means`` by target name.
    """

    friction: float
    rolling_friction: float
    friction_bounds: tuple
    rolling_friction_bounds: tuple
    misfit: float
    threshold: float
    reached: bool
    converged: bool
    predicted: dict
    noise_sd: dict
    points: tuple
    grid: dict


def noise_misfit(n_targets: int) -> float:
    """The misfit within the noise: the 95 % quantile of χ² with ``n_targets`` degrees of freedom.

    Parameters
    ----------
    n_targets : int
        The number of targets.

    Returns
    -------
    float
        The threshold of the standardized misfit.

    Examples
    --------
    >>> round(noise_misfit(2), 2)
    5.99
    """
    from scipy.stats import chi2

    return float(chi2.ppf(0.95, n_targets))


def design_points(n: int, low: Sequence[float], high: Sequence[float], rng=None) -> np.ndarray:
    """``n`` points of a scrambled Latin hypercube over the box ``[low, high]``, the same for the same seed.

    Parameters
    ----------
    n : int
        The number of points.
    low, high : sequence of float
        The box's corners.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The hypercube's randomness (:func:`grainforge.rng.as_generator`).

    Returns
    -------
    numpy.ndarray
        ``(n, len(low))`` points.

    Examples
    --------
    >>> p = design_points(4, [0.1, 0.0], [1.5, 0.5], 0)
    >>> p.shape, bool(((p >= [0.1, 0.0]) & (p <= [1.5, 0.5])).all())
    ((4, 2), True)
    >>> bool((design_points(4, [0.1, 0.0], [1.5, 0.5], 0) == p).all())
    True
    """
    from scipy.stats import qmc

    from ..rng import as_generator

    sampler = qmc.LatinHypercube(d=len(low), rng=as_generator(rng))
    return qmc.scale(sampler.random(n), low, high)


def fit_surrogates(x: np.ndarray, angles: Mapping[str, np.ndarray], restarts: int = 0) -> dict:
    """One Gaussian process per target over the unit square, fitted to every seed's angle.

    Parameters
    ----------
    x : numpy.ndarray
        ``(n, 2)`` points in the unit square, one per seed angle.
    angles : mapping of str to numpy.ndarray
        Each target's ``n`` angles (degrees), by name.
    restarts : int
        The random state of the optimizer's restarts (the same data and ``restarts`` give the same
        surrogates).

    Returns
    -------
    dict
        The fitted ``GaussianProcessRegressor`` by name; each is given ``offset_``, the mean angle subtracted.
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
    from threadpoolctl import threadpool_limits

    out = {}
    for name, y in angles.items():
        y = np.asarray(y, dtype=np.float64)
        # the noise floor 0.1° (one seed a point gives the noise nothing to be fitted to: it would interpolate)
        kernel = (ConstantKernel(25.0, (1e-2, 1e4)) * RBF([0.5, 0.5], (0.1, 20.0))
                  + WhiteKernel(1.0, (1e-2, 1e2)))
        gp = GaussianProcessRegressor(kernel, n_restarts_optimizer=3, random_state=int(restarts))
        # matrices of a few tens of rows: BLAS threads cost more than they bring (7× on a busy 2-core machine)
        with warnings.catch_warnings(), threadpool_limits(1):
            warnings.simplefilter("ignore", ConvergenceWarning)  # a length or a noise at its bound is an answer
            gp.fit(x, y - y.mean())
        gp.offset_ = float(y.mean())
        out[name] = gp
    return out


def predict(gp, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A surrogate's mean angle and the posterior standard deviation of that mean (the seed noise taken out).

    Parameters
    ----------
    gp : GaussianProcessRegressor
        From :func:`fit_surrogates`.
    x : numpy.ndarray
        ``(m, 2)`` points in the unit square.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The mean angles and their standard deviations, degrees.
    """
    mean, sd = gp.predict(x, return_std=True)
    noise = float(gp.kernel_.k2.noise_level)
    return mean + gp.offset_, np.sqrt(np.maximum(sd ** 2 - noise, 0.0))


def _grid(n: int = GRID) -> np.ndarray:
    """The unit square's grid points, μ varying fastest: ``(n * n, 2)``."""
    u = np.linspace(0.0, 1.0, n)
    a, b = np.meshgrid(u, u)
    return np.column_stack([a.ravel(), b.ravel()])


def _surface(gps: dict, targets: Sequence[Target], grid: np.ndarray) -> dict:
    """Each target's mean and sd on ``grid``, the misfit, the optimistic misfit and the widened misfit."""
    means, sds = {}, {}
    misfit = np.zeros(len(grid))
    optimistic = np.zeros(len(grid))
    widened = np.zeros(len(grid))
    for t in targets:
        m, s = predict(gps[t.name], grid)
        means[t.name], sds[t.name] = m, s
        r = np.abs(m - t.angle)
        misfit += (r / t.sd) ** 2
        optimistic += (np.maximum(r - KAPPA * s, 0.0) / t.sd) ** 2
        widened += r ** 2 / (t.sd ** 2 + s ** 2)
    return {"means": means, "sds": sds, "misfit": misfit, "optimistic": optimistic, "widened": widened}


def _next_point(surface: dict, grid: np.ndarray, done: np.ndarray) -> np.ndarray:
    """The grid point of least optimistic misfit (ties: least misfit) away from the points run."""
    far = np.min(np.abs(grid[:, None, :] - done[None, :, :]).max(axis=2), axis=1) > MIN_SPACING
    score = np.where(far, surface["optimistic"] + 1e-6 * surface["misfit"], np.inf)
    return grid[int(np.argmin(score))]


def _settled(surface: dict, targets: Sequence[Target], grid: np.ndarray, done: np.ndarray, points, threshold) -> bool:
    """The stop: the best point's predicted misfit within the noise, every surrogate sure there (posterior sd at
    most half σ_target), and a point run beside it whose seed-averaged angles fit too."""
    best = int(np.argmin(surface["misfit"]))
    if surface["misfit"][best] > threshold or any(surface["sds"][t.name][best] > 0.5 * t.sd for t in targets):
        return False
    near = np.abs(done - grid[best]).max(axis=1) <= 2 * MIN_SPACING
    return any(sum(((p.mean(t.name) - t.angle) / t.sd) ** 2 for t in targets) <= threshold
               for p, close in zip(points, near) if close)


def _fit_all(points: Sequence[Point], targets: Sequence[Target], low, span, restarts: int) -> dict:
    """The surrogates of every target, fitted to every seed's angle of the points run."""
    x, angles = [], {t.name: [] for t in targets}
    for p in points:
        n = len(p.angles[targets[0].name])
        x += [[(p.friction - low[0]) / span[0], (p.rolling_friction - low[1]) / span[1]]] * n
        for t in targets:
            angles[t.name] += list(p.angles[t.name])
    return fit_surrogates(np.array(x), {k: np.array(v) for k, v in angles.items()}, restarts)


def check_search(targets: Sequence[Target], *, friction_range: tuple[float, float],
                 rolling_range: tuple[float, float], budget: int, initial: int) -> None:
    """Refuse targets, bounds or a budget the search cannot use (one line naming the setting).

    Parameters
    ----------
    targets : sequence of Target
        The targets: each name once, each spread a positive number.
    friction_range, rolling_range : (float, float)
        The bounds of μ (0 ≤ low < high ≤ 5) and of μ_r (0 ≤ low < high ≤ 1).
    budget, initial : int
        The most points and the initial design's (2 ≤ initial ≤ budget).

    Raises
    ------
    grainforge.errors.InputError
        The first refusal.
    """
    names = [t.name for t in targets]
    if not targets or len(set(names)) != len(names):
        raise InputError("{targets}: give each test's angle once", setting="targets")
    if any(not (math.isfinite(t.sd) and t.sd > 0) for t in targets):
        raise InputError("{targets}: a target's spread must be a positive number of degrees", setting="targets")
    for name, (lo, hi), top in (("friction_range", friction_range, 5.0), ("rolling_friction_range", rolling_range, 1.0)):
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi <= top):
            raise InputError(f"{{{name}}}: need 0 ≤ low < high ≤ {top:g}, got {lo:g} {hi:g}", setting=name)
    if not 2 <= initial <= budget:
        raise InputError(f"{{initial_points}}: need 2 ≤ initial points ≤ {{budget}} ({budget}), got {initial}",
                         setting=("initial_points", "budget"))


def search_material(angles_of: Callable[[int, float, float], Mapping[str, Sequence[float]]],
                    targets: Sequence[Target], *, friction_range: tuple[float, float] = (0.1, 1.5),
                    rolling_friction_range: tuple[float, float] = (0.0, 0.5), budget: int = 16, initial_points: int = 6,
                    rng=0, progress: Callable[[Point], None] | None = None) -> MaterialSearch:
    """The (μ, μ_r) in the bounds at which every target's angle is reached (see the module's notes).

    Parameters
    ----------
    angles_of : callable
        ``angles_of(k, μ, μ_r)`` → every seed's angle (degrees) by target name, at point ``k``. A NaN stops the
        search with ``ValueError``.
    targets : sequence of Target
        The angles to reach, each test once.
    friction_range, rolling_friction_range : (float, float)
        The bounds of μ (0 ≤ low < high ≤ 5) and of μ_r (0 ≤ low < high ≤ 1).
    budget : int
        The most points run.
    initial_points : int
        The points of the initial design (2 ≤ initial_points ≤ budget).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The design's and the surrogates' randomness (:func:`grainforge.rng.as_generator`; an int: the same
        points for the same arguments).
    progress : callable, optional
        Called with each :class:`Point` as it is run.

    Returns
    -------
    MaterialSearch

    Raises
    ------
    grainforge.errors.InputError
        Targets, bounds or a budget the search cannot use; an angle that could not be measured.

    Examples
    --------
    A stand-in whose tilt rises with μ and whose triaxial angle rises with μ_r more:

    >>> f = lambda k, mu, mr: {"tilt": [20 + 20 * mu + 10 * mr], "triaxial": [20 + 10 * mu + 40 * mr]}
    >>> s = search_material(f, [Target("tilt", 36.0), Target("triaxial", 32.0)], budget=12)
    >>> s.reached, round(s.friction, 1), round(s.rolling_friction, 1)
    (True, 0.7, 0.1)
    """
    from ..rng import as_generator

    check_search(targets, friction_range=friction_range, rolling_range=rolling_friction_range, budget=int(budget),
                 initial=int(initial_points))
    rng = as_generator(rng)
    restarts = int(rng.integers(2 ** 31))
    low = np.array([friction_range[0], rolling_friction_range[0]], dtype=np.float64)
    span = np.array([friction_range[1], rolling_friction_range[1]], dtype=np.float64) - low
    points: list[Point] = []

    def run(u: np.ndarray) -> None:
        mu, mr = (float(v) for v in low + u * span)
        got = angles_of(len(points), mu, mr)
        angles = {t.name: tuple(float(a) for a in got[t.name]) for t in targets}
        if not all(math.isfinite(a) for v in angles.values() for a in v):
            raise InputError(f"no angle could be measured at friction {mu:.4g}, rolling friction {mr:.4g}")
        points.append(Point(len(points), mu, mr, angles))
        if progress is not None:
            progress(points[-1])

    for u in (design_points(int(initial_points), low, low + span, rng) - low) / span:
        run(u)
    grid, threshold = _grid(), noise_misfit(len(targets))
    while True:
        gps = _fit_all(points, targets, low, span, restarts)
        surface = _surface(gps, targets, grid)
        done = np.array([[(p.friction - low[0]) / span[0], (p.rolling_friction - low[1]) / span[1]] for p in points])
        converged = _settled(surface, targets, grid, done, points, threshold)
        if converged or len(points) >= budget:
            break
        run(_next_point(surface, grid, done))
    return _result(gps, surface, targets, grid, low, span, points, threshold, converged)


def _result(gps, surface, targets, grid, low, span, points, threshold, converged) -> MaterialSearch:
    """The best point, its region and the grid of the finished search."""
    best = int(np.argmin(surface["misfit"]))
    x = low + grid * span
    region = surface["widened"] <= max(threshold, surface["widened"][best] + REGION_DELTA)
    region[best] = True
    bounds = [(float(x[region, i].min()), float(x[region, i].max())) for i in range(2)]
    predicted = {t.name: (float(surface["means"][t.name][best]), float(surface["sds"][t.name][best]))
                 for t in targets}
    noise = {t.name: math.sqrt(float(gps[t.name].kernel_.k2.noise_level)) for t in targets}
    n = int(round(math.sqrt(len(grid))))
    axes = [np.linspace(low[i], low[i] + span[i], n) for i in range(2)]
    shape = (n, n)
    figure = {"friction": axes[0], "rolling_friction": axes[1], "misfit": surface["misfit"].reshape(shape),
              "region": region.reshape(shape), "means": {k: v.reshape(shape) for k, v in surface["means"].items()}}
    misfit = float(surface["misfit"][best])
    return MaterialSearch(float(x[best, 0]), float(x[best, 1]), bounds[0], bounds[1], misfit, threshold,
                          misfit <= threshold, converged, predicted, noise, tuple(points), figure)
