"""What ``fit`` writes (:data:`OUTPUTS`): the recipe, each twin beside its sand grain, the statistics and a figure.

``fit.csv`` (:func:`twin_rows`), ``fit-stats.csv`` (:func:`stat_rows`: the
criteria, the settings and the sand's mean settings) and ``fit.png``
(:func:`fit_figure`), each written atomically by :func:`write_outputs`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .acceptance import CORR_TOL, KS_MAX, MEAN_TOL, TWIN_SHARE, TWIN_TOL, spearman
from .designs import IDENTIFIABLE_R2
from .mean_settings import DETERMINED_MIN, SPREAD_DOUBT
from .run import FitResult
from .sand import DESCRIPTORS, Sand

TWIN_COLUMNS = ("grain", "seed", "sand_row", "sand_d_eq_um", "d_eq_um",
                *[f"{w}_{k}" for k in DESCRIPTORS for w in ("sand", "twin")], "max_difference", "within",
                "reachable")


def twin_rows(result: FitResult) -> list[dict[str, Any]]:
    """The rows of ``fit.csv``: each generated grain beside the sand row it is the twin of (row numbers from 1,
    as in the sand's file).

    Parameters
    ----------
    result : FitResult
        A fit's result.

    Returns
    -------
    list of dict
        One per twin, in grain order: the columns :data:`TWIN_COLUMNS` (sizes in µm), then ``setting_NAME`` for
        each of the method's settings.
    """
    err = result.twin_error
    rows = []
    for i, j in enumerate(result.sand_rows):
        row: dict[str, Any] = {"grain": i, "seed": result.seeds[i] if result.seeds else "",
                               "sand_row": int(j) + 1, "sand_d_eq_um": result.generated[i, 0],
                               "d_eq_um": result.generated[i, 0]}
        for c, k in enumerate(DESCRIPTORS):
            row[f"sand_{k}"] = float(result.targets[i, c])
            row[f"twin_{k}"] = float(result.generated[i, c + 1])
        row.update(max_difference=float(err[i]), within=bool(err[i] <= TWIN_TOL),
                   reachable=bool(result.reachable[i]))
        row.update({f"setting_{k}": v for k, v in result.settings[i].items()})
        rows.append(row)
    return rows


STAT_COLUMNS = ("statistic", "quantity", "sand", "generated", "difference", "criterion", "pass")


def stat_rows(result: FitResult) -> list[dict[str, Any]]:
    """The rows of ``fit-stats.csv``: means, sds, KS; Spearman correlations; the twins' share, sand vs generated.

    Parameters
    ----------
    result : FitResult
        A fit's result.

    Returns
    -------
    list of dict
        The columns :data:`STAT_COLUMNS`: per descriptor its mean, sd and KS rows, the six Spearman rows, the
        twins' share within tolerance and unreachable, each setting's identifiability, and the sand's mean
        settings (and their spread sensitivity) where estimated; ``pass`` is a bool for a criterion, ``""``
        for a value only reported.
    """
    rows = []
    for k in DESCRIPTORS:
        p = result.stats["per"][k]
        rows.append({"statistic": "mean", "quantity": k, "sand": p["sand_mean"], "generated": p["gen_mean"],
                     "difference": p["mean_diff"], "criterion": f"|difference| <= {MEAN_TOL}",
                     "pass": abs(p["mean_diff"]) <= MEAN_TOL})
        rows.append({"statistic": "sd", "quantity": k, "sand": p["sand_sd"], "generated": p["gen_sd"],
                     "difference": p["gen_sd"] - p["sand_sd"], "criterion": "", "pass": ""})
        rows.append({"statistic": "ks", "quantity": k, "sand": "", "generated": "", "difference": p["ks"],
                     "criterion": f"KS statistic <= {KS_MAX}", "pass": p["ks"] <= KS_MAX})
    for pair, (a, b) in result.stats["corr"].items():
        rows.append({"statistic": "spearman", "quantity": pair, "sand": a, "generated": b, "difference": b - a,
                     "criterion": f"|difference| <= {CORR_TOL}", "pass": abs(b - a) <= CORR_TOL})
    st = result.stats
    rows.append({"statistic": "twins", "quantity": f"share within {TWIN_TOL} (reachable grains)", "sand": "",
                 "generated": st["twin_within"], "difference": "", "criterion": f">= {TWIN_SHARE}",
                 "pass": st["twin_within"] >= TWIN_SHARE})
    why = ", ".join(f"{n} by {k}" for k, n in st["unreachable_by"].items()) or "none"
    rows.append({"statistic": "twins", "quantity": f"share unreachable ({why})", "sand": "",
                 "generated": 1 - st["reachable"], "difference": "", "criterion": "reported", "pass": ""})
    for k, (r2, err) in result.identifiable.items():  # how much each fitted setting says about the sand
        mean = float(np.mean([v[k] for v in result.settings])) if result.settings else float("nan")
        rows.append({"statistic": "setting", "quantity": f"{k} (mean of the twins; rms error of one grain's)",
                     "sand": "", "generated": mean, "difference": err,
                     "criterion": f"identifiable if R² {r2:.2f} >= {IDENTIFIABLE_R2}", "pass": r2 >= IDENTIFIABLE_R2})
    pop = result.population
    for k in pop.mean if pop is not None else ():  # the sand's mean settings, from its descriptors' means
        rows.append({"statistic": "population", "quantity": f"{k} (the sand's mean; standard error)", "sand": "",
                     "generated": pop.mean[k], "difference": pop.se[k],
                     "criterion": f"determined by the means if {pop.determined[k]:.2f} >= {DETERMINED_MIN}",
                     "pass": pop.determined[k] >= DETERMINED_MIN})
    for k, v in (pop.spread.items() if pop is not None else ()):  # what the table does not give: the spread
        if v > 0:
            rows.append({"statistic": "population spread", "quantity": f"{k} (the estimate's move with the spread "
                         f"of the settings the grains do not determine {SPREAD_DOUBT:.0%} wider)", "sand": "",
                         "generated": "", "difference": v, "criterion": "reported", "pass": ""})
    return rows


def fit_figure(sand: Sand, result: FitResult, path: Path) -> None:
    """``fit.png``: histograms of the four descriptors and the size, twin errors, and the Spearman correlation
    matrices of sand and generated grains.

    Parameters
    ----------
    sand : Sand
        The sand fitted (its sizes, µm, for the size panel).
    result : FitResult
        The fit's result.
    path : pathlib.Path
        The PNG written (atomically).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    gen, st = result.generated[:, 1:], result.targets
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.6))
    for ax, j in zip(axes.flat, range(4)):
        k = DESCRIPTORS[j]
        lo, hi = min(st[:, j].min(), np.nanmin(gen[:, j])), max(st[:, j].max(), np.nanmax(gen[:, j]))
        bins = np.linspace(lo, max(hi, lo + 1e-6), 36)
        ax.hist(st[:, j], bins=bins, density=True, alpha=0.55, color="0.35", label=f"sand (n={len(st)})")
        ax.hist(gen[:, j], bins=bins, density=True, alpha=0.55, color="tab:orange",
                label=f"{result.method} twins (n={len(gen)})")
        p = result.stats["per"][k]
        ax.set_title(f"{k}: mean {p['sand_mean']:.3f} vs {p['gen_mean']:.3f}, KS {p['ks']:.3f}", fontsize=9)
        # a fixed corner: matplotlib's "best" searches every bar, takes seconds on a loaded machine and warns
        ax.legend(fontsize=7, loc="upper left", framealpha=0.8)
    ax = axes.flat[4]
    err = result.twin_error
    ax.hist(np.minimum(err, 0.1), bins=40, color="tab:blue")
    ax.axvline(TWIN_TOL, color="k", ls="--", lw=1)
    ax.set_xlabel("largest |twin − sand grain| (4 descriptors; ≤ 0.1 shown)")
    ax.set_title(f"twins: {result.stats['twin_within']:.1%} of reachable within {TWIN_TOL}; "
                 f"{1 - result.stats['reachable']:.1%} unreachable", fontsize=9)
    ax = axes.flat[5]
    d = result.generated[:, 0]
    bins = np.linspace(sand.equivalent_diameter.min(), sand.equivalent_diameter.max(), 36)
    ax.hist(sand.equivalent_diameter, bins=bins, density=True, alpha=0.55, color="0.35", label="sand (all rows)")
    ax.hist(d, bins=bins, density=True, alpha=0.55, color="tab:orange", label=result.method)
    ax.set_xlabel("equivalent diameter (µm)")
    ax.set_title("size (each twin has its sand grain's)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right", framealpha=0.8)
    labels = [k[:5] for k in DESCRIPTORS]
    for ax, table, who in ((axes.flat[6], st, "sand rows"), (axes.flat[7], gen, f"{result.method} twins")):
        c = spearman(table)
        ax.imshow(c, vmin=-1, vmax=1, cmap="RdBu_r")
        for i in range(4):
            for j in range(4):
                ax.text(j, i, f"{c[i, j]:+.2f}", ha="center", va="center", fontsize=9)
        ax.set_xticks(range(4), labels, fontsize=8)
        ax.set_yticks(range(4), labels, fontsize=8)
        ax.set_title(f"Spearman correlations: {who}", fontsize=9)
    verdict = "passes" if result.stats["pass"] else "does NOT pass"
    fig.suptitle(f"{sand.name} vs {len(gen)} {result.method} twins measured the Atlas way "
                 f"({sand.voxel_size:g} µm voxels): {verdict} (KS <= {KS_MAX}, |Δmean| <= {MEAN_TOL}, "
                 f"|Δρ| <= {CORR_TOL}, twins within {TWIN_TOL} for >= {TWIN_SHARE:.0%})", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


#: what ``fit`` writes into its output folder
OUTPUTS = ("recipe.toml", "fit.csv", "fit-stats.csv", "fit.png")


def write_outputs(sand: Sand, result: FitResult, out: str | os.PathLike) -> list[Path]:
    """Write :data:`OUTPUTS` into ``out`` (each atomically); return the paths.

    Parameters
    ----------
    sand : Sand
        The sand fitted.
    result : FitResult
        The fit's result.
    out : str or os.PathLike
        The output folder (made if missing); files of the same names in it are replaced.

    Returns
    -------
    list of pathlib.Path
        ``recipe.toml``, ``fit.csv``, ``fit-stats.csv`` and ``fit.png`` in ``out``, in that order.
    """
    from ..io import atomic_write, write_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / n for n in OUTPUTS]
    atomic_write(paths[0], result.recipe)
    rows = twin_rows(result)
    write_csv(paths[1], rows, list(rows[0]))
    write_csv(paths[2], stat_rows(result), STAT_COLUMNS)
    fit_figure(sand, result, paths[3])
    return paths
