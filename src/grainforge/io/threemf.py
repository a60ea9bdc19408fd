"""3MF print files: a streaming writer (one named object per part) and a reader.

The writer takes one part at a time and keeps only a few numbers per part in
memory, so a tray of thousands of grains is written with bounded memory (its
binary-STL counterpart is :class:`grainforge.io.stl.STLWriter`):

- :class:`ThreeMFWriter` streams the model XML into a deflated zip entry
  (``3D/3dmodel.model``); each part is an ``<object>`` with its own name and
  mesh, placed by a ``<build><item transform=...>``.  The mesh XML of a part
  can be made in a worker process (:func:`mesh_xml`).

:func:`read_3mf` reads a 3MF back with the standard library only (trimesh's
3MF reader needs lxml) and returns the placed parts.

Examples
--------
>>> import io, trimesh
>>> box = trimesh.creation.box()
>>> buf = io.BytesIO()
>>> with ThreeMFWriter(buf) as w:
...     a = w.add_object("box-a", mesh_xml(box.vertices, box.faces))
...     b = w.add_object("box-b", mesh_xml(box.vertices, box.faces), translation=(3.0, 0, 0))
>>> parts = read_3mf(buf)
>>> [(p.name, len(p.faces), round(float(p.vertices[:, 0].min()), 3)) for p in parts]
[('box-a', 12, -0.5), ('box-b', 12, 2.5)]
"""

from __future__ import annotations

import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from xml.etree import ElementTree
from xml.sax.saxutils import quoteattr

import numpy as np

from .._version import __version__
from ..errors import FileFormatError, InputError

__all__ = [
    "ThreeMFWriter", "mesh_xml", "read_3mf", "read_3mf_file", "Part",
]

_NS = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
_MODEL = "3D/3dmodel.model"
_CONTENT_TYPES = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    "</Types>"
)
_RELS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>'
    "</Relationships>"
)
#: fixed timestamp: the same tray always gives the same bytes
_DATE = (1980, 1, 1, 0, 0, 0)


def mesh_xml(vertices: np.ndarray, faces: np.ndarray, decimals: int = 5) -> bytes:
    """The ``<mesh>`` element of a 3MF object, as UTF-8 bytes.

    Coordinates are written with ``decimals`` digits after the point
    (default 5: 10 nm in millimetres, far below any printer).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions in mm.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise from outside.
    decimals : int, default 5
        Digits after the point of each coordinate.

    Returns
    -------
    bytes
        ASCII XML ``<mesh>…</mesh>``.

    Examples
    --------
    >>> mesh_xml(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]]), np.array([[0, 1, 2]]))[:61]
    b'<mesh><vertices><vertex x="0.00000" y="0.00000" z="0.00000"/>'
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = int(decimals)
    vt = f'<vertex x="%.{d}f" y="%.{d}f" z="%.{d}f"/>'
    text = ["<mesh><vertices>", (vt * len(v)) % tuple(v.ravel().tolist()), "</vertices><triangles>",
            _triangles_xml(f.tobytes(), len(f)), "</triangles></mesh>"]
    return "".join(text).encode("ascii")


@lru_cache(maxsize=8)
def _triangles_xml(faces: bytes, n: int) -> str:
    # grains generated on the same geodesic sphere share their triangles: format them once
    f = np.frombuffer(faces, dtype=np.int64)
    return ('<triangle v1="%d" v2="%d" v3="%d"/>' * n) % tuple(f.tolist())


class ThreeMFWriter:
    """Write a 3MF package one object at a time.

    Parameters
    ----------
    file : path or binary file object
        Seekable destination.
    compresslevel : int
        Deflate level of the model entry (1 = fastest; the XML compresses ~3x anyway).
    """

    def __init__(self, file, compresslevel: int = 1):
        self._zip = zipfile.ZipFile(file, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=compresslevel)
        for name, text in (("[Content_Types].xml", _CONTENT_TYPES), ("_rels/.rels", _RELS)):
            self._zip.writestr(zipfile.ZipInfo(name, _DATE), text)
        info = zipfile.ZipInfo(_MODEL, _DATE)
        info.compress_type = zipfile.ZIP_DEFLATED
        self._model = self._zip.open(info, "w", force_zip64=True)
        self._model.write(
            ('<?xml version="1.0" encoding="UTF-8"?>\n'
             f'<model unit="millimeter" xml:lang="en-US" xmlns="{_NS}">'
             f'<metadata name="Application">grainforge {__version__}</metadata><resources>').encode()
        )
        self._items: list[tuple[int, tuple[float, float, float]]] = []
        self.count = 0

    def add_object(self, name: str, mesh: bytes, translation: Sequence[float] = (0.0, 0.0, 0.0)) -> int:
        """Append one named object (``mesh`` from :func:`mesh_xml`) placed at ``translation``; return its id.

        Parameters
        ----------
        name : str
            The object's name (XML-escaped; slicers show it).
        mesh : bytes
            The ``<mesh>`` element (:func:`mesh_xml`), in part coordinates (mm).
        translation : (3,) sequence of float, default (0, 0, 0)
            The build item's translation, in mm.

        Returns
        -------
        int
            The object id, 1, 2, … in order.
        """
        self.count += 1
        oid = self.count
        self._model.write(f'<object id="{oid}" name={quoteattr(str(name))} type="model">'.encode())
        self._model.write(mesh)
        self._model.write(b"</object>")
        self._items.append((oid, tuple(float(t) for t in translation)))
        return oid

    def close(self) -> None:
        """Write the build section and finish the package."""
        if self._model is None:
            return
        self._model.write(b"</resources><build>")
        parts = []
        for oid, (x, y, z) in self._items:
            parts.append(f'<item objectid="{oid}" transform="1 0 0 0 1 0 0 0 1 {x!r} {y!r} {z!r}"/>')
            if len(parts) >= 4096:
                self._model.write("".join(parts).encode())
                parts = []
        self._model.write(("".join(parts) + "</build></model>").encode())
        self._model.close()
        self._model = None
        self._zip.close()

    def abort(self) -> None:
        """Stop without a build section, releasing the file (the caller deletes the partial file)."""
        if self._model is None:
            return
        try:
            self._model.close()
            self._zip.close()
        except Exception:  # pragma: no cover - best effort on the error path
            pass
        self._model = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()


@dataclass(frozen=True)
class Part:
    """One placed part read back from a print file."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray

    @property
    def mesh(self):
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False, validate=False)


def read_3mf(file) -> list[Part]:
    """Every build item of a 3MF file as a placed :class:`Part` (object meshes with their transforms).

    Only what grainforge writes is supported in full: mesh objects (no
    components) placed by build items with an affine ``transform``.

    Parameters
    ----------
    file : path or binary file object
        A 3MF package (a zip holding ``3D/3dmodel.model``).

    Returns
    -------
    list of Part
        One per build item, in build order, vertices placed by the item's transform (the model's unit).

    Raises
    ------
    ValueError
        If the file is not a 3MF package.
    """
    try:
        zf = zipfile.ZipFile(file)
    except (zipfile.BadZipFile, OSError) as exc:
        raise FileFormatError(f"not a 3MF file ({exc})") from None
    with zf:
        names = {n.lower(): n for n in zf.namelist()}
        if _MODEL.lower() not in names:
            raise FileFormatError("not a 3MF file (no 3D/3dmodel.model)")
        objects: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        items: list[tuple[str, np.ndarray]] = []
        with zf.open(names[_MODEL.lower()]) as fh:
            for _, el in ElementTree.iterparse(fh, events=("end",)):
                tag = el.tag.rsplit("}", 1)[-1]
                if tag == "object":
                    mesh = next((c for c in el if c.tag.endswith("mesh")), None)
                    if mesh is not None:
                        vs = next(c for c in mesh if c.tag.endswith("vertices"))
                        ts = next(c for c in mesh if c.tag.endswith("triangles"))
                        v = np.array([[float(a.get("x")), float(a.get("y")), float(a.get("z"))] for a in vs])
                        f = np.array([[int(a.get("v1")), int(a.get("v2")), int(a.get("v3"))] for a in ts],
                                     dtype=np.int64)
                        objects[el.get("id")] = (el.get("name") or el.get("id"), v.reshape(-1, 3), f.reshape(-1, 3))
                    el.clear()
                elif tag == "item":
                    m = np.eye(4)
                    t = el.get("transform")
                    if t:
                        vals = np.array([float(x) for x in t.split()]).reshape(4, 3)
                        m[:3, :3] = vals[:3].T
                        m[:3, 3] = vals[3]
                    items.append((el.get("objectid"), m))
    parts = []
    for oid, m in items:
        if oid not in objects:
            raise InputError(f"3MF build item refers to missing object {oid}")
        name, v, f = objects[oid]
        parts.append(Part(name, v @ m[:3, :3].T + m[:3, 3], f))
    return parts


def read_3mf_file(path) -> list[Part]:
    """The parts (build items) of the 3MF file ``path``, checked.

    :func:`grainforge.io.read_parts` reads any mesh file as parts; this is its 3MF branch.

    Parameters
    ----------
    path : str or os.PathLike
        A 3MF file.

    Returns
    -------
    list of Part
        As :func:`read_3mf`, at least one.

    Raises
    ------
    ValueError
        If the file is missing, unreadable, corrupt, holds no objects or non-finite coordinates.
    """
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        parts = read_3mf(path)
    except (ValueError, ElementTree.ParseError) as exc:
        raise FileFormatError(f"{path}: {exc}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({(exc.strerror or type(exc).__name__).lower()})") from None
    except Exception as exc:  # a malformed package: missing elements or attributes, bad indices
        detail = " ".join(str(exc).split())
        raise FileFormatError(f"{path}: corrupt 3MF file ({type(exc).__name__}: {detail})") from None
    if not parts:
        raise InputError(f"{path}: holds no objects")
    for part in parts:
        if not np.isfinite(part.vertices).all():
            raise InputError(f"{path}: has non-finite (NaN or infinite) vertex coordinates")
    return parts
