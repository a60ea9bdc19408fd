"""The population runner: a recipe's grains made in processes or on a Dask cluster, journalled, resumable.

:func:`run_batch` refuses a recipe too large (:func:`check_recipe_size`) or
whose distributions reach grains that cannot be made (:func:`check_extremes`)
before any work, makes every grain in a worker (:func:`grainforge.population.grains.make_grain`),
writes each file atomically with a sidecar in the journal (:data:`JOURNAL`),
and at the end the manifest and the report.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import shutil
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from ..errors import InputError, OutputExistsError
from ..io import atomic_write, write_csv
from ..params import ParameterError
from .distributions import Distribution
from .grains import GrainResult, draw_grain, make_grain
from .recipe import Recipe, RecipeError

#: hidden folder inside the output folder: recipe copy and one sidecar per finished grain.
JOURNAL = ".grainforge-batch"


def _sidecar(out: Path, index: int) -> Path:
    return out / JOURNAL / f"grain-{index:06d}.json"


def _intact_row(out: Path, recipe: Recipe, index: int) -> dict | None:
    """The recorded row of grain ``index`` if its file is complete and intact, else None."""
    try:
        rec = json.loads(_sidecar(out, index).read_text(encoding="utf-8"))
        path = out / rec["row"]["file"]
        if rec["row"]["file"] != recipe.file_name(index) or path.stat().st_size != rec["bytes"]:
            return None
        if hashlib.sha256(path.read_bytes()).hexdigest() != rec["row"]["sha256"]:
            return None
        return rec["row"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _record(out: Path, res: GrainResult) -> None:
    atomic_write(out / res.name, res.data)
    atomic_write(_sidecar(out, res.index), json.dumps({"bytes": len(res.data), "row": res.row}, sort_keys=True))


def _local_results(recipe: Recipe, todo: Sequence[int], workers: int, in_process: bool) -> Iterable[GrainResult]:
    if in_process:
        for i in todo:
            yield make_grain(recipe, i)
        return
    from ..methods import METHODS
    from ..runtime.workers import process_pool

    # an error, Ctrl-C, SIGTERM or the generator closed early: the pool's exit stops the workers at once
    with process_pool(workers, ["grainforge.population", METHODS[recipe.method], "grainforge.population.generate",
                                "trimesh", "scipy.special"]) as ex:
        yield from _executor_results(ex, recipe, todo, workers)


def _dask_results(recipe: Recipe, todo: Sequence[int], scheduler: str) -> Iterable[GrainResult]:
    from ..runtime.cluster import dask_executor

    with dask_executor(scheduler) as ex:
        yield from _executor_results(ex, recipe, todo, ex.workers)


def _executor_results(ex, recipe: Recipe, todo: Sequence[int], workers: int) -> Iterable[GrainResult]:
    """:func:`make_grain` of each of ``todo`` on executor ``ex`` (a process pool or a Dask cluster), in the order
    they finish, ``4 × workers`` in flight (memory does not grow with the count); the owner closes ``ex``."""
    from concurrent.futures import FIRST_COMPLETED, wait

    it = iter(todo)
    ahead = 4 * workers
    pending: set = set()
    try:
        pending = {ex.submit(make_grain, recipe, i) for i in itertools.islice(it, ahead)}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            pending |= {ex.submit(make_grain, recipe, i) for i in itertools.islice(it, len(done))}
            for f in sorted(done, key=lambda f: f.exception() is None):
                yield f.result()
    finally:
        for f in pending:  # an error or interrupt: the grains not started are dropped
            f.cancel()


def check_recipe_size(recipe: Recipe, workers: int = 1) -> float:
    """Refuse a recipe whose population would take more than a day (estimated from grain 0's parameters).

    Parameters
    ----------
    recipe : Recipe
        A parsed recipe.
    workers : int
        Processes sharing the work.

    Returns
    -------
    float
        The estimated wall-clock seconds.

    Raises
    ------
    grainforge.runtime.estimate.TooLargeError
        One line with the estimate and what to change (``count``).
    """
    from ..runtime.estimate import check_job, grain_seconds

    _, params, _ = draw_grain(recipe, 0)
    return check_job(recipe.count, grain_seconds(recipe.method, params),
                     what=f"{recipe.source}: {recipe.count} {recipe.method} grains",
                     option="count (or split the population into several batches)", workers=workers)


#: grains made at the ends of every distribution before a batch starts
PILOTS = 3


def check_extremes(recipe: Recipe) -> None:
    """Make grains 0, 1, 2 with each distributed parameter at each end of its range (pilot grains, nothing written).

    A parameter's declared range is checked when the recipe is read; some
    limits depend on the grain itself (e.g. an FSO amplitude too large for
    the grain to stay star-shaped).  This catches a distribution reaching such
    values before any work, instead of failing at grain 517.

    Parameters
    ----------
    recipe : Recipe
        A parsed recipe; nothing is done when no parameter is drawn.

    Raises
    ------
    RecipeError
        Naming ``params.NAME``, the value and the reason.
    """
    import dataclasses

    from ..methods import generate

    varying = {k: v for k, v in recipe.params.items() if isinstance(v, Distribution)}
    if not varying:
        return
    for index in range(min(PILOTS, recipe.count)):
        make_grain(recipe, index)  # the grain as drawn: its own error (fixed parameters) names it
        seed, params, _ = draw_grain(recipe, index)
        for name, dist in varying.items():
            for value in _extremes(dist):
                try:
                    generate(recipe.method, dataclasses.replace(params, **{name: value}), seed)
                except ParameterError as exc:
                    raise RecipeError(recipe.source, f"params.{name}",
                                      f"the distribution reaches {value!r}, where grain {index} cannot be made "
                                      f"({exc.reason}); narrow the distribution") from None


def _extremes(dist: Distribution) -> list:
    """The finite extreme values ``dist`` can draw: a choice's values, an interval's ends, and for
    ``zingg`` and ``each`` every combination of their parts' ends (infinite ends left out).

    Examples
    --------
    >>> e = Distribution("uniform", {"low": 0.5, "high": 0.9})
    >>> _extremes(Distribution("zingg", {"elongation": e, "flatness": 0.8}))
    [(1.0, 0.5, 0.4), (1.0, 0.9, 0.7200000000000001)]
    >>> _extremes(Distribution("each", {"items": (0.0, e)}))
    [(0.0, 0.5), (0.0, 0.9)]
    """
    import itertools

    def ends(x) -> list:
        if not isinstance(x, Distribution):
            return [x]
        if x.kind == "choice":
            return list(x.args["values"])
        return [v for v in x.support() if math.isfinite(v)]

    if dist.kind == "zingg":
        combos = itertools.product(ends(dist.args["elongation"]), ends(dist.args["flatness"]))
        values = [(1.0, e, e * f) for e, f in combos]
    elif dist.kind == "each":
        values = list(itertools.product(*(ends(x) for x in dist.args["items"])))
    else:
        values = ends(dist)
    return list(dict.fromkeys(values))


def existing_grains(out: Path, recipe: Recipe) -> bool:
    """Whether ``out`` holds a grain file of this recipe's naming (listing the folder, not every name).

    Parameters
    ----------
    out : pathlib.Path
        The output folder (need not exist).
    recipe : Recipe
        The recipe (its method, count and format name the files).

    Returns
    -------
    bool
    """
    from .generate import existing_outputs

    return any(p.name != "manifest.csv" for p in existing_outputs(out, recipe.method, recipe.count, recipe.format))


def run_batch(
    recipe: Recipe,
    out: str | os.PathLike,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: Callable[[Iterable], Iterable] | None = None,
    report: bool = True,
    in_process: bool | None = None,
) -> dict[str, Any]:
    """Generate the population of ``recipe`` into ``out``.

    Every grain is generated by :func:`make_grain` in a worker (a local
    process pool of ``workers`` processes, default the CPU count, or the Dask
    cluster at ``scheduler``), then written atomically by this process
    together with a sidecar (byte size and SHA-256) in ``out/.grainforge-batch``.
    At the end ``manifest.csv`` (rows in grain order), its companion
    ``manifest.json`` (summary statistics) and ``population.png`` are written.

    Parameters
    ----------
    recipe : Recipe
        A parsed recipe (:func:`grainforge.population.recipe.load_recipe`); its text is saved in the journal.
    out : str or os.PathLike
        The output folder (made if missing).
    workers : int, optional
        Local worker processes; default the CPU count (at most the grains to make).
    scheduler : str, optional
        A Dask scheduler's address: the grains are made on that cluster instead.
    resume : bool
        Keep every grain whose file matches its sidecar; generate the rest.
        The recipe must be the one the interrupted batch used.
    overwrite : bool
        Replace existing outputs (regenerates everything).
    progress : callable, optional
        ``progress(iterable)`` wraps the grains as they arrive (a bar).
    report : bool
        Write ``manifest.json`` and ``population.png`` too (:func:`grainforge.population.report.population_report`).
    in_process : bool, optional
        Generate in this process instead of a pool (default: only when
        ``workers`` is 1).  The bytes are the same either way; a pool worker
        runs NumPy's BLAS single-threaded, this process does not.

    Returns
    -------
    dict
        ``{"generated": n, "reused": m, "rows": [...], "summary": {...}}``.

    Raises
    ------
    FileExistsError
        If outputs exist and neither ``resume`` nor ``overwrite`` is given.
    ValueError
        For a recipe that does not match the interrupted batch, an unreachable
        scheduler, or a grain that cannot be made (named by index and seed).
    grainforge.runtime.cluster.SchedulerLost
        The Dask scheduler lost mid-run: the grains recorded so far stay, with
        their journal, for ``resume``.
    """
    from ..runtime.workers import default_workers
    from .generate import MANIFEST

    if workers is not None and workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    out = Path(out)
    journal = out / JOURNAL
    n_workers = 1 if scheduler else min(default_workers(workers), recipe.count)
    check_recipe_size(recipe, n_workers)  # before anything: a job beyond a day is refused
    check_extremes(recipe)  # every distribution's range can make a grain (pilot grains, nothing written)
    if not resume and journal.is_dir() and not any(journal.glob("grain-*.json")) \
            and not (out / "manifest.csv").exists() \
            and not existing_grains(out, recipe):
        shutil.rmtree(journal, ignore_errors=True)  # a failed start recorded nothing: it blocks nothing
    names = [recipe.file_name(i) for i in range(recipe.count)]
    saved = journal / "recipe.toml"
    if resume and saved.exists():
        if saved.read_text(encoding="utf-8") != recipe.text:
            raise InputError(f"{recipe.source} differs from the recipe of the batch in {out}; "
                             "resume with the same recipe or use {overwrite}", setting="overwrite")
    elif not overwrite:
        existing = [out / n for n in names + [MANIFEST] if (out / n).exists()]
        if existing or journal.exists():
            first = existing[0] if existing else journal
            hint = "use {overwrite} (no batch journal to resume from)" if resume else "use {resume} or {overwrite}"
            raise OutputExistsError(f"{first} exists (not made by this batch); {hint}" if resume
                                    else f"{first} exists (a batch is already in {out}); {hint}",
                                    setting=("resume", "overwrite"))
    created = [q for q in [out, *out.parents] if not q.exists()]
    try:  # armed before the folder is made: a signal while it is made leaves none behind
        out.mkdir(parents=True, exist_ok=True)
        return _run_batch(recipe, out, names, workers=workers, scheduler=scheduler, resume=resume,
                          overwrite=overwrite, progress=progress, report=report, in_process=in_process)
    except BaseException:
        # a start that recorded no grain leaves nothing behind, so it never blocks a corrected rerun
        if not resume and not any(journal.glob("grain-*.json")):
            shutil.rmtree(journal, ignore_errors=True)
            for q in created:
                try:
                    q.rmdir()
                except OSError:
                    break
        raise


def _run_batch(recipe, out, names, *, workers, scheduler, resume, overwrite, progress, report, in_process):
    from .generate import MANIFEST, manifest_columns

    journal = out / JOURNAL
    saved = journal / "recipe.toml"
    for name in names + [MANIFEST]:  # leftovers of atomic writes interrupted by a kill
        for tmp in out.glob(f".{name}.*.tmp"):
            tmp.unlink(missing_ok=True)
    for tmp in journal.glob(".*.tmp"):  # the journal's own (sidecars, recipe copy): all ours
        tmp.unlink(missing_ok=True)
    if overwrite and journal.exists():
        for p in journal.glob("grain-*.json"):
            p.unlink()
    atomic_write(saved, recipe.text)

    rows: dict[int, dict] = {}
    if resume:
        for i in range(recipe.count):
            row = _intact_row(out, recipe, i)
            if row is not None:
                rows[i] = row
    reused = len(rows)
    todo = [i for i in range(recipe.count) if i not in rows]
    if scheduler:
        results = _dask_results(recipe, todo, scheduler)
    else:
        from ..runtime.workers import default_workers

        n = min(default_workers(workers), max(len(todo), 1))
        results = _local_results(recipe, todo, n, n == 1 if in_process is None else in_process)
    stream = results
    if progress is not None:
        results = progress(results)
    try:
        for res in results:
            _record(out, res)
            rows[res.index] = res.row
    finally:
        stream.close()  # on an error or interrupt: stop the workers now
    ordered = [rows[i] for i in range(recipe.count)]
    write_csv(out / MANIFEST, ordered, manifest_columns(recipe.method, ("sha256",)), units=True)
    summary = None
    if report:
        from .report import population_report

        summary = population_report(recipe, ordered, out)
    return {"generated": len(todo), "reused": reused, "rows": ordered, "summary": summary}
