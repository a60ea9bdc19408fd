"""The solid contract every generated mesh honours, checked as mesh readers see it.

STL (and every slicer) identifies vertices by *position*, in float32.  So
:func:`solid_problems` first rounds the coordinates to float32 and merges
vertices that land on the same position (:func:`as_written`), and then asks:

- **no collapsed or near-zero-area faces**: every triangle's area is at least
  :data:`AREA_TOLERANCE` · d², d the bounding-box diagonal (1e-12 · d² is the
  area of a square of side 1e-6 · d, about 16 float32 steps of the largest
  coordinate);
- **closed 2-manifold, consistently oriented**: every edge is shared by
  exactly two faces, used once in each direction, and the faces around every
  vertex form a single fan (no pinch at a vertex);
- **one body** (faces connected through edges) with **positive volume**;
- **no self-intersecting triangle pairs** (:func:`self_intersections`), or,
  for star-shaped generators, the certificate :func:`star_certificate`
  (every face seen from the centre with positive solid angle and the surface
  wrapping the centre exactly once: then the radial projection onto the unit
  sphere is one-to-one, so no two triangles can cross).

``grainforge check`` (:func:`grainforge.fabrication.printability.check_mesh`),
``grainforge analyse`` and :func:`require_solid` (run on every generated
grain) all use :func:`solid_problems`.

The mass moments the checks use (volume, centroid, second moments) are
:mod:`grainforge.geometry.moments`'s; they are importable from here too.
"""

from __future__ import annotations

import numpy as np

from .moments import cross3, second_moments, signed_volume, volume_and_centroid, volume_centroid

__all__ = [
    "signed_volume", "volume_centroid", "face_components", "is_closed", "as_written", "solid_problems",
    "require_solid", "index_problems", "split_bodies", "self_intersections", "star_certificate", "AREA_TOLERANCE",
    "cross3", "volume_and_centroid", "second_moments", "moller_trumbore", "FLOAT32_OFFSET_LIMIT",
    "precision_problem", "mesh_size_problem", "winding_numbers", "body_nesting",
]

#: smallest face area allowed, relative to the squared bounding-box diagonal of the mesh.
AREA_TOLERANCE = 1e-12


def face_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Label of the vertex-connected component of every face, shape (F,).

    Faces touching at a single vertex get the same label; see
    :func:`solid_problems` for bodies connected through edges.

    Parameters
    ----------
    faces : (F, 3) array_like of int
        Triangles.
    n_vertices : int
        Number of vertices (at least ``faces.max() + 1``).

    Returns
    -------
    (F,) int
        Component label of each face, ``0 … n_components − 1``.

    Examples
    --------
    >>> face_components(np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]]), 7).tolist()
    [0, 0, 1]
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    _, labels = connected_components(g, directed=False)
    return labels[faces[:, 0]]


def _directed_edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted keys of every directed edge and of its reverse."""
    # int32 keys when they fit (sorting them is about twice as fast)
    f = np.asarray(faces)
    top = max(int(n_vertices), int(f.max()) + 1 if f.size else 0)
    dt = np.int32 if top**2 < 2**31 and (f.size == 0 or f.min() >= 0) else np.int64
    f = f.astype(dt, copy=False)
    a = f.ravel()
    b = f[:, [1, 2, 0]].ravel()
    nv = dt(n_vertices)
    return np.sort(a * nv + b), np.sort(b * nv + a)


def is_closed(faces: np.ndarray, n_vertices: int) -> bool:
    """True if every directed edge appears once and its reverse once (closed, consistently oriented).

    Parameters
    ----------
    faces : (F, 3) array_like of int
        Triangles.
    n_vertices : int
        Number of vertices (at least ``faces.max() + 1``).

    Returns
    -------
    bool
        False for an empty face list, an open edge, or an edge used twice in one direction.

    Examples
    --------
    >>> import trimesh
    >>> b = trimesh.creation.box()
    >>> is_closed(b.faces, len(b.vertices)), is_closed(b.faces[:-1], len(b.vertices))
    (True, False)
    """
    if len(faces) == 0:
        return False
    directed, reverse = _directed_edges(faces, n_vertices)
    if np.any(directed[1:] == directed[:-1]):
        return False
    return bool(np.array_equal(directed, reverse))


def as_written(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh as a reader sees it: coordinates rounded to float32, vertices merged by position.

    Every face is kept (faces whose corners merge become degenerate).  The
    vertices are returned as float64 holding float32 values.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.

    Returns
    -------
    vertices : (V', 3) float64
        The distinct float32 positions, sorted (x, then y, then z), as float64.
    faces : (F, 3) int64
        The same faces, re-indexed into the merged vertices.

    Examples
    --------
    >>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1 + 1e-12, 0, 0]])
    >>> w, f = as_written(v, np.array([[0, 1, 2], [0, 3, 2]]))
    >>> len(w), f.tolist()
    (3, [[0, 2, 1], [0, 2, 1]])
    """
    v32 = np.asarray(vertices, dtype=np.float64).astype(np.float32)
    u, inv = unique_rows(v32)
    return u.astype(np.float64), inv[np.asarray(faces, dtype=np.int64)].reshape(-1, 3)


def _edge_components(faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Number and labels of the components of faces connected through shared edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(faces)
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    key = np.minimum(a, b) * (int(faces.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    fi = order[:-1][same] // 3
    fj = order[1:][same] // 3
    g = coo_matrix((np.ones(len(fi)), (fi, fj)), shape=(F, F))
    return connected_components(g, directed=False)


def _fans(faces: np.ndarray, n_vertices: int) -> int:
    """Number of vertices whose faces form more than one fan (given every edge pairs two faces oppositely)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = len(faces)
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    nv = np.int64(n_vertices)
    fwd = a * nv + b
    order = np.argsort(fwd)
    sorted_fwd = fwd[order]
    del fwd
    pos = order[np.searchsorted(sorted_fwd, b * nv + a)]  # the half-edge b->a paired with a->b
    del order, sorted_fwd, b
    # corner ids: 3*f + k is the corner of face f at vertex faces[f, k]; 32-bit ids when they fit (less memory)
    ids = np.int32 if 3 * F < 2**31 else np.int64
    he = np.arange(3 * F, dtype=ids)
    rows = np.concatenate([he, 3 * (he // 3) + (he + 1) % 3])  # ... and the corner of the edge's end vertex b
    del he
    pos = pos.astype(ids)
    cols = np.concatenate([3 * (pos // 3) + (pos + 1) % 3, pos])  # half-edge b->a ends at a, starts at b (pos)
    del pos
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * F, 3 * F))
    del rows, cols
    n_comp, lab = connected_components(g, directed=False)
    del g
    used = np.unique(faces)
    first = np.zeros(n_comp, dtype=np.int64)
    first[lab] = a  # every corner of a fan holds the same vertex
    return int(np.bincount(first, minlength=n_vertices)[used].__gt__(1).sum())


def star_certificate(vertices: np.ndarray, faces: np.ndarray, centre=(0.0, 0.0, 0.0)) -> bool:
    """Proof that a closed, oriented mesh star-shaped about ``centre`` does not self-intersect.

    True when every face subtends a positive solid angle seen from ``centre``
    (the centre lies strictly inside every face's plane, on the inner side)
    and the solid angles add up to 4π (the surface wraps the centre once).
    Then central projection maps the surface one-to-one onto the unit
    sphere (a local homeomorphism of degree one from a closed surface), so
    no two triangles share a point other than their common edges and
    vertices.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.
    centre : (3,) array_like of float, optional
        The point the mesh is star-shaped about (default: the origin).

    Returns
    -------
    bool
        True when the certificate holds; False says nothing (the full check decides).

    Examples
    --------
    >>> from grainforge.geometry.geodesic import icosphere
    >>> v, f = icosphere(2)
    >>> star_certificate(v, f), star_certificate(v, f, centre=(0.0, 0.0, 1.5))
    (True, False)
    """
    v = np.asarray(vertices, dtype=np.float64) - np.asarray(centre, dtype=np.float64)
    a, b, c = (v[faces[:, i]] for i in range(3))
    det = np.einsum("ij,ij->i", a, cross3(b, c))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    if not (det > 0).all() or not (la > 0).all():
        return False
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    omega = 2.0 * np.arctan2(det, den)  # Van Oosterom & Strackee (1983)
    return bool(abs(omega.sum() - 4.0 * np.pi) < 1e-6)


#: candidate triangle pairs :func:`self_intersections` builds at once (bounds its memory by a constant)
PAIR_BLOCK = 1 << 19


def _candidate_pairs(tri: np.ndarray, block: int = PAIR_BLOCK):
    """Pairs (i < j) of triangles whose bounding boxes overlap, from a uniform grid (no O(F²) step).

    Yields (P, 2) arrays, each built from at most about ``block`` pairs of
    triangles sharing a cell (plus one cell's worth), so memory does not grow
    with the number of pairs.  A pair is reported once, by the first cell of
    the overlap of its two boxes of cells, so no global de-duplication is
    needed.
    """
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    F = len(tri)
    ext = np.maximum(hi - lo, 0).max(axis=1)
    h = max(float(np.median(ext)) * 2.0, float(np.ptp(tri.reshape(-1, 3), axis=0).max()) / 4096.0, 1e-300)
    origin = lo.min(axis=0)
    while True:  # coarsen the grid until big triangles cover few cells (bounded memory)
        c0 = np.floor((lo - origin) / h).astype(np.int32)  # at most 4096 cells along the extent: 32 bits
        c1 = np.floor((hi - origin) / h).astype(np.int32)
        span = c1 - c0 + 1
        n = span.prod(axis=1, dtype=np.int64)
        if n.sum() <= 8 * F + 1000:
            break
        h *= 2.0
    del c1
    ids = np.int32 if 8 * F + 1000 < 2**31 else np.int64  # triangle and entry ids: 32 bits when they fit
    owner = np.repeat(np.arange(F, dtype=ids), n)
    local = np.arange(int(n.sum()), dtype=ids) - np.repeat((np.cumsum(n) - n).astype(ids), n)
    sx, sy = span[owner, 0], span[owner, 1]
    cell = c0[owner] + np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], axis=1).astype(np.int32)
    del local, sx, sy, span, n
    dims = (cell.max(axis=0) + 1).astype(np.int64)
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]  # int64 (dims is)
    del cell
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    del order
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ends = np.r_[starts[1:], len(key)]
    gsize = ends - starts
    pos = np.arange(len(key))
    count = np.repeat(ends, gsize) - pos - 1  # pairs that start at each entry (with the later ones of its cell)
    del starts, ends, gsize
    done = np.cumsum(count)
    a = 0
    while a < len(key):
        b = max(a + 1, int(np.searchsorted(done, (done[a - 1] if a else 0) + block, side="right")))
        cnt = count[a:b]
        total = int(cnt.sum())
        if total:
            left = np.repeat(pos[a:b], cnt)
            right = left + 1 + (np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt))
            i, j = owner[left], owner[right]
            ref = np.maximum(c0[i], c0[j])  # first cell of the overlap of the two boxes of cells
            first = (ref[:, 0] * dims[1] + ref[:, 1]) * dims[2] + ref[:, 2] == key[left]
            i, j = i[first], j[first]
            i, j = np.minimum(i, j), np.maximum(i, j)
            overlap = ((lo[i] <= hi[j]) & (lo[j] <= hi[i])).all(axis=1)
            yield np.stack([i[overlap], j[overlap]], axis=1)
        a = b


def moller_trumbore(p0, d, tri, *, det_min: float, relative: bool = False):
    """Vectorised Möller–Trumbore: barycentrics (u, w) and parameter t of ``p0 + t·d`` on each triangle.

    The one ray/segment–triangle intersection of grainforge (the solid contract's
    self-intersection test, the printability checks' thickness rays).

    Parameters
    ----------
    p0, d : (n, 3) float64
        Ray origins and directions (a segment p0→p1 is ``d = p1 − p0``, hit for 0 < t < 1).
    tri : (n, 3, 3) float64
        The matching triangles.
    det_min : float
        ``ok`` is false where the ray is parallel to the triangle: |det| ≤ det_min, or with
        ``relative`` |det| ≤ det_min · |d| |e1| |e2| (a threshold that scales with the mesh).
    relative : bool, default False
        Scale ``det_min`` by the lengths of ``d`` and of the triangle's edges.

    Returns
    -------
    ok : (n,) bool
    u, w, t : (n,) float64

    Examples
    --------
    >>> tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    >>> ok, u, w, t = moller_trumbore(np.array([[0.2, 0.3, -1.0]]), np.array([[0.0, 0, 2]]), tri, det_min=1e-15)
    >>> bool(ok[0]), round(float(u[0]), 12), round(float(w[0]), 12), float(t[0])
    (True, 0.2, 0.3, 0.5)
    """
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    h = np.cross(d, e2)
    a = np.einsum("ij,ij->i", e1, h)
    if relative:
        det_min = det_min * (np.linalg.norm(d, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
    ok = np.abs(a) > det_min
    inv = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    s = p0 - tri[:, 0]
    u = inv * np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    w = inv * np.einsum("ij,ij->i", d, q)
    t = inv * np.einsum("ij,ij->i", e2, q)
    return ok, u, w, t


def _segments_cross(p0, p1, tri, eps: float = 1e-9) -> np.ndarray:
    """Whether each segment p0→p1 crosses the interior of the matching triangle (strictly, relative margin eps)."""
    ok, u, w, t = moller_trumbore(p0, p1 - p0, tri, det_min=1e-12, relative=True)
    return ok & (u > eps) & (w > eps) & (u + w < 1 - eps) & (t > eps) & (t < 1 - eps)


def self_intersections(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Number of pairs of triangles whose interiors cross.

    Candidate pairs are triangles with overlapping bounding boxes (uniform
    grid).  Pairs sharing an edge are skipped; for pairs sharing one vertex
    only the edges opposite it are tested; otherwise each of the six edges is
    tested against the other triangle (vectorised Möller–Trumbore, strict
    interior by a relative margin of 1e-9).  Coplanar overlaps are not seen
    here (they show up as edges shared by more than two faces).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.

    Returns
    -------
    int
        The number of triangle pairs whose interiors cross (0 for a valid solid).

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
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]  # collapsed faces cross nothing
    if len(f) < 2:
        return 0
    tri = v[f]
    hits = 0
    for pairs in _candidate_pairs(tri):
        i, j = pairs.T
        same = f[i][:, :, None] == f[j][:, None, :]  # (P, 3, 3): corner k of i equals corner l of j
        shared = same.sum(axis=(1, 2))
        hit = np.zeros(len(i), dtype=bool)
        for a, b, sm in ((i, j, same.any(axis=2)), (j, i, same.any(axis=1))):
            for k in range(3):
                # edge k of a runs from corner k to corner k+1; skip it when it touches the shared vertex
                touches = sm[:, k] | sm[:, (k + 1) % 3]
                sel = (shared == 0) | ((shared == 1) & ~touches)
                if sel.any():
                    idx = np.flatnonzero(sel)
                    hit[idx] |= _segments_cross(tri[a[idx], k], tri[a[idx], (k + 1) % 3], tri[b[idx]])
        hits += int((hit & (shared < 2)).sum())
    return hits


def solid_problems(vertices: np.ndarray, faces: np.ndarray, *, intersections: bool = True,
                   star_centre=None, merged: bool = False) -> list[str]:
    """What stops the mesh, as a reader sees it, from being a valid solid (empty list if nothing).

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    intersections : bool
        Also look for self-intersecting triangle pairs (the slowest check).
    star_centre : (3,) float, optional
        For star-shaped bodies: once the edges pair up, try
        :func:`star_certificate` about this point (with ``intersections``); it
        proves one body, no pinched vertex, positive volume and no
        self-intersection, so those checks are skipped.  If it does not hold,
        every check runs.  The answer is the same either way, only faster.
    merged : bool
        The caller promises the vertices are already as a reader sees them:
        distinct positions (as :func:`split_bodies` returns them).  If they
        also hold float32 values exactly, the float32 rounding and merge is
        skipped (same answer, faster); otherwise the flag is ignored.

    Returns
    -------
    list of str
        One phrase per problem found (``"12 open edges (not watertight)"``), empty for a valid solid.  The
        checks stop at the first failing group, so a mesh with open edges is not also tested for
        self-intersections.

    Examples
    --------
    >>> import trimesh
    >>> a = trimesh.creation.box()
    >>> b = trimesh.creation.box()
    >>> _ = b.apply_translation((1, 1, 0))     # touches a along one edge only
    >>> solid_problems(a.vertices, a.faces)
    []
    >>> both = trimesh.util.concatenate([a, b])
    >>> solid_problems(both.vertices, both.faces)
    ['1 edges shared by more than two faces']
    """
    problems: list[str] = []
    if len(faces) == 0 or len(vertices) == 0:
        return ["empty mesh"]
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        return ["faces are not triangles"]
    if not np.isfinite(vertices).all():
        return ["non-finite vertex coordinates"]
    if faces.min() < 0 or faces.max() >= len(vertices):
        return ["face index out of range"]
    with np.errstate(over="ignore"):
        v32 = vertices.astype(np.float32)
    if not np.isfinite(v32).all():
        return ["coordinates beyond the float32 range"]
    if merged and np.array_equal(v32, vertices):  # already float32 and merged: as written as is
        v, f = vertices, faces
    else:
        v, f = as_written(vertices, faces)
    collapsed = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if collapsed.any():
        problems.append(f"{int(collapsed.sum())} faces collapse when written (float32, vertices merged)")
    diag2 = float((np.ptp(v[np.bincount(f.ravel(), minlength=len(v)) > 0], axis=0) ** 2).sum())  # used vertices
    area = 0.5 * np.linalg.norm(cross3(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    tiny = ~collapsed & (area < AREA_TOLERANCE * diag2)
    if tiny.any():
        problems.append(f"{int(tiny.sum())} faces of near-zero area (< {AREA_TOLERANCE:g}·d²)")
    if collapsed.any():
        f = f[~collapsed]
        if len(f) == 0:
            return problems
    nv = np.int64(len(v))
    a = f.ravel()
    b = np.roll(f, -1, axis=1).ravel()
    und = np.minimum(a, b) * nv + np.maximum(a, b)
    _, counts = np.unique(und, return_counts=True)
    if (counts == 1).any():
        problems.append(f"{int((counts == 1).sum())} open edges (not watertight)")
    if (counts > 2).any():
        problems.append(f"{int((counts > 2).sum())} edges shared by more than two faces")
    fwd = np.sort(a * nv + b)
    if (fwd[1:] == fwd[:-1]).any():
        twice = int(np.count_nonzero(np.unique(fwd[1:][fwd[1:] == fwd[:-1]])))
        if (counts <= 2).all():
            problems.append(f"{twice} edges used twice in the same direction (inconsistent orientation)")
    del a, b, und, counts, fwd  # the edge keys are not needed below (less memory for the fan test)
    if problems:
        return problems
    if intersections and star_centre is not None and star_certificate(v, f, star_centre):
        # every edge pairs two faces oppositely and the surface projects one-to-one onto the sphere
        # about the centre: one body, no pinched vertex (its fans would cover their directions twice),
        # positive volume (every face's tetrahedron is positive) and no self-intersection
        return problems
    pinched = _fans(f, len(v))
    if pinched:
        problems.append(f"{pinched} vertices where the surface pinches (faces around them form several fans)")
    bodies, _ = _edge_components(f)
    if bodies != 1:
        problems.append(f"{bodies} separate bodies")
    if problems:
        return problems
    if signed_volume(v, f) <= 0:
        return ["non-positive volume (inward orientation)"]
    if intersections:  # (a star certificate, if asked for, failed above)
        n = self_intersections(v, f)
        if n:
            problems.append(f"{n} self-intersecting triangle pairs")
    return problems


def index_problems(vertices: np.ndarray, faces: np.ndarray) -> list[str]:
    """The old, weaker check on vertex *indices* (no float32 rounding, no merging, no intersection test).

    No generator relies on it any more (every grain passes :func:`solid_problems`);
    kept to show, in tests, what the index view misses.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.

    Returns
    -------
    list of str
        The first problem found (``"several bodies"``, ...), or an empty list.
    """
    if len(faces) == 0 or len(vertices) == 0:
        return ["empty mesh"]
    faces = np.asarray(faces, dtype=np.int64)
    if not np.isfinite(vertices).all():
        return ["non-finite vertex coordinates"]
    if not is_closed(faces, len(vertices)):
        return ["not closed and consistently oriented (by indices)"]
    if len(np.unique(face_components(faces, len(vertices)))) != 1:
        return ["several bodies"]
    if signed_volume(vertices, faces) <= 0:
        return ["non-positive volume (inward orientation)"]
    return []


def require_solid(vertices: np.ndarray, faces: np.ndarray, parameter: str, *, star_centre=None) -> None:
    """Raise ``ValueError`` (:class:`~grainforge.params.ParameterError`) naming ``parameter``
    if the mesh, as written, is not a valid solid (see :func:`solid_problems`).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.
    parameter : str
        The parameter the error names (e.g. ``"amplitude"``; the CLI turns it into ``--amplitude``).
    star_centre : (3,) array_like of float, optional
        Passed to :func:`solid_problems`: try the star certificate about this point first.

    Raises
    ------
    grainforge.params.ParameterError
        (a ``ValueError``) naming ``parameter`` and listing the problems.
    """
    problems = solid_problems(vertices, faces, star_centre=star_centre)
    if problems:
        from ..params import ParameterError

        raise ParameterError(parameter, f"gives a mesh that is not a valid solid when written ({'; '.join(problems)})")


def _sortable_bits(q: np.ndarray) -> np.ndarray:
    """Unsigned integers in the numeric order of the float32 array ``q`` (−0.0 taken as 0.0)."""
    b = (q + np.float32(0.0)).view(np.uint32)
    return np.where(b >> np.uint32(31), ~b, b | np.uint32(0x80000000))


def unique_rows(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(points, axis=0, return_inverse=True)`` for (N, 3) points, several times faster.

    Rows are sorted by x, then y, then z (numeric order, as ``np.unique``
    sorts them) with ``np.lexsort`` instead of a sort of structured rows.
    Points that float32 holds exactly (mesh files) are sorted on integer keys,
    (x, y) packed in 64 bits, then z within the rare runs of equal (x, y):
    the same order, faster again.

    Examples
    --------
    >>> p = np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 0]])
    >>> u, inv = unique_rows(p)
    >>> u.tolist(), inv.tolist()
    ([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], [1, 0, 1])
    >>> u, inv = unique_rows(np.array([[0.5, -2.0, 0.0], [-1.0, 3.0, 1.0], [0.5, -2.0, -0.0]]))
    >>> u.tolist(), inv.tolist()
    ([[-1.0, 3.0, 1.0], [0.5, -2.0, 0.0]], [1, 0, 1])
    """
    p = np.asarray(points)
    if len(p) == 0:
        return p.copy(), np.zeros(0, dtype=np.int64)
    new = np.empty(len(p), dtype=bool)
    new[0] = True
    q = None
    if p.ndim == 2 and p.shape[1] == 3 and p.dtype in (np.float32, np.float64):
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.ascontiguousarray(p, dtype=np.float32)
        if p.dtype == np.float64 and not np.array_equal(q, p):  # (NaN never equals: the general path)
            q = None
    if q is not None:
        # one unstable argsort on (x, y) packed in 64 bits; the few runs of equal (x, y) holding
        # different z are then sorted by z in place, and each group keeps its smallest index
        k = _sortable_bits(q)
        xy = (k[:, 0].astype(np.uint64) << np.uint64(32)) | k[:, 1].astype(np.uint64)
        order = np.argsort(xy)
        xs, zs = xy[order], k[order, 2]
        same_xy = xs[1:] == xs[:-1]
        clash = same_xy & (zs[1:] != zs[:-1])
        if clash.any():
            run = np.cumsum(np.concatenate([[True], ~same_xy]))
            pos = np.flatnonzero(np.isin(run, run[1:][clash]))
            sub = np.lexsort((zs[pos], run[pos]))
            order[pos], zs[pos] = order[pos][sub], zs[pos][sub]
        np.logical_or(~same_xy, zs[1:] != zs[:-1], out=new[1:])
        first = np.minimum.reduceat(order, np.flatnonzero(new))
    else:
        order = np.lexsort(p.T[::-1])
        s = p[order]
        np.any(s[1:] != s[:-1], axis=1, out=new[1:])
        first = order[new]
    inverse = np.empty(len(p), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return p[first], inverse


def split_bodies(
    vertices: np.ndarray, faces: np.ndarray, drop_degenerate: bool = True
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Merge coincident vertices and split a triangle set into edge-connected bodies.

    With ``drop_degenerate`` triangles that collapse when coincident vertices
    merge are dropped (for measuring); without it every input face is kept
    (for round-tripping files face for face).

    Bodies are ordered by their first face in the input.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.
    drop_degenerate : bool, default True
        Drop the triangles that collapse when coincident vertices merge.

    Returns
    -------
    list of (vertices, faces)
        One ``((V_k, 3) float64, (F_k, 3) int64)`` pair per body, each indexing its own vertices; an
        empty list when no face is left.

    Examples
    --------
    >>> import trimesh
    >>> a = trimesh.creation.box()
    >>> b = trimesh.creation.box()
    >>> _ = b.apply_translation((3, 0, 0))
    >>> both = trimesh.util.concatenate([a, b])
    >>> [len(f) for _, f in split_bodies(both.vertices, both.faces)]
    [12, 12]
    """
    v, inv = unique_rows(np.asarray(vertices, dtype=np.float64))
    f = inv[np.asarray(faces, dtype=np.int64)]
    if drop_degenerate:
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]
    if len(f) == 0:
        return []
    face_label = face_components(f, len(v))
    _, first = np.unique(face_label, return_index=True)
    bodies = []
    if len(first) == 1 and np.bincount(f.ravel(), minlength=len(v)).all():  # one body using every vertex
        return [(v, f)]  # (what the loop below gives: used = 0…V−1, local = f)
    for lab in face_label[np.sort(first)]:
        ff = f[face_label == lab]
        used, local = np.unique(ff, return_inverse=True)
        bodies.append((v[used], local.reshape(-1, 3)))
    return bodies


#: how far from the origin a body's coordinates may lie, in multiples of its size (the largest side of its
#: bounding box).  float32, in which STL stores coordinates and :func:`solid_problems` checks every mesh,
#: spaces its values 2^-23·|x| apart near x (24 significant bits), so a coordinate is rounded by up to
#: 2^-24·|x| ≈ 6e-8·|x|.  At 1e4 sizes from the origin that is 6e-4 of the size, the grid 1.2e-3 of it:
#: finer than the facets of a grain of 10^5 faces (about d/200), and a sphere of 20,480 faces measures as at
#: the origin (sphericity within 1e-4).  At 1e5 sizes the same sphere's sphericity is 0.8 % low, at 3e5 it
#: is no longer a solid, and at 5e8 (a 2 mm grain at 1e9 mm) every vertex rounds onto a few points.
FLOAT32_OFFSET_LIMIT = 1e4


def precision_problem(vertices: np.ndarray, what: str = "the mesh") -> str | None:
    """Why float32 cannot hold the detail of ``vertices`` (``None`` if it can): coordinates more than
    :data:`FLOAT32_OFFSET_LIMIT` times the mesh's size from the origin, or no extent left at all.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions, any unit.
    what : str, default "the mesh"
        How the message names the mesh (e.g. a file name).

    Returns
    -------
    str or None
        One sentence saying how much float32 rounds the coordinates and what to do, or ``None`` (also for
        an empty or non-finite array, which the readers report themselves).

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(radius=1.0)
    >>> precision_problem(s.vertices) is None
    True
    >>> print(precision_problem(s.vertices + 1e9))
    coordinates reach 1e+09, 5e+08 times the mesh's size (2): float32 (STL's precision, and that of the solid check) rounds them by up to 60, so the shape is lost beyond 1e+04 times its size; translate the mesh near the origin
    """
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0 or not np.isfinite(v).all():
        return None  # (the readers say so in their own words)
    reach = float(np.abs(v).max())
    size = float(np.ptp(v, axis=0).max())
    if reach <= FLOAT32_OFFSET_LIMIT * size:
        return None
    step = reach * 2.0**-24
    if size == 0.0:
        return (f"every vertex of {what} lies on one point, at coordinates reaching {reach:.3g}: float32 (STL's "
                f"precision) rounds them by up to {step:.2g}, so the shape is lost; translate the mesh near the "
                "origin before writing it")
    return (f"coordinates reach {reach:.3g}, {reach / size:.2g} times {what}'s size ({size:.3g}): float32 (STL's "
            f"precision, and that of the solid check) rounds them by up to {step:.2g}, so the shape is lost beyond "
            f"{FLOAT32_OFFSET_LIMIT:.0e} times its size; translate the mesh near the origin")


def mesh_size_problem(vertices: np.ndarray, what: str = "the mesh") -> str | None:
    """Why ``vertices`` (in mm) are no grain's size (``None`` if they are): the largest side of their
    bounding box outside :data:`grainforge.units.MESH_SIZE_RANGE_MM` (0.1 µm to 100 m).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions in mm.
    what : str, default "the mesh"
        How the message names the mesh.

    Returns
    -------
    str or None
        One sentence giving the size and the accepted range, or ``None`` (also for an empty or
        non-finite array).

    Examples
    --------
    >>> print(mesh_size_problem(np.array([[0.0, 0, 0], [2e37, 1, 1]])))
    the mesh is 2e+37 mm across (its bounding box's largest side), outside the 0.0001–100000 mm a grain file is read at (files are in mm); rescale the mesh to millimetres
    """
    from ..units import MESH_SIZE_RANGE_MM

    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0 or not np.isfinite(v).all():
        return None
    size = float(np.ptp(v, axis=0).max())
    lo, hi = MESH_SIZE_RANGE_MM
    if lo <= size <= hi:
        return None
    return (f"{what} is {size:.3g} mm across (its bounding box's largest side), outside the {lo:g}–{hi:g} mm a grain "
            "file is read at (files are in mm); rescale the mesh to millimetres")


def winding_numbers(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Winding number of a closed, oriented mesh about each of ``points`` (1 inside an outward
    surface, −1 inside an inward one, 0 outside), from the faces' solid angles (Van Oosterom &
    Strackee, 1983).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles indexing ``vertices``, counter-clockwise seen from outside.
    points : (n, 3) array_like of float
        Query points.

    Returns
    -------
    (n,) float64
        The winding number about each point (an integer up to rounding for a closed mesh).

    Examples
    --------
    >>> import trimesh
    >>> b = trimesh.creation.box()
    >>> np.round(winding_numbers(b.vertices, b.faces, [[0, 0, 0], [2, 0, 0]]), 6).tolist()
    [1.0, 0.0]
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    out = np.empty(len(points))
    for k, p in enumerate(np.asarray(points, dtype=np.float64).reshape(-1, 3)):
        a, b, c = (v[f[:, i]] - p for i in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, cross3(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
            + np.einsum("ij,ij->i", b, c) * la
        out[k] = 2.0 * np.arctan2(det, den).sum() / (4.0 * np.pi)
    return out


#: vertices of a body tested against another body's winding number (spread over the body)
NESTING_SAMPLE = 64


def body_nesting(bodies: list[tuple[np.ndarray, np.ndarray]]) -> tuple[list[int | None], set[int]]:
    """Which bodies lie inside another and which overlap another.

    A body whose sampled vertices (up to :data:`NESTING_SAMPLE`, spread over
    it) all lie inside a closed body (winding number away from 0) is an
    **inner shell** of it: the wall of a cavity (facing inward: negative
    volume) or a shell nested in the grain; either way not a grain of its
    own.  Bodies that are partly inside another **overlap** it.

    Parameters
    ----------
    bodies : list of (vertices, faces)
        Bodies as :func:`split_bodies` returns them: ``(V_k, 3)`` float and ``(F_k, 3)`` int arrays.

    Returns
    -------
    enclosing : list
        For each body, the index of the outermost body that encloses it, or ``None``.
    overlapping : set of int
        Bodies that are partly inside another body (and that other body).

    Examples
    --------
    >>> import trimesh
    >>> outer = trimesh.creation.icosphere(radius=1.0)
    >>> inner = trimesh.creation.icosphere(radius=0.5)
    >>> _ = inner.invert()
    >>> body_nesting([(outer.vertices, outer.faces), (inner.vertices, inner.faces)])
    ([None, 0], set())
    """
    n = len(bodies)
    enclosing: list[int | None] = [None] * n
    overlapping: set[int] = set()
    if n < 2:
        return enclosing, overlapping
    lo = np.array([np.asarray(v).min(axis=0) for v, _ in bodies])
    hi = np.array([np.asarray(v).max(axis=0) for v, _ in bodies])
    inside: list[list[int]] = [[] for _ in range(n)]
    for j, (vj, fj) in enumerate(bodies):
        if not is_closed(fj, len(vj)):
            continue  # an open body has no inside
        near = np.flatnonzero((lo <= hi[j]).all(axis=1) & (hi >= lo[j]).all(axis=1))
        for i in near[near != j]:
            vi = np.asarray(bodies[i][0])
            sample = vi[np.unique(np.linspace(0, len(vi) - 1, min(len(vi), NESTING_SAMPLE)).astype(np.int64))]
            within = np.abs(winding_numbers(vj, fj, sample)) > 0.5
            if within.all():
                inside[i].append(j)
            elif within.any():
                overlapping.update((int(i), j))
    for i in range(n):
        outer = [j for j in inside[i] if not inside[j]]
        if outer:
            enclosing[i] = outer[0]
        elif inside[i]:  # (containers all inside one another in a loop: not nested shells)
            overlapping.add(i)
    return enclosing, overlapping
