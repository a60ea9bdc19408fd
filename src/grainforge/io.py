"""Mesh export, manifests and atomic writes.

Every file grainforge writes goes through :func:`atomic_write`: the data is
written to a temporary file in the destination folder and renamed into place,
so an interrupted run never leaves a half-written file.
"""

from __future__ import annotations

import csv
import io as _io
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ._version import __version__

__all__ = ["FORMATS", "export_bytes", "atomic_write", "file_mode", "write_mesh", "write_csv", "read_mesh", "save_figure"]


def _as_trimesh(obj):
    import trimesh

    if isinstance(obj, trimesh.Trimesh):
        return obj
    return obj.mesh  # Grain


def _stl(mesh, header: str) -> bytes:
    from trimesh.exchange.stl import export_stl

    data = export_stl(mesh)
    head = header.encode("ascii", "replace")[:80].ljust(80, b" ")
    # A binary STL header must not begin with "solid" (readers would take it for ASCII).
    if head.lower().startswith(b"solid"):
        head = b"_" + head[:79]
    return head + data[80:]


def _obj(mesh, header: str) -> bytes:
    from trimesh.exchange.obj import export_obj

    text = export_obj(mesh, include_normals=False, include_color=False, include_texture=False, header=header)
    return text.encode("utf-8")


def _ply(mesh, header: str) -> bytes:
    from trimesh.exchange.ply import export_ply

    return export_ply(mesh, encoding="binary", include_attributes=False)


#: format name -> exporter(mesh, header) -> bytes
FORMATS: dict[str, Callable[[Any, str], bytes]] = {"stl": _stl, "obj": _obj, "ply": _ply}


def export_bytes(obj, fmt: str = "stl", header: str | None = None) -> bytes:
    """Encode a Grain or trimesh as ``fmt`` ("stl" binary, "obj" or "ply" binary).

    The output holds no timestamp: the same mesh always gives the same bytes.

    Examples
    --------
    >>> import grainforge
    >>> g = grainforge.fso(subdivisions=1, rng=0)
    >>> data = export_bytes(g, "stl")
    >>> len(data) == 84 + 50 * len(g.faces)
    True
    """
    try:
        exporter = FORMATS[fmt]
    except KeyError:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}") from None
    if header is None:
        header = f"grainforge {__version__}"
        method = getattr(obj, "method", None)
        if method is not None:
            header += f" {method} seed={getattr(obj, 'seed', None)}"
    return exporter(_as_trimesh(obj), header)


def file_mode() -> int:
    """0o666 less the process umask: the mode an ordinary ``open(path, "w")`` would give."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename.

    The file gets the permissions an ordinary write would give (umask honoured).
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def save_figure(fig, path: str | os.PathLike, *, dpi: float | None = None) -> Path:
    """Write a matplotlib figure as PNG (atomically) and close it.

    No "Software" metadata is written, so the same figure gives the same bytes.
    """
    import matplotlib.pyplot as plt

    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi="figure" if dpi is None else dpi, metadata={"Software": None})
    plt.close(fig)
    return atomic_write(path, buf.getvalue())


def write_mesh(obj, path: str | os.PathLike, fmt: str | None = None) -> Path:
    """Export a Grain or trimesh to ``path`` atomically (format from the suffix if not given)."""
    path = Path(path)
    fmt = fmt or path.suffix.lstrip(".").lower()
    return atomic_write(path, export_bytes(obj, fmt))


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (tuple, list)):
        return " ".join(_cell(x) for x in v)
    return str(v)


def csv_text(rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """Rows as CSV text (floats written with full precision, ``None`` empty)."""
    rows = list(rows)
    if columns is None:
        columns = []
        for r in rows:
            columns.extend(k for k in r if k not in columns)
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    return buf.getvalue()


def write_csv(path: str | os.PathLike, rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None) -> Path:
    """Write rows of dicts to a CSV file atomically."""
    return atomic_write(path, csv_text(rows, columns))


def read_mesh(path: str | os.PathLike):
    """Read a mesh file (STL, OBJ, PLY, 3MF, ...) as a single trimesh.

    Raises
    ------
    ValueError
        If the file is missing, unreadable, corrupt or holds no triangles.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt input
        raise ValueError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError(f"{path}: holds no triangles")
    return loaded
