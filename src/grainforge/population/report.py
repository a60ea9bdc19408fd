"""The population report: summary statistics (JSON) and a PNG of the population.

``manifest.json`` sits next to ``manifest.csv`` and holds the summary of the
batch: the recipe's identity, statistics of every drawn parameter, of the
size and of the measured descriptors, and for a grading curve the achieved
percent passing at each sieve next to the target.  ``population.png`` shows
the achieved vs target grading curve (or the size histogram) and a histogram
of each drawn parameter and of sphericity and convexity.

Both are computed from the manifest rows alone, so they are byte-identical
whenever the grains are.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_write, save_figure
from .distributions import Distribution, GradingCurve

__all__ = ["summary", "population_report", "population_figure", "achieved_sizes", "SUMMARY", "FIGURE"]

SUMMARY = "manifest.json"
FIGURE = "population.png"
_MEASURED = {"equivalent": "equivalent_diameter", "sieve": "I", "longest": "L"}


def _stats(x: np.ndarray) -> dict[str, float]:
    x = np.asarray(x, dtype=np.float64)
    q = np.quantile(x, [0.1, 0.5, 0.9])
    return {"mean": float(x.mean()), "sd": float(x.std(ddof=1)) if len(x) > 1 else 0.0,
            "min": float(x.min()), "p10": float(q[0]), "median": float(q[1]), "p90": float(q[2]),
            "max": float(x.max())}


def achieved_sizes(rows: Sequence[Mapping[str, Any]], definition: str) -> np.ndarray:
    """Each grain's measured size (mm) under ``definition`` (equivalent, sieve or longest).

    Parameters
    ----------
    rows : sequence of mapping
        Manifest rows (their ``equivalent_diameter``, ``I`` or ``L`` column, mm).
    definition : {"equivalent", "sieve", "longest"}
        The size definition.

    Returns
    -------
    (n,) numpy.ndarray
        Sizes in mm.

    Examples
    --------
    >>> achieved_sizes([{"equivalent_diameter": 1.5, "I": 1.2, "L": 2.0}], "sieve").tolist()
    [1.2]
    """
    return np.array([float(r[_MEASURED[definition]]) for r in rows])


def summary(recipe, rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Summary statistics of a population (the content of ``manifest.json``).

    Parameters
    ----------
    recipe : Recipe
        The population's recipe.
    rows : sequence of mapping
        Its manifest rows, in grain order.

    Returns
    -------
    dict
        The recipe's identity (name, SHA-256, method, count, root seed, format, size definition), per
        parameter its distribution and achieved statistics, the target and measured sizes (mm), the
        descriptors' statistics and, for a grading curve, the achieved percent passing at each sieve.
    """
    out: dict[str, Any] = {
        "recipe": Path(recipe.source).name,
        "recipe_sha256": recipe.digest,
        "method": recipe.method,
        "count": len(rows),
        "root_seed": recipe.seed,
        "format": recipe.format,
        "size_definition": recipe.size_definition,
        "parameters": {},
    }
    for name, v in recipe.params.items():
        vals = [r[name] for r in rows]
        if isinstance(v, Distribution) and v.kind == "choice":
            labels = [_label(x) for x in vals]
            counts = {_label(c): labels.count(_label(c)) for c in v.args["values"]}
            out["parameters"][name] = {"distribution": "choice", "counts": counts}
        elif isinstance(v, Distribution) and v.kind == "zingg":
            ratios = zingg_ratios(vals)
            out["parameters"][name] = {"distribution": "zingg", **{
                k: ({"distribution": d.kind, **dict(d.args), "achieved": _stats(ratios[k])}
                    if isinstance(d, Distribution) else {"fixed": d})
                for k, d in v.args.items()}}
        elif isinstance(v, Distribution) and v.kind == "each":
            out["parameters"][name] = {"distribution": "each", "items": [
                {"distribution": d.kind, **dict(d.args), "achieved": _stats([x[i] for x in vals])}
                if isinstance(d, Distribution) else {"fixed": d} for i, d in enumerate(v.args["items"])]}
        elif isinstance(v, Distribution):
            out["parameters"][name] = {"distribution": v.kind, **dict(v.args), "achieved": _stats(vals)}
        else:
            out["parameters"][name] = {"fixed": v}
    sizes = achieved_sizes(rows, recipe.size_definition)
    out["size_mm"] = {"target": _stats([r["size"] for r in rows]), "measured": _stats(sizes)}
    out["descriptors"] = {c: _stats([r[c] for r in rows])
                          for c in ("sphericity", "convexity", "equivalent_diameter", "volume")}
    if isinstance(recipe.size, GradingCurve):
        g = recipe.size
        weights = np.array([r["volume"] for r in rows]) if g.basis == "mass" else None
        achieved = g.passing(sizes, weights)
        out["grading"] = {
            "basis": g.basis, "sieves_mm": list(g.sieves_mm), "target_percent_passing": list(g.percent_passing),
            "achieved_percent_passing": [float(a) for a in achieved],
            "max_abs_deviation_percent": float(np.max(np.abs(achieved - np.array(g.percent_passing)))),
        }
    return out


def zingg_ratios(values) -> dict[str, np.ndarray]:
    """Elongation I/L and flatness S/I of ratios L:I:S (rows' ``aspect`` values).

    Examples
    --------
    >>> {k: v.tolist() for k, v in zingg_ratios([(1.0, 0.5, 0.25)]).items()}
    {'elongation': [0.5], 'flatness': [0.5]}
    """
    a = np.array([[float(x) for x in v] for v in values], dtype=np.float64).reshape(-1, 3)
    return {"elongation": a[:, 1] / a[:, 0], "flatness": a[:, 2] / a[:, 1]}


def _label(v: Any) -> str:
    """A choice value as text (lists and tuples as ``a,b,c``)."""
    if isinstance(v, (list, tuple)):
        return ",".join(_label(x) for x in v)
    return repr(v) if isinstance(v, float) else str(v)


def _hist(ax, vals, colour) -> None:
    """A histogram that also copes with (nearly) constant data."""
    x = np.asarray(vals, dtype=np.float64)
    lo, hi = float(x.min()), float(x.max())
    if hi - lo <= 1e-9 * max(1.0, abs(hi)):
        lo, hi = lo - 0.5 * max(abs(lo) * 1e-3, 1e-9), hi + 0.5 * max(abs(hi) * 1e-3, 1e-9)
    bins = int(np.clip(np.sqrt(len(x)), 5, 40))
    ax.hist(x, bins=np.linspace(lo, hi, bins + 1), color=colour)


def population_figure(recipe, rows, info: Mapping[str, Any]):
    """The population figure (a matplotlib Figure): grading curve or size histogram, then one panel per
    drawn parameter and sphericity and convexity.  Every panel has both axes labelled (units where
    there are any); the last row is centred, so there are no empty panels.

    Parameters
    ----------
    recipe : Recipe
        The population's recipe.
    rows : sequence of mapping
        Its manifest rows.
    info : mapping
        Its summary (:func:`summary`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..methods import get
    from ..params import specs

    units = {s.name: s.unit for s in specs(get(recipe.method).Params)}
    drawn = [n for n, v in recipe.params.items() if isinstance(v, Distribution)]
    panels = ["size"] + drawn + ["sphericity", "convexity"]
    cols = 2 if len(panels) == 4 else min(3, len(panels))
    nrows = (len(panels) + cols - 1) // cols
    fig = plt.figure(figsize=(4.2 * cols, 3.4 * nrows))
    grid = fig.add_gridspec(nrows, 2 * cols)
    axes = []
    for k in range(len(panels)):
        r, c = divmod(k, cols)
        in_row = min(cols, len(panels) - r * cols)
        start = c * 2 + (cols - in_row)  # centre a short last row
        axes.append(fig.add_subplot(grid[r, start:start + 2]))
    colour = (0.70, 0.58, 0.40)
    xlabels = {"sphericity": "Wadell sphericity", "convexity": "convexity V/V_hull"}
    for ax, name in zip(axes, panels):
        if name == "size" and "grading" in info:
            g = info["grading"]
            ax.semilogx(g["sieves_mm"], g["target_percent_passing"], "k-o", ms=3, label="target")
            ax.semilogx(g["sieves_mm"], g["achieved_percent_passing"], "s--", ms=3, color="tab:red",
                        label=f"achieved (max dev {g['max_abs_deviation_percent']:.1f} points)")
            ax.set_xlabel(f"{recipe.size_definition} size (mm)")
            ax.set_ylabel(f"percent passing (by {g['basis']})")
            ax.set_ylim(-2, 102)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
            ax.set_title("grading curve")
        elif name == "size":
            _hist(ax, achieved_sizes(rows, recipe.size_definition), colour)
            ax.set_xlabel(f"{recipe.size_definition} size (mm)")
            ax.set_ylabel("number of grains")
            ax.set_title("size")
        else:
            vals = [r[name] for r in rows]
            if name in recipe.params and recipe.params[name].kind == "zingg":
                ratios = zingg_ratios(vals)
                bins = np.linspace(0.0, 1.0, 41)
                ax.hist(ratios["elongation"], bins=bins, color=colour, alpha=0.7, label="elongation I/L")
                ax.hist(ratios["flatness"], bins=bins, color="tab:blue", alpha=0.5, label="flatness S/I")
                ax.legend(fontsize=7, loc="upper left", framealpha=0.8)  # "best" is slow over many bars
            elif name in recipe.params and recipe.params[name].kind == "each":
                items = recipe.params[name].args["items"]
                for i, d in enumerate(items):
                    if isinstance(d, Distribution):
                        ax.hist([x[i] for x in vals], bins=30, alpha=0.6, label=f"{name}[{i}]")
                ax.legend(fontsize=7, loc="upper right", framealpha=0.8)
            elif name in recipe.params and recipe.params[name].kind == "choice":
                labels = [_label(x) for x in vals]
                keys = [_label(c) for c in recipe.params[name].args["values"]]
                ax.bar(range(len(keys)), [labels.count(k) for k in keys], color=colour)
                ax.set_xticks(range(len(keys)), keys, rotation=20 if len(keys) > 3 else 0)
                ax.set_xlabel(f"{name} (value drawn)")
            else:
                _hist(ax, vals, colour)
                unit = units.get(name, "")
                ax.set_xlabel(xlabels.get(name, name.replace("_", " ")) + (f" ({unit})" if unit else ""))
            ax.set_ylabel("number of grains")
            ax.set_title(name.replace("_", " ") if name in drawn else xlabels.get(name, name))
        ax.tick_params(labelsize=7)
    fig.suptitle(f"{recipe.method} population: {len(rows)} grains, root seed {recipe.seed}", fontsize=10)
    fig.tight_layout()
    return fig


def _figure(recipe, rows, info: Mapping[str, Any], path: Path) -> None:
    save_figure(population_figure(recipe, rows, info), path, dpi=90)


def population_report(recipe, rows: Sequence[Mapping[str, Any]], out: str | Path) -> dict[str, Any]:
    """Write ``manifest.json`` (summary) and ``population.png`` into ``out``; return the summary.

    Parameters
    ----------
    recipe : Recipe
        The population's recipe.
    rows : sequence of mapping
        Its manifest rows, in grain order.
    out : str or pathlib.Path
        The output folder (existing); both files are written atomically.

    Returns
    -------
    dict
        The summary (:func:`summary`).
    """
    out = Path(out)
    info = summary(recipe, rows)
    atomic_write(out / SUMMARY, json.dumps(info, indent=2, sort_keys=True) + "\n")
    _figure(recipe, rows, info, out / FIGURE)
    return info
