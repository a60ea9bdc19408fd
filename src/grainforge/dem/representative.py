"""Representative templates: K grains whose shape and size distribution matches the whole population's.

An engine is given a few templates (``grainforge simulate --templates K``,
``grainforge dem --templates K``) and draws its grains from them. Taking the
first K grains, or every step-th, of a population sorted by anything (a twin
fit's rows, a size-sorted folder) gives K grains that do not look like the
population. :func:`choose_representative` picks K grains whose five
descriptors — sphericity, convexity, flatness, elongation and size (the
equivalent diameter) — are distributed as the whole set's, and reports the
two-sample Kolmogorov–Smirnov statistic (:func:`scipy.stats.ks_2samp`) of
each descriptor, chosen K against all N.

How (docs/simulate.md, *How the templates are chosen*): each descriptor is
replaced by its mid-rank in the whole set, ``u = (rank - 1/2) / N`` (so its
scale, and the logarithm of the size, do not matter); a set of K grains
matches the set's distribution in a descriptor when its sorted ranks sit at
the K quantiles ``(m + 1/2) / K``. A swap search minimises the sum, over the
five descriptors and the K order statistics, of the squared distances to
those quantiles (a Wasserstein-2 distance in rank space, which bounds the KS
statistic): every chosen grain in turn is swapped for the grain outside the
set that lowers it most, until a sweep swaps nothing. It starts from K
strata of the first principal component of the standardised descriptors
(size in log) and from ``restarts - 1`` random sets drawn from ``rng``;
the result with the smallest largest KS statistic is kept. Values are compared
to 6 significant digits (grains scaled to one size tie in size). Everything
is deterministic for a seed. Pure numpy/scipy.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, as_generator

__all__ = ["DESCRIPTORS", "TemplateChoice", "descriptor_matrix", "significant", "standardise", "ks_statistics",
           "choose_representative"]

#: the descriptors matched, in the columns' order (size: the equivalent diameter, any length unit)
DESCRIPTORS = ("sphericity", "convexity", "flatness", "elongation", "size")
#: full sweeps of the swap search at most (it stops earlier when a sweep swaps nothing)
MAX_SWEEPS = 200


@dataclass(frozen=True)
class TemplateChoice:
    """The grains chosen as templates and how well they match the whole set.

    Attributes
    ----------
    indices : (K,) int64
        Rows chosen, ascending.
    ks : dict
        Descriptor name -> two-sample KS statistic of the chosen rows against
        all rows (:func:`scipy.stats.ks_2samp`); 0 when all rows are taken.
    candidates : int
        Rows the choice was made from (N).
    selected : bool
        False when K ≥ N: every row is taken, nothing is chosen.
    """

    indices: np.ndarray
    ks: dict
    candidates: int
    selected: bool

    @property
    def largest_ks(self) -> float:
        """The largest of the per-descriptor KS statistics."""
        return max(self.ks.values()) if self.ks else 0.0

    def summary(self) -> str:
        """One line: the KS statistic of every descriptor, or that all grains were taken.

        Returns
        -------
        str
            ``K of N grains; KS against all: sphericity 0.040, ... (largest 0.050)``, or the line saying
            every grain was taken.

        Examples
        --------
        >>> TemplateChoice(np.arange(3), dict.fromkeys(DESCRIPTORS, 0.0), 3, False).summary()
        'all 3 grains taken (3 asked or more): no selection'
        """
        if not self.selected:
            return f"all {self.candidates} grains taken ({len(self.indices)} asked or more): no selection"
        figures = ", ".join(f"{name} {value:.3f}" for name, value in self.ks.items())
        return (f"{len(self.indices)} of {self.candidates} grains; KS against all: {figures} "
                f"(largest {self.largest_ks:.3f})")


def descriptor_matrix(rows: Sequence[Mapping[str, float]]) -> np.ndarray:
    """(N, 5) float64 table of :data:`DESCRIPTORS` from one mapping per grain.

    Parameters
    ----------
    rows : sequence of mapping
        One mapping per grain holding at least the five :data:`DESCRIPTORS` (other keys ignored);
        ``size`` (the equivalent diameter) in any length unit, the same for every row.

    Returns
    -------
    (N, 5) float64
        The descriptors, columns in the order of :data:`DESCRIPTORS`.

    Raises
    ------
    ValueError
        If a row lacks a descriptor or holds a non-finite one, or a size is not positive (the row is named).

    Examples
    --------
    >>> descriptor_matrix([dict(sphericity=0.9, convexity=0.95, flatness=0.7, elongation=0.6, size=0.5)])
    array([[0.9 , 0.95, 0.7 , 0.6 , 0.5 ]])
    """
    table = np.empty((len(rows), len(DESCRIPTORS)), dtype=np.float64)
    for i, row in enumerate(rows):
        missing = [name for name in DESCRIPTORS if name not in row]
        if missing:
            raise InputError(f"grain {i}: no {', '.join(missing)}")
        table[i] = [float(row[name]) for name in DESCRIPTORS]
    _check(table)
    return table


def _check(table: np.ndarray) -> None:
    if table.ndim != 2 or table.shape[1] != len(DESCRIPTORS):
        raise InputError(f"descriptors must be an (N, {len(DESCRIPTORS)}) table ({', '.join(DESCRIPTORS)}), "
                         f"got shape {table.shape}")
    if len(table) == 0:
        raise InputError("no grains to choose from")
    bad = np.flatnonzero(~np.isfinite(table).all(axis=1) | (table[:, -1] <= 0))
    if len(bad):
        raise InputError(f"grain {bad[0]}: descriptors must be finite and the size positive, "
                         f"got {table[bad[0]].tolist()}")


def significant(table: np.ndarray, digits: int = 6) -> np.ndarray:
    """The values rounded to ``digits`` significant digits: measures equal to that precision tie.

    Parameters
    ----------
    table : array_like of float
        Any shape; zeros stay zero.
    digits : int
        Significant digits kept (≥ 1).

    Returns
    -------
    float64 ndarray
        The rounded values, the shape of ``table``.

    Examples
    --------
    >>> significant(np.array([[0.99999999, 1.0000001, 123456.78, 0.0]])).tolist()
    [[1.0, 1.0, 123457.0, 0.0]]
    """
    x = np.asarray(table, dtype=np.float64)
    with np.errstate(divide="ignore"):
        exponent = np.floor(np.log10(np.abs(x)))
    scale = 10.0 ** np.where(np.isfinite(exponent), digits - 1 - exponent, 0.0)
    return np.round(x * scale) / scale


def standardise(table: np.ndarray) -> np.ndarray:
    """The descriptors as z-scores, the size by its logarithm (a constant column gives zeros).

    Parameters
    ----------
    table : (N, 5) array_like of float
        Rows of :data:`DESCRIPTORS`, the size (last column) > 0.

    Returns
    -------
    (N, 5) float64
        Each column less its mean, over its standard deviation (population, ``ddof=0``); the last column
        is ``log(size)``'s.

    Examples
    --------
    >>> z = standardise(np.array([[0.8, 0.9, 0.6, 0.7, 1.0], [0.9, 0.95, 0.8, 0.9, 100.0]]))
    >>> z.round(6).tolist()
    [[-1.0, -1.0, -1.0, -1.0, -1.0], [1.0, 1.0, 1.0, 1.0, 1.0]]
    """
    x = np.asarray(table, dtype=np.float64).copy()
    x[:, -1] = np.log(x[:, -1])
    sd = x.std(axis=0)
    return (x - x.mean(axis=0)) / np.where(sd > 0, sd, 1.0)


def ks_statistics(table: np.ndarray, indices: Sequence[int]) -> dict[str, float]:
    """Descriptor -> two-sample KS statistic (:func:`scipy.stats.ks_2samp`) of rows ``indices`` against all rows.

    Parameters
    ----------
    table : (N, 5) array_like of float
        Rows of :data:`DESCRIPTORS`.
    indices : sequence of int
        The rows compared with the whole table.

    Returns
    -------
    dict of str to float
        One statistic in [0, 1] per descriptor, in the order of :data:`DESCRIPTORS`.

    Examples
    --------
    >>> t = np.column_stack([np.linspace(0.5, 1.0, 10)] * 4 + [np.linspace(1.0, 2.0, 10)])
    >>> ks_statistics(t, range(5))["size"]  # the lower half: half the set's mass is above it
    0.5
    """
    from scipy.stats import ks_2samp

    table = np.asarray(table, dtype=np.float64)
    idx = np.asarray(indices, dtype=np.int64)
    return {name: float(ks_2samp(table[idx, j], table[:, j]).statistic) for j, name in enumerate(DESCRIPTORS)}


def _ranks(table: np.ndarray) -> np.ndarray:
    """Each column's mid-rank in (0, 1): (rank - 1/2) / N, ties at their mean rank."""
    from scipy.stats import rankdata

    return (rankdata(table, method="average", axis=0) - 0.5) / len(table)


def _cost(u: np.ndarray, chosen: np.ndarray, target: np.ndarray) -> float:
    return float(((np.sort(u[chosen], axis=0) - target[:, None]) ** 2).sum())


def _swap_search(u: np.ndarray, chosen: np.ndarray, target: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Swap chosen rows for others while the rank cost falls (best swap per chosen row, sweeps until none)."""
    n, d = u.shape
    chosen = chosen.copy()
    inside = np.zeros(n, dtype=bool)
    inside[chosen] = True
    cost = _cost(u, chosen, target)
    for _ in range(MAX_SWEEPS):
        swapped = False
        for slot in order:
            rest = np.delete(chosen, slot)
            outside = np.flatnonzero(~inside)
            new = np.zeros(len(outside))
            for j in range(d):
                r = np.sort(u[rest, j])
                # with the new value x inserted at position p of the K-1 sorted others: the others below it
                # keep their quantiles t_0..t_{p-1}, those above move up by one
                below = np.concatenate(([0.0], np.cumsum((r - target[:-1]) ** 2)))
                above = np.concatenate((np.cumsum(((r - target[1:]) ** 2)[::-1])[::-1], [0.0]))
                x = u[outside, j]
                p = np.searchsorted(r, x)
                new += below[p] + (x - target[p]) ** 2 + above[p]
            best = int(np.argmin(new))
            if new[best] < cost - 1e-12 * max(1.0, cost):
                inside[chosen[slot]] = False
                chosen[slot] = outside[best]
                inside[chosen[slot]] = True
                cost = float(new[best])
                swapped = True
        if not swapped:
            break
    return chosen


def choose_representative(descriptors, k: int, *, rng: RNGLike = 0, restarts: int = 4) -> TemplateChoice:
    """K rows whose descriptor distribution matches the whole table's.

    Parameters
    ----------
    descriptors : (N, 5) array_like
        One row per grain: :data:`DESCRIPTORS` (sphericity, convexity,
        flatness, elongation, equivalent diameter > 0 in any unit).
    k : int
        Templates wanted (≥ 1). With ``k >= N`` every row is taken.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The random starting sets and the search's order, normalised by :func:`grainforge.rng.as_generator`
        (default 0); the same int gives the same choice.
    restarts : int
        Starting sets of the search (≥ 1): the principal-component strata,
        then ``restarts - 1`` random sets.

    Returns
    -------
    TemplateChoice
        The rows (ascending) and each descriptor's KS statistic against all rows.

    Raises
    ------
    ValueError
        For ``k < 1``, ``restarts < 1``, an empty table, a table not of five
        columns, a row with a non-finite descriptor or a size ≤ 0, or an ``rng`` that is not an accepted value.

    Examples
    --------
    A sand-like table of 300 grains whose rows are sorted by size; its first
    40 rows are the 40 smallest grains, the chosen 40 are not:

    >>> rng = np.random.default_rng(1)
    >>> shape = rng.normal([0.85, 0.93, 0.7, 0.7], [0.04, 0.02, 0.1, 0.1], size=(300, 4))
    >>> table = np.column_stack([shape, rng.lognormal(np.log(0.5), 0.1, 300)])
    >>> table = table[np.argsort(table[:, 4])]
    >>> round(ks_statistics(table, range(40))["size"], 2)
    0.87
    >>> choice = choose_representative(table, 40, rng=0)
    >>> len(choice.indices), choice.largest_ks <= 0.1
    (40, True)
    >>> bool(np.array_equal(choice.indices, choose_representative(table, 40, rng=0).indices))
    True
    """
    table = np.asarray(descriptors, dtype=np.float64)
    _check(table)
    table = significant(table)  # sizes equal to a few ulps (grains scaled to one size) tie
    if int(k) != k or k < 1:
        raise InputError(f"k must be a whole number ≥ 1, got {k!r}")
    if restarts < 1:
        raise InputError(f"restarts must be ≥ 1, got {restarts!r}")
    rng = as_generator(rng)  # refused alike whether or not a choice is made
    n, k = len(table), int(k)
    if k >= n:
        return TemplateChoice(np.arange(n, dtype=np.int64), dict.fromkeys(DESCRIPTORS, 0.0), n, False)
    u = _ranks(table)
    target = (np.arange(k) + 0.5) / k
    # the first start: K strata of the first principal component, the middle row of each
    z = standardise(table)
    _, _, vt = np.linalg.svd(z - z.mean(axis=0), full_matrices=False)
    pc1 = z @ vt[0]
    by_pc1 = np.argsort(pc1, kind="stable")
    starts = [by_pc1[((np.arange(k) + 0.5) * n / k).astype(np.int64)]]
    starts += [rng.choice(n, size=k, replace=False) for _ in range(restarts - 1)]
    best = None
    for start in starts:
        chosen = np.sort(_swap_search(u, np.asarray(start, dtype=np.int64), target, rng.permutation(k)))
        ks = ks_statistics(table, chosen)
        key = (max(ks.values()), _cost(u, chosen, target))
        if best is None or key < best[0]:
            best = (key, chosen, ks)
    return TemplateChoice(best[1], best[2], n, True)
