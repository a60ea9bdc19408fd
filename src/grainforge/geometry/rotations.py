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

Every grain a DEM deck or a virtual-test scene places gets its orientation
from :func:`random_quaternions` (the same four normal draws, scalar first),
drawn here in grainforge and written into the deck as numbers: the engine
scripts read them and draw none of their own.  Drawing a uniform axis and
an angle uniform in [0, 2π) is *not* uniform on SO(3): it over-weights small
turns (its rotation angle is uniform on [0, π], where the uniform measure's
has density (1 − cos ω)/π), so that a layer of grains starts with a fabric
aligned with the templates' principal frames.  :func:`haar_angle_test` tells
the two apart (the suite applies its own copy of that check, written
independently, to orientations read back from written decks).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, as_generator

__all__ = ["random_rotation", "random_quaternions", "quaternion_matrix", "quaternion_axis_angle", "axis_angle_matrix",
           "rotation_angles", "haar_angle_test", "CONVENTIONS"]

#: the quaternion conventions :func:`random_rotation` knows
CONVENTIONS = ("scalar-first", "scipy")


def quaternion_matrix(q) -> np.ndarray:
    """The rotation matrix of quaternion ``q = (w, x, y, z)`` (normalised here).

    Parameters
    ----------
    q : (4,) array_like of float
        Quaternion, scalar first; any non-zero length.

    Returns
    -------
    (3, 3) float64
        The rotation matrix (acting on column vectors).

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


def axis_angle_matrix(axis, angle: float) -> np.ndarray:
    """The (3, 3) right-handed rotation by ``angle`` radians about ``axis`` (Rodrigues' formula).

    The one implementation of a turn about an axis (the generators' facets and rings, the DEM decks, the
    box search's rotation vectors). ``axis`` need not be unit: it is normalised unless it already is, so
    a unit axis gives the same bits as the plain formula.

    Parameters
    ----------
    axis : (3,) array_like of float
        Rotation axis, any non-zero length.
    angle : float
        Angle in radians, counter-clockwise seen from the tip of ``axis``.

    Returns
    -------
    (3, 3) float64
        The rotation matrix (acting on column vectors).

    Examples
    --------
    >>> np.round(axis_angle_matrix([0.0, 0.0, 2.0], np.pi / 2) @ [1.0, 0.0, 0.0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    a = np.asarray(axis, dtype=np.float64)
    n = float(np.linalg.norm(a))
    if n != 1.0:
        a = a / n
    x, y, z = a
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def random_rotation(rng: RNGLike, convention: str = "scipy") -> np.ndarray:
    """A uniformly random 3×3 rotation matrix from four normal draws of ``rng``.

    Parameters
    ----------
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is used (and advanced by four
        draws) as it is.
    convention : {"scipy", "scalar-first"}
        How the draws become a rotation (module docstring): ``"scipy"`` is
        scipy's ``Rotation.random``; ``"scalar-first"`` is the FSO method's.

    Returns
    -------
    (3, 3) float64 ndarray

    Raises
    ------
    ValueError
        If ``convention`` is not one of :data:`CONVENTIONS`, or ``rng`` is not an accepted value.

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
        raise InputError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    q = as_generator(rng).standard_normal(4)
    if convention == "scalar-first":
        return quaternion_matrix(q)
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_matrix()


def random_quaternions(count: int, rng: RNGLike) -> np.ndarray:
    """``count`` uniformly random unit quaternions ``(w, x, y, z)``, ``w ≥ 0``, one row each.

    Row ``k`` is what :func:`random_rotation` with ``convention="scalar-first"``
    would turn into a matrix from the same generator state (four normal draws a
    row, normalised), with its sign chosen so that ``w ≥ 0`` (``q`` and ``−q`` are
    the same turn).  The one source of the orientations of every grain that a
    deck or a scene places.

    Parameters
    ----------
    count : int
        Number of quaternions (≥ 0).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by ``4 · count`` draws.

    Returns
    -------
    (count, 4) float64 ndarray

    Raises
    ------
    ValueError
        If ``count`` is negative or ``rng`` is not an accepted value.

    Examples
    --------
    >>> q = random_quaternions(3, 7)
    >>> q.shape, bool(np.allclose(np.linalg.norm(q, axis=1), 1.0)), bool((q[:, 0] >= 0).all())
    ((3, 4), True, True)
    >>> R = random_rotation(np.random.default_rng(7), convention="scalar-first")
    >>> bool(np.allclose(quaternion_matrix(q[0]), R))
    True
    """
    count = int(count)
    if count < 0:
        raise InputError(f"count must be ≥ 0, got {count}")
    q = as_generator(rng).standard_normal((count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q


def quaternion_axis_angle(q) -> tuple[np.ndarray, float]:
    """Unit axis and angle (radians, in [0, π] for ``w ≥ 0``) of the turn ``q = (w, x, y, z)``.

    A turn by 0 has no axis: ``(1, 0, 0)`` is returned with angle 0.

    Parameters
    ----------
    q : (4,) array_like of float
        Quaternion, scalar first; any non-zero length.

    Returns
    -------
    axis : (3,) float64
        Unit axis.
    angle : float
        Angle in radians (in [0, 2π); in [0, π] when ``w ≥ 0``).

    Examples
    --------
    >>> axis, angle = quaternion_axis_angle([np.cos(0.5), 0.0, 0.0, np.sin(0.5)])
    >>> axis.tolist(), round(angle, 12)
    ([0.0, 0.0, 1.0], 1.0)
    """
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    s = float(np.linalg.norm(q[1:]))
    if s == 0.0:
        return np.array([1.0, 0.0, 0.0]), 0.0
    return q[1:] / s, 2.0 * float(np.arctan2(s, q[0]))


def rotation_angles(rotations) -> np.ndarray:
    """Rotation angle ω ∈ [0, π] of each 3×3 rotation matrix (from its trace, 1 + 2 cos ω).

    Parameters
    ----------
    rotations : (n, 3, 3) or (3, 3) array_like of float
        Rotation matrices.

    Returns
    -------
    (n,) float64
        Angles in radians.

    Examples
    --------
    >>> np.round(rotation_angles([np.eye(3), quaternion_matrix([0.0, 1.0, 0.0, 0.0])]), 12).tolist()
    [0.0, 3.14159265359]
    """
    R = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    c = (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def haar_angle_test(rotations) -> dict:
    """How far a set of rotations is from uniformly random: their angles against the uniform law.

    Under the uniform (Haar) measure on SO(3) the rotation angle ω has the
    density ``(1 − cos ω)/π`` on [0, π] (CDF ``(ω − sin ω)/π``) and the trace
    ``1 + 2 cos ω`` has mean 0 and standard deviation 1.  The one-sample
    Kolmogorov–Smirnov test of the angles (scipy's ``kstest``) against that CDF
    gives the p-value; ``mean_trace`` and its standard error ``1/√n`` are
    returned beside it, as is the share of turns within 90° of the identity
    (about 0.18 when uniform; 0.5 for a uniform axis with a uniform angle).

    Parameters
    ----------
    rotations : (n, 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    dict
        ``n``, ``ks`` (statistic), ``p`` (p-value), ``mean_trace``, ``trace_se``, ``within_90``.

    Raises
    ------
    ValueError
        With fewer than two rotations.

    Examples
    --------
    >>> R = [quaternion_matrix(q) for q in random_quaternions(2000, 1)]
    >>> t = haar_angle_test(R)
    >>> t["p"] > 0.01, abs(t["mean_trace"]) < 4 * t["trace_se"], round(t["within_90"], 1)
    (True, True, 0.2)
    """
    from scipy.stats import kstest

    w = rotation_angles(rotations)
    n = len(w)
    if n < 2:
        raise InputError(f"need at least 2 rotations, got {n}")
    res = kstest(w, lambda x: (np.asarray(x) - np.sin(x)) / np.pi)
    trace = 1.0 + 2.0 * np.cos(w)
    return {"n": n, "ks": float(res.statistic), "p": float(res.pvalue), "mean_trace": float(trace.mean()),
            "trace_se": float(1.0 / np.sqrt(n)), "within_90": float(np.mean(w < np.pi / 2))}
