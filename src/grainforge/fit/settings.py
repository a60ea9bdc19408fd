"""Per-method settings: what a fit of each generator solves for, and the resolution it measures at.

A :class:`MethodFit` names a generator's per-grain :class:`Setting` s and
their ranges (the aspect's Zingg ratios are every method's), the parameters
every grain shares, and how setting values become a grain's own parameters;
:data:`FITS` holds the registered ones (``fit --method``).  Adding a method
is a few lines: :func:`register` a :class:`MethodFit`.

Resolution: generated grains are measured at min(voxels across,
``max_across``), by default the method's own cap (:attr:`MethodFit.max_across`:
:data:`MAX_VOXELS_ACROSS` where its grains' descriptors have converged with
resolution, none for ``fso``, whose fractal surface does not converge;
``benchmarks/fit_resolution.py``); the sand's own numbers are never rescaled.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .sand import DESCRIPTORS

#: generated grains of rf, cri and angular are measured at most this many voxels across: their descriptors have
#: converged there (within 0.005 of 300 voxels across; docs/fit.md, benchmarks/fit_resolution.py)
MAX_VOXELS_ACROSS = 150.0
#: ``max_across`` of :func:`grainforge.fit.run.fit_sand` and :func:`grainforge.fit.cost.check_fit_size` meaning "the
#: method's own cap"
METHOD_CAP = "method"


@dataclass(frozen=True)
class Setting:
    """One per-grain setting the inverse model solves for, with the range the design spans."""

    name: str
    low: float
    high: float


#: the aspect's Zingg ratios, a per-grain setting of every method (measured flatness and elongation follow
#: them closely, the surface shifts them a little)
ASPECT_SETTINGS = (Setting("elongation", 0.25, 1.0), Setting("flatness", 0.25, 1.0))


@dataclass(frozen=True)
class MethodFit:
    """How to fit one generator grain by grain.

    Attributes
    ----------
    method : str
        Generator name (must have an ``aspect`` L:I:S parameter).
    settings : tuple of Setting
        Per-grain settings besides the aspect's (``elongation``, ``flatness``,
        appended by :attr:`all_settings`).
    fixed : dict
        The recipe's ``[params]``: what every grain shares.
    params : callable
        Setting values (dict, the aspect's included) -> the grain's own
        parameters (the recipe's ``[grains]`` columns), ``aspect`` included.
    max_across : float or None
        The method's resolution cap: its grains are measured at most this
        many voxels across, where their descriptors have converged with
        resolution (``benchmarks/fit_resolution.py``); None: they do not
        converge, so they are measured at the sand's resolution.
    """

    method: str
    settings: tuple[Setting, ...]
    fixed: Mapping[str, Any]
    params: Callable[[Mapping[str, float]], dict]
    max_across: float | None = MAX_VOXELS_ACROSS

    @property
    def all_settings(self) -> tuple[Setting, ...]:
        return self.settings + ASPECT_SETTINGS

    @property
    def spread_step(self) -> bool:
        """Whether a population estimate measures its sensitivity to the settings' spread: only where the four
        descriptor means can determine every setting (rf's five they cannot: its surface settings' means are the
        starting population's along what the means do not see, spread and all), so that its cost is known up
        front (:func:`grainforge.fit.cost.fit_grains`, :func:`grainforge.fit.mean_settings.population_settings`)."""
        return len(self.all_settings) <= len(DESCRIPTORS)

    def values(self, u: np.ndarray) -> dict[str, float]:
        """Unit-box coordinates ``u`` (one per :attr:`all_settings`) -> setting values.

        Parameters
        ----------
        u : (p,) array_like
            One coordinate in [0, 1] per setting of :attr:`all_settings`, in that order (0: the setting's
            ``low``, 1: its ``high``).

        Returns
        -------
        dict of str to float
            Setting name -> value in the setting's own units (``low + u × (high − low)``).

        Examples
        --------
        >>> FITS["angular"].values([0.5, 0.0, 1.0, 0.0])
        {'rounding': 0.45, 'dent_depth': 0.0, 'elongation': 1.0, 'flatness': 0.25}
        """
        return {s.name: float(s.low + float(x) * (s.high - s.low)) for s, x in zip(self.all_settings, u)}

    def grain_params(self, u: np.ndarray) -> dict:
        """The grain's own parameters for unit-box coordinates ``u``, rounded as the recipe writes them.

        Parameters
        ----------
        u : (p,) array_like
            One coordinate in [0, 1] per setting of :attr:`all_settings`.

        Returns
        -------
        dict
            The generator's per-grain parameters (the recipe's ``[grains]`` columns, ``aspect`` L:I:S
            included), floats to 6 significant digits: what ``batch`` reads back from the recipe.

        Examples
        --------
        >>> FITS["angular"].grain_params([0.5, 0.0, 1.0, 0.0])
        {'rounding': 0.45, 'dent_depth': 0.0, 'aspect': [1.0, 1.0, 0.25]}
        """
        return _written(self.params(self.values(u)))


#: method name -> its :class:`MethodFit` (``fit --method``)
FITS: dict[str, MethodFit] = {}


def register(spec: MethodFit) -> MethodFit:
    """Make ``spec`` available to :func:`grainforge.fit.run.fit_sand` (replaces an earlier one of the same method).

    Parameters
    ----------
    spec : MethodFit
        How to fit its method; stored in :data:`FITS` under ``spec.method``.

    Returns
    -------
    MethodFit
        ``spec`` itself (so that a registration can be written as an assignment).
    """
    FITS[spec.method] = spec
    return spec


def _aspect(v: Mapping[str, float]) -> list[float]:
    return [1.0, v["elongation"], v["elongation"] * v["flatness"]]


def _descriptor_params(v: Mapping[str, float]) -> dict:
    # D2 = 0: the aspect alone sets the form (a per-grain D2 deforms it at random, which the measured
    # flatness and elongation then follow only loosely); D3 (irregularity) and D8 (roughness) per grain
    return {"descriptors": [0.0, v["irregularity"], v["roughness"]], "aspect": _aspect(v)}


_DESCRIPTOR_SETTINGS = (Setting("irregularity", 0.0, 0.25), Setting("roughness", 0.0, 0.04))
#: rf's irregularity decay B1 (every grain: the generator's default); its roughness decay B2 is a per-grain
#: setting: a flatter roughness spectrum (B2 towards 0) puts the roughness into finer surface detail, which
#: lowers sphericity (surface area) far more than convexity, so B2 trades sphericity at a fixed convexity and
#: aspect (docs/fit.md), which D3 and D8 alone cannot
RF_DECAY_B1 = -5.0 / 3.0


def _rf_params(v: Mapping[str, float]) -> dict:
    return {**_descriptor_params(v), "decay": [RF_DECAY_B1, v["roughness_decay"]]}


register(MethodFit("rf", _DESCRIPTOR_SETTINGS + (Setting("roughness_decay", -2.5, 0.0),), {"subdivisions": 5},
                   _rf_params))


register(MethodFit("cri", _DESCRIPTOR_SETTINGS, {"subdivisions": 5}, _descriptor_params))


register(MethodFit(
    "fso", (Setting("amplitude", 0.0, 0.15), Setting("fractal_dimension", 2.0, 2.8)),
    {"surface": "seamless", "subdivisions": 5},
    lambda v: {"amplitude": v["amplitude"], "fractal_dimension": v["fractal_dimension"], "aspect": _aspect(v)},
    # no cap: the FSO overlay's fractal surface keeps gaining area as the voxels resolve it (sphericity 0.044
    # lower at 300 voxels across than at 150, still 0.009 lower than at 250; docs/fit.md), so fso grains are
    # measured at the sand's resolution
    max_across=None,
))


register(MethodFit(
    # crushed, angular grains (Hostun-like): a 7-facet core, so that sphericity falls well below convexity as it
    # does in crushed sands; edge rounding steers sphericity, dent depth convexity (6 dents of width 0.5 rad);
    # a fine texture (FSO overlay of RMS 0.02); the grain stretched to its aspect's inertia ellipsoid, so that
    # its measured flatness and elongation are its settings' (with facets tangent to the aspect's ellipsoid, a
    # 7-facet core's own random shape sets them: at fixed settings they scatter by sd 0.1 from seed to seed)
    "angular", (Setting("rounding", 0.0, 0.9), Setting("dent_depth", 0.0, 0.7)),
    {"facets": 7, "dents": 6, "dent_width": 0.5, "roughness": 0.02, "length_ratio": 2.0, "subdivisions": 5,
     "aspect_by": "inertia"},
    lambda v: {"rounding": v["rounding"], "dent_depth": v["dent_depth"], "aspect": _aspect(v)},
))


def _written(v: Any) -> Any:
    """``v`` as the recipe writes it (floats to 6 significant digits, :func:`grainforge.fit.recipes._toml`): what
    ``batch`` reads back."""
    if isinstance(v, float):
        return float(f"{v:.6g}")
    if isinstance(v, (list, tuple)):
        return [_written(x) for x in v]
    if isinstance(v, dict):
        return {k: _written(x) for k, x in v.items()}
    return v


def resolve_cap(method: str, max_across: float | str | None) -> float | None:
    """The resolution cap a fit of ``method`` measures at: ``max_across`` itself, or with :data:`METHOD_CAP`
    the method's own (:attr:`MethodFit.max_across`); None: uncapped.

    Parameters
    ----------
    method : str
        A method of :data:`FITS`.
    max_across : float, str or None
        A cap in voxels across, :data:`METHOD_CAP` (``"method"``), or None or 0 for none.

    Returns
    -------
    float or None
        The cap in voxels across; None: grains are measured at the sand's resolution.

    Raises
    ------
    KeyError
        If ``max_across`` is :data:`METHOD_CAP` and ``method`` is not in :data:`FITS`.

    Examples
    --------
    >>> resolve_cap("rf", METHOD_CAP), resolve_cap("fso", METHOD_CAP), resolve_cap("fso", 200.0)
    (150.0, None, 200.0)
    """
    if max_across == METHOD_CAP:
        return FITS[method].max_across
    return float(max_across) if max_across else None
