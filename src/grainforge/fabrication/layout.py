"""How grains are laid out on a build plate: each grain oriented, then its box packed on shelves.

Each grain is oriented first (:func:`orient_principal` where the printer allows stacking, its principal
axes along x, y, z; :func:`orient_stable` otherwise, resting on the stable face of its convex hull and
turned about z to align its footprint with x), then its bounding box is placed by the online
:class:`ShelfPacker`: rows along x, rows stacked along y into a layer, layers stacked along z when
stacking is allowed, a new plate when one is full, boxes at least the gap apart.
:mod:`grainforge.fabrication.tray` streams the grains through them.

Examples
--------
>>> p = ShelfPacker((10.0, 10.0, 10.0), gap=1.0, stacking=True)
>>> [p.place((4.0, 4.0, 4.0)) for _ in range(5)]
[(0, 0.0, 0.0, 0.0), (0, 5.0, 0.0, 0.0), (0, 0.0, 5.0, 0.0), (0, 5.0, 5.0, 0.0), (0, 0.0, 0.0, 5.0)]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import InputError

__all__ = ["orient_principal", "orient_stable", "ShelfPacker"]


# --------------------------------------------------------------------------- orientation

def orient_principal(vertices: np.ndarray) -> np.ndarray:
    """Rotate vertices so their principal axes are x (largest spread), y, z (a proper rotation).

    Parameters
    ----------
    vertices : (V, 3) ndarray of float
        Any unit.

    Returns
    -------
    (V, 3) float64
        Centred on the vertex mean.

    Examples
    --------
    >>> v = orient_principal(np.array([[0.0, 0, 0], [0, 3, 0], [0, 0, 1], [0, 3, 1]]))
    >>> np.round(np.ptp(v, axis=0), 6).tolist()
    [3.0, 1.0, 0.0]
    """
    c = vertices.mean(axis=0)
    d = vertices - c
    _, vecs = np.linalg.eigh(d.T @ d)
    R = vecs[:, ::-1].copy()
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1
    return d @ R


def _rotation_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation matrix turning unit vector ``a`` onto unit vector ``b``."""
    v = np.cross(a, b)
    s = np.linalg.norm(v)
    c = float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis -= a * (axis @ a)
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K * ((1 - c) / s**2)


def orient_stable(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Rotate a closed mesh so it rests on a stable face of its hull (that face at the bottom, z = min).

    The hull face whose plane is nearest to the volume centroid is chosen: the
    centroid's projection onto it lies inside it, so the grain is in stable
    equilibrium resting on that face.  The footprint is then turned about z
    so its principal axis is x.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Vertex positions, mm.
    faces : (F, 3) array_like of int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    (V, 3) float64
        The rotated vertices (about the volume centroid, which ends at the origin).

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box(extents=(1.0, 3.0, 2.0))
    >>> v = orient_stable(np.asarray(box.vertices), np.asarray(box.faces))
    >>> np.round(v.max(axis=0) - v.min(axis=0), 6).tolist()   # rests on its largest face
    [3.0, 2.0, 1.0]
    """
    from scipy.spatial import ConvexHull

    from ..geometry.solid import volume_centroid

    c = volume_centroid(vertices, faces)
    eq = ConvexHull(vertices).equations  # n·x + d <= 0 inside, n outward unit
    dist = -(eq[:, :3] @ c + eq[:, 3])
    n = eq[int(np.argmin(dist)), :3]
    v = (vertices - c) @ _rotation_to(n, np.array([0.0, 0.0, -1.0])).T
    xy = v[:, :2] - v[:, :2].mean(axis=0)
    _, vecs = np.linalg.eigh(xy.T @ xy)
    a = vecs[:, 1]
    ang = np.arctan2(a[1], a[0])
    ca, sa = np.cos(-ang), np.sin(-ang)
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    return v @ Rz.T


# --------------------------------------------------------------------------- packing

class ShelfPacker:
    """Online shelf packing of boxes on build plates with a minimum gap.

    Boxes are placed in rows along x; rows fill a layer along y; with
    ``stacking`` layers fill the plate along z; then a new plate starts.

    Parameters
    ----------
    volume : (3,) float
        Build volume x, y, z.
    gap : float
        Minimum distance between boxes (> 0).
    stacking : bool
        Whether layers may be stacked in z.
    """

    def __init__(self, volume: Sequence[float], gap: float, stacking: bool):
        self.W, self.D, self.H = (float(x) for x in volume)
        self.row_width = self.W
        self.gap = float(gap)
        self.stacking = bool(stacking)
        self.plate = 0
        self.x = self.y = self.z = 0.0
        self.row_depth = self.layer_height = 0.0
        self.layers = 1

    def compact(self, count: int, extents: Sequence[float]) -> None:
        """Limit rows to about a square patch for ``count`` boxes like ``extents`` (a compact, not a strip, layout).

        Parameters
        ----------
        count : int
            Boxes to be placed.
        extents : (3,) sequence of float
            A typical box, mm.
        """
        a, b, _ = (float(e) + self.gap for e in extents)
        side = float(np.sqrt(count * a * b * 1.1))
        self.row_width = min(self.W, max(side, a))

    def place(self, extents: Sequence[float]) -> tuple[int, float, float, float]:
        """Position (plate, x, y, z) of the min corner of the next box.

        Parameters
        ----------
        extents : (3,) sequence of float
            The box's x, y, z, mm.

        Returns
        -------
        plate : int
            Counted from 0.
        x, y, z : float
            mm.

        Raises
        ------
        ValueError
            If the box is larger than the build volume.
        """
        a, b, c = (float(e) for e in extents)
        if a > self.W or b > self.D or c > self.H:
            raise InputError(
                f"a grain of {a:.3g} x {b:.3g} x {c:.3g} mm does not fit the build volume "
                f"{self.W:g} x {self.D:g} x {self.H:g} mm"
            )
        while True:
            if self.x + a <= max(self.row_width, a) and self.y + b <= self.D and self.z + c <= self.H:
                pos = (self.plate, self.x, self.y, self.z)
                self.x += a + self.gap
                self.row_depth = max(self.row_depth, b)
                self.layer_height = max(self.layer_height, c)
                return pos
            if self.x > 0:  # new row
                self.y += self.row_depth + self.gap
                self.x, self.row_depth = 0.0, 0.0
            elif self.y > 0 and self.stacking:  # new layer
                self.z += self.layer_height + self.gap
                self.y, self.layer_height = 0.0, 0.0
                self.layers += 1
            else:
                self.new_plate()

    def new_plate(self) -> int:
        """Start the next plate (the current one is full, or its print file reached its triangle budget).

        Returns
        -------
        int
            The new plate, counted from 0.
        """
        self.plate += 1
        self.x = self.y = self.z = 0.0
        self.row_depth = self.layer_height = 0.0
        self.layers = 1
        return self.plate
