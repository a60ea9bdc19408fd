"""Signed distance field of a grain on a regular grid (a DEM level set)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry.voxel import Grid, grid_for, inside_mask

__all__ = ["LevelSet", "level_set", "surface_nodes", "DISTANCE_BLOCK", "MAX_NODES"]

#: the most grid nodes per exact-distance query
DISTANCE_BLOCK = 512
#: the most candidate triangles one exact-distance query may gather (about 250 bytes each in trimesh):
#: trimesh takes every triangle near a node's nearest vertex as a candidate, which is a few near the
#: surface and the whole mesh for the nodes of a coarse grid's margin, so the nodes are grouped by
#: their estimated candidates (twice the vertices within that distance) and the memory of the field stays
#: that of one bounded query, whatever the spacing
DISTANCE_CANDIDATES = 200_000
#: the most grid nodes a level set may have: ~1e6 nodes take ~60 MB of arrays and
#: minutes of exact distances; a finer grid is refused, naming the spacing
MAX_NODES = 1_000_000


@dataclass(frozen=True)
class LevelSet:
    """A signed distance field: negative inside, positive outside.

    Attributes
    ----------
    grid : Grid
        Node positions ``origin + (i, j, k) · spacing``.
    distance : (nx, ny, nz) float64
        Signed distance at the nodes (same length unit as the mesh).
    nodes : (S, 3) float64
        Points on the surface (mesh vertices spread over it), for engines that
        need surface nodes.
    """

    grid: Grid
    distance: np.ndarray
    nodes: np.ndarray


def surface_nodes(vertices: np.ndarray, faces: np.ndarray, count: int) -> np.ndarray:
    """``count`` points on the surface: the mesh vertices nearest to an even spread.

    Farthest-point selection over the vertices (deterministic): it starts from the highest vertex
    (largest z) and adds, one at a time, the vertex farthest from those chosen.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Mesh vertices (any length unit).
    faces : (F, 3) array_like of int
        Mesh triangles (unused: the nodes are vertices; kept so that every mesh function takes a mesh).
    count : int
        Nodes wanted (at most ``V`` are returned).

    Returns
    -------
    (min(count, V), 3) float64
        The chosen vertices, in the order of ``vertices``.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> surface_nodes(box.vertices, box.faces, 2).tolist()  # a highest corner and the one opposite
    [[-0.5, -0.5, 0.5], [0.5, 0.5, -0.5]]
    """
    v = np.asarray(vertices, dtype=np.float64)
    count = min(int(count), len(v))
    chosen = [int(np.argmax(v[:, 2]))]
    dist = np.linalg.norm(v - v[chosen[0]], axis=1)
    for _ in range(count - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(v - v[k], axis=1))
    return v[np.sort(chosen)]


def level_set_grid(vertices: np.ndarray, faces: np.ndarray, *, spacing: float = 0.05, pad: int = 3) -> Grid:
    """The node grid of :func:`level_set` (same arguments), refused over :data:`MAX_NODES` nodes.

    Cheap (one volume, one bounding box): ``grainforge dem`` calls it for every grain before any
    template is built, so that a spacing too fine is refused in one line before any work.

    Raises
    ------
    ValueError
        Over :data:`MAX_NODES` nodes, naming the finest spacing that fits.

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(2)
    >>> level_set_grid(s.vertices, s.faces, spacing=0.2).shape
    (12, 12, 12)
    """
    from ..geometry.moments import signed_volume, sphere_diameter

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = float(sphere_diameter(signed_volume(v, f)))
    grid = grid_for(v, spacing * d, pad=int(pad))
    n_nodes = int(np.prod(grid.shape))
    if n_nodes > MAX_NODES:
        coarsest = spacing * (n_nodes / MAX_NODES) ** (1 / 3)
        while np.prod(grid_for(v, coarsest * d, pad=int(pad)).shape) > MAX_NODES:  # the pad does not scale
            coarsest *= 1.02
        raise InputError(f"level-set spacing {spacing:g} of d_eq needs a {'x'.join(map(str, grid.shape))} grid "
                         f"({n_nodes:,} nodes, more than {MAX_NODES:,}) for this grain: use a spacing of at least "
                         f"{coarsest:.3g}")
    return grid


def _distance_blocks(vertices: np.ndarray, pts: np.ndarray) -> list[np.ndarray]:
    """Index blocks of ``pts`` whose exact-distance queries each gather at most about
    :data:`DISTANCE_CANDIDATES` triangles (and at most :data:`DISTANCE_BLOCK` nodes); see there."""
    from scipy.spatial import cKDTree

    tree = cKDTree(vertices)
    r, _ = tree.query(pts)
    # trimesh's candidates are the triangles whose boxes meet the cube of half-side r (the nearest-vertex
    # distance) about the node: about twice the vertices in that cube (a Chebyshev ball), plus the few that
    # straddle its faces
    est = 2.0 * tree.query_ball_point(pts, r * 1.01 + 1e-12, p=np.inf, return_length=True) + 8.0
    order = np.argsort(est, kind="stable")
    blocks, start, load = [], 0, 0.0
    for k, i in enumerate(order.tolist()):
        if k > start and (load + est[i] > DISTANCE_CANDIDATES or k - start >= DISTANCE_BLOCK):
            blocks.append(np.sort(order[start:k]))
            start, load = k, 0.0
        load += est[i]
    if start < len(order):
        blocks.append(np.sort(order[start:]))
    return blocks


def level_set(vertices: np.ndarray, faces: np.ndarray, *, spacing: float = 0.05, pad: int = 3,
              nodes: int = 500) -> LevelSet:
    """Signed distance to the mesh surface at the nodes of a regular grid.

    Inside/outside is exact at the nodes (scanline winding number,
    :func:`grainforge.geometry.voxel.inside_mask`); the distance is the exact
    Euclidean distance to the nearest triangle (trimesh), signed.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        A closed, outward-oriented mesh (any length unit; the decks give metres).
    spacing : float
        Node spacing as a fraction of the equivalent diameter (0 < spacing ≤ 0.5).
    pad : int
        Nodes beyond the bounding box on each side (≥ 1).
    nodes : int
        Surface nodes to pick (:func:`surface_nodes`).

    Returns
    -------
    LevelSet
        The grid (spacing ``spacing · d_eq``, ``pad`` nodes beyond the mesh's bounding box), the signed
        distances on it (the mesh's length unit, negative inside) and the surface nodes.

    Raises
    ------
    ValueError
        If ``spacing`` is not in (0, 0.5], ``pad < 1``, or the grid would have more than :data:`MAX_NODES`
        nodes (naming the finest spacing that fits).

    Examples
    --------
    >>> import trimesh
    >>> s = trimesh.creation.icosphere(4)
    >>> ls = level_set(s.vertices, s.faces, spacing=0.2)
    >>> nodes = np.stack(np.meshgrid(*ls.grid.axes(), indexing="ij"), axis=-1)
    >>> bool(np.abs(ls.distance - (np.linalg.norm(nodes, axis=-1) - 1.0)).max() < 0.01)
    True
    """
    import trimesh

    if not 0 < spacing <= 0.5:
        raise InputError(f"spacing must be in (0, 0.5] of d_eq, got {spacing!r}")
    if int(pad) < 1:
        raise InputError(f"pad must be ≥ 1, got {pad!r}")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    grid = level_set_grid(v, f, spacing=spacing, pad=pad)
    inside = inside_mask(v, f, grid)
    ax = grid.axes()
    pts = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
    mesh = trimesh.Trimesh(v, f, process=False, validate=False)
    dist = np.empty(len(pts))
    for block in _distance_blocks(v, pts):
        _, dist[block], _ = trimesh.proximity.closest_point(mesh, pts[block])
    sdf = np.where(inside.reshape(-1), -dist, dist).reshape(grid.shape)
    return LevelSet(grid, sdf, surface_nodes(v, f, nodes))
