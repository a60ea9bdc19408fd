"""The recipes a fit writes (``grainforge batch`` runs them as they are), and the seeds ``batch`` gives their grains.

:func:`recipe_text` writes a recipe of parameters and the sand's size
distribution as a grading; :func:`twin_recipe_text` a recipe of twins, each
grain's own parameters, size and (where reseeding kept another) seed in its
``[grains]`` table.  :func:`grain_seed` is the seed ``batch`` gives a grain,
:func:`reseed_seed` the ones a twin tries instead.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .sand import Sand
from .settings import MethodFit


def _toml(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(float(f"{v:.6g}"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} to TOML")


#: percent passing at which the sand's size quantiles become the recipe's sieves (finer in the tails,
#: where a log-linear grading between few sieves would spread grains over sizes the sand barely has)
GRADING_PERCENTS = (0, 0.5, 1, 2, 3, 5, 7.5, *range(10, 95, 5), 92.5, 95, 97, 98, 99, 99.5, 100)


def grading(d_eq_um: np.ndarray, percents: Sequence[float] = GRADING_PERCENTS) -> tuple[list[float], list[float]]:
    """Sieves (mm) and count percent passing at the sizes' quantiles ``percents`` (duplicates dropped).

    Parameters
    ----------
    d_eq_um : (n,) array_like
        Grains' equivalent diameters, µm (a sand table's unit).
    percents : sequence of float
        Percent passing (0 to 100, increasing) at which the sizes' quantiles become sieves.

    Returns
    -------
    sieves_mm : list of float
        Sieve apertures in mm (a recipe's unit), increasing, to 6 significant digits.
    passing : list of float
        Count percent passing at each sieve, the last 100.

    Examples
    --------
    >>> grading(np.array([100.0, 200.0, 300.0, 400.0, 500.0]), (0, 50, 100))
    ([0.1, 0.3, 0.5], [0.0, 50.0, 100.0])
    """
    q = np.asarray(percents, dtype=np.float64)
    sieves = np.percentile(np.asarray(d_eq_um) / 1000.0, q)
    keep = np.r_[True, np.diff(sieves) > 1e-9 * sieves[-1]]
    sieves, q = sieves[keep], q[keep]
    q[-1] = 100.0
    return [float(f"{s:.6g}") for s in sieves], [float(x) for x in q]


def recipe_text(method: str, params: Mapping[str, Any], *, sand: Sand, count: int, seed: int,
                fmt: str = "stl", header: str = "") -> str:
    """A ``grainforge batch`` recipe: ``params`` and the sand's size distribution as a count grading.

    Nothing random is drawn here: ``seed`` is written as the recipe's root seed, from which ``batch``
    draws each grain's own seed and parameters (:func:`grainforge.population.grains.grain_stream`).

    Parameters
    ----------
    method : str
        The generator's name.
    params : mapping
        The recipe's ``[params]``: each a fixed value or a distribution table.
    sand : Sand
        Its equivalent diameters (µm) become the ``[size]`` grading (:func:`grading`), in mm.
    count : int
        Grains of the recipe.
    seed : int
        The recipe's root seed (non-negative, below 2⁶³), written as ``seed = ...``.
    fmt : str
        The recipe's mesh ``format`` (``stl``, ``obj``, ``ply``).
    header : str
        Comment lines written first, each prefixed with ``#``.

    Returns
    -------
    str
        The recipe's TOML text.

    Examples
    --------
    >>> from grainforge.fit import DESCRIPTORS
    >>> from grainforge.population import parse_recipe
    >>> sand = Sand("s.csv", 7.3, np.linspace(300.0, 500.0, 60), {k: np.full(60, 0.8) for k in DESCRIPTORS})
    >>> r = parse_recipe(recipe_text("rf", {"subdivisions": 3}, sand=sand, count=10, seed=5))
    >>> r.count, r.seed, r.size.sieves_mm[0], r.size.sieves_mm[-1]
    (10, 5, 0.3, 0.5)
    """
    sieves, passing = grading(sand.equivalent_diameter)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(method)}", f"count = {int(count)}", f"seed = {int(seed)}", f"format = {_toml(fmt)}",
              "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in params.items()]
    lines += ["", "[size]", 'definition = "equivalent"', f"sieves_mm = {_toml(sieves)}",
              f"percent_passing = {_toml(passing)}", 'basis = "count"', ""]
    return "\n".join(lines)


def twin_recipe_text(spec: MethodFit, grains: Sequence[Mapping[str, Any]], *, size_mm: Sequence[float],
                     seed: int, fmt: str = "stl", header: str = "", seeds: Sequence[int] | None = None) -> str:
    """A ``grainforge batch`` recipe of twins: ``spec.fixed`` in ``[params]``, each grain's own parameters and
    size in ``[grains]`` (one value per grain, in grain order), and each grain's seed when ``seeds`` is given
    and any differs from the one ``batch`` would give it (:func:`grain_seed`).

    Nothing random is drawn here: ``seed`` and ``seeds`` are written into the recipe.

    Parameters
    ----------
    spec : MethodFit
        The method fitted: its name and ``fixed`` parameters.
    grains : sequence of mapping
        Each grain's own parameters (:meth:`grainforge.fit.settings.MethodFit.grain_params`), in grain order;
        every one with the same keys.
    size_mm : sequence of float
        Each grain's equivalent diameter, mm (keyword-only).
    seed : int
        The recipe's root seed (non-negative, below 2⁶³), written as ``seed = ...``.
    fmt : str
        The recipe's mesh ``format``.
    header : str
        Comment lines written first, each prefixed with ``#``.
    seeds : sequence of int, optional
        Each grain's seed; written as the ``[grains] seed`` column only where one differs from
        :func:`grain_seed` (``seed``, its index).

    Returns
    -------
    str
        The recipe's TOML text.

    Examples
    --------
    >>> from grainforge.fit import FITS
    >>> from grainforge.population import draw_grain, parse_recipe
    >>> text = twin_recipe_text(FITS["rf"], [FITS["rf"].grain_params(np.full(5, 0.5))], size_mm=[0.4], seed=1)
    >>> _, params, size = draw_grain(parse_recipe(text), 0)
    >>> params.descriptors, params.decay, params.aspect, size
    ((0.0, 0.125, 0.02), (-1.66667, -1.25), (1.0, 0.625, 0.390625), 0.4)
    """
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(spec.method)}", f"count = {len(grains)}", f"seed = {int(seed)}",
              f"format = {_toml(fmt)}", "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in spec.fixed.items()]
    lines += ["", "[size]", 'definition = "equivalent"', "",
              "[grains]  # one value per grain, in grain order: each the twin of one sand grain (fit.csv)",
              f"size_mm = {_toml([float(s) for s in size_mm])}"]
    for name in grains[0]:
        lines.append(f"{name} = {_toml([g[name] for g in grains])}")
    if seeds is not None and any(int(s) != grain_seed(seed, i) for i, s in enumerate(seeds)):
        lines.append(f"seed = [{', '.join(str(int(s)) for s in seeds)}]")
    return "\n".join(lines) + "\n"


def grain_seed(root: int, index: int) -> int:
    """The seed ``batch`` gives grain ``index`` of a recipe with root seed ``root``.

    Parameters
    ----------
    root : int
        The recipe's root seed (its ``seed = ...``).
    index : int
        The grain's index in the recipe, from 0.

    Returns
    -------
    int
        In [0, 2⁶³): the first draw of the grain's own stream
        (:func:`grainforge.population.grains.grain_stream`), as :func:`grainforge.population.grains.draw_grain`
        draws it.

    Examples
    --------
    >>> from grainforge.population import draw_grain, parse_recipe
    >>> r = parse_recipe('method = "fso"\\ncount = 3\\nseed = 9\\n[size]\\nmm = 1.0\\n')
    >>> draw_grain(r, 2)[0] == grain_seed(9, 2)
    True
    """
    from ..population import grain_stream

    return int(grain_stream(root, index).integers(0, 2**63))


def reseed_seed(root: int, index: int, attempt: int) -> int:
    """Twin ``index``'s seed at reseed try ``attempt`` (from 0) of a fit with root seed ``root`` (written to the
    recipe's ``[grains] seed`` column when kept).

    Parameters
    ----------
    root : int
        The fit's root seed (its recipe's ``seed``).
    index : int
        The twin's index in the recipe, from 0.
    attempt : int
        The reseed try, from 0.

    Returns
    -------
    int
        In [0, 2⁶³), from the stream of ``SeedSequence([root, index, 1 + attempt, 0x5EED])``: distinct from
        the seed ``batch`` gives the grain and from every other try's.

    Examples
    --------
    >>> a = reseed_seed(2024, 3, 0)
    >>> a == reseed_seed(2024, 3, 0), a != reseed_seed(2024, 3, 1), a != grain_seed(2024, 3)
    (True, True, True)
    """
    from ..rng import as_generator

    stream = as_generator(np.random.SeedSequence([int(root), int(index), 1 + int(attempt), 0x5EED]))
    return int(stream.integers(0, 2**63))
