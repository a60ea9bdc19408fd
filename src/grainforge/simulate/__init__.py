"""Virtual bulk tests in Yade: angle of repose and tilt table (the paper's §3.2, in silico).

The paper printed 8,000 CRI grains of two shapes and measured, on a tilt
table, ultimate friction angles of about 38° for "rough spheres" and 43–48° for
"rough and angular" grains.  :func:`run_test` runs the same kind of
comparison in the DEM engine Yade before anything is printed:

1. the population's grains (mesh files, a run folder, a manifest, or grains
   generated from a recipe) become clumps through :mod:`grainforge.dem`, each
   carrying the mesh's exact mass, centre and inertia;
2. a Yade deck is written with a scene from :mod:`grainforge.simulate.scenes`
   (a lifted cylinder on a rough base for the angle of repose; a periodic layer
   on a rough plate tilted until it slides for the tilt table) and run headless
   (``yade -n -x run.py``) once per seed;
3. the angle is measured from the final grain positions by
   :mod:`grainforge.simulate.measure`, and reported with its spread over seeds.

Every shape gets the same contact model (linear spring, Coulomb friction:
Yade's Cundall–Strack law), the same material and the same time-step rule.
Nothing is tuned to the paper's numbers; the contact friction is an input.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..params import param, validate
from .measure import heap_angle, tilt_failure_angle

__all__ = ["TESTS", "Settings", "QUICK", "yade_executable", "scene_settings", "check_inputs", "build_population",
           "write_test_deck", "run_yade", "measure_result", "run_test", "summarise", "check_size", "open_stage",
           "commit_stage", "discard_stage", "EngineFailed", "keep_failed", "FAILED_PREFIX"]

#: the virtual tests
TESTS = ("repose", "tilt")


@dataclass(frozen=True)
class Settings:
    """Settings of a virtual bulk test, SI units unless stated.

    The same settings apply to every shape in a comparison.
    """

    grains: int = param(200, "grains in the test (drawn from the population's templates)", kind="int",
                        low=2, high=20000)
    templates: int = param(40, "distinct grains made into clumps; the test draws from them with replacement "
                           "and random orientations", kind="int", low=1, high=20000)
    spheres: int = param(10, "spheres per clump (grainforge.dem.clump; more = closer to the mesh, slower)",
                         kind="int", low=1, high=200)
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
    seeds: int = param(3, "independent runs (seeds seed, seed+1, ...); the angle is reported with its spread",
                       kind="int", low=1, high=100)
    seed: int = param(0, "first seed", kind="int", low=0, high=2**31 - 1)
    base_roughness: float = param(0.3, "radius of the fixed spheres of the rough base, in mean grain diameters",
                                  low=0.05, high=2.0)
    tilt_step: float = param(0.5, "tilt increment of the tilt test", unit="deg", low=0.05, high=5.0)
    tilt_start: float = param(10.0, "first tilt angle of the tilt test", unit="deg", low=0.0, high=60.0)

    def __post_init__(self):
        validate(self)


#: settings of ``--quick``: a few tens of grains, seconds per run (plumbing, not a measurement)
QUICK = dict(grains=30, templates=6, spheres=6, seeds=1, tilt_step=1.0, tilt_start=15.0)


def yade_executable() -> str:
    """Path of the ``yade`` command.

    Raises
    ------
    FileNotFoundError
        If Yade is not installed (Debian: ``apt-get install yade``).
    """
    exe = shutil.which(os.environ.get("GRAINFORGE_YADE", "yade"))
    if exe is None:
        raise FileNotFoundError("Yade is not installed (on Debian: apt-get install --no-install-recommends yade)")
    return exe


def scene_settings(settings: Settings, test: str, seed: int) -> dict:
    """The ``grains.json["scene"]`` dictionary the Yade scene reads.

    Examples
    --------
    >>> s = scene_settings(Settings(), "repose", 4)
    >>> s["seed"], s["grains"], round(s["friction_deg"], 2)
    (4, 200, 26.57)
    """
    if test not in TESTS:
        raise ValueError(f"test must be one of {', '.join(TESTS)}, got {test!r}")
    return {
        "test": test, "seed": int(seed), "grains": settings.grains, "young": settings.young,
        "poisson": settings.poisson, "friction_deg": math.degrees(math.atan(settings.friction)),
        "damping": settings.damping, "gravity": 9.81, "dt_safety": 0.3, "check_every": 500,
        "ke_ratio": 1e-4, "base_roughness": settings.base_roughness, "lift_speed": 0.5,
        "max_time_factor": 8.0, "tilt_step_deg": settings.tilt_step, "tilt_start_deg": settings.tilt_start,
        "tilt_hold": 8.0, "failure_displacement": 0.5, "layer_depth": 4.0,
    }


def _sphere_mesh(d: float):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    scale = d / (6.0 * m.volume / math.pi) ** (1.0 / 3.0)
    return np.asarray(m.vertices) * scale, np.asarray(m.faces, dtype=np.int64)


def _template(args):
    from ..dem.template import prepare
    from ..solid import signed_volume

    vertices, faces, name, settings, source, k, as_spheres = args
    if as_spheres:
        d = (6.0 * signed_volume(vertices, faces) / math.pi) ** (1.0 / 3.0)
        vertices, faces = _sphere_mesh(d)
        t = prepare(vertices, faces, name, unit=1e-3, density=settings.density, spheres=1, source=source, rng=k)
        # a sphere's clump is the sphere itself
        from ..dem.clump import Clump

        sphere = Clump(np.zeros((1, 3)), np.array([t.d_eq / 2.0]), 1.0, 0.0, t.clump.resolution)
        return replace(t, clump=sphere)
    return prepare(vertices, faces, name, unit=1e-3, density=settings.density, spheres=settings.spheres,
                   source=source, rng=k)


def _scaled_to(vertices, faces, size):
    from ..solid import signed_volume

    d = (6.0 * signed_volume(vertices, faces) / math.pi) ** (1.0 / 3.0)
    return vertices * (size / d)


def _is_recipe(paths: Sequence[Path]) -> bool:
    return len(paths) == 1 and paths[0].suffix.lower() == ".toml"


def check_inputs(inputs: Sequence[str | os.PathLike]) -> tuple[int, float]:
    """Cheap checks of the inputs before any work: a readable recipe, or paths that hold grain files.

    A recipe that ``grainforge batch`` would refuse as too large (its count
    beyond a day of computing, e.g. ``count = 2**63 - 1``) is refused too:
    the simulated grains stand for that population.

    Returns
    -------
    (int, float)
        The grains available (files, or the recipe's count) and the seconds
        to make one (0 for files).

    Raises
    ------
    ValueError
        Naming the input that is missing, unreadable or holds no grain.
    """
    paths = [Path(p) for p in inputs]
    if _is_recipe(paths):
        from ..estimate import grain_seconds
        from ..population import check_recipe_size, draw_grain, load_recipe

        recipe = load_recipe(paths[0])
        check_recipe_size(recipe)
        return recipe.count, grain_seconds(recipe.method, draw_grain(recipe, 0)[1])
    from ..dem.inputs import grain_paths

    return len(grain_paths(paths)), 0.0


#: Yade seconds per grain and run (one core): a fixed part and a part per contact sphere, fitted to the
#: repose runs of docs/simulate.md (200 grains of 1 and of 10 spheres: about 50 and 100 s a run)
YADE_GRAIN_SECONDS, YADE_SPHERE_SECONDS = 0.25, 0.03
#: a tilt run takes longer than a repose run of as many grains (the tilt steps; docs/simulate.md)
TEST_FACTOR = {"repose": 1.0, "tilt": 2.5}
#: seconds to make one clump template: about 0.08 s at 10 spheres, 0.15 s at 200
TEMPLATE_SECONDS, TEMPLATE_SPHERE_SECONDS = 0.08, 0.0005
#: Yade's memory per contact sphere (bytes: the body, its bound, its contacts)
YADE_SPHERE_BYTES = 4096.0


def check_size(test: str, settings: Settings, *, available: int, make_seconds: float = 0.0,
               as_spheres: bool = False, workers: int = 1) -> float:
    """Estimated seconds of a virtual test; refuse one beyond a day or half the machine's memory.

    Parameters
    ----------
    available, make_seconds : int, float
        From :func:`check_inputs`: the grains the inputs hold, and the
        seconds to generate one (a recipe) before it becomes a template.
    workers : int
        Yade runs at once (each on one core).

    Raises
    ------
    grainforge.estimate.TooLargeError
        With the estimate and the options that reduce it.

    Examples
    --------
    >>> 60 < check_size("repose", Settings(), available=3) < 600
    True
    """
    from ..estimate import SECONDS_LIMIT, TooLargeError, _limit, check_memory, duration

    templates = min(settings.templates, available)
    spheres = 1 if as_spheres else settings.spheres
    make = templates * (make_seconds + TEMPLATE_SECONDS + TEMPLATE_SPHERE_SECONDS * spheres)
    per_run = TEST_FACTOR[test] * settings.grains * (YADE_GRAIN_SECONDS + YADE_SPHERE_SECONDS * spheres)
    at_once = max(1, min(int(workers), settings.seeds, os.cpu_count() or 1))
    total = make + per_run * settings.seeds / at_once
    if total > SECONDS_LIMIT:
        option = "--templates" if make > total / 2 else "--grains, --spheres or --seeds"
        raise TooLargeError(
            f"{settings.seeds} {test} run(s) of {settings.grains} grains of {spheres} sphere(s) from {templates} "
            f"template(s) would take about {duration(total)} of computing ({duration(per_run)} a run on "
            f"{at_once} core(s), {duration(make)} for the templates; limit {_limit()}); lower {option}")
    check_memory(YADE_SPHERE_BYTES * settings.grains * spheres * at_once,
                 what=f"{at_once} Yade run(s) at once of {settings.grains} grains of {spheres} sphere(s)",
                 option="--grains, --spheres or --workers")
    return float(total)


def open_stage(out: str | os.PathLike) -> tuple[Path, bool]:
    """A hidden staging folder inside ``out`` for one command's outputs; whether ``out`` was created.

    Staging folders of killed runs (their process gone) are removed first,
    so a run killed by SIGKILL never blocks the next one.
    """
    import tempfile

    from ..run import STAGING_PREFIX, remove_stale_staging

    out = Path(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(out)
    return Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out)), created


def commit_stage(stage: Path, out: str | os.PathLike, *, overwrite: bool = False) -> list[Path]:
    """Move everything in ``stage`` into ``out`` (folders first, then files): the outputs appear together.

    An existing output is replaced only with ``overwrite`` (else ``FileExistsError``, nothing moved).
    """
    out = Path(out)
    items = sorted(stage.iterdir(), key=lambda p: (not p.is_dir(), p.name))
    if not overwrite:
        for p in items:
            if (out / p.name).exists():
                raise FileExistsError(f"{out / p.name} exists; use --overwrite")
    moved = []
    for p in items:
        target = out / p.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        p.replace(target)
        moved.append(target)
    return moved


def discard_stage(stage: Path, out: str | os.PathLike, created: bool) -> None:
    """Remove ``stage`` (empty after :func:`commit_stage`) and ``out`` if this run created it and it is empty."""
    shutil.rmtree(stage, ignore_errors=True)
    out = Path(out)
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def build_population(inputs: Sequence[str | os.PathLike], settings: Settings, *, as_spheres: bool = False,
                     progress: Callable[[int, int], None] | None = None) -> list:
    """Clump templates (:class:`grainforge.dem.template.GrainTemplate`) of the population.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files, run folders, manifests (sizes in mm), or one TOML recipe
        (its first ``settings.templates`` grains are generated, at the recipe's sizes).
    settings : Settings
    as_spheres : bool
        Replace every grain by its volume-equivalent sphere (the sphere
        baseline of a comparison: same sizes, same mass, no shape).
    progress : callable, optional
        Called as ``progress(done, total)`` after each template.

    Raises
    ------
    ValueError
        For inputs that hold no grain, a recipe that cannot be read, or a mesh
        that is not a valid solid (named).
    """
    items = []
    paths = [Path(p) for p in inputs]
    if _is_recipe(paths):
        from ..fabrication.scale import to_size
        from ..methods import generate
        from ..population import draw_grain, load_recipe

        recipe = load_recipe(paths[0])
        for i in range(min(settings.templates, recipe.count)):
            seed, params, size = draw_grain(recipe, i)
            g = to_size(generate(recipe.method, params, seed), size, recipe.size_definition)
            items.append((g.vertices, g.faces, f"{recipe.method}-{i:04d}", f"{paths[0]} grain {i}"))
    else:
        from ..dem.inputs import grain_paths, read_grain

        files = grain_paths(paths)
        step = max(1, len(files) // settings.templates) if len(files) > settings.templates else 1
        for k, f in enumerate(files[::step][: settings.templates]):
            v, fc = read_grain(f)
            items.append((v, fc, f"g{k:04d}-{f.stem}"[:60], str(f)))
    out = []
    for k, (v, f, name, source) in enumerate(items):
        if settings.size is not None:
            v = _scaled_to(v, f, settings.size)
        out.append(_template((v, f, name, settings, source, k, as_spheres)))
        if progress is not None:
            progress(k + 1, len(items))
    return out


def write_test_deck(templates: Sequence, test: str, settings: Settings, seed: int, out: str | os.PathLike,
                    *, overwrite: bool = False) -> list[Path]:
    """Write the Yade deck of one run of ``test`` into ``out`` (``yade -n -x run.py`` from inside it)."""
    from ..dem.yade import write_deck
    from .scenes import REPOSE, TILT

    scene = {"repose": REPOSE, "tilt": TILT}[test]
    return write_deck(templates, out, scene=scene, settings=scene_settings(settings, test, seed),
                      overwrite=overwrite)


def run_yade(deck: str | os.PathLike, *, progress: Callable[[float, str], None] | None = None,
             timeout: float | None = None) -> dict:
    """Run ``yade -n -x run.py`` inside ``deck`` and return its ``result.json``.

    The scene's ``grainforge-progress`` lines are passed to ``progress(fraction,
    phase)``; Yade's own output goes to ``deck/yade.log``.  The Yade process is
    killed if this call is interrupted (no orphan engine left running).

    Raises
    ------
    EngineFailed
        If Yade exits with an error (the last line of its log is quoted; the
        exception's ``deck`` is the run's folder, kept by :func:`keep_failed`).
    """
    deck = Path(deck)
    exe = yade_executable()
    log_path = deck / "yade.log"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    from ..workers import die_with_parent

    with open(log_path, "w", buffering=1) as log:
        proc = _track(subprocess.Popen([exe, "-n", "-x", "run.py"], cwd=deck, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, env=env,
                                start_new_session=True, preexec_fn=die_with_parent))
        try:
            for line in proc.stdout:
                log.write(line)
                if line.startswith("grainforge-progress") and progress is not None:
                    _, frac, *phase = line.split()
                    progress(float(frac), " ".join(phase))
            rc = proc.wait(timeout=timeout)
        except BaseException:
            _kill(proc)
            raise
        finally:
            proc.stdout.close()
            _RUNNING.discard(proc)
    if rc != 0 or not (deck / "result.json").is_file():
        tail = [ln.strip() for ln in log_path.read_text(errors="replace").splitlines() if ln.strip()]
        raise EngineFailed(f"Yade failed in {deck} (exit {rc}): {tail[-1] if tail else 'no output'}", deck)
    return json.loads((deck / "result.json").read_text())


class EngineFailed(RuntimeError):
    """An engine run ended with an error (not an interrupt); ``deck`` is its folder (deck and log)."""

    def __init__(self, message: str, deck: str | os.PathLike):
        super().__init__(message)
        self.deck = Path(deck)


#: name prefix of the folder in ``--out`` that keeps a failed run's deck and log
FAILED_PREFIX = "failed-"


def keep_failed(deck: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Move a failed run's folder (deck and engine log) to ``out/failed-<name>`` and return that path.

    An earlier ``failed-<name>`` folder is replaced: it is a diagnostic of the
    last failure, not a result.  The successful outputs stay staged (nothing
    else of the failed command appears in ``out``).
    """
    deck, out = Path(deck), Path(out)
    target = out / f"{FAILED_PREFIX}{deck.name}"
    if target.is_dir() and not target.is_symlink():
        shutil.rmtree(target)
    elif target.exists() or target.is_symlink():
        target.unlink()
    deck.replace(target)
    return target


#: Yade processes started by this process and not yet finished (killed on an interrupt)
_RUNNING: set = set()


def _track(proc):
    _RUNNING.add(proc)
    return proc


def _kill_all() -> None:
    for proc in list(_RUNNING):
        _kill(proc)


def _kill(proc: subprocess.Popen) -> None:
    import signal

    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


def measure_result(result: dict) -> dict:
    """The measured angle of one finished run (``result.json`` of a scene).

    Returns a dict with ``angle_deg``, ``sector_sd_deg`` (over the heap's
    sectors, repose only), the number of grains inserted and lost, the
    engine's step count and time step, and a ``note`` saying why the angle is
    NaN when it could not be measured (a heap of a few grains).
    """
    d = float(result["d_mean"])
    row = {"test": result["test"], "grains": result["grains"], "inserted": result["inserted"],
           "lost": result["lost"], "steps": result["steps"], "dt_s": result["dt"],
           "simulated_time_s": result["time"]}
    if result["test"] == "repose":
        try:
            h = heap_angle(np.asarray(result["spheres"]), bin_width=0.5 * d, grain_size=d, base=result["base_top"])
        except ValueError as exc:  # a heap of a few grains (--quick): no slope to measure
            # the ring width is fixed (half a grain): the remedy open to the user is a bigger heap
            reason = str(exc).split(" (")[0]
            note = f"{reason} ({result['grains']} grains); use more --grains"
            row.update(angle_deg=float("nan"), sector_sd_deg=float("nan"), heap_height_mm=float("nan"),
                       heap_foot_radius_mm=float("nan"), settled=bool(result["settled"]), note=note)
        else:
            row.update(angle_deg=h.angle, sector_sd_deg=h.spread, heap_height_mm=1e3 * h.height,
                       heap_foot_radius_mm=1e3 * h.foot, settled=bool(result["settled"]), note="")
    else:
        hist = np.asarray(result["history"], dtype=np.float64)
        angle = tilt_failure_angle(hist[:, :2], displacement=0.5)
        row.update(angle_deg=angle, sector_sd_deg=float("nan"), settled=result["failure_angle"] is not None,
                   note="" if np.isfinite(angle) else "the layer did not fail, or had failed at the first angle")
    return row


def run_test(test: str, templates: Sequence, settings: Settings, out: str | os.PathLike, *,
             label: str = "", progress: Callable[[int, float, str], None] | None = None,
             overwrite: bool = False, workers: int = 1) -> list[dict]:
    """Run ``test`` once per seed into ``out/<test>-seed<k>/`` and measure each run.

    Parameters
    ----------
    test : {"repose", "tilt"}
    templates : sequence of GrainTemplate
        From :func:`build_population`.
    settings : Settings
    out : path
        Folder for the decks (written before Yade starts; an existing deck is
        refused unless ``overwrite``).
    label : str
        Name of the population in the rows.
    progress : callable, optional
        ``progress(run index, fraction, phase)`` while each run goes on.
    workers : int
        Yade processes at once (each single-threaded); the seeds' runs are
        independent, so the rows do not depend on it.

    Returns
    -------
    list of dict
        One row per seed, in seed order (see :func:`measure_result`), with ``label`` and ``seed``.
    """
    out = Path(out)
    seeds = [settings.seed + k for k in range(settings.seeds)]
    decks = [out / f"{test}-seed{seed}" for seed in seeds]
    for seed, deck in zip(seeds, decks):
        write_test_deck(templates, test, settings, seed, deck, overwrite=overwrite)

    def one(k):
        report = None if progress is None else (lambda f, p: progress(k, f, p))
        result = run_yade(decks[k], progress=report)
        return {"label": label, "seed": seeds[k], **measure_result(result)}

    if workers <= 1 or len(seeds) == 1:
        return [one(k) for k in range(len(seeds))]
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=min(workers, len(seeds)))
    try:
        return list(pool.map(one, range(len(seeds))))
    except BaseException:
        _kill_all()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def summarise(rows: Sequence[dict]) -> dict:
    """Mean and standard deviation of the angle over seeds (NaN runs excluded).

    Examples
    --------
    >>> summarise([{"angle_deg": 30.0}, {"angle_deg": 32.0}])
    {'runs': 2, 'angle_mean_deg': 31.0, 'angle_sd_deg': 1.4142135623730951}
    """
    a = np.array([r["angle_deg"] for r in rows], dtype=np.float64)
    a = a[np.isfinite(a)]
    return {"runs": int(len(a)), "angle_mean_deg": float(a.mean()) if len(a) else float("nan"),
            "angle_sd_deg": float(a.std(ddof=1)) if len(a) > 1 else float("nan")}
