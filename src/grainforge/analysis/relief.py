"""Where on a grain its relief sits: radii along arbitrary rays, mirror correlation, cap/band RMS.

Measuring tools for the seam checks of FSO grains (docs/validation.md §4).
They work on any closed mesh, knowing nothing of how it was made:

* :func:`radii_along` — distance from a centre to the farthest crossing of
  the surface along each ray (trimesh's ray casting; slow, used as a check);
* :func:`small_scale_relief` — r − G_σ∗r at the vertices: the radius minus its
  Gaussian average over angular distance σ (default 0.05 rad), a high-pass
  that keeps the relief finer than about 2σ;
* :func:`interpolate_at` — vertex values at any direction, linearly on the
  face that the ray from the centre crosses (for a mesh star-shaped about the
  centre, exactly where the ray meets the surface);
* :func:`mirror_correlation` — the correlation, over the azimuth, of the
  small-scale relief at polar angles φ0 − δ and φ0 + δ (a mirror seam at φ0
  makes it ≈ 1 for every δ; an isotropic surface gives the same value about
  every φ0);
* :func:`separable_share` — the share of the small-scale relief explained by
  a separable pattern f(θ) + g(ψ) in angles about the x axis (parallel
  ridges around x and along meridians through x make it large);
* :func:`cap_band_rms` — RMS of the relief r/r̄ − 1 in the two polar caps and
  in an equatorial band.

Polar angles are measured from +z of the mesh's own frame, with the volume
centroid as the centre.
"""

from __future__ import annotations

import numpy as np

from ..geometry.solid import volume_centroid
from .fractal import radial_function

__all__ = ["radii_along", "vertex_areas", "small_scale_relief", "interpolate_at", "mirror_correlation", "cap_band_rms", "ring", "separable_share"]


def vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """One third of the area of the faces around each vertex.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    (V,) float64
        In the square of the vertices' unit; they sum to the surface area.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    t = v[f]
    area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1) / 2.0
    return np.bincount(f.ravel(), np.repeat(area / 3.0, 3), minlength=len(v))


def radii_along(vertices: np.ndarray, faces: np.ndarray, directions: np.ndarray, centre=None) -> np.ndarray:
    """Distance from ``centre`` (default: volume centroid) to the farthest crossing along each ray.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    directions : (N, 3) array_like of float
        Ray directions (normalised here).
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    (N,) float64
        In the vertices' unit; NaN where a ray meets nothing.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(4)
    >>> r = radii_along(s.vertices, s.faces, np.eye(3))
    >>> bool(np.allclose(r, 1.0, atol=2e-3))
    True
    """
    import trimesh

    v = np.asarray(vertices, dtype=np.float64)
    c = volume_centroid(v, np.asarray(faces)) if centre is None else np.asarray(centre, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    from trimesh.ray.ray_triangle import RayMeshIntersector

    mesh = trimesh.Trimesh(v, faces, process=False)
    # trimesh's float64 intersector whatever else is installed (``mesh.ray`` would be Embree's, in float32)
    loc, ray, _ = RayMeshIntersector(mesh).intersects_location(np.broadcast_to(c, d.shape), d, multiple_hits=True)
    out = np.full(len(d), np.nan)
    np.fmax.at(out, ray, np.linalg.norm(loc - c, axis=1))
    return out


def small_scale_relief(vertices, faces, sigma: float = 0.05, centre=None) -> np.ndarray:
    """r − G_σ∗r at each vertex, relative to the mean radius (r from the volume centroid).

    G_σ∗r is the area-weighted Gaussian average of r over the vertices within
    3σ of angular distance, weight exp(−δ²/2σ²).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    sigma : float, default 0.05
        Smoothing width, radians of angular distance.
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    (V,) float64
        Dimensionless (relative to the area-weighted mean radius).
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    c = volume_centroid(v, np.asarray(faces)) if centre is None else np.asarray(centre, dtype=np.float64)
    u, r = radial_function(v, c)
    w = vertex_areas(v, faces)
    tree = cKDTree(u)
    chord = 2.0 * np.sin(1.5 * sigma)
    pairs = tree.query_pairs(chord, output_type="ndarray")
    i = np.r_[pairs[:, 0], pairs[:, 1], np.arange(len(u))]
    j = np.r_[pairs[:, 1], pairs[:, 0], np.arange(len(u))]
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", u[i], u[j]), -1.0, 1.0))
    k = w[j] * np.exp(-0.5 * (ang / sigma) ** 2)
    smooth = np.bincount(i, k * r[j], minlength=len(u)) / np.bincount(i, k, minlength=len(u))
    return (r - smooth) / np.average(r, weights=w)


def interpolate_at(vertices, faces, *, values, directions, centre=None) -> np.ndarray:
    """``values`` (per vertex) at ``directions``: barycentric on the face the ray from ``centre`` crosses.

    Candidate faces are the 16 whose centre directions are nearest; the first
    whose cone (spanned by its vertex directions) contains the ray is used.
    NaN where none does (a mesh not star-shaped about the centre).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    values : (V,) array_like of float
        One value per vertex.
    directions : (N, 3) array_like of float
        Ray directions (normalised here).
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    (N,) float64

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> x = interpolate_at(s.vertices, s.faces, values=s.vertices[:, 0], directions=[[1.0, 0.2, 0.1]])
    >>> bool(abs(x[0] - 1 / np.sqrt(1.05)) < 0.01)
    True
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    c = volume_centroid(v, f) if centre is None else np.asarray(centre, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    p = v - c
    fc = p[f].mean(axis=1)
    fc /= np.linalg.norm(fc, axis=1, keepdims=True)
    _, cand = cKDTree(fc).query(d, k=min(16, len(f)))
    a, b, e = p[f[cand, 0]], p[f[cand, 1]], p[f[cand, 2]]  # (N, k, 3)
    dd = d[:, None, :]
    # barycentric weights of the ray's crossing with the face plane: signed volumes
    wa = np.einsum("nki,nki->nk", dd, np.cross(b, e))
    wb = np.einsum("nki,nki->nk", dd, np.cross(e, a))
    we = np.einsum("nki,nki->nk", dd, np.cross(a, b))
    tot = wa + wb + we
    inside = (wa >= -1e-12 * np.abs(tot)) & (wb >= -1e-12 * np.abs(tot)) & (we >= -1e-12 * np.abs(tot)) & (tot > 0)
    first = np.argmax(inside, axis=1)
    rows = np.arange(len(d))
    ok = inside[rows, first]
    fi = f[cand[rows, first]]
    vals = np.asarray(values, dtype=np.float64)
    W = np.stack([wa[rows, first], wb[rows, first], we[rows, first]], axis=1) / tot[rows, first][:, None]
    out = (vals[fi] * W).sum(axis=1)
    out[~ok] = np.nan
    return out


def ring(polar: float, n: int = 720) -> np.ndarray:
    """``n`` unit vectors at polar angle ``polar`` (from +z), evenly spaced in azimuth.

    Parameters
    ----------
    polar : float
        Polar angle from +z, radians.
    n : int, default 720
        Number of vectors.

    Returns
    -------
    (n, 3) float64

    Examples
    --------
    >>> np.round(ring(np.pi / 2, 4), 12).tolist()[:2]
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    """
    t = 2.0 * np.pi * np.arange(n) / n
    s = np.sin(polar)
    return np.column_stack([s * np.cos(t), s * np.sin(t), np.full(n, np.cos(polar))])


def mirror_correlation(vertices, faces, *, polar: float, deltas, n: int = 720, sigma: float = 0.05,
                       centre=None) -> np.ndarray:
    """Correlation over azimuth of the small-scale relief at ``polar − δ`` and ``polar + δ``, for each δ.

    Polar angles about +z from ``centre`` (default: the volume centroid).  A
    mirror seam lies in a plane through the point the surface was built
    around; pass that point (for FSO, the origin of ``fso.build``'s vertices,
    before the grain is centred) to find it at small δ.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    polar : float
        The circle of the suspected mirror plane, radians from +z (π/2: the equator).
    deltas : float or sequence of float
        Offsets δ from it, radians.
    n : int, default 720
        Azimuths sampled.
    sigma : float, default 0.05
        Width of the relief's smoothing (:func:`small_scale_relief`), radians.
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    (len(deltas),) float64
        Pearson correlations, in [−1, 1].

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(5)
    >>> z = s.vertices[:, 2:]
    >>> v = s.vertices * (1 + 0.02 * np.cos(40 * z ** 2) * np.cos(20 * s.vertices[:, :1]))  # even in z
    >>> float(mirror_correlation(v, s.faces, polar=np.pi / 2, deltas=[0.1], n=360)[0]) > 0.95
    True
    """
    deltas = np.atleast_1d(np.asarray(deltas, dtype=np.float64))
    v = np.asarray(vertices, dtype=np.float64)
    c = volume_centroid(v, np.asarray(faces)) if centre is None else np.asarray(centre, dtype=np.float64)
    h = small_scale_relief(v, faces, sigma, centre=c)
    dirs = np.vstack([ring(polar + s * d, n) for d in deltas for s in (-1.0, 1.0)])
    x = interpolate_at(v, faces, values=h, directions=dirs, centre=c).reshape(len(deltas), 2, n)
    return np.array([np.corrcoef(a, b)[0, 1] for a, b in x])


def cap_band_rms(vertices, faces, *, cap: float = 0.3, band: float = 0.15, centre=None) -> tuple[float, float]:
    """Area-weighted RMS of r/r̄ − 1 at vertices within ``cap`` rad of either pole, and within
    ``band`` rad of the equator (r̄: area-weighted mean radius; angles from ``centre``, default
    the volume centroid).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    cap : float, default 0.3
        Half-angle of the polar caps, radians.
    band : float, default 0.15
        Half-width of the equatorial band, radians.
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    caps, band : float
        Dimensionless RMS values.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(3)
    >>> [round(x, 9) for x in cap_band_rms(s.vertices, s.faces)]
    [0.0, 0.0]
    """
    v = np.asarray(vertices, dtype=np.float64)
    c = volume_centroid(v, np.asarray(faces)) if centre is None else np.asarray(centre, dtype=np.float64)
    u, r = radial_function(v, c)
    w = vertex_areas(v, faces)
    rel = r / np.average(r, weights=w) - 1.0
    polar = np.arccos(np.clip(u[:, 2], -1.0, 1.0))
    caps = (polar < cap) | (polar > np.pi - cap)
    eq = np.abs(polar - np.pi / 2) < band
    rms = [float(np.sqrt(np.average(rel[m] ** 2, weights=w[m]))) for m in (caps, eq)]
    return rms[0], rms[1]


def separable_share(vertices, faces, *, sigma: float = 0.1, n_theta: int = 64, n_psi: int = 128,
                    centre=None) -> float:
    """Share of the variance of the small-scale relief explained by f(θ) + g(ψ).

    θ = angle from +x, ψ = azimuth about x, from ``centre`` (default the
    volume centroid); θ ∈ [0.35, π − 0.35] avoids the x poles.  The relief is
    r − G_σ∗r (:func:`small_scale_relief`) interpolated on the mesh at a
    regular (θ, ψ) grid; f and g are its row and column means.  An isotropic
    surface gives a small share (the row and column means of a finite grid
    are never exactly zero); relief made of rings about x plus meridional
    ridges gives a large one.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.
    sigma : float, default 0.1
        Width of the relief's smoothing, radians.
    n_theta, n_psi : int, default 64, 128
        Grid size in θ and ψ.
    centre : (3,) array_like of float, optional
        Where the radii and angles are measured from (default: the volume centroid).

    Returns
    -------
    float
        1 − var(residual)/var(relief), in [0, 1].
    """
    v = np.asarray(vertices, dtype=np.float64)
    c = volume_centroid(v, np.asarray(faces)) if centre is None else np.asarray(centre, dtype=np.float64)
    h = small_scale_relief(v, faces, sigma, centre=c)
    t = np.linspace(0.35, np.pi - 0.35, n_theta)
    p = 2 * np.pi * np.arange(n_psi) / n_psi
    T, P = np.meshgrid(t, p, indexing="ij")
    d = np.column_stack([np.cos(T).ravel(), (np.sin(T) * np.cos(P)).ravel(), (np.sin(T) * np.sin(P)).ravel()])
    H = interpolate_at(v, faces, values=h, directions=d, centre=c).reshape(n_theta, n_psi)
    H = H - H.mean()
    fit = H.mean(axis=1, keepdims=True) + H.mean(axis=0, keepdims=True)
    return float(1.0 - np.var(H - fit) / np.var(H))
