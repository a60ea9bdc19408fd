"""The :class:`Grain` value that travels between every part of grainforge."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from ._version import __version__
from .errors import InputError

__all__ = ["Grain"]


def _frozen(a: np.ndarray, dtype) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True, order="C")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Grain:
    """An immutable grain: a closed triangle mesh plus how it was made.

    Grains are generated in dimensionless units (equivalent radius about 1,
    centred on the volume centroid); physical size is applied by
    :meth:`scaled` or at export.

    Parameters
    ----------
    vertices : (V, 3) float64
        Vertex positions (read-only copy is stored).
    faces : (F, 3) int64
        Triangles, counter-clockwise seen from outside.
    method : str
        Generator name (``"fso"``, ``"cri"``, ``"dpa"``, ...).
    params : object
        The method's frozen parameter dataclass.
    seed : int or None
        Seed the grain was generated from (``None`` if a Generator was given).
    version : str
        grainforge version that made the grain.
    info : mapping
        Derived quantities of the generation (e.g. the amplitude scale ``K``).

    Examples
    --------
    >>> import grainforge
    >>> g = grainforge.fso(subdivisions=2, rng=1)
    >>> g.vertices.shape, g.faces.shape
    ((162, 3), (320, 3))
    >>> bool(g.mesh.is_watertight)
    True
    >>> round(float(g.scaled(2.0).mesh.volume / g.mesh.volume), 6)
    8.0
    """

    vertices: np.ndarray
    faces: np.ndarray
    method: str
    params: Any
    seed: int | None
    version: str = __version__
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "vertices", _frozen(self.vertices, np.float64))
        object.__setattr__(self, "faces", _frozen(self.faces, np.int64))
        object.__setattr__(self, "info", MappingProxyType(dict(self.info)))
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise InputError(f"vertices must have shape (V, 3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InputError(f"faces must have shape (F, 3), got {self.faces.shape}")

    @property
    def mesh(self):
        """A new :class:`trimesh.Trimesh` of the grain (safe to modify)."""
        import trimesh

        return trimesh.Trimesh(
            vertices=self.vertices.copy(), faces=self.faces.copy(), process=False, validate=False
        )

    def scaled(self, factor: float) -> Grain:
        """A new Grain with every coordinate multiplied by ``factor`` (> 0).

        Parameters
        ----------
        factor : float
            Scale factor (> 0, finite): model units -> millimetres when scaling a generated grain to size.

        Returns
        -------
        Grain
            A copy with ``vertices * factor`` and ``info["scale"]`` multiplied by ``factor``; the faces,
            method, parameters and seed are kept.

        Raises
        ------
        ValueError
            If ``factor`` is not a positive finite number.
        """
        factor = float(factor)
        if not np.isfinite(factor) or factor <= 0:
            raise InputError(f"scale factor must be a positive number, got {factor!r}")
        info = dict(self.info)
        info["scale"] = info.get("scale", 1.0) * factor
        return dataclasses.replace(self, vertices=self.vertices * factor, info=info)

    def __repr__(self) -> str:
        return (
            f"Grain(method={self.method!r}, seed={self.seed!r}, "
            f"vertices={len(self.vertices)}, faces={len(self.faces)})"
        )
