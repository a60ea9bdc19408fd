"""Fourier descriptors of planar sections of a closed mesh: one core, two outline conventions.

A plane cuts the mesh in an outline; its radii are taken along ``n_rays``
rays θ_j = 2πj/n_rays from the outline's area centroid (outermost crossing,
as for silhouettes: :mod:`grainforge.analysis.fourier`,
docs/design/algorithms.md §2b) and D_n = 2|c_n|/c_0.  :func:`section_radii`
is the one implementation; its ``outline`` parameter says which outline:

``"segments"``
    Every segment where the plane cuts the mesh
    (``trimesh.intersections.mesh_plane``), taken together: the radius is the
    outermost crossing of any of them, the area centroid that of the radius
    function.  Any plane, any orientation (:func:`random_normals`).
``"loop"``
    The largest closed loop of the section (trimesh ``section``), as a
    polygon (:func:`grainforge.outline.contours.polygon_contour`: shoelace centroid),
    the plane nudged off the mesh's vertices when they leave the loop in
    pieces.  What a thin section shows.

:func:`principal_section_descriptors` cuts through the volume centroid
perpendicular to the principal axes of inertia with ``"loop"`` outlines.
Used to check what the generators put into the grains (``docs/validation.md``).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, as_generator
from .fourier import FD_ORDERS, N_RAYS, _outline_radii, _polygon_area_centroid_of_radii, descriptors_from_radii

__all__ = ["plane_basis", "section_radii", "section_descriptors", "principal_section_descriptors",
           "random_normals", "OUTLINES"]

#: the outline conventions of :func:`section_radii`
OUTLINES = ("segments", "loop")

#: rays used to find the outline's area centroid
CENTROID_RAYS = 1024


def plane_basis(normal) -> np.ndarray:
    """Two orthonormal in-plane axes (rows) for a plane with ``normal`` (right-handed with it).

    Parameters
    ----------
    normal : (3,) array_like of float
        The plane's normal (any non-zero length).

    Returns
    -------
    (2, 3) float64
        e1, e2 with e1 × e2 along the normal.

    Examples
    --------
    >>> plane_basis((0.0, 0.0, 1.0)).round(12).tolist()
    [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    return np.stack([e1, e2])


def _trimesh(mesh):
    import trimesh

    if isinstance(mesh, trimesh.Trimesh):
        return mesh
    return trimesh.Trimesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64),
                           process=False)


def section_radii(mesh, normal, *, origin=None, n_rays: int = N_RAYS, outline: str = "segments",
                  basis=None) -> tuple[np.ndarray, np.ndarray]:
    """Radii of the section through ``origin`` with ``normal``, from the outline's area centroid.

    Parameters
    ----------
    mesh : trimesh.Trimesh, Grain or anything with ``vertices`` and ``faces``
    normal : (3,) float
    origin : (3,) float, optional
        A point of the plane (default: the volume centroid of the mesh; pass
        it when cutting one mesh many times).
    n_rays : int
    outline : {"segments", "loop"}
        Which outline (module docstring).
    basis : (2, 3) float, optional
        The in-plane axes the angles are measured in (default
        :func:`plane_basis`).

    Returns
    -------
    r : (n_rays,) float64
        Outermost crossing along θ_j = 2πj/n_rays, measured in ``basis``.
    centre : (3,) float64
        The outline's area centroid (the rays' origin) in 3D.

    Raises
    ------
    ValueError
        If the plane misses the mesh or the outline does not surround its centroid.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box((2.0, 2.0, 2.0))
    >>> [np.round(section_radii(box, (0, 0, 1), n_rays=8, outline=o)[0][:2], 6).tolist() for o in OUTLINES]
    [[1.0, 1.414214], [1.0, 1.414214]]
    """
    if outline not in OUTLINES:
        raise InputError(f"outline must be one of {', '.join(OUTLINES)}, got {outline!r}")
    mesh = _trimesh(mesh)
    o = np.asarray(mesh.center_mass if origin is None else origin, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    basis = plane_basis(n) if basis is None else np.asarray(basis, dtype=np.float64)
    if outline == "loop":
        c = _loop_contour(mesh, n, o, basis, n_rays)
        return c.radii * c.scale, o + np.asarray(c.centroid) @ basis
    from trimesh.intersections import mesh_plane

    seg = mesh_plane(mesh, n, o)
    if len(seg) == 0:
        raise InputError("the plane does not cut the mesh")
    q = (seg.reshape(-1, 3) - o) @ basis.T
    edges = np.arange(len(q)).reshape(-1, 2)
    r, _ = _outline_radii(q, edges, CENTROID_RAYS)
    if not np.isfinite(r).all():
        raise InputError("the section does not surround the plane's origin")
    c = _polygon_area_centroid_of_radii(r, np.zeros(2))
    r, _ = _outline_radii(q - c, edges, n_rays)
    if not np.isfinite(r).all():
        raise InputError("the section does not surround its area centroid")
    return r, o + c @ basis


def _loop_contour(mesh, normal, origin, basis, n_rays):
    """The largest closed loop of the section as a Contour (``"loop"`` outlines)."""
    from ..outline.contours import polygon_contour

    size = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
    unit = normal / np.linalg.norm(normal)
    # a plane through mesh vertices can leave the outline in pieces: nudge it off them
    for nudge in (0.0, 1e-7, -1e-7, 1e-5):
        sec = mesh.section(plane_origin=origin + nudge * size * unit, plane_normal=normal)
        if sec is None:
            continue
        pts = max((np.asarray(p) for p in sec.discrete), key=len) - origin
        try:
            return polygon_contour(pts @ basis.T, n_angles=n_rays, source="section")
        except ValueError:
            continue
    raise InputError("no closed outline around the centroid in the section")


def section_descriptors(mesh, normal, *, origin=None, orders=FD_ORDERS, n_rays: int = N_RAYS,
                        outline: str = "segments") -> np.ndarray:
    """D_n (for ``orders``) of the section through ``origin`` (default the volume centroid) with ``normal``.

    ``mesh``, ``outline`` as in :func:`section_radii`.

    Parameters
    ----------
    mesh : trimesh.Trimesh, Grain or anything with ``vertices`` and ``faces``
        A closed mesh.
    normal : (3,) array_like of float
        The plane's normal.
    origin : (3,) array_like of float, optional
        A point of the plane (default: the volume centroid).
    orders : sequence of int, default FD_ORDERS
        The orders n.
    n_rays : int, default N_RAYS
        Rays from the outline's area centroid.
    outline : {"segments", "loop"}, default "segments"
        As :func:`section_radii`.

    Returns
    -------
    (len(orders),) float64

    Raises
    ------
    ValueError
        As :func:`section_radii`.

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(5)
    >>> _ = e.apply_scale((2.0, 1.0, 1.0))
    >>> d = section_descriptors(e, (0, 0, 1), orders=(2, 3))
    >>> np.round(d, 3).tolist()  # a 2:1 ellipse: D2 = 0.338, D3 = 0
    [0.338, 0.0]
    """
    r, _ = section_radii(mesh, normal, origin=origin, n_rays=n_rays, outline=outline)
    return descriptors_from_radii(r, orders)


def principal_section_descriptors(mesh, orders=(2, 3, 8), n_rays: int = 256) -> np.ndarray:
    """(3, len(orders)) D_n of the sections through the volume centroid ⊥ the principal inertia axes.

    Rows: ⊥ the longest, the intermediate, the shortest axis; ``"loop"``
    outlines (what a thin section or a cut would show, measured with no
    knowledge of how the grain was made).

    Parameters
    ----------
    mesh : trimesh.Trimesh, Grain or anything with ``vertices`` and ``faces``
        A closed mesh.
    orders : sequence of int, default (2, 3, 8)
        The orders n.
    n_rays : int, default 256
        Rays per section.

    Returns
    -------
    (3, len(orders)) float64

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(4)
    >>> _ = e.apply_scale((3.0, 2.0, 1.0))
    >>> np.round(principal_section_descriptors(e, orders=(2,))[:, 0], 2).tolist()  # ellipses 2:1, 3:1, 3:2
    [0.34, 0.52, 0.2]
    """
    mesh = _trimesh(mesh)
    centre = np.asarray(mesh.center_mass, dtype=np.float64)
    _, vec = np.linalg.eigh(np.asarray(mesh.moment_inertia, dtype=np.float64))
    axes = vec.T  # smallest moment first: the longest axis
    rows = []
    for k in range(3):
        r, _ = section_radii(mesh, axes[k], origin=centre, n_rays=n_rays, outline="loop",
                             basis=np.stack([axes[(k + 1) % 3], axes[(k + 2) % 3]]))
        rows.append(descriptors_from_radii(r, orders))
    return np.array(rows)


def random_normals(count: int, rng: RNGLike = None) -> np.ndarray:
    """``count`` unit vectors uniform on the sphere (normalised Gaussian triples).

    Parameters
    ----------
    count : int
        Number of vectors.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Normalised by :func:`grainforge.rng.as_generator`; 3·count normal draws.

    Returns
    -------
    (count, 3) float64

    Examples
    --------
    >>> n = random_normals(4, rng=0)
    >>> n.shape, np.allclose(np.linalg.norm(n, axis=1), 1.0)
    ((4, 3), True)
    """
    g = as_generator(rng).standard_normal((int(count), 3))
    return g / np.linalg.norm(g, axis=1, keepdims=True)
