"""Directed Polyhedra Aggregation (DPA): the method's public function, its geometry and its calibration.

- :mod:`grainforge.methods.dpa.aggregation`: the aggregate (paper §2.3, Eqs. 4–5) and its surface;
- :mod:`grainforge.methods.dpa.calibration`: the curve from the exponent ε to the aggregate fractal
  dimension D_A, used when a grain asks for a target D_A;
- :func:`dpa`: one grain, from ε or from a target D_A.
"""

from __future__ import annotations

from ...params import ParameterError
from ...rng import RNGLike
from .aggregation import (
    INFO_COLUMNS,
    NAME,
    PRIMITIVES,
    VALIDITY_PARAMETER,
    Aggregate,
    Params,
    aggregate,
    build,
    lattice_surface,
    parent_index,
    physical_info,
    separate_pinches,
    smooth_surface,
    union_surface,
)

__all__ = ["dpa", "NAME", "VALIDITY_PARAMETER", "INFO_COLUMNS", "Params", "Aggregate", "build", "aggregate", "parent_index", "lattice_surface", "union_surface", "separate_pinches", "smooth_surface", "PRIMITIVES", "physical_info"]

def dpa(
    *,
    primitive: str = "cube",
    exponent: float | None = None,
    primaries: int = 200,
    smooth: int = 0,
    target_fractal_dimension: float | None = None,
    rng: RNGLike = None,
):
    """Generate one aggregate grain by Directed Polyhedra Aggregation (paper §2.3).

    Parameters
    ----------
    primitive : str
        ``cube`` (lattice), ``octahedron`` (as in the paper), or ``tetrahedron``,
        ``dodecahedron``, ``icosahedron``, ``truncated-octahedron``.
    exponent : float, optional
        ε of Eq. 4 in [0.01, 100] (default 1.0).  Exclusive with
        ``target_fractal_dimension``.
    primaries : int
        Number of primaries N in [1, 100000] (default 200).
    smooth : int
        0 keeps sharp corners; K in 1..4 rounds them by K steps of Loop
        subdivision (each step multiplies the triangles by four).
    target_fractal_dimension : float, optional
        Ask for an aggregate fractal dimension D_A instead of ε: ε is read
        from the (cached, computed on first use) calibration curve of this
        primitive and N, see :func:`grainforge.methods.dpa.calibration.exponent_for_dimension`.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seed or generator (:mod:`grainforge.rng`).  An int, a plain SeedSequence's entropy, or the seed
        drawn for None is recorded as ``Grain.seed``; a Generator leaves it None.

    Returns
    -------
    Grain
        Centred, scaled so that the primaries' total volume is a unit-radius
        sphere's; ``info`` holds D_A, porosity, R_g, cavity_volume and
        primary_size.

    Raises
    ------
    ValueError
        For an out-of-range parameter, an unknown primitive, or a target
        D_A outside the calibrated range.

    References
    ----------
    Hanaor et al., *3D printable geomaterials*, Géotechnique (2016), Eqs. 4–5.

    Examples
    --------
    >>> from grainforge import dpa
    >>> g = dpa(primitive="cube", exponent=0.5, primaries=27, rng=3)
    >>> g.method, round(float(g.mesh.volume / g.info["primary_size"] ** 3), 2)  # edge contacts notched
    ('dpa', 27.0)
    >>> dpa(exponent=0)
    Traceback (most recent call last):
    ...
    grainforge.params.ParameterError: exponent must be in [0.01, 100], got 0.0
    """
    from .. import generate, get
    from .calibration import exponent_for_dimension

    P = get("dpa").Params  # the registered module's class (robust to the module being imported twice)

    if target_fractal_dimension is not None and exponent is not None:
        raise ParameterError("target_fractal_dimension", "cannot be combined with exponent: give one of them")
    if target_fractal_dimension is not None:
        P(primitive=primitive, exponent=1.0, primaries=primaries, smooth=smooth,
          target_fractal_dimension=target_fractal_dimension)  # validate first
        exponent = exponent_for_dimension(target_fractal_dimension, primitive=primitive, primaries=primaries)
    p = P(primitive=primitive, exponent=exponent, primaries=primaries, smooth=smooth,
          target_fractal_dimension=target_fractal_dimension)
    return generate("dpa", p, rng)
