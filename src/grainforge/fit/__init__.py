"""Fit a generated population to a real sand, grain by grain (docs/design/algorithms.md §8, docs/fit.md).

Every generated grain is the *twin* of one sand grain: its size, and generator settings chosen so that,
measured as the Sand Atlas measures, it has that grain's true sphericity, convexity, flatness and elongation.
The modules, by job:

- :mod:`grainforge.fit.sand`: the sand's table (Sand Atlas CSV), read, checked and written.
- :mod:`grainforge.fit.settings`: per-method settings (:class:`MethodFit`, :data:`FITS`) and resolution caps.
- :mod:`grainforge.fit.cost`: the grains, time and memory a fit takes, refused up front when too large.
- :mod:`grainforge.fit.recipes`: the recipes a fit writes, and the seeds ``batch`` gives their grains.
- :mod:`grainforge.fit.made_grains`: grains made and measured, one by one or on a pool (:class:`MeasurePool`).
- :mod:`grainforge.fit.designs`: a method's design of measured grains, cached on disk.
- :mod:`grainforge.fit.twins`: the inverse model from descriptors to settings.
- :mod:`grainforge.fit.mean_settings`: the sand's mean settings from its descriptors' means.
- :mod:`grainforge.fit.refine`: the twins' settings refined, reseeded and made.
- :mod:`grainforge.fit.acceptance`: when a fit passes (KS, means, Spearman, twins within tolerance).
- :mod:`grainforge.fit.run`: :func:`fit_sand`, the fit's phases in order, and its :class:`FitResult`.
- :mod:`grainforge.fit.outputs`: the files and the figure a fit writes.

Every public name of these modules but :mod:`grainforge.fit.twins`'s is re-exported here.
"""

from ..analysis.atlas import OPENING_RADIUS
from .acceptance import CORR_TOL, KS_MAX, MEAN_TOL, PAIRS, TWIN_SHARE, TWIN_TOL, compare, spearman
from .cost import (
    EXPECTED_MEASUREMENTS,
    FIT_ACROSS_REF,
    FIT_GRAIN_SECONDS,
    FIT_MAKE_SECONDS,
    FIT_ROW_BYTES,
    FIT_VOXEL_BYTES,
    FIT_VOXEL_SECONDS,
    MAX_MINUTES,
    RESEED_MOST,
    RESEED_SHARE,
    check_fit_size,
    fit_grains,
    measured_grain_seconds,
)
from .designs import (
    DESIGN_ACROSS_LOW,
    DESIGN_GRAINS,
    DESIGN_SEED,
    DESIGN_VERSION,
    IDENTIFIABLE_R2,
    Design,
    design,
    design_path,
    setting_identifiability,
)
from .made_grains import MeasurePool, measure_made_grain, measure_settings
from .mean_settings import (
    DETERMINED_MIN,
    OPENING_ROUNDS,
    OPENING_SECANT_MIN,
    OPENING_TRUST,
    POPULATION_GRAINS,
    POPULATION_ROUNDS,
    POPULATION_SLOPES,
    SLOPE_CHOICES,
    SLOPE_GRAINS,
    SLOPE_STEP,
    SLOPES_MEASURED_FROM,
    SPREAD_DOUBT,
    Population,
    population_settings,
    slopes_for,
)
from .outputs import OUTPUTS, STAT_COLUMNS, TWIN_COLUMNS, fit_figure, stat_rows, twin_rows, write_outputs
from .recipes import GRADING_PERCENTS, grading, grain_seed, recipe_text, reseed_seed, twin_recipe_text
from .refine import REFINE_SD, REFINE_TOL, REFUSED_TRIES, RESEED
from .run import FitResult, choose_method, choose_rows, fit_sand
from .sand import (
    COLUMNS,
    DESCRIPTORS,
    MIN_GRAINS,
    OPENING_COLUMN,
    SAND_HEADER,
    SCAN_COLUMNS,
    SPHERICITY_MAX,
    VOXEL_COLUMN,
    VOXELS_ACROSS,
    Sand,
    check_sand,
    measured_across,
    read_sand,
    scan_sand_text,
    uses_opening,
    write_sand,
)
from .settings import (
    ASPECT_SETTINGS,
    FITS,
    MAX_VOXELS_ACROSS,
    METHOD_CAP,
    RF_DECAY_B1,
    MethodFit,
    Setting,
    register,
    resolve_cap,
)

__all__ = [
    "DESCRIPTORS", "COLUMNS", "VOXEL_COLUMN", "OPENING_COLUMN", "SPHERICITY_MAX", "MIN_GRAINS", "VOXELS_ACROSS",
    "Sand", "read_sand", "SAND_HEADER", "write_sand", "SCAN_COLUMNS", "scan_sand_text", "check_sand", "measured_across", "uses_opening",
    "OPENING_RADIUS", "MAX_VOXELS_ACROSS", "METHOD_CAP", "Setting", "ASPECT_SETTINGS", "MethodFit", "FITS", "register",
    "RF_DECAY_B1", "resolve_cap", "RESEED_SHARE", "RESEED_MOST", "FIT_GRAIN_SECONDS", "FIT_VOXEL_SECONDS",
    "FIT_ACROSS_REF", "FIT_MAKE_SECONDS", "EXPECTED_MEASUREMENTS", "FIT_VOXEL_BYTES", "FIT_ROW_BYTES", "MAX_MINUTES",
    "fit_grains", "check_fit_size", "measured_grain_seconds", "GRADING_PERCENTS", "grading", "recipe_text", "twin_recipe_text",
    "grain_seed", "reseed_seed", "measure_made_grain", "measure_settings", "MeasurePool", "DESIGN_GRAINS",
    "DESIGN_ACROSS_LOW", "DESIGN_SEED", "DESIGN_VERSION", "design_path", "Design", "design", "IDENTIFIABLE_R2",
    "setting_identifiability", "OPENING_ROUNDS", "OPENING_TRUST", "OPENING_SECANT_MIN", "POPULATION_GRAINS",
    "POPULATION_ROUNDS", "POPULATION_SLOPES", "SLOPE_CHOICES", "SLOPES_MEASURED_FROM", "SLOPE_GRAINS", "SLOPE_STEP",
    "SPREAD_DOUBT", "slopes_for", "DETERMINED_MIN", "Population", "population_settings", "REFINE_TOL", "REFINE_SD",
    "REFUSED_TRIES", "RESEED", "KS_MAX", "MEAN_TOL", "CORR_TOL", "TWIN_TOL", "TWIN_SHARE", "PAIRS", "spearman",
    "compare", "FitResult", "choose_rows", "choose_method", "fit_sand", "TWIN_COLUMNS", "twin_rows", "STAT_COLUMNS",
    "stat_rows", "fit_figure", "OUTPUTS", "write_outputs",
]
