"""Files shared by every engine deck: sphere lists, clump VTK, the file set writer."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Mapping

import numpy as np

__all__ = ["xyzr_text", "clump_vtk_text", "write_files", "template_record", "fmt", "updated_settings", "settle_loop",
           "rotation_matrix", "lattice_slots"]


def updated_settings(defaults: dict, kw: dict, what: str = "scene settings") -> dict:
    """``defaults`` updated with ``kw``; an unknown key raises ``ValueError`` naming it.

    Examples
    --------
    >>> updated_settings({"seed": 0, "dt": 1.0}, {"seed": 3})
    {'seed': 3, 'dt': 1.0}
    """
    unknown = set(kw) - set(defaults)
    if unknown:
        raise ValueError(f"unknown {what}: {', '.join(sorted(unknown))}")
    return {**defaults, **kw}


def settle_loop(check_every: int, max_checks: int) -> str:
    """LIGGGHTS/LAMMPS input lines: run ``check_every`` steps at a time until the variable
    ``ke`` falls below ``kethr`` (at most ``max_checks`` times), then write ``settle.txt``.

    Examples
    --------
    >>> print(settle_loop(1000, 5).splitlines()[0])
    variable i loop 5
    """
    return (f"variable i loop {int(max_checks)}\nlabel settle\nrun {int(check_every)}\n"
            'if "${ke} < ${kethr}" then "jump SELF settled"\nnext i\njump SELF settle\nlabel settled\n'
            'print "ke ${ke} threshold ${kethr}" file settle.txt')


def rotation_matrix(axis: np.ndarray, theta: float) -> np.ndarray:
    """Right-handed rotation by ``theta`` radians about ``axis`` (Rodrigues).

    Examples
    --------
    >>> np.round(rotation_matrix(np.array([0.0, 0.0, 1.0]), np.pi / 2) @ [1.0, 0.0, 0.0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * K @ K


def lattice_slots(count: int, side: int, cell: float, rng: np.random.Generator):
    """Pour positions on a ``side`` × ``side`` lattice of ``cell``, layer after layer, each with a
    random orientation from ``rng``: yields ``(slot, pos, axis, theta_deg, R)`` for slots 0..count-1.

    Examples
    --------
    >>> [(s, p.tolist()) for s, p, *_ in lattice_slots(3, 2, 1.0, np.random.default_rng(0))]
    [(0, [0.5, 0.5, 1.0]), (1, [1.5, 0.5, 1.0]), (2, [0.5, 1.5, 1.0])]
    """
    for slot in range(count):
        i, j, layer = slot % side, (slot // side) % side, slot // (side * side)
        pos = np.array([(i + 0.5) * cell, (j + 0.5) * cell, (layer + 1.0) * cell])
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        theta = float(rng.uniform(0, 360))
        yield slot, pos, axis, theta, rotation_matrix(axis, math.radians(theta))


def fmt(x: float) -> str:
    """A float with 17 significant digits (round-trips exactly)."""
    return repr(float(x))


def xyzr_text(centres: np.ndarray, radii: np.ndarray, *, header: str = "") -> str:
    """``x y z r`` per line (full precision), after ``#`` comment lines from ``header``.

    Examples
    --------
    >>> print(xyzr_text(np.zeros((1, 3)), np.array([0.5]), header="one sphere"), end="")
    # one sphere
    0.0 0.0 0.0 0.5
    """
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    lines += [" ".join(fmt(v) for v in (*c, r)) for c, r in zip(centres, radii)]
    return "\n".join(lines) + "\n"


def clump_vtk_text(centres: np.ndarray, radii: np.ndarray, title: str = "grainforge clump") -> str:
    """A legacy-VTK POLYDATA file: one vertex per sphere with a ``radius`` scalar.

    In ParaView apply *Glyph* (sphere, scale by ``radius``, factor 2 for diameter).
    """
    n = len(radii)
    lines = ["# vtk DataFile Version 3.0", title[:250], "ASCII", "DATASET POLYDATA", f"POINTS {n} double"]
    lines += [" ".join(fmt(v) for v in c) for c in centres]
    lines += [f"VERTICES {n} {2 * n}"] + [f"1 {i}" for i in range(n)]
    lines += [f"POINT_DATA {n}", "SCALARS radius double 1", "LOOKUP_TABLE default"]
    lines += [fmt(r) for r in radii]
    return "\n".join(lines) + "\n"


def template_record(t) -> dict:
    """JSON-able summary of a GrainTemplate (SI units)."""
    rec = {
        "name": t.name, "source": t.source, "count": t.count, "shape": t.shape,
        "density": t.density, "volume": t.props.volume, "mass": t.mass, "d_eq": t.d_eq,
        "centroid": [0.0, 0.0, 0.0],
        "inertia_tensor": t.inertia.tolist(), "principal_inertia": t.principal.tolist(),
        "principal_axes": t.props.axes.tolist(), "bounding_radius": t.bounding_radius,
    }
    if t.clump is not None:
        rec.update({"xyzr": f"{t.name}.xyzr", "spheres": t.clump.count, "coverage": t.clump.coverage,
                    "spill": t.clump.spill, "r_min": float(t.clump.radii.min())})
    return rec


def json_text(obj) -> str:
    return json.dumps(obj, indent=1, sort_keys=False) + "\n"


def write_files(files: Mapping[str, str | bytes], out: str | Path, *, overwrite: bool = False) -> list[Path]:
    """Write ``{relative path: data}`` under ``out``, each atomically.

    Raises
    ------
    FileExistsError
        If any of the files exists and ``overwrite`` is false (checked before
        anything is written).
    """
    from ..io import atomic_write

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder")
    if not overwrite:
        existing = [out / p for p in files if (out / p).exists()]
        if existing:
            raise FileExistsError(f"{existing[0]} exists; use --overwrite")
    return [atomic_write(out / p, data) for p, data in files.items()]
