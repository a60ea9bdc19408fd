"""Every reader and writer of files: mesh export, manifests, atomic writes, STL and 3MF.

Every file grainforge writes goes through :func:`atomic_write`: the data is
written to a temporary file in the destination folder and renamed into place,
so an interrupted run never leaves a half-written file.  The format modules
below this package hold the rest: :mod:`grainforge.io.stl` (the one STL
reader, the record layout and the streaming tray writer) and
:mod:`grainforge.io.threemf` (3MF writing and reading).  This package imports
nothing above it: fabrication, dem and the commands import it.
"""

from __future__ import annotations

import contextlib
import csv
import io as _io
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import FileFormatError, InputError
from .inputs import MESH_SUFFIXES
from .sniff import what_is
from .stl import check_stl, read_stl, stl_header

__all__ = ["FORMATS", "READABLE_MESHES", "export_bytes", "atomic_file", "atomic_write", "file_mode", "write_mesh", "write_csv", "read_mesh", "read_parts", "check_stl", "save_figure"]


def _as_trimesh(obj):
    import trimesh

    if isinstance(obj, trimesh.Trimesh):
        return obj
    return obj.mesh  # Grain


def _stl(mesh, header: str) -> bytes:
    from trimesh.exchange.stl import export_stl

    return stl_header(header) + export_stl(mesh)[80:]


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

    Parameters
    ----------
    obj : Grain or trimesh.Trimesh
        The mesh, in its own units (grainforge writes millimetres).
    fmt : {"stl", "obj", "ply"}, default "stl"
        The format (:data:`FORMATS`).
    header : str, optional
        The STL header / OBJ comment (default ``grainforge VERSION [METHOD seed=SEED]``; PLY has none).

    Returns
    -------
    bytes

    Raises
    ------
    ValueError
        If ``fmt`` is not a key of :data:`FORMATS`.

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
        raise InputError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}") from None
    if header is None:
        header = f"grainforge {__version__}"
        method = getattr(obj, "method", None)
        if method is not None:
            header += f" {method} seed={getattr(obj, 'seed', None)}"
    return exporter(_as_trimesh(obj), header)


def file_mode() -> int:
    """0o666 less the process umask: the mode an ordinary ``open(path, "w")`` would give.

    Returns
    -------
    int
        Permission bits, e.g. ``0o644`` under the usual umask 022.
    """
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike):
    """A temporary path beside ``path`` to write to; renamed onto ``path`` when the block ends without an
    exception, removed otherwise (an interrupt included). The file gets the permissions an ordinary
    write would give (umask honoured).

    Parameters
    ----------
    path : str or os.PathLike
        The final file; its folder is created if missing.

    Yields
    ------
    Path
        The temporary file (``.NAME.XXXX.tmp`` in the same folder) to write.

    Examples
    --------
    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_file(target) as tmp:
    ...     _ = tmp.write_text("x")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('x', ['a.txt'])
    """
    from ..runtime.staging import signals_held

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        with signals_held():  # a signal between the file's creation and this block's clean-up waits for both
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            os.close(fd)
        yield Path(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
        raise


def atomic_write(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename (:func:`atomic_file`).

    Parameters
    ----------
    path : str or os.PathLike
        The final file; its folder is created if missing.
    data : bytes or str
        The content (a str is written as UTF-8).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    if isinstance(data, str):
        data = data.encode("utf-8")
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)
    return path


def save_figure(fig, path: str | os.PathLike, *, dpi: float | None = None, description: str | None = None) -> Path:
    """Write a matplotlib figure (atomically) and close it: JPEG for ``.jpg``/``.jpeg``, PNG otherwise.

    No "Software" metadata is written, so the same figure gives the same bytes.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        Closed after writing.
    path : str or os.PathLike
        The image file (``.jpg``/``.jpeg`` for JPEG at quality 92, anything else PNG).
    dpi : float, optional
        Resolution in dots per inch (default: the figure's own).
    description : str, optional
        A PNG's ``Description`` text (what the figure shows, e.g. its caption); not written into a JPEG.

    Returns
    -------
    Path
        ``path``.
    """
    import matplotlib.pyplot as plt

    buf = _io.BytesIO()
    if Path(path).suffix.lower() in (".jpg", ".jpeg"):
        fig.savefig(buf, format="jpeg", dpi="figure" if dpi is None else dpi, pil_kwargs={"quality": 92})
    else:
        metadata = {"Software": None, **({"Description": description} if description else {})}
        fig.savefig(buf, format="png", dpi="figure" if dpi is None else dpi, metadata=metadata)
    plt.close(fig)
    return atomic_write(path, buf.getvalue())


def write_mesh(obj, path: str | os.PathLike, fmt: str | None = None) -> Path:
    """Export a Grain or trimesh to ``path`` atomically (format from the suffix if not given).

    Parameters
    ----------
    obj : Grain or trimesh.Trimesh
        The mesh, in its own units (grainforge writes millimetres).
    path : str or os.PathLike
        The file to write.
    fmt : {"stl", "obj", "ply"}, optional
        Default: ``path``'s suffix.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If the format is not one of :data:`FORMATS`.
    """
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


def csv_text(
    rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None, *,
    units: bool | Mapping[str, str] = False,
) -> str:
    """Rows as CSV text (floats written with full precision, ``None`` empty).

    With ``units=True`` every header states its unit (``volume_mm3``; see :mod:`grainforge.units`);
    ``units`` may also be a ``{column: unit suffix}`` mapping of the file's own.
    """
    rows = list(rows)
    if columns is None:
        columns = []
        for r in rows:
            columns.extend(k for k in r if k not in columns)
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    if units:
        from ..units import UNITS, headers

        w.writerow(headers(columns, UNITS if units is True else units))
    else:
        w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    return buf.getvalue()


def write_csv(
    path: str | os.PathLike, rows: Iterable[Mapping[str, Any]], columns: Sequence[str] | None = None,
    *, units: bool | Mapping[str, str] = False,
) -> Path:
    """Write rows of dicts to a CSV file atomically (``units``: see :func:`csv_text`).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    rows : iterable of mapping
        One dict per row (missing keys and ``None`` are written empty; floats with full precision).
    columns : sequence of str, optional
        Column order (default: the keys in order of first appearance).
    units : bool or mapping of str to str, default False
        Suffix each header with its unit (:mod:`grainforge.units`).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import tempfile
    >>> p = write_csv(Path(tempfile.mkdtemp()) / "t.csv", [{"size": 2.0, "n": 3}], units=True)
    >>> p.read_text().splitlines()
    ['size_mm,n', '2.0,3']
    """
    return atomic_write(path, csv_text(rows, columns, units=units))


#: the mesh formats every command reads (named in the message for a file of another kind)
READABLE_MESHES = ", ".join(s.lstrip(".").upper() for s in MESH_SUFFIXES)

def read_mesh(path: str | os.PathLike):
    """Read a mesh file (STL, OBJ, PLY, 3MF, ...) as a single trimesh.

    Parameters
    ----------
    path : str or os.PathLike
        A mesh file (STL, OBJ, PLY, 3MF, ... :data:`READABLE_MESHES`), coordinates in mm.

    Returns
    -------
    trimesh.Trimesh
        Not processed (no vertex merged; an STL is its triangle soup); a 3MF's build items concatenated.

    Raises
    ------
    ValueError
        If the file is missing, unreadable, corrupt, holds no triangles,
        non-finite coordinates or coordinates so far from the origin that float32
        loses the shape (:func:`grainforge.geometry.solid.precision_problem`); the message
        says what is wrong with the file.
    """
    import trimesh

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a mesh file")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".stl":
            loaded = read_stl(path)
        elif suffix == ".3mf":
            from .threemf import read_3mf_file

            parts = read_3mf_file(path)
            loaded = trimesh.util.concatenate(
                [trimesh.Trimesh(p.vertices, p.faces, process=False, validate=False) for p in parts])
        else:
            with path.open("rb") as fh:
                head = fh.read(16)
            other = what_is(head)
            if other is not None:
                raise FileFormatError(f"{path}: not a mesh file (it is {other}); mesh files read: {READABLE_MESHES}")
            loaded = trimesh.load(path, force="mesh", process=False)
    except ValueError as exc:
        if str(exc).startswith(f"{path}:"):  # ours: it names the file already
            raise
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise FileFormatError(f"{path}: corrupt or unsupported mesh file ({detail})") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({(exc.strerror or type(exc).__name__).lower()})") from None
    except Exception as exc:  # trimesh raises many types for corrupt input
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise FileFormatError(f"{path}: corrupt or unsupported mesh file ({detail})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: holds no triangles")
    if not np.isfinite(np.asarray(loaded.vertices)).all():
        raise InputError(f"{path}: has non-finite (NaN or infinite) vertex coordinates")
    _check_precision(path, loaded.vertices)
    return loaded


def _check_precision(path: Path, vertices, what: str = "the mesh") -> None:
    """Refuse coordinates so far from the origin that float32 loses the shape (:func:`grainforge.geometry.solid.precision_problem`)."""
    from ..geometry.solid import precision_problem

    problem = precision_problem(vertices, what)
    if problem is not None:
        raise InputError(f"{path}: {problem}")


def read_parts(path: str | os.PathLike) -> list:
    """The parts of a mesh file: every build item of a 3MF, the single mesh of an STL/OBJ/PLY.

    Parameters
    ----------
    path : str or os.PathLike
        A mesh file (:data:`READABLE_MESHES`).

    Returns
    -------
    list of grainforge.io.threemf.Part
        Named parts; an STL's triangle soup has its exactly coincident vertices merged.

    Raises
    ------
    ValueError
        If the file is missing, unreadable, holds no triangles or a part too far
        from the origin for float32 (as :func:`read_mesh`).
    """
    from .threemf import Part, read_3mf_file

    path = Path(path)
    if path.suffix.lower() == ".3mf":
        parts = read_3mf_file(path)
        for part in parts:
            _check_precision(path, part.vertices, f"part {part.name}")
        return parts
    mesh = read_mesh(path)  # (checks the precision)
    # STL stores a triangle soup: merge exactly coincident vertices so topology can be checked
    from ..geometry.solid import unique_rows

    v, inv = unique_rows(np.asarray(mesh.vertices, dtype=np.float64))
    f = inv[np.asarray(mesh.faces, dtype=np.int64)]
    return [Part(path.stem, v, f)]
