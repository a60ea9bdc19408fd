"""Physical scale by the definition a geotechnical user means."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..params import ParameterError
from ..units import MESH_SIZE_RANGE_MM, SIZE_RANGE_MM

__all__ = ["SIZE_DEFINITIONS", "MESH_SIZE_RANGE_MM", "SIZE_RANGE_MM", "check_target_size", "scale_factor", "to_size"]

#: definition -> description
SIZE_DEFINITIONS = {
    "equivalent": "diameter of the sphere of equal volume, d_eq = (6V/π)^(1/3)",
    "sieve": "sieve size, taken as the intermediate dimension I of the minimum-volume box",
    "longest": "longest dimension L of the minimum-volume box",
}


def _current_size(grain, definition: str) -> float:
    from ..analysis.descriptors import principal_dimensions
    from ..geometry.moments import signed_volume, sphere_diameter

    if definition == "equivalent":
        return float(sphere_diameter(signed_volume(grain.vertices, grain.faces)))
    L, I, _ = principal_dimensions(grain)
    return I if definition == "sieve" else L


#: (SIZE_RANGE_MM: the physical sizes a grain may be given, 1 µm to 10 m; MESH_SIZE_RANGE_MM: the sizes a mesh
#: file is read at; both defined in grainforge.units)
MIN_SIZE_MM, MAX_SIZE_MM = SIZE_RANGE_MM


def check_target_size(size: float, definition: str = "equivalent") -> float:
    """Validate a size in mm and its definition; return the size as a float.

    Parameters
    ----------
    size : float
        mm.
    definition : str, default "equivalent"
        One of :data:`SIZE_DEFINITIONS`.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        For a non-positive or non-finite size or an unknown definition.
    ParameterError
        Naming ``size`` when it is outside :data:`grainforge.units.SIZE_RANGE_MM`.
    """
    if definition not in SIZE_DEFINITIONS:
        raise InputError(f"size_definition must be one of {', '.join(SIZE_DEFINITIONS)}, got {definition!r}")
    try:
        value = float(size)
    except (TypeError, ValueError):
        value = float("nan")
    if not np.isfinite(value) or not SIZE_RANGE_MM[0] <= value <= SIZE_RANGE_MM[1]:
        raise ParameterError(
            "size", f"must be between {SIZE_RANGE_MM[0]:g} and {SIZE_RANGE_MM[1]:g} mm (1 µm to 10 m), got {size!r}"
        )
    return value


def scale_factor(grain, size: float, definition: str = "equivalent") -> float:
    """The factor that brings ``grain`` to ``size`` under ``definition``.

    Parameters
    ----------
    grain : Grain or trimesh.Trimesh
        The mesh, in its own units.
    size : float
        mm.
    definition : str, default "equivalent"
        One of :data:`SIZE_DEFINITIONS`.

    Returns
    -------
    float
        mm per model unit.

    Raises
    ------
    ValueError
        For a non-positive size or an unknown definition.
    """
    return check_target_size(size, definition) / _current_size(grain, definition)


def to_size(grain, size: float, definition: str = "equivalent"):
    """A scaled copy of ``grain`` whose size under ``definition`` is ``size``.

    Parameters
    ----------
    grain : Grain
        The grain, in model units.
    size : float
        mm.
    definition : str, default "equivalent"
        One of :data:`SIZE_DEFINITIONS`.

    Returns
    -------
    Grain
        Coordinates in mm.

    Raises
    ------
    ValueError
        As :func:`check_target_size`.

    Examples
    --------
    >>> import grainforge
    >>> from grainforge.analysis import basic_descriptors
    >>> g = to_size(grainforge.fso(subdivisions=3, rng=0), 2.0)
    >>> round(basic_descriptors(g)["equivalent_diameter"], 9)
    2.0
    """
    return grain.scaled(scale_factor(grain, size, definition))
