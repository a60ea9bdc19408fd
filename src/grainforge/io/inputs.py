"""The one resolver of a command's grain inputs, and the one reader of a run's manifest.

Every command that takes grains (``analyse``, ``check``, ``render``, ``tray``, ``dem``, ``simulate``)
names them the same ways: mesh files, folders of them, and a run's ``manifest.csv`` (or the folder
holding one, whose files then come in the manifest's order).  :func:`mesh_paths` turns such inputs
into mesh files; :func:`read_manifest` reads a manifest's rows.

Examples
--------
>>> import tempfile, pathlib
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> for name in ("b.stl", "a.stl", ".a.stl.tmp", "notes.txt"):
...     _ = (folder / name).write_text("solid x\\nendsolid x\\n")
>>> [p.name for p in mesh_paths([folder])]
['a.stl', 'b.stl']
>>> _ = (folder / "manifest.csv").write_text("file,seed\\nb.stl,1\\na.stl,2\\n")
>>> [p.name for p in mesh_paths([folder])], read_manifest(folder / "manifest.csv")[0]
(['b.stl', 'a.stl'], {'file': 'b.stl', 'seed': '1'})
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..errors import InputError

__all__ = ["MESH_SUFFIXES", "MANIFEST", "read_manifest", "manifest_files", "mesh_paths"]

#: the mesh files a folder of grains is searched for
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".3mf", ".off")
#: a run's manifest: one row per grain, its ``file`` relative to the manifest's folder
MANIFEST = "manifest.csv"


def read_manifest(path: str | os.PathLike, *, require: Sequence[str] = ()) -> list[dict[str, str]]:
    """The rows of a manifest CSV, values as text.

    Parameters
    ----------
    path : path-like
        The ``manifest.csv`` (or any CSV table with a header row).
    require : sequence of str, optional
        Columns the table must have.

    Returns
    -------
    list of dict
        One dict per row, header -> text.

    Raises
    ------
    ValueError
        In one line: the file is missing or unreadable, is not a UTF-8 CSV table, or lacks a required column.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            columns = reader.fieldnames or []
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except (UnicodeDecodeError, csv.Error):
        raise InputError(f"{path}: not a grainforge manifest (not a UTF-8 CSV table)") from None
    missing = [c for c in require if c not in columns]
    if missing:
        raise InputError(f"{path}: not a grainforge manifest (no {', '.join(repr(c) for c in missing)} column)")
    return rows


def manifest_files(path: str | os.PathLike) -> list[Path]:
    """The grain files a manifest lists, in its order, relative to its folder.

    Parameters
    ----------
    path : path-like
        The manifest.

    Returns
    -------
    list of Path
        ``folder / row["file"]`` for every row.

    Raises
    ------
    ValueError
        As :func:`read_manifest` (the ``file`` column is required).
    """
    path = Path(path)
    return [path.parent / row["file"] for row in read_manifest(path, require=("file",))]


def _folder_meshes(folder: Path) -> list[Path]:
    if (folder / MANIFEST).is_file():
        return manifest_files(folder / MANIFEST)
    found = sorted(q for q in folder.iterdir()
                   if q.suffix.lower() in MESH_SUFFIXES and not q.name.startswith(".") and q.is_file())
    if not found:
        raise InputError(f"{folder}: no grain files (no mesh file {', '.join(MESH_SUFFIXES)} and no {MANIFEST} in "
                         "the folder)")
    return found


def mesh_paths(inputs: Iterable[str | os.PathLike]) -> list[Path]:
    """Mesh files named by ``inputs``: files, folders and manifests.

    Parameters
    ----------
    inputs : iterable of path-like
        A mesh file is taken as it is; a folder gives its ``manifest.csv``'s files in the manifest's
        order if it has one, else its mesh files (:data:`MESH_SUFFIXES`, hidden files skipped: ours
        are temporaries) sorted by name; a ``.csv`` file is a manifest.

    Returns
    -------
    list of Path
        In the order of the inputs.

    Raises
    ------
    ValueError
        In one line: an empty or missing path, a folder without mesh files, a manifest that cannot be
        read or lists a missing file, or no file at all.
    """
    out: list[Path] = []
    for item in inputs:
        if str(item).strip() == "":
            raise InputError("an empty path")
        p = Path(item)
        if p.is_dir():
            out += _folder_meshes(p)
        elif p.suffix.lower() == ".csv" and p.is_file():
            out += manifest_files(p)
        elif p.is_file():
            out.append(p)
        else:
            raise InputError(f"{p}: no such file or folder")
    if not out:
        raise InputError("no grain files in the inputs")
    missing = [q for q in out if not q.is_file()]
    if missing:
        raise InputError(f"{missing[0]}: no such file (listed in a manifest)")
    return out
