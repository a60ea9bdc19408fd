"""Ctrl-C and SIGTERM honoured at every moment of a command, imports included.

Some libraries guard their optional imports with ``except BaseException``
(trimesh does), so a ``KeyboardInterrupt`` raised while such a module loads
is swallowed and the command would run on to its end as if nothing had
happened; and an exception raised in the middle of a C extension's import
can leave it half made (a crash at exit was seen).  So a command loads its
heavy modules with :func:`preload`, after its checks and before any work:
a signal meanwhile ends the command at once with the usual line and code
(nothing is written yet, no process started), without raising anything
into the importing code.  :func:`signals_held` instead holds the signals
for a block that must not stop half-way (moving finished outputs into
place) and delivers the first one as it ends.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from collections.abc import Iterable

from ..runtime.staging import _handled, signals_held

__all__ = ["signals_held", "preload", "ready_for_work", "say_estimate", "STARTUP_MODULES"]

#: modules every working command needs, loaded by ``cli.main`` at start-up, while a signal still ends the
#: process at once (nothing written, no process started): trimesh swallows a ``KeyboardInterrupt`` raised
#: while it loads, and it is the longest import (a second or more on a busy machine)
STARTUP_MODULES = ("numpy", "scipy.spatial", "trimesh")

#: the signals a command stops on, with the line it prints
SIGNALS = {signal.SIGINT: "Interrupted.", signal.SIGTERM: "Terminated."}


def _exit_now(signum, frame):  # pragma: no cover - exercised by a real signal
    try:
        sys.stderr.write(SIGNALS[signum] + "\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum)


def preload(modules: Iterable[str]) -> None:
    """Import ``modules``; a SIGINT or SIGTERM meanwhile ends the process at once (exit 130 or 143, one line).

    Call it only where nothing needs cleaning up: before any output or process exists.

    Examples
    --------
    >>> preload(["json"])
    """
    with _handled(_exit_now):
        for name in modules:
            importlib.import_module(name)


def ready_for_work(modules: Iterable[str], seconds: float, *, bound: str = "about") -> None:
    """Before a long job: load the plotting backend and ``modules`` (:func:`preload`), then, when
    the job is estimated at 10 s or more, say so on stderr.

    ``seconds`` is the job's estimate; ``bound`` words it ("about", "at most about").
    """
    preload(["matplotlib"])
    import matplotlib

    matplotlib.use("Agg")
    preload(modules)  # before any work: no lazy import later can swallow a Ctrl-C
    say_estimate(seconds, bound=bound)


def say_estimate(seconds: float, *, bound: str = "about") -> None:
    """On stderr, the job's estimated time when it is 10 s or more (nothing below: a user waits for no such job)."""
    import click

    from ..runtime.estimate import duration

    if seconds >= 10:
        click.echo(f"estimated time: {bound} {duration(seconds)} (a rough model; the progress bar shows the "
                   "measured rate)", err=True)
