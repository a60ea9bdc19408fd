"""Grains for DEM engines: exact mass properties, clumps, polyhedra, level sets, decks.

Engine decks: :mod:`grainforge.dem.yade`, :mod:`grainforge.dem.liggghts`,
:mod:`grainforge.dem.lammps`. See docs/dem.md.
"""

from .massprops import MassProperties, mass_properties

__all__ = ["MassProperties", "mass_properties", "ENGINES", "SUPPORTED"]

#: engine name -> shapes its deck writer supports
SUPPORTED = {
    "yade": ("clump", "polyhedron", "levelset"),
    "liggghts": ("clump",),
    "lammps": ("clump", "polyhedron"),
}
ENGINES = tuple(SUPPORTED)
