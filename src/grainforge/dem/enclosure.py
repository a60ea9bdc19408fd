"""Whether a mesh encloses one solid with a well-defined inside (shared by :mod:`.inputs` and
:mod:`.template`; a module of its own so that neither imports the other for it)."""

from __future__ import annotations

import numpy as np

__all__ = ["enclosure_problems"]


def enclosure_problems(vertices: np.ndarray, faces: np.ndarray) -> list[str]:
    """What stops a mesh from enclosing one solid with a well-defined inside (empty if nothing).

    Weaker than :func:`grainforge.geometry.solid.solid_problems` in one respect only:
    an edge may be shared by four faces (two touching cubes of a DPA
    aggregate, once coincident vertices are merged), as long as every directed
    edge is matched by as many reverse edges. The winding number — hence the
    inside, the volume integrals and the voxelisation used here — is then
    well defined. Open boundaries, inconsistent orientation, degenerate
    faces, several bodies and non-positive volume are refused.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex coordinates (any length unit), coincident vertices merged.
    faces : (F, 3) array_like of int
        Triangles as vertex indices, counter-clockwise seen from outside.

    Returns
    -------
    list of str
        The first problem found, as one short phrase (empty list: the mesh encloses one solid).

    Examples
    --------
    >>> import trimesh
    >>> b = trimesh.creation.box()
    >>> enclosure_problems(b.vertices, b.faces)
    []
    >>> enclosure_problems(b.vertices, b.faces[:-1])
    ['open boundary or inconsistent orientation']
    """
    from ..geometry.solid import _directed_edges, face_components, signed_volume

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0 or len(v) == 0:
        return ["empty mesh"]
    if not np.isfinite(v).all():
        return ["non-finite vertex coordinates"]
    if f.min() < 0 or f.max() >= len(v):
        return ["face index out of range"]
    if ((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])).any():
        return ["degenerate faces (repeated vertex)"]
    directed, reverse = _directed_edges(f, len(v))
    if not np.array_equal(directed, reverse):
        return ["open boundary or inconsistent orientation"]
    bodies = len(np.unique(face_components(f, len(v))))
    if bodies != 1:
        return [f"{bodies} separate bodies"]
    if not signed_volume(v, f) > 0:
        return ["non-positive volume (inward orientation)"]
    return []
