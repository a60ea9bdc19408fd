"""Reading 3D images (a μCT scan's labelled or binary volume) slab by slab, and writing label images.

A volume is read a few slices at a time, never whole: :func:`open_volume` returns a :class:`Volume` whose
:meth:`Volume.read` gives slices ``z0 … z1 − 1`` as an array.  Formats:

- ``.npy`` (:func:`numpy.load` with ``mmap_mode="r"``: the header is read and the slices are mapped);
- raw binary (any other suffix, ``.raw`` typically), given its shape ``(Z, Y, X)`` and dtype;
- a multi-page TIFF (``.tif``/``.tiff``) or a folder of single-slice TIFF files (sorted by name, numbers
  compared as numbers), through `tifffile` (the ``scan`` extra: ``pip install 'grainforge[scan]'``).  An
  uncompressed TIFF is memory-mapped, a compressed one read a page at a time.  The voxel size is read from
  the TIFF's ImageJ metadata or resolution tags where present (``unit`` µm or mm).

Axes are the image's own: ``(Z, Y, X)``, slices first, as tifffile and :func:`numpy.save` store them.

Examples
--------
>>> import tempfile, pathlib
>>> import numpy as np
>>> p = pathlib.Path(tempfile.mkdtemp()) / "labels.npy"
>>> np.save(p, np.arange(24, dtype=np.uint16).reshape(2, 3, 4))
>>> v = open_volume(p)
>>> v.shape, v.dtype.name, int(v.read(1, 2).sum())
((2, 3, 4), 'uint16', 210)
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

__all__ = ["Volume", "open_volume", "write_labels", "TIFF_SUFFIXES", "LABEL_SUFFIXES", "tifffile_module"]

#: suffixes read as TIFF images (a folder is read as its TIFF slices)
TIFF_SUFFIXES = (".tif", ".tiff")
#: suffixes :func:`write_labels` writes
LABEL_SUFFIXES = (".npy", ".tif", ".tiff")
#: how a missing tifffile is reported
TIFFFILE_HINT = "reading TIFF images needs tifffile: pip install 'grainforge[scan]' (or pip install tifffile)"


def tifffile_module():
    """tifffile, imported on first use; a missing one is one line saying how to install it.

    Returns
    -------
    module
        ``tifffile``.

    Raises
    ------
    ValueError
        If tifffile is not installed (:data:`TIFFFILE_HINT`).
    """
    try:
        import tifffile
    except ImportError:
        raise InputError(TIFFFILE_HINT) from None
    return tifffile


class Volume:
    """A 3D image read slab by slab.

    Attributes
    ----------
    path : Path
    shape : tuple of int
        ``(Z, Y, X)``.
    dtype : numpy.dtype
    voxel_size_um : float or None
        From the file's metadata (TIFF), if it says.
    """

    def __init__(self, path, shape, dtype, reader, voxel_size_um=None, array=None):
        self.path = Path(path)
        self.shape = tuple(int(s) for s in shape)
        self.dtype = np.dtype(dtype)
        self._reader = reader
        self.voxel_size_um = voxel_size_um
        self._array = array

    @classmethod
    def from_array(cls, array, name: str = "<array>") -> Volume:
        """A volume over an array already in memory (a segmentation's labels).

        Parameters
        ----------
        array : array_like
            A ``(Z, Y, X)`` image; kept by reference, not copied.
        name : str, default "<array>"
            Stands for the path in messages.

        Returns
        -------
        Volume

        Examples
        --------
        >>> Volume.from_array(np.zeros((2, 2, 2), np.uint8)).read(0, 1).shape
        (1, 2, 2)
        """
        a = np.asarray(array)
        return cls(name, a.shape, a.dtype, lambda z0, z1: a[z0:z1], array=a)

    @property
    def plane_bytes(self) -> int:
        """Bytes of one slice."""
        return int(self.shape[1]) * int(self.shape[2]) * self.dtype.itemsize

    def read(self, z0: int, z1: int) -> np.ndarray:
        """Slices ``z0 … z1 − 1`` as a ``(z1 − z0, Y, X)`` array."

        Parameters
        ----------
        z0, z1 : int
            First slice and one past the last (0 ≤ z0 ≤ z1 ≤ Z).

        Returns
        -------
        (z1 − z0, Y, X) ndarray
            In the file's dtype (native byte order), a copy (not a view of a memory map).
        """
        return np.asarray(self._reader(int(z0), int(z1)))

    def whole(self) -> np.ndarray:
        """The whole image in memory (for a segmentation, which needs it).

        Returns
        -------
        (Z, Y, X) ndarray
            The array itself for :meth:`from_array`, else a copy read from the file.
        """
        if self._array is not None:
            return self._array
        return self.read(0, self.shape[0])


def _mapped_reader(path: Path, offset: int, shape, dtype, order: str = "C"):
    """Read slices through a fresh memory map each time: the slices are copied out and the map closed, so the
    process never holds more of the file than one slab (a long-lived map keeps every page it read)."""
    dtype = np.dtype(dtype)
    plane = int(shape[1]) * int(shape[2]) * dtype.itemsize

    def read(z0: int, z1: int) -> np.ndarray:
        if z1 <= z0:
            return np.zeros((0, *shape[1:]), dtype)
        if order == "F":  # Fortran order (np.save of a transposed array): the whole file is one map
            m = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=tuple(shape), order="F")
            out = np.ascontiguousarray(m[z0:z1])
        else:
            m = np.memmap(path, dtype=dtype, mode="r", offset=offset + z0 * plane, shape=(z1 - z0, *shape[1:]))
            out = np.array(m)
        del m
        return out if out.dtype.isnative else out.astype(dtype.newbyteorder("="))  # big-endian raw: native

    return read


def _check_3d(path: Path, shape, what: str) -> tuple[int, int, int]:
    shape = tuple(int(s) for s in shape)
    squeezed = tuple(s for s in shape if s != 1) if len(shape) > 3 else shape
    if len(squeezed) != 3:
        raise InputError(f"{path}: not a 3D image: {what} has shape {shape} (a volume has 3 axes, Z Y X)")
    if min(squeezed) < 1:
        raise InputError(f"{path}: the image is empty (shape {shape})")
    return squeezed  # type: ignore[return-value]


def _natural_key(p: Path):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


def _tiff_voxel_size(tif) -> float | None:
    """Isotropic voxel size in µm from a TiffFile's ImageJ metadata / resolution tags, or None."""
    try:
        page = tif.pages[0]
        meta = tif.imagej_metadata or {}
        unit = str(meta.get("unit", "")).strip().lower().replace("\\u00b5", "µ")
        tags = page.tags
        res = tags.get("XResolution")
        if res is None:
            return None
        num, den = res.value
        if not num:
            return None
        xy = den / num
        scale = {"micron": 1.0, "microns": 1.0, "um": 1.0, "µm": 1.0, "μm": 1.0, "mm": 1000.0,
                 "millimeter": 1000.0, "nm": 1e-3}.get(unit)
        if scale is None:
            unit_tag = tags.get("ResolutionUnit")
            code = int(unit_tag.value) if unit_tag is not None else 1
            scale = {3: 1e4}.get(code)  # centimetre; 2 (inch) and 1 (none) say nothing usable
            if scale is None:
                return None
        size = xy * scale
        z = meta.get("spacing")
        if z is not None and not math.isclose(float(z) * scale, size, rel_tol=1e-3):
            raise InputError(f"{tif.filehandle.path}: anisotropic voxels ({size:g} µm in x and y, "
                             f"{float(z) * scale:g} µm in z): the descriptors need cubic voxels")
        return float(size) if math.isfinite(size) and size > 0 else None
    except ValueError:
        raise
    except Exception:  # odd or partial metadata: no voxel size from it
        return None


@contextlib.contextmanager
def _tifffile_warnings():
    """tifffile's logged warnings (a page or tag it could not read: a cut file) collected, not printed: a list of
    messages, filled while the block runs."""
    messages: list[str] = []

    class _Keep(logging.Handler):
        def emit(self, record):
            messages.append(re.sub(r"<[^>]*>\s*", "", record.getMessage()).strip())

    log = logging.getLogger("tifffile")
    handler, propagate = _Keep(logging.WARNING), log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield messages
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


def _check_tiff_whole(path: Path, series, warned: list[str]) -> None:
    """Refuse a TIFF cut short (a copy or download that stopped): image data that end past the file's end, or
    pages and tags tifffile could not read, in one line naming the file (instead of tifffile's log lines and a
    memory map's "mmap length is greater than file size")."""
    size = path.stat().st_size
    ends = [int(o) + int(c) for page in series.pages if page is not None
            for o, c in zip(page.dataoffsets, page.databytecounts)]
    if series.dataoffset is not None:
        ends.append(int(series.dataoffset) + int(series.nbytes))
    end = max(ends, default=0)
    if end > size:
        raise FileFormatError(f"{path}: truncated TIFF image: its image data end at byte {end} but the file has {size} "
                             "bytes; copy the file again")
    if warned:
        raise FileFormatError(f"{path}: truncated or damaged TIFF image ({size} bytes; tifffile: {warned[0]}); copy "
                             "the file again")


def _open_tiff(path: Path) -> Volume:
    tifffile = tifffile_module()
    with _tifffile_warnings() as warned:
        try:
            tif = tifffile.TiffFile(path)
            series = tif.series[0]
        except Exception as exc:
            raise FileFormatError(f"{path}: not a readable TIFF image ({exc.__class__.__name__}: {exc})") from None
    with tif:
        _check_tiff_whole(path, series, warned)
        shape = _check_3d(path, series.shape, "its first series")
        dtype = series.dtype
        size = _tiff_voxel_size(tif)
        offset = series.dataoffset
        npages = len(series.pages)
    if offset is not None:  # uncompressed, contiguous: map it
        return Volume(path, shape, dtype, _mapped_reader(path, offset, shape, dtype), voxel_size_um=size)
    if npages != shape[0]:
        raise InputError(f"{path}: a compressed TIFF with {npages} page(s) for {shape[0]} slices: save it "
                         "uncompressed, as one page per slice, or as .npy")

    def read(z0: int, z1: int) -> np.ndarray:
        with tifffile.TiffFile(path) as t:
            pages = t.series[0].pages
            return np.stack([pages[z].asarray().reshape(shape[1:]) for z in range(z0, z1)]) if z1 > z0 else \
                np.zeros((0, *shape[1:]), dtype)

    return Volume(path, shape, dtype, read, voxel_size_um=size)


def _open_slices(path: Path) -> Volume:
    tifffile = tifffile_module()
    files = sorted((q for q in path.iterdir() if q.suffix.lower() in TIFF_SUFFIXES and q.is_file()
                    and not q.name.startswith(".")), key=_natural_key)
    if not files:
        raise InputError(f"{path}: a folder without TIFF slices ({', '.join(TIFF_SUFFIXES)})")
    try:
        with _tifffile_warnings() as warned, tifffile.TiffFile(files[0]) as tif:
            first = tif.series[0]
            _check_tiff_whole(files[0], first, warned)
            plane, dtype = tuple(s for s in first.shape if s != 1), first.dtype
            size = _tiff_voxel_size(tif)
    except ValueError:
        raise
    except Exception as exc:
        raise FileFormatError(f"{files[0]}: not a readable TIFF image ({exc.__class__.__name__}: {exc})") from None
    if len(plane) != 2:
        raise InputError(f"{files[0]}: a slice must be a 2D image; it has shape {first.shape}")
    if len(files) < 2:
        raise InputError(f"{path}: not a 3D image: one TIFF slice")

    def read(z0: int, z1: int) -> np.ndarray:
        out = np.empty((max(z1 - z0, 0), *plane), dtype)
        for k, z in enumerate(range(z0, z1)):
            try:
                with _tifffile_warnings() as warned, tifffile.TiffFile(files[z]) as tif:
                    _check_tiff_whole(files[z], tif.series[0], warned)
                    a = tif.asarray()
            except ValueError as exc:
                if str(exc).startswith(str(files[z])):
                    raise
                raise FileFormatError(f"{files[z]}: not a readable TIFF image ({exc})") from None
            except Exception as exc:
                raise FileFormatError(f"{files[z]}: not a readable TIFF image ({exc.__class__.__name__}: "
                                      f"{exc})") from None
            a = np.asarray(a)
            if a.size != out[k].size or a.dtype != dtype:
                raise InputError(f"{files[z]}: slice of shape {a.shape} ({a.dtype}); the first is {plane} ({dtype})")
            out[k] = a.reshape(plane)
        return out

    return Volume(path, (len(files), *plane), dtype, read, voxel_size_um=size)


def _check_npy_whole(path: Path) -> None:
    """Refuse a ``.npy`` file shorter than its header announces (a cut copy), in one line naming the file; a file
    whose header cannot be read passes (the caller reports it)."""
    try:
        with open(path, "rb") as fh:
            fmt = np.lib.format
            version = fmt.read_magic(fh)
            header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, _, dtype = header(fh)
            start = fh.tell()
    except Exception:
        return
    need = start + math.prod(shape) * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise FileFormatError(f"{path}: truncated .npy array: its header announces a {' x '.join(map(str, shape))} "
                             f"{dtype.name} array ({need} bytes) but the file has {size} bytes; copy the file again")


def open_volume(path, *, raw_shape=None, raw_dtype=None) -> Volume:
    """Open a 3D image for reading slab by slab (formats: the module's docstring).

    Parameters
    ----------
    path : path
        ``.npy``, ``.tif``/``.tiff``, a folder of TIFF slices, or a raw file (with ``raw_shape``).
    raw_shape : (3,) sequence of int, optional
        ``(Z, Y, X)`` of a raw file (C order, no header).
    raw_dtype : str, optional
        NumPy dtype of a raw file, e.g. ``"uint16"`` (``"<u2"`` little-endian explicitly); default uint16.

    Returns
    -------
    Volume
        ``voxel_size_um`` set when a TIFF's metadata gives it.

    Raises
    ------
    ValueError
        One line naming the file: missing, not a 3D image, a raw size that does not match its shape and dtype,
        an unreadable file, no tifffile for a TIFF.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "v.raw"
    >>> _ = p.write_bytes(np.ones((3, 4, 5), np.uint16).tobytes())
    >>> open_volume(p, raw_shape=(3, 4, 5)).read(0, 3).sum()
    np.uint64(60)
    >>> open_volume(p, raw_shape=(3, 4, 6))
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: ...v.raw: 120 bytes, but a 3 x 4 x 6 uint16 image needs 144 bytes: check raw_shape and raw_dtype
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    if raw_shape is not None:
        if path.is_dir():
            raise InputError(f"{path}: a folder; a raw image is one file")
        try:
            dtype = np.dtype(raw_dtype or "uint16")
        except TypeError:
            raise InputError(f"{{raw_dtype}} {raw_dtype!r}: not a NumPy dtype (uint8, uint16, uint32, int32, ...)",
                             setting="raw_dtype") from None
        shape = tuple(int(s) for s in raw_shape)
        if len(shape) != 3 or min(shape) < 1:
            raise InputError(f"{{raw_shape}} must be three positive sizes Z Y X, got {raw_shape!r}", setting="raw_shape")
        need = math.prod(shape) * dtype.itemsize
        have = path.stat().st_size
        if have != need:
            raise InputError(f"{path}: {have} bytes, but a {shape[0]} x {shape[1]} x {shape[2]} {dtype.name} image "
                             f"needs {need} bytes: check {{raw_shape}} and {{raw_dtype}}", setting=("raw_shape", "raw_dtype"))
        return Volume(path, shape, dtype.newbyteorder("="), _mapped_reader(path, 0, shape, dtype))
    if raw_dtype is not None:
        raise InputError("{raw_dtype} needs {raw_shape} (a raw image's Z Y X)", setting=("raw_shape", "raw_dtype"))
    if path.is_dir():
        return _open_slices(path)
    suffix = path.suffix.lower()
    if suffix in TIFF_SUFFIXES:
        return _open_tiff(path)
    if suffix == ".npy":
        try:
            m = np.load(path, mmap_mode="r", allow_pickle=False)
        except Exception as exc:
            _check_npy_whole(path)
            raise FileFormatError(f"{path}: not a readable .npy array ({exc.__class__.__name__}: {exc})") from None
        if not isinstance(m, np.memmap):
            raise FileFormatError(f"{path}: not a .npy array")
        shape = _check_3d(path, m.shape, "the array")
        if m.dtype.hasobject or m.dtype.names is not None:
            raise InputError(f"{path}: an array of {m.dtype}, not an image")
        order = "F" if (m.flags.f_contiguous and not m.flags.c_contiguous) else "C"
        offset, dtype = int(m.offset), m.dtype
        del m
        return Volume(path, shape, dtype, _mapped_reader(path, offset, shape, dtype, order))
    raise FileFormatError(f"{path}: unknown image format {suffix or '(no suffix)'!r}: give a .npy, a .tif/.tiff, "
                          "a folder of TIFF slices, or a raw file with {raw_shape} Z Y X and {raw_dtype}",
                          setting=("raw_shape", "raw_dtype"))


def write_labels(path, labels: np.ndarray, voxel_size_um: float | None = None, fmt: str | None = None) -> Path:
    """Write a label image as ``.npy`` or ``.tif`` (ImageJ metadata with the voxel size in µm), atomically.

    ``fmt`` (``".npy"``, ``".tif"``, ``".tiff"``) is the format; by default the path's suffix.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    labels : (Z, Y, X) ndarray of int
        Label image (0 background).
    voxel_size_um : float, optional
        Voxel side in µm, written in a TIFF's metadata (ImageJ's for uint8/uint16, resolution tags
        per centimetre otherwise); not stored in ``.npy``.
    fmt : {".npy", ".tif", ".tiff"}, optional
        Default: ``path``'s suffix.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If the format is not one of :data:`LABEL_SUFFIXES`, or a TIFF is asked for without tifffile.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "l.npy"
    >>> _ = write_labels(p, np.ones((2, 2, 2), np.uint16))
    >>> int(np.load(p).sum())
    8
    """

    from . import atomic_file

    path = Path(path)
    suffix = (fmt or path.suffix).lower()
    if suffix not in LABEL_SUFFIXES:
        raise InputError(f"{path.name!r} must end in {' or '.join(LABEL_SUFFIXES)}")
    tifffile = tifffile_module() if suffix != ".npy" else None
    with atomic_file(path) as tmp:
        if suffix == ".npy":
            with open(tmp, "wb") as fh:  # (np.save would add .npy to the name)
                np.save(fh, labels)
        elif not voxel_size_um:
            tifffile.imwrite(tmp, labels)
        elif labels.dtype in (np.uint8, np.uint16):  # ImageJ's own types: its metadata, in µm
            tifffile.imwrite(tmp, labels, imagej=True, resolution=(1.0 / voxel_size_um, 1.0 / voxel_size_um),
                             metadata={"spacing": voxel_size_um, "unit": "um", "axes": "ZYX"})
        else:  # the resolution tags, per centimetre
            tifffile.imwrite(tmp, labels, resolution=(1e4 / voxel_size_um, 1e4 / voxel_size_um),
                             resolutionunit="CENTIMETER")
    return path
