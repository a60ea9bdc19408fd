"""results.csv and the figure of a virtual bulk test."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io import save_figure, write_csv
from ..params import as_dict
from .angles import TILT_FAILURE, heap_angle, tilt_curve

__all__ = ["write_report", "figure", "figure_caption", "add_caption", "annotate_rows", "result_line", "failed_runs"]

#: the lowest displacement tilt.png's log axis shows (grain diameters); smaller ones are drawn on it
DISPLACEMENT_FLOOR = 1e-4


def write_report(rows: Sequence[dict], out: str | Path, *, test: str, settings,
                 caption: str | None = None) -> list[Path]:
    """Write ``out/results.csv`` (one row per seed, the settings in every row) and ``out/<test>.png``; for a
    triaxial test also each seed's ``triaxial-seed<k>/triaxial.csv``.

    Parameters
    ----------
    rows : sequence of dict
        One row per seed (:func:`grainforge.simulate.run_test`; angles in degrees).
    out : path
        The output folder, holding each run's ``<test>-seed<k>/result.json``.
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The runs' settings, written into every row as ``setting_<name>`` (SI units; a triaxial test's stresses in
        kPa).
    caption : str, optional
        The figure's line naming the engine, the population and the rate (:func:`figure_caption`), also the
        PNG's ``Description``.

    Returns
    -------
    list of Path
        The files written: ``results.csv``, each ``triaxial.csv`` (stresses in kPa) of a triaxial test, the figure.
    """
    out = Path(out)
    extra = {f"setting_{k}": v for k, v in as_dict(settings).items()}
    table = [{**r, **extra} for r in rows]
    paths = [write_csv(out / "results.csv", table)]
    results = [json.loads((out / f"{test}-seed{r['seed']}" / "result.json").read_text()) for r in rows]
    if test == "triaxial":  # each seed's curve in its folder; the figure of q/p' and volumetric strain
        from .triaxial import triaxial_figure, write_triaxial_csv

        paths += [write_triaxial_csv(res, out / f"{test}-seed{r['seed']}" / "triaxial.csv")
                  for res, r in zip(results, rows)]
        fig = triaxial_figure(results, rows)
        add_caption(fig, caption)
        paths.append(save_figure(fig, out / f"{test}.png", description=caption))
        return paths
    paths.append(save_figure(figure(test, results, rows, caption), out / f"{test}.png", description=caption))
    return paths


#: the engines' names in the figures' captions
ENGINE_NAMES = {"yade": "Yade", "liggghts": "LIGGGHTS"}


def figure_caption(test: str, settings, *, templates: Sequence, label: str, engine: str = "yade",
                   mpi: int | None = None, spacing: float | None = None, rows: Sequence[dict] = (),
                   friction: bool = True) -> str:
    """The line every figure of a virtual test carries: the engine, the population and the test's rate.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The runs' settings (grains, the tilt's steps, the triaxial test's inertial number, μ).
    templates : sequence of GrainTemplate
        The templates the runs drew their grains from (:func:`grainforge.simulate.build_population`): their
        number and representation (clumps and their sphere counts, or level sets).
    label : str
        The population's name (the inputs', or ``--label``).
    engine : {"yade", "liggghts"}
        The engine of the runs.
    mpi : int, optional
        LIGGGHTS's MPI ranks per run.
    spacing : float, optional
        A level set's grid spacing, in equivalent diameters.
    rows : sequence of dict
        The runs' rows: a triaxial run's ``strain_rate_per_s`` (the strain rate its inertial number set).
    friction : bool
        Name the contact friction μ (a calibration's figure, whose runs vary it, does not).

    Returns
    -------
    str
        ``engine · population: N grains from T templates, representation · [μ[, μ_r] ·] rate``.

    Examples
    --------
    >>> from .settings import Settings
    >>> figure_caption("tilt", Settings(), templates=[], label="sand.toml")
    'Yade · sand.toml: 200 grains from 0 templates · μ = 0.5 · tilt 0.5° every 8 √(d/g) from 10°'
    >>> figure_caption("tilt", Settings(rolling_friction=0.2), templates=[], label="sand.toml").split(" · ")[2]
    'μ = 0.5, μ_r = 0.2'
    """
    from .settings import LIFT_SPEED, TILT_HOLD

    name = ENGINE_NAMES.get(engine, engine) + (f", {mpi} MPI ranks" if mpi else "")
    population = f"{label}: {settings.grains} grains from {len(templates)} template" + "s" * (len(templates) != 1)
    shapes = {getattr(t, "shape", "clump") for t in templates}
    if shapes == {"levelset"}:
        population += ", level sets" + (f" (grid {spacing:g} d)" if spacing is not None else "")
    elif templates and all(getattr(t, "clump", None) is not None for t in templates):
        counts = sorted(len(t.clump.radii) for t in templates)
        if counts[-1] == 1:
            population += ", one sphere a grain"
        else:
            many = f"{counts[0]}" if counts[0] == counts[-1] else f"{counts[0]}–{counts[-1]}"
            population += f", clumps of {many} spheres"
    if test == "tilt":
        rate = f"tilt {settings.tilt_step:g}° every {TILT_HOLD:g} √(d/g) from {settings.tilt_start:g}°"
    elif test == "repose":
        rate = ("cylinder removed at once" if engine == "liggghts"
                else f"cylinder lifted at {LIFT_SPEED:g} √(g d)")
    else:
        rates = [float(r["strain_rate_per_s"]) for r in rows if r.get("strain_rate_per_s") is not None]
        rate = f"sheared at I = {settings.inertial_number:g}" + (f" (ε̇ = {rates[0]:.3g}/s)" if rates else "")
    mu_r = float(getattr(settings, "rolling_friction", 0.0) or 0.0)
    contact = f"μ = {settings.friction:g}" + (f", μ_r = {mu_r:g}" if mu_r > 0 else "")
    parts = [name, population] + ([contact] if friction else []) + [rate]
    return " · ".join(parts)


def add_caption(fig, caption: str | None) -> None:
    """Put ``caption`` (:func:`figure_caption`) above a figure's panels, wrapped to its width between its
    `` · ``-separated parts, and lay the figure out.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure, its panels drawn.
    caption : str or None
        The line; None lays the figure out without one.
    """
    import textwrap

    if caption:
        width = max(40, int(fig.get_figwidth() * 16))  # characters of 8 pt a line
        lines: list[str] = []
        for part in caption.split(" · "):
            if lines and len(lines[-1]) + 3 + len(part) <= width:
                lines[-1] += " · " + part
            else:
                lines += textwrap.wrap(part, width) or [""]
        fig.suptitle("\n".join(lines), fontsize=8, color="0.2")
    fig.tight_layout()


def _heap(result: dict):
    """The measured heap of a repose result, or None when it is too small to have a slope."""
    d = result["d_mean"]
    try:
        return heap_angle(np.asarray(result["spheres"]), bin_width=0.5 * d, grain_size=d, base=result["base_top"])
    except ValueError:
        return None


def figure(test: str, results: Sequence[dict], rows: Sequence[dict], caption: str | None = None):
    """The figure of a finished test: the final heap (or the tilt record) and the measured angle.

    Repose: left, a side view of the first seed's heap (every contact sphere,
    height against distance from the heap's axis, in mm) with the fitted slope;
    right, each seed's surface profile with its angle.  Tilt: the layer's mean
    downslope displacement against the tilt angle, per seed, with the failure
    threshold and the failure angles; between increments each line is the
    interpolation the failure angle is read from (:func:`grainforge.simulate.angles.tilt_curve`), so it
    crosses the threshold at the angle reported.

    Parameters
    ----------
    test : {"repose", "tilt"}
        The virtual test.
    results : sequence of dict
        Each seed's ``result.json`` (lengths in m).
    rows : sequence of dict
        Each seed's row (:func:`grainforge.simulate.measure_result`; angles in degrees).
    caption : str, optional
        The line above the panels (:func:`figure_caption`: engine, population, rate).

    Returns
    -------
    matplotlib.figure.Figure
        The figure (two panels).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if test == "repose":
        fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2), dpi=120)
        r0 = results[0]
        s = np.asarray(r0["spheres"])
        base = r0["base_top"]
        h = _heap(r0)
        xy = s[:, :2] - np.average(s[:, :2], axis=0, weights=s[:, 3] ** 3)
        side = np.hypot(xy[:, 0], xy[:, 1]) * np.sign(xy[:, 0] + 1e-30)
        from matplotlib.collections import EllipseCollection

        ax0.add_collection(EllipseCollection(2e3 * s[:, 3], 2e3 * s[:, 3], 0.0, units="xy",
                                             offsets=np.column_stack([1e3 * side, 1e3 * (s[:, 2] - base)]),
                                             offset_transform=ax0.transData, facecolors="0.6",
                                             edgecolors="0.3", linewidths=0.2, alpha=0.6))
        ax0.autoscale_view()
        ax0.axhline(0.0, color="k", lw=1)
        if h is not None:
            a, b = h.fit
            rr = np.array(h.fitted)
            for sgn in (1, -1):
                ax0.plot(sgn * 1e3 * rr, 1e3 * (a + b * rr), "C3-", lw=2)
        slope = f"slope {h.angle:.1f}°" if h is not None else "too small to measure a slope"
        ax0.set_title(f"seed {rows[0]['seed']}: final heap, side view; {slope}")
        ax0.set_xlabel("distance from the heap axis, signed by side (mm)")
        ax0.set_ylabel("height above the rough base (mm)")
        ax0.set_aspect("equal", adjustable="datalim")
        for k, (res, row) in enumerate(zip(results, rows)):
            hk = _heap(res)
            if hk is None:
                continue
            ax1.plot(1e3 * hk.profile[:, 0], 1e3 * hk.profile[:, 1], "o-", ms=3, color=f"C{k}",
                     label=f"seed {row['seed']}: {row['angle_deg']:.1f}°")
            ak, bk = hk.fit
            rk = np.array(hk.fitted)
            ax1.plot(1e3 * rk, 1e3 * (ak + bk * rk), "-", lw=3, alpha=0.4, color=f"C{k}")
        ax1.set_xlabel("distance from the heap axis (mm)")
        ax1.set_ylabel("surface height, mean of 8 sectors (mm)")
        ax1.set_title("profiles; thick: the slope fitted between 20 % and 80 % of the height", fontsize=10)
        if ax1.get_lines():
            ax1.legend(loc="upper right", fontsize=8)
        else:
            ax1.text(0.5, 0.5, "no heap with a slope to measure\n(too few grains: use more --grains)",
                     ha="center", va="center", transform=ax1.transAxes)
    else:
        fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
        for k, (res, row) in enumerate(zip(results, rows)):
            # between increments, as the failure angle interpolates them (tilt_failure_angle): the line crosses
            # the threshold at the angle the legend gives
            angles, disp, increments = tilt_curve(np.asarray(res["history"]), displacement=TILT_FAILURE)
            failed = math.isfinite(row["angle_deg"])
            ax.plot(angles, np.maximum(disp, DISPLACEMENT_FLOOR), "o-", ms=3, markevery=list(increments),
                    color=f"C{k}", label=f"seed {row['seed']}: fails at {row['angle_deg']:.1f}°" if failed
                    else f"seed {row['seed']}: no failure")
            if failed:
                ax.plot([row["angle_deg"]], [TILT_FAILURE], "|", ms=10, mew=1.5, color=f"C{k}")
        ax.axhline(TILT_FAILURE, color="0.3", ls="--", lw=1, label="failure: 0.5 grain diameters")
        ax.set_xlabel("tilt angle (°)")
        ax.set_ylabel("mean downslope displacement (grain diameters)")
        ax.set_yscale("log")
        ax.set_ylim(DISPLACEMENT_FLOOR, 2.0)
        ax.set_title("tilt table: a periodic layer on a rough plate")
        ax.legend(loc="upper left", fontsize=8)
    add_caption(fig, caption)
    return fig


def annotate_rows(rows: list[dict], *, shape: str, spacing: float, engine: str, mpi: int | None,
                  clump_accuracy: float | None) -> list[dict]:
    """``results.csv``'s rows with the settings that differ from the defaults (the default runs' rows unchanged).

    Parameters
    ----------
    rows : list of dict
        One row per seed.
    shape, spacing : str, float
        The grains' representation and a level set's grid (added when not ``"clump"``).
    engine, mpi : str, int or None
        The engine and its MPI ranks (added when not Yade).
    clump_accuracy : float or None
        The clumps' accuracy target (added when given).

    Returns
    -------
    list of dict
        The rows, each with those columns added.

    Examples
    --------
    >>> annotate_rows([{"seed": 0}], shape="clump", spacing=0.05, engine="liggghts", mpi=None, clump_accuracy=None)
    [{'seed': 0, 'engine': 'liggghts', 'mpi_ranks': 1}]
    """
    if shape != "clump":  # the representation
        rows = [{**r, "shape": shape, "spacing": spacing} for r in rows]
    if engine != "yade":  # the engine and its MPI ranks
        rows = [{**r, "engine": engine, "mpi_ranks": mpi or 1} for r in rows]
    if clump_accuracy is not None:  # the clumps' accuracy target
        rows = [{**r, "clump_accuracy": clump_accuracy} for r in rows]
    return rows


def result_line(test: str, rows: list[dict], label: str, out) -> str:
    """The line a finished run prints: the measured angle(s) over the seeds and where the outputs are.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    rows : list of dict
        ``results.csv``'s rows.
    label : str
        The population's name.
    out : pathlib.Path
        The output folder.

    Returns
    -------
    str
        ``label: <angle> ± <sd> ...; <results.csv>, <figure>``, or what was not measured and why.
    """
    from .engine import summarise

    where = f"{out / 'results.csv'}, {out / (test + '.png')}"
    if test == "triaxial":
        from .triaxial import summarise_triaxial

        return f"{label}: {summarise_triaxial(rows)}; {where}"
    summary = summarise(rows)
    sd = summary["angle_sd_deg"]
    spread = f" ± {sd:.1f}° (sd over {summary['runs']} seeds)" if summary["runs"] > 1 else " (one seed)"
    name = "angle of repose" if test == "repose" else "tilt failure angle"
    if summary["runs"] == 0:
        return f"{label}: no {name} measured ({rows[0].get('note', '')}); {out / 'results.csv'}"
    return f"{label}: {name} {summary['angle_mean_deg']:.1f}°{spread}; {where}"


def failed_runs(rows: list[dict], first_seed: int) -> str:
    """The runs that fail their own check, in one line: no angle measured, a repose heap not at rest, grains lost;
    a triaxial run's own ``problems`` (:func:`grainforge.simulate.triaxial.measure_triaxial`).

    Parameters
    ----------
    rows : list of dict
        ``results.csv``'s rows.
    first_seed : int
        The first seed (a row without ``seed`` is numbered from it).

    Returns
    -------
    str
        ``seed <k>: <why>`` for each failing run, joined by ``; `` (empty when every run passes).

    Examples
    --------
    >>> failed_runs([{"test": "repose", "angle_deg": float("nan"), "settled": True, "lost": 0, "note": "too flat"},
    ...              {"test": "repose", "angle_deg": 30.0, "settled": False, "lost": 2, "note": ""}], 0)
    'seed 0: no angle (too flat); seed 1: not at rest at the end, 2 grain(s) lost'
    >>> failed_runs([{"test": "triaxial", "seed": 4, "problems": "no stress ratio recorded", "lost": 0}], 0)
    'seed 4: no stress ratio recorded'
    """
    import math

    out = []
    for k, r in enumerate(rows):
        why = []
        if r.get("test") == "triaxial":
            why += [r["problems"]] if r.get("problems") else []
        elif not math.isfinite(float(r["angle_deg"])):
            why.append(f"no angle ({r.get('note') or 'not measured'})")
        if r.get("test") == "repose" and not r.get("settled", True):
            why.append("not at rest at the end")
        if int(r.get("lost", 0)):
            why.append(f"{int(r['lost'])} grain(s) lost")
        if why:
            out.append(f"seed {r.get('seed', first_seed + k)}: " + ", ".join(why))
    return "; ".join(out)
