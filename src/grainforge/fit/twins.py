"""Inverse models for twin fits: measured descriptors → generator settings (docs/fit.md).

A *design* is a set of generated grains whose settings ``u`` (each scaled to
[0, 1]) and resolution (voxels across) are spread over the method's whole
range, measured once.  :class:`ForwardModel` is a least-squares cubic
polynomial from (settings, log resolution) to the four measured descriptors;
:func:`invert` solves it, bounded, for the settings whose grain the model
predicts to measure like a target, optionally with a per-grain offset (what
one grain's own seed and orientation add to the model, learnt from
measuring it: the refinement step).

Pure functions of NumPy arrays; nothing here generates or measures a grain
(:mod:`grainforge.fit` does).

Examples
--------
>>> rng = np.random.default_rng(0)
>>> u = rng.random((200, 2))
>>> across = np.full(200, 60.0)
>>> y = np.column_stack([0.9 - 0.3 * u[:, 0] ** 2, 0.5 + 0.4 * u[:, 1], u[:, 0] * u[:, 1], 1 - u[:, 1] / 2])
>>> model = ForwardModel.fit(u, across, y)
>>> sol, miss = invert(model, y[:3], np.full(3, 60.0))
>>> bool(np.allclose(sol, u[:3], atol=1e-2)), bool(np.all(miss < 1e-3))
(True, True)
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..rng import RNGLike, as_generator

__all__ = ["design_points", "ForwardModel", "invert", "identifiability", "population_step", "population_error"]

#: polynomial degree of the forward model
DEGREE = 3
#: ridge penalty on the polynomial coefficients (relative to the design's size): keeps the corners tame
RIDGE = 1e-6


def design_points(n: int, dims: int, rng: RNGLike) -> np.ndarray:
    """``n`` scrambled Sobol points in [0, 1]^dims (a design that fills the box evenly).

    Parameters
    ----------
    n : int
        Points wanted (the first ``n`` of a Sobol sequence of the next power of two).
    dims : int
        Dimensions of the box.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The scrambling's randomness, normalised by :func:`grainforge.rng.as_generator` (an int gives the
        points it has always given; a Generator is advanced).

    Returns
    -------
    (n, dims) numpy.ndarray of float64
        In [0, 1).

    Examples
    --------
    >>> p = design_points(64, 3, rng=1)
    >>> p.shape, bool(p.min() >= 0 and p.max() < 1)
    ((64, 3), True)
    >>> bool(np.array_equal(p, design_points(64, 3, rng=1)))
    True
    """
    from scipy.stats import qmc

    m = int(np.ceil(np.log2(max(n, 2))))
    return qmc.Sobol(dims, scramble=True, seed=as_generator(rng)).random_base2(m)[:n]


def _features(u: np.ndarray, across: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """Monomials up to ``degree`` of the settings and log(voxels across) (scaled to about [0, 1])."""
    z = np.column_stack([np.asarray(u, np.float64), np.log(np.asarray(across, np.float64)) / np.log(1000.0)])
    cols = [np.ones(len(z))]
    for d in range(1, degree + 1):
        for idx in itertools.combinations_with_replacement(range(z.shape[1]), d):
            cols.append(np.prod(z[:, idx], axis=1))
    return np.column_stack(cols)


@dataclass(frozen=True)
class ForwardModel:
    """Settings u ∈ [0, 1]^p and voxels across → the four descriptors (a cubic least-squares fit).

    ``rms`` is the root-mean-square residual per descriptor on the design:
    what one grain's own seed and orientation scatter about the model.

    Attributes
    ----------
    coef : (features, 4) numpy.ndarray
        The polynomial's coefficients, one column per descriptor.
    rms : (4,) numpy.ndarray
        Root-mean-square residual per descriptor on the design.
    dims : int
        Settings of the model (p).
    """

    coef: np.ndarray  # (features, 4)
    rms: np.ndarray  # (4,)
    dims: int

    @classmethod
    def fit(cls, u: np.ndarray, across: np.ndarray, y: np.ndarray) -> ForwardModel:
        """The model fitted to a design by ridge-damped least squares.

        Parameters
        ----------
        u : (n, p) numpy.ndarray
            The design's settings in [0, 1].
        across : (n,) numpy.ndarray
            Voxels across each was measured at.
        y : (n, 4) numpy.ndarray
            Their measured descriptors (no NaN).

        Returns
        -------
        ForwardModel
        """
        X = _features(u, across)
        y = np.asarray(y, np.float64)
        A = np.vstack([X, np.sqrt(RIDGE * len(X)) * np.eye(X.shape[1])])
        b = np.vstack([y, np.zeros((X.shape[1], y.shape[1]))])
        coef = np.linalg.lstsq(A, b, rcond=None)[0]
        rms = np.sqrt(np.mean((X @ coef - y) ** 2, axis=0))
        return cls(coef=coef, rms=rms, dims=u.shape[1])

    def predict(self, u: np.ndarray, across: np.ndarray) -> np.ndarray:
        """The descriptors the model predicts for settings ``u`` measured ``across`` voxels across.

        Parameters
        ----------
        u : (p,) or (n, p) array_like
            Settings in the unit box (a polynomial: defined, and smooth, just outside it too).
        across : float or (n,) array_like
            Voxels across, one for all or one per row.

        Returns
        -------
        (n, 4) numpy.ndarray
            One row per row of ``u`` (one row for a single setting vector).
        """
        u = np.atleast_2d(u)
        return _features(u, np.broadcast_to(across, (len(u),))) @ self.coef


def identifiability(u: np.ndarray, across: np.ndarray, y: np.ndarray, *, folds: int = 5,
                    rng: RNGLike = 0) -> tuple[np.ndarray, np.ndarray]:
    """How well each setting is known from a grain's four measured descriptors, learnt from a design.

    Each setting (unit-box coordinate) is predicted from the descriptors and
    the resolution by a least-squares polynomial like :class:`ForwardModel`'s,
    the other way round, and scored on the design grains it was not fitted
    to (``folds``-fold cross-validation; of degrees 1 to :data:`DEGREE`, the
    one that predicts best, so that a small design is not over-fitted).  A setting the descriptors
    determine is predicted closely (R² near 1, a small error); one shaped
    over by the grain's seed, or traded against another setting (two
    settings that make the same descriptors), is not (R² near 0).  This
    bounds what a twin fit can say about a sand grain's settings: no
    inverse of the four descriptors knows a setting better than its best
    prediction from them.

    Parameters
    ----------
    u : (n, p) array
        The design's settings in [0, 1].
    across : (n,) array
        Voxels across each design grain was measured at.
    y : (n, 4) array
        Their measured descriptors.
    folds : int
        Folds of the cross-validation (each grain is scored by the model fitted to the other folds).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The random split into folds, normalised by :func:`grainforge.rng.as_generator`; the default 0 makes the
        scores a function of the design alone (an int gives the split it has always given).

    Returns
    -------
    r2 : (p,) array
        Cross-validated coefficient of determination per setting (1 − mean
        squared error / variance of the setting over the design; 0 when the
        descriptors predict it no better than its mean).
    rmse : (p,) array
        Cross-validated root-mean-square error per setting, in unit-box units
        (× the setting's range for its own units).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.random((400, 2))                   # setting 0 shapes the grain, setting 1 does nothing
    >>> y = np.column_stack([u[:, 0], u[:, 0] ** 2, 1 - u[:, 0], rng.random(400)])
    >>> r2, rmse = identifiability(u, np.full(400, 60.0), y)
    >>> bool(r2[0] > 0.99 and rmse[0] < 0.01), bool(abs(r2[1]) < 0.1 and rmse[1] > 0.25)
    (True, True)
    """
    u, y = np.asarray(u, np.float64), np.asarray(y, np.float64)
    fold = as_generator(rng).permutation(len(u)) % folds
    mse = np.var(u, axis=0)  # predicting the mean
    for degree in range(1, DEGREE + 1):
        X = _features(y, across, degree)
        pred = np.empty_like(u)
        for k in range(folds):
            train, test = fold != k, fold == k
            A = np.vstack([X[train], np.sqrt(RIDGE * train.sum()) * np.eye(X.shape[1])])
            b = np.vstack([u[train], np.zeros((X.shape[1], u.shape[1]))])
            pred[test] = X[test] @ np.linalg.lstsq(A, b, rcond=None)[0]
        mse = np.minimum(mse, np.mean((np.clip(pred, 0.0, 1.0) - u) ** 2, axis=0))
    return 1.0 - mse / np.var(u, axis=0), np.sqrt(mse)


def invert(model: ForwardModel, targets: np.ndarray, across: np.ndarray, *, offsets: np.ndarray | None = None,
           start: np.ndarray | None = None, scale: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Settings u ∈ [0, 1]^p whose predicted descriptors (plus ``offsets``) come closest to each target.

    Parameters
    ----------
    model : ForwardModel
        The design's model.
    targets : (n, 4) array
        The descriptors to reach, one row per grain.
    across : (n,) array
        Voxels across each grain is measured at.
    offsets : (n, 4) array, optional
        Added to the model's prediction per grain (measured − predicted at
        the grain's last settings): the refinement step.
    start : (n, p) array, optional
        Where each solve starts (default: the best of a coarse grid).
    scale : float or (4,) array
        Each descriptor's misfit is divided by it (the twin tolerance).

    Returns
    -------
    u : (n, p) array
        The settings found, in the unit box.
    miss : (n,) array
        Largest |predicted − target| over the descriptors at ``u``: what the
        model says the method cannot reach (the solve stops at a bound).
    """
    targets = np.atleast_2d(np.asarray(targets, np.float64))
    n = len(targets)
    across = np.broadcast_to(np.asarray(across, np.float64), (n,)).copy()
    offsets = np.zeros_like(targets) if offsets is None else np.asarray(offsets, np.float64)
    scale = np.broadcast_to(np.asarray(scale, np.float64), (targets.shape[1],))
    if start is None:
        grid = design_points(512, model.dims, rng=0)
        start = np.empty((n, model.dims))
        for i in range(n):
            pred = model.predict(grid, across[i]) + offsets[i]
            start[i] = grid[np.argmin(np.max(np.abs(pred - targets[i]) / scale, axis=1))]
    u = _gauss_newton(lambda x: (model.predict(x, across) + offsets - targets) / scale, np.clip(start, 0.0, 1.0))
    miss = np.max(np.abs(model.predict(u, across) + offsets - targets), axis=1)
    return u, miss


def _gauss_newton(resid, u: np.ndarray, iterations: int = 60, h: float = 1e-6) -> np.ndarray:
    """Minimise ``|resid(u)|²`` row by row over u ∈ [0, 1]^p: damped Gauss–Newton on all rows at once.

    A setting at a bound that the gradient pushes outward is held there
    (its column dropped) while the others move; the damping of a row grows
    after a step that does not lower its misfit and shrinks after one that does.
    """
    n, p = u.shape
    lam = np.full(n, 1e-3)
    r = resid(u)
    cost = np.sum(r**2, axis=1)
    eye = np.eye(p)
    for _ in range(iterations):
        J = np.stack([(resid(u + h * eye[k]) - r) / h for k in range(p)], axis=2)  # (n, m, p); the model is
        # a polynomial, defined (and smooth) just outside the box too
        g = np.einsum("nmp,nm->np", J, r)
        held = ((u <= 0) & (g > 0)) | ((u >= 1) & (g < 0))
        J = np.where(held[:, None, :], 0.0, J)
        A = np.einsum("nmp,nmq->npq", J, J)
        A += (lam[:, None, None] * (np.einsum("npp->np", A)[:, :, None] * eye + 1e-9 * eye))
        du = -np.linalg.solve(A, np.einsum("nmp,nm->np", J, r)[:, :, None])[:, :, 0]
        trial = np.clip(u + du, 0.0, 1.0)
        rt = resid(trial)
        ct = np.sum(rt**2, axis=1)
        better = ct < cost
        u = np.where(better[:, None], trial, u)
        r = np.where(better[:, None], rt, r)
        done = np.abs(cost - ct) <= 1e-14 * (1 + cost)
        cost = np.where(better, ct, cost)
        lam = np.where(better, lam / 3, lam * 4)
        if np.all(done | (lam > 1e8)):
            break
    return u


def population_step(jac: np.ndarray, gap: np.ndarray, weight: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The shift of a population's mean settings that moves its mean descriptors by ``gap``, to first order.

    Solves ``jac @ step = gap`` in the least-squares sense; with more
    settings than descriptors (or settings the descriptors' means cannot
    tell apart) the shortest such step, so that what the means do not
    determine stays where it is.  With more descriptors than settings the
    misfit is weighed by ``weight`` (``W @ (jac @ step - gap)`` is what is
    least: with W the inverse of a Cholesky factor of the descriptors'
    covariance, the generalised least squares whose standard errors are
    the least the means allow); a square system is solved exactly either way.

    Parameters
    ----------
    jac : (d, p) array
        d(mean descriptors) / d(mean settings), unit-box settings (d = 4, or
        5 with the opening fraction).
    gap : (d,) array
        Target mean descriptors minus the population's.
    weight : (d, d) array, optional
        Invertible; default: the identity.

    Returns
    -------
    step : (p,) array
    pinv : (p, d) array
        The (pseudo-)inverse used: what :func:`population_error` propagates.

    Examples
    --------
    >>> jac = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0], [0.0, 0.0]])
    >>> step, _ = population_step(jac, np.array([0.1, 0.1, 0.0, 0.0]))
    >>> np.round(step, 6).tolist()
    [0.1, 0.05]

    A fifth descriptor that sees only the first setting, known ten times better, outweighs a first that
    disagrees with it:

    >>> jac5 = np.vstack([jac, [[1.0, 0.0]]])
    >>> step, _ = population_step(jac5, np.array([0.1, 0.1, 0.0, 0.0, 0.2]), np.diag([1, 1, 1, 1, 10.0]))
    >>> np.round(step, 3).tolist()
    [0.199, 0.05]
    """
    jac = np.asarray(jac, np.float64)
    if weight is None:
        pinv = np.linalg.pinv(jac, rcond=1e-6)
    else:
        w = np.asarray(weight, np.float64)
        pinv = np.linalg.pinv(w @ jac, rcond=1e-6) @ w
    return pinv @ np.asarray(gap, np.float64), pinv


def population_error(pinv: np.ndarray, cov_mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard errors of mean settings estimated from mean descriptors, and how far the means determine them.

    Parameters
    ----------
    pinv : (p, d) array
        From :func:`population_step`.
    cov_mean : (d, d) array
        Covariance of the mean-descriptor gap: the sand's covariance over
        its grain count plus the made population's over its.

    Returns
    -------
    se : (p,) array
        Standard error of each mean setting (unit-box units): the least any
        estimate from the descriptors' means can have, to first order (for
        a sand whose descriptors scatter about their means as a Gaussian,
        no estimator from the table does better).
    determined : (p,) array
        1 where the four means pin the setting down, towards 0 where
        a combination of it with other settings leaves every mean as it is
        (the part of the setting's axis outside the rows of ``pinv``'s
        pseudo-inverse): its estimate is then the starting population's.

    Examples
    --------
    >>> jac = np.array([[1.0, 1.0], [1.0, 1.0], [0.0, 0.0], [0.0, 0.0]])   # only their sum shows
    >>> se, det = population_error(np.linalg.pinv(jac), np.eye(4) * 1e-4)
    >>> np.round(det, 3).tolist()
    [0.5, 0.5]
    """
    pinv = np.asarray(pinv, np.float64)
    se = np.sqrt(np.maximum(np.einsum("pi,ij,pj->p", pinv, cov_mean, pinv), 0.0))
    jac = np.linalg.pinv(pinv)  # (4, p): the map back; pinv @ jac projects onto what the means see
    determined = np.clip(np.diag(pinv @ jac), 0.0, 1.0)
    return se, determined
