"""The sand: its table of per-grain measurements, read, checked and written (docs/fit.md).

A *sand* is a table of per-grain measurements in the Sand Atlas format
(:func:`read_sand`): equivalent diameter, true sphericity, convexity,
flatness and elongation, measured on μCT voxel images of a known voxel size,
and optionally each grain's opening fraction (:data:`OPENING_COLUMN`).
:func:`read_sand` names in one line what makes a file not such a table,
:func:`check_sand` what makes a table too poor to fit, and :func:`write_sand`
writes one.  :func:`measured_across` gives the resolution each sand grain's
twin is measured at.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

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
#: optional column, not the Sand Atlas's: each grain's opening fraction at a ball of OPENING_RADIUS times its d_eq
#: (:func:`grainforge.analysis.atlas.opening_fraction`, on the grain's voxel image; ``grainforge analyse --voxel-size-mm
#: H --atlas-csv FILE`` writes it for mesh files).  Where a table has it, the estimate of the sand's mean settings uses
#: it as a fifth descriptor (:func:`grainforge.fit.mean_settings.population_settings`): it responds to edge rounding far
#: more than to a grain's seed (docs/fit.md, "What a scan's images add")
OPENING_COLUMN = "Opening Fraction (-)"
#: largest true sphericity accepted: measured on voxels it can exceed 1 a little (Ottawa's largest is 1.02)
SPHERICITY_MAX = 1.2
#: fewest grains a sand must have to be fitted: two samples of 50 grains of one sand already differ by a
#: KS statistic of about 0.17 (0.87·√(2/50)), beyond the 0.1 criterion; fewer grains say too little
MIN_GRAINS = 50
#: range of grain sizes, in voxels across (d_eq / voxel size), the fit measures: fewer than 5 voxels across
#: describe no shape; at 1,000 one grain's voxel image holds 10⁹ voxels
VOXELS_ACROSS = (5.0, 1000.0)


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
        """The four matched descriptors of every grain, one row per grain.

        Returns
        -------
        (n, 4) numpy.ndarray of float64
            Columns in the order of :data:`DESCRIPTORS` (sphericity, convexity, flatness, elongation),
            rows in the table's order.
        """
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
        raise InputError(f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    for magic, what in _MAGIC:
        if data.startswith(magic):
            raise FileFormatError(f"{path}: not a CSV table: the file is {what}")
    if b"\x00" in data[:4096]:
        raise FileFormatError(f"{path}: not a CSV table: the file holds binary data (NUL bytes)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        byte = data[exc.start]
        guess = data[exc.start:exc.start + 1].decode("latin-1")
        raise FileFormatError(f"{path}: not UTF-8 text (byte 0x{byte:02x} at offset {exc.start}, {guess!r} in Latin-1 "
                             "or Windows-1252): save the table as UTF-8") from None


def _check_separator(path: Path, header: Sequence[str]) -> None:
    """A header read as one or two columns that holds ';' or a tab: another separator, named."""
    if len(header) <= 2:
        joined = ",".join(header)
        for sep, name in ((";", "semicolons"), ("\t", "tabs")):
            if joined.count(sep) >= 2:
                raise InputError(f"{path}: the columns are separated by {name}; a Sand Atlas CSV is "
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
            raise InputError(f"{path}: column {near[0]!r} is not read: name it {col!r} (with its unit) or drop it")


def _check_ids_and_volumes(path: Path, rows: Sequence[Sequence[str]], header: Mapping[str, int]) -> None:
    """Duplicate particle IDs and volumes that are not positive numbers are named (the fit reads neither)."""
    i = header.get(_norm("Particle ID"))
    if i is not None:
        seen: dict[str, int] = {}
        for line, row in enumerate(rows[1:], start=2):
            key = row[i].strip() if i < len(row) else ""
            if key and key in seen:
                raise InputError(f"{path}: line {line}: Particle ID {key!r} appears again (first on line "
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
                raise InputError(f"{path}: line {line}, column {rows[0][j]!r}: a grain's volume must be a positive "
                                 f"number, got {cell!r}")


def read_sand(path: str | os.PathLike, voxel_size: float | None = None) -> Sand:
    """Read a Sand Atlas CSV (one row per grain; columns as in :data:`COLUMNS`).

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file (UTF-8, comma-separated, a header row naming the columns with their units).
    voxel_size : float, optional
        Voxel size of the scan (µm); required unless the file has a
        ``Voxel Size (µm)`` column (then its median is used).

    Returns
    -------
    Sand
        Named after the file; lengths in µm (equivalent diameters and the voxel size), each of
        :data:`DESCRIPTORS` as an (n,) array, and the :data:`OPENING_COLUMN` where the file has it.

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
        raise InputError(f"{path}: empty file (expected a Sand Atlas CSV with a header row)")
    _check_separator(path, rows[0])
    header = {_norm(h): i for i, h in enumerate(rows[0])}
    want = dict(COLUMNS)
    missing = [c for c in want.values() if _norm(c) not in header]
    if missing:
        raise InputError(f"{path}: not a Sand Atlas CSV: missing column(s) {', '.join(repr(c) for c in missing)}"
                         + _near_misses(rows[0], missing))
    _check_unit_less(path, rows[0], (VOXEL_COLUMN, OPENING_COLUMN))
    if len(rows) < 2:
        raise InputError(f"{path}: no grains (only a header row)")
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
                raise InputError(f"{path}: line {line}, column {col!r}: not a number: {cell!r}") from None
            unit = key in (*DESCRIPTORS, "opening")  # a ratio: at most 1
            high = SPHERICITY_MAX if key == "sphericity" else 1 + 1e-6 if unit else math.inf
            if not (math.isfinite(x) and (0 <= x if key == "opening" else 0 < x) and x <= high):
                limit = f" (at most {SPHERICITY_MAX:g})" if key == "sphericity" else " (at most 1)" if unit else ""
                raise InputError(f"{path}: line {line}, column {col!r}: out of range{limit}: {cell!r}")
            data[key].append(x)
    _check_ids_and_volumes(path, rows, header)
    if voxel_size is None:
        if "voxel_size" not in data:
            raise InputError(f"{path}: no {VOXEL_COLUMN!r} column: give the scan's voxel size ({{voxel_size}})",
                             setting="voxel_size")
        voxel_size = float(np.median(data["voxel_size"]))
    elif "voxel_size" in data:
        column = np.asarray(data["voxel_size"])
        if not np.allclose(column, voxel_size, rtol=1e-6, atol=0):
            raise InputError(f"{path}: the voxel size given ({voxel_size:g} µm) differs from the file's "
                             f"{VOXEL_COLUMN!r} column ({np.median(column):g} µm): give one of them (drop "
                             "{voxel_size} to use the column)", setting="voxel_size")
    if not (math.isfinite(voxel_size) and voxel_size > 0):
        raise InputError(f"{path}: the voxel size must be a positive number of µm, got {voxel_size!r}")
    across = np.asarray(data["equivalent_diameter"]) / voxel_size
    lo, hi = VOXELS_ACROSS
    if not (np.all(np.isfinite(across)) and across.min() >= lo and across.max() <= hi):
        raise InputError(f"{path}: at a voxel size of {voxel_size:g} µm its grains are {across.min():.3g} to "
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
               *, voxel_size: float | Sequence[float], opening: Sequence[float] | None = None) -> Path:
    """Write grains' measurements as a Sand Atlas CSV that :func:`read_sand` reads (atomically).

    Columns :data:`SAND_HEADER` (particle IDs from 1, the volume of a ball of each d_eq, lengths in µm,
    values to 6 significant digits), and :data:`OPENING_COLUMN` where ``opening`` is given.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file written (replaced if it exists).
    equivalent_diameter : (n,) array_like
        Each grain's equivalent diameter, µm.
    values : mapping
        Each of :data:`DESCRIPTORS` to its (n,) values (dimensionless).
    voxel_size : float or (n,) array_like
        µm, per grain or for all (keyword-only).
    opening : (n,) array_like, optional
        Each grain's opening fraction (:func:`grainforge.analysis.atlas.opening_fraction`), written as the
        :data:`OPENING_COLUMN`; keyword-only.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    ValueError
        If a column does not have one value per grain.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.csv"
    >>> _ = write_sand(p, [500.0], {k: [0.8] for k in DESCRIPTORS}, voxel_size=7.3, opening=[0.99])
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
        raise InputError("every column needs one value per grain")
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\r\n")
    w.writerow(header)
    w.writerows([[int(r[0]), *(f"{float(x):.6g}" for x in r[1:])] for r in zip(*cols)])
    return atomic_write(path, out.getvalue())


#: the columns a scan's table adds after :data:`SAND_HEADER` and :data:`OPENING_COLUMN` (:func:`scan_sand_text`)
SCAN_COLUMNS = (("voxels", "Voxels (-)"), ("centroid_x", "Centroid X (µm)"), ("centroid_y", "Centroid Y (µm)"),
                ("centroid_z", "Centroid Z (µm)"), ("border", "Border (-)"))


def scan_sand_text(rows: Sequence[Mapping], voxel_size_um: float) -> str:
    """A μCT scan's measured grains as a Sand Atlas CSV text that :func:`read_sand` reads.

    :data:`SAND_HEADER`, the :data:`OPENING_COLUMN`, then :data:`SCAN_COLUMNS`; Particle ID is the grain's
    label.  Values as :func:`write_sand` writes them (6 significant digits, lengths in µm).

    Parameters
    ----------
    rows : sequence of mapping
        The measured grains (:func:`grainforge.analysis.scan.measure_scan`'s rows: ``label``, ``volume``,
        ``equivalent_diameter``, the :data:`DESCRIPTORS`, ``opening_fraction``, ``voxels``, the centroid, µm,
        and ``border``).
    voxel_size_um : float
        The scan's voxel size, µm.

    Returns
    -------
    str
        The CSV text, CRLF line ends.

    Examples
    --------
    >>> row = dict(label=7, volume=523.6, equivalent_diameter=10.0, sphericity=0.9, convexity=0.95, flatness=0.8,
    ...            elongation=0.7, opening_fraction=0.99, voxels=523, centroid_x=1.0, centroid_y=2.0,
    ...            centroid_z=3.0, border=False)
    >>> scan_sand_text([row], 1.0).splitlines()[1]
    '7,523.6,10,0.9,0.95,0.8,0.7,1,0.99,523,1,2,3,0'
    """
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\r\n")
    w.writerow([*SAND_HEADER, OPENING_COLUMN, *(h for _, h in SCAN_COLUMNS)])
    for r in rows:
        cells = [r["volume"], r["equivalent_diameter"], *(r[k] for k in DESCRIPTORS), voxel_size_um,
                 r["opening_fraction"], r["voxels"], r["centroid_x"], r["centroid_y"], r["centroid_z"]]
        w.writerow([int(r["label"]), *(f"{float(x):.6g}" for x in cells), int(bool(r["border"]))])
    return out.getvalue()


def check_sand(sand: Sand) -> None:
    """Refuse a sand that cannot be fitted: fewer than :data:`MIN_GRAINS` grains, or a column without spread.

    A fit matches distributions; identical grains (every value of a column
    the same) have none to match, and their single size makes no grading.

    Parameters
    ----------
    sand : Sand
        The table to check (its equivalent diameters, the four descriptors and, where it has one, the
        opening fraction).

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
    grainforge.errors.InputError: s.csv: every grain has the same sphericity (0.8): a fit needs a spread of sizes and shapes to match
    """
    if sand.count < MIN_GRAINS:
        raise InputError(f"{sand.name}: {sand.count} grain(s); a fit needs at least {MIN_GRAINS} "
                         "(fewer grains say too little about the sand's distributions)")
    opening = [] if sand.opening is None else [("opening fraction", sand.opening)]
    for key, col in [("equivalent diameter", sand.equivalent_diameter)] + [(k, sand.values[k]) for k in DESCRIPTORS] \
            + opening:
        if float(np.ptp(col)) <= 1e-9 * float(np.max(np.abs(col))):
            raise InputError(f"{sand.name}: every grain has the same {key} ({float(col[0]):g}): a fit needs a "
                             "spread of sizes and shapes to match")


def measured_across(sand: Sand, max_across: float | None) -> np.ndarray:
    """Voxels across each sand grain's twin is measured at: the sand's, capped at ``max_across``.

    Parameters
    ----------
    sand : Sand
        The sand (equivalent diameters and voxel size in µm).
    max_across : float or None
        The resolution cap in voxels across (:func:`grainforge.fit.settings.resolve_cap`); None or 0:
        uncapped.

    Returns
    -------
    (n,) numpy.ndarray of float64
        Per sand grain, min(d_eq / voxel size, ``max_across``).

    Examples
    --------
    >>> s = Sand("s.csv", 10.0, np.array([300.0, 2000.0]), {k: np.ones(2) for k in DESCRIPTORS})
    >>> measured_across(s, 150.0).tolist(), measured_across(s, None).tolist()
    ([30.0, 150.0], [30.0, 200.0])
    """
    across = sand.equivalent_diameter / sand.voxel_size
    return np.minimum(across, max_across) if max_across else across


def uses_opening(sand: Sand, max_across: float | None) -> bool:
    """Whether a fit's mean-settings estimate uses the table's :data:`OPENING_COLUMN`: where it has one and no
    grain's twin is measured coarser than the sand grain (``max_across``), since the opening fraction, like
    true sphericity, depends on the voxels across and is compared at the sand's own resolution only.

    Parameters
    ----------
    sand : Sand
        The sand (its ``opening`` is None where the table has no such column).
    max_across : float or None
        The fit's resolution cap in voxels across; None or 0: uncapped.

    Returns
    -------
    bool
        True where the table has the column and no sand grain is more than ``max_across`` voxels across.
    """
    return sand.opening is not None and not (max_across and bool(np.any(
        sand.equivalent_diameter / sand.voxel_size > max_across)))
