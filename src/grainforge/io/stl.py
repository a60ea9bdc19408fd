"""Binary and ASCII STL: the one reader, the one record layout, the writers' header.

- :func:`read_stl` reads an STL (binary or ASCII) with trimesh's parser
  (:func:`trimesh.exchange.stl.load_stl`) after :func:`check_stl` has
  refused what is not a consistent STL, with a message naming the problem.
  The mesh is the file's triangle soup (``process=False``: no vertex is
  merged); the face normals are computed from the vertices, never taken from
  the file.
- :data:`STL_DTYPE` is the 50-byte record; :func:`stl_triangles` makes the
  records of a mesh, :class:`STLWriter` streams them into one file part by
  part (trays).  :func:`stl_header` is the 80-byte header every binary STL
  grainforge writes starts with.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .._version import __version__
from ..errors import FileFormatError, InputError
from .sniff import what_is

__all__ = ["STL_DTYPE", "TRUNCATED_FACTOR", "stl_header", "stl_triangles", "STLWriter", "check_stl", "read_stl",
           "read_stl_parts"]


def stl_header(text: str) -> bytes:
    """The 80-byte header of a binary STL: ``text`` in ASCII, padded; never starting with ``solid``
    (readers would take the file for ASCII STL).

    Parameters
    ----------
    text : str
        Header text (non-ASCII characters become ``?``; cut at 80 bytes).

    Returns
    -------
    bytes
        Exactly 80 bytes, space-padded.

    Examples
    --------
    >>> stl_header("solid grain")[:12]
    b'_solid grain'
    >>> len(stl_header("x" * 100))
    80
    """
    head = text.encode("ascii", "replace")[:80].ljust(80, b" ")
    if head.lower().startswith(b"solid"):
        head = b"_" + head[:79]
    return head


STL_DTYPE = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])


def stl_triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Binary-STL records (50 bytes each) of a mesh, with unit face normals.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions (written as float32).
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise from outside.

    Returns
    -------
    (F,) structured array of dtype ``normal (3,) f4, vertices (3, 3) f4, attr u2``
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    out = np.zeros(len(tri), dtype=STL_DTYPE)
    out["normal"] = n
    out["vertices"] = tri
    return out


class STLWriter:
    """Write a binary STL one part at a time (header, triangles, then the count is patched)."""

    def __init__(self, file: BinaryIO, header: str = ""):
        self._fh = file
        head = stl_header(header or f"grainforge {__version__} tray")
        self._start = file.tell()
        file.write(head + struct.pack("<I", 0))
        self.triangles = 0
        self.count = 0

    def add_object(self, name: str, records: np.ndarray, translation: Sequence[float] = (0.0, 0.0, 0.0)) -> int:
        """Append a part (records from :func:`stl_triangles`, in part coordinates) moved by ``translation``.

        Parameters
        ----------
        name : str
            The part's name (binary STL has no place for it; kept for the writers' common interface).
        records : (F,) ndarray of :data:`STL_DTYPE`
            The part's triangles, from :func:`stl_triangles`.
        translation : (3,) sequence of float, default (0, 0, 0)
            Where the part goes, in the file's unit.

        Returns
        -------
        int
            The number of parts written so far.
        """
        rec = records.copy()
        rec["vertices"] += np.asarray(translation, dtype=np.float64).astype(np.float32)
        self._fh.write(rec.tobytes())
        self.triangles += len(rec)
        self.count += 1
        return self.count

    def close(self) -> None:
        if self.triangles >= 2**32:
            raise InputError(f"binary STL holds at most 2^32 - 1 triangles, got {self.triangles}; use .3mf")
        end = self._fh.tell()
        self._fh.seek(self._start + 80)
        self._fh.write(struct.pack("<I", self.triangles))
        self._fh.seek(end)

    def abort(self) -> None:
        """Stop without patching the count (the caller deletes the partial file)."""

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()


#: a binary STL whose header announces at most this many times the file's size is called truncated;
#: beyond, the count is taken as noise (random bytes, another kind of file)
TRUNCATED_FACTOR = 64


def check_stl(path: str | os.PathLike) -> None:
    """Refuse an STL file whose bytes are neither a consistent binary STL nor ASCII STL.

    A binary STL is an 80-byte header, a facet count ``n`` and ``n`` records
    of 50 bytes: the file size must be ``84 + 50 n``.  An ASCII STL starts with
    ``solid`` and holds ``facet``/``vertex`` lines.

    Parameters
    ----------
    path : str or os.PathLike
        The file (it must exist).

    Raises
    ------
    ValueError
        Saying what is wrong with the file (truncated, wrong facet count,
        another kind of file, empty).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.stl"
    >>> _ = p.write_bytes(b"x" * 80 + (3).to_bytes(4, "little") + b"y" * 60)
    >>> check_stl(p)
    Traceback (most recent call last):
    ...
    grainforge.errors.FileFormatError: ...t.stl: truncated binary STL: the header announces 3 facets (234 bytes) but the file has 144 bytes
    """
    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as fh:
        head = fh.read(1024)
    if size == 0:
        raise InputError(f"{path}: empty file")
    other = what_is(head)
    if other is not None:
        raise FileFormatError(f"{path}: not an STL file (it is {other})")
    if size >= 84:
        n = int.from_bytes(head[80:84], "little") if len(head) >= 84 else -1
        if size == 84 + 50 * n:
            if n == 0:
                raise InputError(f"{path}: binary STL with no facets")
            return
    if head.lstrip()[:5].lower() == b"solid":
        try:
            text = head.decode("ascii")
        except UnicodeDecodeError:
            text = ""
        if "facet" in text or "endsolid" in text or size < 1024:
            return  # ASCII STL (trimesh parses and validates it)
    if size < 84:
        raise FileFormatError(f"{path}: not an STL file ({size} bytes: too short for a binary STL, and not ASCII STL)")
    n = int.from_bytes(head[80:84], "little")
    expected = 84 + 50 * n
    if size < expected <= TRUNCATED_FACTOR * size:  # plausibly the start of a real binary STL
        raise FileFormatError(f"{path}: truncated binary STL: the header announces {n} facets "
                             f"({expected} bytes) but the file has {size} bytes")
    if (size - 84) % 50 == 0:
        raise FileFormatError(f"{path}: corrupt binary STL: the header announces {n} facets but the file holds "
                             f"{(size - 84) // 50}")
    raise FileFormatError(f"{path}: not an STL file (neither ASCII STL nor a binary STL: facet count {n} in the "
                         f"header does not match the file size of {size} bytes)")


def read_stl(path: str | os.PathLike):
    """An STL file (binary or ASCII) as a triangle-soup ``trimesh.Trimesh``, checked.

    Parameters
    ----------
    path : str or os.PathLike
        A binary or ASCII STL.

    Returns
    -------
    trimesh.Trimesh
        Three vertices per face, not merged, not processed.

    Raises
    ------
    ValueError
        From :func:`check_stl`, naming what is wrong with the file; other
        parse errors are the caller's to word (trimesh raises many types).

    Examples
    --------
    >>> import tempfile, pathlib, trimesh
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "box.stl"
    >>> box = trimesh.creation.box()
    >>> _ = p.write_bytes(stl_header("box") + struct.pack("<I", 12) + stl_triangles(box.vertices, box.faces).tobytes())
    >>> m = read_stl(p)
    >>> len(m.vertices), len(m.faces), round(float(m.volume), 6)
    (36, 12, 1.0)
    """
    import trimesh
    from trimesh.exchange.stl import load_stl

    path = Path(path)
    check_stl(path)
    with path.open("rb") as fh:
        kw = load_stl(fh)
    return trimesh.Trimesh(kw["vertices"], kw["faces"], process=False, validate=False)


def read_stl_parts(path) -> list:
    """The connected bodies of an STL (vertices merged exactly), in file order, as
    :class:`grainforge.io.threemf.Part` named ``body-K``.

    Parameters
    ----------
    path : str or os.PathLike
        A binary or ASCII STL.

    Returns
    -------
    list of grainforge.io.threemf.Part
        One per edge-connected body, every face kept (degenerate ones too).

    Raises
    ------
    ValueError
        From :func:`check_stl`.
    """
    from ..geometry.solid import split_bodies
    from .threemf import Part

    mesh = read_stl(path)
    bodies = split_bodies(mesh.vertices, mesh.faces, drop_degenerate=False)
    return [Part(f"body-{k}", v, f) for k, (v, f) in enumerate(bodies)]
