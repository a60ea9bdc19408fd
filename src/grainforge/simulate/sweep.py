"""A sweep's engine runs on a Dask cluster, and its journal of finished runs (``--scheduler``, ``--resume``).

On a cluster
    Each engine run (one seed at one friction) is one Dask task running
    :func:`grainforge.simulate.engine.run_deck`, the function the local pool
    runs.  The driver writes the deck as usual (in its staging folder), sends
    the deck's files to the task as bytes (:func:`read_deck`); the task
    (:func:`run_remote`) writes them into a temporary folder on its worker,
    runs the engine there (under ``mpirun -np N`` with ``--mpi``) and returns
    the files the run made or changed (``result.json``, the engine's log, …),
    which the driver writes into the run's folder.  No shared filesystem is
    needed, and the run's folder in ``--out`` is the one a local run makes.
    A run that fails on its worker comes back with its log, so its deck and
    log are kept in ``--out/failed-<run>`` as for a local run.

The journal
    A finished run is copied (deck, ``result.json``, log; times kept) into
    :data:`JOURNAL` inside ``--out`` the moment it finishes (a copy into a
    hidden folder renamed into place: a run is in the journal whole or not at
    all), with the sweep's settings (``sweep.json``).  An interrupted sweep
    leaves its journal; ``--resume`` reuses each run found there whose deck
    is byte-identical to the one written now, runs the others, and removes the
    journal once the outputs are committed.  A resume asking other settings is
    refused (:func:`open_journal`).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError, OutputExistsError

__all__ = ["JOURNAL", "SweepJournal", "open_journal", "sweep_fingerprint", "read_deck", "run_remote", "run_on_cluster", "JournalMismatch"]

#: the folder inside ``--out`` that keeps the finished runs of a sweep until its outputs are committed
JOURNAL = ".grainforge-sweep"
#: the journal's record of the sweep's settings
SETTINGS_FILE = "sweep.json"
#: separator of a run's folder levels in its journal name (``runs+e0-mu0.5000+repose-seed0``)
SEP = "+"


class JournalMismatch(InputError):
    """A ``--resume`` whose settings or decks are not those of the interrupted sweep."""


def read_deck(folder: str | os.PathLike) -> dict[str, bytes]:
    """The files under ``folder`` as ``{relative POSIX path: bytes}`` (sorted by path).

    Parameters
    ----------
    folder : path
        A run's folder.

    Returns
    -------
    dict of str to bytes
        Each file's contents by its path relative to ``folder``.
    """
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def write_files(folder: str | os.PathLike, files: dict[str, bytes]) -> None:
    """Write ``files`` (as :func:`read_deck` returns them) under ``folder``."""
    folder = Path(folder)
    for name, data in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


#: the stand-in for a run's folder in the error message a remote run returns
DECK_MARK = "\0deck\0"


def run_remote(run, files: dict[str, bytes], *, name: str, engine: str = "yade",
               mpi: int | None = None) -> tuple[dict[str, bytes], dict | None, str | None]:
    """One engine run on a Dask worker: the deck ``files`` in a temporary folder ``name``, run there by ``run``.

    Parameters
    ----------
    run : callable
        :func:`grainforge.simulate.engine.run_deck` (passed in: this module does not import the engine's).
    files : dict of str to bytes
        The deck (:func:`read_deck`).
    name : str
        The run's folder name (``repose-seed0``).
    engine, mpi
        As :func:`grainforge.simulate.engine.run_deck` (``mpi`` ranks under ``mpirun`` on this worker).

    Returns
    -------
    (dict, dict or None, str or None)
        The files the run made or changed, its ``result.json`` (``None`` if it failed) and, if it failed, the
        engine's one-line error with the folder's path replaced by :data:`DECK_MARK`.
    """
    from .process import EngineFailed

    with tempfile.TemporaryDirectory(prefix="grainforge-run-") as tmp:
        deck = Path(tmp) / name
        deck.mkdir()
        write_files(deck, files)
        result = error = None
        try:
            result = run(deck, engine=engine, mpi=mpi)
        except EngineFailed as exc:
            error = str(exc).replace(str(deck), DECK_MARK)
        made = {k: v for k, v in read_deck(deck).items() if files.get(k) != v}
    return made, result, error


def run_on_cluster(executor, run, *, decks: Sequence[Path], which: Sequence[int], engine: str = "yade",
                   mpi: int | None = None, progress=None, journal: SweepJournal | None = None) -> dict[int, dict]:
    """Run the decks ``decks[k]`` for ``k`` in ``which`` as tasks of ``executor`` (:func:`run_remote` with ``run``,
    :func:`grainforge.simulate.engine.run_deck`).

    Each run's files are written into its folder as it comes back (and recorded in ``journal``);
    ``progress(k, fraction, phase)`` says when a run is sent and when it is done.

    Parameters
    ----------
    executor : grainforge.runtime.cluster.DaskExecutor
        The cluster the runs are sent to (its ``submit``).
    run : callable
        :func:`grainforge.simulate.engine.run_deck`, run on the worker by :func:`run_remote`.
    decks : sequence of Path
        Every run's folder, its deck written.
    which : sequence of int
        The indices of the decks to run (the others are kept from a journal).
    engine : {"yade", "liggghts"}
        The engine of the decks.
    mpi : int, optional
        LIGGGHTS only: ranks of each run under ``mpirun`` on its worker.
    progress : callable, optional
        ``progress(k, fraction, phase)`` when run ``k`` is sent and when it is done.
    journal : SweepJournal, optional
        Records each run as it comes back.

    Returns
    -------
    dict of int to dict
        ``result.json`` of each run, by its index.

    Raises
    ------
    EngineFailed
        A run failed on its worker: its folder has its deck and the engine's log (the other tasks are cancelled).
    grainforge.runtime.cluster.SchedulerLost
        The scheduler was lost (the runs finished are in their folders and the journal).
    """
    import concurrent.futures as cf

    from .process import EngineFailed

    futures = {}
    try:
        for k in which:
            futures[executor.submit(run_remote, run, read_deck(decks[k]), name=decks[k].name, engine=engine,
                                    mpi=mpi)] = k
            if progress is not None:
                progress(k, 0.0, "sent to the cluster")
        results = {}

        def take(fut, made, result, error):
            k = futures[fut]
            write_files(decks[k], made)
            if error is not None:
                raise EngineFailed(error.replace(DECK_MARK, str(decks[k])), decks[k])
            if journal is not None:
                journal.record(decks[k])
            results[k] = result
            if progress is not None:
                progress(k, 1.0, "done")

        for fut in cf.as_completed(futures):
            try:
                outcome = fut.result()
            except BaseException:  # a lost scheduler (or an interrupt): the runs already back are kept first
                for other in futures:
                    if (other is not fut and futures[other] not in results and other.done()
                            and not other.cancelled() and other.exception() is None
                            and other.result()[2] is None):
                        take(other, *other.result())
                raise
            take(fut, *outcome)
        return results
    finally:
        for fut in futures:
            fut.cancel()


class SweepJournal:
    """The finished runs of one sweep in ``out/.grainforge-sweep`` (see the module text).

    Parameters
    ----------
    folder : path
        The journal folder (made at the first finished run).
    fingerprint : dict
        The sweep's settings, written to ``sweep.json`` with the first run.
    stage : path, optional
        The staging folder the runs' folders lie in (their journal names are relative to it); set by
        :meth:`bind`.
    """

    def __init__(self, folder: str | os.PathLike, fingerprint: dict, stage: str | os.PathLike | None = None):
        self.folder = Path(folder)
        self.fingerprint = fingerprint
        self.stage = None if stage is None else Path(stage)
        self.reused = 0

    def bind(self, stage: str | os.PathLike) -> SweepJournal:
        """Set the staging folder the runs are made in; returns ``self``.

        Parameters
        ----------
        stage : path
            The staging folder of the command.

        Returns
        -------
        SweepJournal
            This journal.
        """
        self.stage = Path(stage)
        return self

    def _key(self, deck: Path) -> Path:
        rel = Path(deck).relative_to(self.stage) if self.stage is not None else Path(Path(deck).name)
        return self.folder / SEP.join(rel.parts)

    def finished(self) -> list[str]:
        """Journal names of the runs kept (sorted).

        Returns
        -------
        list of str
            The names, empty when the journal folder does not exist.
        """
        if not self.folder.is_dir():
            return []
        return sorted(p.name for p in self.folder.iterdir() if p.is_dir() and not p.name.startswith("."))

    def reuse(self, deck: str | os.PathLike, written: Sequence[str | os.PathLike]) -> dict | None:
        """Copy the kept run of ``deck`` into it and return its ``result.json``; ``None`` if none is kept.

        Parameters
        ----------
        deck : path
            The run's folder (in the staging folder).
        written : sequence of path
            The deck's files just written into it (:func:`grainforge.simulate.write_test_deck`).

        Returns
        -------
        dict or None
            The kept run's ``result.json``, or None when the journal holds no finished run of ``deck``.

        Raises
        ------
        JournalMismatch
            If a file of the deck just ``written`` differs from the kept run's (other templates or inputs).
        """
        deck = Path(deck)
        kept = self._key(deck)
        if not (kept / "result.json").is_file():
            return None
        for f in written:
            f = Path(f)
            rel = f.relative_to(deck)
            if not (kept / rel).is_file() or (kept / rel).read_bytes() != f.read_bytes():
                raise JournalMismatch(f"{{resume}}: {rel} of {deck.name} differs from the interrupted sweep's "
                                      "(other inputs or templates); use {overwrite} to start again",
                                      setting=("resume", "overwrite"))
        shutil.copytree(kept, deck, copy_function=shutil.copy2, dirs_exist_ok=True)
        self.reused += 1
        return json.loads((deck / "result.json").read_text())

    def record(self, deck: str | os.PathLike) -> None:
        """Copy the finished run in ``deck`` into the journal (whole or not at all).

        Parameters
        ----------
        deck : path
            The finished run's folder (in the staging folder); the first run also writes the sweep's settings.
        """
        deck = Path(deck)
        target = self._key(deck)
        self.folder.mkdir(parents=True, exist_ok=True)
        settings = self.folder / SETTINGS_FILE
        if not settings.is_file():
            # a name of its own per thread too: runs finishing at once in one process record at once
            tmp = self.folder / f".{SETTINGS_FILE}.{os.getpid()}.{threading.get_ident()}.tmp"
            tmp.write_text(json.dumps(self.fingerprint, indent=1, sort_keys=True) + "\n")
            tmp.replace(settings)
        tmp = Path(tempfile.mkdtemp(prefix=".run-", dir=self.folder))
        try:
            shutil.copytree(deck, tmp, copy_function=shutil.copy2, dirs_exist_ok=True)
            if target.exists():
                shutil.rmtree(target)
            tmp.replace(target)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)

    def remove(self) -> None:
        """Remove the journal (the outputs are committed)."""
        shutil.rmtree(self.folder, ignore_errors=True)


def _differences(saved: dict, now: dict) -> list[str]:
    out = []
    for key in sorted(set(saved) | set(now)):
        if saved.get(key) != now.get(key):
            out.append(f"{key} {_show(saved.get(key))} (now {_show(now.get(key))})")
    return out


def _show(value) -> str:
    if isinstance(value, list):
        return ", ".join(map(str, value))
    return "none" if value is None else str(value)


def open_journal(out: str | os.PathLike, fingerprint: dict, *, resume: bool = False,
                 overwrite: bool = False) -> SweepJournal:
    """The journal of a sweep into ``out``, checked against an interrupted sweep's before any work.

    ``fingerprint`` is the sweep's settings, a JSON-able dict whose keys name them as the user does
    (``--friction``).  An interrupted sweep's journal is removed with ``overwrite``; reused with ``resume``
    when its settings are these; a journal with no finished run (a sweep stopped before its first) is removed.

    Parameters
    ----------
    out : path
        The sweep's output folder (the journal is ``out/.grainforge-sweep``).
    fingerprint : dict
        The sweep's settings.
    resume : bool
        Continue an interrupted sweep with these settings (``--resume``).
    overwrite : bool
        Remove an interrupted sweep's journal (``--overwrite``).

    Returns
    -------
    SweepJournal
        The journal, empty or holding the runs an interrupted sweep finished.

    Raises
    ------
    grainforge.errors.OutputExistsError
        A journal with finished runs, without ``resume`` or ``overwrite`` (a ``FileExistsError``).
    JournalMismatch
        ``resume`` with other settings: one line naming the first that differs.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> j = open_journal(d, {"--seeds": 2})
    >>> (d / "run").mkdir(); _ = (d / "run" / "result.json").write_text("{}")
    >>> j.record(d / "run"); j.finished()
    ['run']
    >>> open_journal(d, {"--seeds": 3}, resume=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    grainforge.simulate.sweep.JournalMismatch: resume: the interrupted sweep in ... ran with --seeds 2 (now 3); ...
    """
    journal = SweepJournal(Path(out) / JOURNAL, json.loads(json.dumps(fingerprint)))
    if not journal.folder.exists():
        return journal
    runs = journal.finished()
    if overwrite or not runs:
        journal.remove()
        return journal
    if not resume:
        raise OutputExistsError(f"{journal.folder} holds {len(runs)} finished run(s) of an interrupted sweep; "
                                "use {resume} to continue it or {overwrite} to start again",
                                setting=("resume", "overwrite"))
    try:
        saved = json.loads((journal.folder / SETTINGS_FILE).read_text())
    except (OSError, ValueError):
        saved = {}
    diff = _differences(saved, journal.fingerprint)
    if diff:
        more = f" and {len(diff) - 1} more" if len(diff) > 1 else ""
        raise JournalMismatch(f"{{resume}}: the interrupted sweep in {journal.folder} ran with {diff[0]}{more}; "
                              "resume with its settings, or use {overwrite} to start again",
                              setting=("resume", "overwrite"))
    for tmp in journal.folder.glob(".*"):  # a copy cut short by the interrupt
        shutil.rmtree(tmp, ignore_errors=True) if tmp.is_dir() else tmp.unlink(missing_ok=True)
    return journal


def sweep_fingerprint(test: str, inputs, settings, **options) -> dict:
    """The settings of a sweep that decide its runs, keyed as the user names them (the journal's ``sweep.json``).

    Parameters
    ----------
    test : str
        The test (``"repose"``, ``"calibrate tilt"``, ...).
    inputs : sequence of path
        The inputs (recorded resolved).
    settings : Settings or TriaxialSettings
        The runs' settings.
    **options
        Further settings of the command (engine, ranks, representation, the search's options).

    Returns
    -------
    dict
        ``test``, ``inputs`` and every setting as ``--name``: value (``--rolling-friction`` only when above 0, so
        that a sweep begun before the setting existed resumes).

    Examples
    --------
    >>> from grainforge.simulate import Settings
    >>> record = sweep_fingerprint("repose", [], Settings(), engine="yade")
    >>> record["test"], record["--grains"], record["--engine"], "--rolling-friction" in record
    ('repose', 200, 'yade', False)
    """
    from dataclasses import asdict

    record = {"test": test, "inputs": [str(Path(p).resolve()) for p in inputs]}
    for key, value in {**asdict(settings), **options}.items():
        if key == "rolling_friction" and not value:  # none: the record of a sweep begun before the setting existed
            continue
        record["--" + key.replace("_", "-")] = value
    return record
