"""Directed Polyhedra Aggregation (DPA): porous, branching aggregates of convex primaries.

Implements §2.3 of Hanaor et al., *3D printable geomaterials* (Eqs. 4–5;
docs/design/algorithms.md §3; ``docs/methods/dpa.md``).  Primaries of unit volume are
added one at a time; the n-th attaches to a face of the parent
i = ⌈(n−1)·u^(1/ε)⌉, u ~ U(0, 1] (Eq. 4).  Low ε favours old primaries
(compact aggregates), high ε recent ones (branching aggregates).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from ...errors import InputError
from ...params import ParameterError, param, validate
from ...rng import RNGLike, as_generator
from .._polyhedra import (
    PRIMITIVES,
    Solid,
    edge_directions,
    face_frame,
    face_normals,
    rotation_matrix,
    sat_gap,
    solid,
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
#: non-cube growth: a child may come closer than this (in primary sizes, measured as a separating-axis
#: gap) to a primary other than its parent only where the two share vertices of the child's contact
#: face exactly (docs/methods/dpa.md, "Contacts").
CONTACT_CLEARANCE = 1e-3
#: non-cube growth: the smallest empty angle left around an edge shared by several primaries (radians);
#: narrower notches fold over when smoothed (docs/methods/dpa.md, "Contacts").
MIN_NOTCH = np.radians(30.0)
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


def parent_index(existing: int, exponent: float, rng: RNGLike, open_: np.ndarray) -> int:
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
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by
        :data:`MAX_REDRAWS` uniform draws (and one more when none of them is acceptable).
    open_ : (≥ existing,) bool
        Whether each primary still has a free face.

    Returns
    -------
    int
        The parent's index, in ``0 … existing − 1``.

    Raises
    ------
    ValueError
        If no primary has a free face (cannot happen for a finite aggregate).
    """
    rng = as_generator(rng)
    u = 1.0 - rng.random(MAX_REDRAWS)
    i = np.clip(np.ceil(existing * u ** (1.0 / exponent)).astype(np.int64), 1, existing) - 1
    ok = np.flatnonzero(open_[i])
    if len(ok):
        return int(i[ok[0]])
    w = parent_weights(existing, exponent) * open_[:existing]
    total = w.sum()
    if not total > 0:
        raise InputError("primaries: no primary has a free face left")
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
    #: chosen (face, orientation) slots of non-cube growth: accepted, rejected as intruding, rejected as
    #: too close to a primary other than the parent without an exact contact (:func:`aggregate`)
    tried: tuple[int, int, int] = (0, 0, 0)

    @property
    def primaries(self) -> int:
        return len(self.centres)

    def measures(self) -> dict[str, float]:
        """D_A (Eq. 5), D_A_scaling, porosity, R_g (units of a) and box mean edge of the aggregate.

        Returns
        -------
        dict of str to float
            ``D_A``, ``D_A_scaling``, ``porosity``, ``R_g`` (primary sizes) and the others of
            :func:`grainforge.analysis.aggregate.aggregate_measures`.
        """
        from ...analysis.aggregate import aggregate_measures

        pts = self.vertices.reshape(-1, 3)
        owner = np.repeat(np.arange(self.primaries), self.vertices.shape[1])
        if self.cells is not None:  # only the distinct lattice corners matter (first owner kept)
            _, first = np.unique(pts, axis=0, return_index=True)
            first = np.sort(first)
            pts, owner = pts[first], owner[first]
        return aggregate_measures(pts, self.centres, volume=float(self.primaries),
                                  primary_gyration2=self.solid.gyration2, owner=owner)


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


@cache
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


def _exact_contacts(c, c_normals, c_offsets, q, q_normals, q_offsets, on_face, clearance: float) -> np.ndarray:
    """Whether each near pair (candidate c, existing q) touches only at exactly shared vertices of the
    candidate's contact face (see :func:`aggregate`).

    ``c``/``q`` (P, V, 3) vertices, outward face normals (P, F, 3) and plane offsets (P, F);
    ``on_face`` (P, V) marks the candidate's contact-face vertices.  A vertex is near the other solid
    when its largest signed face-plane distance (a lower bound on its distance) is below ``clearance``.
    """
    near_c = (np.einsum("pvk,pfk->pvf", c, q_normals) - q_offsets[:, None, :]).max(axis=2) < clearance
    near_q = (np.einsum("pvk,pfk->pvf", q, c_normals) - c_offsets[:, None, :]).max(axis=2) < clearance
    same = (c[:, :, None, :] == q[:, None, :, :]).all(axis=3)  # bit-exact coincidence
    return (near_c.any(axis=1) & (~near_c | (same.any(axis=2) & on_face)).all(axis=1)
            & (~near_q | same.any(axis=1)).all(axis=1))


def _dihedrals(s: Solid) -> np.ndarray:
    """Interior dihedral angle of the solid at each edge of each face: list (per face) of (k,) arrays,
    entry i for the edge from vertex i to vertex i + 1 of the face."""
    first = np.array([fc[0] for fc in s.faces])
    n0 = face_normals(s, s.vertices)
    n0 = n0 * np.sign((n0 * s.vertices[first]).sum(axis=1))[:, None]
    owner = {}
    for k, fc in enumerate(s.faces):
        for i in range(len(fc)):
            owner.setdefault(frozenset((int(fc[i]), int(fc[(i + 1) % len(fc)]))), []).append(k)
    out = []
    for fc in s.faces:
        ang = []
        for i in range(len(fc)):
            a, b = owner[frozenset((int(fc[i]), int(fc[(i + 1) % len(fc)])))]
            ang.append(np.pi - np.arccos(np.clip(np.dot(n0[a], n0[b]), -1.0, 1.0)))
        out.append(np.array(ang))
    return out


def _edge_key(p: np.ndarray, q: np.ndarray) -> tuple:
    a, b = p.tobytes(), q.tobytes()
    return (a, b) if a < b else (b, a)


def _add_edges_around(around: dict, kid: np.ndarray, face_idx, dihedral) -> None:
    """Count a placed primary's dihedral angles into ``around`` (exact edge -> angle taken around it); each
    edge is seen from its two faces, so each counts half its angle."""
    for fc, ang in zip(face_idx, dihedral):
        for i in range(len(fc)):
            key = _edge_key(kid[fc[i]], kid[fc[(i + 1) % len(fc)]])
            around[key] = around.get(key, 0.0) + 0.5 * ang[i]


@dataclass
class _Growth:
    """The state of a polyhedral aggregate as it grows (:func:`_aggregate_polyhedra`), and the primary's
    constants the slot tests use."""

    s: Solid
    tol: float
    clearance: float
    min_notch: float
    tpl: list
    slot_A: np.ndarray
    slot_b: np.ndarray
    base: np.ndarray
    v0: np.ndarray
    n0: np.ndarray
    h0: np.ndarray
    e0: np.ndarray
    on_face: np.ndarray
    dihedral: list
    verts: np.ndarray
    normals: np.ndarray
    edges: np.ndarray
    rot: np.ndarray
    shift: np.ndarray
    avail: np.ndarray
    open_: np.ndarray
    h: float
    reach2: float
    cell: float
    grid: dict
    around: dict

    @classmethod
    def start(cls, s: Solid, n_total: int, tol: float, clearance: float, min_notch: float) -> _Growth:
        tpl = _templates(s.name)
        F, K = len(s.faces), s.max_orientations
        base = np.zeros((F, K), dtype=bool)
        slot_A, slot_b = np.zeros((F, K, 3, 3)), np.zeros((F, K, 3))
        for f, per_face in enumerate(tpl):
            for q, (_, A, b, _) in enumerate(per_face):
                base[f, q] = True  # slot q holds the q-th distinct orientation of face f
                slot_A[f, q], slot_b[f, q] = A, b
        v0 = s.vertices
        n0 = face_normals(s, v0)
        first = np.array([fc[0] for fc in s.faces])
        n0 = n0 * np.sign((n0 * v0[first]).sum(axis=1))[:, None]  # outward (the solid is centred on the origin)
        h0 = (n0 * v0[first]).sum(axis=1)  # face-plane distances from the centre
        e0 = edge_directions(s, v0)
        on_face = np.zeros((F, len(v0)), dtype=bool)
        for f, fc in enumerate(s.faces):
            on_face[f, fc] = True
        g = cls(s=s, tol=tol, clearance=clearance, min_notch=min_notch, tpl=tpl, slot_A=slot_A, slot_b=slot_b,
                base=base, v0=v0, n0=n0, h0=h0, e0=e0, on_face=on_face, dihedral=_dihedrals(s),
                verts=np.empty((n_total, len(v0), 3)), normals=np.empty((n_total, F, 3)),
                edges=np.empty((n_total, len(e0), 3)), rot=np.empty((n_total, 3, 3)), shift=np.zeros((n_total, 3)),
                avail=np.zeros((n_total, F, K), dtype=bool), open_=np.zeros(n_total, dtype=bool),
                h=2.0 * s.circumradius + max(clearance, 0.0),
                # a child's centre lies twice its face distance away
                reach2=(2.0 * s.circumradius + 2.0 * float(h0.max()) + max(clearance, 0.0)) ** 2,
                cell=0.0, grid={(0, 0, 0): [0]}, around={})
        g.cell = float(np.sqrt(g.reach2))  # hash-grid cell: every primary within reach is in the 27 cells around
        g.verts[0], g.normals[0], g.edges[0], g.rot[0] = v0, n0, e0, np.eye(3)
        g.avail[0], g.open_[0] = base, True
        _add_edges_around(g.around, v0, s.faces, g.dihedral)
        return g

    def near(self, p: int) -> np.ndarray:
        """The primaries within reach of a child of primary ``p`` (the hash grid's 27 cells around it)."""
        key = np.floor(self.shift[p] / self.cell).astype(np.int64)
        near = np.array([i for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)
                         for i in self.grid.get((key[0] + a, key[1] + b, key[2] + c), ())], dtype=np.int64)
        return near[((self.shift[near] - self.shift[p]) ** 2).sum(axis=1) < self.reach2]

    def test_slots(self, p: int):
        """Every open slot of parent ``p`` tested at once against the primaries nearby: the slots ``(ff, qq)``,
        the children there (vertices, rotations, shifts) and which intrude (``bad``) or come too close or
        leave too narrow a notch (``close``)."""
        face_idx, tol, clearance = self.s.faces, self.tol, self.clearance
        ff, qq = np.nonzero(self.avail[p])
        Rp = self.rot[p]
        Rc = Rp @ self.slot_A[ff, qq]                       # (C, 3, 3)
        tc = self.slot_b[ff, qq] @ Rp.T + self.shift[p]     # (C, 3)
        kids = self.v0 @ Rc.transpose(0, 2, 1) + tc[:, None, :]
        for c in range(len(ff)):  # contact face: the parent's exact coordinates
            kids[c, face_idx[ff[c]]] = self.verts[p][self.tpl[ff[c]][qq[c]][3]]
        near = self.near(p)
        d2 = ((tc[:, None, :] - self.shift[near][None, :, :]) ** 2).sum(-1)  # (C, M)
        ci, mj = np.nonzero(d2 < self.h * self.h)
        deep = d2[ci, mj] < (2.0 * self.s.inradius) ** 2 - tol  # inspheres overlap: intrusion for sure
        bad = np.zeros(len(ff), dtype=bool)
        bad[ci[deep]] = True
        ci, mj = ci[~deep], mj[~deep]
        test = ~bad[ci]
        ci, mj = ci[test], near[mj[test]]
        close = np.zeros(len(ff), dtype=bool)
        if len(ci):
            kn = self.n0 @ Rc[ci].transpose(0, 2, 1)
            gap = sat_gap(kids[ci], kn, self.e0 @ Rc[ci].transpose(0, 2, 1), self.verts[mj], self.normals[mj],
                          self.edges[mj], clearance)
            hit = gap < -tol
            bad[ci[hit]] = True
            # contact with a primary other than the parent: allowed only at exactly shared vertices
            sel = np.flatnonzero(~hit & (gap < clearance) & (mj != p))
            if len(sel):
                cs, ms = ci[sel], mj[sel]
                exact = _exact_contacts(
                    kids[cs], kn[sel], self.h0 + np.einsum("pfk,pk->pf", kn[sel], tc[cs]),
                    self.verts[ms], self.normals[ms], self.h0 + np.einsum("pfk,pk->pf", self.normals[ms], self.shift[ms]),
                    self.on_face[ff[cs]], clearance)
                close[cs[~exact]] = True
        for c in np.flatnonzero(~(bad | close)):  # the notch left around each edge of the contact face
            fc, kid = face_idx[ff[c]], kids[c]
            for i in range(len(fc)):
                taken = self.around.get(_edge_key(kid[fc[i]], kid[fc[(i + 1) % len(fc)]]), 0.0)
                if 2.0 * np.pi - taken - self.dihedral[ff[c]][i] < self.min_notch:
                    close[c] = True
                    break
        return ff, qq, kids, Rc, tc, bad, close

    def place(self, n: int, kid: np.ndarray, Rn: np.ndarray, tn: np.ndarray, f: int) -> None:
        """Primary ``n`` placed: its geometry, its open faces (all but ``f``, its contact face), its edges."""
        _add_edges_around(self.around, kid, self.s.faces, self.dihedral)
        self.verts[n], self.rot[n], self.shift[n] = kid, Rn, tn
        self.normals[n], self.edges[n] = self.n0 @ Rn.T, self.e0 @ Rn.T
        self.avail[n] = self.base
        self.avail[n, f] = False
        self.open_[n] = self.avail[n].any()
        self.grid.setdefault(tuple(int(x) for x in np.floor(tn / self.cell)), []).append(n)


def _choose_slot(g: _Growth, p: int, rng: np.random.Generator, tried: np.ndarray):
    """The paper's choice on parent ``p``: an open face uniformly, then an orientation; rejected ones are
    dropped (``tried`` counts accepted, intruding, too close).  The child placed, or None when ``p`` has no
    acceptable slot left (``p`` is then closed)."""
    ff, qq, kids, Rc, tc, bad, close = g.test_slots(p)
    F, K = g.base.shape
    ok = np.zeros((F, K), dtype=bool)
    ok[ff, qq] = ~(bad | close)
    why = np.zeros((F, K), dtype=np.int64)
    why[ff, qq] = np.where(bad, 1, np.where(close, 2, 0))
    slot_of = np.full((F, K), -1, dtype=np.int64)
    slot_of[ff, qq] = np.arange(len(ff))
    placed = None
    while g.avail[p].any():
        faces_open = np.flatnonzero(g.avail[p].any(axis=1))
        f = int(faces_open[rng.integers(len(faces_open))])
        slots = np.flatnonzero(g.avail[p, f])
        q = int(slots[rng.integers(len(slots))])
        tried[why[f, q]] += 1
        if ok[f, q]:
            g.avail[p, f] = False
            c = slot_of[f, q]
            placed = (kids[c], Rc[c], tc[c], f)
            break
        g.avail[p, f, q] = False
    if not g.avail[p].any():
        g.open_[p] = False
    return placed


def _aggregate_polyhedra(s: Solid, n_total: int, exponent: float, rng: np.random.Generator, tol: float,
                         clearance: float, min_notch: float = MIN_NOTCH):
    g = _Growth.start(s, n_total, tol, clearance, min_notch)
    tried = np.zeros(3, dtype=np.int64)  # chosen slots: accepted, intruding, too close / too narrow a notch
    for n in range(1, n_total):
        placed = None
        while placed is None:
            placed = _choose_slot(g, parent_index(n, exponent, rng, g.open_), rng, tried)
        g.place(n, *placed)
    return g.verts, g.shift, tried


def aggregate(primitive: str, primaries: int, *, exponent: float, rng: RNGLike,
              tol: float = INTRUSION_TOLERANCE, clearance: float = CONTACT_CLEARANCE,
              min_notch: float = MIN_NOTCH) -> Aggregate:
    """Grow an aggregate of ``primaries`` unit-volume primaries (no mesh).

    Cubes grow on the integer lattice (a face is occupied when the
    neighbouring cell is).  Other primaries attach by reflection through the
    chosen face of the parent, turned about the face normal into one of the
    face's distinct orientations; a placement that intrudes into an existing
    primary (exact separating-axis test, overlap > ``tol``) is rejected and
    another face/orientation of the same parent is tried.  So is a placement
    that comes within ``clearance`` (separating-axis gap, in primary sizes)
    of a primary other than its parent, unless the two touch only at
    vertices of the contact face that they share bit for bit (edge and
    vertex contacts inherited through the parent), and one that leaves less
    than ``min_notch`` radians empty around an edge shared by several
    primaries.  Together these keep the exact face-cancellation union
    (:func:`union_surface`) a 2-manifold as written, also after smoothing
    (docs/methods/dpa.md, "Contacts"); ``clearance=-1, min_notch=-1``
    turns them off (the growth before these contact rules were added, for
    comparison).

    Parameters
    ----------
    primitive : str
        One of :data:`PRIMITIVES`.
    primaries : int
        N ≥ 1.
    exponent : float
        ε of Eq. 4 (> 0): small values grow compact aggregates, large ones branched.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The parents, faces
        and orientations are drawn in growth order.
    tol : float, default INTRUSION_TOLERANCE
        Largest overlap accepted by the separating-axis test, in primary sizes.
    clearance : float, default CONTACT_CLEARANCE
        Smallest gap to a non-parent primary, in primary sizes (−1: no check).
    min_notch : float, default MIN_NOTCH
        Smallest empty angle around a shared edge, radians (−1: no check).

    Returns
    -------
    Aggregate
        The primaries' vertices and centres, in primary sizes.

    Raises
    ------
    ValueError
        For an unknown primitive.

    Examples
    --------
    >>> agg = aggregate("octahedron", 50, exponent=2.0, rng=0)
    >>> agg.vertices.shape
    (50, 6, 3)
    """
    rng = as_generator(rng)
    s = solid(primitive)
    if primitive == "cube":
        cells = _aggregate_cubes(primaries, exponent, rng)
        verts = cells[:, None, :] + (s.vertices[None] + 0.5)
        return Aggregate(s, verts, cells + 0.5, cells)
    verts, centres, tried = _aggregate_polyhedra(s, primaries, exponent, rng, tol, clearance, min_notch)
    return Aggregate(s, verts, centres, None, tuple(int(t) for t in tried))


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
    edge at the default, measured in ``tests/methods/test_dpa.py``).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        The lattice surface's vertices, in primary sizes.
    faces : (F, 3) array_like of int
        Its triangles.
    gap : float, default PINCH_GAP
        Distance each copy of a pinched vertex moves, in primary sizes.

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


def union_surface(agg: Aggregate) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The union of the primaries as one closed 2-manifold, by exact coincident-face cancellation.

    Every primary contributes its polygonal faces (outward; reversed for the
    mirrored, left-handed primaries).  Vertices are merged by exact position:
    a child's contact face holds its parent's exact coordinates
    (:func:`aggregate`), so the two copies of a contact face are the same
    vertices in opposite order and both are removed.  The remaining polygons
    are fan-triangulated.  Growth allows no other contact than at exactly
    shared vertices (``CONTACT_CLEARANCE``), so what remains is the outer
    surface plus one closed component, of negative volume, per sealed cavity;
    the cavities are dropped (filled).  No boolean, no tolerance: the union
    volume is N primary volumes up to rounding.

    Parameters
    ----------
    agg : Aggregate
        A non-cube aggregate (cubes use :func:`lattice_surface`).

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    union_volume : float
        Volume of the union before filling sealed cavities (N primary volumes).
    cavity : float
        Volume of the sealed cavities that were filled.

    Raises
    ------
    ValueError
        (naming ``primaries``) if a face is shared by more than two primaries or
        twice with the same orientation, or the surface is not one body (the
        growth rule excludes both).

    Examples
    --------
    >>> agg = aggregate("octahedron", 2, exponent=1.0, rng=1)
    >>> v, f, vol, cav = union_surface(agg)
    >>> len(v), len(f), round(vol, 12), cav
    (9, 14, 2.0, 0.0)
    """
    from ...geometry.solid import _edge_components, signed_volume, unique_rows

    s = agg.solid
    V = agg.vertices
    n, nv = V.shape[0], V.shape[1]
    a, b, c = V[:, s.triangles[:, 0]], V[:, s.triangles[:, 1]], V[:, s.triangles[:, 2]]
    handed = (a * np.cross(b, c)).sum(axis=(1, 2)) > 0  # reflected primaries are left-handed
    points, inv = unique_rows(V.reshape(-1, 3))
    ids = inv.reshape(n, nv)
    tris = []
    for k in sorted({len(fc) for fc in s.faces}):
        idx = np.array([fc for fc in s.faces if len(fc) == k], dtype=np.int64)  # (Fk, k)
        poly = ids[:, idx].reshape(-1, k)
        poly = np.where(np.repeat(handed, len(idx))[:, None], poly, poly[:, ::-1])
        key = np.sort(poly, axis=1)
        _, group, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        group = group.reshape(-1)
        if (count > 2).any():
            raise InputError("primaries: a face is shared by more than two primaries")
        pair = np.flatnonzero(count[group] == 2)
        if len(pair):
            # a cancelled pair must run in opposite directions: start both at their smallest vertex
            mine = poly[pair]
            other = poly[_partner(group, pair)]
            r0 = np.argmin(mine, axis=1)
            r1 = np.argmin(other, axis=1)
            cols = np.arange(k)
            m0 = np.take_along_axis(mine, (r0[:, None] + cols) % k, axis=1)
            m1 = np.take_along_axis(other, (r1[:, None] - cols) % k, axis=1)  # reversed
            if not (m0 == m1).all():
                raise InputError("primaries: two primaries share a face with the same orientation")
        keep = poly[count[group] == 1]
        for j in range(1, k - 1):
            tris.append(keep[:, [0, j, j + 1]])
    f = np.concatenate(tris)
    union_volume = signed_volume(points, f)
    n_comp, label = _edge_components(f)
    keep = np.zeros(len(f), dtype=bool)
    cavity, bodies = 0.0, 0
    for comp in range(n_comp):
        sel = label == comp
        vol = signed_volume(points, f[sel])
        if vol > 0:
            keep |= sel
            bodies += 1
        else:
            cavity -= vol
    if bodies != 1:
        raise InputError(f"primaries: the union surface has {bodies} outer bodies")
    used, f = np.unique(f[keep], return_inverse=True)
    return points[used], f.reshape(-1, 3).astype(np.int64), union_volume, cavity


def _partner(group: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """For rows of a group of two, the index of the other row of the same group."""
    order = np.argsort(group, kind="stable")
    pos = np.empty_like(order)
    pos[order] = np.arange(len(order))
    # the two members of a group are adjacent in ``order``
    p = pos[rows]
    left = (p > 0) & (group[order[np.maximum(p - 1, 0)]] == group[rows])
    return np.where(left, order[np.maximum(p - 1, 0)], order[np.minimum(p + 1, len(order) - 1)])


def smooth_surface(vertices: np.ndarray, faces: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Round the corners by ``level`` steps of Loop subdivision (each splits a triangle into four).

    Loop subdivision works on the connectivity only, so a closed, oriented
    2-manifold stays one; flat regions stay flat, edges and corners are
    rounded over about one primary size and convex parts shrink slightly.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        A closed, oriented 2-manifold.
    faces : (F, 3) array_like of int
        Its triangles.
    level : int
        Loop subdivision steps (0 returns the mesh as float64/int64).

    Returns
    -------
    vertices : (V', 3) float64
    faces : (4^level · F, 3) int64
    """
    from trimesh.remesh import subdivide_loop

    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    v, f = subdivide_loop(v, f, iterations=int(level))
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


# --------------------------------------------------------------------------- the generator

def physical_info(info: dict, scale: float) -> dict:
    """``info`` of a grain scaled by ``scale`` (mm per model unit) with its lengths in mm.

    :func:`build` gives ``R_g`` in primary sizes, ``cavity_volume`` in primary
    volumes and ``primary_size`` in model units; a manifest records all three in
    mm / mm³ (``R_g_mm``, ``cavity_volume_mm3``, ``primary_size_mm``), like
    ``grainforge analyse`` (``radius_of_gyration_mm``).  R_g/a, the ratio of
    the paper's mass–radius relation, is ``R_g_mm / primary_size_mm``.

    Parameters
    ----------
    info : dict
        A DPA grain's ``info`` (:func:`build`).
    scale : float
        Millimetres per model unit.

    Returns
    -------
    dict
        A copy with ``R_g`` and ``primary_size`` in mm and ``cavity_volume`` in mm³.

    Examples
    --------
    >>> physical_info({"R_g": 3.0, "cavity_volume": 2.0, "primary_size": 0.5, "D_A": 2.1}, 4.0)
    {'R_g': 6.0, 'cavity_volume': 16.0, 'primary_size': 2.0, 'D_A': 2.1}
    """
    a = float(info["primary_size"]) * float(scale)
    return {**info, "R_g": float(info["R_g"]) * a, "cavity_volume": float(info["cavity_volume"]) * a**3,
            "primary_size": a}


def build(p: Params, rng: RNGLike):
    """Vertices, faces and info of one DPA grain (scaled to equivalent radius 1, not centred).

    Info: ``D_A`` (Eq. 5), ``D_A_scaling`` (the slope of log V against log A
    over the aggregate's growth), ``porosity`` (1 − V/V_hull) and ``R_g`` (radius
    of gyration in primary sizes) of the aggregate of primaries;
    ``cavity_volume`` (sealed cavities filled in the mesh, in primary
    volumes); ``primary_size`` (the primary's V_p^(1/3) in grain units).

    Parameters
    ----------
    p : Params
        The grain's parameters (validated).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The aggregate's
        growth, :func:`aggregate`.

    Returns
    -------
    vertices : (V, 3) float64
        In model units, about the construction origin (not yet centred on the centroid).
    faces : (F, 3) int64
        Outward, counter-clockwise triangles.
    info : dict
        The generation's derived quantities, the keys of :data:`INFO_COLUMNS`.

    Raises
    ------
    ParameterError
        Naming the parameter to lower when the grain would not be a valid star-shaped solid.
    """
    agg = aggregate(p.primitive, p.primaries, exponent=p.exponent, rng=rng)
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
