"""Directed Polyhedra Aggregation (DPA): porous, branching aggregates of convex primaries.

Implements §2.3 of Hanaor et al., *3D printable geomaterials* (Eqs. 4–5;
ALGORITHMS.md §3; ``docs/methods/dpa.md``).  Primaries of unit volume are
added one at a time; the n-th attaches to a face of the parent
i = ⌈(n−1)·u^(1/ε)⌉, u ~ U(0, 1] (Eq. 4).  Low ε favours old primaries
(compact aggregates), high ε recent ones (branching aggregates).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..params import ParameterError, param, validate
from ._polyhedra import (
    PRIMITIVES, Solid, edge_directions, face_frame, face_normals, rotation_matrix, sat_intrudes, solid,
)

__all__ = [
    "Params", "Aggregate", "build", "aggregate", "parent_index", "lattice_surface",
    "union_surface", "separate_pinches", "smooth_surface", "PRIMITIVES", "physical_info",
]

NAME = "dpa"
VALIDITY_PARAMETER = "smooth"
#: generation outputs recorded in manifests (see :func:`build`)
INFO_COLUMNS = ("D_A", "D_A_scaling", "porosity", "R_g", "cavity_volume", "primary_size")
DEFAULT_EXPONENT = 1.0
#: draws of Eq. 4 tried before sampling the same distribution restricted to non-full parents directly.
MAX_REDRAWS = 16
#: overlap depth (in primary sizes) below which two primaries only touch.
INTRUSION_TOLERANCE = 1e-9
#: relative growths of each primary tried before the union, so that touching faces overlap and
#: fuse (changes the union volume by at most 3 × growth, relative).
UNION_INFLATION = (1e-9, 3e-9, 1e-8, 3e-10, 3e-8)
#: how far (in primary sizes) the two sides of an edge- or vertex-only cube contact are moved apart
PINCH_GAP = 1e-3
_DIRS = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


@dataclass(frozen=True)
class Params:
    """Parameters of the DPA generator (paper §2.3, Eq. 4)."""

    primitive: str = param("cube", "primary particle shape", kind="str", choices=PRIMITIVES)
    exponent: float | None = param(
        None, "parent-choice exponent ε of Eq. 4 (low: compact, high: branching)",
        low=0.01, high=100.0, shown_default=f"{DEFAULT_EXPONENT:g}",
    )
    primaries: int = param(200, "number of primary particles N", kind="int", low=1, high=100_000)
    smooth: int = param(
        0, "corner smoothing: 0 keeps sharp corners, K ≥ 1 rounds them by K Loop subdivision steps (4^K triangles)",
        kind="int", low=0, high=4,
    )
    target_fractal_dimension: float | None = param(
        None, "the D_A the exponent was calibrated for (recorded, set by --target-fractal-dimension)",
        low=1.0, high=3.0, cli=False,
    )

    def __post_init__(self):
        validate(self)
        if self.exponent is None:
            if self.target_fractal_dimension is not None:
                raise ParameterError(
                    "exponent", "is required with target_fractal_dimension (use grainforge.dpa(...) or the CLI, "
                    "which pick it from the calibration)",
                )
            object.__setattr__(self, "exponent", DEFAULT_EXPONENT)


# --------------------------------------------------------------------------- parent choice (Eq. 4)

def parent_weights(existing: int, exponent: float) -> np.ndarray:
    """P(i) for i = 1..n−1 under Eq. 4: ((i/(n−1))^ε − ((i−1)/(n−1))^ε).

    Examples
    --------
    >>> parent_weights(4, 1.0).tolist()
    [0.25, 0.25, 0.25, 0.25]
    >>> round(float(parent_weights(10, 3.0).sum()), 12)
    1.0
    """
    i = np.arange(1, existing + 1, dtype=np.float64)
    hi = (i / existing) ** exponent
    with np.errstate(divide="ignore"):
        lo = np.where(i > 1, ((i - 1) / existing) ** exponent, 0.0)
    return hi - lo


def parent_index(existing: int, exponent: float, rng: np.random.Generator, open_: np.ndarray) -> int:
    """0-based index of the parent of the next primary (Eq. 4 with re-draws).

    i = ⌈(n−1)·u^(1/ε)⌉ with u ~ U(0, 1]; a parent with no free face is
    drawn again.  The draws are made :data:`MAX_REDRAWS` at a time (the
    first acceptable one is used); if none is acceptable the same
    distribution, restricted to parents with a free face, is sampled
    directly (identical in law to re-drawing until success, but bounded).

    Parameters
    ----------
    existing : int
        n − 1, the number of primaries already placed.
    exponent : float
        ε > 0.
    rng : numpy.random.Generator
    open_ : (≥ existing,) bool
        Whether each primary still has a free face.

    Raises
    ------
    ValueError
        If no primary has a free face (cannot happen for a finite aggregate).
    """
    u = 1.0 - rng.random(MAX_REDRAWS)
    i = np.clip(np.ceil(existing * u ** (1.0 / exponent)).astype(np.int64), 1, existing) - 1
    ok = np.flatnonzero(open_[i])
    if len(ok):
        return int(i[ok[0]])
    w = parent_weights(existing, exponent) * open_[:existing]
    total = w.sum()
    if not total > 0:
        raise ValueError("primaries: no primary has a free face left")
    c = np.cumsum(w)
    return int(min(np.searchsorted(c, rng.random() * c[-1], side="right"), existing - 1))


# --------------------------------------------------------------------------- aggregation

@dataclass(frozen=True)
class Aggregate:
    """The primaries of one aggregate, in units of the primary size (unit volume each).

    Attributes
    ----------
    solid : Solid
        The primary shape.
    vertices : (N, V, 3) float64
        Every primary's vertices.
    centres : (N, 3) float64
    cells : (N, 3) int64 or None
        Lattice cells (cubes only): cube n occupies [c, c + 1]^3.
    """

    solid: Solid
    vertices: np.ndarray
    centres: np.ndarray
    cells: np.ndarray | None = None

    @property
    def primaries(self) -> int:
        return len(self.centres)

    def measures(self) -> dict[str, float]:
        """D_A (Eq. 5), D_A_scaling, porosity, R_g (units of a) and box mean edge of the aggregate."""
        from ..analysis.aggregate import aggregate_measures

        pts = self.vertices.reshape(-1, 3)
        owner = np.repeat(np.arange(self.primaries), self.vertices.shape[1])
        if self.cells is not None:  # only the distinct lattice corners matter (first owner kept)
            _, first = np.unique(pts, axis=0, return_index=True)
            first = np.sort(first)
            pts, owner = pts[first], owner[first]
        return aggregate_measures(pts, self.centres, float(self.primaries), self.solid.gyration2, owner)


def _aggregate_cubes(n_total: int, exponent: float, rng: np.random.Generator) -> np.ndarray:
    cells = [(0, 0, 0)]
    index = {(0, 0, 0): 0}
    free = np.zeros(n_total, dtype=np.int64)
    free[0] = 6
    open_ = np.zeros(n_total, dtype=bool)
    open_[0] = True
    for n in range(1, n_total):
        p = parent_index(n, exponent, rng, open_)
        x, y, z = cells[p]
        empty = [(x + dx, y + dy, z + dz) for dx, dy, dz in _DIRS if (x + dx, y + dy, z + dz) not in index]
        c = empty[int(rng.integers(len(empty)))]
        index[c] = n
        cells.append(c)
        k = 0
        for dx, dy, dz in _DIRS:
            j = index.get((c[0] + dx, c[1] + dy, c[2] + dz))
            if j is None:
                k += 1
            else:
                free[j] -= 1
                if free[j] == 0:
                    open_[j] = False
        free[n] = k
        open_[n] = k > 0
    return np.array(cells, dtype=np.int64).reshape(-1, 3)


@lru_cache(maxsize=None)
def _templates(name: str):
    """For each face f and distinct orientation j: the map x -> A x + b that turns the
    reference solid into its child on face f (mirror through f, then turn by 2πj/k about
    the face normal), and ``perm`` with child[face_f] == parent[perm] exactly."""
    s = solid(name)
    v0 = s.vertices
    out = []
    for f, js in zip(s.faces, s.orientations):
        c, n = face_frame(v0, f, np.zeros(3))
        Mf = np.eye(3) - 2.0 * np.outer(n, n)
        per_face = []
        for j in js:
            R = rotation_matrix(n, 2.0 * np.pi * int(j) / len(f))
            A = R @ Mf
            b = R @ (2.0 * np.dot(c, n) * n - c) + c
            kid = v0 @ A.T + b
            d = ((kid[f][:, None, :] - v0[f][None, :, :]) ** 2).sum(-1)
            per_face.append((int(j), A, b, f[np.argmin(d, axis=1)]))
        out.append(per_face)
    return out


def _aggregate_polyhedra(s: Solid, n_total: int, exponent: float, rng: np.random.Generator, tol: float):
    tpl = _templates(s.name)
    F, K = len(s.faces), s.max_orientations
    base = np.zeros((F, K), dtype=bool)
    slot_A = np.zeros((F, K, 3, 3))
    slot_b = np.zeros((F, K, 3))
    for f, per_face in enumerate(tpl):
        for q, (_, A, b, _) in enumerate(per_face):
            base[f, q] = True  # slot q holds the q-th distinct orientation of face f
            slot_A[f, q], slot_b[f, q] = A, b
    v0 = s.vertices
    n0 = face_normals(s, v0)
    e0 = edge_directions(s, v0)
    verts = np.empty((n_total, len(v0), 3))
    normals = np.empty((n_total, F, 3))
    edges = np.empty((n_total, len(e0), 3))
    rot = np.empty((n_total, 3, 3))
    shift = np.zeros((n_total, 3))
    verts[0], normals[0], edges[0], rot[0] = v0, n0, e0, np.eye(3)
    avail = np.zeros((n_total, F, K), dtype=bool)
    avail[0] = base
    open_ = np.zeros(n_total, dtype=bool)
    open_[0] = True
    R, r_in = s.circumradius, s.inradius
    r_face = max(float(np.dot(v0[f[0]], face_frame(v0, f, np.zeros(3))[1])) for f in s.faces)
    h = 2.0 * R
    reach2 = (2.0 * R + 2.0 * r_face) ** 2  # a child's centre lies twice its face distance from the parent's
    grid: dict[tuple[int, int, int], list[int]] = {(0, 0, 0): [0]}
    cell = float(np.sqrt(reach2))  # hash-grid cell: every primary within reach is in the 27 cells around
    offsets = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    face_idx = s.faces
    for n in range(1, n_total):
        placed = None
        while placed is None:
            p = parent_index(n, exponent, rng, open_)
            # test every open slot of the parent at once against the primaries nearby
            ff, qq = np.nonzero(avail[p])
            Rp = rot[p]
            Rc = Rp @ slot_A[ff, qq]                       # (C, 3, 3)
            tc = slot_b[ff, qq] @ Rp.T + shift[p]          # (C, 3)
            kids = v0 @ Rc.transpose(0, 2, 1) + tc[:, None, :]
            key = np.floor(shift[p] / cell).astype(np.int64)
            near = np.array([i for o in offsets
                             for i in grid.get((key[0] + o[0], key[1] + o[1], key[2] + o[2]), ())], dtype=np.int64)
            near = near[((shift[near] - shift[p]) ** 2).sum(axis=1) < reach2]
            d2 = ((tc[:, None, :] - shift[near][None, :, :]) ** 2).sum(-1)  # (C, M)
            ci, mj = np.nonzero(d2 < h * h)
            deep = d2[ci, mj] < (2.0 * r_in) ** 2 - tol  # inspheres overlap: intrusion for sure
            bad = np.zeros(len(ff), dtype=bool)
            bad[ci[deep]] = True
            ci, mj = ci[~deep], mj[~deep]
            test = ~bad[ci]
            ci, mj = ci[test], near[mj[test]]
            if len(ci):
                hit = sat_intrudes(kids[ci], n0 @ Rc[ci].transpose(0, 2, 1), e0 @ Rc[ci].transpose(0, 2, 1),
                                   verts[mj], normals[mj], edges[mj], tol)
                bad[ci[hit]] = True
            ok = np.zeros((F, K), dtype=bool)
            ok[ff, qq] = ~bad
            slot_of = np.full((F, K), -1, dtype=np.int64)
            slot_of[ff, qq] = np.arange(len(ff))
            # the paper's choice: an open face uniformly, then an orientation; intruding ones are dropped
            while avail[p].any():
                faces_open = np.flatnonzero(avail[p].any(axis=1))
                f = int(faces_open[rng.integers(len(faces_open))])
                slots = np.flatnonzero(avail[p, f])
                q = int(slots[rng.integers(len(slots))])
                if ok[f, q]:
                    avail[p, f] = False
                    c = slot_of[f, q]
                    kid = kids[c]
                    kid[face_idx[f]] = verts[p][tpl[f][q][3]]  # contact face: the parent's exact coordinates
                    placed = (kid, Rc[c], tc[c], f)
                    break
                avail[p, f, q] = False
            if not avail[p].any():
                open_[p] = False
        kid, Rn, tn, f = placed
        verts[n], rot[n], shift[n] = kid, Rn, tn
        normals[n], edges[n] = n0 @ Rn.T, e0 @ Rn.T
        avail[n] = base
        avail[n, f] = False
        open_[n] = avail[n].any()
        grid.setdefault(tuple(int(x) for x in np.floor(tn / cell)), []).append(n)
    return verts, shift


def aggregate(primitive: str, primaries: int, exponent: float, rng: np.random.Generator,
              tol: float = INTRUSION_TOLERANCE) -> Aggregate:
    """Grow an aggregate of ``primaries`` unit-volume primaries (no mesh).

    Cubes grow on the integer lattice (a face is occupied when the
    neighbouring cell is).  Other primaries attach by reflection through the
    chosen face of the parent, turned about the face normal into one of the
    face's distinct orientations; a placement that intrudes into an existing
    primary (exact separating-axis test, overlap > ``tol``) is rejected and
    another face/orientation of the same parent is tried.

    Examples
    --------
    >>> agg = aggregate("octahedron", 50, 2.0, np.random.default_rng(0))
    >>> agg.vertices.shape
    (50, 6, 3)
    """
    s = solid(primitive)
    if primitive == "cube":
        cells = _aggregate_cubes(primaries, exponent, rng)
        verts = cells[:, None, :] + (s.vertices[None] + 0.5)
        return Aggregate(s, verts, cells + 0.5, cells)
    verts, centres = _aggregate_polyhedra(s, primaries, exponent, rng, tol)
    return Aggregate(s, verts, centres)


# --------------------------------------------------------------------------- union as one solid

def lattice_surface(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Exact outer boundary of a union of unit lattice cubes, as a 2-manifold.

    Faces between filled and empty cells become two triangles each.  Sealed
    cavities (empty cells not face-connected to the outside; a pocket open
    only through an edge or a corner gap counts as sealed) are filled.  Where
    two cubes meet only along an edge or at a vertex the surface is pinched:
    the vertex is duplicated, one copy per fan of faces around it, and the
    edge gets one midpoint per cube, so the mesh stays an oriented
    2-manifold (cubes are joined through faces only).

    Parameters
    ----------
    cells : (N, 3) int
        Occupied cells; cell c is the cube [c, c + 1]^3.

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        Outward oriented.
    cavity : int
        Number of sealed empty cells that were filled.

    Examples
    --------
    >>> v, f, cav = lattice_surface(np.array([[0, 0, 0], [1, 0, 0]]))
    >>> len(v), len(f), cav
    (12, 20, 0)
    """
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    cells = np.asarray(cells, dtype=np.int64)
    lo = cells.min(axis=0) - 1
    c = cells - lo
    shape = tuple(c.max(axis=0) + 2)
    occ = np.zeros(shape, dtype=bool)
    occ[c[:, 0], c[:, 1], c[:, 2]] = True
    labels, _ = ndimage.label(~occ)  # 6-connected: a pocket open only through an edge or corner is sealed
    cavity = (~occ) & (labels != labels[0, 0, 0])
    filled = occ | cavity
    quads, owners = [], []
    pshape = np.array(shape) + 1
    for a in range(3):
        b, cc = (a + 1) % 3, (a + 2) % 3
        ea, eb, ec = np.eye(3, dtype=np.int64)[[a, b, cc]]
        for sign in (1, -1):
            nb = np.roll(filled, -sign, axis=a)  # neighbour in direction sign·e_a (padding keeps roll safe)
            idx = np.argwhere(filled & ~nb)
            if sign == 1:
                corners = np.stack([idx + ea, idx + ea + eb, idx + ea + eb + ec, idx + ea + ec], axis=1)
            else:
                corners = np.stack([idx, idx + ec, idx + eb + ec, idx + eb], axis=1)
            quads.append(corners)
            owners.append(np.ravel_multi_index(idx.T, shape))
    corners = np.concatenate(quads)  # (Q, 4, 3) lattice points
    owner = np.concatenate(owners)
    Q = len(corners)
    pid = np.ravel_multi_index(corners.reshape(-1, 3).T, tuple(pshape)).reshape(Q, 4)
    start = pid.reshape(-1)
    end = np.roll(pid, -1, axis=1).reshape(-1)
    P = int(np.prod(pshape))
    ukey = np.minimum(start, end) * P + np.maximum(start, end)
    _, inv, counts = np.unique(ukey, return_inverse=True, return_counts=True)
    pinched = counts[inv] == 4
    second = np.where(pinched, np.repeat(owner, 4), -1)
    order = np.lexsort((start > end, second, ukey))
    e1, e2 = order[0::2], order[1::2]  # paired half-edges (edge id = 4q + k)
    q1, k1 = np.divmod(e1, 4)
    q2, k2 = np.divmod(e2, 4)
    node_a = np.concatenate([4 * q1 + k1, 4 * q1 + (k1 + 1) % 4])
    node_b = np.concatenate([4 * q2 + (k2 + 1) % 4, 4 * q2 + k2])
    g = coo_matrix((np.ones(len(node_a)), (node_a, node_b)), shape=(4 * Q, 4 * Q))
    _, vid = connected_components(g, directed=False)
    nv = int(vid.max()) + 1
    vertices = np.zeros((nv, 3))
    vertices[vid] = corners.reshape(-1, 3) + lo
    vq = vid.reshape(Q, 4)
    plain = np.ones(Q, dtype=bool)
    extra_v, extra_f = [], []
    pin = pinched[e1]
    if pin.any():
        # an edge shared by two cubes only: even with split vertex fans its two copies may join the
        # same two vertices, so each copy gets its own midpoint vertex (one per cube)
        mid_of = np.full(4 * Q, -1, dtype=np.int64)
        ids = nv + np.arange(int(pin.sum()))
        mid_of[e1[pin]] = ids
        mid_of[e2[pin]] = ids
        a = corners.reshape(-1, 3)[e1[pin]]
        b = corners.reshape(-1, 3)[4 * (e1[pin] // 4) + (e1[pin] % 4 + 1) % 4]
        extra_v.append((a + b) / 2.0 + lo)
        hit = np.unique(np.concatenate([e1[pin], e2[pin]]) // 4)
        plain[hit] = False
        nxt = nv + len(ids)
        centres = corners[hit].mean(axis=1) + lo
        extra_v.append(centres)
        for i, q in enumerate(hit.tolist()):
            poly = []
            for k in range(4):
                poly.append(int(vq[q, k]))
                if mid_of[4 * q + k] >= 0:
                    poly.append(int(mid_of[4 * q + k]))
            ctr = nxt + i
            extra_f.extend((ctr, poly[j], poly[(j + 1) % len(poly)]) for j in range(len(poly)))
    vq = vq[plain]
    faces = np.concatenate([vq[:, [0, 1, 2]], vq[:, [0, 2, 3]]] + ([np.array(extra_f)] if extra_f else []))
    vertices = np.concatenate([vertices] + extra_v)
    return vertices.astype(np.float64), faces.astype(np.int64), int(cavity.sum())


def separate_pinches(vertices: np.ndarray, faces: np.ndarray, gap: float = PINCH_GAP) -> np.ndarray:
    """Move apart the copies of a pinched vertex so that the surface is a 2-manifold by position.

    :func:`lattice_surface` keeps edge- and vertex-only contacts manifold by
    *indices*: each cube's copy of a pinched edge or vertex has the same
    coordinates.  Every such copy is moved by ``gap`` (in primary sizes)
    towards the mean of its neighbours: into its own cube where cubes touch
    at an edge or a corner (a notch), into the empty corner where empty cells
    touch at a corner (a small fillet).  The two sides then stay ``gap`` apart
    instead of touching; the volume changes by about ``gap``/3 of the area of
    the faces around each moved vertex (≤ 2e-3 primary volumes per pinched
    edge at the default, measured in ``tests/test_dpa.py``).

    Returns
    -------
    (V, 3) float64
        The moved vertices (faces unchanged).
    """
    v = np.array(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    _, inv, cnt = np.unique(v, axis=0, return_inverse=True, return_counts=True)
    dup = np.flatnonzero(cnt[inv.reshape(-1)] > 1)
    if len(dup) == 0:
        return v
    a = f.ravel()
    b = np.roll(f, -1, axis=1).ravel()
    total = np.zeros_like(v)
    np.add.at(total, a, v[b])
    np.add.at(total, b, v[a])
    count = np.bincount(np.concatenate([a, b]), minlength=len(v)).astype(np.float64)
    d = total[dup] / count[dup, None] - v[dup]
    v[dup] += gap * d / np.linalg.norm(d, axis=1, keepdims=True)
    return v


def _manifold_mesh(m) -> tuple[np.ndarray, np.ndarray]:
    mesh = m.to_mesh64()
    return np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy(), np.asarray(mesh.tri_verts, dtype=np.int64)


def union_surface(agg: Aggregate) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The union of the primaries as one closed 2-manifold (manifold3d), cavities filled.

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    union_volume : float
        Volume of the union before filling sealed cavities (equals N when
        no primary intrudes into another).
    cavity : float
        Volume of the sealed cavities that were filled.
    """
    import manifold3d as m3

    from ..solid import face_components, signed_volume

    s = agg.solid
    tris = s.triangles.astype(np.uint32)
    flipped = np.ascontiguousarray(tris[:, ::-1])
    V = agg.vertices
    a, b, c = V[:, s.triangles[:, 0]], V[:, s.triangles[:, 1]], V[:, s.triangles[:, 2]]
    handed = (a * np.cross(b, c)).sum(axis=(1, 2)) > 0  # reflected primaries are left-handed
    # A touching contact must fuse: grow each primary about its centre by a tiny factor.  Boolean
    # robustness with such slivers is not guaranteed, so the result is checked (one solid whose
    # volume is N to within the growth) and the next factor is tried if the check fails.
    n = agg.primaries
    for grow in UNION_INFLATION:
        g = agg.centres[:, None, :] + (V - agg.centres[:, None, :]) * (1.0 + grow)
        parts = [m3.Manifold(m3.Mesh64(vert_properties=np.ascontiguousarray(v), tri_verts=tris if ok else flipped))
                 for v, ok in zip(g, handed)]
        u = m3.Manifold.batch_boolean(parts, m3.OpType.Add) if n > 1 else parts[0]
        volume = float(u.volume())
        v, f = _manifold_mesh(u)
        comp = face_components(f, len(v))
        keep = np.zeros(len(f), dtype=bool)
        cavity, bodies = 0.0, 0
        for k in np.unique(comp):
            sel = comp == k
            vol = signed_volume(v, f[sel])
            if vol > 0:
                keep |= sel
                bodies += 1
            else:
                cavity -= vol
        if abs(volume - n) <= 4.0 * grow * n + 1e-9 and bodies == 1:
            break
    else:
        raise ValueError("primaries: manifold3d could not fuse the primaries into one solid")
    f = f[keep]
    used, f = np.unique(f, return_inverse=True)
    return v[used], f.reshape(-1, 3).astype(np.int64), volume, cavity


def smooth_surface(vertices: np.ndarray, faces: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Round the corners by ``level`` steps of Loop subdivision (each splits a triangle into four).

    Loop subdivision works on the connectivity only, so a closed, oriented
    2-manifold stays one; flat regions stay flat, edges and corners are
    rounded over about one primary size and convex parts shrink slightly.
    """
    from trimesh.remesh import subdivide_loop

    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    v, f = subdivide_loop(v, f, iterations=int(level))
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


# --------------------------------------------------------------------------- the generator

def index_contract_only(p: Params) -> bool:
    """Whether this grain is checked by the old index-based contract only (non-cube primitives).

    The union of non-cube primaries (:func:`union_surface`) still leaves
    sliver edges and edge contacts that merge when written in float32; until
    it is rebuilt these grains are checked by
    :func:`grainforge.solid.index_problems` (``docs/validation.md``, "Known gaps").
    """
    return p.primitive != "cube"


def physical_info(info: dict, scale: float) -> dict:
    """``info`` of a grain scaled by ``scale`` (mm per model unit) with its lengths in mm.

    :func:`build` gives ``R_g`` in primary sizes, ``cavity_volume`` in primary
    volumes and ``primary_size`` in model units; a manifest records all three in
    mm / mm³ (``R_g_mm``, ``cavity_volume_mm3``, ``primary_size_mm``), like
    ``grainforge analyse`` (``radius_of_gyration_mm``).  R_g/a, the ratio of
    the paper's mass–radius relation, is ``R_g_mm / primary_size_mm``.

    Examples
    --------
    >>> physical_info({"R_g": 3.0, "cavity_volume": 2.0, "primary_size": 0.5, "D_A": 2.1}, 4.0)
    {'R_g': 6.0, 'cavity_volume': 16.0, 'primary_size': 2.0, 'D_A': 2.1}
    """
    a = float(info["primary_size"]) * float(scale)
    return {**info, "R_g": float(info["R_g"]) * a, "cavity_volume": float(info["cavity_volume"]) * a**3,
            "primary_size": a}


def build(p: Params, rng: np.random.Generator):
    """Vertices, faces and info of one DPA grain (scaled to equivalent radius 1, not centred).

    Info: ``D_A`` (Eq. 5), ``D_A_scaling`` (the slope of log V against log A
    over the aggregate's growth), ``porosity`` (1 − V/V_hull) and ``R_g`` (radius
    of gyration in primary sizes) of the aggregate of primaries;
    ``cavity_volume`` (sealed cavities filled in the mesh, in primary
    volumes); ``primary_size`` (the primary's V_p^(1/3) in grain units).
    """
    agg = aggregate(p.primitive, p.primaries, p.exponent, rng)
    if agg.cells is not None:
        v, f, cavity = lattice_surface(agg.cells)
        if not p.smooth:  # smoothing separates the pinches by itself (each copy follows its own cube)
            v = separate_pinches(v, f)
    else:
        v, f, _, cavity = union_surface(agg)
    if p.smooth:
        v, f = smooth_surface(v, f, p.smooth)
    scale = float((4.0 * np.pi / (3.0 * p.primaries)) ** (1.0 / 3.0))
    m = agg.measures()
    info = {
        "D_A": m["D_A"], "D_A_scaling": m["D_A_scaling"], "porosity": m["porosity"], "R_g": m["R_g"],
        "cavity_volume": float(cavity), "primary_size": scale,
    }
    return v * scale, f, info
