"""Staging of a command's outputs: all of a run appears in ``--out`` or none of it; a failed run's deck is kept."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..runtime.staging import commit_stage, discard_stage, open_stage, staged

__all__ = ["open_stage", "staged", "commit_stage", "discard_stage", "FAILED_PREFIX", "keep_failed"]


#: name prefix of the folder in ``--out`` that keeps a failed run's deck and log
FAILED_PREFIX = "failed-"


def keep_failed(deck: str | os.PathLike, out: str | os.PathLike) -> Path:
    """Move a failed run's folder (deck and engine log) to ``out/failed-<name>`` and return that path.

    An earlier ``failed-<name>`` folder is replaced: it is a diagnostic of the
    last failure, not a result.  The successful outputs stay staged (nothing
    else of the failed command appears in ``out``).

    Parameters
    ----------
    deck : path
        The failed run's folder (in the staging folder).
    out : path
        The command's output folder.

    Returns
    -------
    Path
        ``out/failed-<name>``, where the folder now is.
    """
    deck, out = Path(deck), Path(out)
    target = out / f"{FAILED_PREFIX}{deck.name}"
    if target.is_dir() and not target.is_symlink():
        shutil.rmtree(target)
    elif target.exists() or target.is_symlink():
        target.unlink()
    deck.replace(target)
    return target
