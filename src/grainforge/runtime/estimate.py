"""Up-front estimates of how long and how much memory a job takes, to refuse what cannot finish.

A request is refused *before any work* when its estimate exceeds a day of
computing or the memory of the machine, and the message gives the estimate
and the option that reduces it.  Below that, long jobs run with a progress
bar and an ETA.  The per-grain costs are rough models fitted to the timings
in docs/benchmarks.md (one core of the project machine); they are meant to
tell a two-hour job from a two-year one, not to predict within 10 %.

Examples
--------
>>> from grainforge.methods import get
>>> t = grain_seconds("fso", get("fso").Params())
>>> 0.005 < t < 1.0
True
>>> check_job(10, t, what="10 fso grains", option="{count}", setting="count") == 10 * t  # fine: returns the estimate
True
>>> check_job(10**9, t, what="1000000000 fso grains", option="{count}", setting="count")
Traceback (most recent call last):
...
grainforge.runtime.estimate.TooLargeError: 1000000000 fso grains would take about 5 years of computing (1.6e+02 ms each; limit 1 day); lower count

(the command line says ``lower --count``: a setting written ``{name}`` and given as ``setting`` is named by its
option there, :mod:`grainforge.errors`).
"""

from __future__ import annotations

import os
from typing import Any

from ..errors import InputError

__all__ = ["SECONDS_LIMIT", "grain_seconds", "check_job", "check_memory", "machine_memory", "duration",
           "TooLargeError", "icosphere_vertices", "dem_template_seconds"]

#: longest job accepted (seconds of computing on the given workers)
SECONDS_LIMIT = 24 * 3600.0

#: FSO kernel cost per vertex and term (s) at the default 40 × 40 terms; docs/benchmarks.md measures 2.3–2.7 ns
FSO_TERM_SECONDS = 3e-9
#: growth of the per-term cost with the number of terms T: (T / 1600)^0.6, fitted to 2.7 ns at 1,600 terms and
#: 43 ns (CPU) at 400 × 400 = 160,000 terms (subdivisions 5, gamma 1.05, measured under load)
FSO_TERM_EXPONENT = 0.6
#: per-vertex cost of the solid check, centring, scaling, manifest descriptors and export (s)
VERTEX_SECONDS = 1e-5
#: fixed cost per grain (s)
GRAIN_SECONDS = 5e-3
#: DPA cost per primary particle (s): 100,000 primaries took 31 s
DPA_PRIMARY_SECONDS = 4e-4

#: DEM template costs on one core, measured by benchmarks/bench_dem_templates.py on 2 mm angular and CRI
#: grains of 20,480 faces: reading, checking, mass properties and the greedy clump (or the hull) (s)
DEM_TEMPLATE_SECONDS = 0.08
#: one L-BFGS-B iteration of the clump refinement: a fixed part and a part per sphere (s)
DEM_REFINE_ITERATION_SECONDS = 1.7e-3
DEM_REFINE_SPHERE_SECONDS = 1.5e-4
#: the greedy placement stops where another sphere adds no coverage: 58-67 spheres on the benchmark
#: grains for any --spheres above that, so the refinement cost stops growing near this count
DEM_REFINE_SPHERES_CAP = 100
#: level set: seconds = coefficient x nodes^exponent (exact distances to the mesh; fitted to 8.9 s at
#: 20,384 nodes and 137 s at ~800,000)
LEVELSET_NODE_COEFFICIENT = 5.5e-3
LEVELSET_NODE_EXPONENT = 0.745


class TooLargeError(InputError):
    """A request that would take longer than :data:`SECONDS_LIMIT` or more memory than the machine has."""


def icosphere_vertices(subdivisions: int) -> int:
    """10·4^s + 2."

    Parameters
    ----------
    subdivisions : int
        Subdivisions s of the geodesic sphere.

    Returns
    -------
    int
        Its number of vertices, 10·4^s + 2.

    Examples
    --------
    >>> icosphere_vertices(5)
    10242
    """
    return 10 * 4 ** int(subdivisions) + 2


def grain_seconds(method: str, params: Any) -> float:
    """Rough seconds to generate, measure and encode one grain of ``method`` on one core.

    Parameters
    ----------
    method : str
        Method name (``"fso"``, ``"dpa"``, ...; others cost by vertices only).
    params : object
        The method's parameters; ``subdivisions``, and for FSO ``ridges``/``frequencies``, for DPA
        ``primaries``/``smooth`` are read when present.

    Returns
    -------
    float
        Seconds.
    """
    s = getattr(params, "subdivisions", None)
    v = icosphere_vertices(s) if isinstance(s, int) else 2562
    t = GRAIN_SECONDS + VERTEX_SECONDS * v
    if method == "fso":
        m = getattr(params, "ridges", 40) or 40
        n = getattr(params, "frequencies", 40) or 40
        t += FSO_TERM_SECONDS * v * m * n * max(1.0, m * n / 1600) ** FSO_TERM_EXPONENT
    elif method == "dpa":
        n = int(getattr(params, "primaries", 200) or 200)
        smooth = int(getattr(params, "smooth", 0) or 0)
        t = GRAIN_SECONDS + DPA_PRIMARY_SECONDS * n * 4**smooth
    return float(t)


def dem_template_seconds(shape: str, *, spheres: int = 30, refine_iterations: int = 0,
                         spacing: float = 0.05) -> float:
    """Rough upper bound of the seconds one grain's DEM template takes on one core.

    The clump refinement is counted at its full ``refine_iterations`` (L-BFGS-B
    often converges sooner: an upper bound); the level-set grid is that of a
    compact grain (about 1.4 d_eq across each way, plus the padding).

    Parameters
    ----------
    shape : str
        ``"clump"``, ``"levelset"`` or another template kind (the fixed cost only).
    spheres : int, default 30
        Clump spheres asked for (the refinement's cost stops growing at :data:`DEM_REFINE_SPHERES_CAP`).
    refine_iterations : int, default 0
        L-BFGS-B iterations of the clump refinement.
    spacing : float, default 0.05
        Level-set grid spacing, in equivalent diameters.

    Returns
    -------
    float
        Seconds.

    Examples
    --------
    >>> round(dem_template_seconds("clump"), 2)
    0.08
    >>> 5 < dem_template_seconds("clump", spheres=100, refine_iterations=1000) < 20
    True
    >>> 3 < dem_template_seconds("levelset") < 20
    True
    """
    t = DEM_TEMPLATE_SECONDS
    if shape == "clump":
        n = min(int(spheres), DEM_REFINE_SPHERES_CAP)
        t += int(refine_iterations) * (DEM_REFINE_ITERATION_SECONDS + DEM_REFINE_SPHERE_SECONDS * n)
    elif shape == "levelset":
        nodes = (1.4 / float(spacing) + 4) ** 3
        t += LEVELSET_NODE_COEFFICIENT * nodes ** LEVELSET_NODE_EXPONENT
    return float(t)


def duration(seconds: float) -> str:
    """``"3.2 h"``, ``"41 s"``, ``"1.9e+04 years"``.

    Parameters
    ----------
    seconds : float
        A duration (≥ 0).

    Returns
    -------
    str
        Two significant digits in the largest unit that fits (s, min, h, days, years).

    Examples
    --------
    >>> duration(41.0), duration(7200.0), duration(3e12)
    ('41 s', '2 h', '9.5e+4 years')
    """
    for unit, size in (("years", 365.25 * 86400), ("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            x = seconds / size
            return f"{x:.2g} {unit}" if x < 1e4 else f"{x:.2g} {unit}".replace("e+0", "e+")
    return f"{seconds:.2g} s"


def check_job(count: int, seconds_each: float, *, what: str, option: str, workers: int = 1,
              advice: str | None = None, setting: str | tuple[str, ...] | None = None) -> float:
    """Total seconds for ``count`` items of ``seconds_each`` on ``workers``; refuse beyond a day.

    The message ends "lower ``option``", or ``advice`` when given (e.g. "raise --spacing").

    Parameters
    ----------
    count : int
        Number of items.
    seconds_each : float
        Estimated seconds per item on one core.
    what : str
        How the message names the job (``"10 fso grains"``).
    option : str
        The option that reduces the job (``"--count"``).
    workers : int, default 1
        Processes sharing the work.
    advice : str, optional
        The message's last words instead of ``lower OPTION``.
    setting : str or tuple of str, optional
        The settings ``option`` or ``advice`` name as ``{name}`` (:class:`grainforge.errors.InputError`).

    Returns
    -------
    float
        The estimate in seconds (of wall time on ``workers``).

    Raises
    ------
    TooLargeError
        Naming the estimate and the ``option`` that reduces it.
    """
    total = float(count) * float(seconds_each) / max(int(workers), 1)
    if total > SECONDS_LIMIT:
        per = f"{duration(seconds_each)} each" if seconds_each >= 1 else f"{seconds_each * 1000:.2g} ms each"
        raise TooLargeError(
            f"{what} would take about {duration(total)} of computing ({per}"
            + (f" on {workers} workers" if workers > 1 else "") + f"; limit {_limit()}); " + (advice or f"lower {option}"),
            setting=setting)
    return total


def _limit() -> str:
    """The time limit as the messages say it (``1 day`` by default; tests may lower :data:`SECONDS_LIMIT`)."""
    return "1 day" if SECONDS_LIMIT == 24 * 3600.0 else duration(SECONDS_LIMIT)


def machine_memory() -> int:
    """Physical memory of this machine in bytes (24 GiB if it cannot be read).

    Returns
    -------
    int
        Bytes.
    """
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 24 * 1024**3


def check_memory(nbytes: float, *, what: str, option: str, fraction: float = 0.5,
                 setting: str | tuple[str, ...] | None = None) -> float:
    """Refuse when ``nbytes`` exceeds ``fraction`` of the machine's memory (the machine is shared).

    Parameters
    ----------
    nbytes : float
        Estimated bytes the job needs.
    what : str
        How the message names the job.
    option : str
        The option that reduces the memory.
    fraction : float, default 0.5
        Share of :func:`machine_memory` allowed.
    setting : str or tuple of str, optional
        The settings ``option`` names as ``{name}`` (:class:`grainforge.errors.InputError`).

    Returns
    -------
    float
        ``nbytes``.

    Raises
    ------
    TooLargeError
        Naming the estimate, the limit in GiB and ``option``.
    """
    limit = machine_memory() * fraction
    if nbytes > limit:
        raise TooLargeError(f"{what} would need about {nbytes / 1024**3:.3g} GiB of memory "
                            f"(limit {limit / 1024**3:.3g} GiB); lower {option}", setting=setting)
    return float(nbytes)
