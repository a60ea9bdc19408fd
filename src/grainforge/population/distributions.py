"""Values a population recipe draws from: parameter distributions and size distributions.

:class:`Distribution` (a parameter drawn per grain), :class:`FixedSize`,
:class:`LognormalSize` and :class:`GradingCurve` (the size of each grain).
:mod:`grainforge.population.recipe` parses recipes into them and
:mod:`grainforge.population.report` summarises populations with them; neither of those
two modules is imported here (no import cycle).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, as_generator

__all__ = ["Distribution", "FixedSize", "LognormalSize", "GradingCurve"]


# --------------------------------------------------------------------------- distributions
@dataclass(frozen=True)
class Distribution:
    """A parameter drawn per grain.

    ``kind`` is one of ``uniform(low, high)``, ``normal(mean, sd)``,
    ``truncnormal(mean, sd, low, high)``, ``lognormal(median, sigma)`` (sigma
    of ln x), ``choice(values, weights)`` or, for a three-number ratio such
    as ``aspect``, ``zingg(elongation, flatness)``: the Zingg ratios
    e = I/L and f = S/I, each a fixed number in (0, 1] or a distribution
    whose support lies in (0, 1], give the ratio L:I:S = 1 : e : e·f.
    Every draw consumes exactly one uniform variate (inverse CDF), except
    ``choice`` (one ``Generator.choice``) and ``zingg`` (elongation's draw,
    then flatness's).  A list of numbers (``descriptors``, ``aspect``) may
    also be drawn element by element: kind ``each`` with ``items``, each a
    fixed number or a scalar distribution (written in a recipe as a list whose
    elements are numbers or distribution tables); drawn in order.

    Examples
    --------
    >>> e = Distribution("uniform", {"low": 0.6, "high": 0.9})
    >>> z = Distribution("zingg", {"elongation": e, "flatness": 0.8})
    >>> L, I, S = z.draw(np.random.default_rng(1))
    >>> L, 0.6 <= I <= 0.9, round(S / I, 12)
    (1.0, True, 0.8)
    >>> d = Distribution("truncnormal", {"mean": 2.4, "sd": 0.2, "low": 2.2, "high": 2.6})
    >>> x = d.draw(np.random.default_rng(0))
    >>> 2.2 <= x <= 2.6
    True
    """

    kind: str
    args: Mapping[str, Any]
    integer: bool = False

    def support(self) -> tuple[float, float]:
        """The interval the distribution draws from.

        Returns
        -------
        low, high : float
            Its ends (infinite for an unbounded side).

        Raises
        ------
        ValueError
            For a kind without an interval (``choice``, ``zingg``, ``each``).

        Examples
        --------
        >>> Distribution("lognormal", {"median": 1.0, "sigma": 0.5}).support()
        (0.0, inf)
        """
        a = self.args
        if self.kind in ("uniform", "truncnormal"):
            return float(a["low"]), float(a["high"])
        if self.kind == "normal":
            return -math.inf, math.inf
        if self.kind == "lognormal":
            return 0.0, math.inf
        raise InputError(f"{self.kind} has no interval support")

    def typical(self) -> Any:
        """A representative value (used to check cross-parameter rules up front).

        Returns
        -------
        object
            The middle of a uniform (rounded for an integer one), a normal's mean (clipped to a truncated one's
            bounds), a lognormal's median, a choice's first value; a tuple for ``zingg`` (L:I:S) and ``each``.

        Examples
        --------
        >>> Distribution("uniform", {"low": 2, "high": 5}, integer=True).typical()
        4
        """
        a = self.args
        if self.kind == "uniform":
            mid = 0.5 * (a["low"] + a["high"])
            return int(round(mid)) if self.integer else mid
        if self.kind in ("normal", "truncnormal"):
            m = float(a["mean"])
            return min(max(m, a["low"]), a["high"]) if self.kind == "truncnormal" else m
        if self.kind == "lognormal":
            return float(a["median"])
        if self.kind == "zingg":
            e, f = (x.typical() if isinstance(x, Distribution) else x for x in (a["elongation"], a["flatness"]))
            return (1.0, e, e * f)
        if self.kind == "each":
            return tuple(x.typical() if isinstance(x, Distribution) else x for x in a["items"])
        return self.args["values"][0]

    def draw(self, rng: RNGLike) -> Any:
        """One value from ``rng``.

        Parameters
        ----------
        rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
            Normalised by :func:`grainforge.rng.as_generator`; a Generator (a grain's own stream) is advanced by
            exactly the draws described above, so the next draw from it is the next parameter's.

        Returns
        -------
        object
            A float (an int for an integer uniform), a choice's value, or a tuple for ``zingg`` and ``each``.
        """
        from scipy.special import ndtr, ndtri

        rng = as_generator(rng)
        a = self.args
        if self.kind == "zingg":
            e, f = (x.draw(rng) if isinstance(x, Distribution) else x for x in (a["elongation"], a["flatness"]))
            return (1.0, e, e * f)
        if self.kind == "each":
            return tuple(x.draw(rng) if isinstance(x, Distribution) else x for x in a["items"])
        if self.kind == "choice":
            values = a["values"]
            return values[int(rng.choice(len(values), p=a["weights"]))]
        if self.kind == "uniform" and self.integer:
            return int(rng.integers(int(a["low"]), int(a["high"]) + 1))
        u = float(rng.random())
        if self.kind == "uniform":
            return float(a["low"] + u * (a["high"] - a["low"]))
        if self.kind == "normal":
            return float(a["mean"] + a["sd"] * ndtri(u if u > 0 else 2.0**-60))
        if self.kind == "truncnormal":
            lo = ndtr((a["low"] - a["mean"]) / a["sd"])
            hi = ndtr((a["high"] - a["mean"]) / a["sd"])
            x = float(a["mean"] + a["sd"] * ndtri(lo + u * (hi - lo)))
            return min(max(x, a["low"]), a["high"])
        return float(a["median"] * math.exp(a["sigma"] * ndtri(u if u > 0 else 2.0**-60)))


# --------------------------------------------------------------------------- sizes
@dataclass(frozen=True)
class FixedSize:
    """Every grain has the same size (mm)."""

    mm: float

    def sample(self, u: float) -> float:
        """The size at quantile ``u``: always ``mm``.

        Parameters
        ----------
        u : float
            A quantile in [0, 1] (not used).

        Returns
        -------
        float
            The size, mm.
        """
        return self.mm


@dataclass(frozen=True)
class LognormalSize:
    """ln(size) ~ N(ln median_mm, sigma²)."""

    median_mm: float
    sigma: float

    def sample(self, u: float) -> float:
        """The size (mm) at quantile ``u`` (inverse CDF).

        Parameters
        ----------
        u : float
            A quantile in [0, 1] (kept just inside it, so that the size is finite).

        Returns
        -------
        float
            The size, mm.

        Examples
        --------
        >>> LognormalSize(2.0, 0.3).sample(0.5)
        2.0
        """
        from scipy.special import ndtri

        return float(self.median_mm * math.exp(self.sigma * ndtri(min(max(u, 2.0**-60), 1 - 2.0**-53))))


@dataclass(frozen=True)
class GradingCurve:
    """A grading curve: sieve apertures (mm) and percent passing, linear in log-size.

    Between two sieves the passing fraction is taken as linear in ln(size)
    (the way grading curves are drawn).  With ``basis="mass"`` (what a sieve
    analysis reports) the curve is a mass fraction and is converted to a
    number fraction with mass ∝ size³, so that a population of grains of
    similar shape reproduces it by mass; with ``basis="count"`` it is a number
    fraction directly.

    Examples
    --------
    >>> g = GradingCurve((0.1, 1.0), (0.0, 100.0), basis="count")
    >>> [round(g.sample(q), 6) for q in (0.0, 0.5, 1.0)]
    [0.1, 0.316228, 1.0]
    """

    sieves_mm: tuple[float, ...]
    percent_passing: tuple[float, ...]
    basis: str = "mass"

    def _number_cdf(self) -> tuple[np.ndarray, np.ndarray]:
        """Log sizes and the number CDF at each sieve."""
        u = np.log(np.asarray(self.sieves_mm, dtype=np.float64))
        P = np.asarray(self.percent_passing, dtype=np.float64) / 100.0
        if self.basis == "count":
            return u, P
        dP = np.diff(P)
        du = np.diff(u)
        # number weight of bin i: ∫ (dP/du) e^{-3u} du over the bin
        w = dP / du * (np.exp(-3 * u[:-1]) - np.exp(-3 * u[1:])) / 3.0
        return u, np.concatenate([[0.0], np.cumsum(w) / w.sum()])

    def number_percent_passing(self) -> np.ndarray:
        """Percent passing *by count* at each sieve implied by the curve (equal to it for ``basis="count"``).

        Returns
        -------
        numpy.ndarray
            One value per sieve, from 0 to 100.
        """
        return 100.0 * self._number_cdf()[1]

    def sample(self, q: float) -> float:
        """The size (mm) at number quantile ``q`` in [0, 1] (inverse CDF).

        Parameters
        ----------
        q : float
            The number quantile, clipped to [0, 1].

        Returns
        -------
        float
            The size, mm.
        """
        return float(self.sample_many(np.array([q]))[0])

    def sample_many(self, q: np.ndarray) -> np.ndarray:
        """The sizes (mm) at number quantiles ``q`` (vectorised :meth:`sample`).

        Parameters
        ----------
        q : array_like
            Number quantiles, clipped to [0, 1].

        Returns
        -------
        numpy.ndarray
            Sizes in mm, the shape of ``q``.

        Examples
        --------
        >>> g = GradingCurve((0.1, 1.0, 10.0), (0.0, 50.0, 100.0), basis="count")
        >>> g.sample_many(np.array([0.25, 0.5, 0.75])).round(6).tolist()
        [0.316228, 1.0, 3.162278]
        """
        u, F = self._number_cdf()
        q = np.clip(np.asarray(q, dtype=np.float64), 0.0, 1.0)
        i = np.clip(np.searchsorted(F, q, side="right") - 1, 0, len(u) - 2)
        # skip empty bins (equal F on both sides)
        while np.any(nz := (F[i + 1] <= F[i]) & (i < len(u) - 2)):
            i = np.where(nz, i + 1, i)
        t = np.where(F[i + 1] > F[i], (q - F[i]) / np.where(F[i + 1] > F[i], F[i + 1] - F[i], 1.0), 0.0)
        t = np.clip(t, 0.0, 1.0)
        if self.basis == "count":
            return np.exp(u[i] + t * (u[i + 1] - u[i]))
        a, b = np.exp(-3 * u[i]), np.exp(-3 * u[i + 1])
        return np.exp(-np.log(a - t * (a - b)) / 3.0)

    def passing(self, sizes: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Achieved percent passing at each sieve for ``sizes`` (weighted, e.g. by volume).

        Parameters
        ----------
        sizes : (n,) array_like
            Grains' sizes, mm.
        weights : (n,) array_like, optional
            Each grain's weight (its volume for a mass grading); default 1 each (by count).

        Returns
        -------
        numpy.ndarray
            Percent (of the total weight) of grains no larger than each sieve, one value per sieve.

        Examples
        --------
        >>> GradingCurve((0.1, 1.0), (0.0, 100.0)).passing([0.05, 0.5, 0.5, 2.0]).tolist()
        [25.0, 75.0]
        """
        sizes = np.asarray(sizes, dtype=np.float64)
        w = np.ones_like(sizes) if weights is None else np.asarray(weights, dtype=np.float64)
        total = w.sum()
        return np.array([100.0 * w[sizes <= s].sum() / total for s in self.sieves_mm])
