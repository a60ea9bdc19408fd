"""Shape analysis: descriptors of 3D grains (ALGORITHMS.md §4)."""

from .descriptors import basic_descriptors, principal_dimensions

__all__ = ["basic_descriptors", "principal_dimensions"]
