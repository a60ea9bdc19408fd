"""When a fit passes: its twins' population compared with the sand (:func:`compare`).

The fit **passes** when, on the population: each descriptor's two-sample KS
statistic ≤ :data:`KS_MAX` and mean within :data:`MEAN_TOL`; each of the six
pairwise Spearman correlations within :data:`CORR_TOL` of the sand's; and at
least :data:`TWIN_SHARE` of the grains the method can reach (the model's
closest setting predicts a twin within :data:`TWIN_TOL`) have a twin within
:data:`TWIN_TOL` on every descriptor.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .sand import DESCRIPTORS

#: acceptance: two-sample KS statistic and |mean difference| per descriptor
KS_MAX = 0.1
MEAN_TOL = 0.01
#: acceptance: |Spearman correlation difference| for each pair of descriptors
CORR_TOL = 0.1
#: acceptance: a twin is within this of its sand grain on every descriptor, for this share of reachable grains
TWIN_TOL = 0.03
TWIN_SHARE = 0.9


#: the six descriptor pairs whose rank correlations are compared
PAIRS = tuple((DESCRIPTORS[i], DESCRIPTORS[j]) for i in range(4) for j in range(i + 1, 4))


def spearman(table: np.ndarray) -> np.ndarray:
    """(k, k) Spearman rank correlations of the columns of ``table``.

    Parameters
    ----------
    table : (n, k) array_like
        One row per grain, one column per quantity (ties get their mean rank).

    Returns
    -------
    (k, k) numpy.ndarray
        The Pearson correlations of the columns' ranks; ones on the diagonal.

    Examples
    --------
    >>> x = np.arange(10.0)
    >>> spearman(np.column_stack([x, x**3, -x])).round(6).tolist()
    [[1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]
    """
    from scipy.stats import rankdata

    r = np.apply_along_axis(rankdata, 0, np.asarray(table, np.float64))
    return np.corrcoef(r.T)


def compare(sand: np.ndarray, gen: np.ndarray, *, twin_within: float | None = None) -> dict[str, Any]:
    """Statistics of two (n, 4) descriptor tables: means, sds, KS per descriptor; Spearman correlations.

    ``score`` is the largest of KS/:data:`KS_MAX`, |Δmean|/:data:`MEAN_TOL`
    and |Δρ|/:data:`CORR_TOL` (and, with ``twin_within``, the share of
    reachable twins within :data:`TWIN_TOL`, as :data:`TWIN_SHARE`/share):
    the fit passes when it is ≤ 1.

    Parameters
    ----------
    sand : (n, 4) numpy.ndarray
        The sand's descriptors (columns :data:`grainforge.fit.sand.DESCRIPTORS`).
    gen : (m, 4) numpy.ndarray
        The generated grains' descriptors, same columns.
    twin_within : float, optional
        The share (0 to 1) of reachable twins within :data:`TWIN_TOL` of their sand grain; None: not judged.

    Returns
    -------
    dict
        ``"per"``: per descriptor ``sand_mean``, ``gen_mean``, ``sand_sd``, ``gen_sd`` (ddof 1), ``ks``,
        ``mean_diff`` (generated − sand) and ``pass``; ``"corr"``: per pair ``"a-b"`` of :data:`PAIRS` the
        (sand, generated) Spearman correlations; ``"twin_within"``; ``"score"``; ``"pass"``.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> a = rng.uniform(0.6, 0.9, size=(400, 4))
    >>> st = compare(a, a.copy())
    >>> st["pass"], st["score"]
    (True, 0.0)
    """
    from scipy.stats import ks_2samp

    out: dict[str, Any] = {"per": {}, "corr": {}}
    worst = 0.0
    for j, k in enumerate(DESCRIPTORS):
        a, b = sand[:, j], gen[:, j]
        ks = float(ks_2samp(a, b, method="asymp").statistic)  # the statistic only (its exact p-value can fail)
        dm = float(b.mean() - a.mean())
        out["per"][k] = {"sand_mean": float(a.mean()), "gen_mean": float(b.mean()), "sand_sd": float(a.std(ddof=1)),
                         "gen_sd": float(b.std(ddof=1)), "ks": ks, "mean_diff": dm,
                         "pass": ks <= KS_MAX and abs(dm) <= MEAN_TOL}
        worst = max(worst, ks / KS_MAX, abs(dm) / MEAN_TOL)
    cs, cg = spearman(sand), spearman(gen)
    for a, b in PAIRS:
        i, j = DESCRIPTORS.index(a), DESCRIPTORS.index(b)
        out["corr"][f"{a}-{b}"] = (float(cs[i, j]), float(cg[i, j]))
        worst = max(worst, abs(cg[i, j] - cs[i, j]) / CORR_TOL)
    corr_ok = all(abs(g - s) <= CORR_TOL for s, g in out["corr"].values())
    out["twin_within"] = twin_within
    if twin_within is not None:
        worst = max(worst, TWIN_SHARE / max(twin_within, 1e-9))
    out["score"] = float(worst)
    out["pass"] = (all(v["pass"] for v in out["per"].values()) and corr_ok
                   and (twin_within is None or twin_within >= TWIN_SHARE))
    return out
