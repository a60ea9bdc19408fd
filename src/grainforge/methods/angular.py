"""Angular grains: a rounded random polyhedron with dents and fractal roughness.

docs/design/algorithms.md §6; see ``docs/methods/angular.md``.  The grain is built in four
steps, all as a radius function r(u) of the unit direction u, sampled on the
icosphere like FSO and CRI grains:

1. **Core** (choice: random half-spaces, not a Voronoi cell).  ``facets``
   unit normals n_i are drawn by dart throwing on the sphere (no two closer
   than half the mean spacing, and every direction within 70° of a normal, so
   there are no slivers and no needle corners); each half-space n_i·x ≤ h_i is
   tangent to the ellipsoid with semi-axes proportional to ``aspect``
   (geometric mean 1 = R0), h_i = |diag(a, b, c) n_i|.  Every plane touches
   the ellipsoid, which lies inside all the others, so every plane is a facet:
   the core has exactly ``facets`` faces.
2. **Rounding**: the Minkowski sum of the core shrunk by ρ (planes at h_i − ρ)
   with a ball of radius ρ = ``rounding`` × c, c the smallest semi-axis (the
   radius of the largest sphere inscribed in the ellipsoid, hence roughly
   Wadell's roundness: corner radius / inscribed radius).  The facets stay on
   the same planes and stay exactly flat; edges become cylinders and corners
   spheres of radius ρ.  Its radius function is evaluated exactly: on a facet,
   r = h_i / (n_i·u) for the first plane the ray meets, kept where the point
   lies over the shrunk facet; elsewhere the ray leaves through an edge cylinder
   or corner sphere, and r is the largest exit distance over the edge
   cylinders and corner spheres of the shrunk core (evaluated only for the
   features whose planes pass close enough to the ray's exit point).
3. **Dents** (concavities): ``dents`` dips at uniformly random directions
   d_j with flat bottoms and steep walls,
   r ← r · (1 − depth · (1 − Π_j (1 − g_j))), g_j = exp(−2 x_j²),
   x_j = (1 − u·d_j) / w² ≈ θ²/(2w²), w = ``dent_width``: g is 1 at the
   centre and e^(−1/2) at θ = w; overlapping dents merge rather than deepen,
   so r never falls below (1 − depth) times the core's radius.
4. **Roughness**: the FSO overlay (:func:`grainforge.methods.fso.overlay`;
   ``fractal_dimension``, ``length_ratio``, ``surface`` — by default its
   seamless form, the double sum of Eqs. 2–3 on the 3D unit vector) with RMS
   ``roughness``, applied along the radius: r ← r · (1 + K·S(u)).

The sampled mesh of a positive radius function on the icosphere is always a
valid star-shaped solid.  With ``rounding`` = 0 the facets are exact planes
between the mesh vertices that lie on them; only the triangles that straddle
an edge cut it, by at most about one mesh edge length (see
``grainforge generate angular --printer`` for resolution matching).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.geodesic import icosphere
from ..params import ParameterError, param, validate
from ..rng import RNGLike, as_generator

__all__ = ["Params", "Core", "build", "core", "core_edges", "radius", "angular", "NAME"]

NAME = "angular"
VALIDITY_PARAMETER = "roughness"
#: vertices are unit directions times a positive radius: the solid contract's star certificate applies
STAR_SHAPED = True
#: generation outputs recorded in manifests
INFO_COLUMNS = ("rounding_radius", "flat_fraction", "min_radius", "max_radius")
#: largest ratio of the longest to the shortest aspect axis
MAX_ASPECT_RATIO = 20.0
#: every direction lies within this angle of some facet normal (bounds corner sharpness)
MAX_COVER_ANGLE = np.deg2rad(70.0)
#: no two facet normals closer than this fraction of the mean spacing sqrt(8π/(√3 k))
MIN_SEPARATION = 0.5
#: smallest allowed radius after dents and roughness, as a fraction of R0
MIN_RADIUS = 0.05
#: icosphere level of the covering check (642 directions, spacing ≈ 9°)
_COVER_LEVEL = 3
_MAX_DRAWS = 200
#: ``aspect_by`` choices: the facets' tangent ellipsoid, or the finished grain's inertia ellipsoid
ASPECT_BY = ("facets", "inertia")


@dataclass(frozen=True)
class Params:
    """Parameters of the angular generator."""

    facets: int = param(20, "number of facets of the polyhedral core", kind="int", low=6, high=200)
    aspect: tuple[float, float, float] = param(
        (1.3, 1.1, 1.0), "semi-axes L:I:S (along x, y, z) of the ellipsoid the facets are tangent to "
        f"(ratios only; L/S at most {MAX_ASPECT_RATIO:g})", kind="floats", low=0.0, low_open=True, high=100.0,
        shown_default="1.3:1.1:1",
    )
    rounding: float = param(
        0.1, "edge and corner radius relative to the smallest semi-axis (≈ Wadell roundness; 0 = sharp)",
        low=0.0, high=0.9,
    )
    dents: int = param(0, "number of smooth concavities", kind="int", low=0, high=12)
    dent_depth: float = param(0.25, "relative depth of each dent (radius × (1 − depth) at its centre)",
                              low=0.0, high=0.7)
    dent_width: float = param(0.45, "angular width w of each dent (Gaussian in angle)", unit="rad",
                              low=0.1, high=1.2)
    roughness: float = param(0.0, "RMS of the FSO overlay, relative to the radius (0 = smooth facets)",
                             low=0.0, high=0.15)
    fractal_dimension: float = param(2.4, "FSO overlay: fractal dimension D", low=2.0, high=3.0,
                                     high_open=True)
    length_ratio: float = param(1.0, "FSO overlay: stochastic length L/R0 (small = fine texture)",
                                low=0.05, high=20.0)
    surface: str = param("seamless", "FSO overlay form: seamless (3D unit vector, no special latitude) or "
                         "paper (Eqs. 2-3, mirror seam at the equator)", kind="str", choices=("seamless", "paper"))
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)
    aspect_by: str = param(
        "facets", "how the aspect shapes the grain: facets (tangent to the L:I:S ellipsoid; with few facets the "
        "core's own random shape sets much of the grain's proportions) or inertia (the finished grain is "
        "stretched so that its inertia ellipsoid has exactly the L:I:S ratios)", kind="str",
        choices=ASPECT_BY,
    )

    def __post_init__(self):
        validate(self)
        if len(self.aspect) != 3:
            raise ParameterError("aspect", f"must be 3 numbers L:I:S, got {self.aspect!r}")
        L, I, S = self.aspect
        if not L >= I >= S:
            raise ParameterError("aspect", f"must be ordered L >= I >= S, got {L:g}:{I:g}:{S:g}")
        if L > MAX_ASPECT_RATIO * S:
            raise ParameterError("aspect", f"L/S must be at most {MAX_ASPECT_RATIO:g}, got {L:g}:{I:g}:{S:g}")


@dataclass(frozen=True)
class Core:
    """The rounded convex core of one grain (R0 = 1 units).

    Attributes
    ----------
    normals : (k, 3) float64
        Unit outward facet normals n_i.
    offsets : (k,) float64
        Plane offsets h_i: facet i lies on n_i·x = h_i.
    rho : float
        Edge and corner radius ρ.
    vertices : (m, 3) float64
        Vertices of the shrunk core (planes at h_i − ρ).
    vertex_planes : (m, k) bool
        The planes through each vertex.
    edges : (e, 2) int64
        End vertices of each edge of the shrunk core.
    edge_planes : (e, 2) int64
        The two facets i < j meeting at each edge.
    semi_axes : (3,) float64
    """

    normals: np.ndarray
    offsets: np.ndarray
    rho: float
    vertices: np.ndarray
    vertex_planes: np.ndarray
    edges: np.ndarray
    edge_planes: np.ndarray
    semi_axes: np.ndarray


def _semi_axes(aspect) -> np.ndarray:
    a = np.asarray(aspect, dtype=np.float64)
    a = a / a.max()  # ratios only (and no underflow for tiny values): each in [1/MAX_ASPECT_RATIO, 1]
    return a / np.prod(a) ** (1.0 / 3.0)


def _draw_normals(k: int, rng: np.random.Generator) -> np.ndarray:
    """k unit normals by dart throwing, redrawn until they cover every direction within 70°."""
    cover_dirs, _ = icosphere(_COVER_LEVEL)
    sep = np.cos(MIN_SEPARATION * np.sqrt(8.0 * np.pi / (np.sqrt(3.0) * k)))
    for _ in range(_MAX_DRAWS):
        cand = rng.normal(size=(40 * k, 3))
        cand /= np.linalg.norm(cand, axis=1, keepdims=True)
        chosen = [cand[0]]
        for c in cand[1:]:
            if len(chosen) == k:
                break
            if np.max(np.asarray(chosen) @ c) < sep:
                chosen.append(c)
        if len(chosen) < k:
            continue
        n = np.asarray(chosen)
        if np.min(np.max(cover_dirs @ n.T, axis=1)) > np.cos(MAX_COVER_ANGLE):
            return n
    raise ParameterError("facets", f"could not place {k} facet normals covering every direction")  # pragma: no cover


def core(p: Params, rng: RNGLike) -> Core:
    """Draw the convex core (facet planes) and its rounding geometry.

    The draws (the normals) come first from ``rng``; :func:`build` then draws
    the dents and the roughness field from the same generator.

    Parameters
    ----------
    p : Params
        ``facets``, ``aspect`` and ``rounding`` are used.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  Three normal draws
        per facet normal.

    Returns
    -------
    Core
        Facet planes tangent to the ``aspect`` ellipsoid, the rounding radius ρ and the shrunk polytope.

    Examples
    --------
    >>> c = core(Params(facets=12, rounding=0.2), np.random.default_rng(0))
    >>> c.normals.shape, round(c.rho, 3) > 0
    ((12, 3), True)
    """
    n = _draw_normals(p.facets, as_generator(rng))
    ax = _semi_axes(p.aspect)
    h = np.linalg.norm(n * ax, axis=1)
    rho = float(p.rounding * ax.min())
    return Core(n, h, rho, *_polytope(n, h - rho), ax)


def _polytope(normals: np.ndarray, offsets: np.ndarray):
    """Vertices, vertex-plane incidence, edges and edge planes of {x : n_i·x ≤ offsets_i} (origin inside)."""
    from scipy.spatial import HalfspaceIntersection

    hs = HalfspaceIntersection(np.column_stack([normals, -offsets]), np.zeros(3))
    verts = np.asarray(hs.intersections, dtype=np.float64)
    on = np.abs(verts @ normals.T - offsets) <= 1e-8 * (1.0 + np.abs(offsets))
    # merge numerically coincident vertices (qhull reports a degenerate vertex once per simplex)
    key = np.round(verts, 9)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    merged = np.zeros((len(first), len(offsets)), dtype=bool)
    np.logical_or.at(merged, inverse, on)
    verts, on = verts[first], merged
    shared = on.T.astype(np.int64) @ on.astype(np.int64)  # vertices on both planes
    ii, jj = np.nonzero(np.triu(shared >= 2, 1))
    edges = np.empty((len(ii), 2), dtype=np.int64)
    for e, (i, j) in enumerate(zip(ii, jj)):
        idx = np.flatnonzero(on[:, i] & on[:, j])
        s = verts[idx] @ np.cross(normals[i], normals[j])
        edges[e] = idx[np.argmin(s)], idx[np.argmax(s)]
    return verts, on, edges, np.column_stack([ii, jj]).astype(np.int64)


def core_edges(c: Core) -> list[tuple[np.ndarray, np.ndarray, float, int, int]]:
    """The edges of the shrunk core (planes at h_i − ρ; the core itself when ρ = 0).

    Parameters
    ----------
    c : Core
        From :func:`core`.

    Returns
    -------
    list of (midpoint, unit direction, length, i, j)
        One per edge, with the indices i < j of the two facets meeting there.

    Examples
    --------
    >>> c = core(Params(facets=8), np.random.default_rng(0))
    >>> len(core_edges(c)) == 3 * 8 - 6   # a simple polyhedron: E = 3F − 6
    True
    """
    out = []
    for (va, vb), (i, j) in zip(c.edges, c.edge_planes):
        a, b = c.vertices[va], c.vertices[vb]
        length = float(np.linalg.norm(b - a))
        if length > 1e-9:
            out.append(((a + b) / 2, (b - a) / length, length, int(i), int(j)))
    return out


def _feature_planes(c: Core) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per corner and per edge: its planes (padded by repetition) and the smallest n_i·x on each of them.

    On the rounded surface over a feature F of the shrunk core, x = p + ρν with
    ν in F's normal cone (spanned by the normals n_j, j ∈ F), so for i ∈ F
    n_i·x = h_i − ρ + ρ n_i·ν ≥ h_i − ρ (1 − min_{j∈F} n_i·n_j).
    """
    NN = c.normals @ c.normals.T
    deg = max(1, int(c.vertex_planes.sum(axis=1).max(initial=1)))
    v_idx = np.empty((len(c.vertices), deg), dtype=np.int64)
    for m, row in enumerate(c.vertex_planes):
        idx = np.flatnonzero(row)
        v_idx[m] = np.resize(idx, deg)
    v_min = np.take_along_axis(NN[v_idx], v_idx[:, None, :].repeat(deg, 1), axis=2).min(axis=2)
    v_tau = c.offsets[v_idx] - c.rho * (1.0 - v_min)
    e_idx = c.edge_planes
    cij = NN[e_idx[:, 0], e_idx[:, 1]]
    e_tau = c.offsets[e_idx] - c.rho * (1.0 - np.minimum(cij, 1.0))[:, None]
    return v_idx, v_tau, e_idx, e_tau


def _capsule_exit(unit: np.ndarray, c: Core, along: np.ndarray) -> np.ndarray:
    """Largest exit distance of the rays t·u (t > 0) from the shrunk core's edge cylinders and corner spheres.

    ``along`` (n, k) bounds n_i·x from above for the ray's exit point x
    (r_h n_i·u where n_i·u ≥ 0, r' n_i·u elsewhere, with r' ≤ r ≤ r_h the
    radii of the shrunk core and of the sharp one).  A feature is
    evaluated only where every one of its planes passes the bound of
    :func:`_feature_planes`, which the feature the ray leaves through always
    does; any other capsule lies inside the grain, so the result is exact.
    Edge cylinders count where the exit point projects inside the segment.
    """
    rho2 = c.rho * c.rho
    V = c.vertices
    tol = 1e-9 * (1.0 + np.abs(c.offsets)).max()
    v_idx, v_tau, e_idx, e_tau = _feature_planes(c)
    best = np.full(len(unit), -np.inf)
    # corner spheres: |t u − v| = ρ, far root t = u·v + sqrt((u·v)² − |v|² + ρ²)
    iu, iv = np.nonzero(np.all(along[:, v_idx] >= v_tau - tol, axis=2))
    b = np.einsum("ij,ij->i", unit[iu], V[iv])
    disc = b * b - (np.einsum("ij,ij->i", V[iv], V[iv]) - rho2)
    hit = disc >= 0.0
    np.maximum.at(best, iu[hit], b[hit] + np.sqrt(disc[hit]))
    # edge cylinders
    a = V[c.edges[:, 0]]
    d = V[c.edges[:, 1]] - a
    length = np.linalg.norm(d, axis=1)
    d = d / np.maximum(length, 1e-300)[:, None]
    ad = np.einsum("ij,ij->i", a, d)
    C_e = np.einsum("ij,ij->i", a, a) - ad * ad - rho2  # |a⊥|² − ρ²
    iu, ie = np.nonzero(np.all(along[:, e_idx] >= e_tau - tol, axis=2) & (length > 1e-12))
    u = unit[iu]
    ud = np.einsum("ij,ij->i", u, d[ie])
    q = 1.0 - ud * ud  # |u⊥|²
    B = np.einsum("ij,ij->i", u, a[ie]) - ud * ad[ie]  # u⊥·a⊥
    disc = B * B - q * C_e[ie]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (B + np.sqrt(np.maximum(disc, 0.0))) / q
        s = t * ud - ad[ie]
        ok = (disc >= 0.0) & (q > 1e-12) & (s >= 0.0) & (s <= length[ie])
    np.maximum.at(best, iu[ok], t[ok])
    return best


def radius(unit: np.ndarray, c: Core) -> tuple[np.ndarray, np.ndarray]:
    """Exact radius function of the rounded core in directions ``unit``.

    Parameters
    ----------
    unit : (V, 3) float64
        Unit vectors.
    c : Core

    Returns
    -------
    r : (V,) float64
        Distance from the origin to the surface along each direction.
    flat : (V,) bool
        Whether the surface point lies on a flat facet.

    Examples
    --------
    A cube of half-width 1 rounded with ρ = 0.5: the face centre is at 1, the
    corner at (1 − ρ)·√3 + ρ.

    >>> n = np.vstack([np.eye(3), -np.eye(3)])
    >>> c = Core(n, np.ones(6), 0.5, *_polytope(n, np.full(6, 0.5)), np.ones(3))
    >>> r, flat = radius(np.array([[1.0, 0, 0], [1, 1, 1] / np.sqrt(3)]), c)
    >>> np.round(r, 6).tolist(), flat.tolist()
    ([1.0, 1.366025], [True, False])
    """
    cos = unit @ c.normals.T  # (V, k)
    g = cos / c.offsets  # the first plane met along u has the largest (n_i·u)/h_i > 0
    i = np.argmax(g, axis=1)
    r_h = 1.0 / g[np.arange(len(unit)), i]
    if c.rho <= 0.0:
        return r_h, np.ones(len(unit), dtype=bool)
    # over the shrunk facet i: y = r_h u − ρ n_i satisfies n_j·y ≤ h_j − ρ for every j
    along = r_h[:, None] * cos  # n_j·x_H
    lhs = along - c.rho * (c.normals @ c.normals.T)[i]
    flat = np.all(lhs <= c.offsets - c.rho + 1e-9 * (1.0 + c.offsets), axis=1)
    r = r_h.copy()
    rounded = ~flat
    if rounded.any():
        # upper bound of n_j·x at the exit point x = r u, with r' ≤ r ≤ r_h (r' the shrunk core's radius)
        cr = cos[rounded]
        r_lo = 1.0 / np.max(cr / (c.offsets - c.rho), axis=1)
        upper = np.where(cr >= 0.0, along[rounded], r_lo[:, None] * cr)
        exit_r = _capsule_exit(unit[rounded], c, upper)
        lost = ~np.isfinite(exit_r)
        if lost.any():  # pragma: no cover - the bound is proven; this keeps a numerical edge case exact
            exit_r[lost] = _capsule_exit(unit[rounded][lost], c, np.full((int(lost.sum()), len(c.offsets)), np.inf))
        r[rounded] = np.minimum(r_h[rounded], exit_r)
    return r, flat


def _dent_factor(unit: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """Dents at uniformly random directions: flat-bottomed dips with steep walls (super-Gaussian in angle)."""
    if p.dents == 0:
        return np.ones(len(unit))
    centres = rng.normal(size=(p.dents, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    x = (1.0 - unit @ centres.T) / (p.dent_width**2)  # ≈ θ² / (2w²)
    g = np.exp(-2.0 * x * x)  # = exp(−θ⁴ / (2w⁴)): 1 at the centre, e^(−1/2) at θ = w
    # overlapping dents merge ("or"), they do not deepen: the factor stays in [1 − depth, 1]
    return 1.0 - p.dent_depth * (1.0 - np.prod(1.0 - g, axis=1))


def _roughness_factor(unit: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    """1 + K·S(u): the FSO overlay (:func:`grainforge.methods.fso.overlay`) with RMS ``roughness``."""
    from . import fso

    fp = fso.Params(fractal_dimension=p.fractal_dimension, length_ratio=p.length_ratio, amplitude=p.roughness,
                    surface=p.surface)
    if p.roughness == 0.0:
        return np.ones(len(unit))
    return 1.0 + fso.overlay(unit, fp, rng)


def build(p: Params, rng: RNGLike):
    """Vertices, faces and info of one angular grain (R0 = 1, not yet centred).

    Parameters
    ----------
    p : Params
        The grain's parameters (validated).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by the draws.  The core's
        normals, then the dents, then the roughness field.

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
    rng = as_generator(rng)
    unit, faces = icosphere(p.subdivisions)
    inertia = p.aspect_by == "inertia"
    c = core(replace(p, aspect=(1.0, 1.0, 1.0)) if inertia else p, rng)
    r, flat = radius(unit, c)
    r = r * _dent_factor(unit, p, rng)
    r = r * _roughness_factor(unit, p, rng)
    rmin = float(r.min())
    if rmin <= MIN_RADIUS:
        raise ParameterError(
            "roughness",
            f"{p.roughness} is too large for this grain: the smallest radius would be {rmin:.3f}·R0 "
            f"(must stay above {MIN_RADIUS}·R0 for a star-shaped solid); lower it (or the dents)",
        )
    faces = np.array(faces)
    vertices = unit * r[:, None]
    scale = np.ones(3)
    if inertia:
        stretch = _inertia_stretch(vertices, faces, p.aspect)
        vertices = vertices @ stretch.T
        scale = np.linalg.svd(stretch, compute_uv=False)
    info = {"rounding_radius": c.rho * float(scale.min()), "flat_fraction": float(flat.mean()), "min_radius": rmin,
            "max_radius": float(r.max())}
    return vertices, faces, info


def _inertia_stretch(vertices: np.ndarray, faces: np.ndarray, aspect) -> np.ndarray:
    """The linear map (determinant 1) that turns the solid's inertia ellipsoid into one of semi-axes ∝ ``aspect``
    along x, y, z (its principal axes rotated onto them, longest on x).

    A linear map of determinant 1 keeps the volume, and keeps a solid star-shaped about the origin a valid
    star-shaped solid (every face's orientation about the origin has the sign of the determinant).

    Examples
    --------
    >>> unit, faces = icosphere(3)
    >>> v = unit * np.array([0.5, 2.0, 1.0])                      # an ellipsoid with its long axis on y
    >>> M = _inertia_stretch(v, np.array(faces), (3.0, 2.0, 1.0))
    >>> from grainforge.geometry.solid import second_moments
    >>> vol, _, C = second_moments(v @ M.T, np.array(faces))
    >>> sd = np.sqrt(np.diag(C))
    >>> np.round(sd / sd[2], 4).tolist(), bool(abs(np.linalg.det(M) - 1) < 1e-12)
    ([3.0, 2.0, 1.0], True)
    """
    from ..geometry.solid import second_moments

    vol, _, second = second_moments(vertices, faces)
    var, axes = np.linalg.eigh(second / vol)
    axes, sd = axes[:, ::-1], np.sqrt(np.maximum(var[::-1], 1e-300))  # longest first
    if np.linalg.det(axes) < 0:  # a rotation, not a reflection (which would turn the faces inside out)
        axes[:, 2] = -axes[:, 2]
    m = np.diag(_semi_axes(aspect) / sd) @ axes.T
    return m / np.cbrt(np.linalg.det(m))


def physical_info(info: dict, scale: float) -> dict:
    """``info`` of a grain scaled by ``scale`` (mm per model unit): ``rounding_radius`` in mm.

    Examples
    --------
    >>> physical_info({"rounding_radius": 0.1, "flat_fraction": 0.5}, 5.0)
    {'rounding_radius': 0.5, 'flat_fraction': 0.5}
    """
    return {**info, "rounding_radius": float(info["rounding_radius"]) * float(scale)}


def angular(
    *,
    facets: int = 20,
    aspect=(1.3, 1.1, 1.0),
    rounding: float = 0.1,
    dents: int = 0,
    dent_depth: float = 0.25,
    dent_width: float = 0.45,
    roughness: float = 0.0,
    fractal_dimension: float = 2.4,
    length_ratio: float = 1.0,
    surface: str = "seamless",
    subdivisions: int = 5,
    aspect_by: str = "facets",
    rng: RNGLike = None,
):
    """Generate one angular grain: a rounded random polyhedron with dents and roughness.

    Parameters
    ----------
    facets : int
        Number of facets of the convex core, 6–200 (default 20).
    aspect : (float, float, float)
        L:I:S semi-axes of the ellipsoid the facets are tangent to (x, y, z).
    rounding : float
        Edge/corner radius relative to the smallest semi-axis, 0–0.9 (0 = sharp).
    dents : int
        Number of smooth concavities, 0–12.
    dent_depth, dent_width : float
        Relative depth (0–0.7) and angular width in radians (0.1–1.2) of each dent.
    roughness : float
        RMS of the FSO overlay relative to the radius, 0–0.15 (0 = smooth facets).
    fractal_dimension, length_ratio : float
        D and L/R0 of the FSO overlay.
    surface : {"seamless", "paper"}
        FSO overlay form (see :func:`grainforge.methods.fso.overlay`).
    subdivisions : int
        Icosphere level 0–8 (default 5: 10,242 vertices).
    aspect_by : {"facets", "inertia"}
        ``facets``: the core's facets are tangent to the L:I:S ellipsoid (few
        facets leave much of the grain's proportions to its seed);
        ``inertia``: the grain is built isotropic, then stretched so that its
        inertia ellipsoid has exactly the L:I:S ratios (measured flatness and
        elongation then follow ``aspect``).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seed or generator (:mod:`grainforge.rng`).  An int, a plain SeedSequence's entropy, or the seed
        drawn for None is recorded as ``Grain.seed``; a Generator leaves it None.

    Returns
    -------
    Grain
        Centred on its volume centroid, R0 = 1 (the facets' ellipsoid has
        geometric-mean semi-axis 1).

    Raises
    ------
    ValueError
        For an out-of-range parameter, or when dents and roughness would bring
        a radius to 0.05·R0 or less (the message names ``roughness``).

    Examples
    --------
    >>> from grainforge import angular
    >>> g = angular(facets=12, rounding=0.2, subdivisions=3, rng=1)
    >>> len(g.vertices), g.seed, g.method
    (642, 1, 'angular')
    >>> angular(rounding=1.5)
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: rounding must be in [0, 0.9], got 1.5
    """
    from . import generate

    p = Params(
        facets=facets, aspect=tuple(aspect), rounding=rounding, dents=dents, dent_depth=dent_depth,
        dent_width=dent_width, roughness=roughness, fractal_dimension=fractal_dimension,
        length_ratio=length_ratio, surface=surface, subdivisions=subdivisions, aspect_by=aspect_by,
    )
    return generate(NAME, p, rng)
