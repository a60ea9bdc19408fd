"""Uniformly random rotations: the one implementation every generator and measurement uses.

A uniform random rotation is the unit quaternion of four independent
standard normal draws (the normalised Gaussian 4-vector is uniform on the
3-sphere, and the quaternion map covers SO(3) twice, evenly).  Two
conventions read the same four draws differently, and both are kept because
outputs depend on them bit for bit:

``"scalar-first"``
    ``q = (w, x, y, z)``, turned into a matrix by the closed-form
    expression below.  It defines the FSO method's seamless-surface ridge
    directions (:mod:`grainforge.methods.fso`), so its formula must not
    change: a grain of a given seed keeps its bytes.
``"scipy"``
    ``q = (x, y, z, w)``, turned into a matrix by
    :class:`scipy.spatial.transform.Rotation`: bit for bit
    ``Rotation.random(random_state=default_rng(rng)).as_matrix()`` (the
    Sand-Atlas measurement's random orientation,
    :func:`grainforge.analysis.atlas.atlas_descriptors`).

Both are uniform on SO(3); for the same draws they are different rotations.
The Yade scene scripts (``grainforge.dem.scripts``) run inside Yade's own
interpreter, cannot import grainforge and draw their orientations with
Python's :mod:`random`: a deliberate, engine-side copy of the idea, not of
this code.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["random_rotation", "quaternion_matrix", "CONVENTIONS"]

#: the quaternion conventions :func:`random_rotation` knows
CONVENTIONS = ("scalar-first", "scipy")


def quaternion_matrix(q) -> np.ndarray:
    """The rotation matrix of quaternion ``q = (w, x, y, z)`` (normalised here).

    Examples
    --------
    >>> quaternion_matrix([1.0, 0.0, 0.0, 0.0]).tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    >>> np.round(quaternion_matrix([1.0, 0.0, 0.0, 1.0]), 12).tolist()   # 90° about z
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def random_rotation(rng: Any, convention: str = "scipy") -> np.ndarray:
    """A uniformly random 3×3 rotation matrix from four normal draws of ``rng``.

    Parameters
    ----------
    rng : numpy.random.Generator, int, SeedSequence or None
        Anything :func:`numpy.random.default_rng` accepts; a Generator is
        used (and advanced by four draws) as it is.
    convention : {"scipy", "scalar-first"}
        How the draws become a rotation (module docstring): ``"scipy"`` is
        scipy's ``Rotation.random``; ``"scalar-first"`` is the FSO method's.

    Returns
    -------
    (3, 3) float64 ndarray

    Examples
    --------
    >>> R = random_rotation(1)
    >>> bool(np.allclose(R @ R.T, np.eye(3))), round(float(np.linalg.det(R)), 9)
    (True, 1.0)
    >>> from scipy.spatial.transform import Rotation
    >>> bool(np.array_equal(R, Rotation.random(random_state=np.random.default_rng(1)).as_matrix()))
    True
    >>> S = random_rotation(np.random.default_rng(1), convention="scalar-first")
    >>> bool(np.allclose(S @ S.T, np.eye(3))), bool(np.allclose(S, R))
    (True, False)
    """
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    q = np.random.default_rng(rng).standard_normal(4)
    if convention == "scalar-first":
        return quaternion_matrix(q)
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_matrix()
