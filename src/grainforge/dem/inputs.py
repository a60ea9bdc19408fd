"""Grain files to templates: resolve inputs (files, run folders, manifests), prepare in parallel."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

__all__ = ["grain_paths", "read_grain", "load_template", "build_templates", "enclosure_problems", "MESH_SUFFIXES"]

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


def enclosure_problems(vertices: np.ndarray, faces: np.ndarray) -> list[str]:
    """What stops a mesh from enclosing one solid with a well-defined inside (empty if nothing).

    Weaker than :func:`grainforge.solid.solid_problems` in one respect only:
    an edge may be shared by four faces (two touching cubes of a DPA
    aggregate, once coincident vertices are merged), as long as every directed
    edge is matched by as many reverse edges. The winding number — hence the
    inside, the volume integrals and the voxelisation used here — is then
    well defined. Open boundaries, inconsistent orientation, degenerate
    faces, several bodies and non-positive volume are refused.

    Examples
    --------
    >>> import trimesh
    >>> b = trimesh.creation.box()
    >>> enclosure_problems(b.vertices, b.faces)
    []
    >>> enclosure_problems(b.vertices, b.faces[:-1])
    ['open boundary or inconsistent orientation']
    """
    from ..solid import face_components, signed_volume

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0 or len(v) == 0:
        return ["empty mesh"]
    if not np.isfinite(v).all():
        return ["non-finite vertex coordinates"]
    if f.min() < 0 or f.max() >= len(v):
        return ["face index out of range"]
    if ((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])).any():
        return ["degenerate faces (repeated vertex)"]
    a = f.ravel()
    b = np.roll(f, -1, axis=1).ravel()
    n = np.int64(len(v))
    if not np.array_equal(np.sort(a * n + b), np.sort(b * n + a)):
        return ["open boundary or inconsistent orientation"]
    bodies = len(np.unique(face_components(f, len(v))))
    if bodies != 1:
        return [f"{bodies} separate bodies"]
    if not signed_volume(v, f) > 0:
        return ["non-positive volume (inward orientation)"]
    return []


def read_grain(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a mesh file, vertices merged by position (as any reader sees it).

    Raises
    ------
    ValueError
        If the file is unreadable or the mesh is not a valid solid.
    """
    from ..io import read_mesh

    mesh = read_mesh(path)
    v, inv = np.unique(np.asarray(mesh.vertices, dtype=np.float64), axis=0, return_inverse=True)
    f = inv.reshape(-1)[np.asarray(mesh.faces, dtype=np.int64)]
    problems = enclosure_problems(v, f)
    if problems:
        raise ValueError(f"{path}: not a closed solid ({'; '.join(problems)})")
    return v, f


def load_template(path: str | Path, name: str, kwargs: dict):
    """Read ``path`` and :func:`~grainforge.dem.template.prepare` it as ``name``."""
    from .template import prepare

    v, f = read_grain(path)
    return prepare(v, f, name, source=str(path), **kwargs)


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
