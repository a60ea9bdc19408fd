"""Population plots from manifests: Zingg diagram, sphericity–convexity, FD spectra, size distribution.

Each plot takes one or more manifests (CSV files written by ``grainforge
generate``/``batch`` or ``grainforge analyse --csv``) and overlays them with a
legend.  Columns used: ``L, I, S`` (Zingg), ``sphericity, convexity``,
``equivalent_diameter`` (and ``volume`` for mass weighting), and for FD
spectra the ``fd_LI_n``/``fd_LS_n``/``fd_IS_n`` columns of ``analyse`` (or a
CRI manifest's ``descriptors``/``decay``/``modes``, drawn as the input spectrum).
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = [
    "KINDS", "manifest_columns", "plot", "figure", "zingg", "sphericity_convexity", "fd_spectrum", "size_distribution", "demo_plots",
]


def manifest_columns(path: str | Path) -> dict[str, list[str]]:
    """Columns of a CSV manifest as lists of strings.

    Parameters
    ----------
    path : str or Path
        A manifest (or any CSV grainforge writes).

    Returns
    -------
    dict of str to list of str
        Plain column name (unit suffix removed, :func:`grainforge.units.plain`) -> its cells.

    Raises
    ------
    ValueError
        If the file is missing, not CSV or empty.
    """
    from ..io.inputs import read_manifest

    path = Path(path)
    rows = read_manifest(path)
    if not rows:
        raise InputError(f"{path}: holds no rows")
    from ..units import plain

    # headers state their unit (volume_mm3); the plots use the plain names
    return {plain(k): [r.get(k) or "" for r in rows] for k in rows[0] if k is not None}


def _numeric(table: dict, column: str, path) -> np.ndarray:
    if column not in table:
        raise InputError(f"{path}: no column {column!r}")
    out = np.full(len(table[column]), np.nan)
    for i, s in enumerate(table[column]):
        try:
            out[i] = float(s)
        except ValueError:
            pass
    if len(out) and not np.isfinite(out).any():
        bad = next((s for s in table[column] if s.strip()), "")
        raise InputError(f"{path}: column {column!r} holds no numbers" + (f" (e.g. {bad!r})" if bad else ""))
    return out


def _label(path: Path) -> str:
    path = Path(path)
    return path.parent.name or path.stem if path.name == "manifest.csv" else path.stem


def zingg(ax, tables) -> None:
    """Zingg diagram: flatness S/I against elongation I/L, with the 2/3 class boundaries.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axis to draw on.
    tables : iterable of (Path, dict)
        ``(manifest path, manifest_columns(path))`` per population.
    """
    for (path, t), marker in zip(tables, _markers()):
        L, I, S = (_numeric(t, c, path) for c in ("L", "I", "S"))
        ax.scatter(I / L, S / I, s=14, alpha=0.75, marker=marker, label=f"{_label(path)} (n={len(L)})")
    ax.axvline(2 / 3, color="0.6", lw=0.8)
    ax.axhline(2 / 3, color="0.6", lw=0.8)
    # each class name in its quadrant's corner next to the 2/3 lines, above the points on a light
    # box: the equant corner (1, 1) is where most grains fall, and a name there would be hidden
    pad = 0.015
    for x, y, ha, va, name in ((2 / 3 - pad, 2 / 3 - pad, "right", "top", "blade"),
                               (2 / 3 + pad, 2 / 3 - pad, "left", "top", "disc"),
                               (2 / 3 - pad, 2 / 3 + pad, "right", "bottom", "rod"),
                               (2 / 3 + pad, 2 / 3 + pad, "left", "bottom", "equant")):
        ax.text(x, y, name, ha=ha, va=va, color="0.35", fontsize=9, zorder=5,
                bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.85))
    ax.set(xlim=(0, 1.02), ylim=(0, 1.02), xlabel="elongation I/L", ylabel="flatness S/I", title="Zingg diagram")
    ax.set_aspect("equal")


def sphericity_convexity(ax, tables) -> None:
    """Wadell sphericity against convexity V/V_hull.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axis to draw on.
    tables : iterable of (Path, dict)
        ``(manifest path, manifest_columns(path))`` per population.
    """
    for (path, t), marker in zip(tables, _markers()):
        x, y = _numeric(t, "convexity", path), _numeric(t, "sphericity", path)
        ax.scatter(x, y, s=14, alpha=0.75, marker=marker, label=f"{_label(path)} (n={len(x)})")
    ax.set(xlabel="convexity V/V_hull", ylabel="Wadell sphericity", title="Sphericity vs convexity")
    ax.set_xlim(right=1.01)
    ax.set_ylim(top=1.01)


def _fd_matrix(t, plane: str):
    cols = sorted(
        (int(k.rsplit("_", 1)[1]), k) for k in t if k.startswith(f"fd_{plane}_") and k.rsplit("_", 1)[1].isdigit()
    )
    return [n for n, _ in cols], [k for _, k in cols]


def fd_spectrum(ax, tables) -> None:
    """Fourier descriptor spectra D_n (log–log): median and 10–90 % band over each population.

    Uses the principal-projection descriptors of ``grainforge analyse`` (all
    three planes pooled); a CRI manifest's input spectrum (its
    ``descriptors``, ``decay`` and ``modes``) is drawn dashed where present.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axis to draw on.
    tables : iterable of (Path, dict)
        ``(manifest path, manifest_columns(path))`` per population.
    """
    from ..analysis.fourier import FD_ORDERS, PLANES
    from ..outline.contours import DEFAULT_DECAY, DEFAULT_MODES, descriptor_spectrum

    drew = False
    for (path, t), color in zip(tables, _colors()):
        lab = _label(path)
        planes = [m for m in (_fd_matrix(t, p) for p in PLANES) if m[0]]
        if planes:
            n = planes[0][0]
            M = np.concatenate([np.stack([_numeric(t, k, path) for k in cols], axis=1) for _, cols in planes])
            M = np.where(M > 0, M, np.nan)
            med = np.nanmedian(M, axis=0)
            lo, hi = np.nanpercentile(M, [10, 90], axis=0)
            ax.fill_between(n, lo, hi, color=color, alpha=0.2, lw=0)
            ax.plot(n, med, "o-", color=color, ms=3, label=f"{lab}: measured (median, 10–90 %)")
            drew = True
        if "descriptors" in t and any(t["descriptors"]):
            s = next(x for x in t["descriptors"] if x)
            d2, d3, d8 = (float(x) for x in s.split())
            decay = tuple(float(x) for x in t["decay"][0].split()) if t.get("decay", [""])[0] else DEFAULT_DECAY
            modes = int(float(t["modes"][0])) if t.get("modes", [""])[0] else DEFAULT_MODES
            D = descriptor_spectrum(d2, d3, d8, decay=decay, modes=modes)
            k = np.arange(FD_ORDERS[0], min(len(D), FD_ORDERS[-1] + 1))
            keep = D[k] > 0
            ax.plot(k[keep], D[k][keep], "--", color=color, label=f"{lab}: input ({d2:g}, {d3:g}, {d8:g})")
            drew = True
    if not drew:
        raise InputError(
            "no Fourier descriptor columns (fd_LI_2 ...) or CRI input descriptors in the manifest(s); "
            "measure the grains with `grainforge analyse FILES --csv OUT.csv`"
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set(xlabel="harmonic order n", ylabel="Fourier descriptor D_n = 2|c_n|/c_0",
           title="Fourier descriptor spectrum (principal projections)")
    ax.set_xticks([2, 3, 4, 6, 8, 12, 16])
    ax.set_xticklabels(["2", "3", "4", "6", "8", "12", "16"])


def size_distribution(ax, tables) -> None:
    """Grading curve: percentage finer by volume (mass) against equivalent diameter (mm, log scale).

    Populations with identical sizes (e.g. several runs all generated at
    10 mm) give the same curve: it is drawn once, with every population named
    in its legend entry, rather than as lines hiding each other.  A single-size
    population is a vertical step, marked at its size.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axis to draw on.
    tables : iterable of (Path, dict)
        ``(manifest path, manifest_columns(path))`` per population.
    """
    curves: list[tuple[np.ndarray, np.ndarray, list[str]]] = []
    for path, t in tables:
        d = _numeric(t, "equivalent_diameter", path)
        w = _numeric(t, "volume", path) if "volume" in t else d**3
        ok = np.isfinite(d) & np.isfinite(w)
        d, w = d[ok], w[ok]
        d = np.round(d, 6)  # sizes equal to a micrometre are one size (10 mm written as 9.999999999)
        o = np.argsort(d, kind="stable")
        finer = 100 * np.cumsum(w[o]) / w.sum()
        # the curve as drawn: % finer after each distinct size
        ud = np.unique(d[o])
        uf = finer[np.searchsorted(d[o], ud, side="right") - 1]
        name = f"{_label(path)} (n={len(d)})"
        for cd, cf, names in curves:
            if len(cd) == len(ud) and np.allclose(cd, ud, rtol=1e-6) and np.allclose(cf, uf, atol=1e-6):
                names.append(name)
                break
        else:
            curves.append((ud, uf, [name]))
    lo = min(float(c[0][0]) for c in curves)
    hi = max(float(c[0][-1]) for c in curves)
    for (d, finer, names), color, marker in zip(curves, _colors(), _markers()):
        x = np.concatenate([[d[0]], d])
        y = np.concatenate([[0.0], finer])
        single = np.ptp(d) <= 1e-9 * d[0]
        label = textwrap.fill(", ".join(names) + (f": all {d[0]:.3g} mm" if single else ""), 70)
        ax.step(x, y, where="post", color=color, lw=1.4, label=label, marker=marker if single else None,
                markevery=[len(x) - 1] if single else None, ms=5)
    ax.set_xscale("log")
    ax.set_xlim(lo / 1.6, hi * 1.6)
    _plain_log_ticks(ax.xaxis, lo / 1.6, hi * 1.6)
    ax.set(xlabel="equivalent diameter d_eq (mm)", ylabel="% finer by volume", ylim=(0, 102),
           title="Size distribution")
    ax.grid(True, which="both", color="0.9", lw=0.5)
    # below the axes: any corner inside may hold a curve (tight_layout makes room for it)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.17), ncol=1, frameon=False)


def _plain_log_ticks(axis, lo: float, hi: float, most: int = 6) -> None:
    """Labelled ticks in mm as a person writes them (0.2, 0.5, 1, 2, ...) on a log axis from ``lo`` to ``hi``.

    The densest of the 1-9, 1-2-3-5, 1-2-5, 1-3 and 1 sequences with at most ``most`` ticks in view, the
    rest unlabelled: matplotlib's own labels (3×10⁻¹, 4×10⁻¹, ...) overlap on an axis of one or two
    decades.

    Examples
    --------
    >>> import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
    >>> fig, ax = plt.subplots(); ax.set_xscale("log"); ax.set_xlim(0.3, 5)
    (0.3, 5)
    >>> _plain_log_ticks(ax.xaxis, 0.3, 5); [f"{v:g}" for v in ax.get_xticks()]
    ['0.3', '0.5', '1', '2', '3', '5']
    >>> plt.close(fig)
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    ticks = [1.0]
    for subs in (tuple(range(1, 10)), (1, 2, 3, 5), (1, 2, 5), (1, 3), (1,)):
        k = np.arange(np.floor(np.log10(lo)), np.ceil(np.log10(hi)) + 1)
        cand = np.sort((np.asarray(subs, dtype=float)[None, :] * 10.0 ** k[:, None]).ravel())
        ticks = [float(v) for v in cand if lo <= v <= hi]
        if len(ticks) <= most:
            break
    if len(ticks) > most:  # many decades: every n-th power of ten
        step = int(np.ceil(len(ticks) / most))
        ticks = ticks[::step]
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    axis.set_minor_locator(LogLocator(subs=np.arange(2, 10)))
    axis.set_minor_formatter(NullFormatter())


def _fit_legend(fig, ax) -> None:
    """Lay ``fig`` out tightly, making the figure taller until the legend below the axes is inside it.

    ``tight_layout`` alone leaves the legend cut off on an equal-aspect axis (the Zingg diagram).
    """
    for _ in range(4):
        fig.tight_layout()
        legend = ax.get_legend()
        if legend is None:
            return
        fig.canvas.draw()  # applies the axis aspect: the legend's place as it will be saved
        box = legend.get_window_extent(fig.canvas.get_renderer())
        short = max(0.0, fig.bbox.y0 - box.y0) + max(0.0, box.y1 - fig.bbox.y1)
        if short < 1.0:  # pixels
            return
        w, h = fig.get_size_inches()
        fig.set_size_inches(w, h + short / fig.dpi + 0.1)


def _markers():
    while True:
        yield from ("o", "s", "^", "D", "v", "P", "X", "*")


def _colors():
    while True:
        yield from (f"C{i}" for i in range(10))


#: plot kind -> function(ax, [(path, table), ...])
KINDS = {
    "zingg": zingg,
    "sphericity-convexity": sphericity_convexity,
    "fd-spectrum": fd_spectrum,
    "size-distribution": size_distribution,
}


def figure(kind: str, manifests: Sequence[str | Path], *, title: str | None = None):
    """The matplotlib Figure of plot ``kind`` for one or more manifests (see :func:`plot`).

    Parameters
    ----------
    kind : str
        A key of :data:`KINDS`: ``"zingg"``, ``"sphericity-convexity"``, ``"fd-spectrum"`` or ``"size-distribution"``.
    manifests : sequence of str or Path
        One population per manifest.
    title : str, optional
        The axis title.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        For an unknown kind, no manifest, or a manifest without the columns the plot needs.
    """
    if kind not in KINDS:
        raise InputError(f"plot kind must be one of {', '.join(KINDS)}, got {kind!r}")
    if not manifests:
        raise InputError("at least one manifest is needed")
    tables = [(Path(p), manifest_columns(p)) for p in manifests]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_entries = len(manifests)
    fig, ax = plt.subplots(figsize=(6.0, 4.8 + 0.16 * n_entries) if kind != "zingg" else (5.4, 5.8 + 0.16 * n_entries),
                           dpi=130)
    try:
        KINDS[kind](ax, tables)
        if title:
            ax.set_title(title)
        if ax.get_legend() is None:
            # below the axes: inside, a legend may cover points or bands
            ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1, frameon=False)
        _fit_legend(fig, ax)
    except BaseException:
        plt.close(fig)  # also when drawing fails
        raise
    return fig


def plot(kind: str, manifests: Sequence[str | Path], out: str | Path, *, title: str | None = None) -> Path:
    """Draw plot ``kind`` for one or more manifests into a PNG (atomically).

    Parameters
    ----------
    kind : str
        A key of :data:`KINDS`.
    manifests : sequence of str or Path
        One population per manifest.
    out : str or Path
        The PNG file.
    title : str, optional
        The axis title.

    Returns
    -------
    Path
        ``out``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "m.csv").write_text("L,I,S\\n3,2,1\\n2,2,1\\n")
    >>> plot("zingg", [d / "m.csv"], d / "z.png").name
    'z.png'
    """
    from ..io import save_figure

    return save_figure(figure(kind, manifests, title=title), out)


def demo_plots(out: str | Path, quick: bool = False) -> list[Path]:
    """The demo's analysis section: population plots of every run the demo wrote.

    Manifests are pooled per top-level folder of ``out`` (one legend entry
    each) into ``out/analysis/<folder>.csv``; up to 4 (quick: 2) grain
    files per folder are measured with :func:`~grainforge.analysis.measure.analyse_file`
    for the FD spectra.  Writes ``out/analysis/*.png``.

    Parameters
    ----------
    out : str or Path
        The demo's output folder.
    quick : bool, default False
        Measure fewer grain files.

    Returns
    -------
    list of Path
        The pooled CSVs and the PNGs (empty when ``out`` holds no manifest).
    """
    from ..analysis.measure import ANALYSE_COLUMNS, analyse_file
    from ..io import write_csv

    out = Path(out)
    dest = out / "analysis"
    groups: dict[str, list[Path]] = {}
    for m in sorted(out.rglob("manifest.csv")):
        rel = m.relative_to(out)
        if rel.parts[0] == "analysis" or any(p.startswith(".") for p in rel.parts):
            continue
        groups.setdefault(rel.parts[0] if len(rel.parts) > 1 else out.name, []).append(m)
    if not groups:
        return []
    pooled, measured = [], []
    per_group = 2 if quick else 4
    for name, files in groups.items():
        rows: list[dict] = []
        meshes: list[Path] = []
        for m in files:
            t = manifest_columns(m)
            n = len(next(iter(t.values())))
            rows += [{k: t[k][i] for k in t} for i in range(n)]
            meshes += [m.parent / f for f in t.get("file", []) if f and (m.parent / f).is_file()]
        pooled.append(write_csv(dest / f"{name}.csv", rows, units=True))
        if meshes:
            pick = [meshes[i] for i in np.linspace(0, len(meshes) - 1, min(per_group, len(meshes))).astype(int)]
            mrows = [r for p in pick for r in analyse_file(p, fractal=False)]
            measured.append(write_csv(dest / f"{name}-measured.csv", mrows, ANALYSE_COLUMNS(True), units=True))
    written = [
        plot("zingg", pooled, dest / "zingg.png"),
        plot("sphericity-convexity", pooled, dest / "sphericity-convexity.png"),
        plot("size-distribution", pooled, dest / "size-distribution.png"),
    ]
    if measured:
        written.append(plot("fd-spectrum", measured, dest / "fd-spectrum.png"))
    return pooled + measured + written
