"""Fit a generated population to a real sand, grain by grain (docs/design/algorithms.md §8, docs/fit.md).

A *sand* is a table of per-grain measurements in the Sand Atlas format
(:func:`read_sand`): equivalent diameter, true sphericity, convexity,
flatness and elongation, measured on μCT voxel images of a known voxel size.
:func:`fit_sand` makes every generated grain the **twin** of one sand grain:
it has that grain's equivalent diameter, and generator settings chosen so
that, measured the same way (:func:`grainforge.analysis.atlas.atlas_descriptors`
at the same voxel size relative to its size), it has that grain's four
descriptors.  The population so inherits the sand's joint distribution —
its marginals, the correlations between descriptors and between size and
shape — instead of matching four marginals made of independent draws.

How
---
1. **Design** (:func:`design`): a few hundred grains of the method, their
   per-grain settings (surface knobs and the aspect's Zingg ratios) and
   resolution spread over the method's whole range (a Sobol design), each
   generated and measured once; cached on disk per method, convention and
   resolution range (:func:`design_path`), so a second fit of any sand
   measures none.
2. **Inverse model** (:mod:`grainforge.fit.twins`): a cubic least-squares model
   from settings and log(voxels across) to the four descriptors, solved,
   bounded, per sand grain for the settings it predicts to measure like it.
3. **Twins**: grain ``i`` of the recipe (its own seed, as ``batch`` makes it)
   gets its sand grain's size and the model's settings, and is measured.
4. **The sand's mean settings** (:func:`population_settings`): from the
   means of its descriptors, with standard errors — what a sand's scan says
   about the settings even where one grain's descriptors cannot (the seed's
   share averages out over the grains).
5. **Refinement**: a twin more than :data:`REFINE_TOL` off on any descriptor
   gets new settings from the model plus its own offset (measured minus
   predicted: what its seed and orientation add) and is measured again, up
   to ``refine`` times; each grain keeps its closest twin.
6. **Reseeding** (:func:`_reseed`): a twin still more than :data:`TWIN_TOL`
   off tries up to ``reseed`` other seeds (:func:`reseed_seed`), written to
   the recipe's ``[grains] seed`` when one comes closer.

The fit **passes** when, on the population: each descriptor's two-sample KS
statistic ≤ :data:`KS_MAX` and mean within :data:`MEAN_TOL`; each of the six
pairwise Spearman correlations within :data:`CORR_TOL` of the sand's; and at
least :data:`TWIN_SHARE` of the grains the method can reach (the model's
closest setting predicts a twin within :data:`TWIN_TOL`) have a twin within
:data:`TWIN_TOL` on every descriptor (:func:`compare`).

Resolution: generated grains are measured at min(voxels across,
``max_across``), by default the method's own cap (:attr:`MethodFit.max_across`:
:data:`MAX_VOXELS_ACROSS` where its grains' descriptors have converged with
resolution, none for ``fso``, whose fractal surface does not converge;
``benchmarks/fit_resolution.py``); the sand's own numbers are never rescaled.

Adding a method is a few lines: :func:`register` a :class:`MethodFit` that
names its per-grain settings and their ranges and turns them into a grain's
parameters.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.atlas import OPENING_RADIUS

__all__ = [
    "DESCRIPTORS", "COLUMNS", "Sand", "read_sand", "Setting", "MethodFit", "FITS", "register", "fit_sand",
    "compare", "recipe_text", "twin_recipe_text", "FitResult", "write_outputs", "KS_MAX", "MEAN_TOL", "CORR_TOL",
    "TWIN_TOL", "TWIN_SHARE", "check_sand", "fit_grains", "check_fit_size", "grain_seconds", "MIN_GRAINS", "VOXELS_ACROSS",
    "SPHERICITY_MAX", "MAX_VOXELS_ACROSS", "METHOD_CAP", "resolve_cap", "design", "design_path", "measure_grain",
    "OUTPUTS", "setting_identifiability", "population_settings", "Population", "OPENING_COLUMN", "OPENING_RADIUS",
    "write_sand", "SAND_HEADER",
    "uses_opening",
]

#: the four descriptors that are matched
DESCRIPTORS = ("sphericity", "convexity", "flatness", "elongation")
#: Sand Atlas column of each quantity (units in the header; lengths in µm)
COLUMNS = {
    "equivalent_diameter": "Equivalent Diameter (µm)",
    "sphericity": "True Sphericity (-)",
    "convexity": "Convexity (-)",
    "flatness": "Flatness (-)",
    "elongation": "Elongation (-)",
}
#: optional column giving the voxel size (µm) of each grain's scan
VOXEL_COLUMN = "Voxel Size (µm)"
#: optional column, not the Sand Atlas's: each grain's opening fraction at a ball of OPENING_RADIUS times its
#: d_eq (:func:`grainforge.analysis.atlas.opening_fraction`, on the grain's voxel image; ``grainforge analyse
#: --voxel-size-mm H --atlas-csv FILE`` writes it for mesh files).  Where a table has it,
#: the estimate of the sand's mean settings uses it as a fifth descriptor (:func:`population_settings`): it
#: responds to edge rounding far more than to a grain's seed (docs/fit.md, "What a scan's images add")
OPENING_COLUMN = "Opening Fraction (-)"
#: with the opening fraction the estimate's rounds are more and shorter: its response to edge rounding saturates
#: (it hardly moves once the edges are rounder than the ball), so slopes measured at the twins' starting
#: population are too flat; each round's step is held to OPENING_TRUST of the unit box and the slopes are
#: updated from how the means moved (docs/fit.md, "What a scan's images add")
OPENING_ROUNDS = 4
OPENING_TRUST = 0.1
#: the slopes are updated from a round's move only where some setting's mean moved this much (unit box)
OPENING_SECANT_MIN = 0.02
#: acceptance: two-sample KS statistic and |mean difference| per descriptor
KS_MAX = 0.1
MEAN_TOL = 0.01
#: acceptance: |Spearman correlation difference| for each pair of descriptors
CORR_TOL = 0.1
#: acceptance: a twin is within this of its sand grain on every descriptor, for this share of reachable grains
TWIN_TOL = 0.03
TWIN_SHARE = 0.9
#: a twin further than this from its sand grain on any descriptor, or than REFINE_SD of the sand's sd of
#: that descriptor, is refined (tighter than TWIN_TOL: the population's means and rank correlations need
#: twins that are close on the scale of the sand's own spread, not just inside the tolerance)
REFINE_TOL = 0.012
REFINE_SD = 0.3
#: extra tries, after the refinement, for a twin the generator refused to make at every settings tried so far
#: (each moves its settings a third of the way towards the middle of the design box)
REFUSED_TRIES = 6
#: twins still off by more than TWIN_TOL after the refinement try up to this many other seeds (``--reseed``)
RESEED = 6
#: the population estimate of the sand's mean settings remakes the first this many twins, this many rounds
POPULATION_GRAINS = 300
POPULATION_ROUNDS = 2
#: the slopes the population estimate steps through: "measured" on the grains, the design "model"'s, or "auto":
#: measured from SLOPES_MEASURED_FROM grains remade per round (where the means' noise falls below what the
#: model's slopes leave of the gap), the model's below
POPULATION_SLOPES = "auto"
SLOPE_CHOICES = ("auto", "measured", "model")
SLOPES_MEASURED_FROM = 1000
#: with measured slopes (``slopes="measured"``), this many of the population's grains are each remade with one
#: unit-box setting raised and lowered by SLOPE_STEP under their own seed
SLOPE_GRAINS = 300
SLOPE_STEP = 0.05
#: how much wider the sand's spread of a setting its grains' descriptors do not determine may be than the made
#: population's: the estimate's sensitivity to that is measured (SLOPE_GRAINS grains remade with the setting's
#: spread this much wider) and stated beside its standard error.  0.4: on the synthetic angular sand the shrunk
#: twins' spread of dent depth is 40 % off the known one (docs/fit.md, "The spread of the settings")
SPREAD_DOUBT = 0.4
#: the share of twins expected to be reseeded, and the most counted, for the up-front estimate
RESEED_SHARE = 0.05
RESEED_MOST = 0.5
#: largest true sphericity accepted: measured on voxels it can exceed 1 a little (Ottawa's largest is 1.02)
SPHERICITY_MAX = 1.2
#: fewest grains a sand must have to be fitted: two samples of 50 grains of one sand already differ by a
#: KS statistic of about 0.17 (0.87·√(2/50)), beyond the 0.1 criterion; fewer grains say too little
MIN_GRAINS = 50
#: range of grain sizes, in voxels across (d_eq / voxel size), the fit measures: fewer than 5 voxels across
#: describe no shape; at 1,000 one grain's voxel image holds 10⁹ voxels
VOXELS_ACROSS = (5.0, 1000.0)
#: generated grains of rf, cri and angular are measured at most this many voxels across: their descriptors have
#: converged there (within 0.005 of 300 voxels across; docs/fit.md, benchmarks/fit_resolution.py)
MAX_VOXELS_ACROSS = 150.0
#: ``max_across`` of :func:`fit_sand` and :func:`check_fit_size` meaning "the method's own cap"
METHOD_CAP = "method"
#: grains of a method's design, and the smallest resolution it spans (voxels across)
DESIGN_GRAINS = 400
DESIGN_ACROSS_LOW = 10.0
#: root seed of every design (designs do not depend on the sand or the fit's seed); bump DESIGN_VERSION
#: when a generator or the measurement changes, so that cached designs are not reused
DESIGN_SEED = 20261202
DESIGN_VERSION = 1
#: per-grain cost of a fit (s, one core): a fixed part, making the grain (:data:`FIT_MAKE_SECONDS`, the
#: method's), and voxelising and measuring it, which grows with the cube of the voxels across (0.05 s at
#: Ottawa's 69; docs/benchmarks.md, ``benchmarks/bench_estimates.py``)
FIT_GRAIN_SECONDS, FIT_VOXEL_SECONDS, FIT_ACROSS_REF = 0.085, 0.05, 69.0
#: CPU seconds to make one grain of each fitted method at its fit resolution (subdivisions 5; median of 5
#: seeds, ``benchmarks/bench_estimates.py``): a seamless FSO grain is ten times an rf grain, which made the
#: estimate of an FSO fit about half its time when one figure stood for every method
FIT_MAKE_SECONDS = {"rf": 0.015, "cri": 0.077, "fso": 0.159, "angular": 0.048}
#: measurements per twin the estimate expects (the first, and the refinements of the twins that miss;
#: the Ottawa rf fit measured 3.17 per twin, docs/fit.md)
EXPECTED_MEASUREMENTS = 3.2
#: memory of one grain's measurement, per cubed voxel across (bytes; 330 MB at 250 across, for an elongated
#: grain's larger box a factor 2 more)
FIT_VOXEL_BYTES = 48.0
#: memory the fit keeps per grain measured (its cached row)
FIT_ROW_BYTES = 300.0
#: a fit estimated beyond this is refused up front (``--max-minutes``)
MAX_MINUTES = 60.0


# --------------------------------------------------------------------------- the sand
@dataclass(frozen=True)
class Sand:
    """Per-grain measurements of a sand (lengths in µm)."""

    name: str
    voxel_size: float  # µm
    equivalent_diameter: np.ndarray
    values: Mapping[str, np.ndarray]  # descriptor -> (n,)
    opening: np.ndarray | None = None  # (n,) the OPENING_COLUMN, where the table has it

    @property
    def count(self) -> int:
        return len(self.equivalent_diameter)

    def table(self) -> np.ndarray:
        """(n, 4) array of :data:`DESCRIPTORS`."""
        return np.column_stack([self.values[k] for k in DESCRIPTORS])


def _norm(header: str) -> str:
    return " ".join(header.replace("\u03bc", "\u00b5").replace("\ufeff", "").split()).lower()


#: the first bytes of files a sand table is sometimes mistaken for, and what they are
_MAGIC = ((b"\x89PNG", "a PNG image"), (b"\x1f\x8b", "gzip-compressed (gunzip it first)"),
          (b"PK\x03\x04", "a ZIP archive (an .xlsx workbook? save the sheet as CSV)"), (b"%PDF", "a PDF"),
          (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"))


def _sand_text(path: Path) -> str:
    """The file's text as UTF-8, or one line saying what the file is and how to make it a table."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    for magic, what in _MAGIC:
        if data.startswith(magic):
            raise ValueError(f"{path}: not a CSV table: the file is {what}")
    if b"\x00" in data[:4096]:
        raise ValueError(f"{path}: not a CSV table: the file holds binary data (NUL bytes)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        byte = data[exc.start]
        guess = data[exc.start:exc.start + 1].decode("latin-1")
        raise ValueError(f"{path}: not UTF-8 text (byte 0x{byte:02x} at offset {exc.start}, {guess!r} in Latin-1 "
                         "or Windows-1252): save the table as UTF-8") from None


def _check_separator(path: Path, header: Sequence[str]) -> None:
    """A header read as one or two columns that holds ';' or a tab: another separator, named."""
    if len(header) <= 2:
        joined = ",".join(header)
        for sep, name in ((";", "semicolons"), ("\t", "tabs")):
            if joined.count(sep) >= 2:
                raise ValueError(f"{path}: the columns are separated by {name}; a Sand Atlas CSV is "
                                 "comma-separated: save it with commas (and '.' as the decimal mark)")


def _same_but_unit(header: Sequence[str], col: str) -> list[str]:
    """Header names that match ``col`` but for its unit (or its case and spacing)."""
    bare = _norm(col.split(" (")[0])
    return [h for h in header if _norm(h).split(" (")[0] == bare]


def _near_misses(header: Sequence[str], missing: Sequence[str]) -> str:
    """``'; found ...'`` for header names that match a missing column but for its unit or case."""
    found = [repr(h) for want in missing for h in _same_but_unit(header, want)]
    return f"; found {', '.join(found)} (the name must carry the unit as written)" if found else ""


def _check_unit_less(path: Path, header: Sequence[str], optional: Sequence[str]) -> None:
    """An optional column named without its unit would be ignored without a word: name it instead."""
    names = {_norm(h) for h in header}
    for col in optional:
        near = [] if _norm(col) in names else _same_but_unit(header, col)
        if near:
            raise ValueError(f"{path}: column {near[0]!r} is not read: name it {col!r} (with its unit) or drop it")


def _check_ids_and_volumes(path: Path, rows: Sequence[Sequence[str]], header: Mapping[str, int]) -> None:
    """Duplicate particle IDs and volumes that are not positive numbers are named (the fit reads neither)."""
    i = header.get(_norm("Particle ID"))
    if i is not None:
        seen: dict[str, int] = {}
        for line, row in enumerate(rows[1:], start=2):
            key = row[i].strip() if i < len(row) else ""
            if key and key in seen:
                raise ValueError(f"{path}: line {line}: Particle ID {key!r} appears again (first on line "
                                 f"{seen[key]}): one row per grain")
            seen[key] = line
    j = next((k for h, k in header.items() if h.startswith("volume")), None)
    if j is not None:
        for line, row in enumerate(rows[1:], start=2):
            cell = row[j].strip() if j < len(row) else ""
            try:
                ok = float(cell) > 0 and math.isfinite(float(cell))
            except ValueError:
                ok = False
            if not ok:
                raise ValueError(f"{path}: line {line}, column {rows[0][j]!r}: a grain's volume must be a positive "
                                 f"number, got {cell!r}")


def read_sand(path: str | os.PathLike, voxel_size: float | None = None) -> Sand:
    """Read a Sand Atlas CSV (one row per grain; columns as in :data:`COLUMNS`).

    Parameters
    ----------
    path : path
    voxel_size : float, optional
        Voxel size of the scan (µm); required unless the file has a
        ``Voxel Size (µm)`` column (then its median is used).

    Raises
    ------
    ValueError
        One line naming the file and the problem: unreadable, not UTF-8 text
        (the byte and its Latin-1 reading), another kind of file (an image,
        a gzip or ZIP archive), another separator (semicolons, tabs), empty,
        missing columns (naming a column that matches but for its unit), an
        optional column named without its unit, a repeated Particle ID, a
        volume or value that is not a positive finite number, no voxel size,
        or a ``voxel_size`` that contradicts the file's voxel-size column.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = p.write_text("Equivalent Diameter (µm),True Sphericity (-),Convexity (-),Flatness (-),Elongation (-)\\n"
    ...                  "500,0.9,0.95,0.8,0.7\\n", encoding="utf-8")
    >>> s = read_sand(p, voxel_size=7.3)
    >>> s.count, float(s.values["flatness"][0]), round(float(s.equivalent_diameter[0] / s.voxel_size), 1)
    (1, 0.8, 68.5)
    """
    path = Path(path)
    text = _sand_text(path)
    rows = list(csv.reader(text.splitlines()))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{path}: empty file (expected a Sand Atlas CSV with a header row)")
    _check_separator(path, rows[0])
    header = {_norm(h): i for i, h in enumerate(rows[0])}
    want = dict(COLUMNS)
    missing = [c for c in want.values() if _norm(c) not in header]
    if missing:
        raise ValueError(f"{path}: not a Sand Atlas CSV: missing column(s) {', '.join(repr(c) for c in missing)}"
                         + _near_misses(rows[0], missing))
    _check_unit_less(path, rows[0], (VOXEL_COLUMN, OPENING_COLUMN))
    if len(rows) < 2:
        raise ValueError(f"{path}: no grains (only a header row)")
    if _norm(VOXEL_COLUMN) in header:
        want["voxel_size"] = VOXEL_COLUMN
    if _norm(OPENING_COLUMN) in header:
        want["opening"] = OPENING_COLUMN
    data: dict[str, list[float]] = {k: [] for k in want}
    for line, row in enumerate(rows[1:], start=2):
        for key, col in want.items():
            i = header[_norm(col)]
            cell = row[i].strip() if i < len(row) else ""
            try:
                x = float(cell)
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {col!r}: not a number: {cell!r}") from None
            unit = key in (*DESCRIPTORS, "opening")  # a ratio: at most 1
            high = SPHERICITY_MAX if key == "sphericity" else 1 + 1e-6 if unit else math.inf
            if not (math.isfinite(x) and (0 <= x if key == "opening" else 0 < x) and x <= high):
                limit = f" (at most {SPHERICITY_MAX:g})" if key == "sphericity" else " (at most 1)" if unit else ""
                raise ValueError(f"{path}: line {line}, column {col!r}: out of range{limit}: {cell!r}")
            data[key].append(x)
    _check_ids_and_volumes(path, rows, header)
    if voxel_size is None:
        if "voxel_size" not in data:
            raise ValueError(f"{path}: no {VOXEL_COLUMN!r} column: give the scan's voxel size (--voxel-size-um)")
        voxel_size = float(np.median(data["voxel_size"]))
    elif "voxel_size" in data:
        column = np.asarray(data["voxel_size"])
        if not np.allclose(column, voxel_size, rtol=1e-6, atol=0):
            raise ValueError(f"{path}: the voxel size given ({voxel_size:g} µm) differs from the file's "
                             f"{VOXEL_COLUMN!r} column ({np.median(column):g} µm): give one of them (drop "
                             "--voxel-size-um to use the column)")
    if not (math.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"{path}: the voxel size must be a positive number of µm, got {voxel_size!r}")
    across = np.asarray(data["equivalent_diameter"]) / voxel_size
    lo, hi = VOXELS_ACROSS
    if not (np.all(np.isfinite(across)) and across.min() >= lo and across.max() <= hi):
        raise ValueError(f"{path}: at a voxel size of {voxel_size:g} µm its grains are {across.min():.3g} to "
                         f"{across.max():.3g} voxels across; the fit measures grains {lo:g} to {hi:g} voxels "
                         "across (is the voxel size in µm?)")
    return Sand(name=path.name, voxel_size=float(voxel_size),
                equivalent_diameter=np.asarray(data["equivalent_diameter"]),
                values={k: np.asarray(data[k]) for k in DESCRIPTORS},
                opening=np.asarray(data["opening"]) if "opening" in data else None)


#: the columns :func:`write_sand` writes, in order (the Sand Atlas's, then the voxel size)
SAND_HEADER = ("Particle ID", "Volume (µm³)", COLUMNS["equivalent_diameter"], *(COLUMNS[k] for k in DESCRIPTORS),
               VOXEL_COLUMN)


def write_sand(path: str | os.PathLike, equivalent_diameter: Sequence[float], values: Mapping[str, Sequence[float]],
               voxel_size: float | Sequence[float], opening: Sequence[float] | None = None) -> Path:
    """Write grains' measurements as a Sand Atlas CSV that :func:`read_sand` reads (atomically).

    Columns :data:`SAND_HEADER` (particle IDs from 1, the volume of a ball of each d_eq, lengths in µm,
    values to 6 significant digits), and :data:`OPENING_COLUMN` where ``opening`` is given.

    Parameters
    ----------
    path : path
    equivalent_diameter : (n,) array_like
        µm.
    values : mapping
        Each of :data:`DESCRIPTORS` to its (n,) values.
    voxel_size : float or (n,) array_like
        µm, per grain or for all.
    opening : (n,) array_like, optional
        Each grain's opening fraction (:func:`grainforge.analysis.atlas.opening_fraction`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = write_sand(p, [500.0], {k: [0.8] for k in DESCRIPTORS}, 7.3, opening=[0.99])
    >>> s = read_sand(p)
    >>> s.count, s.voxel_size, float(s.opening[0])
    (1, 7.3, 0.99)
    """
    from ..io import atomic_write

    d = np.asarray(equivalent_diameter, dtype=np.float64)
    cols = [np.arange(1, len(d) + 1), math.pi / 6 * d**3, d, *(np.asarray(values[k], np.float64) for k in DESCRIPTORS),
            np.broadcast_to(np.asarray(voxel_size, np.float64), d.shape)]
    header = list(SAND_HEADER)
    if opening is not None:
        cols.append(np.asarray(opening, np.float64))
        header.append(OPENING_COLUMN)
    if any(len(c) != len(d) for c in cols):
        raise ValueError("every column needs one value per grain")
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\r\n")
    w.writerow(header)
    w.writerows([[int(r[0]), *(f"{float(x):.6g}" for x in r[1:])] for r in zip(*cols)])
    return atomic_write(path, out.getvalue())


def check_sand(sand: Sand) -> None:
    """Refuse a sand that cannot be fitted: fewer than :data:`MIN_GRAINS` grains, or a column without spread.

    A fit matches distributions; identical grains (every value of a column
    the same) have none to match, and their single size makes no grading.

    Raises
    ------
    ValueError
        One line naming the sand and the problem.

    Examples
    --------
    >>> one = np.full(60, 0.8)
    >>> s = Sand("s.csv", 7.3, np.linspace(300, 500, 60), {k: one for k in DESCRIPTORS})
    >>> check_sand(s)
    Traceback (most recent call last):
    ...
    ValueError: s.csv: every grain has the same sphericity (0.8): a fit needs a spread of sizes and shapes to match
    """
    if sand.count < MIN_GRAINS:
        raise ValueError(f"{sand.name}: {sand.count} grain(s); a fit needs at least {MIN_GRAINS} "
                         "(fewer grains say too little about the sand's distributions)")
    opening = [] if sand.opening is None else [("opening fraction", sand.opening)]
    for key, col in [("equivalent diameter", sand.equivalent_diameter)] + [(k, sand.values[k]) for k in DESCRIPTORS] \
            + opening:
        if float(np.ptp(col)) <= 1e-9 * float(np.max(np.abs(col))):
            raise ValueError(f"{sand.name}: every grain has the same {key} ({float(col[0]):g}): a fit needs a "
                             "spread of sizes and shapes to match")




# --------------------------------------------------------------------------- per-method settings
@dataclass(frozen=True)
class Setting:
    """One per-grain setting the inverse model solves for, with the range the design spans."""

    name: str
    low: float
    high: float


#: the aspect's Zingg ratios, a per-grain setting of every method (measured flatness and elongation follow
#: them closely, the surface shifts them a little)
ASPECT_SETTINGS = (Setting("elongation", 0.25, 1.0), Setting("flatness", 0.25, 1.0))


@dataclass(frozen=True)
class MethodFit:
    """How to fit one generator grain by grain.

    Attributes
    ----------
    method : str
        Generator name (must have an ``aspect`` L:I:S parameter).
    settings : tuple of Setting
        Per-grain settings besides the aspect's (``elongation``, ``flatness``,
        appended by :attr:`all_settings`).
    fixed : dict
        The recipe's ``[params]``: what every grain shares.
    params : callable
        Setting values (dict, the aspect's included) -> the grain's own
        parameters (the recipe's ``[grains]`` columns), ``aspect`` included.
    max_across : float or None
        The method's resolution cap: its grains are measured at most this
        many voxels across, where their descriptors have converged with
        resolution (``benchmarks/fit_resolution.py``); None: they do not
        converge, so they are measured at the sand's resolution.
    """

    method: str
    settings: tuple[Setting, ...]
    fixed: Mapping[str, Any]
    params: Callable[[Mapping[str, float]], dict]
    max_across: float | None = MAX_VOXELS_ACROSS

    @property
    def all_settings(self) -> tuple[Setting, ...]:
        return self.settings + ASPECT_SETTINGS

    @property
    def spread_step(self) -> bool:
        """Whether a population estimate measures its sensitivity to the settings' spread: only where the four
        descriptor means can determine every setting (rf's five they cannot: its surface settings' means are the
        starting population's along what the means do not see, spread and all), so that its cost is known up
        front (:func:`fit_grains`, :func:`population_settings`)."""
        return len(self.all_settings) <= len(DESCRIPTORS)

    def values(self, u: np.ndarray) -> dict[str, float]:
        """Unit-box coordinates ``u`` (one per :attr:`all_settings`) -> setting values."""
        return {s.name: float(s.low + float(x) * (s.high - s.low)) for s, x in zip(self.all_settings, u)}

    def grain_params(self, u: np.ndarray) -> dict:
        """The grain's own parameters for unit-box coordinates ``u``, rounded as the recipe writes them."""
        return _written(self.params(self.values(u)))


#: method name -> its :class:`MethodFit` (``fit --method``)
FITS: dict[str, MethodFit] = {}


def register(spec: MethodFit) -> MethodFit:
    """Make ``spec`` available to :func:`fit_sand` (replaces an earlier one of the same method)."""
    FITS[spec.method] = spec
    return spec


def _aspect(v: Mapping[str, float]) -> list[float]:
    return [1.0, v["elongation"], v["elongation"] * v["flatness"]]


def _descriptor_params(v: Mapping[str, float]) -> dict:
    # D2 = 0: the aspect alone sets the form (a per-grain D2 deforms it at random, which the measured
    # flatness and elongation then follow only loosely); D3 (irregularity) and D8 (roughness) per grain
    return {"descriptors": [0.0, v["irregularity"], v["roughness"]], "aspect": _aspect(v)}


_DESCRIPTOR_SETTINGS = (Setting("irregularity", 0.0, 0.25), Setting("roughness", 0.0, 0.04))
#: rf's irregularity decay B1 (every grain: the generator's default); its roughness decay B2 is a per-grain
#: setting: a flatter roughness spectrum (B2 towards 0) puts the roughness into finer surface detail, which
#: lowers sphericity (surface area) far more than convexity, so B2 trades sphericity at a fixed convexity and
#: aspect (docs/fit.md), which D3 and D8 alone cannot
RF_DECAY_B1 = -5.0 / 3.0


def _rf_params(v: Mapping[str, float]) -> dict:
    return {**_descriptor_params(v), "decay": [RF_DECAY_B1, v["roughness_decay"]]}


register(MethodFit("rf", _DESCRIPTOR_SETTINGS + (Setting("roughness_decay", -2.5, 0.0),), {"subdivisions": 5},
                   _rf_params))
register(MethodFit("cri", _DESCRIPTOR_SETTINGS, {"subdivisions": 5}, _descriptor_params))
register(MethodFit(
    "fso", (Setting("amplitude", 0.0, 0.15), Setting("fractal_dimension", 2.0, 2.8)),
    {"surface": "seamless", "subdivisions": 5},
    lambda v: {"amplitude": v["amplitude"], "fractal_dimension": v["fractal_dimension"], "aspect": _aspect(v)},
    # no cap: the FSO overlay's fractal surface keeps gaining area as the voxels resolve it (sphericity 0.044
    # lower at 300 voxels across than at 150, still 0.009 lower than at 250; docs/fit.md), so fso grains are
    # measured at the sand's resolution
    max_across=None,
))
register(MethodFit(
    # crushed, angular grains (Hostun-like): a 7-facet core, so that sphericity falls well below convexity as it
    # does in crushed sands; edge rounding steers sphericity, dent depth convexity (6 dents of width 0.5 rad);
    # a fine texture (FSO overlay of RMS 0.02); the grain stretched to its aspect's inertia ellipsoid, so that
    # its measured flatness and elongation are its settings' (with facets tangent to the aspect's ellipsoid, a
    # 7-facet core's own random shape sets them: at fixed settings they scatter by sd 0.1 from seed to seed)
    "angular", (Setting("rounding", 0.0, 0.9), Setting("dent_depth", 0.0, 0.7)),
    {"facets": 7, "dents": 6, "dent_width": 0.5, "roughness": 0.02, "length_ratio": 2.0, "subdivisions": 5,
     "aspect_by": "inertia"},
    lambda v: {"rounding": v["rounding"], "dent_depth": v["dent_depth"], "aspect": _aspect(v)},
))


def _written(v: Any) -> Any:
    """``v`` as the recipe writes it (floats to 6 significant digits, :func:`_toml`): what ``batch`` reads back."""
    if isinstance(v, float):
        return float(f"{v:.6g}")
    if isinstance(v, (list, tuple)):
        return [_written(x) for x in v]
    if isinstance(v, dict):
        return {k: _written(x) for k, x in v.items()}
    return v


# --------------------------------------------------------------------------- estimate
def fit_grains(method: str, *, count: int, design_grains: int, refine: int, reseed: int = 0,
               population_grains: int = POPULATION_GRAINS, population_slopes: str = POPULATION_SLOPES,
               cached: Callable[[str], bool] = lambda m: False, opening: bool = False) -> tuple[int, int]:
    """Grains a fit of ``method`` measures: (expected, at most).

    The design's grains (none when it is cached), the population estimate's
    (:data:`POPULATION_ROUNDS` × up to ``population_grains``, plus with
    measured slopes 2 × settings × up to :data:`SLOPE_GRAINS`: :func:`slopes_for`; plus, for its
    sensitivity to the spread, up to :data:`SLOPE_GRAINS` per setting besides the aspect where the
    four means can determine every setting, counted here for each although only those a grain's
    descriptors do not determine are remade; with ``opening``, the sand's opening fraction used
    (:func:`uses_opening`), the starting grains measured again, the slopes always measured and
    :data:`OPENING_ROUNDS` rounds), then each
    twin once, plus refinements: :data:`EXPECTED_MEASUREMENTS` per twin
    expected, ``1 + refine`` at most, plus two per reseeded twin and try
    (:data:`RESEED_SHARE` of the twins expected, :data:`RESEED_MOST` at most:
    the twins still off after the refinement; a third of them on a sand the
    method reaches only with other seeds).
    ``"auto"`` measures every method's design.

    Examples
    --------
    >>> fit_grains("rf", count=500, design_grains=400, refine=3)
    (2600, 3000)
    >>> fit_grains("rf", count=500, design_grains=400, refine=3, population_grains=500)
    (3000, 3400)
    >>> fit_grains("rf", count=500, design_grains=400, refine=3, population_slopes="measured")
    (5600, 6000)
    >>> fit_grains("angular", count=500, design_grains=400, refine=3)   # rounding's and dent depth's spread
    (3200, 3600)
    >>> fit_grains("angular", count=500, design_grains=400, refine=3, opening=True)   # + 300 + 2 × 4 × 300 + 2 × 300
    (6500, 6900)
    """
    methods = list(FITS) if method == "auto" else [method]
    designs = sum(0 if cached(m) else design_grains for m in methods)
    designs += (OPENING_ROUNDS if opening else POPULATION_ROUNDS) * min(count, population_grains)
    designs += max(len(FITS[m].settings) if FITS[m].spread_step else 0
                   for m in methods) * min(count, population_grains, SLOPE_GRAINS)
    if opening:
        designs += min(count, population_grains)
    if opening or slopes_for(population_slopes, min(count, population_grains)) == "measured":
        p = max(len(FITS[m].all_settings) for m in methods)  # the dearest method's settings (rf's five)
        designs += 2 * p * min(count, population_grains, SLOPE_GRAINS)
    expected = designs + int(round(count * (min(EXPECTED_MEASUREMENTS, 1 + refine) + 2 * reseed * RESEED_SHARE)))
    return expected, designs + count * (1 + refine) + int(round(count * 2 * reseed * RESEED_MOST))


def slopes_for(slopes: str, grains: int) -> str:
    """The slopes a population estimate of ``grains`` grains a round steps through: ``slopes`` itself, or for
    ``"auto"`` measured from :data:`SLOPES_MEASURED_FROM` grains, the design model's below.

    Examples
    --------
    >>> slopes_for("auto", 300), slopes_for("auto", 2000), slopes_for("measured", 300)
    ('model', 'measured', 'measured')
    """
    if slopes not in SLOPE_CHOICES:
        raise ValueError(f"slopes must be one of {', '.join(SLOPE_CHOICES)}, got {slopes!r}")
    if slopes == "auto":
        return "measured" if grains >= SLOPES_MEASURED_FROM else "model"
    return slopes


def resolve_cap(method: str, max_across: float | str | None) -> float | None:
    """The resolution cap a fit of ``method`` measures at: ``max_across`` itself, or with :data:`METHOD_CAP`
    the method's own (:attr:`MethodFit.max_across`); None: uncapped.

    Examples
    --------
    >>> resolve_cap("rf", METHOD_CAP), resolve_cap("fso", METHOD_CAP), resolve_cap("fso", 200.0)
    (150.0, None, 200.0)
    """
    if max_across == METHOD_CAP:
        return FITS[method].max_across
    return float(max_across) if max_across else None


def measured_across(sand: Sand, max_across: float | None) -> np.ndarray:
    """Voxels across each sand grain's twin is measured at: the sand's, capped at ``max_across``."""
    across = sand.equivalent_diameter / sand.voxel_size
    return np.minimum(across, max_across) if max_across else across


def uses_opening(sand: Sand, max_across: float | None) -> bool:
    """Whether a fit's mean-settings estimate uses the table's :data:`OPENING_COLUMN`: where it has one and no
    grain's twin is measured coarser than the sand grain (``max_across``), since the opening fraction, like
    true sphericity, depends on the voxels across and is compared at the sand's own resolution only."""
    return sand.opening is not None and not (max_across and bool(np.any(
        sand.equivalent_diameter / sand.voxel_size > max_across)))


def check_fit_size(sand: Sand, method: str, *, count: int, design_grains: int = DESIGN_GRAINS, refine: int = 4,
                   reseed: int = RESEED, population_grains: int = POPULATION_GRAINS,
                   population_slopes: str = POPULATION_SLOPES,
                   max_across: float | str | None = METHOD_CAP, workers: int = 1,
                   max_minutes: float = MAX_MINUTES, convention: str = "atlas",
                   cache: str | os.PathLike | None = None, cores: int | None = None) -> float:
    """Expected wall-clock seconds of a fit; refuse one over ``max_minutes``, a day or the machine's memory.

    ``workers`` processes share this machine's cores and memory; ``cores``
    (a Dask cluster's worker threads, each with its own memory) divides the
    time instead, and the memory is then checked for one worker.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        One line with the estimate and what to change.
    """
    from ..runtime.estimate import TooLargeError, check_job, check_memory, duration

    methods = list(FITS) if method == "auto" else [method]
    # per method (each has its own resolution cap): the design's top resolution, the twins' resolutions, and
    # the cost of one grain; "auto" is costed at its dearest method
    caps = {m: resolve_cap(m, max_across) for m in methods}
    highs = {m: _design_high(sand, caps[m]) for m in methods}
    acrosses = {m: measured_across(sand, caps[m]) for m in methods}
    costs = {m: grain_seconds(m, acrosses[m]) for m in methods}
    dear = max(methods, key=lambda m: costs[m])
    across, each, design_high, max_across = acrosses[dear], costs[dear], highs[dear], caps[dear]
    fresh = [m for m in methods if not design_path(m, convention, highs[m], design_grains, cache).exists()]
    expected, most = fit_grains(method, count=count, design_grains=design_grains, refine=refine, reseed=reseed,
                                population_grains=population_grains, population_slopes=population_slopes,
                                cached=lambda m: m not in fresh,
                                opening=any(uses_opening(sand, caps[m]) for m in methods))
    option = "--count" + (" or fit one --method" if method == "auto" else "")
    if cores is None:
        cores = max(1, min(int(workers), os.cpu_count() or 1))
    else:
        cores, workers = max(1, int(cores)), 1
    check_job(most, each, what=f"fit --method {method}, measuring up to {most} grains,", option=option, workers=cores)
    per_worker = FIT_VOXEL_BYTES * float(max(across.max(), design_high)) ** 3
    check_memory(per_worker * max(1, int(workers)) + FIT_ROW_BYTES * most,
                 what=f"fit --method {method} on {workers} worker(s), measuring grains {across.max():.0f} voxels "
                      "across,", option=f"{option}, --max-voxels-across or --workers")
    # the design's grains are spread log-uniformly from DESIGN_ACROSS_LOW to its top resolution: most are far
    # cheaper than the twins (the mean of across³ over that spread)
    design_seconds = sum(design_grains * (FIT_GRAIN_SECONDS + _make_seconds(m) + FIT_VOXEL_SECONDS
                                          * _log_uniform_cube_mean(DESIGN_ACROSS_LOW, highs[m]) / FIT_ACROSS_REF**3)
                         for m in fresh)
    seconds = ((expected - design_grains * len(fresh)) * each + design_seconds) / cores
    if seconds > 60 * max_minutes:
        cap = (f" or --max-voxels-across (now {max_across:g})" if max_across
               else f" or set --max-voxels-across (e.g. {MAX_VOXELS_ACROSS:g})")
        raise TooLargeError(
            f"fit --method {method} would take about {duration(seconds)} on {cores} core(s) (about {expected} "
            f"grains at {duration(each) if each >= 1 else f'{each * 1000:.2g} ms'} each, {across.mean():.0f} "
            f"voxels across), over --max-minutes {max_minutes:g}: raise --max-minutes, lower {option}{cap}")
    return seconds


def grain_seconds(method: str, across) -> float:
    """The estimate's CPU seconds for one grain of ``method`` measured at ``across`` voxels across (the mean over
    an array): :data:`FIT_GRAIN_SECONDS` + the method's :data:`FIT_MAKE_SECONDS` + :data:`FIT_VOXEL_SECONDS` ×
    (across / :data:`FIT_ACROSS_REF`)³. A method without a measured making time is costed at the dearest's.

    Examples
    --------
    >>> round(grain_seconds("rf", 69.0), 3), round(grain_seconds("fso", 69.0), 3)
    (0.15, 0.294)
    """
    return FIT_GRAIN_SECONDS + _make_seconds(method) + FIT_VOXEL_SECONDS * float(np.mean(
        (np.asarray(across, dtype=float) / FIT_ACROSS_REF) ** 3))


def _make_seconds(method: str) -> float:
    """:data:`FIT_MAKE_SECONDS` of ``method``; the dearest's for a method not measured."""
    return FIT_MAKE_SECONDS.get(method, max(FIT_MAKE_SECONDS.values()))


def _log_uniform_cube_mean(low: float, high: float) -> float:
    """The mean of a³ for a log-uniform on [low, high]: (high³ − low³) / (3 ln(high / low)).

    Examples
    --------
    >>> round(_log_uniform_cube_mean(10.0, 150.0) / 150.0**3, 3)
    0.123
    """
    if high <= low:
        return float(low) ** 3
    return (high**3 - low**3) / (3.0 * math.log(high / low))


# --------------------------------------------------------------------------- recipes
def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(float(f"{v:.6g}"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} to TOML")


#: percent passing at which the sand's size quantiles become the recipe's sieves (finer in the tails,
#: where a log-linear grading between few sieves would spread grains over sizes the sand barely has)
GRADING_PERCENTS = (0, 0.5, 1, 2, 3, 5, 7.5, *range(10, 95, 5), 92.5, 95, 97, 98, 99, 99.5, 100)


def grading(d_eq_um: np.ndarray, percents: Sequence[float] = GRADING_PERCENTS) -> tuple[list[float], list[float]]:
    """Sieves (mm) and count percent passing at the sizes' quantiles ``percents`` (duplicates dropped).

    Examples
    --------
    >>> grading(np.array([100.0, 200.0, 300.0, 400.0, 500.0]), (0, 50, 100))
    ([0.1, 0.3, 0.5], [0.0, 50.0, 100.0])
    """
    q = np.asarray(percents, dtype=np.float64)
    sieves = np.percentile(np.asarray(d_eq_um) / 1000.0, q)
    keep = np.r_[True, np.diff(sieves) > 1e-9 * sieves[-1]]
    sieves, q = sieves[keep], q[keep]
    q[-1] = 100.0
    return [float(f"{s:.6g}") for s in sieves], [float(x) for x in q]


def recipe_text(method: str, params: Mapping[str, Any], sand: Sand, *, count: int, seed: int,
                fmt: str = "stl", header: str = "") -> str:
    """A ``grainforge batch`` recipe: ``params`` and the sand's size distribution as a count grading."""
    sieves, passing = grading(sand.equivalent_diameter)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(method)}", f"count = {int(count)}", f"seed = {int(seed)}", f"format = {_toml(fmt)}",
              "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in params.items()]
    lines += ["", "[size]", 'definition = "equivalent"', f"sieves_mm = {_toml(sieves)}",
              f"percent_passing = {_toml(passing)}", 'basis = "count"', ""]
    return "\n".join(lines)



def twin_recipe_text(spec: MethodFit, grains: Sequence[Mapping[str, Any]], size_mm: Sequence[float], *,
                     seed: int, fmt: str = "stl", header: str = "", seeds: Sequence[int] | None = None) -> str:
    """A ``grainforge batch`` recipe of twins: ``spec.fixed`` in ``[params]``, each grain's own parameters and
    size in ``[grains]`` (one value per grain, in grain order), and each grain's seed when ``seeds`` is given
    and any differs from the one ``batch`` would give it (:func:`grain_seed`).

    Examples
    --------
    >>> from grainforge.population import draw_grain, parse_recipe
    >>> text = twin_recipe_text(FITS["rf"], [FITS["rf"].grain_params(np.full(5, 0.5))], [0.4], seed=1)
    >>> _, params, size = draw_grain(parse_recipe(text), 0)
    >>> params.descriptors, params.decay, params.aspect, size
    ((0.0, 0.125, 0.02), (-1.66667, -1.25), (1.0, 0.625, 0.390625), 0.4)
    """
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(spec.method)}", f"count = {len(grains)}", f"seed = {int(seed)}",
              f"format = {_toml(fmt)}", "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in spec.fixed.items()]
    lines += ["", "[size]", 'definition = "equivalent"', "",
              "[grains]  # one value per grain, in grain order: each the twin of one sand grain (fit.csv)",
              f"size_mm = {_toml([float(s) for s in size_mm])}"]
    for name in grains[0]:
        lines.append(f"{name} = {_toml([g[name] for g in grains])}")
    if seeds is not None and any(int(s) != grain_seed(seed, i) for i, s in enumerate(seeds)):
        lines.append(f"seed = [{', '.join(str(int(s)) for s in seeds)}]")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- measuring grains
@lru_cache(maxsize=8)
def _recipe(text: str):
    from ..population import parse_recipe

    return parse_recipe(text, source="<fit>")


def measure_grain(text: str, index: int, voxel_size_um: float, convention: str = "atlas",
                  max_across: float | None = None) -> tuple[float, ...]:
    """Grain ``index`` of recipe ``text`` as ``batch`` makes it, measured the Atlas way.

    It is voxelised at ``voxel_size_um`` relative to its drawn equivalent
    diameter (at most ``max_across`` voxels across), in a random orientation
    drawn from its own seed; ``convention`` is true sphericity's
    (:func:`grainforge.analysis.atlas.voxel_descriptors`).  Returns (d_eq µm,
    sphericity, convexity, flatness, elongation, CPU seconds spent).
    """
    import time

    cpu = time.process_time()
    from ..population import draw_grain

    recipe = _recipe(text)
    seed, params, size_mm = draw_grain(recipe, index)
    across = size_mm * 1000.0 / voxel_size_um
    d = _measure(recipe.method, params, seed, min(across, max_across) if max_across else across, convention)
    return (size_mm * 1000.0, *d, time.process_time() - cpu)


def _measure(method: str, params: Any, seed: int, across: float, convention: str,
             opening: bool = False) -> tuple[float, ...]:
    from ..analysis.atlas import opening_fraction, voxel_descriptors, voxel_image
    from ..methods import generate

    grain = generate(method, params, seed)
    mask, h, _ = voxel_image(grain, voxels_across=across, rotation=np.random.default_rng([seed, 1]))
    d = voxel_descriptors(mask, h, convention=convention)
    return tuple(float(d[k]) for k in DESCRIPTORS) + ((opening_fraction(mask, OPENING_RADIUS * across),)
                                                      if opening else ())


def measure_settings(method: str, fixed: Mapping[str, Any], own: Mapping[str, Any], seed: int, across: float,
                     convention: str = "atlas", opening: bool = False) -> tuple[float, ...]:
    """One grain made with ``fixed`` and its ``own`` parameters and ``seed``, measured ``across`` voxels across.

    Returns the four descriptors (and, with ``opening``, the opening fraction of :data:`OPENING_COLUMN`) and
    the CPU seconds; NaNs if the generator refuses these settings (a design corner, say).
    """
    import time

    from ..methods import get
    from ..params import ParameterError

    cpu = time.process_time()
    try:
        d = _measure(method, get(method).Params(**{**fixed, **own}), seed, across, convention, opening)
    except (ParameterError, ValueError):
        d = (math.nan,) * (len(DESCRIPTORS) + bool(opening))
    return (*d, time.process_time() - cpu)


def grain_seed(root: int, index: int) -> int:
    """The seed ``batch`` gives grain ``index`` of a recipe with root seed ``root``."""
    from ..population import grain_stream

    return int(grain_stream(root, index).integers(0, 2**63))


def reseed_seed(root: int, index: int, attempt: int) -> int:
    """Twin ``index``'s seed at reseed try ``attempt`` (from 0) of a fit with root seed ``root`` (written to the
    recipe's ``[grains] seed`` column when kept).

    Examples
    --------
    >>> a = reseed_seed(2024, 3, 0)
    >>> a == reseed_seed(2024, 3, 0), a != reseed_seed(2024, 3, 1), a != grain_seed(2024, 3)
    (True, True, True)
    """
    return int(np.random.default_rng([int(root), int(index), 1 + int(attempt), 0x5EED]).integers(0, 2**63))


class _Pool:
    """Runs :func:`measure_settings` jobs, in this process, on a worker pool or on the caller's ``executor`` (a
    :class:`grainforge.runtime.cluster.DaskExecutor`): the same jobs and seeds, each result in its job's place."""

    def __init__(self, workers: int, convention: str = "atlas", executor=None):
        self.workers = workers
        self.convention = convention
        self.ex = executor
        self.own = executor is None  # a pool of our own is closed on leaving; the caller's executor is not
        self.cpu = 0.0  # CPU seconds the workers spent generating and measuring
        self.grains = 0

    def __enter__(self):
        if self.own and self.workers > 1:
            from ..runtime.workers import process_pool

            self.ex = process_pool(self.workers, ["grainforge.fit", "grainforge.analysis.atlas",
                                                  "grainforge.population", "trimesh", "scipy.ndimage",
                                                  "skimage.measure"])
        return self

    def __exit__(self, exc_type, exc, tb):
        if self.ex is not None and self.own:
            from ..runtime.workers import close_pool

            # an error, Ctrl-C or SIGTERM: stop the workers now (waiting for them from inside an
            # interrupted as_completed could hang; seen with SIGTERM during a fit)
            close_pool(self.ex, abort=exc_type is not None)

    def run(self, method: str, fixed: Mapping[str, Any], jobs: Sequence[tuple[dict, int, float]],
            progress, opening: bool = False) -> np.ndarray:
        """(n, 4) descriptors of the jobs (own parameters, seed, voxels across); NaN rows where refused.  With
        ``opening``, (n, 5): the opening fraction of :data:`OPENING_COLUMN` last."""
        width = len(DESCRIPTORS) + bool(opening)
        out = np.empty((len(jobs), width))
        args = [(method, fixed, own, seed, across, self.convention, bool(opening)) for own, seed, across in jobs]
        if self.ex is None:
            it: Iterable = ((i, measure_settings(*a)) for i, a in enumerate(args))
        else:
            from concurrent.futures import as_completed

            from ..runtime.workers import single_threaded_children

            with single_threaded_children():
                futs = {self.ex.submit(measure_settings, *a): i for i, a in enumerate(args)}
            it = ((futs[f], f.result()) for f in as_completed(futs))
        if progress is not None and jobs:
            it = progress(it, len(jobs))
        done = False
        try:
            for i, row in it:
                out[i] = row[:width]
                self.cpu += row[width]
                self.grains += 1
            done = True
        finally:
            if not done and self.ex is not None:  # an error or interrupt: drop the jobs not started
                for f in futs:
                    f.cancel()
        return out


# --------------------------------------------------------------------------- the design
def _design_high(sand: Sand, max_across: float | None) -> float:
    """Highest resolution a design spans: the cap, or (uncapped) the sand's largest grain's, on a 10 % grid."""
    if max_across:
        return float(max_across)
    top = float((sand.equivalent_diameter / sand.voxel_size).max())
    return float(f"{1.1 ** math.ceil(math.log(max(top, DESIGN_ACROSS_LOW * 1.1)) / math.log(1.1)):.4g}")


def design_path(method: str, convention: str, high: float, grains: int = DESIGN_GRAINS,
                cache: str | os.PathLike | None = None) -> Path:
    """Where a method's design is cached: under ``cache`` (default :func:`grainforge.runtime.cache.cache_dir`),
    keyed by everything that changes its grains."""
    from .._version import __version__
    from ..runtime.cache import cache_dir

    spec = FITS[method]
    key = repr((DESIGN_VERSION, __version__, DESIGN_SEED, method, spec.all_settings, sorted(spec.fixed.items()),
                convention, float(high), int(grains)))
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return Path(cache or cache_dir()) / "fit-designs" / f"{method}-{convention}-{high:g}-{grains}-{digest}.npz"


@dataclass(frozen=True)
class Design:
    """A method's design: unit-box settings ``u``, resolutions ``across`` and measured descriptors ``y``."""

    method: str
    u: np.ndarray
    across: np.ndarray
    y: np.ndarray  # NaN rows: the generator refused those settings

    def model(self):
        from .twins import ForwardModel

        ok = np.all(np.isfinite(self.y), axis=1)
        return ForwardModel.fit(self.u[ok], self.across[ok], self.y[ok])


def design(method: str, pool: _Pool, *, high: float, grains: int = DESIGN_GRAINS,
           cache: str | os.PathLike | None = None, progress=None) -> Design:
    """The cached design of ``method`` (measured, and cached atomically, if it is not yet)."""
    from ..io import atomic_write
    from .twins import design_points

    spec = FITS[method]
    path = design_path(method, pool.convention, high, grains, cache)
    if path.exists():
        with np.load(path) as z:
            return Design(method, z["u"], z["across"], z["y"])
    pts = design_points(grains, len(spec.all_settings) + 1, DESIGN_SEED)
    u, t = pts[:, :-1], pts[:, -1]
    across = DESIGN_ACROSS_LOW * (high / DESIGN_ACROSS_LOW) ** t
    jobs = [(spec.grain_params(u[i]), grain_seed(DESIGN_SEED, i), float(across[i])) for i in range(grains)]
    y = pool.run(method, spec.fixed, jobs, progress)
    buf = io.BytesIO()
    np.savez(buf, u=u, across=across, y=y)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, buf.getvalue())
    return Design(method, u, across, y)


#: a setting predicted from a grain's descriptors with at least this cross-validated R² is called identifiable
IDENTIFIABLE_R2 = 0.9
#: a setting whose axis the descriptors' means see less than this much is "not determined by the means": a
#: combination of it with other settings that leaves all four means as they are moves it (more settings than
#: descriptors: rf's three surface settings), so its estimate is the starting population's, not the sand's
DETERMINED_MIN = 0.98


def setting_identifiability(des: Design) -> dict[str, tuple[float, float]]:
    """Per setting of ``des``'s method: (R², rms error in the setting's units) of predicting it from a grain's
    four descriptors (:func:`grainforge.fit.twins.identifiability` on the design).

    What the fitted settings of a twin can say about its sand grain: with R² ≥ :data:`IDENTIFIABLE_R2` the
    descriptors determine the setting (a sand's setting is *acquired* from its scan, within the error);
    near 0 the grain's seed or another setting shapes the same descriptors, and the fitted value is one
    choice among many that measure alike.
    """
    from .twins import identifiability

    ok = np.all(np.isfinite(des.y), axis=1)
    r2, rmse = identifiability(des.u[ok], des.across[ok], des.y[ok])
    return {st.name: (float(a), float(e * (st.high - st.low)))
            for st, a, e in zip(FITS[des.method].all_settings, r2, rmse)}


# --------------------------------------------------------------------------- comparing
#: the six descriptor pairs whose rank correlations are compared
PAIRS = tuple((DESCRIPTORS[i], DESCRIPTORS[j]) for i in range(4) for j in range(i + 1, 4))


def spearman(table: np.ndarray) -> np.ndarray:
    """(k, k) Spearman rank correlations of the columns of ``table``."""
    from scipy.stats import rankdata

    r = np.apply_along_axis(rankdata, 0, np.asarray(table, np.float64))
    return np.corrcoef(r.T)


def compare(sand: np.ndarray, gen: np.ndarray, *, twin_within: float | None = None) -> dict[str, Any]:
    """Statistics of two (n, 4) descriptor tables: means, sds, KS per descriptor; Spearman correlations.

    ``score`` is the largest of KS/:data:`KS_MAX`, |Δmean|/:data:`MEAN_TOL`
    and |Δρ|/:data:`CORR_TOL` (and, with ``twin_within``, the share of
    reachable twins within :data:`TWIN_TOL`, as :data:`TWIN_SHARE`/share):
    the fit passes when it is ≤ 1.

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


# --------------------------------------------------------------------------- the fit
@dataclass
class FitResult:
    """What :func:`fit_sand` found: one twin per generated grain."""

    method: str
    recipe: str  # TOML text of the final recipe
    stats: dict[str, Any]  # compare(sand rows, twins)
    generated: np.ndarray  # (count, 5): d_eq µm + DESCRIPTORS, as measured
    sand_rows: np.ndarray  # (count,): index into the sand of each grain's original
    settings: list[dict[str, float]]  # each grain's setting values
    reachable: np.ndarray  # (count,) bool: the model's closest setting predicts a twin within TWIN_TOL
    history: list[str] = field(default_factory=list)
    seconds: float = 0.0  # wall clock
    cpu_seconds: float = 0.0  # generating and measuring, summed over the workers
    grains_measured: int = 0

    @property
    def twin_error(self) -> np.ndarray:
        """(count,) largest |twin − original| over the four descriptors."""
        return np.max(np.abs(self.generated[:, 1:] - self.targets), axis=1)

    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # (count, 4) the originals'
    #: setting -> (cross-validated R², rms error in the setting's units) of predicting it from a grain's four
    #: descriptors on the method's design (:func:`setting_identifiability`)
    identifiable: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: the sand's mean settings estimated from its descriptors' means (:func:`population_settings`)
    population: Population | None = None
    #: each grain's seed (as the recipe makes it)
    seeds: list[int] = field(default_factory=list)


def choose_rows(n: int, count: int | None, seed: int) -> np.ndarray:
    """Sand rows the twins copy: all (``count`` None), a random ``count`` of them without replacement, or with
    replacement beyond all ``n`` (all rows, then random repeats).

    Examples
    --------
    >>> choose_rows(5, None, 1).tolist(), len(set(choose_rows(100, 60, 1).tolist())), len(choose_rows(5, 8, 1))
    ([0, 1, 2, 3, 4], 60, 8)
    """
    rng = np.random.default_rng([seed, 7])
    if count is None or count == n:
        return np.arange(n)
    if count < n:
        return np.sort(rng.choice(n, size=count, replace=False))
    return np.concatenate([np.arange(n), rng.choice(n, size=count - n, replace=True)])


@dataclass
class _Twins:
    """The fit's working state: per grain its target, resolution, seed, settings and best twin so far."""

    spec: MethodFit
    targets: np.ndarray  # (n, 4)
    across: np.ndarray  # (n,) measured at
    seeds: list[int]
    u: np.ndarray  # (n, p) settings being tried
    reach: np.ndarray  # (n,) the model's predicted miss at u
    tol: np.ndarray  # (4,) refinement tolerance per descriptor
    best_u: np.ndarray = None  # type: ignore[assignment]
    best_y: np.ndarray = None  # type: ignore[assignment]

    def error(self, y: np.ndarray, idx: np.ndarray | None = None) -> np.ndarray:
        """Largest |measured − target| per grain (of ``idx``, default all); inf where unmeasured."""
        e = np.max(np.abs(y - (self.targets if idx is None else self.targets[idx])), axis=1)
        return np.where(np.isfinite(e), e, np.inf)

    def relative(self, y: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Largest |measured − target| / tolerance per grain of ``idx``: > 1 is refined."""
        e = np.max(np.abs(y - self.targets[idx]) / self.tol, axis=1)
        return np.where(np.isfinite(e), e, np.inf)

    def made(self) -> np.ndarray:
        """(n,) bool: the generator has made and measured the grain at some settings tried."""
        return np.all(np.isfinite(self.best_y), axis=1)

    def keep_reseeded(self, idx: np.ndarray, u: np.ndarray, y: np.ndarray, seeds: Sequence[int],
                      reach: np.ndarray) -> np.ndarray:
        """Keep, for twins ``idx``, the grains made with other ``seeds`` at settings ``u`` that come closer than
        their best so far; returns which were kept."""
        better = self.relative(y, idx) < self.relative(self.best_y[idx], idx)
        kept = idx[better]
        self.best_u[kept] = self.u[kept] = u[better]
        self.best_y[kept], self.reach[kept] = y[better], reach[better]
        for i, s in zip(kept, np.asarray(seeds)[better]):
            self.seeds[i] = int(s)
        return better

    def keep_best(self, idx: np.ndarray, y: np.ndarray) -> None:
        if self.best_y is None:
            self.best_u, self.best_y = self.u.copy(), np.full_like(self.targets, np.nan)
        better = self.relative(y, idx) < self.relative(self.best_y[idx], idx)
        self.best_u[idx[better]] = self.u[idx[better]]
        self.best_y[idx[better]] = y[better]


def _start_twins(spec: MethodFit, model, sand: Sand, rows: np.ndarray, across_cap: float | None,
                 seed: int) -> _Twins:
    """Each twin's first settings: the inverse model's, for its original at its resolution."""
    from .twins import invert

    targets = sand.table()[rows]
    across = measured_across(sand, across_cap)[rows]
    tol = np.minimum(REFINE_TOL, REFINE_SD * sand.table().std(axis=0))
    u, miss = invert(model, targets, across, scale=tol)
    return _Twins(spec, targets, across, [grain_seed(seed, i) for i in range(len(rows))], u, miss, tol)


def _measure_twins(tw: _Twins, pool: _Pool, idx: np.ndarray, progress) -> np.ndarray:
    jobs = [(tw.spec.grain_params(tw.u[i]), tw.seeds[i], float(tw.across[i])) for i in idx]
    y = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress)
    tw.keep_best(idx, y)
    return y


def _refine(tw: _Twins, model, idx: np.ndarray, y: np.ndarray) -> None:
    """New settings for twins ``idx`` (last measured ``y``): the model plus each grain's own offset."""
    from .twins import invert

    pred = np.array([model.predict(tw.u[i], tw.across[i])[0] for i in idx])
    offsets = np.where(np.isfinite(y), y - pred, 0.0)
    u, miss = invert(model, tw.targets[idx], tw.across[idx], offsets=offsets, start=tw.u[idx], scale=tw.tol)
    # a grain the generator refused to make or measure at its settings (a corner of the design box, with its own
    # seed) is not re-solved, which would lead back to that corner: its settings move towards the middle
    refused = ~np.all(np.isfinite(y), axis=1)
    u[refused] = _toward_middle(tw.u[idx][refused])
    tw.u[idx] = u
    tw.reach[idx] = miss


def _reseed(tw: _Twins, model, pool: _Pool, root: int, tries: int, progress, note, name) -> None:
    """Twins still off by more than :data:`TWIN_TOL` try other seeds: each is made at its best settings with a
    new seed, then once more at the settings the model gives with that seed's own offset, and keeps the closer
    of the two if it beats its best.  Where a grain's seed shapes a descriptor as much as a setting can (the
    angular method's sphericity and convexity), another seed can put the sand grain within reach."""
    from .twins import invert

    for k in range(tries):
        idx = np.flatnonzero(tw.error(tw.best_y) > TWIN_TOL)
        if not len(idx):
            return
        seeds = [reseed_seed(root, int(i), k) for i in idx]
        u0 = tw.best_u[idx].copy()
        name(f"reseed {k + 1}/{tries}")
        jobs = [(tw.spec.grain_params(u0[j]), seeds[j], float(tw.across[i])) for j, i in enumerate(idx)]
        y0 = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress)
        pred = model.predict(u0, tw.across[idx])
        made = np.all(np.isfinite(y0), axis=1)
        u1, reach = invert(model, tw.targets[idx], tw.across[idx], offsets=np.where(made[:, None], y0 - pred, 0.0),
                           start=u0, scale=tw.tol)
        u1[~made] = u0[~made]
        jobs = [(tw.spec.grain_params(u1[j]), seeds[j], float(tw.across[i])) for j, i in enumerate(idx)]
        y1 = pool.run(tw.spec.method, tw.spec.fixed, jobs, progress)
        first = tw.relative(y0, idx) <= tw.relative(y1, idx)
        u = np.where(first[:, None], u0, u1)
        y = np.where(first[:, None], y0, y1)
        kept = tw.keep_reseeded(idx, u, y, seeds, np.where(first, tw.reach[idx], reach))
        note(f"reseed {k + 1}: {len(idx)} twins off by more than {TWIN_TOL} tried another seed, {int(kept.sum())} "
             f"came closer; {_twin_summary(tw)}")


def _toward_middle(u: np.ndarray) -> np.ndarray:
    """Unit-box settings moved a third of the way towards the middle of the box (where the generator makes every
    grain of the design)."""
    return 0.5 + (u - 0.5) * (2.0 / 3.0)


def _make_refused(tw: _Twins, pool: _Pool, progress, note, name) -> None:
    """Move the settings of twins never made so far towards the middle of the box until the generator makes them,
    so that every grain of the recipe can be built; a twin still refused after :data:`REFUSED_TRIES` is an error."""
    for k in range(REFUSED_TRIES):
        refused = np.flatnonzero(~tw.made())
        if not len(refused):
            return
        name(f"refused twins, try {k + 1}/{REFUSED_TRIES}")
        tw.u[refused] = _toward_middle(tw.u[refused])
        _measure_twins(tw, pool, refused, progress)
        note(f"refused twins: {len(refused)} the generator had refused at every settings tried, moved towards the "
             f"middle of the box; {int(tw.made()[refused].sum())} made")
    if not tw.made().all():
        raise ValueError(f"{int((~tw.made()).sum())} twin(s) could not be made at any settings tried: the "
                         f"{tw.spec.method} generator refuses them; try another --method or --seed")


@dataclass(frozen=True)
class Population:
    """The sand's mean settings, estimated from the means of its four descriptors (:func:`population_settings`).

    Per setting (its own units): ``mean``, its standard error ``se`` (the sand's finite table and the made
    grains' scatter, to first order) and ``determined`` (1: the four means pin it down; towards 0: another
    setting trades with it at equal means, and its mean is the twins' starting one).
    """

    mean: dict[str, float]
    se: dict[str, float]
    determined: dict[str, float]
    grains: int  # grains made per round
    #: per setting: how far the estimate moves when the made population's spread of a setting a grain's
    #: descriptors do not determine is SPREAD_DOUBT wider (all such settings' moves added in quadrature)
    spread: dict[str, float] = field(default_factory=dict)

    def text(self) -> str:
        """One line: each setting's mean ± standard error (and ± its sensitivity to the settings' spread), the
        undetermined ones named."""
        sure = [f"{k} {self.mean[k]:.4g} ± {self.se[k]:.2g}"
                + (f" (± {self.spread[k]:.2g} spread)" if self.spread.get(k, 0.0) > 0 else "") for k in self.mean
                if self.determined[k] >= DETERMINED_MIN]
        loose = [k for k in self.mean if self.determined[k] < DETERMINED_MIN]
        return ", ".join(sure) + (f"; not determined by the means: {', '.join(loose)}" if loose else "")


def _mean_jacobian(model, u: np.ndarray, across: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """(4, p): d(mean predicted descriptors) / d(a shift of every grain's unit-box settings), from the model."""
    cols = []
    for k in range(u.shape[1]):
        e = np.zeros(u.shape[1])
        e[k] = h
        cols.append((model.predict(u + e, across) - model.predict(u - e, across)).mean(axis=0) / (2 * h))
    return np.column_stack(cols)


def _measured_mean_jacobian(spec: MethodFit, pool: _Pool, u: np.ndarray, seeds: Sequence[int], across: np.ndarray,
                            progress=None, step: float | np.ndarray = SLOPE_STEP, opening: bool = False) -> np.ndarray:
    """(4, p), with ``opening`` (5, p): d(mean measured descriptors) / d(a shift of every grain's unit-box
    settings), measured on the first :data:`SLOPE_GRAINS` grains: each remade with one setting raised and lowered by ``step`` (one for all
    settings, or one each; kept in the box) under its own seed, so that the difference is the setting's and not
    the seed's."""
    n = min(len(u), SLOPE_GRAINS)
    steps = np.broadcast_to(np.asarray(step, np.float64), (u.shape[1],))
    cols = []
    for k in range(u.shape[1]):
        up, down = u[:n].copy(), u[:n].copy()
        up[:, k] = np.clip(up[:, k] + steps[k], 0.0, 1.0)
        down[:, k] = np.clip(down[:, k] - steps[k], 0.0, 1.0)
        jobs = [(spec.grain_params(v[i]), seeds[i], float(across[i])) for v in (up, down) for i in range(n)]
        y = pool.run(spec.method, spec.fixed, jobs, progress, opening=opening)
        ok = np.all(np.isfinite(y[:n]), axis=1) & np.all(np.isfinite(y[n:]), axis=1)
        dy, du = (y[:n] - y[n:])[ok], (up[:, k] - down[:, k])[ok]
        cols.append(dy.sum(axis=0) / max(float(du.sum()), 1e-12))
    return np.column_stack(cols)


def population_settings(spec: MethodFit, model, sand: Sand, u0: np.ndarray, y0: np.ndarray, seeds: Sequence[int],
                        across: np.ndarray, pool: _Pool, progress=None, note=None, name=None,
                        shrink: Sequence[float] | None = None, grains: int = POPULATION_GRAINS,
                        slopes: str = POPULATION_SLOPES, start: np.ndarray | None = None,
                        opening: bool = False) -> Population:
    """Estimate the sand's **mean** settings: shift a population until its mean descriptors are the sand's.

    A twin's settings are not its sand grain's: where the seed shapes a descriptor as much as a setting does,
    one grain's descriptors cannot say which setting made it (:func:`setting_identifiability`), and the twins'
    mean is pulled towards the middle of the design box.  The *population*'s mean setting is known far better:
    the seed's share averages out over the sand's grains.  Starting from the first ``grains`` twins' first
    settings ``u0`` (measured as ``y0``; :data:`POPULATION_GRAINS` in a fit at its defaults; each setting's
    spread about the mean shrunk by ``shrink``), every grain's settings are shifted by one common step (the
    slopes of the mean descriptors, solved for the gap between the sand's mean descriptors and the made
    grains'), remade with its own seed and measured, :data:`POPULATION_ROUNDS` times (a Newton iteration on
    measured means).  The estimate is the mean settings of the round whose means came closest to the sand's,
    plus a last linear step for the gap left; its standard error propagates the sand's and the made grains'
    scatter of their means through the same step (:func:`grainforge.fit.twins.population_error`).

    ``slopes="measured"`` measures the slopes on the grains (:func:`_measured_mean_jacobian`, 2 × settings ×
    up to :data:`SLOPE_GRAINS` grains more); ``"model"`` takes the design model's, which cost nothing but are
    off where the model is (the angular method's surface settings: its rounds then leave a gap in the means
    that counts once their noise is smaller, from about a thousand grains); ``"auto"`` (the default) chooses
    by the grains remade (:func:`slopes_for`).

    ``start`` (unit-box settings, one row per grain remade) replaces the shrunk twins as the population the
    common shift moves: the settings' *spread* about their mean is then the caller's.

    ``opening`` (the sand has the :data:`OPENING_COLUMN`; :func:`uses_opening`): the opening fraction is a fifth
    descriptor.  The starting grains are measured again with it (``grains`` more), the slopes are measured
    (the design model has none for it), the means' misfit is weighed by the sand's covariance (generalised
    least squares, :func:`grainforge.fit.twins.population_step`), and, since its response to edge rounding
    saturates, :data:`OPENING_ROUNDS` rounds are made, each step held to :data:`OPENING_TRUST` of the unit
    box and the slopes updated after each from how the means moved (Broyden's secant update).

    Which mean settings match the sand's means depends on that spread (the descriptors respond to the settings
    with curvature), and the table does not give the spread of a setting that a grain's descriptors do not
    determine (``shrink`` below :data:`IDENTIFIABLE_R2`).  For each such setting whose mean the means determine
    (its estimate is reported; for methods of at most four settings, so that the cost is known up front), the
    first :data:`SLOPE_GRAINS`
    grains of the estimate's round are remade with its spread :data:`SPREAD_DOUBT` wider, under their own seeds,
    and the estimate's move is ``Population.spread`` (in quadrature over those settings): a systematic error
    stated beside the standard error, which does not shrink with the table.

    Returns
    -------
    Population
    """
    from .twins import population_error, population_step

    say, label = note or (lambda s: None), name or (lambda s: None)
    m = min(len(u0), int(grains))
    u, y, across = np.asarray(u0[:m], np.float64), np.asarray(y0[:m], np.float64), np.asarray(across[:m])

    def remake(v: np.ndarray) -> np.ndarray:  # the m grains at settings v, each under its own seed
        return pool.run(spec.method, spec.fixed, [(spec.grain_params(v[i]), seeds[i], float(across[i]))
                                                  for i in range(m)], progress, opening=opening)

    table, weight, short = sand.table(), None, list(DESCRIPTORS)
    if opening:
        table, short = np.column_stack([table, sand.opening]), short + ["opening"]
        try:  # generalised least squares: the misfit in the sand's own scatter, correlations included
            weight = np.linalg.inv(np.linalg.cholesky(np.cov(table.T)))
        except np.linalg.LinAlgError:
            weight = np.diag(1.0 / np.maximum(table.std(axis=0), 1e-12))
        label("population start")
        y = remake(u)
        say(f"population: the table's opening fraction is a fifth descriptor; {m} grains measured again with it")
    target, cov_sand, scale = table.mean(axis=0), np.cov(table.T) / len(table), table.std(axis=0)
    rounds = []  # (settings, measured, gap, largest gap in the sand's sds)

    def record(u: np.ndarray, y: np.ndarray) -> np.ndarray:
        ok = np.all(np.isfinite(y), axis=1)
        gap = target - y[ok].mean(axis=0)
        rounds.append((u, y, gap, float(np.max(np.abs(gap) / scale))))
        return gap

    gap = record(u, y)
    if start is not None:
        start = np.asarray(start, np.float64)[:m]
    elif shrink is None:
        start = u
    else:  # each twin's settings carry its own seed's share: keep only what the descriptors know
        start = u.mean(axis=0) + (u - u.mean(axis=0)) * np.clip(np.asarray(shrink, np.float64), 0.0, 1.0)
    if opening or slopes_for(slopes, m) == "measured":  # the design model does not predict the opening fraction
        label("population slopes")
        jac = _measured_mean_jacobian(spec, pool, start, seeds, across, progress, opening=opening)
        say(f"population slopes: measured on {min(m, SLOPE_GRAINS)} grains, each setting raised and lowered by "
            f"{SLOPE_STEP:g} of its range under the grain's own seed")
    else:
        jac = _mean_jacobian(model, start, across)
    # with the opening fraction, whose response to rounding is curved (it saturates once the edges are rounder
    # than the ball), the slopes measured at the start are updated after each round from how the means moved
    # (Broyden's secant update), each step is held to OPENING_TRUST of the unit box, and there are
    # OPENING_ROUNDS rounds
    shift = np.zeros(u.shape[1])
    prev = None
    total = OPENING_ROUNDS if opening else POPULATION_ROUNDS
    for r in range(1, total + 1):
        step = population_step(jac, gap, weight)[0]
        if opening:
            step = step * min(1.0, OPENING_TRUST / max(float(np.max(np.abs(step))), 1e-12))
        shift = shift + step
        new_u = np.clip(start + shift, 0.0, 1.0)
        label(f"population {r}/{total}")
        new_y = remake(new_u)
        gap = record(new_u, new_y)
        if opening and prev is not None:
            both = np.all(np.isfinite(prev[1]), axis=1) & np.all(np.isfinite(new_y), axis=1)
            du = (new_u[both] - prev[0][both]).mean(axis=0)
            dy = (new_y[both] - prev[1][both]).mean(axis=0)
            # a short move's difference is mostly the voxels' quantisation, not the slope: no update
            if float(np.max(np.abs(du))) >= OPENING_SECANT_MIN:
                jac = jac + np.outer(dy - jac @ du, du) / float(du @ du)
        prev = (new_u, new_y)
        refused = int(np.sum(~np.all(np.isfinite(rounds[-1][1]), axis=1)))
        say(f"population {r}: {m} grains remade" + (f" ({refused} refused by the generator, left out)"
                                                     if refused else "")
            + "; mean descriptors off the sand's by " + ", ".join(f"{k[:5]} {g:+.4f}" for k, g in zip(short, gap))
            + "; mean settings " + ", ".join(f"{k} {v:.4g}" for k, v in spec.values(new_u.mean(axis=0)).items()))
    # the round whose means came closest (a step may overshoot where the model's slopes are not the grains')
    u, y, gap, _ = min(rounds, key=lambda r: r[3])
    ok = np.all(np.isfinite(y), axis=1)
    step, pinv = population_step(jac, gap, weight)
    est = np.clip(u[ok].mean(axis=0) + step, 0.0, 1.0)
    se, determined = population_error(pinv, cov_sand + np.cov(y[ok].T) / max(int(ok.sum()), 1))
    width = np.array([st.high - st.low for st in spec.all_settings])
    names = [st.name for st in spec.all_settings]
    # settings whose mean is reported (the means determine it) but whose spread the table does not give
    loose = [] if shrink is None or not spec.spread_step else [
        k for k, r2 in enumerate(shrink) if r2 < IDENTIFIABLE_R2 and determined[k] >= DETERMINED_MIN]
    spread = _spread_sensitivity(spec, pool, u, y, seeds, across, pinv, loose, progress, label, opening)
    if loose:
        say(f"population spread: the estimate's move with the spread of {', '.join(names[k] for k in loose)} "
            f"{SPREAD_DOUBT:.0%} wider (on {min(int(ok.sum()), SLOPE_GRAINS)} grains remade each): "
            + ", ".join(f"{k} {v:.2g}" for k, v in zip(names, spread * width)))
    return Population(mean=spec.values(est), se={k: float(e) for k, e in zip(names, se * width)},
                      determined={k: float(d) for k, d in zip(names, determined)}, grains=m,
                      spread={k: float(v) for k, v in zip(names, spread * width)})


def _spread_sensitivity(spec: MethodFit, pool: _Pool, u: np.ndarray, y: np.ndarray, seeds: Sequence[int],
                        across: np.ndarray, pinv: np.ndarray, loose: Sequence[int], progress=None,
                        label=None, opening: bool = False) -> np.ndarray:
    """(p,) unit-box: how far a population estimate (``pinv``, at settings ``u`` measured as ``y``) moves when the
    spread of each of the settings ``loose`` about its mean is :data:`SPREAD_DOUBT` wider; the moves of the
    settings added in quadrature.  Measured on the first :data:`SLOPE_GRAINS` grains made, each remade under its
    own seed, so that the difference is the spread's and not the seeds'."""
    total = np.zeros(u.shape[1])
    idx = np.flatnonzero(np.all(np.isfinite(y), axis=1))[:SLOPE_GRAINS]
    for k in loose:
        (label or (lambda s: None))(f"population spread {spec.all_settings[k].name}")
        wide = u[idx].copy()
        centre = wide[:, k].mean()
        wide[:, k] = np.clip(centre + (wide[:, k] - centre) * (1.0 + SPREAD_DOUBT), 0.0, 1.0)
        yw = pool.run(spec.method, spec.fixed, [(spec.grain_params(wide[j]), seeds[i], float(across[i]))
                                                for j, i in enumerate(idx)], progress, opening=opening)
        both = np.all(np.isfinite(yw), axis=1)
        if not both.any():
            continue
        # the settings' mean moves too where the wider spread is clipped at the box; the means' match moves back
        move = (wide[both] - u[idx][both]).mean(axis=0) - pinv @ (yw[both] - y[idx][both]).mean(axis=0)
        total += move**2
    return np.sqrt(total)


def _twin_summary(tw: _Twins) -> str:
    e = tw.error(tw.best_y)
    reach = tw.reach <= TWIN_TOL
    return (f"{np.mean(e <= TWIN_TOL):.1%} of twins within {TWIN_TOL} on every descriptor "
            f"({np.mean(e[reach] <= TWIN_TOL) if reach.any() else 0:.1%} of the {reach.sum()} reachable), "
            f"{np.mean(tw.relative(tw.best_y, np.arange(len(e))) <= 1):.1%} within the refinement tolerance "
            f"({', '.join(f'{t:.4f}' for t in tw.tol)}); median error {np.median(e):.4f}")


def choose_method(sand: Sand, pool: _Pool, *, max_across: float | str | None, grains: int, cache, progress, say,
                  name) -> str:
    """``auto``: the method whose inverse model reaches the most of the sand (ties: the smaller median miss)."""
    from .twins import invert

    table = sand.table()
    rows = choose_rows(sand.count, min(sand.count, 300), 0)
    best = None
    for m in FITS:
        cap = resolve_cap(m, max_across)
        name(f"design {m}")
        model = design(m, pool, high=_design_high(sand, cap), grains=grains, cache=cache, progress=progress).model()
        _, miss = invert(model, table[rows], measured_across(sand, cap)[rows])
        key = (float(np.mean(miss <= TWIN_TOL)), -float(np.median(miss)))
        say(f"auto: {m} reaches {key[0]:.1%} of the sand (model's median miss {-key[1]:.4f})")
        best = max(best or (key, m), (key, m))
    return best[1]


def fit_sand(
    sand: Sand,
    method: str = "rf",
    *,
    count: int | None = 500,
    refine: int = 4,
    reseed: int = RESEED,
    population_grains: int = POPULATION_GRAINS,
    population_slopes: str = POPULATION_SLOPES,
    seed: int = 2024,
    workers: int = 1,
    sphericity: str = "atlas",
    max_across: float | str | None = METHOD_CAP,
    design_grains: int = DESIGN_GRAINS,
    cache: str | os.PathLike | None = None,
    progress: Callable[[Iterable, int], Iterable] | None = None,
    log: Callable[[str], None] | None = None,
    desc: Callable[[str], None] | None = None,
    executor: Any = None,
) -> FitResult:
    """Make ``count`` twins of ``sand``'s grains with ``method``; see the module docstring.

    Parameters
    ----------
    count : int or None
        Grains of the recipe, each the twin of one sand row (:func:`choose_rows`;
        None: every row once).
    refine : int
        Rounds of per-grain refinement of the twins that miss by more than
        :data:`REFINE_TOL`.
    reseed : int
        Other seeds tried by each twin still off by more than :data:`TWIN_TOL`
        after the refinement (:func:`reseed_seed`; a kept seed is written to
        the recipe's ``[grains] seed``).
    population_grains : int
        Twins remade in each round of the estimate of the sand's mean
        settings (:func:`population_settings`; at most ``count``): its
        standard errors shrink as one over the square root of the grains,
        down to what the sand's own grain count allows.
    population_slopes : {"auto", "measured", "model"}
        The slopes the estimate steps through: measured on the grains, the
        design model's, or (``"auto"``) measured from
        :data:`SLOPES_MEASURED_FROM` grains remade per round
        (:func:`population_settings`).
    workers : int
        Processes measuring grains (1: this process).
    executor : concurrent.futures.Executor, optional
        Measure the grains on it instead (a :class:`grainforge.runtime.cluster.DaskExecutor`:
        a Dask cluster); the same jobs and seeds, so the same result.  The
        caller opens and closes it.
    sphericity : {"atlas", "whole"}
        How the generated grains' true sphericity is measured: as the Sand
        Atlas did (spam's cube, the default) or on the whole grain
        (:func:`grainforge.analysis.atlas.voxel_descriptors`).
    max_across : float, None or :data:`METHOD_CAP`
        Generated grains are measured at most this many voxels across (None:
        at the sand's resolution, however fine; :data:`METHOD_CAP`: the
        method's own cap, :attr:`MethodFit.max_across`).
    design_grains : int
        Grains of the method's design (cached under ``cache``).
    progress : callable, optional
        ``progress(iterable, total)`` wraps each phase's grains (a bar).
    log, desc : callable, optional
        ``log(line)`` gets one line per phase; ``desc(text)`` names the
        phase measured next.
    """
    import time

    if method != "auto" and method not in FITS:
        raise ValueError(f"method must be one of {', '.join(list(FITS) + ['auto'])}, got {method!r}")
    slopes_for(population_slopes, 0)  # refuses an unknown choice before any work
    check_sand(sand)
    say, name = log or (lambda s: None), desc or (lambda s: None)
    t0 = time.perf_counter()
    history: list[str] = []

    def note(line: str) -> None:
        history.append(line)
        say(line)

    with _Pool(max(1, int(workers)), sphericity, executor) as pool:
        if method == "auto":
            method = choose_method(sand, pool, max_across=max_across, grains=design_grains, cache=cache,
                                   progress=progress, say=note, name=name)
            note(f"auto: chose {method}")
        spec = FITS[method]
        cap = resolve_cap(method, max_across)
        name(f"design {method}")
        des = design(method, pool, high=_design_high(sand, cap), grains=design_grains, cache=cache,
                     progress=progress)
        model = des.model()
        note(f"design {method}: model rms " + ", ".join(f"{k[:5]} {r:.4f}" for k, r in zip(DESCRIPTORS, model.rms)))
        known = setting_identifiability(des)
        note(f"design {method}: each setting from a grain's 4 descriptors (R², rms error): " + ", ".join(
            f"{k} {r2:.2f} ±{e:.3g}" for k, (r2, e) in known.items()))
        opening = uses_opening(sand, cap)
        if sand.opening is not None and not opening:
            note(f"population: the table's opening fraction is not used: {method}'s twins of its grains over "
                 f"{cap:g} voxels across are measured at {cap:g}, where their opening fraction is not the sand "
                 "grain's (--max-voxels-across 0 measures every grain at the sand's resolution)")
        rows = choose_rows(sand.count, count, seed)
        tw = _start_twins(spec, model, sand, rows, cap, seed)
        idx = np.arange(len(rows))
        population = None
        for r in range(refine + 1):
            name("twins" if r == 0 else f"refine {r}/{refine}")
            y = _measure_twins(tw, pool, idx, progress)
            note(f"{'twins' if r == 0 else f'refine {r}'}: {len(idx)} grains measured; {_twin_summary(tw)}")
            if r == 0:
                population = population_settings(spec, model, sand, tw.u, y, tw.seeds, tw.across, pool, progress,
                                                 note, name, shrink=[r2 for r2, _ in known.values()],
                                                 grains=population_grains, slopes=population_slopes,
                                                 opening=opening)
                note(f"population: the sand's mean settings from its descriptors' means"
                     f"{' and its opening fraction' if opening else ''} (± standard error; "
                     f"{sand.count} sand grains, {population.grains} made): {population.text()}")
            keep = tw.relative(tw.best_y[idx], idx) > 1
            if r == refine or not keep.any():
                break
            idx, y = idx[keep], y[keep]
            _refine(tw, model, idx, y)
        _reseed(tw, model, pool, seed, reseed, progress, note, name)
        _make_refused(tw, pool, progress, note, name)
    return _result(sand, spec, tw, rows, seed, history, time.perf_counter() - t0, pool, known, population)


def _result(sand: Sand, spec: MethodFit, tw: _Twins, rows: np.ndarray, seed: int, history: list[str],
            seconds: float, pool: _Pool, known: dict[str, tuple[float, float]],
            population: Population | None = None) -> FitResult:
    """The fit's result from its twins: each grain's closest measurement, its settings and the recipe."""
    ok = tw.made()
    err = tw.error(tw.best_y)
    reachable = (tw.reach <= TWIN_TOL) | (err <= TWIN_TOL)
    within = float(np.mean(err[reachable] <= TWIN_TOL)) if reachable.any() else 0.0
    st = compare(tw.targets[ok], tw.best_y[ok], twin_within=within)
    st["reachable"] = float(np.mean(reachable))
    st["unreachable_by"] = _unreachable_by(tw, ~reachable)
    st["refused"] = int((~ok).sum())
    size_mm = [_written(float(d) / 1000.0) for d in sand.equivalent_diameter[rows]]
    gen = np.column_stack([np.asarray(size_mm) * 1000.0, tw.best_y])
    header = _recipe_header(sand, spec.method, st, len(rows), known, population)
    own = [spec.grain_params(u) for u in tw.best_u]
    text = twin_recipe_text(spec, own, size_mm, seed=seed, header=header, seeds=tw.seeds)
    return FitResult(method=spec.method, recipe=text, stats=st, generated=gen, sand_rows=rows,
                     settings=[spec.values(u) for u in tw.best_u], reachable=reachable, history=history,
                     seconds=seconds, cpu_seconds=pool.cpu, grains_measured=pool.grains, targets=tw.targets,
                     identifiable=known, population=population, seeds=list(tw.seeds))


def _unreachable_by(tw: _Twins, out: np.ndarray) -> dict[str, int]:
    """Unreachable grains counted by the descriptor their closest twin misses most."""
    if not out.any():
        return {}
    worst = np.nanargmax(np.abs(np.nan_to_num(tw.best_y[out], nan=9.0) - tw.targets[out]), axis=1)
    return {DESCRIPTORS[k]: int(np.sum(worst == k)) for k in range(4) if np.any(worst == k)}


def _recipe_header(sand: Sand, method: str, st: dict, n: int, known: dict[str, tuple[float, float]],
                   population: Population | None = None) -> str:
    lines = [f"grainforge fit: {n} {method} grains, each the twin of one grain of {sand.name} "
             f"({sand.count} grains, voxel {sand.voxel_size:g} µm)"]
    lines += [f"{k}: sand {p['sand_mean']:.3f} generated {p['gen_mean']:.3f} KS {p['ks']:.3f}"
              for k, p in st["per"].items()]
    lines += ["Spearman " + ", ".join(f"{k} {a:+.2f}/{b:+.2f}" for k, (a, b) in st["corr"].items())]
    lines += [f"{st['twin_within']:.1%} of reachable twins within {TWIN_TOL}; {1 - st['reachable']:.1%} "
              "unreachable"]
    lines += [f"{'passes' if st['pass'] else 'does NOT pass'}: KS <= {KS_MAX}, |mean diff| <= {MEAN_TOL}, "
              f"|Spearman diff| <= {CORR_TOL}, twins within {TWIN_TOL} for >= {TWIN_SHARE:.0%}"]
    sure = [f"{k} (±{e:.2g})" for k, (r2, e) in known.items() if r2 >= IDENTIFIABLE_R2]
    loose = [f"{k} (R² {r2:.2f})" for k, (r2, e) in known.items() if r2 < IDENTIFIABLE_R2]
    lines += [f"settings a grain's descriptors determine: {', '.join(sure) or 'none'}; "
              f"not determined (seed or another setting shapes the same descriptors): {', '.join(loose) or 'none'}"]
    if population is not None:
        why = (f"; ± spread: the estimate's move with a {SPREAD_DOUBT:.0%} wider spread of the settings a grain's "
               "descriptors do not determine" if any(population.spread.values()) else "")
        lines += [f"the sand's mean settings (± standard error{why}): {population.text()}"]
    return "\n".join(lines)


# --------------------------------------------------------------------------- outputs
TWIN_COLUMNS = ("grain", "seed", "sand_row", "sand_d_eq_um", "d_eq_um",
                *[f"{w}_{k}" for k in DESCRIPTORS for w in ("sand", "twin")], "max_difference", "within",
                "reachable")


def twin_rows(result: FitResult) -> list[dict[str, Any]]:
    """The rows of ``fit.csv``: each generated grain beside the sand row it is the twin of (row numbers from 1,
    as in the sand's file)."""
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
    """The rows of ``fit-stats.csv``: means, sds, KS; Spearman correlations; the twins' share, sand vs generated."""
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
    matrices of sand and generated grains."""
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
    """Write :data:`OUTPUTS` into ``out`` (each atomically); return the paths."""
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
