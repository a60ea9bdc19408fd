"""Generate a run of grains into a folder, with a manifest.

This is the library side of ``grainforge generate``: it validates, generates,
scales, measures and writes, and knows nothing of the command line.
"""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from ..analysis.descriptors import BASIC_COLUMNS, basic_descriptors
from ..errors import InputError, OutputExistsError
from ..fabrication.scale import check_target_size, to_size
from ..io import FORMATS, _cell, export_bytes, file_mode
from ..io.inputs import MANIFEST, read_manifest
from ..methods import generate, get
from ..params import as_dict, specs
from ..rng import RNGLike
from ..runtime.staging import signals_held, staged

__all__ = ["grain_file_name", "manifest_row", "manifest_columns", "encode_grain", "write_run", "planned_files",
           "existing_outputs", "earlier_run_files"]



def grain_file_name(method: str, index: int, fmt: str) -> str:
    """``fso-0000.stl`` style names (at least four digits).

    Parameters
    ----------
    method : str
        The generator's name.
    index : int
        The grain's index, from 0.
    fmt : str
        The file format's extension (``stl``, ``obj``, ``ply``).

    Returns
    -------
    str

    Examples
    --------
    >>> grain_file_name("fso", 7, "stl"), grain_file_name("rf", 12345, "ply")
    ('fso-0007.stl', 'rf-12345.ply')
    """
    return f"{method}-{index:04d}.{fmt}"


def manifest_columns(method: str, extra: Sequence[str] = ()) -> list[str]:
    """Manifest columns for ``method``: identity, every parameter, scale, measures.

    Parameters
    ----------
    method : str
        The generator's name.
    extra : sequence of str
        Columns added after the method's info columns (e.g. a printer's, ``sha256``).

    Returns
    -------
    list of str
        ``file, method, seed``, the method's parameters, ``size, size_definition, scale``, its info columns,
        ``extra``, the basic descriptors and ``version`` (without units: :func:`grainforge.units.headers`
        adds them).

    Examples
    --------
    >>> cols = manifest_columns("fso", ("sha256",))
    >>> cols[:3], cols[-1], "sha256" in cols
    (['file', 'method', 'seed'], 'version', True)
    """
    module = get(method)
    cols = ["file", "method", "seed"]
    cols += [s.name for s in specs(module.Params)]
    cols += ["size", "size_definition", "scale"]
    cols += list(getattr(module, "INFO_COLUMNS", ()))
    cols += list(extra)
    cols += list(BASIC_COLUMNS)
    cols += ["version"]
    return cols


def manifest_row(grain, file: str, size: float, size_definition: str) -> dict[str, Any]:
    """One manifest row for a grain already scaled to physical units (mm).

    Lengths, areas and volumes are in mm, mm², mm³ (the CSV headers say so:
    :mod:`grainforge.units`); a method's ``physical_info(info, scale)``, if it
    has one, converts its info values from model units.

    Parameters
    ----------
    grain : grainforge.grain.Grain
        The grain, scaled to mm (:func:`grainforge.fabrication.scale.to_size`).
    file : str
        Its file's name.
    size : float
        The size asked for, mm.
    size_definition : str
        What ``size`` measures (``equivalent``, ``sieve`` or ``longest``).

    Returns
    -------
    dict
        The manifest's columns (:func:`manifest_columns`) with the grain's values; ``seed`` is the grain's
        recorded seed (None where it was made from a Generator).
    """
    row: dict[str, Any] = {"file": file, "method": grain.method, "seed": grain.seed}
    row.update(as_dict(grain.params))
    row.update({"size": size, "size_definition": size_definition, "scale": grain.info.get("scale", 1.0)})
    info = {k: v for k, v in grain.info.items() if k != "scale"}
    physical = getattr(get(grain.method), "physical_info", None)
    if physical is not None:  # info in model units -> mm (e.g. DPA: R_g in primary sizes)
        info = physical(info, row["scale"])
    row.update(info)
    row.update(basic_descriptors(grain))
    row["version"] = grain.version
    return row


def encode_grain(
    method: str, params: Any, *, rng: RNGLike, name: str, fmt: str, size: float, size_definition: str,
) -> tuple[bytes, dict[str, Any]]:
    """Generate one grain, scale it to ``size`` and encode it: (file bytes, manifest row). Writes nothing.

    Parameters
    ----------
    method : str
        The generator's name.
    params : object
        An instance of the method's ``Params``.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The grain's randomness (:func:`grainforge.methods.generate`): an int is the grain's seed, recorded in
        the manifest row's ``seed`` (the same int, the same bytes as ever); None draws a seed and records it;
        a Generator records none.
    name : str
        The file's name, recorded in the row's ``file``.
    fmt : str
        Mesh format (``stl``, ``obj``, ``ply``).
    size : float
        The grain's size, mm.
    size_definition : str
        What ``size`` measures (``equivalent``, ``sieve`` or ``longest``).

    Returns
    -------
    data : bytes
        The mesh file's bytes.
    row : dict
        Its manifest row (:func:`manifest_row`).

    Raises
    ------
    grainforge.params.ParameterError
        If the grain cannot be made with ``params`` (naming the parameter).

    Examples
    --------
    >>> data, row = encode_grain("fso", get("fso").Params(subdivisions=2), rng=3, name="fso-0000.stl", fmt="stl",
    ...                          size=2.0, size_definition="equivalent")
    >>> row["file"], row["seed"], len(data) == 84 + 50 * 320, round(row["equivalent_diameter"], 6)
    ('fso-0000.stl', 3, True, 2.0)
    """
    grain = to_size(generate(method, params, rng), size, size_definition)
    return export_bytes(grain, fmt), manifest_row(grain, name, size, size_definition)


def planned_files(out: Path, method: str, count: int, fmt: str) -> list[Path]:
    """Every path a run would write (grain files, then the manifest).

    Parameters
    ----------
    out : pathlib.Path
        The output folder.
    method : str
        The generator's name.
    count : int
        Grains of the run.
    fmt : str
        Mesh format.

    Returns
    -------
    list of pathlib.Path
        ``count`` grain files (:func:`grain_file_name`), then ``manifest.csv``.
    """
    return [out / grain_file_name(method, i, fmt) for i in range(count)] + [out / MANIFEST]


def existing_outputs(out: Path, method: str, count: int, fmt: str) -> list[Path]:
    """The files a run of ``count`` grains would replace in ``out``: found by listing ``out``, not by
    building every planned name (memory does not grow with ``count``).

    Parameters
    ----------
    out : pathlib.Path
        The output folder (need not exist).
    method : str
        The generator's name.
    count : int
        Grains of the run.
    fmt : str
        Mesh format.

    Returns
    -------
    list of pathlib.Path
        The grain files of indices below ``count`` and the manifest that exist in ``out``, sorted.
    """
    if not out.is_dir():
        return []
    pattern = re.compile(rf"{re.escape(method)}-(\d{{4,}})\.{re.escape(fmt)}")
    found = []
    for p in out.iterdir():
        m = pattern.fullmatch(p.name)
        if (m and int(m.group(1)) < count and grain_file_name(method, int(m.group(1)), fmt) == p.name) \
                or p.name == MANIFEST:
            found.append(p)
    return sorted(found)


def earlier_run_files(out: Path) -> list[Path]:
    """Files the manifest already in ``out`` lists (an earlier run's grains), existing ones only.

    Parameters
    ----------
    out : pathlib.Path
        The output folder.

    Returns
    -------
    list of pathlib.Path
        Plain file names inside ``out`` only (a manifest cannot point elsewhere); empty without a readable
        manifest.
    """
    manifest = out / MANIFEST
    if not manifest.is_file():
        return []
    try:
        names = [row.get("file") or "" for row in read_manifest(manifest)]
    except ValueError:
        return []
    files = []
    for name in names:
        p = out / name
        # only plain names inside ``out`` (a manifest cannot make us delete elsewhere)
        if name and Path(name).name == name and not name.startswith(".") and p.is_file():
            files.append(p)
    return files


def write_run(
    method: str,
    params: Any,
    *,
    seeds: Sequence[int],
    out: str | Path,
    fmt: str = "stl",
    size: float = 10.0,
    size_definition: str = "equivalent",
    overwrite: bool = False,
    progress: Callable[[Iterable], Iterable] | None = None,
    extra_columns: Sequence[str] = (),
    row_extra: dict[str, Any] | None = None,
) -> int:
    """Generate grain ``i`` with ``seeds[i]``, scale it, write it and the manifest.

    Files are staged in a hidden folder inside ``out`` and moved into place
    only when every grain succeeded: a failure (bad parameter, a seed for
    which the amplitude is too large, an interrupt) leaves no new file behind.
    Memory does not grow with the number of grains: ``seeds`` may be a
    ``range`` of any length, and manifest rows are staged on disk.

    With ``overwrite``, the files an earlier manifest in ``out`` lists are
    removed when the new run succeeds (a shorter run leaves no grain that its
    manifest does not list).

    ``row_extra`` (e.g. the printer and the chosen resolution) is added to
    every manifest row; list its keys in ``extra_columns``.

    Parameters
    ----------
    method : str
        The generator's name.
    params : object
        An instance of the method's ``Params``, shared by every grain.
    seeds : sequence of int
        Grain ``i`` is made with ``rng=seeds[i]`` (:func:`encode_grain`) and that seed recorded in the manifest:
        data for regenerating it, one per grain (keyword-only).
    out : str or pathlib.Path
        The output folder (made if missing; keyword-only).
    fmt : str
        Mesh format (``stl``, ``obj``, ``ply``).
    size : float
        Each grain's size, mm.
    size_definition : str
        What ``size`` measures (``equivalent``, ``sieve`` or ``longest``).
    overwrite : bool
        Replace existing outputs (and remove the earlier manifest's grains this run does not replace).
    progress : callable, optional
        ``progress(iterable)`` wraps the grains as they are made (a bar).
    extra_columns : sequence of str
        Manifest columns for ``row_extra``'s keys.
    row_extra : dict, optional
        Added to every manifest row.

    Returns
    -------
    int
        The number of grains written.

    Raises
    ------
    FileExistsError
        If an output exists and ``overwrite`` is false (nothing is written).
    ValueError
        For bad parameters (named).
    """
    if fmt not in FORMATS:
        raise InputError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    check_target_size(size, size_definition)  # before anything is generated or written
    out = Path(out)
    count = len(seeds)
    if not overwrite:
        existing = existing_outputs(out, method, count, fmt)
        if existing:
            raise OutputExistsError(
                f"{existing[0]} exists ({len(existing)} output file(s) would be replaced); use {{overwrite}}",
                setting="overwrite")
    columns = manifest_columns(method, extra_columns)
    written = 0
    with staged(out) as stage:  # on success the stage is empty; on failure nothing new is left behind
        with open(stage / MANIFEST, "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh, lineterminator="\n")
            from ..units import UNITS, headers

            writer.writerow(headers(columns, UNITS))  # every header states its unit, as write_csv(units=True)
            iterator = enumerate(seeds)
            if progress is not None:
                iterator = progress(iterator)
            for i, seed in iterator:
                name = grain_file_name(method, i, fmt)
                data, row = encode_grain(method, params, rng=seed, name=name, fmt=fmt, size=size,
                                         size_definition=size_definition)
                (stage / name).write_bytes(data)
                row = {**row, **(row_extra or {})}
                writer.writerow([_cell(row.get(c)) for c in columns])
                written += 1
        earlier = set(earlier_run_files(out)) if overwrite else set()
        os.chmod(stage / MANIFEST, file_mode())
        with signals_held():  # the grains and the manifest appear together; a signal is answered after them
            for i in range(count):
                name = grain_file_name(method, i, fmt)
                (stage / name).replace(out / name)
                earlier.discard(out / name)
            (stage / MANIFEST).replace(out / MANIFEST)
            for p in sorted(earlier):  # the earlier run's grains that this run did not replace
                p.unlink(missing_ok=True)
    return written
