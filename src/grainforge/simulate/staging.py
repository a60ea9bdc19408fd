"""Staging of a command's outputs: all of a run appears in ``--out`` or none of it; a failed run's deck is kept."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["open_stage", "staged", "commit_stage", "discard_stage", "FAILED_PREFIX", "keep_failed"]


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


@contextmanager
def staged(out: str | os.PathLike) -> Iterator[Path]:
    """``with staged(out) as stage:`` a staging folder (:func:`open_stage`), removed on the way out with ``out``
    itself when this run created it and left it empty (:func:`discard_stage`) — also when a signal lands while
    the folders are being made: whether ``out`` existed is noted before anything is made, and the clean-up is
    armed before :func:`open_stage` runs."""
    out = Path(out)
    created, stage = not out.exists(), None
    try:
        stage = open_stage(out)[0]
        yield stage
    finally:
        discard_stage(stage, out, created)


def discard_stage(stage: Path | None, out: str | os.PathLike, created: bool) -> None:
    """Remove ``stage`` (empty after :func:`commit_stage`; None: none was made) and ``out`` if this run created
    it and it is empty."""
    if stage is not None:
        shutil.rmtree(stage, ignore_errors=True)
    out = Path(out)
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


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
