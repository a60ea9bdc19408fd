"""Grain files to templates: resolve inputs (files, run folders, manifests), prepare in parallel."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from .enclosure import enclosure_problems

__all__ = ["grain_paths", "read_grain", "merge_vertices", "load_template", "build_templates", "enclosure_problems", "MESH_SUFFIXES"]

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".3mf", ".off")


def _manifest_files(manifest: Path) -> list[Path]:
    try:
        with open(manifest, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ValueError(f"{manifest}: cannot read ({exc.strerror})") from None
    if not rows or "file" not in rows[0]:
        raise ValueError(f"{manifest}: not a grainforge manifest (no 'file' column)")
    return [manifest.parent / r["file"] for r in rows]


def grain_paths(inputs: Iterable[str | Path]) -> list[Path]:
    """Mesh files named by ``inputs``: files, run folders (their manifest) or manifests.

    A folder with a ``manifest.csv`` gives the manifest's files in its order; a
    folder without one gives its mesh files sorted by name.

    Raises
    ------
    ValueError
        For a missing path, or inputs that hold no mesh file.
    """
    out: list[Path] = []
    for p in map(Path, inputs):
        if p.is_dir():
            if (p / "manifest.csv").is_file():
                out += _manifest_files(p / "manifest.csv")
            else:
                out += sorted(q for q in p.iterdir() if q.suffix.lower() in MESH_SUFFIXES)
        elif p.suffix.lower() == ".csv":
            if not p.is_file():
                raise ValueError(f"{p}: no such file")
            out += _manifest_files(p)
        elif p.is_file():
            out.append(p)
        else:
            raise ValueError(f"{p}: no such file or folder")
    if not out:
        raise ValueError("no grain files in the inputs")
    for p in out:
        if not p.is_file():
            raise ValueError(f"{p}: no such file")
    return out


def merge_vertices(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`grainforge.solid.unique_rows` of (N, 3) points, faster for points float32 holds exactly.

    The same result bit for bit: unique rows in numeric (x, y, z) order (−0.0 equal to 0.0, the
    first occurrence kept) and the inverse. Float32-exact points (mesh files) are sorted with one
    unstable ``argsort`` on (x, y) packed in 64 bits instead of a ``lexsort`` of all rows; the few
    runs of equal (x, y) with different z are then sorted by z in place, and the row kept for each
    group is its smallest index. Other points go to ``unique_rows``.

    Examples
    --------
    >>> u, inv = merge_vertices(np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, -1]]))
    >>> u.tolist(), inv.tolist()
    ([[0.0, 1.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], [2, 1, 2, 0])
    """
    from ..solid import unique_rows

    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2 or p.dtype not in (np.float32, np.float64):
        return unique_rows(p)
    with np.errstate(over="ignore", invalid="ignore"):
        q = np.ascontiguousarray(p, dtype=np.float32)
    if p.dtype == np.float64 and not np.array_equal(q, p):  # (NaN never equals: the general path)
        return unique_rows(p)
    b = (q + np.float32(0.0)).view(np.uint32)  # -0.0 -> 0.0, then bits in numeric order
    k = np.where(b >> np.uint32(31), ~b, b | np.uint32(0x80000000))
    xy = (k[:, 0].astype(np.uint64) << np.uint64(32)) | k[:, 1]
    order = np.argsort(xy)
    xs, zs = xy[order], k[order, 2]
    same_xy = xs[1:] == xs[:-1]
    differ_z = zs[1:] != zs[:-1]
    clash = same_xy & differ_z
    if clash.any():
        # the few runs of equal (x, y) holding different z: sort those positions by (run, z) in place
        run = np.cumsum(np.concatenate([[True], ~same_xy]))
        pos = np.flatnonzero(np.isin(run, run[1:][clash]))
        sub = np.lexsort((zs[pos], run[pos]))
        order[pos], zs[pos] = order[pos][sub], zs[pos][sub]
        differ_z = zs[1:] != zs[:-1]
    new = np.empty(len(p), dtype=bool)
    new[0] = True
    np.logical_or(~same_xy, differ_z, out=new[1:])
    inverse = np.empty(len(p), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    first = np.minimum.reduceat(order, np.flatnonzero(new))
    return p[first], inverse


def read_grain(path: str | Path, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a mesh file, vertices merged by position (as any reader sees it).

    ``check=False`` skips :func:`enclosure_problems` (for a caller that checks the mesh itself).

    Raises
    ------
    ValueError
        If the file is unreadable or (with ``check``) the mesh is not a valid solid.
    """
    from ..io import read_mesh

    mesh = read_mesh(path)
    # merge by exact position (sorted by x, y, z, as np.unique(axis=0) would, several times faster)
    v, inv = merge_vertices(np.ascontiguousarray(mesh.vertices, dtype=np.float64))
    f = inv[np.asarray(mesh.faces, dtype=np.int64)]
    if check:
        problems = enclosure_problems(v, f)
        if problems:
            raise ValueError(f"{path}: not a closed solid ({'; '.join(problems)})")
    return v, f


def load_template(path: str | Path, name: str, kwargs: dict):
    """Read ``path`` and :func:`~grainforge.dem.template.prepare` it as ``name`` (mesh dropped)."""
    from .template import prepare

    v, f = read_grain(path, check=False)  # prepare checks it, naming the file
    return prepare(v, f, name, source=str(path), **kwargs).without_mesh()


def _unique_names(paths: Sequence[Path]) -> list[str]:
    seen: dict[str, int] = {}
    names = []
    for p in paths:
        stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in p.stem)
        k = seen.get(stem, 0)
        seen[stem] = k + 1
        names.append(stem if k == 0 else f"{stem}_{k}")
    return names


def _load_one(args):
    return load_template(*args)


def build_templates(paths: Sequence[Path], *, workers: int = 1,
                    progress: Callable[[Iterable], Iterable] | None = None, **kwargs) -> list:
    """Templates of every grain file, in order (``kwargs`` go to ``prepare``).

    Runs on ``workers`` processes; the result does not depend on the count.
    """
    names = _unique_names(paths)
    tasks = [(p, n, kwargs) for p, n in zip(paths, names)]
    wrap = progress or (lambda it: it)
    if workers <= 1 or len(tasks) < 4:
        return list(wrap(map(_load_one, tasks)))
    from ..workers import process_pool, single_threaded_children

    with single_threaded_children(), process_pool(workers, preload=["grainforge.dem.template",
                                                                    "grainforge.dem.clump"]) as pool:
        return list(wrap(pool.map(_load_one, tasks, chunksize=max(1, min(32, len(tasks) // (8 * workers))))))
