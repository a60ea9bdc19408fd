"""Calibration of the DPA exponent ε against the aggregate fractal dimension D_A.

For one primitive and number of primaries N, :func:`calibrate` grows
``repeats`` aggregates at every ε of a grid and records the mean and the
standard deviation of D_A (Eq. 5), porosity and R_g.  The mean curve is
inverted by :meth:`Calibration.exponent_for`, so a user can ask for a target
D_A (paper §2.3: "by constructing a calibration curve, it is possible to
control the value of the exponent ε to yield a desired D_A").

Aggregate ``k`` of the grid (ε index i, repeat r, k = i·repeats + r) is grown
from ``SeedSequence(rng).spawn(...)[k]`` (``rng`` an int seed; see
:func:`grainforge.rng.seed_sequence` for the other kinds), so the numbers do
not depend on the number of worker processes.  Curves used by ``dpa(target_fractal_dimension=...)``
are cached as CSV under :func:`cache_dir`.

:func:`dpa` (exported as ``grainforge.dpa``) lives here rather than in
:mod:`grainforge.methods.dpa` because choosing ε for a target D_A needs the
calibration, which grows aggregates with :mod:`grainforge.methods.dpa`: the
method module stays free of this dependency (no import cycle).
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...params import ParameterError
from ...rng import RNGLike, seed_sequence
from ...runtime.cache import cache_dir

__all__ = [
    "Calibration", "calibrate", "parse_exponents", "cached_calibration",
    "exponent_for_dimension", "DEFAULT_EXPONENTS", "DEFAULT_REPEATS", "COLUMNS",
]

#: header units of calibration.csv: R_g of the aggregate of primaries in primary sizes a = V_p^(1/3)
UNITS = {"R_g_mean": "primary_sizes", "R_g_std": "primary_sizes"}
#: ε grid of the cached curves: 16 points, log-spaced from 0.05 to 100.
DEFAULT_EXPONENTS = tuple(float(x) for x in np.round(np.geomspace(0.05, 100.0, 16), 6))
DEFAULT_REPEATS = 8
#: bump when the DPA algorithm changes so that old cached curves are not reused.
#: 2: exact minimum-volume box (analysis.box), D_A_scaling columns;
#: 3: DPA contact rules (clearance 1e-3, notch ≥ 30°; docs/methods/dpa.md, "Contacts").
ALGORITHM_VERSION = 3
COLUMNS = (
    "exponent", "D_A_mean", "D_A_std", "porosity_mean", "porosity_std", "R_g_mean", "R_g_std",
    "D_A_scaling_mean", "D_A_scaling_std",
    "primitive", "primaries", "repeats", "seed",
)


#: most ε values one calibration may have
MAX_EXPONENTS = 1000


def parse_exponents(text: str) -> np.ndarray:
    """``"A:B:STEP"`` → A, A + STEP, …, B (inclusive); ``"a,b,c"`` → that list.

    Parameters
    ----------
    text : str
        ``"A:B:STEP"`` or comma-separated values (each > 0).

    Returns
    -------
    (E,) float64
        The ε grid (at most :data:`MAX_EXPONENTS` values).

    Raises
    ------
    ParameterError
        Naming ``exponents`` for a malformed text or too many values.

    Examples
    --------
    >>> parse_exponents("0.5:2:0.5").tolist()
    [0.5, 1.0, 1.5, 2.0]
    >>> parse_exponents("0.1,1,10").tolist()
    [0.1, 1.0, 10.0]
    >>> parse_exponents("2:1:0.5")
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: exponents must be A:B:STEP with 0 < A <= B and STEP > 0, got '2:1:0.5'
    """
    text = str(text).strip()
    try:
        if ":" in text:
            a, b, step = (float(x) for x in text.split(":"))
            if not (0 < a <= b and step > 0 and np.isfinite([a, b, step]).all()):
                raise ValueError
            n = int(np.floor((b - a) / step + 1e-9)) + 1
            if n > MAX_EXPONENTS:  # before allocating the grid
                values = None
            else:
                values = np.round(a + step * np.arange(n), 12)
        else:
            values = np.array([float(x) for x in text.split(",") if x.strip()])
            if len(values) == 0 or not (values > 0).all():
                raise ValueError
    except ValueError:
        raise ParameterError(
            "exponents", f"must be A:B:STEP with 0 < A <= B and STEP > 0, got {text!r}"
        ) from None
    if values is None:
        raise ParameterError("exponents", f"{text!r} gives {n} values; at most {MAX_EXPONENTS} are allowed "
                                          "(use a larger STEP)")
    if len(values) > MAX_EXPONENTS:
        raise ParameterError("exponents", f"gives {len(values)} values; at most {MAX_EXPONENTS} are allowed")
    return values


@dataclass(frozen=True)
class Calibration:
    """An ε → D_A calibration curve (mean and spread over seeds).

    Attributes
    ----------
    primitive : str
    primaries : int
    repeats : int
    seed : int or None
        The root seed the curve was grown from (``None`` when ``rng`` was a Generator or a spawned
        SeedSequence, which no int reproduces).
    exponent, D_A_mean, D_A_std, porosity_mean, porosity_std, R_g_mean, R_g_std : (E,) float64
    D_A_scaling_mean, D_A_scaling_std : (E,) float64
        The scaling dimension (:func:`grainforge.analysis.aggregate.scaling_dimension`);
        NaN when read from a file written before it existed.
    """

    primitive: str
    primaries: int
    repeats: int
    seed: int | None
    exponent: np.ndarray
    D_A_mean: np.ndarray
    D_A_std: np.ndarray
    porosity_mean: np.ndarray
    porosity_std: np.ndarray
    R_g_mean: np.ndarray
    R_g_std: np.ndarray
    D_A_scaling_mean: np.ndarray | None = None
    D_A_scaling_std: np.ndarray | None = None

    def __post_init__(self):
        nan = np.full(len(self.exponent), np.nan)
        for name in ("D_A_scaling_mean", "D_A_scaling_std"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, nan)

    def rows(self) -> list[dict]:
        """One dict per ε, keys :data:`COLUMNS`."

        Returns
        -------
        list of dict
        """
        out = []
        for i, e in enumerate(self.exponent):
            out.append({
                "exponent": float(e), "D_A_mean": float(self.D_A_mean[i]), "D_A_std": float(self.D_A_std[i]),
                "porosity_mean": float(self.porosity_mean[i]), "porosity_std": float(self.porosity_std[i]),
                "R_g_mean": float(self.R_g_mean[i]), "R_g_std": float(self.R_g_std[i]),
                "D_A_scaling_mean": float(self.D_A_scaling_mean[i]),
                "D_A_scaling_std": float(self.D_A_scaling_std[i]),
                "primitive": self.primitive, "primaries": self.primaries, "repeats": self.repeats, "seed": self.seed,
            })
        return out

    def write_csv(self, path: str | os.PathLike) -> Path:
        """Write ``calibration.csv``-style text atomically.

        Parameters
        ----------
        path : str or os.PathLike
            The CSV file (R_g columns suffixed with their unit, primary sizes).

        Returns
        -------
        Path
            ``path``.
        """
        from ...io import write_csv

        return write_csv(path, self.rows(), COLUMNS, units=UNITS)

    @classmethod
    def read_csv(cls, path: str | os.PathLike) -> Calibration:
        """Read a file written by :meth:`write_csv`.

        Parameters
        ----------
        path : str or os.PathLike
            A file written by :meth:`write_csv`.

        Returns
        -------
        Calibration
            The D_A scaling columns NaN-free only if the file has them.

        Raises
        ------
        ValueError
            If the file has no rows.
        """
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
        if not rows:
            raise InputError(f"{path}: empty calibration file")
        plain = {f"{c}_{u}": c for c, u in UNITS.items()}
        rows = [{plain.get(k, k): v for k, v in r.items()} for r in rows]
        r0 = rows[0]
        col = lambda k: np.array([float(r[k]) for r in rows]) if k in r0 else None  # noqa: E731
        return cls(
            primitive=r0["primitive"], primaries=int(r0["primaries"]), repeats=int(r0["repeats"]),
            seed=int(r0["seed"]) if r0.get("seed") else None, exponent=col("exponent"),
            D_A_mean=col("D_A_mean"), D_A_std=col("D_A_std"),
            porosity_mean=col("porosity_mean"), porosity_std=col("porosity_std"),
            R_g_mean=col("R_g_mean"), R_g_std=col("R_g_std"),
            D_A_scaling_mean=col("D_A_scaling_mean"), D_A_scaling_std=col("D_A_scaling_std"),
        )

    def usable(self) -> tuple[np.ndarray, np.ndarray]:
        """The invertible part of the curve: ε and mean D_A from the ε of the largest D_A on,
        made non-increasing (running minimum).  D_A falls with ε except for a small dip at the
        very lowest ε (breadth-first growth around the first primaries)."

        Returns
        -------
        exponent : (E',) float64
            ε, increasing.
        D_A : (E',) float64
            Mean D_A, non-increasing.
        """
        m = np.asarray(self.D_A_mean, dtype=np.float64)
        good = np.isfinite(m)
        e, m = np.asarray(self.exponent)[good], m[good]
        if len(e) == 0:
            return e, m
        k = int(np.argmax(m))
        return e[k:], np.minimum.accumulate(m[k:])

    def exponent_for(self, target: float) -> float:
        """ε whose mean D_A is ``target`` (interpolated in log ε on :meth:`usable`).

        Parameters
        ----------
        target : float
            Mean aggregate fractal dimension D_A wanted.

        Returns
        -------
        float
            ε.

        Raises
        ------
        ParameterError
            If ``target`` lies outside the calibrated range of mean D_A.
        """
        e, m = self.usable()
        target = float(target)
        if len(e) == 0 or not (m.min() <= target <= m.max()):
            lo, hi = (float(m.min()), float(m.max())) if len(m) else (float("nan"),) * 2
            raise ParameterError(
                "target_fractal_dimension",
                f"must be within the calibrated range [{lo:.3f}, {hi:.3f}] of mean D_A for "
                f"{self.primitive} aggregates of N={self.primaries}, got {target!r}",
            )
        if len(e) == 1:
            return float(e[0])
        # m is non-increasing: interpolate on the reversed (non-decreasing) arrays
        x = np.interp(target, m[::-1], np.log(e[::-1]))
        return float(np.exp(x))

    def plot(self, path: str | os.PathLike) -> Path:
        """A PNG of mean D_A ± one standard deviation against ε (and porosity on a second axis)."

        Parameters
        ----------
        path : str or os.PathLike
            The PNG file.

        Returns
        -------
        Path
            ``path``.
        """
        from ...io import save_figure

        return save_figure(self.figure(), path)

    def figure(self):
        """The Figure of :meth:`plot`; the legend sits below the axes, clear of every curve.

        Returns
        -------
        matplotlib.figure.Figure
        """
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        e = np.asarray(self.exponent)
        fig, ax = plt.subplots(figsize=(6.0, 4.8), dpi=110)
        ax.fill_between(e, self.D_A_mean - self.D_A_std, self.D_A_mean + self.D_A_std, color="C0", alpha=0.25,
                        label="D_A ± 1 s.d.")
        ax.plot(e, self.D_A_mean, "o-", color="C0", ms=3, label="mean D_A (Eq. 5)")
        if np.any(np.isfinite(self.D_A_scaling_mean)):
            sm, ss = self.D_A_scaling_mean, self.D_A_scaling_std
            ax.fill_between(e, sm - ss, sm + ss, color="C2", alpha=0.15, label="D_A scaling ± 1 s.d.")
            ax.plot(e, sm, "^:", color="C2", ms=3, label="mean D_A scaling (growth slope)")
        ax.set_xlabel("exponent ε (Eq. 4)")
        ax.set_ylabel("aggregate fractal dimension D_A")
        if e.max() / e.min() > 20:
            ax.set_xscale("log")
        ax2 = ax.twinx()
        ax2.plot(e, self.porosity_mean, "s--", color="C3", ms=3, label="mean porosity (right axis)")
        ax2.set_ylabel("porosity 1 − V/V_hull", color="C3")
        lines = ax.get_legend_handles_labels()
        lines2 = ax2.get_legend_handles_labels()
        # below the axes: inside, "best" only avoids the left-axis curves and covered the porosity
        ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=8, loc="upper center",
                  bbox_to_anchor=(0.5, -0.17), ncol=2, frameon=False)
        ax.set_title(f"DPA calibration: {self.primitive}, N = {self.primaries}, {self.repeats} seeds per ε",
                     fontsize=9)
        fig.tight_layout()
        return fig


def _measure(task) -> tuple[float, float, float, float]:
    """Grow one aggregate and return (D_A, porosity, R_g, D_A_scaling).  Module level so that it pickles."""
    from .aggregation import aggregate

    primitive, primaries, exponent, seed_seq = task
    m = aggregate(primitive, primaries, exponent=exponent, rng=seed_seq).measures()
    return m["D_A"], m["porosity"], m["R_g"], m["D_A_scaling"]


def calibrate(
    primitive: str = "cube",
    primaries: int = 200,
    *,
    exponents: Sequence[float] = DEFAULT_EXPONENTS,
    repeats: int = DEFAULT_REPEATS,
    rng: RNGLike = 0,
    workers: int | None = 1,
    progress: Callable[[Iterable], Iterable] | None = None,
) -> Calibration:
    """Measure D_A, D_A_scaling, porosity and R_g over ``repeats`` seeds at each ε.

    Parameters
    ----------
    primitive : str
        One of :data:`grainforge.methods.dpa.PRIMITIVES`.
    primaries : int
        N.
    exponents : sequence of float
        The ε grid (each in [0.01, 100]).
    repeats : int
        Aggregates per ε (≥ 1).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, default 0
        The root of the aggregates' streams, :func:`grainforge.rng.seed_sequence`: aggregate k
        uses ``SeedSequence(rng).spawn(E·repeats)[k]`` for an int seed, child k of a given
        SeedSequence, of fresh entropy for None, of one draw of a Generator.
    workers : int or None
        Processes (1: in this process; None: one per CPU).  The result does
        not depend on it.
    progress : callable, optional
        Wraps the iterator of finished aggregates (e.g. a tqdm bar).

    Returns
    -------
    Calibration

    Raises
    ------
    ParameterError
        Naming ``exponents``, ``primitive``, ``primaries``, ``repeats``, ``workers`` or ``rng`` for a value
        out of range.

    Examples
    --------
    >>> c = calibrate("cube", 30, exponents=[0.5, 20.0], repeats=3, rng=1)
    >>> c.exponent.tolist(), bool(c.D_A_mean[0] > c.D_A_mean[1])
    ([0.5, 20.0], True)
    """
    from .aggregation import Params

    exps = np.asarray([float(e) for e in exponents], dtype=np.float64)
    if len(exps) == 0:
        raise ParameterError("exponents", "must hold at least one value")
    for e in exps:
        Params(primitive=primitive, exponent=float(e), primaries=primaries)  # validates every value
    if int(repeats) != repeats or repeats < 1:
        raise ParameterError("repeats", f"must be a whole number >= 1, got {repeats!r}")
    try:
        root = seed_sequence(rng)
    except ValueError:
        raise ParameterError("rng", f"must be None, a non-negative int seed, a numpy SeedSequence or a numpy "
                                    f"Generator, got {rng!r}") from None
    seed = int(root.entropy) if not root.spawn_key and isinstance(root.entropy, (int, np.integer)) else None
    repeats = int(repeats)
    children = root.spawn(len(exps) * repeats)
    tasks = [(primitive, int(primaries), float(exps[k // repeats]), children[k]) for k in range(len(children))]
    if workers is None:
        from ...runtime.workers import default_workers

        workers = default_workers()
    if workers < 1:
        raise ParameterError("workers", f"must be >= 1, got {workers!r}")
    if workers == 1 or len(tasks) == 1:
        pool_or_none = contextlib.nullcontext()
    else:
        from ...runtime.workers import process_pool

        pool_or_none = process_pool(workers, ["grainforge.methods.dpa.calibration", "grainforge.methods.dpa",
                                              "trimesh"])
    with pool_or_none as pool:  # an error, Ctrl-C or SIGTERM: the pool's exit stops the workers now
        results: Iterable = (map(_measure, tasks) if pool is None
                             else pool.map(_measure, tasks, chunksize=max(1, len(tasks) // (8 * workers))))
        if progress is not None:
            results = progress(results)
        values = np.array(list(results), dtype=np.float64).reshape(len(exps), repeats, 4)

    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows (N = 1: D_A undefined) stay NaN
        mean = np.nanmean(values, axis=1)
        std = np.nanstd(values, axis=1)
    (dm, pm, rm, sm), (ds, ps, rs, ss) = mean.T, std.T
    return Calibration(
        primitive=primitive, primaries=int(primaries), repeats=repeats, seed=seed, exponent=exps,
        D_A_mean=dm, D_A_std=ds, porosity_mean=pm, porosity_std=ps, R_g_mean=rm, R_g_std=rs,
        D_A_scaling_mean=sm, D_A_scaling_std=ss,
    )


def _cache_path(primitive: str, primaries: int, exponents, repeats: int, seed: int) -> Path:
    key = repr((ALGORITHM_VERSION, [float(e) for e in exponents], int(repeats), int(seed)))
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return cache_dir() / "calibration" / f"dpa-{primitive}-N{int(primaries)}-{digest}.csv"


def cached_calibration(
    primitive: str,
    primaries: int,
    *,
    exponents: Sequence[float] | None = None,
    repeats: int | None = None,
    rng: RNGLike = 0,
    workers: int | None = None,
    progress: Callable[[Iterable], Iterable] | None = None,
) -> Calibration:
    """The calibration for (primitive, N, grid), read from the cache or computed and stored.

    ``exponents`` and ``repeats`` default to :data:`DEFAULT_EXPONENTS` and
    :data:`DEFAULT_REPEATS`.  The cache key is the primitive, N, the ε grid,
    the repeats, the root seed and :data:`ALGORITHM_VERSION`; a damaged cache
    file is recomputed.  An ``rng`` that is no int seed (None, a Generator, a
    SeedSequence) has no key: the curve is computed and not stored.

    Parameters
    ----------
    primitive : str
        One of :data:`grainforge.methods.dpa.PRIMITIVES`.
    primaries : int
        N.
    exponents : sequence of float, optional
        The ε grid (default :data:`DEFAULT_EXPONENTS`).
    repeats : int, optional
        Aggregates per ε (default :data:`DEFAULT_REPEATS`).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, default 0
        As for :func:`calibrate`; only an int seed is cached.
    workers : int or None, optional
        Processes when computing (None: one per CPU).
    progress : callable, optional
        Wraps the iterator of finished aggregates.

    Returns
    -------
    Calibration
    """
    exponents = DEFAULT_EXPONENTS if exponents is None else exponents
    repeats = DEFAULT_REPEATS if repeats is None else repeats
    if isinstance(rng, bool) or not isinstance(rng, (int, np.integer)):
        return calibrate(primitive, primaries, exponents=exponents, repeats=repeats, rng=rng, workers=workers,
                         progress=progress)
    seed = int(rng)
    path = _cache_path(primitive, primaries, exponents, repeats, seed)
    if path.exists():
        try:
            return Calibration.read_csv(path)
        except (ValueError, KeyError, OSError):
            pass
    cal = calibrate(primitive, primaries, exponents=exponents, repeats=repeats, rng=seed, workers=workers,
                    progress=progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    cal.write_csv(path)
    return cal


def exponent_for_dimension(
    target: float,
    *,
    primitive: str = "cube",
    primaries: int = 200,
    progress: Callable[[Iterable], Iterable] | None = None,
) -> float:
    """ε expected to give mean D_A = ``target`` for this primitive and N (cached calibration).

    Parameters
    ----------
    target : float
        Mean aggregate fractal dimension D_A wanted.
    primitive : str, default "cube"
        One of :data:`grainforge.methods.dpa.PRIMITIVES`.
    primaries : int, default 200
        N.
    progress : callable, optional
        Wraps the iterator of finished aggregates when the curve is computed (first use).

    Returns
    -------
    float
        ε, interpolated on the cached curve (:func:`cached_calibration`, default grid and seed).

    Raises
    ------
    ParameterError
        If ``target`` is outside the calibrated range (the message gives it).
    """
    from .aggregation import Params

    Params(primitive=primitive, exponent=1.0, primaries=primaries, target_fractal_dimension=target)
    cal = cached_calibration(primitive, primaries, progress=progress)
    return cal.exponent_for(target)
