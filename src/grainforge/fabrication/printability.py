"""Will it print?  Checks of a grain mesh against a printer profile.

:func:`check_mesh` runs, for one part:

- **solid**: watertight, manifold, consistently oriented, one body, positive
  volume (:func:`grainforge.geometry.solid.solid_problems`);
- **self-intersection**: pairs of non-adjacent triangles that cross
  (:func:`self_intersections`);
- **wall thickness / minimum feature**: rays cast inward along the normal of
  each face (or an area-weighted sample of faces) measure the local thickness
  of the solid (:func:`local_thickness`).  The part fails when more than
  :data:`THIN_AREA_LIMIT` of its surface is thinner than the printer's
  ``min_wall``; a smaller thin area (sharp corners and tips) is a warning;
- **necks**: the thickness measured at saddle-shaped parts of the surface
  (negative angle defect at the face's vertices), where aggregates of
  particles join.  Thinner than ``min_wall``: fail; thinner than
  :data:`NECK_FACTOR` x ``min_wall``: a warning that the grain is fragile;
- **size**: an equivalent diameter below the printer's reliable ``min_size``
  fails (tested first and listed first), and so does a part larger than the
  build volume.

The rays find their candidate triangles in a :class:`TriangleGrid` walked
along each ray, and test them :data:`MAX_PAIRS` at a time: memory is bounded
by the mesh's own size whatever the printer's wall horizon, and the result
is that of testing every triangle.

All lengths are in millimetres.  Thickness along the inward normal is an
approximation of the medial-axis thickness (it can over-estimate a wall
met at a slant); coplanar overlapping triangles are not reported as
self-intersections.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..geometry.moments import equivalent_diameter  # re-exported: it lived here
from ..geometry.solid import moller_trumbore
from ..rng import as_generator

__all__ = ["CheckResult", "check_mesh", "equivalent_diameter", "TriangleGrid", "triangle_grid", "local_thickness", "self_intersections", "THIN_AREA_LIMIT", "NECK_FACTOR"]

#: largest fraction of the surface area allowed below ``min_wall`` before a part fails.
THIN_AREA_LIMIT = 0.005
#: necks thinner than this many ``min_wall`` are reported as fragile.
NECK_FACTOR = 2.0
#: walls are measured up to this many ``min_wall`` (thicker is reported as "thick enough").
THICKNESS_HORIZON = 4.0
#: faces sampled for ray casting (all faces when there are fewer).
MAX_RAYS = 4000
#: (ray, triangle) candidate pairs the wall-thickness test holds at once (about 350 bytes each):
#: bounds its memory whatever the mesh, the grain's size and the printer's horizon.
MAX_PAIRS = 1 << 17
#: the triangle grid of the wall-thickness test holds at most this many (triangle, cell) entries per
#: triangle, plus 1000 (its cells are coarsened until it does) ...
GRID_ENTRIES_PER_FACE = 8
#: ... and its cells are at least 1/GRID_MAX_CELLS of the mesh's extent.
GRID_MAX_CELLS = 4096


@dataclass
class CheckResult:
    """Outcome of :func:`check_mesh` for one part."""

    name: str
    faces: int
    equivalent_diameter: float
    solid: list[str]
    self_intersections: int
    min_thickness: float
    thin_area: float
    min_neck: float
    failures: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    #: walls are measured up to this thickness (mm); inf when not measured (not a valid solid)
    horizon: float = np.inf

    @property
    def ok(self) -> bool:
        return not self.failures

    @property
    def status(self) -> str:
        return "FAIL" if self.failures else ("WARN" if self.warnings else "OK")

    def row(self) -> dict[str, Any]:
        """The part's row of ``grainforge check``'s table.

        Returns
        -------
        dict
            ``part``, ``status``, ``faces``, ``d_eq_mm``, ``solid``, ``self_intersections``, the wall and neck
            columns (mm), ``thin_area_%`` and ``problems``.
        """
        return {
            "part": self.name, "status": self.status, "faces": self.faces,
            "d_eq_mm": round(self.equivalent_diameter, 4),
            "solid": "yes" if not self.solid else "no",
            "self_intersections": self.self_intersections,
            **self._thickness("min_wall", self.min_thickness),
            "thin_area_%": round(100 * self.thin_area, 2),
            **self._thickness("min_neck", self.min_neck),
            "problems": "; ".join(self.failures + self.warnings),
        }

    def _thickness(self, name: str, value: float) -> dict[str, Any]:
        """``{name}_mm`` as a number and ``{name}_status``: ``measured``; ``thicker`` (nothing thinner
        than the measuring horizon, which ``{name}_mm`` then holds: a lower bound); ``not measured``
        (empty ``{name}_mm``: the mesh is not a valid solid)."""
        if np.isfinite(value):
            return {f"{name}_mm": round(float(value), 4), f"{name}_status": "measured"}
        if np.isfinite(self.horizon):
            return {f"{name}_mm": round(float(self.horizon), 4), f"{name}_status": "thicker"}
        return {f"{name}_mm": "", f"{name}_status": "not measured"}


def self_intersections(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Number of self-intersecting triangle pairs of the mesh as written (float32, vertices merged).

    The same test as the solid contract (:func:`grainforge.geometry.solid.self_intersections`).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions, mm.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    int

    Examples
    --------
    >>> import trimesh
    >>> a = trimesh.creation.box()
    >>> self_intersections(a.vertices, a.faces)
    0
    >>> b = a.copy().apply_translation([0.5, 0.3, 0.2])
    >>> both = trimesh.util.concatenate([a, b])
    >>> self_intersections(both.vertices, both.faces) > 0
    True
    """
    from ..geometry.solid import as_written
    from ..geometry.solid import self_intersections as count

    return count(*as_written(vertices, faces))


def _segment_hits_triangle(p0, p1, tri):
    """Whether segment p0→p1 crosses each triangle's interior (strictly, by a 1e-9 margin)."""
    ok, u, w, t = moller_trumbore(p0, p1 - p0, tri, det_min=1e-15)
    eps = 1e-9
    return ok & (u > eps) & (w > eps) & (u + w < 1 - eps) & (t > eps) & (t < 1 - eps)


def local_thickness(mesh, max_rays: int = MAX_RAYS, max_distance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Thickness of the solid behind sampled faces, by rays cast inward along the face normals.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed, outward-oriented mesh.
    max_rays : int
        At most this many faces are sampled (area-weighted, deterministic).
    max_distance : float, optional
        Only look this far: thicker places get ``inf``.  Much faster on
        fine meshes (each ray is tested against the triangles near it only).

    Returns
    -------
    faces : (k,) int64
        Sampled face indices.
    thickness : (k,) float64
        Distance to the first surface crossed (``inf`` if none).

    Examples
    --------
    >>> import trimesh
    >>> _, t = local_thickness(trimesh.creation.box(extents=(4.0, 4.0, 0.1)))
    >>> round(float(t.min()), 6)
    0.1
    """
    from trimesh.ray.ray_triangle import RayMeshIntersector

    area = np.asarray(mesh.area_faces)
    usable = np.flatnonzero(area > 0)  # zero-area faces have no normal (and rng.choice needs p > 0)
    if len(usable) <= max_rays:
        idx = usable
    else:
        rng = as_generator(0)  # a fixed sample: the same faces every run
        idx = np.sort(rng.choice(usable, size=max_rays, replace=False, p=area[usable] / area[usable].sum()))
    normals = np.asarray(mesh.face_normals)[idx]
    scale = float(np.ptp(mesh.vertices, axis=0).max())
    eps = 1e-7 * scale
    origins = np.asarray(mesh.triangles_center)[idx] - normals * eps
    if max_distance is not None:
        return idx, _short_rays(mesh, idx, origins, normals, float(max_distance), eps)
    locs, ray_idx, tri_idx = RayMeshIntersector(mesh).intersects_location(origins, -normals, multiple_hits=True)
    thickness = np.full(len(idx), np.inf)
    if len(ray_idx):
        dist = np.einsum("ij,ij->i", locs - origins[ray_idx], -normals[ray_idx])
        valid = (dist > eps) & (tri_idx != idx[ray_idx])
        np.minimum.at(thickness, ray_idx[valid], dist[valid] + eps)
    return idx, thickness


def _box_cells(c0: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every cell of the boxes of cells ``c0 .. c0 + span - 1``: (box index, (n, 3) cell) per cell."""
    n = span.prod(axis=1, dtype=np.int64)
    ids = np.int32 if n.sum() + len(c0) < 2**31 else np.int64  # 32-bit ids when they fit (less memory)
    owner = np.repeat(np.arange(len(c0), dtype=ids), n)
    local = np.arange(int(n.sum()), dtype=ids) - np.repeat((np.cumsum(n) - n).astype(ids), n)
    sx, sy = span[owner, 0], span[owner, 1]
    step = np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1).astype(c0.dtype)
    return owner, c0[owner] + step


@dataclass(frozen=True)
class TriangleGrid:
    """Triangles binned in a uniform grid of cubic cells: each in every cell its bounding box overlaps.

    Only occupied cells are stored, sorted by key, so memory is the number of
    (triangle, cell) entries, which :func:`triangle_grid` bounds by the mesh's
    own size.
    """

    origin: np.ndarray  #: (3,) corner of cell (0, 0, 0)
    cell: float  #: edge of a cell
    dims: np.ndarray  #: (3,) cells along x, y, z
    keys: np.ndarray  #: (K,) occupied cells, ``(i * dims[1] + j) * dims[2] + k``, sorted
    first: np.ndarray  #: (K,) where each cell's triangles start in ``owner``
    count: np.ndarray  #: (K,) how many triangles each cell holds
    owner: np.ndarray  #: (E,) triangle indices, grouped by cell

    @property
    def entries(self) -> int:
        """Number of (triangle, cell) entries."""
        return len(self.owner)

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Integer cell coordinates of ``points`` (not clipped to the grid).

        Parameters
        ----------
        points : (n, 3) ndarray of float
            Points, in the triangles' unit.

        Returns
        -------
        (n, 3) int64
        """
        return np.floor((points - self.origin) / self.cell).astype(np.int64)


def triangle_grid(tri: np.ndarray, max_entries: int | None = None) -> TriangleGrid:
    """Bin triangles ``(F, 3, 3)`` in a :class:`TriangleGrid`, coarse enough to hold at most ``max_entries``.

    The cell starts at twice the median triangle extent (at least
    1/:data:`GRID_MAX_CELLS` of the mesh's extent) and doubles until the
    entries fit ``max_entries`` (default :data:`GRID_ENTRIES_PER_FACE` per
    triangle plus 1000; never less than one per triangle): a few big triangles
    cannot make the grid large.

    Parameters
    ----------
    tri : (F, 3, 3) array_like of float
        The triangles' corners.
    max_entries : int, optional
        Most (triangle, cell) entries stored (default :data:`GRID_ENTRIES_PER_FACE` · F + 1000).

    Returns
    -------
    TriangleGrid

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> g = triangle_grid(s.triangles)
    >>> g.entries <= GRID_ENTRIES_PER_FACE * len(s.faces) + 1000
    True
    >>> triangle_grid(s.triangles, max_entries=len(s.faces)).entries   # one cell: every triangle once
    1280
    """
    tri = np.asarray(tri, dtype=np.float64)
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    F = len(tri)
    budget = GRID_ENTRIES_PER_FACE * F + 1000 if max_entries is None else int(max_entries)
    budget = max(budget, F)
    origin = lo.min(axis=0)
    extent = float((hi.max(axis=0) - origin).max())
    size = np.maximum(hi - lo, 0).max(axis=1)
    h = max(2.0 * float(np.median(size)), extent / GRID_MAX_CELLS, np.finfo(np.float64).tiny)
    while True:  # once the cell exceeds the extent every triangle is in one cell: F entries, the loop ends
        c0 = np.floor((lo - origin) / h).astype(np.int32)  # at most GRID_MAX_CELLS along the extent
        c1 = np.floor((hi - origin) / h).astype(np.int32)
        span = c1 - c0 + 1
        if int(span.prod(axis=1, dtype=np.int64).sum()) <= budget:
            break
        h *= 2.0
    dims = (c1.max(axis=0) + 1).astype(np.int64)  # cell keys are int64
    del c1, lo, hi, size
    owner, cell = _box_cells(c0, span)
    del c0, span
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    del cell
    order = np.argsort(key, kind="stable")
    key = key[order]
    owner = owner[order]
    del order
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[first, len(key)])
    return TriangleGrid(origin, h, dims, key[first], first, count, owner)


def _ray_cells(grid: TriangleGrid, origins, directions, reach: float, pad: float):
    """The occupied cells that rays ``origins + s * directions`` (unit directions, 0 ≤ s ≤ reach) pass.

    Each ray is cut into segments of at most half a cell; a cell is kept when
    a segment's bounding box, grown by ``pad``, overlaps it (so no cell a ray
    crosses is missed, and a segment meets at most 2 x 2 x 2 cells).

    Returns
    -------
    ray : (m,) int64
        Ray index (into ``origins``) of each (ray, cell) pair, each pair once.
    slot : (m,) int64
        Index of the cell in ``grid.keys``.
    """
    n = _segments(grid, reach)
    s = np.linspace(0.0, reach, n + 1)
    p = origins[:, None, :] + s[None, :, None] * directions[:, None, :]  # (r, n + 1, 3)
    c0 = np.maximum(grid.cell_of(np.minimum(p[:, :-1], p[:, 1:]).reshape(-1, 3) - pad), 0)
    c1 = np.minimum(grid.cell_of(np.maximum(p[:, :-1], p[:, 1:]).reshape(-1, 3) + pad), grid.dims - 1)
    inside = (c0 <= c1).all(axis=1)  # segments outside the grid meet no triangle
    seg, cell = _box_cells(c0[inside], c1[inside] - c0[inside] + 1)
    ray = np.flatnonzero(inside)[seg] // n
    key = (cell[:, 0] * grid.dims[1] + cell[:, 1]) * grid.dims[2] + cell[:, 2]
    cells = int(grid.dims[0]) * int(grid.dims[1]) * int(grid.dims[2])  # <= 4097**3: no overflow
    if cells * len(origins) < 2**62:  # each (ray, cell) once (consecutive segments share cells)
        packed = np.unique(ray * np.int64(cells) + key)
        ray, key = packed // cells, packed % cells
    slot = np.minimum(np.searchsorted(grid.keys, key), len(grid.keys) - 1)
    hit = grid.keys[slot] == key
    return ray[hit], slot[hit]


def _segments(grid: TriangleGrid, reach: float) -> int:
    """Segments of at most half a cell that cover a ray of length ``reach``."""
    return max(1, int(np.ceil(2.0 * reach / grid.cell)))


def _candidate_slices(grid: TriangleGrid, ray: np.ndarray, slot: np.ndarray, max_pairs: int):
    """(ray, triangle) pairs of the given (ray, cell) pairs, at most ``max_pairs`` at a time."""
    count = grid.count[slot]
    end = np.cumsum(count)
    total = int(end[-1]) if len(end) else 0
    for a in range(0, total, max_pairs):
        pos = np.arange(a, min(a + max_pairs, total))
        k = np.searchsorted(end, pos, side="right")
        yield ray[k], grid.owner[grid.first[slot[k]] + pos - (end[k] - count[k])]


def _short_rays(mesh, idx, origins, normals, length, eps, max_pairs: int = MAX_PAIRS):
    """Distance along -normal to the first triangle within ``length`` (``inf`` if none).

    Candidates come from a :class:`TriangleGrid` walked along each ray, up to
    ``length`` or the mesh's bounding-box diagonal, whichever is shorter
    (nothing lies further); rays are taken in groups and candidate pairs at
    most ``max_pairs`` at a time, so memory stays bounded whatever the mesh
    size and the horizon.  Every triangle a ray can hit is a candidate: the
    result is that of testing every triangle.
    """
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    out = np.full(len(idx), np.inf)
    if len(idx) == 0 or len(tri) == 0:
        return out
    grid = triangle_grid(tri)
    diag = float(np.linalg.norm(np.ptp(tri.reshape(-1, 3), axis=0)))
    reach = min(length, diag + 4 * eps)  # an origin lies within eps of the mesh: nothing is further
    pad = 2 * eps + 1e-9 * diag
    direction = -normals * length
    per = max(1, max_pairs // (8 * _segments(grid, reach)))  # (ray, cell) pairs of a group <= max_pairs
    for r0 in range(0, len(idx), per):
        ray, slot = _ray_cells(grid, origins[r0:r0 + per], -normals[r0:r0 + per], reach, pad)
        for ray_k, cand in _candidate_slices(grid, ray + r0, slot, max_pairs):
            keep = cand != idx[ray_k]
            ray_k, cand = ray_k[keep], cand[keep]
            ok, u, w, t = moller_trumbore(origins[ray_k], direction[ray_k], tri[cand], det_min=1e-30)
            hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t * length > eps) & (t <= 1)
            np.minimum.at(out, ray_k[hit], t[hit] * length + eps)
    return out


def check_mesh(vertices: np.ndarray, faces: np.ndarray, printer, name: str = "part") -> CheckResult:
    """Check one part against ``printer`` (a :class:`~grainforge.fabrication.printers.Printer` or name).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions, mm.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    printer : Printer or str
        A profile or its name (:func:`~grainforge.fabrication.printers.get_printer`).
    name : str, default "part"
        The part's name in the result.

    Returns
    -------
    CheckResult
        ``failures`` (too small, not a valid solid, self-intersections, larger than the build volume, thin
        walls or necks) and ``warnings``.

    Raises
    ------
    ValueError
        For an unknown printer.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3, radius=1.0)
    >>> r = check_mesh(s.vertices, s.faces, "objet-eden-250")
    >>> r.status, r.min_thickness    # nothing thinner than 4 x min_wall = 0.4 mm
    ('OK', inf)
    >>> tiny = check_mesh(s.vertices * 0.05, s.faces, "objet-eden-250")
    >>> tiny.status, tiny.failures[0][:31]
    ('FAIL', 'equivalent diameter 0.0997 mm <')
    """
    import trimesh

    from ..geometry.solid import solid_problems
    from .printers import get_printer

    printer = get_printer(printer)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    problems = solid_problems(v, f, intersections=False)  # the solid contract; intersections counted below
    d_eq = equivalent_diameter(v, f)
    res = CheckResult(name, len(f), d_eq, problems, 0, np.inf, 0.0, np.inf)
    small = printer.size_problem(d_eq)  # first: the cheapest test, and the one that matters most
    if small is not None:
        res.failures.append(small)
    if problems:
        res.failures.append("not a valid solid: " + "; ".join(problems))
    if len(f) == 0 or not np.isfinite(v).all():
        return res
    res.self_intersections = self_intersections(v, f)
    if res.self_intersections:
        res.failures.append(f"{res.self_intersections} self-intersecting triangle pairs")
    ext = np.sort(np.ptp(v, axis=0))[::-1]
    if (ext > np.sort(printer.build_volume)[::-1]).any():
        res.failures.append(f"larger than the build volume ({' x '.join(f'{e:.1f}' for e in ext)} mm)")
    if not problems:
        mesh = trimesh.Trimesh(v, f, process=False, validate=False)
        res.horizon = THICKNESS_HORIZON * printer.min_wall
        idx, t = local_thickness(mesh, max_distance=res.horizon)
        area = mesh.area_faces[idx]
        thin = t < printer.min_wall
        res.min_thickness = float(t.min())
        res.thin_area = float(area[thin].sum() / area.sum())
        if res.thin_area > THIN_AREA_LIMIT:
            res.failures.append(f"{100 * res.thin_area:.1f}% of the surface is thinner than the "
                                f"minimum wall {printer.min_wall:g} mm (thinnest {res.min_thickness:.3g} mm)")
        elif thin.any():
            res.warnings.append(f"thin spots (min {res.min_thickness:.3g} mm < {printer.min_wall:g} mm) "
                                f"on {100 * res.thin_area:.2f}% of the surface: sharp tips will be rounded")
        defect = mesh.vertex_defects[f[idx]].mean(axis=1)
        saddle = defect < -1e-9
        if saddle.any():
            res.min_neck = float(t[saddle].min())
            if res.min_neck < printer.min_wall and res.thin_area <= THIN_AREA_LIMIT:
                res.failures.append(f"neck {res.min_neck:.3g} mm thinner than the minimum wall {printer.min_wall:g} mm")
            elif res.min_neck < NECK_FACTOR * printer.min_wall:
                res.warnings.append(f"fragile neck {res.min_neck:.3g} mm (< {NECK_FACTOR:g} x minimum wall)")
    return res
