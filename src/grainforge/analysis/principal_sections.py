"""Planar sections of a grain through its volume centroid, perpendicular to its principal axes.

What a thin section (or a cut) of the grain would show, measured with no
knowledge of how the grain was made: the mesh is cut by the three planes
through its volume centroid perpendicular to the principal axes of its
inertia tensor (trimesh ``section``), and each section's outline is described
by its radius function about its own area centroid
(:func:`grainforge.contours.polygon_contour`, docs/design/algorithms.md §2b), giving
D_n = 2|c_n|/c_0.
"""

from __future__ import annotations

import numpy as np

__all__ = ["inertia_sections", "section_descriptors"]


def inertia_sections(mesh, n_angles: int = 256):
    """The three sections (⊥ longest, ⊥ intermediate, ⊥ shortest axis) as Contours.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed mesh with positive volume.
    n_angles : int
        Rays per outline.

    Returns
    -------
    list of grainforge.contours.Contour
        The largest closed loop of each section, about its own area centroid.

    Examples
    --------
    >>> import trimesh
    >>> e = trimesh.creation.icosphere(4)
    >>> _ = e.apply_scale((3.0, 2.0, 1.0))
    >>> [round(float(c.descriptors(2)[2]), 2) for c in inertia_sections(e)]  # ellipses 2:1, 3:1, 3:2
    [0.34, 0.52, 0.2]
    """
    from ..contours import polygon_contour

    centre = np.asarray(mesh.center_mass, dtype=np.float64)
    _, vec = np.linalg.eigh(np.asarray(mesh.moment_inertia, dtype=np.float64))
    axes = vec.T  # smallest moment first: the longest axis
    size = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
    out = []
    for k in range(3):
        e1, e2 = axes[(k + 1) % 3], axes[(k + 2) % 3]
        # a plane through mesh vertices can leave the outline in pieces: nudge it off them
        for nudge in (0.0, 1e-7, -1e-7, 1e-5):
            sec = mesh.section(plane_origin=centre + nudge * size * axes[k], plane_normal=axes[k])
            if sec is None:
                continue
            pts = max((np.asarray(p) for p in sec.discrete), key=len) - centre
            try:
                out.append(polygon_contour(np.column_stack([pts @ e1, pts @ e2]), n_angles=n_angles,
                                           source="section"))
                break
            except ValueError:
                continue
        else:
            raise ValueError("no closed outline around the centroid in the section through the volume centroid")
    return out


def section_descriptors(mesh, orders=(2, 3, 8), n_angles: int = 256) -> np.ndarray:
    """(3, len(orders)) Fourier descriptors of :func:`inertia_sections`."""
    from ..contours import descriptors_of_radii

    D = np.array([descriptors_of_radii(c.radii) for c in inertia_sections(mesh, n_angles)])
    return D[:, list(orders)]
