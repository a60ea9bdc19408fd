"""Generate a run of grains into a folder, with a manifest.

This is the library side of ``grainforge generate``: it validates, generates,
scales, measures and writes, and knows nothing of the command line.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from .analysis.descriptors import BASIC_COLUMNS, basic_descriptors
from .fabrication.scale import check_size, to_size
from .io import FORMATS, export_bytes, write_csv
from .methods import generate, get
from .params import as_dict, specs

__all__ = ["grain_file_name", "manifest_row", "manifest_columns", "encode_grain", "write_run", "planned_files"]

MANIFEST = "manifest.csv"


def grain_file_name(method: str, index: int, fmt: str) -> str:
    """``fso-0000.stl`` style names (at least four digits)."""
    return f"{method}-{index:04d}.{fmt}"


def manifest_columns(method: str, extra: Sequence[str] = ()) -> list[str]:
    """Manifest columns for ``method``: identity, every parameter, scale, measures."""
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
    method: str, params: Any, seed: int, name: str, *, fmt: str, size: float, size_definition: str,
) -> tuple[bytes, dict[str, Any]]:
    """Generate one grain, scale it to ``size`` and encode it: (file bytes, manifest row). Writes nothing."""
    grain = to_size(generate(method, params, int(seed)), size, size_definition)
    return export_bytes(grain, fmt), manifest_row(grain, name, size, size_definition)


def planned_files(out: Path, method: str, count: int, fmt: str) -> list[Path]:
    """Every path a run would write (grain files, then the manifest)."""
    return [out / grain_file_name(method, i, fmt) for i in range(count)] + [out / MANIFEST]


def write_run(
    method: str,
    params: Any,
    seeds: Sequence[int],
    out: str | Path,
    *,
    fmt: str = "stl",
    size: float = 10.0,
    size_definition: str = "equivalent",
    overwrite: bool = False,
    progress: Callable[[Iterable], Iterable] | None = None,
    extra_columns: Sequence[str] = (),
    row_extra: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Generate grain ``i`` with ``seeds[i]``, scale it, write it and the manifest.

    Files are staged in a hidden folder inside ``out`` and moved into place
    only when every grain succeeded: a failure (bad parameter, a seed for
    which the amplitude is too large, ...) leaves no new file behind.

    ``row_extra`` (e.g. the printer and the chosen resolution) is added to
    every manifest row; list its keys in ``extra_columns``.

    Returns
    -------
    list of dict
        The manifest rows.

    Raises
    ------
    FileExistsError
        If an output exists and ``overwrite`` is false (nothing is written).
    ValueError
        For bad parameters (named).
    """
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    check_size(size, size_definition)  # before anything is generated or written
    out = Path(out)
    targets = planned_files(out, method, len(seeds), fmt)
    if not overwrite:
        existing = [p for p in targets if p.exists()]
        if existing:
            raise FileExistsError(
                f"{existing[0]} exists ({len(existing)} output file(s) would be replaced); use --overwrite"
            )
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".grainforge-staging-", dir=out))
    rows: list[dict[str, Any]] = []
    try:
        iterator = enumerate(seeds)
        if progress is not None:
            iterator = progress(iterator)
        for i, seed in iterator:
            name = grain_file_name(method, i, fmt)
            data, row = encode_grain(method, params, seed, name, fmt=fmt, size=size, size_definition=size_definition)
            (stage / name).write_bytes(data)
            rows.append({**row, **(row_extra or {})})
        for row in rows:
            (stage / row["file"]).replace(out / row["file"])
        write_csv(out / MANIFEST, rows, manifest_columns(method, extra_columns), units=True)
    finally:  # on success the stage is empty; on failure nothing new is left behind
        shutil.rmtree(stage, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()
    return rows
