"""Before the work: a command's heavy modules loaded where a signal ends it at once (:func:`preload`), its
estimate said (:func:`ready_for_work`, :func:`say_estimate`), and the block that moves its outputs into place
held against signals (:func:`signals_held`).

Loaded before the command's signal handlers are armed: it imports the standard library only (and the rest
when a function is called).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable

from .startup import exit_now as _exit_now

__all__ = ["signals_held", "preload", "ready_for_work", "say_estimate", "say_short_estimate",
           "LONG_JOB_SECONDS", "SHORT_JOB_SECONDS"]


def signals_held():
    """Hold SIGINT and SIGTERM for a block that must not stop half-way and deliver the first as it ends
    (:func:`grainforge.runtime.staging.signals_held`, imported when used: this module is loaded before the
    command's signal handlers are armed, so it imports the standard library only)."""
    from ..runtime.staging import signals_held as held

    return held()


def preload(modules: Iterable[str]) -> None:
    """Import ``modules``; a SIGINT or SIGTERM meanwhile ends the process at once (exit 130 or 143, one line).

    Call it only where nothing needs cleaning up: before any output or process exists.

    Examples
    --------
    >>> preload(["json"])
    """
    from ..runtime.staging import _handled

    with _handled(_exit_now):
        for name in modules:
            importlib.import_module(name)


def ready_for_work(modules: Iterable[str], seconds: float, *, bound: str = "about",
                   most: float | None = None) -> None:
    """Before a long job: load the plotting backend and ``modules`` (:func:`preload`), then, when
    the job is estimated at over a minute, say so on stderr (a shorter one of 10 s or more:
    :func:`say_short_estimate`, once the inputs are read).

    ``seconds`` is the job's estimate; ``bound`` words it ("about", "at most about"); ``most``, the
    longest it may take where that differs (a search that may need more runs than usual).
    """
    preload(["matplotlib"])
    import matplotlib

    matplotlib.use("Agg")
    preload(modules)  # before any work: no lazy import later can swallow a Ctrl-C
    say_estimate(seconds, bound=bound, most=most)


#: estimates longer than this are said before any work; shorter ones of at least SHORT_JOB_SECONDS when the
#: inputs have been read (:func:`say_short_estimate`), so that a refused input is still the only line
LONG_JOB_SECONDS, SHORT_JOB_SECONDS = 60.0, 10.0


def say_estimate(seconds: float, *, bound: str = "about", most: float | None = None,
                 within: tuple[float, float] = (LONG_JOB_SECONDS, float("inf"))) -> None:
    """On stderr, the job's estimated time when it is over ``within[0]`` and at most ``within[1]`` seconds
    (by default over a minute), and the longest it may take when ``most`` is given and larger."""
    import click

    from ..runtime.estimate import duration

    if within[0] < seconds <= within[1]:
        longest = f"at most {duration(most)}; " if most is not None and most > seconds else ""
        click.echo(f"estimated time: {bound} {duration(seconds)} ({longest}a rough model; the progress bar shows "
                   "the measured rate)", err=True)


def say_short_estimate(seconds: float, *, most: float | None = None) -> None:
    """The estimate of a job of 10 s to a minute, once its inputs are read and before its main work (a longer
    one was said by :func:`ready_for_work`)."""
    say_estimate(seconds, most=most, within=(SHORT_JOB_SECONDS, LONG_JOB_SECONDS))
