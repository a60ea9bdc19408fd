"""Grain generators and their registry.

Each generator lives in its own module exposing

- ``NAME`` : str, the method name used by the CLI, manifests and recipes;
- ``Params`` : a frozen dataclass declared with :func:`grainforge.params.param`;
- ``build(params, rng) -> (vertices, faces, info)`` : the pure geometry;

and optionally ``INFO_COLUMNS`` (the ``info`` keys a manifest records) and
``physical_info(info, scale) -> info`` (info values in model units converted
to mm for the manifest, e.g. DPA's R_g in primary sizes).  Method modules
never import click or :mod:`grainforge.cli`: ``grainforge generate NAME`` is
derived from ``Params`` by :mod:`grainforge.cli.generate`, and options that
are not plain parameters go in a hook ``grainforge/cli/generate_<name>.py``.

:func:`generate` turns a (method, params, seed) triple into a checked,
centred :class:`~grainforge.grain.Grain`.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

import numpy as np

from ..errors import InputError
from ..geometry.solid import require_solid, volume_centroid
from ..grain import Grain
from ..rng import RNGLike, resolve_rng

__all__ = ["METHODS", "get", "generate"]

#: method name -> module path.  Modules are imported lazily.
METHODS: dict[str, str] = {
    "fso": "grainforge.methods.fso",
    "cri": "grainforge.methods.cri",
    "dpa": "grainforge.methods.dpa",
    "angular": "grainforge.methods.angular",
    "rf": "grainforge.methods.rf",
}


def get(name: str) -> ModuleType:
    """The module implementing method ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`METHODS` (``"fso"``, ``"cri"``, ``"dpa"``, ``"angular"``, ``"rf"``).

    Returns
    -------
    module
        The method's module (imported on first use): ``NAME``, ``Params``, ``build``.

    Raises
    ------
    ValueError
        If no such method exists.
    """
    try:
        path = METHODS[name]
    except KeyError:
        raise InputError(f"method must be one of {', '.join(sorted(METHODS))}, got {name!r}") from None
    return importlib.import_module(path)


def generate(name: str, params: Any, rng: RNGLike = None) -> Grain:
    """Generate one grain of method ``name`` with ``params``.

    The mesh is checked by the solid contract as a reader will see it
    (:func:`grainforge.geometry.solid.solid_problems`: float32, vertices merged by
    position, closed 2-manifold, no near-zero-area face, one body, positive
    volume, no self-intersection) and translated so that its volume centroid
    is at the origin.

    Parameters
    ----------
    name : str
        A key of :data:`METHODS`.
    params : object
        An instance of the method's ``Params``.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Normalised by :func:`grainforge.rng.resolve_rng`; the seed it returns (an int, the entropy drawn
        for None) is recorded as ``Grain.seed``, None for a Generator.

    Returns
    -------
    Grain
        Dimensionless (the method's R0 or equivalent radius about 1), centred on its volume centroid.

    Raises
    ------
    ValueError
        Naming the parameter when the result would not be a valid solid; an unknown ``name``;
        an ``rng`` of another kind.
    TypeError
        If ``params`` is not the method's ``Params``.

    Examples
    --------
    >>> from grainforge.methods import generate, get
    >>> g = generate("fso", get("fso").Params(subdivisions=2), rng=3)
    >>> g.method, g.seed, len(g.faces)
    ('fso', 3, 320)
    """
    module = get(name)
    if not isinstance(params, module.Params):
        raise TypeError(f"params must be {module.Params.__name__}, got {type(params).__name__}")
    generator, seed = resolve_rng(rng)
    vertices, faces, info = module.build(params, generator)
    if hasattr(module, "validity_parameter"):
        parameter = module.validity_parameter(params)
    else:
        parameter = getattr(module, "VALIDITY_PARAMETER", "parameters")
    # star-shaped generators (radius function on a sphere about the origin) may prove no self-intersection
    star = np.zeros(3) if getattr(module, "STAR_SHAPED", False) else None
    if star is None:
        vertices = vertices - volume_centroid(vertices, faces)  # checked where it will be written
    require_solid(vertices, faces, parameter, star_centre=star)
    vertices = vertices - volume_centroid(vertices, faces)
    return Grain(vertices=vertices, faces=faces, method=module.NAME, params=params, seed=seed, info=info)
