"""Angular grains: a rounded random polyhedron with dents and fractal roughness.

ALGORITHMS.md §6; see ``docs/methods/angular.md``.  The grain is built in four
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
   or corner sphere, and r is the largest exit distance over the capsules
   (segment ⊕ ball) of the shrunk core's edges.
3. **Dents** (concavities): ``dents`` smooth radial dips at random directions,
   r ← r · (1 − depth · (1 − Π_j (1 − g_j))), g_j = exp((u·d_j − 1) / w²),
   w = ``dent_width``: one dent is a Gaussian dip of the given depth, and
   overlapping dents merge rather than deepen, so r never falls below
   (1 − depth) times the core's radius.
4. **Roughness**: the FSO overlay (Eqs. 2–3; ``fractal_dimension``,
   ``length_ratio``) with RMS ``roughness``, applied along the radius:
   r ← r · (1 + K·S(u)).

The sampled mesh of a positive radius function on the icosphere is always a
valid star-shaped solid.  With ``rounding`` = 0 the facets are exact planes
between the mesh vertices that lie on them; only the triangles that straddle
an edge cut it, by at most about one mesh edge length (see
``grainforge generate angular --printer`` for resolution matching).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geodesic import icosphere
from ..params import ParameterError, param, validate

__all__ = ["Params", "Core", "build", "core", "core_edges", "radius", "angular", "NAME"]

NAME = "angular"
VALIDITY_PARAMETER = "roughness"
#: generation outputs recorded in manifests
INFO_COLUMNS = ("rounding_radius", "flat_fraction", "min_radius", "max_radius")
#: largest ratio of the longest to the shortest aspect axis
MAX_ASPECT_RATIO = 10.0
#: every direction lies within this angle of some facet normal (bounds corner sharpness)
MAX_COVER_ANGLE = np.deg2rad(70.0)
#: no two facet normals closer than this fraction of the mean spacing sqrt(8π/(√3 k))
MIN_SEPARATION = 0.5
#: smallest allowed radius after dents and roughness, as a fraction of R0
MIN_RADIUS = 0.05
#: icosphere level of the covering check (642 directions, spacing ≈ 9°)
_COVER_LEVEL = 3
_MAX_DRAWS = 200


@dataclass(frozen=True)
class Params:
    """Parameters of the angular generator."""

    facets: int = param(20, "number of facets of the polyhedral core", kind="int", low=6, high=200)
    aspect: tuple[float, float, float] = param(
        (1.3, 1.1, 1.0), "semi-axes L:I:S (along x, y, z) of the ellipsoid the facets are tangent to "
        f"(ratios only; L/S at most {MAX_ASPECT_RATIO:g})", kind="floats", low=0.1, high=10.0,
    )
    rounding: float = param(
        0.1, "edge and corner radius relative to the smallest semi-axis (≈ Wadell roundness; 0 = sharp)",
        low=0.0, high=0.9,
    )
    dents: int = param(0, "number of smooth concavities", kind="int", low=0, high=12)
    dent_depth: float = param(0.25, "relative depth of each dent (radius × (1 − depth) at its centre)",
                              low=0.0, high=0.5)
    dent_width: float = param(0.45, "angular width w of each dent (Gaussian in angle)", unit="rad",
                              low=0.1, high=1.2)
    roughness: float = param(0.0, "RMS of the FSO overlay, relative to the radius (0 = smooth facets)",
                             low=0.0, high=0.3)
    fractal_dimension: float = param(2.4, "FSO overlay: fractal dimension D", low=2.0, high=3.0,
                                     high_open=True)
    length_ratio: float = param(1.0, "FSO overlay: stochastic length L/R0 (small = fine texture)",
                                low=0.05, high=20.0)
    subdivisions: int = param(5, "icosphere subdivisions (10·4^s + 2 vertices)", kind="int", low=0, high=8)

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
        Vertices of the shrunk core (planes at h_i − ρ); empty when ρ = 0.
    edges : (e, 2) int64
        Vertex index pairs whose capsules cover the rounded part (every hull
        triangle edge of the shrunk core: its true edges and, harmlessly,
        facet diagonals, whose capsules lie inside the grain).
    semi_axes : (3,) float64
    """

    normals: np.ndarray
    offsets: np.ndarray
    rho: float
    vertices: np.ndarray
    edges: np.ndarray
    semi_axes: np.ndarray


def _semi_axes(aspect) -> np.ndarray:
    a = np.asarray(aspect, dtype=np.float64)
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


def core(p: Params, rng: np.random.Generator) -> Core:
    """Draw the convex core (facet planes) and its rounding geometry.

    The draws (the normals) come first from ``rng``; :func:`build` then draws
    the dents and the roughness field from the same generator.

    Examples
    --------
    >>> c = core(Params(facets=12, rounding=0.2), np.random.default_rng(0))
    >>> c.normals.shape, round(c.rho, 3) > 0
    ((12, 3), True)
    """
    n = _draw_normals(p.facets, rng)
    ax = _semi_axes(p.aspect)
    h = np.linalg.norm(n * ax, axis=1)
    rho = float(p.rounding * ax.min())
    if rho > 0.0:
        from scipy.spatial import ConvexHull, HalfspaceIntersection

        hs = HalfspaceIntersection(np.column_stack([n, -(h - rho)]), np.zeros(3))
        verts = np.asarray(hs.intersections, dtype=np.float64)
        tri = ConvexHull(verts).simplices
        e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        edges = np.unique(e, axis=0)
    else:
        verts = np.zeros((0, 3))
        edges = np.zeros((0, 2), dtype=np.int64)
    return Core(n, h, rho, verts, edges, ax)


def core_edges(c: Core) -> list[tuple[np.ndarray, np.ndarray, float, int, int]]:
    """The true edges of the shrunk core (planes at h_i − ρ; the core itself when ρ = 0).

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
    from scipy.spatial import HalfspaceIntersection

    off = c.offsets - c.rho
    hs = HalfspaceIntersection(np.column_stack([c.normals, -off]), np.zeros(3))
    verts = np.asarray(hs.intersections)
    active = np.abs(verts @ c.normals.T - off) < 1e-9 * (1.0 + np.abs(off))
    out = []
    k = len(off)
    for i in range(k):
        for j in range(i + 1, k):
            on = np.flatnonzero(active[:, i] & active[:, j])
            if len(on) < 2:
                continue
            pts = verts[on]
            d = np.cross(c.normals[i], c.normals[j])
            d /= np.linalg.norm(d)
            s = pts @ d
            a, b = pts[np.argmin(s)], pts[np.argmax(s)]
            length = float(s.max() - s.min())
            if length > 1e-9:
                out.append(((a + b) / 2, d, length, i, j))
    return out


def _capsule_exit(unit: np.ndarray, c: Core) -> np.ndarray:
    """Largest exit distance of the rays t·u (t > 0) from the capsules of the shrunk core's edges."""
    rho2 = c.rho * c.rho
    V = c.vertices
    # corner spheres: |t u − v| = ρ, far root t = u·v + sqrt((u·v)² − |v|² + ρ²)
    b = unit @ V.T
    disc = b * b - (np.einsum("ij,ij->i", V, V) - rho2)
    best = np.where(disc >= 0.0, b + np.sqrt(np.maximum(disc, 0.0)), -np.inf).max(axis=1)
    # edge cylinders, kept where the exit point projects inside the segment
    a = V[c.edges[:, 0]]
    d = V[c.edges[:, 1]] - a
    length = np.linalg.norm(d, axis=1)
    keep = length > 1e-12
    a, d, length = a[keep], d[keep] / length[keep, None], length[keep]
    ad = np.einsum("ij,ij->i", a, d)
    ud = unit @ d.T
    ua = unit @ a.T
    q = 1.0 - ud * ud  # |u⊥|²
    B = ua - ud * ad  # u⊥·a⊥
    C = np.einsum("ij,ij->i", a, a) - ad * ad - rho2  # |a⊥|² − ρ²
    disc = B * B - q * C
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (B + np.sqrt(np.maximum(disc, 0.0))) / q
        s = t * ud - ad
        ok = (disc >= 0.0) & (q > 1e-12) & (s >= 0.0) & (s <= length)
    best = np.maximum(best, np.where(ok, t, -np.inf).max(axis=1, initial=-np.inf))
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
    >>> c = Core(n, np.ones(6), 0.5, np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)]),
    ...          np.array([[0, 1], [0, 2], [0, 4], [1, 3], [1, 5], [2, 3], [2, 6], [3, 7], [4, 5], [4, 6], [5, 7], [6, 7]]),
    ...          np.ones(3))
    >>> r, flat = radius(np.array([[1.0, 0, 0], [1, 1, 1] / np.sqrt(3)]), c)
    >>> np.round(r, 6).tolist(), flat.tolist()
    ([1.0, 1.366025], [True, False])
    """
    cos = unit @ c.normals.T  # (V, k)
    with np.errstate(divide="ignore"):
        t = np.where(cos > 1e-12, c.offsets / np.where(cos > 1e-12, cos, 1.0), np.inf)
    i = np.argmin(t, axis=1)
    r_h = t[np.arange(len(unit)), i]
    if c.rho <= 0.0:
        return r_h, np.ones(len(unit), dtype=bool)
    # over the shrunk facet i: y = r_h u − ρ n_i satisfies n_j·y ≤ h_j − ρ for every j
    lhs = r_h[:, None] * cos - c.rho * (c.normals[i] @ c.normals.T)
    flat = np.all(lhs <= c.offsets - c.rho + 1e-9 * (1.0 + c.offsets), axis=1)
    r = r_h.copy()
    rounded = ~flat
    if rounded.any():
        r[rounded] = np.minimum(r_h[rounded], _capsule_exit(unit[rounded], c))
    return r, flat


def _dent_factor(unit: np.ndarray, p: Params, rng: np.random.Generator) -> np.ndarray:
    if p.dents == 0:
        return np.ones(len(unit))
    centres = rng.normal(size=(p.dents, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    g = np.exp((unit @ centres.T - 1.0) / (p.dent_width**2))
    # overlapping dents merge ("or"), they do not deepen: the factor stays in [1 − depth, 1]
    return 1.0 - p.dent_depth * (1.0 - np.prod(1.0 - g, axis=1))


def _roughness_factor(unit: np.ndarray, p: Params, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """1 + K·S(u): the FSO overlay (fso.draw_field / wm_sum), RMS ``roughness`` on the level-3 sphere."""
    from . import fso

    fp = fso.Params(fractal_dimension=p.fractal_dimension, length_ratio=p.length_ratio, amplitude=p.roughness)
    f = fso.draw_field(fp, rng)
    if p.roughness == 0.0:
        return np.ones(len(unit)), 0.0
    S = fso.wm_sum(unit, f)
    ref, _ = icosphere(fso.REFERENCE_SUBDIVISIONS)
    nref = len(ref)
    S_ref = S[:nref] if len(unit) >= nref and np.array_equal(unit[:nref], ref) else fso.wm_sum(ref, f)
    rms = float(np.sqrt(np.mean(S_ref**2)))
    K = p.roughness / rms if rms > 0 else 0.0
    return 1.0 + K * S, K


def build(p: Params, rng: np.random.Generator):
    """Vertices, faces and info of one angular grain (R0 = 1, not yet centred)."""
    unit, faces = icosphere(p.subdivisions)
    c = core(p, rng)
    r, flat = radius(unit, c)
    r = r * _dent_factor(unit, p, rng)
    rough, _ = _roughness_factor(unit, p, rng)
    r = r * rough
    rmin = float(r.min())
    if rmin <= MIN_RADIUS:
        raise ParameterError(
            "roughness",
            f"{p.roughness} is too large for this grain: the smallest radius would be {rmin:.3f}·R0 "
            f"(must stay above {MIN_RADIUS}·R0 for a star-shaped solid); lower it (or the dents)",
        )
    info = {"rounding_radius": c.rho, "flat_fraction": float(flat.mean()), "min_radius": rmin,
            "max_radius": float(r.max())}
    return unit * r[:, None], np.array(faces), info


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
    subdivisions: int = 5,
    rng=None,
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
        Relative depth (0–0.5) and angular width in radians (0.1–1.2) of each dent.
    roughness : float
        RMS of the FSO overlay relative to the radius, 0–0.3 (0 = smooth facets).
    fractal_dimension, length_ratio : float
        D and L/R0 of the FSO overlay.
    subdivisions : int
        Icosphere level 0–8 (default 5: 10,242 vertices).
    rng : None, int or numpy.random.Generator
        Seed or generator.

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
        length_ratio=length_ratio, subdivisions=subdivisions,
    )
    return generate(NAME, p, rng)
