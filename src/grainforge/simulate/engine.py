"""Running a virtual test in Yade: the deck of one seed, the engine process, the measured angle."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .angles import TILT_FAILURE, heap_angle, tilt_failure_angle
from .process import EngineFailed, find_executable, kill_running, run_engine_process
from .settings import Settings, scene_settings

__all__ = ["yade_executable", "write_test_deck", "run_yade", "run_engine_process", "EngineFailed", "measure_result",
           "run_deck", "run_test", "summarise"]


#: the name's beginning of the temporary folder every Yade process makes (``/tmp/yade-XXXXXX``, whatever ``TMPDIR``
#: says) and leaves behind: the deck names it, and it is removed after the run (:func:`run_yade`)
YADE_TEMP_PREFIX = "yade-"


def yade_executable() -> str:
    """Path of the ``yade`` command.

    Returns
    -------
    str
        The absolute path of ``yade``, or of the command ``GRAINFORGE_YADE`` names.

    Raises
    ------
    FileNotFoundError
        If Yade is not installed (Debian: ``apt-get install yade``).
    """
    return find_executable("GRAINFORGE_YADE", "yade",
                           "Yade is not installed (on Debian: apt-get install --no-install-recommends yade)")


def write_test_deck(templates: Sequence, test: str, *, settings: Settings, seed: int, out: str | os.PathLike,
                    overwrite: bool = False, engine: str = "yade") -> list[Path]:
    """Write the deck of one run of ``test`` into ``out`` (Yade: ``yade -n -x run.py`` from inside it;
    ``engine="liggghts"``: :func:`grainforge.simulate.liggghts_scenes.run_deck_files`, a triaxial test's
    :func:`grainforge.simulate.liggghts_triaxial.triaxial_deck_files`).

    In Yade, the templates' shape (clumps, or level sets: :mod:`grainforge.simulate.levelset_scenes`) picks the scene;
    ``settings`` of a triaxial test are :class:`~grainforge.simulate.TriaxialSettings`.

    Parameters
    ----------
    templates : sequence of GrainTemplate
        The specimen's grains (:func:`grainforge.simulate.build_population`): clumps, or level sets in Yade.
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    settings : Settings or TriaxialSettings
        The run's settings (SI units in the deck: m, kg, Pa, s; the triaxial scene's stresses in kPa).
    seed : int
        The run's seed number (``settings.seed + k``), written into the deck: the scene's orientations and
        layout, and the engine's own random seeds, are derived from it.
    out : path
        The deck's folder (created).
    overwrite : bool
        Replace a deck already in ``out``; otherwise one is refused.
    engine : {"yade", "liggghts"}
        The engine the deck is written for.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    FileExistsError
        If ``out`` already holds a deck and ``overwrite`` is False.
    ValueError
        If the templates do not fit the engine (LIGGGHTS takes multisphere clumps) or ``test`` is unknown.
    """
    if engine == "liggghts" and test == "triaxial":  # a box of servo-controlled walls
        from .liggghts_triaxial import write_deck as write_triaxial

        return write_triaxial(templates, settings, seed=seed, out=out, overwrite=overwrite)
    if engine == "liggghts":
        from .liggghts_scenes import write_test_deck as write_liggghts

        return write_liggghts(templates, test, settings=settings, seed=seed, out=out, overwrite=overwrite)
    from ..dem.yade import write_deck
    from .levelset_scenes import scene_extra, scene_text

    shape = templates[0].shape if templates else "clump"
    if test == "triaxial":
        from .triaxial import triaxial_scene_settings

        scene = triaxial_scene_settings(settings, seed)
    else:
        scene = scene_settings(settings, test, seed)
    return write_deck(templates, out, scene=scene_text(test, shape), settings={**scene, **scene_extra(shape)},
                      overwrite=overwrite)


def run_yade(deck: str | os.PathLike, *, progress: Callable[[float, str], None] | None = None,
             timeout: float | None = None) -> dict:
    """Run ``yade -n -x run.py`` inside ``deck`` and return its ``result.json``.

    The scene's ``grainforge-progress`` lines are passed to ``progress(fraction,
    phase)``; Yade's own output goes to ``deck/yade.log``.  The Yade process is
    killed if this call is interrupted (no orphan engine left running).  The
    temporary folder Yade makes (``/tmp/yade-*``), which the deck names on its
    first line, is removed after the run, however it ended.

    Parameters
    ----------
    deck : path
        The deck's folder (:func:`write_test_deck`).
    progress : callable, optional
        ``progress(fraction, phase)`` for each progress line of the scene.
    timeout : float, optional
        Seconds to wait for Yade after its output has ended; None waits for ever.

    Returns
    -------
    dict
        The run's ``result.json`` (lengths in m, times in s).

    Raises
    ------
    EngineFailed
        If Yade exits with an error (the last line of its log is quoted; the
        exception's ``deck`` is the run's folder, kept by :func:`keep_failed`).
    """
    deck = Path(deck)
    log_path = deck / "yade.log"
    rc = run_engine_process([yade_executable(), "-n", "-x", "run.py"], deck, log_path=log_path, env={},
                            progress=progress, timeout=timeout, temp_prefix=YADE_TEMP_PREFIX)
    if rc != 0 or not (deck / "result.json").is_file():
        tail = [ln.strip() for ln in log_path.read_text(errors="replace").splitlines() if ln.strip()]
        raise EngineFailed(f"Yade failed in {deck} (exit {rc}): {tail[-1] if tail else 'no output'}", deck)
    return json.loads((deck / "result.json").read_text())


def measure_result(result: dict) -> dict:
    """The measured angle of one finished run (``result.json`` of a scene; a triaxial run's row is
    :func:`grainforge.simulate.triaxial.measure_triaxial`'s).

    Returns a dict with ``angle_deg``, ``sector_sd_deg`` (over the heap's
    sectors, repose only), the number of grains inserted and lost, the
    engine's step count and time step, and a ``note`` saying why the angle is
    NaN when it could not be measured (a heap of a few grains).

    Parameters
    ----------
    result : dict
        The ``result.json`` of one finished run (:func:`run_yade`, :func:`run_deck`).

    Returns
    -------
    dict
        ``angle_deg`` (degrees), ``sector_sd_deg``, ``grains``, ``inserted``, ``lost``, ``steps``, ``dt_s``,
        ``simulated_time_s``, ``settled`` and ``note``; a repose run's ``heap_height_mm`` and
        ``heap_foot_radius_mm`` too.
    """
    if result["test"] == "triaxial":
        from .triaxial import measure_triaxial

        return measure_triaxial(result)
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
        angle = tilt_failure_angle(hist[:, :2], displacement=TILT_FAILURE)
        row.update(angle_deg=angle, sector_sd_deg=float("nan"), settled=result["failure_angle"] is not None,
                   note="" if np.isfinite(angle) else "the layer did not fail, or had failed at the first angle")
    return row


def run_deck(deck: str | os.PathLike, *, engine: str = "yade", mpi: int | None = None,
             progress: Callable[[float, str], None] | None = None) -> dict:
    """Run the deck in ``deck`` in ``engine`` (LIGGGHTS under ``mpirun -np mpi`` if given); its ``result.json``.

    The one engine run of :func:`run_test`, in the local pool and in a Dask task
    (:func:`grainforge.simulate.sweep.run_remote`).

    Parameters
    ----------
    deck : path
        The deck's folder (:func:`write_test_deck`).
    engine : {"yade", "liggghts"}
        The engine the deck was written for.
    mpi : int, optional
        LIGGGHTS only: ranks of the run under ``mpirun``.
    progress : callable, optional
        ``progress(fraction, phase)`` while the run goes on.

    Returns
    -------
    dict
        The run's ``result.json``.

    Raises
    ------
    EngineFailed
        If the engine exits with an error (its folder is kept with its log).
    """
    if engine == "liggghts":
        from .liggghts_scenes import run_liggghts

        collect = None
        if json.loads((Path(deck) / "grains.json").read_text())["result"]["test"] == "triaxial":
            from .liggghts_triaxial import collect_triaxial as collect  # the walled box's records
        return run_liggghts(deck, mpi=mpi, progress=progress, collect=collect)
    return run_yade(deck, progress=progress)


def run_test(test: str, templates: Sequence, *, settings: Settings, out: str | os.PathLike,
             label: str = "", progress: Callable[[int, float, str], None] | None = None,
             overwrite: bool = False, workers: int = 1, engine: str = "yade",
             mpi: int | None = None, executor=None, journal=None) -> list[dict]:
    """Run ``test`` once per seed into ``out/<test>-seed<k>/`` and measure each run.

    Parameters
    ----------
    test : {"repose", "tilt", "triaxial"}
        The virtual test.
    templates : sequence of GrainTemplate
        From :func:`build_population`.
    settings : Settings or TriaxialSettings
        The runs' settings; seeds ``settings.seed`` to ``settings.seed + settings.seeds - 1`` are run.
    out : path
        Folder for the decks (written before Yade starts; an existing deck is
        refused unless ``overwrite``).
    label : str
        Name of the population in the rows.
    progress : callable, optional
        ``progress(run index, fraction, phase)`` while each run goes on.
    overwrite : bool
        Replace decks already in ``out``.
    workers : int
        Engine runs at once (each single-threaded, or ``mpi`` ranks); the seeds' runs are
        independent, so the rows do not depend on it.
    engine : {"yade", "liggghts"}
        The engine of the runs.
    mpi : int, optional
        LIGGGHTS only: ranks of each run under ``mpirun``.
    executor : grainforge.runtime.cluster.DaskExecutor, optional
        Run each seed as a Dask task (:func:`grainforge.simulate.sweep.run_remote`: the deck's files go to the
        worker, the run's files come back into its folder); ``workers`` is then unused, and ``progress`` says
        when each run starts and ends.
    journal : grainforge.simulate.sweep.SweepJournal, optional
        Reuse the runs it keeps (their decks byte-identical to the ones written now) and record each run as it
        finishes.

    Returns
    -------
    list of dict
        One row per seed, in seed order (see :func:`measure_result`), with ``label`` and ``seed``.

    Raises
    ------
    FileExistsError
        If a run's folder already holds a deck and ``overwrite`` is False.
    EngineFailed
        If a run fails (its folder is kept with its log); the other runs are stopped.
    grainforge.simulate.sweep.JournalMismatch
        If a deck differs from the one ``journal`` kept of the interrupted sweep.
    """
    out = Path(out)
    seeds = [settings.seed + k for k in range(settings.seeds)]
    decks = [out / f"{test}-seed{seed}" for seed in seeds]
    written = [write_test_deck(templates, test, settings=settings, seed=seed, out=deck, overwrite=overwrite,
                               engine=engine) for seed, deck in zip(seeds, decks)]

    def row(k, result):
        return {"label": label, "seed": seeds[k], **measure_result(result)}

    kept = {}
    if journal is not None:
        for k in range(len(seeds)):
            result = journal.reuse(decks[k], written[k])
            if result is not None:
                kept[k] = result
                if progress is not None:
                    progress(k, 1.0, "kept from the interrupted sweep")
    if executor is not None:
        from .sweep import run_on_cluster

        results = run_on_cluster(executor, run_deck, decks=decks, which=[k for k in range(len(seeds)) if k not in kept],
                                 engine=engine, mpi=mpi, progress=progress, journal=journal)
        return [row(k, kept[k] if k in kept else results[k]) for k in range(len(seeds))]

    def one(k):
        if k in kept:
            return row(k, kept[k])
        report = None if progress is None else (lambda f, p: progress(k, f, p))
        result = run_deck(decks[k], engine=engine, mpi=mpi, progress=report)
        if journal is not None:
            journal.record(decks[k])
        return row(k, result)

    if workers <= 1 or len(seeds) == 1:
        return [one(k) for k in range(len(seeds))]
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=min(workers, len(seeds)))
    try:
        return list(pool.map(one, range(len(seeds))))
    except BaseException:
        kill_running()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def summarise(rows: Sequence[dict]) -> dict:
    """Mean and standard deviation of the angle over seeds (NaN runs excluded).

    Parameters
    ----------
    rows : sequence of dict
        Rows of :func:`run_test` (each with ``angle_deg``, degrees).

    Returns
    -------
    dict
        ``runs`` (the runs with an angle), ``angle_mean_deg`` and ``angle_sd_deg`` (degrees; NaN without
        enough runs).

    Examples
    --------
    >>> summarise([{"angle_deg": 30.0}, {"angle_deg": 32.0}])
    {'runs': 2, 'angle_mean_deg': 31.0, 'angle_sd_deg': 1.4142135623730951}
    """
    a = np.array([r["angle_deg"] for r in rows], dtype=np.float64)
    a = a[np.isfinite(a)]
    return {"runs": int(len(a)), "angle_mean_deg": float(a.mean()) if len(a) else float("nan"),
            "angle_sd_deg": float(a.std(ddof=1)) if len(a) > 1 else float("nan")}
