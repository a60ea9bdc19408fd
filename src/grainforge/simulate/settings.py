"""Settings of the virtual bulk tests, the scene dictionary the engine reads, and the up-front estimate."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InputError
from ..params import param, validate

__all__ = ["TESTS", "GrainSettings", "Settings", "TriaxialSettings", "QUICK", "QUICK_REPOSE", "QUICK_TRIAXIAL",
           "QUICK_TRIAXIAL_LIGGGHTS", "quick_settings", "scene_settings", "check_size", "MIN_TRIAXIAL_GRAINS", "check_triaxial_run", "triaxial_steps"]

#: the virtual tests under gravity (their scene settings: :func:`scene_settings`)
TESTS = ("repose", "tilt")


@dataclass(frozen=True)
class GrainSettings:
    """The settings every virtual test shares: the grains, their material and contact, the seeds (SI units
    unless stated).

    The same settings apply to every shape in a comparison.
    """

    grains: int = param(200, "grains in the test (drawn from the population's templates)", kind="int",
                        low=2, high=20000)
    templates: int = param(40, "distinct grains made into clumps; the test draws from them with replacement "
                           "and random orientations", kind="int", low=1, high=20000)
    spheres: int = param(10, "spheres per clump, as for grainforge dem (grainforge.dem.clump; more = closer to the "
                         "mesh, slower; one sphere per grain: --as-spheres)", kind="int", low=2, high=1000)
    size: float | None = param(None, "equivalent diameter every grain is scaled to", unit="mm", low=0.01,
                               high=1000, optional=True,
                               shown_default="the files' own size in mm, or the recipe's sizes")
    density: float = param(1180.0, "grain density; 1180 is a PolyJet photopolymer, as the paper's printed grains",
                           unit="kg/m³", low=1.0, high=30000.0)
    young: float = param(1e6, "contact modulus E: normal stiffness k_n = E·r of a sphere contact", unit="Pa",
                         low=1e3, high=1e11)
    poisson: float = param(0.3, "tangential/normal stiffness ratio k_s/k_n", low=0.0, high=1.0, low_open=True)
    friction: float = param(0.5, "contact friction coefficient μ (the same for grains, base and walls)",
                            low=0.0, high=5.0)
    damping: float = param(0.3, "Yade's local (non-viscous) damping, the same for every shape", low=0.0,
                           high=0.9)
    rolling_friction: float = param(0.0, "rolling resistance μ_r: a contact's rolling moment is limited to "
                                    "μ_r·F_n·r, r the smaller contact sphere's radius (0: none; clumps and "
                                    "spheres only; docs/simulate.md, Rolling resistance)", low=0.0, high=1.0)
    seeds: int = param(3, "independent runs (seeds seed, seed+1, ...); the angle is reported with its spread",
                       kind="int", low=1, high=100)
    seed: int = param(0, "first seed", kind="int", low=0, high=2**31 - 1)

    def __post_init__(self):
        validate(self)


@dataclass(frozen=True)
class Settings(GrainSettings):
    """Settings of a virtual bulk test under gravity (angle of repose, tilt table), SI units unless stated."""

    base_roughness: float = param(0.3, "radius of the fixed spheres of the rough base, in mean grain diameters",
                                  low=0.05, high=2.0)
    tilt_step: float = param(0.5, "tilt increment of the tilt test", unit="deg", low=0.05, high=5.0)
    tilt_start: float = param(10.0, "first tilt angle of the tilt test", unit="deg", low=0.0, high=60.0)


#: the repose cylinder's lift speed in Yade, in √(g d) (d the mean equivalent diameter; LIGGGHTS removes it at once)
LIFT_SPEED = 0.5
#: the tilt test's hold at each tilt angle, in √(d/g)
TILT_HOLD = 8.0

#: settings of ``simulate tilt --quick``: a few tens of grains, a minute a run (plumbing, not a measurement)
QUICK = dict(grains=30, templates=6, spheres=6, seeds=1, tilt_step=1.0, tilt_start=15.0)
#: settings of ``simulate repose --quick``: the fewest grains whose heap has a slope to measure. A heap stands
#: about 2.4 grains high at 120 rough spheres (μ = 0.5) and 2.2 at 80, where the rings between 20 % and 80 % of
#: its height are a shelf (no angle); 30 grains make no heap at all
QUICK_REPOSE = {**QUICK, "grains": 120}


def quick_settings(test: str, shape: str = "clump", engine: str = "yade") -> dict:
    """The settings ``--quick`` gives a virtual test (those not set otherwise).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    engine : {"yade", "liggghts"}
        The engine (a LIGGGHTS triaxial box shears slower: :data:`QUICK_TRIAXIAL_LIGGGHTS`).
    shape : {"clump", "levelset"}
        The grains' representation (a level-set tilt needs a wider layer:
        :func:`grainforge.simulate.levelset_scenes.quick_levelset`; a level-set repose keeps :data:`QUICK`'s
        grains, a heap too small to measure, for its cost).

    Returns
    -------
    dict
        Setting name to value: :data:`QUICK_TRIAXIAL` (:data:`QUICK_TRIAXIAL_LIGGGHTS`), :data:`QUICK_REPOSE` or
        :data:`QUICK`.

    Examples
    --------
    >>> quick_settings("repose")["grains"], quick_settings("tilt")["grains"], quick_settings("triaxial")["grains"]
    (120, 30, 100)
    >>> quick_settings("repose", "levelset")["grains"], quick_settings("tilt", "levelset")["grains"]
    (30, 49)
    """
    if test == "triaxial":
        return dict(QUICK_TRIAXIAL_LIGGGHTS if engine == "liggghts" else QUICK_TRIAXIAL)
    if shape == "levelset":
        from .levelset_scenes import quick_levelset

        return {**QUICK, **quick_levelset(test, shape)}
    return dict(QUICK_REPOSE if test == "repose" else QUICK)


#: the densest solid fraction a triaxial specimen is assumed to reach (random close packing of spheres, 0.64)
DENSEST_FRACTION = 0.64
#: a triaxial cell is at least this many mean grain diameters wide when shearing starts
MIN_CELL_DIAMETERS = 4.0
#: fewest grains of a triaxial specimen: a cube of MIN_CELL_DIAMETERS diameters at DENSEST_FRACTION (79)
MIN_TRIAXIAL_GRAINS = math.ceil(MIN_CELL_DIAMETERS ** 3 * DENSEST_FRACTION / (math.pi / 6.0))


@dataclass(frozen=True)
class TriaxialSettings(GrainSettings):
    """Settings of the drained triaxial test in a periodic cell (``grainforge simulate triaxial``).

    The contacts are a hundred times stiffer than the gravity tests' (``young`` 10⁸ Pa): at the default
    confining stress the stiffness number k_n / (p′ d) is about 10³, so overlaps stay near 0.1 % of a grain.
    """

    young: float = param(1e8, "contact modulus E: normal stiffness k_n = E·r of a sphere contact; 100 times the "
                         "gravity tests' (stiffness number k_n/(σ′₃·d) about 10³ at 20 kPa)", unit="Pa", low=1e3,
                         high=1e11, shown_default="1e8")
    confining_kpa: float = param(20.0, "effective confining stress σ′₃ of the isotropic compaction and of the "
                                 "drained shearing (the paper's test: 20 kPa)", unit="kPa", low=0.0, high=1e4,
                                 low_open=True)
    axial_strain: float = param(0.25, "axial strain at the end of the shearing (compression positive)", low=0.0,
                                high=1.0, low_open=True, high_open=True)
    packing: str = param("dense", "dense: isotropic compaction without friction; loose: compaction with the "
                         "contact friction (the void ratio reached is reported)", kind="str",
                         choices=("dense", "loose"))
    inertial_number: float = param(1e-3, "inertial number I = ε̇·d·√(ρ/σ′₃) that sets the axial strain rate "
                                   "(quasi-static below about 1e-3)", low=1e-6, high=0.1)


#: settings of ``simulate triaxial --quick``: the fewest grains a periodic cell takes, a quarter of the shearing at
#: five times the default strain rate (about a minute per run; plumbing, not a measurement). At I = 1e-2 Yade's
#: cell let the lateral stress of the quick rough spheres stray 6 % (median), failing the run's own 5 % check; at
#: 5e-3 both paper presets pass it (a dense specimen's few jam-and-release bursts are left to the median)
QUICK_TRIAXIAL = dict(grains=MIN_TRIAXIAL_GRAINS + 21, templates=6, spheres=6, seeds=1, axial_strain=0.06,
                      inertial_number=5e-3)
#: ``simulate triaxial --quick --engine liggghts``: the same at I = 2e-3: the walls'
#: servo follows the specimen through its contacts with the walls; at I = 1e-2 the lateral stress strays 7-9 %
#: (median), at 2e-3 about 1 %
QUICK_TRIAXIAL_LIGGGHTS = {**QUICK_TRIAXIAL, "inertial_number": 2e-3}


#: inertial number of the triaxial compaction's largest strain rate (the servo slows it near the goal)
COMPACTION_INERTIAL_NUMBER = 1e-2
#: the triaxial scene's time step over d·√(ρ/E) (0.3 √(m/(E r_max)) for clumps of a few spheres: 0.31 measured)
TRIAXIAL_DT_FACTOR = 0.3
#: steps of the isotropic compaction (and, dense, of the friction switched on) over √(E/σ′₃)/(0.3 I_c): 16,000
#: for 100 grains, 31,500 for 500 (dense rough spheres, I_c = 0.01, E/σ′₃ = 5000: 23,570 × 1.34)
TRIAXIAL_COMPACTION_FACTOR = 1.4
#: the same at the compaction's time limit (3 / ε̇_c; the scene's time step is 0.34 d √(ρ/E) for clumps of a few
#: spheres, so 3 × 0.3 / 0.34): the quick dense rough-angular specimen (100 clumps of 6 spheres) ends its
#: compaction there, still creeping, after 62,200 steps (2.64 in these units), where the rough spheres take 24,690
TRIAXIAL_COMPACTION_LIMIT_FACTOR = 2.65
#: Yade seconds per grain and step of the triaxial scene (one core): a fixed part (the clump, its six mass
#: spheres, the servo's sum over the contacts every 10 steps) and a part per contact sphere; set to the
#: 500-grain run of 10-sphere clumps (1.9e-5 s a grain-step on a loaded machine), above the 100-grain runs of
#: 6 spheres (7.9e-6 measured, 1.2e-5 modelled)
TRIAXIAL_GRAIN_STEP_SECONDS, TRIAXIAL_SPHERE_STEP_SECONDS = 2e-6, 1.7e-6
#: LIGGGHTS seconds per grain and step of the walled-box triaxial deck (one core's work, ranks not counted as a
#: speed-up): measured 0.70 µs for 250 spheres and 1.72 µs for 250 clumps of 10 spheres (serial, the shared
#: machine at load average 2-3; 1.23 µs for 100 clumps of 6 spheres), a fit of 0.59 + 0.11 per sphere set here
#: a fifth higher (a run under mpirun costs a quarter more CPU); with triaxial_steps' count, about 30 % above the
#: steps these runs took, the estimate is about 1.8 times their CPU time
TRIAXIAL_LIGGGHTS_GRAIN_STEP_SECONDS, TRIAXIAL_LIGGGHTS_SPHERE_STEP_SECONDS = 0.7e-6, 0.14e-6


def triaxial_steps(settings: TriaxialSettings, *, longest: bool = False) -> float:
    """Estimated time steps of one triaxial run: the compaction's and the shearing's.

    The shearing takes ε_a / (ε̇ dt) steps, with ε̇ = I √(σ′₃/ρ)/d and dt ≈ 0.3 d √(ρ/E): that is
    ε_a √(E/σ′₃) / (0.3 I), whatever the grains' size and density. The compaction usually takes
    :data:`TRIAXIAL_COMPACTION_FACTOR` √(E/σ′₃)/(0.3 I_c) steps; ``longest`` counts it to its time limit
    (:data:`TRIAXIAL_COMPACTION_LIMIT_FACTOR`), where frictionless angular clumps that creep end it.

    Parameters
    ----------
    settings : TriaxialSettings
        The run's settings (Young's modulus in Pa, confining stress in kPa, axial strain and inertial number).
    longest : bool, default False
        Count the compaction to its time limit.

    Returns
    -------
    float
        The time steps of the compaction and the shearing together.

    Examples
    --------
    >>> round(triaxial_steps(TriaxialSettings()))  # 58,926 shearing + 32,998 compaction
    91924
    >>> round(triaxial_steps(TriaxialSettings(), longest=True))  # the compaction to its time limit: 62,461
    121387
    """
    stiffness = math.sqrt(settings.young / (1e3 * settings.confining_kpa))
    shear = settings.axial_strain * stiffness / (TRIAXIAL_DT_FACTOR * settings.inertial_number)
    factor = TRIAXIAL_COMPACTION_LIMIT_FACTOR if longest else TRIAXIAL_COMPACTION_FACTOR
    compaction = factor * stiffness / (TRIAXIAL_DT_FACTOR * COMPACTION_INERTIAL_NUMBER)
    return float(shear + compaction)


def check_triaxial_run(settings: TriaxialSettings, engine: str = "yade") -> None:
    """Refuse (``ValueError``, one line) a triaxial specimen too small for a periodic cell (Yade) or for a box of
    walls (LIGGGHTS: the same bound, a box at least 4 diameters wide, so that each wall's servo meets a dozen
    grains and more).

    Parameters
    ----------
    settings : TriaxialSettings
        The run's settings (its ``grains``).
    engine : {"yade", "liggghts"}
        The engine: Yade's periodic cell or LIGGGHTS's box of walls (named in the message).

    Raises
    ------
    ValueError
        If ``settings.grains`` is below :data:`MIN_TRIAXIAL_GRAINS`.

    Examples
    --------
    >>> check_triaxial_run(TriaxialSettings(grains=200))
    >>> check_triaxial_run(TriaxialSettings(grains=30))
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: grains 30: a periodic triaxial cell needs grains ≥ 79 (a cell at least 4 grain diameters wide at a solid fraction of 0.64)
    >>> check_triaxial_run(TriaxialSettings(grains=30), "liggghts")
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: grains 30: a triaxial box of walls needs grains ≥ 79 (a box at least 4 grain diameters wide at a solid fraction of 0.64)
    """
    what, where = ("a triaxial box of walls", "a box") if engine == "liggghts" else ("a periodic triaxial cell",
                                                                                   "a cell")
    if settings.grains < MIN_TRIAXIAL_GRAINS:
        raise InputError(f"{{grains}} {settings.grains}: {what} needs {{grains}} ≥ {MIN_TRIAXIAL_GRAINS} ({where} at "
                         f"least {MIN_CELL_DIAMETERS:g} grain diameters wide at a solid fraction of "
                         f"{DENSEST_FRACTION:g})", setting="grains")


def scene_settings(settings: Settings, test: str, seed: int) -> dict:
    """The ``grains.json["scene"]`` dictionary the Yade scene reads.

    Parameters
    ----------
    settings : Settings
        The run's settings (SI units: Young's modulus in Pa; the friction coefficient becomes ``friction_deg``,
        degrees; the tilt's steps in degrees).
    test : {"repose", "tilt"}
        The virtual test under gravity.
    seed : int
        The run's seed number (``settings.seed + k``), written as ``seed`` (the Yade scene's own random seed) and
        the seed of the grains' orientations (:func:`grainforge.dem.deck.grain_orientations`).

    Returns
    -------
    dict
        The scene's settings: ``test``, ``seed``, ``grains``, the contact model's (``young`` in Pa, ``poisson``,
        ``friction_deg``, ``damping``), ``gravity`` (m/s²), the run's controls and ``orientations`` (one unit
        quaternion ``(w, x, y, z)`` per grain).

    Raises
    ------
    ValueError
        If ``test`` is not one of :data:`TESTS`.

    Examples
    --------
    >>> s = scene_settings(Settings(), "repose", 4)
    >>> s["seed"], s["grains"], round(s["friction_deg"], 2)
    (4, 200, 26.57)
    """
    if test not in TESTS:
        raise InputError(f"test must be one of {', '.join(TESTS)}, got {test!r}")
    from ..dem.deck import grain_orientations, orientation_rows

    return {
        "test": test, "seed": int(seed), "grains": settings.grains, "young": settings.young,
        "poisson": settings.poisson, "friction_deg": math.degrees(math.atan(settings.friction)),
        "damping": settings.damping, "gravity": 9.81, "dt_safety": 0.3, "check_every": 500,
        "ke_ratio": 1e-4, "base_roughness": settings.base_roughness, "lift_speed": LIFT_SPEED,
        "max_time_factor": 8.0, "tilt_step_deg": settings.tilt_step, "tilt_start_deg": settings.tilt_start,
        "tilt_hold": TILT_HOLD, "failure_displacement": 0.5, "layer_depth": 4.0,
        # written only when set, so that a deck without rolling resistance is as before
        **({"rolling_friction": settings.rolling_friction} if settings.rolling_friction > 0 else {}),
        # grain k of the scene is placed in orientation k (w, x, y, z): uniformly random, drawn here
        "orientations": orientation_rows(grain_orientations(settings.grains, seed)),
    }


#: Yade seconds per grain and run (one core): a fixed part and a part per contact sphere, fitted to the
#: repose runs of docs/simulate.md (200 grains of 1 and of 10 spheres: about 50 and 100 s a run)
YADE_GRAIN_SECONDS, YADE_SPHERE_SECONDS = 0.25, 0.03
#: LIGGGHTS's time for a run, as a fraction of the Yade model's, per test: a tilt of 200 FSO grains of 10-sphere
#: clumps took 82 s of CPU a run (0.47 of the Yade tilt model), repose heaps of 2,000 grains 0.08-0.19 of the
#: repose model, a tilt of 100 spheres 0.1 (docs/benchmarks.md); the largest of each test is kept
ENGINE_FACTOR = {"yade": {"repose": 1.0, "tilt": 1.0}, "liggghts": {"repose": 0.2, "tilt": 0.5}}
#: a tilt run of as many grains as a repose run, as a fraction of it: a layer on a small periodic plate, tilted
#: in steps. The quick tilt of 30 rough spheres (6-sphere clumps, from 15° in 1° steps) took 22 s of CPU in all
#: (the model: 29 s), the quick tilt calibration of the rough angular grains 1.9 min (87 s), a 50-grain tilt of
#: 10-sphere clumps 29 s (50 s) (benchmarks/doc_costs.py; docs/benchmarks.md)
TEST_FACTOR = {"repose": 1.0, "tilt": 1.6}
#: seconds of a command's own start and end (its imports, the figure, results.csv): about 2.5 s of CPU
START_SECONDS = 3.0
#: seconds of an engine's start-up and of reading its run back, per run: Yade's own imports take about 2.2 s of
#: CPU before the scene, LIGGGHTS starts in a tenth of a second (its deck's set-up is in the model)
RUN_START_SECONDS = {"yade": 2.5, "liggghts": 0.5}
#: seconds to make one clump template: about 0.08 s at 10 spheres, 0.15 s at 200
TEMPLATE_SECONDS, TEMPLATE_SPHERE_SECONDS = 0.08, 0.0005
#: Yade's memory per contact sphere (bytes: the body, its bound, its contacts)
YADE_SPHERE_BYTES = 4096.0
#: Yade seconds per level-set grain and run (one core, repose; the tilt factor applies): a 50-grain level-set
#: tilt of the rough spheres (150 surface nodes a grain) took 611 s, 21 times the 10-sphere clumps' 29 s
#: (docs/simulate.md); the model gives it 640 s
YADE_LEVELSET_GRAIN_SECONDS = 8.5
#: Yade's memory per level-set grid node of each grain (its distance field, copied per body)
YADE_LEVELSET_NODE_BYTES = 16.0


def check_size(test: str, settings: Settings, *, available: int, make_seconds: float = 0.0,
               as_spheres: bool = False, workers: int = 1, shape: str = "clump", spacing: float = 0.05,
               engine: str = "yade", longest: bool = False) -> float:
    """Estimated seconds of a virtual test; refuse one beyond a day or half the machine's memory.

    A triaxial test (``settings`` a :class:`TriaxialSettings`) is costed per time step
    (:func:`triaxial_steps`, :data:`TRIAXIAL_GRAIN_STEP_SECONDS`; in LIGGGHTS
    :data:`TRIAXIAL_LIGGGHTS_GRAIN_STEP_SECONDS`).

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The runs' settings (``grains``, ``spheres``, ``seeds``).
    available, make_seconds : int, float
        From :func:`check_inputs`: the grains the inputs hold, and the
        seconds to generate one (a recipe) before it becomes a template.
    as_spheres : bool
        Each grain a single sphere (``--as-spheres``): one contact sphere a grain.
    workers : int
        Yade runs at once (each on one core).
    shape, spacing : str, float
        The grains' representation: clumps of ``settings.spheres``, or level
        sets of grid ``spacing`` (their grids cost template time and Yade time
        and memory per grain: :data:`YADE_LEVELSET_GRAIN_SECONDS`).
    engine : {"yade", "liggghts"}
        The engine of the runs; a LIGGGHTS run is costed at
        :data:`ENGINE_FACTOR` of the Yade model (one core's work: MPI ranks
        are not counted as a speed-up).
    longest : bool, default False
        A triaxial run's compaction counted to its time limit (``triaxial_steps(longest=True)``): the most
        the runs may take, where the usual estimate counts a compaction that ends on its criteria.

    Returns
    -------
    float
        The estimated seconds: the start (:data:`START_SECONDS`), the templates' making, then every run
        (each with its engine's start, :data:`RUN_START_SECONDS`) with ``workers`` of them at once.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        With the estimate and the options that reduce it.

    Examples
    --------
    >>> 60 < check_size("repose", Settings(), available=3) < 600
    True
    >>> check_size("tilt", Settings(), available=3, shape="levelset") > 5 * check_size("tilt", Settings(), available=3)
    True
    >>> check_size("tilt", Settings(), available=3, engine="liggghts") < check_size("tilt", Settings(), available=3)
    True
    >>> 100 < check_size("triaxial", TriaxialSettings(), available=3) < 3600  # 3 runs of 200 grains, 2 at once
    True
    >>> 10 < check_size("triaxial", TriaxialSettings(), available=3, engine="liggghts") < 300
    True
    """
    from ..runtime.estimate import SECONDS_LIMIT, TooLargeError, _limit, check_memory, dem_template_seconds, duration
    from ..runtime.workers import default_workers

    templates = min(settings.templates, available)
    spheres = 1 if as_spheres else settings.spheres
    make = templates * (make_seconds + TEMPLATE_SECONDS + TEMPLATE_SPHERE_SECONDS * spheres)
    if test == "triaxial" and engine == "liggghts":  # the walled box's own cost per step (no ENGINE_FACTOR)
        per_run = triaxial_steps(settings, longest=longest) * settings.grains * (
            TRIAXIAL_LIGGGHTS_GRAIN_STEP_SECONDS + TRIAXIAL_LIGGGHTS_SPHERE_STEP_SECONDS * spheres)
    elif test == "triaxial":  # its own model: steps from the strain rate and the time step (triaxial_steps)
        per_run = triaxial_steps(settings, longest=longest) * settings.grains * (TRIAXIAL_GRAIN_STEP_SECONDS
                                                                + TRIAXIAL_SPHERE_STEP_SECONDS * spheres)
    else:
        per_run = TEST_FACTOR[test] * settings.grains * (YADE_GRAIN_SECONDS + YADE_SPHERE_SECONDS * spheres)
    if shape == "levelset":
        make = templates * (make_seconds + dem_template_seconds("levelset", spacing=spacing))
        per_run = TEST_FACTOR[test] * settings.grains * YADE_LEVELSET_GRAIN_SECONDS
    if test != "triaxial":
        per_run *= ENGINE_FACTOR[engine][test]
    per_run += RUN_START_SECONDS[engine]
    at_once = max(1, min(int(workers), settings.seeds, default_workers()))
    total = START_SECONDS + make + per_run * settings.seeds / at_once
    grain = f"{spheres} sphere(s)" if shape == "clump" else f"level sets of spacing {spacing:g}"
    raise_spacing = "" if shape == "clump" else ", or raise --spacing"
    if total > SECONDS_LIMIT:
        if make > total / 2:
            option = "--templates" + raise_spacing
        else:
            option = ("--grains, --spheres or --seeds" if shape == "clump" else "--grains or --seeds") + raise_spacing
        raise TooLargeError(
            f"{settings.seeds} {test} run(s) of {settings.grains} grains of {grain} from {templates} "
            f"template(s) would take about {duration(total)} of computing ({duration(per_run)} a run on "
            f"{at_once} core(s), {duration(make)} for the templates; limit {_limit()}); lower {option}")
    per_grain = (YADE_SPHERE_BYTES * spheres if shape == "clump"
                 else YADE_LEVELSET_NODE_BYTES * (1.4 / spacing + 7.0) ** 3 + YADE_SPHERE_BYTES)
    check_memory(per_grain * settings.grains * at_once,
                 what=f"{at_once} Yade run(s) at once of {settings.grains} grains of {grain}",
                 option=("--grains, --spheres or --workers" if shape == "clump" else "--grains or --workers")
                 + raise_spacing)
    return float(total)
