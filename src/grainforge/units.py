"""Units of the columns grainforge writes: every CSV header states its unit.

Rows are dicts with plain keys (``volume``, ``L``, ``size``); a CSV written
with :data:`UNITS` names each column with its unit as a suffix
(``volume_mm3``, ``L_mm``, ``size_mm``), and readers take either form
(:func:`plain`).  Lengths are millimetres: the size a grain is generated at,
and the unit a mesh file's coordinates are read in (STL and friends carry no
unit; grainforge writes them in mm).  Columns without a suffix are
dimensionless (ratios, counts, descriptors) or words.

Examples
--------
>>> [with_unit(c) for c in ("volume", "L", "sphericity")]
['volume_mm3', 'L_mm', 'sphericity']
>>> plain("volume_mm3"), plain("sphericity")
('volume', 'sphericity')
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

__all__ = ["UNITS", "with_unit", "plain", "headers"]

_LENGTHS = ("size", "equivalent_diameter", "L", "I", "S", "L_pca", "I_pca", "S_pca", "radius_of_gyration",
            "R_g", "primary_size", "rounding_radius", "chordal_deviation", "deviation_tolerance", "mean_edge",
            "retained_wavelength", "x", "y", "z", "size_x", "size_y", "size_z", "gap",
            # analyse --voxel-size-mm/--voxels-across (Sand-Atlas voxel measures)
            "atlas_voxel_size", "atlas_equivalent_diameter", "atlas_major", "atlas_middle", "atlas_minor")

#: column -> unit suffix, for every column grainforge writes that has a unit
UNITS: dict[str, str] = {
    **{c: "mm" for c in _LENGTHS},
    "volume": "mm3", "surface_area": "mm2", "cavity_volume": "mm3", "atlas_volume": "mm3",
    # model coordinates (before scaling) x scale = millimetres
    "scale": "mm_per_unit",
    # extreme radii of a generated grain relative to its mean radius R0 (FSO) or r0 (CRI)
    "min_radius": "per_R0", "max_radius": "per_R0",
}

_SUFFIXED = {f"{c}_{u}": c for c, u in UNITS.items()}


def with_unit(column: str, units: Mapping[str, str] = UNITS) -> str:
    """``column`` with its unit suffix (unchanged if it has no unit)."""
    unit = units.get(column)
    return f"{column}_{unit}" if unit else column


def headers(columns: Sequence[str], units: Mapping[str, str] = UNITS) -> list[str]:
    """:func:`with_unit` of every column."""
    return [with_unit(c, units) for c in columns]


def plain(header: str) -> str:
    """The row key of a CSV header: ``volume_mm3`` -> ``volume`` (unchanged if it has no unit suffix)."""
    return _SUFFIXED.get(header, header)
