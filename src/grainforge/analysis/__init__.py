"""Shape analysis: descriptors of 3D grains (docs/design/algorithms.md §4).

- :func:`describe` — every descriptor of one body (size, form, roughness,
  surface fractal dimension, principal-projection Fourier descriptors,
  aggregate measures); :func:`basic_descriptors` — the manifest columns.
- :func:`analyse_file` — read a mesh file, split it into bodies, flag and describe them.
- :mod:`.fourier`, :mod:`.fractal` — the outline and texture estimators.
"""

from .descriptors import BASIC_COLUMNS, DESCRIPTOR_COLUMNS, basic_descriptors, describe, principal_dimensions
from .measure import analyse_file

__all__ = [
    "basic_descriptors", "principal_dimensions", "describe", "analyse_file", "BASIC_COLUMNS", "DESCRIPTOR_COLUMNS",
]
