"""From grains to printable files: physical scale, printability, trays."""

from .scale import SIZE_DEFINITIONS, scale_factor, to_size

__all__ = ["SIZE_DEFINITIONS", "scale_factor", "to_size"]
