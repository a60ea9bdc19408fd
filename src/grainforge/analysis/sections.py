"""Fourier descriptors of planar sections of a closed mesh.

A plane through a point (by default the volume centroid) cuts the mesh in a
closed outline (``trimesh.intersections.mesh_plane``); as for silhouettes
(:mod:`grainforge.analysis.fourier`, docs/design/algorithms.md §2b) the outline's radii
are taken along ``n_rays`` rays from its area centroid (outermost crossing)
and D_n = 2|c_n|/c_0.  Used to check what the generators put into the
grains (``docs/validation.md``): any orientation (:func:`random_normals`)
or perpendicular to chosen axes.
"""

from __future__ import annotations

import numpy as np

from .fourier import FD_ORDERS, N_RAYS, _outline_radii, _polygon_area_centroid_of_radii, descriptors_from_radii

__all__ = ["plane_basis", "section_radii", "section_descriptors", "random_normals"]

#: rays used to find the outline's area centroid
CENTROID_RAYS = 1024


def plane_basis(normal) -> np.ndarray:
    """Two orthonormal in-plane axes (rows) for a plane with ``normal`` (right-handed with it).

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


def section_radii(mesh, normal, origin=None, n_rays: int = N_RAYS) -> tuple[np.ndarray, np.ndarray]:
    """Radii of the section through ``origin`` with ``normal``, from the outline's area centroid.

    Parameters
    ----------
    mesh : trimesh.Trimesh, Grain or anything with ``vertices`` and ``faces``
    normal : (3,) float
    origin : (3,) float, optional
        A point of the plane (default: the volume centroid of the mesh; pass
        it when cutting one mesh many times).
    n_rays : int

    Returns
    -------
    r : (n_rays,) float64
        Outermost crossing along θ_j = 2πj/n_rays, measured in ``plane_basis(normal)``.
    centre : (3,) float64
        The outline's area centroid (the rays' origin) in 3D.

    Raises
    ------
    ValueError
        If the plane misses the mesh or the outline does not surround its centroid.
    """
    from trimesh.intersections import mesh_plane

    mesh = _trimesh(mesh)
    o = np.asarray(mesh.center_mass if origin is None else origin, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    seg = mesh_plane(mesh, n, o)
    if len(seg) == 0:
        raise ValueError("the plane does not cut the mesh")
    basis = plane_basis(n)
    q = (seg.reshape(-1, 3) - o) @ basis.T
    edges = np.arange(len(q)).reshape(-1, 2)
    r, _ = _outline_radii(q, edges, CENTROID_RAYS)
    if not np.isfinite(r).all():
        raise ValueError("the section does not surround the plane's origin")
    c = _polygon_area_centroid_of_radii(r, np.zeros(2))
    r, _ = _outline_radii(q - c, edges, n_rays)
    if not np.isfinite(r).all():
        raise ValueError("the section does not surround its area centroid")
    return r, o + c @ basis


def section_descriptors(mesh, normal, origin=None, orders=FD_ORDERS, n_rays: int = N_RAYS) -> np.ndarray:
    """D_n (for ``orders``) of the section through ``origin`` (default the volume centroid) with ``normal``.

    ``mesh`` as in :func:`section_radii`.

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(5)
    >>> _ = e.apply_scale((2.0, 1.0, 1.0))
    >>> d = section_descriptors(e, (0, 0, 1), orders=(2, 3))
    >>> np.round(d, 3).tolist()  # a 2:1 ellipse: D2 = 0.338, D3 = 0
    [0.338, 0.0]
    """
    r, _ = section_radii(mesh, normal, origin, n_rays)
    return descriptors_from_radii(r, orders)


def random_normals(count: int, rng=None) -> np.ndarray:
    """``count`` unit vectors uniform on the sphere (normalised Gaussian triples).

    Examples
    --------
    >>> n = random_normals(4, rng=0)
    >>> n.shape, np.allclose(np.linalg.norm(n, axis=1), 1.0)
    ((4, 3), True)
    """
    g = np.random.default_rng(rng).standard_normal((int(count), 3))
    return g / np.linalg.norm(g, axis=1, keepdims=True)
