"""Bulk print trays: many grains laid out on the build plates of a printer.

The pipeline streams: grains are made (generated or read) and oriented in
worker processes, then placed one by one in index order by an online shelf
packer and appended to the print file, so memory does not grow with the
number of grains.  Only a few numbers and a small footprint polygon per
grain are kept, for the CSV of positions and the plate previews.

Layout
------
Each grain is oriented first:

- printers that allow stacking (PolyJet, support material surrounds every
  part): the principal axes of the grain are aligned with x, y, z (longest
  along x), which makes its bounding box tight;
- other printers (FDM, SLA): the grain rests on a **stable face** of its
  convex hull, the hull face nearest to the volume centroid (the centroid
  projects inside that face, so the grain does not tip over), and is turned
  about z to align its footprint with x.

The oriented boxes are then packed in rows along x, rows stacked along y into
a layer, and, when stacking is allowed, layers stacked along z; when a plate is
full a new one starts.  Boxes are separated by at least the gap, and every
grain lies inside its box, so no two grains are closer than the gap.  The
orientations and the packer are :mod:`grainforge.fabrication.layout`'s
(importable from here too).

Examples
--------
>>> p = ShelfPacker((10.0, 10.0, 10.0), gap=1.0, stacking=True)
>>> [p.place((4.0, 4.0, 4.0)) for _ in range(5)]
[(0, 0.0, 0.0, 0.0), (0, 5.0, 0.0, 0.0), (0, 0.0, 5.0, 0.0), (0, 5.0, 5.0, 0.0), (0, 0.0, 0.0, 5.0)]
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, OutputExistsError
from ..geometry.moments import sphere_diameter
from ..rng import RNGLike, as_generator
from .layout import ShelfPacker, orient_principal, orient_stable

__all__ = [
    "ShelfPacker", "GeneratorSource", "FileSource", "Prepared", "TrayPlan", "TrayResult", "build_tray", "plan_tray",
    "orient_principal", "orient_stable", "tray_outputs", "min_mesh_distance",
]

OUT_FORMATS = (".3mf", ".stl")
#: triangles a print file may hold (about a 1 GB binary STL, 260 MB of 3MF): print-preparation software
#: handles files of this size.  With one file (``plates=1``) it keeps the paper's 8,000-grain tray within
#: two minutes and 2 GB; ``plates="auto"`` spreads finer grains over as many such files as they need.
#: See docs/printing.md.
DEFAULT_TRIANGLE_BUDGET = 20_000_000


# --------------------------------------------------------------------------- sources

@dataclass(frozen=True)
class GeneratorSource:
    """Grains generated on the fly: ``method`` with ``params``, grain i from ``seeds[i]``, scaled to ``size`` mm."""

    method: str
    params: Any
    seeds: tuple[int, ...]
    size: float
    size_definition: str = "equivalent"

    def __len__(self):
        return len(self.seeds)


@dataclass(frozen=True)
class FileSource:
    """Grains read from mesh files (millimetres), optionally rescaled to ``size``."""

    paths: tuple[Path, ...]
    size: float | None = None
    size_definition: str = "equivalent"

    def __len__(self):
        return len(self.paths)


# --------------------------------------------------------------------------- per-grain work (workers)

@dataclass
class Prepared:
    """A grain made ready for the tray (picklable, small except ``payload``)."""

    index: int
    name: str
    source: str
    extents: np.ndarray
    footprint: np.ndarray  # (k, 2) float32 convex hull of the xy projection, part coordinates
    payload: Any  # 3MF <mesh> bytes or STL records
    faces: int
    volume: float
    subdivisions: int | None


def _grain_mesh(task) -> tuple[str, str, np.ndarray, np.ndarray, int | None]:
    from .scale import scale_factor

    if task["kind"] == "gen":
        from ..methods import generate

        g = generate(task["method"], task["params"], task["seed"])
        k = scale_factor(g, task["size"], task["size_definition"])
        name = f"{task['method']}-{task['index']:05d}"
        return name, f"seed {task['seed']}", g.vertices * k, g.faces, getattr(task["params"], "subdivisions", None)
    from ..geometry.solid import solid_problems
    from ..io import read_parts

    path = Path(task["path"])
    parts = read_parts(path)
    if len(parts) != 1:
        raise InputError(f"{path}: holds {len(parts)} parts; a tray takes one grain per file")
    part = parts[0]
    v, f = part.vertices, part.faces
    problems = solid_problems(v, f)
    if problems:
        raise InputError(f"{path}: not a printable solid ({'; '.join(problems)}); see `grainforge check`")
    if task["size"] is not None:
        v = v * scale_factor(part, task["size"], task["size_definition"])
    else:  # printed as it is, in mm
        from ..geometry.solid import mesh_size_problem

        problem = mesh_size_problem(v)
        if problem is not None:
            raise InputError(f"{path}: {problem} (or give {{size}})", setting="size")
    return path.stem, str(path), v, f, None


def prepare(task: dict) -> Prepared:
    """Make, scale and orient one grain, and encode it for the output format."""
    from scipy.spatial import ConvexHull

    from ..geometry.solid import signed_volume
    from ..io.stl import stl_triangles
    from ..io.threemf import mesh_xml

    name, source, v, f, subdivisions = _grain_mesh(task)
    v = orient_principal(v) if task["stacking"] else orient_stable(v, f)
    v = v - v.min(axis=0)
    extents = v.max(axis=0)
    hull = ConvexHull(v[:, :2])
    footprint = v[hull.vertices, :2].astype(np.float32)
    payload = mesh_xml(v, f) if task["fmt"] == ".3mf" else stl_triangles(v, f)
    return Prepared(task["index"], name, source, extents, footprint, payload, len(f), signed_volume(v, f),
                    subdivisions)


def _prepare_chunk(tasks: list[dict]) -> list[Prepared]:
    return [prepare(t) for t in tasks]


def _chunks(tasks: Iterable[dict], chunk: int) -> Iterator[list[dict]]:
    batch: list[dict] = []
    for t in tasks:
        batch.append(t)
        if len(batch) == chunk:
            yield batch
            batch = []
    if batch:
        yield batch


def _prepared_in_order(tasks: Iterable[dict], workers: int, chunk: int = 16) -> Iterator[Prepared]:
    """Prepared grains in index order; at most a few chunks in flight, so memory stays bounded.

    ``tasks`` may be a generator: it is consumed as the work goes.
    """
    from ..runtime.workers import ordered_map

    for done in ordered_map(_prepare_chunk, _chunks(tasks, chunk), workers=workers,
                            preload=["grainforge.fabrication.tray", "trimesh", "scipy.special"]):
        yield from done


# --------------------------------------------------------------------------- the tray

@dataclass
class TrayResult:
    """What :func:`build_tray` wrote."""

    files: list[Path]
    previews: list[Path]
    csv: Path
    rows: list[dict[str, Any]]
    plates: int
    resolution: Any = None
    gap: float = 0.0
    layers: list[int] = field(default_factory=list)
    plan: Any = None


def tray_outputs(out: Path, plates: int) -> tuple[list[Path], list[Path], Path]:
    """Print files, previews and CSV of a tray of ``plates`` plates written to ``out``.

    One plate: ``out`` itself; several: ``STEM-plateK.EXT``.  Previews are
    always ``STEM-plateK.png`` and the CSV ``STEM.csv``.

    Parameters
    ----------
    out : Path
        The requested print file.
    plates : int
        Plates used.

    Returns
    -------
    files : list of Path
    previews : list of Path
    table : Path
    """
    stem, ext = out.stem, out.suffix
    files = [out] if plates == 1 else [out.with_name(f"{stem}-plate{k}{ext}") for k in range(1, plates + 1)]
    previews = [out.with_name(f"{stem}-plate{k}.png") for k in range(1, plates + 1)]
    return files, previews, out.with_name(f"{stem}.csv")


def _existing_outputs(out: Path) -> list[Path]:
    stem, ext = out.stem, out.suffix
    found = [p for p in (out, out.with_name(f"{stem}.csv")) if p.exists()]
    if out.parent.is_dir():
        found += sorted(out.parent.glob(f"{stem}-plate*{ext}")) + sorted(out.parent.glob(f"{stem}-plate*.png"))
    return found


def _preview(path: Path, footprints: list[np.ndarray], layer_of: list[int], volume, title: str) -> None:
    from ..io import save_figure

    save_figure(preview_figure(footprints, layer_of, volume, title), path)


def preview_figure(footprints: list[np.ndarray], layer_of: list[int], volume, title: str):
    """The plate preview: grain footprints (mm) on the build plate, coloured by layer (with a colour bar
    when there are several layers)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Rectangle

    W, D, _ = volume
    fig, ax = plt.subplots(figsize=(6, 6 * D / W + 0.4), dpi=120)
    ax.add_patch(Rectangle((0, 0), W, D, fill=False, edgecolor="0.3", linewidth=1))
    cmap = plt.get_cmap("viridis")
    top = max(layer_of) if layer_of else 0
    colors = [cmap(0.15 + 0.7 * (lay / top if top else 0)) for lay in layer_of]
    ax.add_collection(PolyCollection(footprints, facecolors=colors, edgecolors="none"))
    ax.set_xlim(-0.02 * W, 1.02 * W)
    ax.set_ylim(-0.02 * D, 1.02 * D)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title, fontsize=9)
    if footprints:
        pts = np.concatenate([np.asarray(fp, dtype=np.float64) for fp in footprints])
        lo, hi = pts.min(0), pts.max(0)
        if np.prod(hi - lo) < 0.1 * W * D:  # grains fill a small corner: zoom on them (inset, same mm)
            pad = 0.04 * float(max(hi - lo))
            ins = ax.inset_axes([0.42, 0.36, 0.55, 0.55])
            ins.add_collection(PolyCollection(footprints, facecolors=colors, edgecolors="none"))
            span = float(max(hi - lo)) + 2 * pad
            ins.set_xlim(lo[0] - pad, lo[0] - pad + span)
            ins.set_ylim(lo[1] - pad, lo[1] - pad + span)
            ins.set_aspect("equal")
            ins.tick_params(labelsize=6)
            ins.set_xlabel("x (mm)", fontsize=7)
            ins.set_ylabel("y (mm)", fontsize=7)
            ins.set_title("enlarged", fontsize=7)
            ax.indicate_inset_zoom(ins, edgecolor="0.4")
    if top:
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import BoundaryNorm, ListedColormap

        levels = [cmap(0.15 + 0.7 * k / top) for k in range(top + 1)]
        sm = ScalarMappable(norm=BoundaryNorm(np.arange(top + 2) + 0.5, top + 1), cmap=ListedColormap(levels))
        bar = fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02, ticks=np.arange(1, top + 2))
        bar.set_label("layer (1 = on the plate)")
    return fig


def _tasks(source, fmt: str, stacking: bool) -> Iterator[dict]:
    """One task per grain, made as they are consumed (memory does not grow with the count)."""
    common = {"fmt": fmt, "stacking": stacking}
    if isinstance(source, GeneratorSource):
        for i, s in enumerate(source.seeds):
            yield dict(common, kind="gen", index=i, method=source.method, params=source.params, seed=int(s),
                       size=float(source.size), size_definition=source.size_definition)
        return
    for i, p in enumerate(source.paths):
        yield dict(common, kind="file", index=i, path=str(p), size=source.size,
                   size_definition=source.size_definition)


def _temp_prefix(out: Path, pid: int) -> str:
    """Temporary print files are ``.NAME.pidPID.XXXX.tmp``: the next run can tell a killed run's leftovers."""
    return f".{out.name}.pid{pid}."


def remove_stale_temps(out: Path) -> list[Path]:
    """Remove temporary print files for ``out`` left by killed runs (their process is gone).

    Parameters
    ----------
    out : Path
        The tray's print file.

    Returns
    -------
    list of Path
        The files removed (:func:`grainforge.runtime.children.remove_leftovers`).
    """
    from ..runtime.children import remove_leftovers

    return remove_leftovers(out.parent, f".{out.name}.pid", suffix=".tmp")


#: memory kept per grain until the end (CSV row, footprint polygon), bytes
ROW_BYTES = 2048


def _check_size_of_job(source, workers: int) -> None:
    """Refuse, before any work, a tray that would take more than a day or more memory than the machine has."""
    from ..runtime.estimate import check_job, check_memory, grain_seconds

    n = len(source)
    check_memory(n * ROW_BYTES, what=f"a tray of {n} grains", option="{count}", setting="count")
    if isinstance(source, GeneratorSource):
        check_job(n, grain_seconds(source.method, source.params), what=f"a tray of {n} {source.method} grains",
                  option="{count}", setting="count", workers=workers)


def _checked_request(source, printer, out, gap, overwrite: bool) -> tuple[Path, str, float]:
    """``(out, its format, gap)`` of a tray request, or ``ValueError``/``FileExistsError`` (nothing written)."""
    out = Path(out)
    fmt = out.suffix.lower()
    if fmt not in OUT_FORMATS:
        raise InputError(f"{{out}} must end in .3mf or .stl, got {out.name!r}", setting="out")
    gap = printer.default_gap if gap is None else float(gap)
    if not np.isfinite(gap) or gap <= 0:
        raise InputError(f"gap must be a positive number of millimetres (parts must never touch), got {gap!r}")
    if len(source) == 0:
        raise InputError("no grains to lay out")
    if not overwrite:
        existing = _existing_outputs(out)
        if existing:
            raise OutputExistsError(f"{existing[0]} exists; use {{overwrite}}", setting="overwrite")
    return out, fmt, gap


def _matched_source(source, printer, max_subdivisions: int | None, max_faces: int | None):
    """``(source, resolution)``: generated grains at the subdivisions their printed size calls for, with at most
    ``max_faces`` faces a grain (``resolution`` None and ``source`` as given when that does not apply)."""
    from .resolution import MAX_MATCHED, match_subdivisions, supports_matching

    if not (isinstance(source, GeneratorSource) and supports_matching(source.method)):
        return source, None
    resolution = match_subdivisions(
        source.method, source.params, size=source.size, size_definition=source.size_definition, printer=printer,
        seeds=source.seeds[:3],
        max_level=MAX_MATCHED if max_subdivisions is None else max_subdivisions,
        max_faces=max_faces,
    )
    source = dataclasses.replace(source, params=dataclasses.replace(source.params,
                                                                     subdivisions=resolution.subdivisions))
    return source, resolution


# --------------------------------------------------------------------------- the plan

#: bytes of a 3MF tray per triangle, about: the compressed XML measured 12.5 at subdivisions 6 and 12.9 at 3
#: (2 mm CRI grains; docs/printing.md)
THREEMF_BYTES_PER_TRIANGLE = 13
#: bytes of a binary STL per triangle (exact), plus :data:`STL_HEADER_BYTES` a file
STL_BYTES_PER_TRIANGLE = 50
STL_HEADER_BYTES = 84
#: most print files a tray plans (each also gets a preview): more is a budget or --plates mistyped
MAX_FILES = 1000


def file_bytes(triangles: int, fmt: str, files: int = 1) -> int:
    """About the bytes ``files`` print files holding ``triangles`` triangles in all take on disk.

    Parameters
    ----------
    triangles : int
        Triangles of all the files.
    fmt : {".3mf", ".stl"}
        The print format (STL: exact; 3MF: :data:`THREEMF_BYTES_PER_TRIANGLE`).
    files : int, default 1
        How many files they are spread over.

    Returns
    -------
    int

    Examples
    --------
    >>> file_bytes(1000, ".stl", files=2)
    50168
    """
    if fmt == ".stl":
        return STL_BYTES_PER_TRIANGLE * int(triangles) + STL_HEADER_BYTES * int(files)
    return THREEMF_BYTES_PER_TRIANGLE * int(triangles)


def _bytes_text(n: float) -> str:
    """``"8.5 GB"``, ``"133 MB"``, ``"12 kB"`` (decimal units, two or three significant digits)."""
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.2g} {unit}" if n / size < 10 else f"{n / size:.0f} {unit}"
    return f"{n:.0f} B"


def plates_value(plates: int | str) -> int | str:
    """``plates`` checked: a positive number of print files, or ``"auto"``.

    Parameters
    ----------
    plates : int or "auto"
        As given to :func:`build_tray`.

    Returns
    -------
    int or "auto"

    Raises
    ------
    ValueError
        For anything else.

    Examples
    --------
    >>> plates_value("auto"), plates_value(3)
    ('auto', 3)
    """
    if plates == "auto":
        return "auto"
    if isinstance(plates, (int, np.integer)) and not isinstance(plates, bool) and plates >= 1:
        return int(plates)
    raise InputError(f"plates must be a positive number of print files or 'auto', got {plates!r}")


def _ceil_div(a: int, b: int) -> int:
    return -(-int(a) // int(b))


@dataclass(frozen=True)
class TrayPlan:
    """How a tray spreads its grains over print files and meshes them, decided before any grain is made.

    Attributes
    ----------
    source : GeneratorSource or FileSource
        The grains (generated ones at the chosen ``subdivisions``).
    printer : Printer
    fmt : str
        ``".3mf"`` or ``".stl"``.
    plates : int or "auto"
        As asked for.
    max_triangles : int or None
        Triangle budget of one print file (None: no budget).
    files : int or None
        Print files the split makes (more if the grains do not fit as many build plates); None when they are
        counted as the grains are read (``"auto"`` without resolution matching: a file ends where the next
        grain would exceed ``max_triangles``).
    per_file : int or None
        Most grains in one print file (None: no fixed number).
    max_faces : int or None
        Faces a grain the budget allows resolution matching.
    resolution : Resolution or None
        The mesh level generated grains get (None: no resolution matching).
    needed : Resolution or None
        When the budget caps the level below the printer tolerance: what the tolerance alone asks for
        (found by :meth:`explained`).
    given : GeneratorSource or FileSource
        The grains as given (before resolution matching).
    """

    source: Any
    printer: Any
    fmt: str
    plates: int | str
    max_triangles: int | None
    files: int | None
    per_file: int | None
    max_faces: int | None = None
    resolution: Any = None
    needed: Any = None
    given: Any = None

    @property
    def count(self) -> int:
        """Grains in the tray."""
        return len(self.source)

    def file_of(self, index: int) -> int | None:
        """The print file (from 0) grain ``index`` goes to: the grains in order, as evenly as they divide.

        Parameters
        ----------
        index : int
            The grain's index (0 to ``count - 1``).

        Returns
        -------
        int or None
            None when the files are made as the grains are read (:attr:`files` is None).
        """
        return None if self.files is None else int(index) * self.files // self.count

    def needed_files(self) -> int | None:
        """Print files of at most ``max_triangles`` that the tolerance's level (:attr:`needed`) takes.

        Returns
        -------
        int or None
            None when nothing is needed, there is no budget, or one grain alone exceeds the budget.
        """
        if self.needed is None or self.max_triangles is None or self.needed.faces > self.max_triangles:
            return None
        return _ceil_div(self.count, self.max_triangles // self.needed.faces)

    def budget_problem(self) -> str | None:
        """When the triangle budget caps the mesh below the printer tolerance: what that does to the surface.

        Returns
        -------
        str or None
        """
        r = self.resolution
        if r is None or r.limited_by != "budget":
            return None
        return (f"the triangle budget (--max-triangles {self.max_triangles} a print file, --plates {self.plates}, "
                f"for {self.count} grains: {self.max_faces} faces per grain) caps the mesh at level {r.subdivisions} "
                f"({r.faces} faces): its chordal deviation {r.deviation * 1000:.1f} µm exceeds the printer tolerance "
                f"{r.tolerance * 1000:.1f} µm (half the {self.printer.name} resolution), so the printed surface "
                f"will show the mesh facets")

    def advice(self) -> str | None:
        """When the budget caps the mesh: the level the tolerance asks for, what it costs and how to get it.

        Returns
        -------
        str or None
            None until :attr:`needed` is known (:meth:`explained`).
        """
        need, n, budget = self.needed, self.count, self.max_triangles
        if need is None:
            return None
        reach = ("meets the tolerance" if need.converged else
                 f"is the finest allowed (--max-subdivisions {need.subdivisions})" if need.limited_by == "max level"
                 else "comes closest")
        text = (f"level {need.subdivisions} ({need.faces} faces a grain, {need.deviation * 1000:.1f} µm) {reach}: "
                f"{n * need.faces:,} triangles")
        k = self.needed_files()
        if k is None:
            return text + f", more than a print file of --max-triangles {budget}: give --max-triangles " \
                          f"{need.faces} or more and --plates auto"
        size = _bytes_text(file_bytes(n * need.faces, self.fmt, k))
        return text + (f", which --plates auto (here --plates {k}) writes as {k} print file{'s' * (k > 1)} of at most "
                       f"{budget:,} triangles, {size} in all, or --max-triangles {n * need.faces} as one file")

    def explained(self, max_subdivisions: int | None = None) -> TrayPlan:
        """This plan with :attr:`needed` found, when the budget caps the mesh (pilot grains at finer levels).

        Parameters
        ----------
        max_subdivisions : int, optional
            Finest level considered (as :func:`plan_tray`).

        Returns
        -------
        TrayPlan
        """
        if self.budget_problem() is None or self.needed is not None:
            return self
        _, needed = _matched_source(self.given, self.printer, max_subdivisions, None)
        return dataclasses.replace(self, needed=needed)

    def lines(self) -> list[str]:
        """What the tray will do, for the user, before it starts: the mesh level, the print files, the budget.

        Returns
        -------
        list of str
            One line each; empty when there is nothing to decide (mesh files or given subdivisions, one file).
        """
        r, n = self.resolution, self.count
        out = []
        if r is not None:
            out.append(f"resolution matching ({self.printer.name}, {self.printer.resolution * 1000:g} µm): "
                       f"{r.describe()}")
        if self.files is None:
            out.append(f"plan: {n} grains in print files of at most {self.max_triangles:,} triangles "
                       f"(--plates auto): a file ends where the next grain would pass that")
        elif r is not None or self.files > 1:
            split = "1 print file" if self.files == 1 else f"{self.files} print files of up to {self.per_file} grains"
            text = f"plan: {n} grains in {split}"
            if r is not None:
                text += (f", {r.faces:,} faces a grain: {n * r.faces:,} triangles (at most {self.per_file * r.faces:,}"
                         f" a file" + ("" if self.max_triangles is None else f", budget {self.max_triangles:,}")
                         + f"), about {_bytes_text(file_bytes(n * r.faces, self.fmt, self.files))}")
            out.append(text)
        for extra in (self.budget_problem(), self.advice()):
            if extra is not None:
                out.append("plan: " + extra)
        return out

    def warning(self) -> str | None:
        """The budget's problem and the advice in one sentence (the command repeats it last), or None.

        Returns
        -------
        str or None
        """
        problem, advice = self.budget_problem(), self.advice()
        return None if problem is None else problem + ("" if advice is None else "; " + advice)


def plan_tray(source: GeneratorSource | FileSource, printer, *, fmt: str = ".3mf", plates: int | str = 1,
              max_triangles: int | None = DEFAULT_TRIANGLE_BUDGET, match_resolution: bool = True,
              max_subdivisions: int | None = None, workers: int = 2, explain: bool = True) -> TrayPlan:
    """Decide, before any grain is made, the grains' mesh level and how they are spread over print files.

    Each print file holds at most ``max_triangles`` triangles.  ``plates=N``
    spreads the grains evenly over N files, so each grain may have
    ``max_triangles // ceil(count / N)`` faces and resolution matching
    chooses within that; ``plates="auto"`` gives every grain the level the
    printer tolerance asks for (each grain within the budget) and makes as
    many files as those triangles need.  Resolution matching runs its pilot
    grains here.

    Parameters
    ----------
    source : GeneratorSource or FileSource
    printer : Printer or str
    fmt : {".3mf", ".stl"}
        The print format (for the size estimate).
    plates : int or "auto", default 1
        Print files to spread the grains over.
    max_triangles : int, optional
        Triangle budget of one print file (None: no budget).
    match_resolution : bool
        As :func:`build_tray`.
    max_subdivisions : int, optional
        Finest level resolution matching may choose.
    workers : int
        Processes that will make the grains (for the refusal of a job that would take more than a day).
    explain : bool, default True
        When the budget caps the level: also find the level the tolerance asks for
        (:meth:`TrayPlan.explained`; its pilot grains are the finest).

    Returns
    -------
    TrayPlan

    Raises
    ------
    ValueError
        For a bad ``plates`` or ``max_triangles``, more than :data:`MAX_FILES` print files, or a job refused
        by its estimate.
    """
    from .printers import get_printer

    printer = get_printer(printer)
    plates = plates_value(plates)
    if max_triangles is not None and (int(max_triangles) != max_triangles or max_triangles < 1):
        raise InputError(f"max_triangles must be a positive whole number, got {max_triangles!r}")
    budget = None if max_triangles is None else int(max_triangles)
    n = len(source)
    if budget is None:
        max_faces = None
    else:
        max_faces = budget if plates == "auto" else max(20, budget // _ceil_div(n, min(plates, n)))
    given, resolution = source, None
    if match_resolution:
        source, resolution = _matched_source(source, printer, max_subdivisions, max_faces)
    _check_size_of_job(source, workers)
    if plates != "auto":
        files = min(plates, n)
    elif budget is None:
        files = 1
    elif resolution is not None:
        files = _ceil_div(n, max(1, budget // resolution.faces))
    else:
        files = None
    if files is not None and files > MAX_FILES:
        raise InputError(f"a tray of {n} grains in {files} print files is more than {MAX_FILES} files (each with its "
                         f"preview); raise --max-triangles or lower --plates")
    per_file = None if files is None else _ceil_div(n, files)
    plan = TrayPlan(source, printer, fmt, plates, budget, files, per_file, max_faces, resolution, given=given)
    return plan.explained(max_subdivisions) if explain else plan


def _csv_row(p: Prepared, plate: int, position: tuple[float, float, float], resolution) -> dict[str, Any]:
    """The CSV row of a placed grain (``plate`` counted from 0)."""
    x, y, z = position
    return {
        "index": p.index, "name": p.name, "source": p.source, "plate": plate + 1,
        "x": x, "y": y, "z": z,
        "size_x": float(p.extents[0]), "size_y": float(p.extents[1]), "size_z": float(p.extents[2]),
        "volume": p.volume, "equivalent_diameter": float(sphere_diameter(p.volume)),
        "faces": p.faces, "subdivisions": p.subdivisions,
        "chordal_deviation": None if resolution is None else resolution.deviation,
        "resolution_limited_by": None if resolution is None else resolution.limited_by,
    }


def _open_plate(out: Path, fmt: str, temps: list[Path]):
    """A new plate's print file: a temporary file beside ``out`` (noted in ``temps`` for the clean-up, with
    signals held so that a signal waits for both) and its writer."""
    from ..io import file_mode
    from ..io.stl import STLWriter
    from ..io.threemf import ThreeMFWriter
    from ..runtime.staging import signals_held

    with signals_held():
        fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(out, os.getpid()), suffix=".tmp", dir=out.parent)
        temps.append(Path(tmp))
    os.chmod(tmp, file_mode())
    fh = os.fdopen(fd, "w+b")
    return fh, (ThreeMFWriter(fh) if fmt == ".3mf" else STLWriter(fh))


def _write_previews_and_table(out: Path, plates: int, footprints, layers_of, rows, printer, gap: float,
                              written: list[Path]):
    """Each plate's preview and the tray's table (noted in ``written``); the print files' final names, the
    previews', the table's and each plate's layer count."""
    from ..io import write_csv

    layer_count = [layers[-1] + 1 for layers in layers_of]  # layers only grow within a plate
    files, previews, csv_path = tray_outputs(out, plates)
    for k, path in enumerate(previews):
        n = len(footprints[k])
        _preview(path, footprints[k], layers_of[k], printer.build_volume,
                 f"{out.name} plate {k + 1}/{len(previews)}: {n} grains, {layer_count[k]} layer(s), "
                 f"{printer.name}, gap {gap * 1000:.0f} µm")
        written.append(path)
    write_csv(csv_path, rows, units=True)
    written.append(csv_path)
    return files, previews, csv_path, layer_count


class _PlateFiles:
    """The plates being filled: the packer, the open print file, and each plate's footprints and layers."""

    def __init__(self, out: Path, fmt: str, printer, gap: float, plan: TrayPlan):
        self.out, self.fmt, self.plan = out, fmt, plan
        self.packer = ShelfPacker(printer.build_volume, gap, printer.stacking)
        self.temps: list[Path] = []
        self.footprints: list[list[np.ndarray]] = []
        self.layers_of: list[list[int]] = []
        self.writer = self.fh = None
        self.plate = -1
        self.part: int | None = 0  # the plan's print file of the last grain
        self.triangles = 0  # on the open plate

    def add(self, p: Prepared) -> tuple[int, tuple[float, float, float]]:
        """Place ``p`` (on a new plate when it starts the plan's next print file) and write it: its plate and
        position."""
        part = self.plan.file_of(p.index)
        if self.plate < 0:
            self.packer.compact(self.plan.per_file or self.plan.count, p.extents)
        elif part != self.part or (part is None and self.triangles + p.faces > self.plan.max_triangles):
            self.packer.new_plate()
        self.part = part
        pl, x, y, z = self.packer.place(p.extents)
        if pl != self.plate:
            self.close()
            self.fh, self.writer = _open_plate(self.out, self.fmt, self.temps)
            self.footprints.append([])
            self.layers_of.append([])
            self.plate, self.triangles = pl, 0
        self.writer.add_object(p.name, p.payload, (x, y, z))
        self.footprints[-1].append(p.footprint + np.array([x, y], dtype=np.float32))
        self.layers_of[-1].append(self.packer.layers - 1)
        self.triangles += p.faces
        return pl, (x, y, z)

    def close(self) -> None:
        """Finish the open print file."""
        if self.writer is not None:
            self.writer.close()
            self.fh.close()
            self.writer = None

    def abort(self) -> None:
        """Release the open print file unfinished (the caller deletes the temporary files)."""
        if self.writer is not None:
            self.writer.abort()
        if self.fh is not None and not self.fh.closed:
            self.fh.close()


def build_tray(
    source: GeneratorSource | FileSource,
    printer,
    out: str | Path,
    *,
    gap: float | None = None,
    workers: int = 2,
    overwrite: bool = False,
    match_resolution: bool = True,
    max_subdivisions: int | None = None,
    max_triangles: int | None = DEFAULT_TRIANGLE_BUDGET,
    plates: int | str = 1,
    progress: Callable[[Iterable], Iterable] | None = None,
    say: Callable[[str], Any] | None = None,
) -> TrayResult:
    """Lay out grains on the build plates of ``printer`` and write the print file(s).

    Parameters
    ----------
    source : GeneratorSource or FileSource
    printer : Printer or str
    out : path
        ``.3mf`` (one named object per grain) or ``.stl`` (binary).
    gap : float, optional
        Minimum distance between grains, mm (default two printer resolutions).
    workers : int
        Processes that make the grains (output does not depend on it).
    overwrite : bool
        Replace existing outputs.
    match_resolution : bool
        For generated grains whose method has ``subdivisions``: choose it with
        :func:`~grainforge.fabrication.resolution.match_subdivisions` (pilots:
        the first three seeds).  If false, the given params are used as they are.
    max_subdivisions : int, optional
        Finest level resolution matching may choose.
    max_triangles : int, optional
        Triangle budget of one print file (default :data:`DEFAULT_TRIANGLE_BUDGET`;
        ``None``: no budget); see :func:`plan_tray`.
    plates : int or "auto", default 1
        Print files to spread the grains over (``STEM-plateK.EXT`` when more
        than one; more plates when the grains do not fit as many build
        plates); ``"auto"``: as many as the printer tolerance needs, each
        within ``max_triangles`` (:func:`plan_tray`).
    progress : callable, optional
        Wraps the iterator of grains (a progress bar).
    say : callable, optional
        Called with each line of the plan (:meth:`TrayPlan.lines`) as soon as
        it is known, all before any grain is made (the command line prints
        them on stderr).

    Returns
    -------
    TrayResult

    Raises
    ------
    ValueError
        For a bad extension, gap, ``plates``, or a grain that does not fit the printer.
    FileExistsError
        If an output exists and ``overwrite`` is false.
    """
    from .printers import get_printer

    printer = get_printer(printer)
    out, fmt, gap = _checked_request(source, printer, out, gap, overwrite)
    plan = plan_tray(source, printer, fmt=fmt, plates=plates, max_triangles=max_triangles,
                     match_resolution=match_resolution, max_subdivisions=max_subdivisions, workers=workers,
                     explain=False)
    say = (lambda line: None) if say is None else say
    for line in plan.lines():
        say(line)
    plan = plan.explained(max_subdivisions)  # the finest pilot grains: said once the plan so far is
    if plan.advice() is not None:
        say("plan: " + plan.advice())

    from ..runtime.staging import signals_held

    made = [q for q in [out.parent, *out.parent.parents] if not q.exists()]
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out)
    state = _PlateFiles(out, fmt, printer, gap, plan)
    written: list[Path] = []  # outputs already in place: removed again if the run does not complete
    rows: list[dict[str, Any]] = []
    stream = None
    try:
        it = stream = _prepared_in_order(_tasks(plan.source, fmt, printer.stacking), workers)
        if progress is not None:
            it = progress(it)
        for p in it:
            pl, position = state.add(p)
            rows.append(_csv_row(p, pl, position, plan.resolution))
        state.close()
        files, previews, csv_path, layer_count = _write_previews_and_table(
            out, len(state.temps), state.footprints, state.layers_of, rows, printer, gap, written)
        with signals_held():  # the print files last, together: all outputs or none
            for tmp, final in zip(state.temps, files):
                os.replace(tmp, final)
                written.append(final)
            state.temps = []
    except BaseException:
        if stream is not None:
            stream.close()  # stops the workers now (an error, Ctrl-C, SIGTERM), not after their current chunks
        state.abort()
        for t in state.temps + written:
            t.unlink(missing_ok=True)
        for q in made:  # folders this call created, innermost first, if still empty
            try:
                q.rmdir()
            except OSError:
                break
        raise
    return TrayResult(files, previews, csv_path, rows, len(files), plan.resolution, gap, layer_count, plan)


def min_mesh_distance(parts: Sequence, within: float, samples: int = 2000, rng: RNGLike = 0) -> float:
    """Smallest distance between the surfaces of any two parts whose boxes are closer than ``within``.

    For every such pair, the vertices and ``samples`` random surface points of
    each part are projected onto the other part exactly
    (``trimesh.proximity.closest_point``); the minimum is an upper bound of
    the true surface distance that tightens with ``samples``.  Pairs whose
    boxes are farther apart than ``within`` are not measured (their distance
    exceeds ``within``).

    Parameters
    ----------
    parts : sequence of objects with ``vertices`` and ``faces`` (e.g. :class:`~grainforge.io.threemf.Part`)
        Placed parts, coordinates in mm.
    within : float
        Largest box distance of a measured pair, mm.
    samples : int, default 2000
        Random surface points per part and pair.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, default 0
        Where the surface points are drawn, normalised by :func:`grainforge.rng.as_generator`.

    Returns
    -------
    float
        ``inf`` when no two boxes are within ``within``.
    """
    import trimesh
    from scipy.spatial import cKDTree

    lo = np.array([np.asarray(p.vertices).min(axis=0) for p in parts])
    hi = np.array([np.asarray(p.vertices).max(axis=0) for p in parts])
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    tree = cKDTree(centre)
    reach = 2 * float(np.linalg.norm(half, axis=1).max()) + within
    best = np.inf
    meshes: dict[int, Any] = {}
    rng = as_generator(rng)

    def mesh(i):
        if i not in meshes:
            meshes[i] = trimesh.Trimesh(parts[i].vertices, parts[i].faces, process=False, validate=False)
        return meshes[i]

    for i, j in sorted(tree.query_pairs(reach)):
        box_gap = np.maximum(0.0, np.maximum(lo[i] - hi[j], lo[j] - hi[i]))
        if np.linalg.norm(box_gap) > within:
            continue
        for a, b in ((i, j), (j, i)):
            ma = mesh(a)
            pts = np.vstack([ma.vertices, trimesh.sample.sample_surface(ma, samples, seed=rng)[0]])
            # only points near b's box can be closer than ``within``
            pts = pts[((pts >= lo[b] - within) & (pts <= hi[b] + within)).all(axis=1)]
            for k in range(0, len(pts), 512):
                _, dist, _ = trimesh.proximity.closest_point(mesh(b), pts[k : k + 512])
                best = min(best, float(dist.min()))
    return best
