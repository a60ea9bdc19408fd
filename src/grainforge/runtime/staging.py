"""Staging of a command's outputs: all of a run appears in its output folder or none of it.

A run writes into a hidden folder inside ``out`` (:data:`STAGING_PREFIX` and its process id), then moves
everything into place at once (:func:`commit_stage`, with SIGINT and SIGTERM held by :func:`signals_held` while
the files move, so a signal then is answered after the last one); an interrupt or failure removes the folder, and
``out`` too when the run made it (:func:`staged`); a SIGKILLed run's folder is removed by the next run in ``out``.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputExistsError
from .children import remove_leftovers

__all__ = ["signals_held", "STAGING_PREFIX", "remove_stale_staging", "open_stage", "staged", "commit_stage", "discard_stage"]


#: the signals a command stops on (Ctrl-C and a polite kill)
HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def _handled(handler) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in HELD_SIGNALS}
    for s, usual in previous.items():
        if usual is not signal.SIG_IGN:  # an ignored signal (SIGINT of a background job) stays ignored
            signal.signal(s, handler)
    try:
        yield
    finally:
        for s, usual in previous.items():
            signal.signal(s, usual if usual is not None else signal.SIG_DFL)


@contextmanager
def signals_held() -> Iterator[list]:
    """Hold SIGINT and SIGTERM during the block; deliver the first one that came as it ends.

    Yields the list of signals held so far.  Outside the main thread (where
    Python cannot set handlers) nothing is held.

    Yields
    ------
    list of int
        The signal numbers received so far during the block.

    Examples
    --------
    >>> with signals_held() as got:
    ...     got
    []
    """
    got: list[int] = []
    with _handled(lambda signum, frame: got.append(signum)):
        yield got
    if got:
        signal.raise_signal(got[0])  # the usual handler now: KeyboardInterrupt, Terminated, or the default


def remove_stale_staging(out: Path) -> None:
    """Remove staging folders of runs that were killed (their process is gone).

    Parameters
    ----------
    out : Path
        An output folder (nothing happens when it does not exist).
    """
    remove_leftovers(out, STAGING_PREFIX)


#: hidden folder a run stages its files in (``.grainforge-staging-PID-XXXX``)
STAGING_PREFIX = ".grainforge-staging-"


def open_stage(out: str | os.PathLike) -> tuple[Path, bool]:
    """A hidden staging folder inside ``out`` for one command's outputs; whether ``out`` was created.

    Staging folders of killed runs (their process gone) are removed first,
    so a run killed by SIGKILL never blocks the next one.

    Parameters
    ----------
    out : str or os.PathLike
        The output folder (created, with its parents, if missing).

    Returns
    -------
    stage : Path
        A new folder ``out/.grainforge-staging-PID-XXXX``.
    created : bool
        Whether ``out`` did not exist before.
    """
    out = Path(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(out)
    return Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-", dir=out)), created


def commit_stage(stage: Path, out: str | os.PathLike, *, overwrite: bool = False) -> list[Path]:
    """Move everything in ``stage`` into ``out`` (folders first, then files): the outputs appear together.

    An existing output is replaced only with ``overwrite`` (else ``FileExistsError``, nothing moved).

    Parameters
    ----------
    stage : Path
        The staging folder (:func:`open_stage`).
    out : str or os.PathLike
        The output folder.
    overwrite : bool, default False
        Replace outputs that exist (a folder is removed first).

    Returns
    -------
    list of Path
        The outputs now in ``out``, folders first.

    Raises
    ------
    grainforge.errors.OutputExistsError
        Without ``overwrite``, when an output exists (a ``FileExistsError``); nothing is moved then.
    """
    out = Path(out)
    items = sorted(stage.iterdir(), key=lambda p: (not p.is_dir(), p.name))
    if not overwrite:
        for p in items:
            if (out / p.name).exists():
                raise OutputExistsError(f"{out / p.name} exists; use {{overwrite}}", setting="overwrite")
    moved = []
    with signals_held():  # a signal meanwhile is answered once every output is in place
        for p in items:
            target = out / p.name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            p.replace(target)
            moved.append(target)
    return moved


@contextmanager
def staged(out: str | os.PathLike) -> Iterator[Path]:
    """``with staged(out) as stage:`` a staging folder (:func:`open_stage`), removed on the way out with ``out``
    itself when this run created it and left it empty (:func:`discard_stage`) — also when a signal lands while
    the folders are being made: whether ``out`` existed is noted before anything is made, and the clean-up is
    armed before :func:`open_stage` runs.

    Parameters
    ----------
    out : str or os.PathLike
        The output folder.

    Yields
    ------
    Path
        The staging folder; commit it with :func:`commit_stage` before the block ends.
    """
    out = Path(out)
    created, stage = not out.exists(), None
    try:
        stage = open_stage(out)[0]
        yield stage
    finally:
        discard_stage(stage, out, created)


def discard_stage(stage: Path | None, out: str | os.PathLike, created: bool) -> None:
    """Remove ``stage`` (empty after :func:`commit_stage`; None: none was made) and ``out`` if this run created
    it and it is empty.

    Parameters
    ----------
    stage : Path or None
        The staging folder, or None.
    out : str or os.PathLike
        The output folder.
    created : bool
        Whether this run created ``out`` (then it is removed when empty).
    """
    if stage is not None:
        shutil.rmtree(stage, ignore_errors=True)
    out = Path(out)
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()
