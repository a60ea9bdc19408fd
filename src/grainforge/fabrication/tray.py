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
grain lies inside its box, so no two grains are closer than the gap.

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

from ..rng import RNGLike, as_generator

__all__ = [
    "ShelfPacker", "GeneratorSource", "FileSource", "Prepared", "TrayResult", "build_tray",
    "orient_principal", "orient_stable", "tray_outputs", "min_mesh_distance",
]

OUT_FORMATS = (".3mf", ".stl")
#: triangles per print job that resolution matching may spend (about a 1 GB binary STL);
#: print-preparation software handles jobs of this size, and it keeps the paper's
#: 8,000-grain tray within two minutes and 2 GB.  See docs/printing.md.
DEFAULT_TRIANGLE_BUDGET = 20_000_000


# --------------------------------------------------------------------------- orientation

def orient_principal(vertices: np.ndarray) -> np.ndarray:
    """Rotate vertices so their principal axes are x (largest spread), y, z (a proper rotation).

    Parameters
    ----------
    vertices : (V, 3) ndarray of float
        Any unit.

    Returns
    -------
    (V, 3) float64
        Centred on the vertex mean.

    Examples
    --------
    >>> v = orient_principal(np.array([[0.0, 0, 0], [0, 3, 0], [0, 0, 1], [0, 3, 1]]))
    >>> np.round(np.ptp(v, axis=0), 6).tolist()
    [3.0, 1.0, 0.0]
    """
    c = vertices.mean(axis=0)
    d = vertices - c
    _, vecs = np.linalg.eigh(d.T @ d)
    R = vecs[:, ::-1].copy()
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1
    return d @ R


def _rotation_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation matrix turning unit vector ``a`` onto unit vector ``b``."""
    v = np.cross(a, b)
    s = np.linalg.norm(v)
    c = float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis -= a * (axis @ a)
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s**2)


def orient_stable(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Rotate a closed mesh so it rests on a stable face of its hull (that face at the bottom, z = min).

    The hull face whose plane is nearest to the volume centroid is chosen: the
    centroid's projection onto it lies inside it, so the grain is in stable
    equilibrium resting on that face.  The footprint is then turned about z
    so its principal axis is x.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions, mm.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    (V, 3) float64
        The rotated vertices (about the volume centroid, which ends at the origin).

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box(extents=(1.0, 3.0, 2.0))
    >>> v = orient_stable(np.asarray(box.vertices), np.asarray(box.faces))
    >>> np.round(v.max(axis=0) - v.min(axis=0), 6).tolist()   # rests on its largest face
    [3.0, 2.0, 1.0]
    """
    from scipy.spatial import ConvexHull

    from ..geometry.solid import volume_centroid

    c = volume_centroid(vertices, faces)
    eq = ConvexHull(vertices).equations  # n·x + d <= 0 inside, n outward unit
    dist = -(eq[:, :3] @ c + eq[:, 3])
    n = eq[int(np.argmin(dist)), :3]
    v = (vertices - c) @ _rotation_to(n, np.array([0.0, 0.0, -1.0])).T
    xy = v[:, :2] - v[:, :2].mean(axis=0)
    _, vecs = np.linalg.eigh(xy.T @ xy)
    a = vecs[:, 1]
    ang = np.arctan2(a[1], a[0])
    ca, sa = np.cos(-ang), np.sin(-ang)
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    return v @ Rz.T


# --------------------------------------------------------------------------- packing

class ShelfPacker:
    """Online shelf packing of boxes on build plates with a minimum gap.

    Boxes are placed in rows along x; rows fill a layer along y; with
    ``stacking`` layers fill the plate along z; then a new plate starts.

    Parameters
    ----------
    volume : (3,) float
        Build volume x, y, z.
    gap : float
        Minimum distance between boxes (> 0).
    stacking : bool
        Whether layers may be stacked in z.
    """

    def __init__(self, volume: Sequence[float], gap: float, stacking: bool):
        self.W, self.D, self.H = (float(x) for x in volume)
        self.row_width = self.W
        self.gap = float(gap)
        self.stacking = bool(stacking)
        self.plate = 0
        self.x = self.y = self.z = 0.0
        self.row_depth = self.layer_height = 0.0
        self.layers = 1

    def compact(self, count: int, extents: Sequence[float]) -> None:
        """Limit rows to about a square patch for ``count`` boxes like ``extents`` (a compact, not a strip, layout).

        Parameters
        ----------
        count : int
            Boxes to be placed.
        extents : (3,) sequence of float
            A typical box, mm.
        """
        a, b, _ = (float(e) + self.gap for e in extents)
        side = float(np.sqrt(count * a * b * 1.1))
        self.row_width = min(self.W, max(side, a))

    def place(self, extents: Sequence[float]) -> tuple[int, float, float, float]:
        """Position (plate, x, y, z) of the min corner of the next box.

        Parameters
        ----------
        extents : (3,) sequence of float
            The box's x, y, z, mm.

        Returns
        -------
        plate : int
            Counted from 0.
        x, y, z : float
            mm.

        Raises
        ------
        ValueError
            If the box is larger than the build volume.
        """
        a, b, c = (float(e) for e in extents)
        if a > self.W or b > self.D or c > self.H:
            raise ValueError(
                f"a grain of {a:.3g} x {b:.3g} x {c:.3g} mm does not fit the build volume "
                f"{self.W:g} x {self.D:g} x {self.H:g} mm"
            )
        while True:
            if self.x + a <= max(self.row_width, a) and self.y + b <= self.D and self.z + c <= self.H:
                pos = (self.plate, self.x, self.y, self.z)
                self.x += a + self.gap
                self.row_depth = max(self.row_depth, b)
                self.layer_height = max(self.layer_height, c)
                return pos
            if self.x > 0:  # new row
                self.y += self.row_depth + self.gap
                self.x, self.row_depth = 0.0, 0.0
            elif self.y > 0 and self.stacking:  # new layer
                self.z += self.layer_height + self.gap
                self.y, self.layer_height = 0.0, 0.0
                self.layers += 1
            else:  # new plate
                self.plate += 1
                self.x = self.y = self.z = 0.0
                self.row_depth = self.layer_height = 0.0
                self.layers = 1


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
        raise ValueError(f"{path}: holds {len(parts)} parts; a tray takes one grain per file")
    part = parts[0]
    v, f = part.vertices, part.faces
    problems = solid_problems(v, f)
    if problems:
        raise ValueError(f"{path}: not a printable solid ({'; '.join(problems)}); see `grainforge check`")
    if task["size"] is not None:
        v = v * scale_factor(part, task["size"], task["size_definition"])
    else:  # printed as it is, in mm
        from ..geometry.solid import mesh_size_problem

        problem = mesh_size_problem(v)
        if problem is not None:
            raise ValueError(f"{path}: {problem} (or give tray --size)")
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
    check_memory(n * ROW_BYTES, what=f"a tray of {n} grains", option="--count")
    if isinstance(source, GeneratorSource):
        check_job(n, grain_seconds(source.method, source.params), what=f"a tray of {n} {source.method} grains",
                  option="--count", workers=workers)


def _checked_request(source, printer, out, gap, overwrite: bool) -> tuple[Path, str, float]:
    """``(out, its format, gap)`` of a tray request, or ``ValueError``/``FileExistsError`` (nothing written)."""
    out = Path(out)
    fmt = out.suffix.lower()
    if fmt not in OUT_FORMATS:
        raise ValueError(f"--out must end in .3mf or .stl, got {out.name!r}")
    gap = printer.default_gap if gap is None else float(gap)
    if not np.isfinite(gap) or gap <= 0:
        raise ValueError(f"gap must be a positive number of millimetres (parts must never touch), got {gap!r}")
    if len(source) == 0:
        raise ValueError("no grains to lay out")
    if not overwrite:
        existing = _existing_outputs(out)
        if existing:
            raise FileExistsError(f"{existing[0]} exists; use --overwrite")
    return out, fmt, gap


def _matched_source(source, printer, max_subdivisions: int | None, max_triangles: int | None):
    """``(source, resolution)``: generated grains at the subdivisions their printed size calls for
    (``resolution`` None and ``source`` as given when that does not apply)."""
    from .resolution import MAX_MATCHED, match_subdivisions, supports_matching

    if not (isinstance(source, GeneratorSource) and supports_matching(source.method)):
        return source, None
    resolution = match_subdivisions(
        source.method, source.params, size=source.size, size_definition=source.size_definition, printer=printer,
        seeds=source.seeds[:3],
        max_level=MAX_MATCHED if max_subdivisions is None else max_subdivisions,
        max_faces=None if max_triangles is None else max(20, int(max_triangles) // len(source)),
    )
    source = dataclasses.replace(source, params=dataclasses.replace(source.params,
                                                                     subdivisions=resolution.subdivisions))
    return source, resolution


def _csv_row(p: Prepared, plate: int, position: tuple[float, float, float], resolution) -> dict[str, Any]:
    """The CSV row of a placed grain (``plate`` counted from 0)."""
    x, y, z = position
    return {
        "index": p.index, "name": p.name, "source": p.source, "plate": plate + 1,
        "x": x, "y": y, "z": z,
        "size_x": float(p.extents[0]), "size_y": float(p.extents[1]), "size_z": float(p.extents[2]),
        "volume": p.volume, "equivalent_diameter": float(np.cbrt(6 * p.volume / np.pi)),
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
    progress: Callable[[Iterable], Iterable] | None = None,
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
        Triangle budget of the whole job for resolution matching (default
        :data:`DEFAULT_TRIANGLE_BUDGET`; ``None``: no budget).  Each grain may
        use ``max_triangles // count`` faces.
    progress : callable, optional
        Wraps the iterator of grains (a progress bar).

    Returns
    -------
    TrayResult

    Raises
    ------
    ValueError
        For a bad extension, gap, or a grain that does not fit the printer.
    FileExistsError
        If an output exists and ``overwrite`` is false.
    """
    from .printers import get_printer

    printer = get_printer(printer)
    out, fmt, gap = _checked_request(source, printer, out, gap, overwrite)
    resolution = None
    if match_resolution:
        source, resolution = _matched_source(source, printer, max_subdivisions, max_triangles)
    _check_size_of_job(source, workers)

    from ..runtime.staging import signals_held

    made = [q for q in [out.parent, *out.parent.parents] if not q.exists()]
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out)
    packer = ShelfPacker(printer.build_volume, gap, printer.stacking)
    temps: list[Path] = []
    written: list[Path] = []  # outputs already in place: removed again if the run does not complete
    rows: list[dict[str, Any]] = []
    footprints: list[list[np.ndarray]] = []
    layers_of: list[list[int]] = []
    writer = fh = stream = None
    plate = -1
    try:
        it = stream = _prepared_in_order(_tasks(source, fmt, printer.stacking), workers)
        if progress is not None:
            it = progress(it)
        for p in it:
            if not rows:
                packer.compact(len(source), p.extents)
            pl, x, y, z = packer.place(p.extents)
            if pl != plate:
                if writer is not None:
                    writer.close()
                    fh.close()
                fh, writer = _open_plate(out, fmt, temps)
                footprints.append([])
                layers_of.append([])
                plate = pl
            writer.add_object(p.name, p.payload, (x, y, z))
            footprints[-1].append(p.footprint + np.array([x, y], dtype=np.float32))
            layers_of[-1].append(packer.layers - 1)
            rows.append(_csv_row(p, pl, (x, y, z), resolution))
        writer.close()
        fh.close()
        files, previews, csv_path, layer_count = _write_previews_and_table(out, len(temps), footprints, layers_of,
                                                                          rows, printer, gap, written)
        with signals_held():  # the print files last, together: all outputs or none
            for tmp, final in zip(temps, files):
                os.replace(tmp, final)
                written.append(final)
            temps = []
    except BaseException:
        if stream is not None:
            stream.close()  # stops the workers now (an error, Ctrl-C, SIGTERM), not after their current chunks
        if writer is not None:
            writer.abort()
        if fh is not None and not fh.closed:
            fh.close()
        for t in temps + written:
            t.unlink(missing_ok=True)
        for q in made:  # folders this call created, innermost first, if still empty
            try:
                q.rmdir()
            except OSError:
                break
        raise
    return TrayResult(files, previews, csv_path, rows, len(files), resolution, gap, layer_count)


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
