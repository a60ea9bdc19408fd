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

__all__ = ["UNITS", "SIZE_RANGE_MM", "MESH_SIZE_RANGE_MM", "with_unit", "plain", "headers"]

#: physical sizes a grain may be given, in mm: 1 µm to 10 m (beyond them float32 files lose the shape or
#: the slicer's units overflow); grainforge.fabrication.scale checks them
SIZE_RANGE_MM = (1e-3, 1e4)
#: sizes (the largest side of the bounding box, mm) at which ``analyse``, ``check`` and ``tray`` take a file's
#: body for a grain (:func:`grainforge.geometry.solid.mesh_size_problem`): a decade beyond :data:`SIZE_RANGE_MM` on
#: each side, so that every grain grainforge makes is read whatever its shape (the largest side is at least
#: 0.8 d_eq), 0.1 µm to 100 m in all; beyond, the file is in another unit or scaled by mistake
MESH_SIZE_RANGE_MM = (SIZE_RANGE_MM[0] / 10, SIZE_RANGE_MM[1] * 10)

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
    """``column`` with its unit suffix (unchanged if it has no unit).

    Parameters
    ----------
    column : str
        A row key (``volume``, ``L``).
    units : mapping of str to str, optional
        Column -> unit suffix; default :data:`UNITS`.

    Returns
    -------
    str
        ``column_unit`` (``volume_mm3``), or ``column`` when ``units`` gives it no unit.
    """
    unit = units.get(column)
    return f"{column}_{unit}" if unit else column


def headers(columns: Sequence[str], units: Mapping[str, str] = UNITS) -> list[str]:
    """:func:`with_unit` of every column.

    Parameters
    ----------
    columns : sequence of str
        Row keys, in the order of the CSV's columns.
    units : mapping of str to str, optional
        Column -> unit suffix; default :data:`UNITS`.

    Returns
    -------
    list of str
        The CSV header, one name per column.

    Examples
    --------
    >>> headers(["size", "n_faces"])
    ['size_mm', 'n_faces']
    """
    return [with_unit(c, units) for c in columns]


def plain(header: str) -> str:
    """The row key of a CSV header: ``volume_mm3`` -> ``volume`` (unchanged if it has no unit suffix).

    Parameters
    ----------
    header : str
        A CSV column name, with or without the unit suffix grainforge writes.

    Returns
    -------
    str
        The row key (a name that is not a suffixed column of :data:`UNITS` is returned unchanged).
    """
    return _SUFFIXED.get(header, header)
