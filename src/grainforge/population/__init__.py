"""Populations of grains: TOML recipes, per-grain seeds, and the runner (local processes, Dask).

The modules, by job:

- :mod:`grainforge.population.recipe`: a recipe's TOML text parsed and checked (:func:`load_recipe`,
  :func:`parse_recipe`, :class:`RecipeError` naming the field and its line); the format is described there.
- :mod:`grainforge.population.grains`: each grain's own random stream, its drawn parameters and size, and the
  grain made (:func:`draw_grain`, :func:`make_grain`); the seeds are described there.
- :mod:`grainforge.population.batch`: the runner (:func:`run_batch`): checks before any work, workers, the
  journal that ``--resume`` reads, the manifest and the report.
- :mod:`grainforge.population.distributions`: the parameter and size distributions a recipe draws from.
- :mod:`grainforge.population.generate`: a run of grains into a folder, with its manifest (``grainforge generate``).
- :mod:`grainforge.population.report`: a population's summary and figure.

The public names of ``recipe``, ``grains``, ``batch`` and ``distributions`` are re-exported here.
"""

from .batch import JOURNAL, PILOTS, check_extremes, check_recipe_size, existing_grains, run_batch
from .distributions import Distribution, FixedSize, GradingCurve, LognormalSize
from .grains import GrainResult, draw_grain, grain_stream, make_grain, size_quantile
from .recipe import DISTRIBUTIONS, GRAIN_COLUMNS, MAX_SIGMA, Recipe, RecipeError, field_line, load_recipe, parse_recipe

__all__ = [
    "RecipeError", "Distribution", "GradingCurve", "LognormalSize", "FixedSize", "Recipe", "load_recipe",
    "parse_recipe", "grain_stream", "draw_grain", "make_grain", "run_batch", "JOURNAL",
    "DISTRIBUTIONS", "GRAIN_COLUMNS", "MAX_SIGMA", "field_line", "size_quantile", "GrainResult", "PILOTS",
    "check_recipe_size", "check_extremes", "existing_grains",
]
