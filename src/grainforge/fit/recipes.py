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


def recipe_text(method: str, params: Mapping[str, Any], sand: Sand, *, count: int, seed: int,
                fmt: str = "stl", header: str = "") -> str:
    """A ``grainforge batch`` recipe: ``params`` and the sand's size distribution as a count grading."""
    sieves, passing = grading(sand.equivalent_diameter)
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    lines += [f"method = {_toml(method)}", f"count = {int(count)}", f"seed = {int(seed)}", f"format = {_toml(fmt)}",
              "", "[params]"]
    lines += [f"{k} = {_toml(v)}" for k, v in params.items()]
    lines += ["", "[size]", 'definition = "equivalent"', f"sieves_mm = {_toml(sieves)}",
              f"percent_passing = {_toml(passing)}", 'basis = "count"', ""]
    return "\n".join(lines)


def twin_recipe_text(spec: MethodFit, grains: Sequence[Mapping[str, Any]], size_mm: Sequence[float], *,
                     seed: int, fmt: str = "stl", header: str = "", seeds: Sequence[int] | None = None) -> str:
    """A ``grainforge batch`` recipe of twins: ``spec.fixed`` in ``[params]``, each grain's own parameters and
    size in ``[grains]`` (one value per grain, in grain order), and each grain's seed when ``seeds`` is given
    and any differs from the one ``batch`` would give it (:func:`grain_seed`).

    Examples
    --------
    >>> from grainforge.fit import FITS
    >>> from grainforge.population import draw_grain, parse_recipe
    >>> text = twin_recipe_text(FITS["rf"], [FITS["rf"].grain_params(np.full(5, 0.5))], [0.4], seed=1)
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
    """The seed ``batch`` gives grain ``index`` of a recipe with root seed ``root``."""
    from ..population import grain_stream

    return int(grain_stream(root, index).integers(0, 2**63))


def reseed_seed(root: int, index: int, attempt: int) -> int:
    """Twin ``index``'s seed at reseed try ``attempt`` (from 0) of a fit with root seed ``root`` (written to the
    recipe's ``[grains] seed`` column when kept).

    Examples
    --------
    >>> a = reseed_seed(2024, 3, 0)
    >>> a == reseed_seed(2024, 3, 0), a != reseed_seed(2024, 3, 1), a != grain_seed(2024, 3)
    (True, True, True)
    """
    return int(np.random.default_rng([int(root), int(index), 1 + int(attempt), 0x5EED]).integers(0, 2**63))
