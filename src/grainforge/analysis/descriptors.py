"""3D shape descriptors (docs/design/algorithms.md §4).

:func:`basic_descriptors` gives the columns every manifest carries;
:func:`describe` gives everything ``grainforge analyse`` reports: size and
form (volume, area, d_eq, Wadell sphericity, convexity, L ≥ I ≥ S from the
minimum-volume box and from the principal axes, Zingg ratios, Krumbein
intercept sphericity), texture (roughness and a surface fractal dimension,
:mod:`grainforge.analysis.fractal`), outline (Fourier descriptors of the
three principal projections, :mod:`grainforge.analysis.fourier`) and, for
aggregates, porosity, radius of gyration and the aggregate dimension D_A.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..geometry.moments import sphere_diameter
from ..geometry.solid import is_closed
from .mass import mesh_moments

__all__ = [
    "basic_descriptors", "principal_dimensions", "describe", "BASIC_COLUMNS", "DESCRIPTOR_COLUMNS",
    "mesh_moments", "is_closed",
]

#: the measured columns every manifest carries, in order.
BASIC_COLUMNS = (
    "volume", "surface_area", "equivalent_diameter", "sphericity", "convexity", "L", "I", "S",
)

#: every scalar column of :func:`describe` except the Fourier descriptors, in order.
DESCRIPTOR_COLUMNS = BASIC_COLUMNS + (
    "L_pca", "I_pca", "S_pca", "elongation", "flatness", "krumbein_sphericity",
    "roughness", "fractal_dimension", "porosity", "radius_of_gyration", "aggregate_dimension",
    "closed",
)


def _arrays(obj) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 faces of a Grain, trimesh or anything with both."""
    return np.asarray(obj.vertices, dtype=np.float64), np.asarray(obj.faces, dtype=np.int64)


def principal_dimensions(obj) -> tuple[float, float, float]:
    """L ≥ I ≥ S: edges of the minimum-volume oriented bounding box.

    Uses :func:`grainforge.analysis.box.minimum_box`: the smallest box with a
    face flush with the convex hull, exact over every hull-face direction
    (the classical search for the 3D minimum-volume box, an upper bound on it).

    Parameters
    ----------
    obj : Grain, trimesh.Trimesh or anything with ``vertices`` and ``faces``
        The mesh.

    Returns
    -------
    L, I, S : float
        In the mesh's unit, L ≥ I ≥ S.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box(extents=(3.0, 1.0, 2.0))
    >>> [round(x, 6) for x in principal_dimensions(box)]
    [3.0, 2.0, 1.0]
    """
    v, _ = _arrays(obj)
    return _box_dimensions(v, _hull(v))


def _hull(v: np.ndarray):
    """scipy ConvexHull of the points, or None for degenerate (flat, too few) point sets."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        return ConvexHull(v)
    except QhullError:
        return None


def _box_dimensions(v: np.ndarray, hull) -> tuple[float, float, float]:
    """L ≥ I ≥ S of the minimum-volume box (:func:`grainforge.analysis.box.minimum_box`)."""
    from .box import minimum_box

    L, I, S = (float(e) for e in minimum_box(v, hull)[0])
    return L, I, S


def basic_descriptors(obj) -> dict[str, float]:
    """Volume, area, equivalent diameter, Wadell sphericity, convexity and L, I, S.

    Parameters
    ----------
    obj : Grain or trimesh.Trimesh
        A closed mesh, in whatever units it carries.

    Returns
    -------
    dict
        Keys as in :data:`BASIC_COLUMNS`.  Sphericity is Wadell's
        π^(1/3)(6V)^(2/3)/A (sphere 1, cube 0.806); convexity is V/V_hull.

    Examples
    --------
    >>> import trimesh
    >>> d = basic_descriptors(trimesh.creation.box(extents=(1, 1, 1)))
    >>> round(d["sphericity"], 3), round(d["convexity"], 3)
    (0.806, 1.0)
    """
    v, f = _arrays(obj)
    return _basic(v, mesh_moments(v, f), _hull(v))


def _basic(v: np.ndarray, mp: dict, hull) -> dict[str, float]:
    """The :data:`BASIC_COLUMNS` from the mass properties and the convex hull (None if degenerate)."""
    V, A = mp["volume"], mp["area"]
    d_eq = float(sphere_diameter(V)) if V > 0 else 0.0
    sph = float(np.pi ** (1 / 3) * (6 * V) ** (2 / 3) / A) if V > 0 and A > 0 else 0.0
    hull_v = float(hull.volume) if hull is not None else 0.0
    L, I, S = _box_dimensions(v, hull)
    return {
        "volume": V, "surface_area": A, "equivalent_diameter": d_eq, "sphericity": sph,
        "convexity": V / hull_v if hull_v > 0 else 0.0, "L": L, "I": I, "S": S,
    }


def describe(
    obj, *, fractal: bool = True, fourier: bool = True, primary_volume: float | None = None,
    closed: bool | None = None,
) -> dict[str, float]:
    """Every descriptor of one body (docs/design/algorithms.md §4).

    Parameters
    ----------
    obj : Grain or trimesh.Trimesh
        One body.  If it is not closed (``closed`` = 0 in the result), the
        volume-based values describe the mesh as if it were and should be
        read with care.
    fractal : bool
        Compute the surface fractal dimension (the slowest step).
    fourier : bool
        Compute the principal-projection Fourier descriptors.
    primary_volume : float, optional
        Volume V_p of an aggregate's primary particle; with it the aggregate
        dimension D_A = log(V/V_p) / log(Ā/a) of paper Eq. 5 is reported, Ā
        the mean edge of the minimum-volume box and a = V_p^(1/3) the primary
        size (docs/design/algorithms.md §3, the convention of
        ``grainforge.analysis.aggregate``).  NaN when V ≤ V_p or Ā ≤ a.
    closed : bool, optional
        Whether the body is closed (:func:`is_closed`), if the caller already
        knows; found here otherwise.

    Returns
    -------
    dict
        :data:`DESCRIPTOR_COLUMNS` (``aggregate_dimension`` NaN without a
        primary volume, ``fractal_dimension`` NaN if not computed or not
        measurable) followed by the Fourier columns of
        :func:`~grainforge.analysis.fourier.fd_columns` and ``fd_star_shaped``.

    Examples
    --------
    >>> import trimesh
    >>> d = describe(trimesh.creation.box(extents=(4, 2, 1)), fractal=False, fourier=False)
    >>> d["L"], d["I"], d["S"], d["elongation"], d["flatness"]
    (4.0, 2.0, 1.0, 0.5, 0.5)
    >>> round(d["krumbein_sphericity"], 4)  # (I·S/L²)^(1/3)
    0.5
    """
    from . import fourier as fourier_mod
    from .fractal import fractal_dimension, radial_function, roughness, smooth_fit

    v, f = _arrays(obj)
    if len(f) == 0:
        raise InputError("the mesh holds no triangles")
    if closed is None:
        closed = is_closed(f, len(v))
    mp = mesh_moments(v, f)
    hull = _hull(v)
    out: dict[str, float] = _basic(v, mp, hull)
    L, I, S = out["L"], out["I"], out["S"]
    centre, axes = fourier_mod.principal_axes(v, f, mp)
    proj = np.einsum("vi,ji->vj", v - centre, axes)
    Lp, Ip, Sp = sorted(proj.max(0) - proj.min(0), reverse=True)
    out.update({"L_pca": float(Lp), "I_pca": float(Ip), "S_pca": float(Sp)})
    out["elongation"] = I / L if L > 0 else 0.0
    out["flatness"] = S / I if I > 0 else 0.0
    out["krumbein_sphericity"] = float(np.cbrt(I * S / L**2)) if L > 0 else 0.0
    # radial function about the volume centroid, area weights per vertex
    u, r = radial_function(v, mp["centroid"])
    wv = np.bincount(f.ravel(), np.repeat(mp["face_areas"] / 3.0, 3), minlength=len(v))
    used = wv > 0
    fit = smooth_fit(u[used], r[used], wv[used])
    res = r[used] - fit
    rbar = float(np.sum(wv[used] * r[used]) / np.sum(wv[used]))
    out["roughness"] = roughness(res, wv[used], rbar) if rbar > 0 else 0.0
    if fractal:
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
        edge_angle = float(np.median(np.arccos(np.clip((u[e[:, 0]] * u[e[:, 1]]).sum(1), -1, 1))))
        out["fractal_dimension"] = fractal_dimension(u[used], res / rbar, edge_angle)
    else:
        out["fractal_dimension"] = float("nan")
    hull_v = float(hull.volume) if hull is not None else 0.0
    out["porosity"] = 1.0 - mp["volume"] / hull_v if hull_v > 0 else 0.0
    out["radius_of_gyration"] = float(np.sqrt(max(np.trace(mp["covariance"]), 0.0)))
    if primary_volume is not None:
        if not primary_volume > 0:
            raise InputError(f"primary_volume must be positive, got {primary_volume!r}")
        Vn = mp["volume"] / primary_volume
        An = (L + I + S) / 3.0 / np.cbrt(primary_volume)
        out["aggregate_dimension"] = float(np.log(Vn) / np.log(An)) if Vn > 1 and An > 1 else float("nan")
    else:
        out["aggregate_dimension"] = float("nan")
    out["closed"] = 1.0 if closed else 0.0
    if fourier:
        try:
            out.update(fourier_mod.projection_descriptors(
                v, f, axes=(centre, axes), closed=closed and mp["volume"] > 0
            ))
        except ValueError:
            out.update({c: float("nan") for c in fourier_mod.fd_columns()})
            out["fd_star_shaped"] = 0.0
    return out
