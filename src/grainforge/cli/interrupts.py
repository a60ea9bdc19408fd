"""Ctrl-C and SIGTERM honoured at every moment of a command, imports included.

Some libraries guard their optional imports with ``except BaseException``
(trimesh does), so a ``KeyboardInterrupt`` raised while such a module loads
is swallowed and the command would run on to its end as if nothing had
happened.  :func:`never_lost` runs a block (imports, quick checks) with
handlers that note each signal before the usual handler raises: a signal
that something swallowed is raised again every 50 ms (SIGALRM) until it
leaves the block.  :func:`preload` imports a
command's heavy modules that way, before any work, so that no lazy import
later can swallow one.  :func:`signals_held` instead holds the signals for
the whole block (moving finished outputs into place, which must not stop
half-way) and delivers the first one as it ends.
"""

from __future__ import annotations

import importlib
import signal
import threading
from contextlib import contextmanager
from typing import Iterable, Iterator

__all__ = ["signals_held", "never_lost", "preload"]

#: the signals a command stops on
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: seconds between the raises of a signal that something swallowed
RETRY = 0.05


@contextmanager
def _handled(hold: bool) -> Iterator[list]:
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    got: list[int] = []
    previous = {s: signal.getsignal(s) for s in SIGNALS}

    def handler(signum, frame):
        got.append(signum)
        usual = previous[signum]
        if not hold and callable(usual):
            # raise at once (KeyboardInterrupt, Terminated); should something swallow it, raise it again every
            # RETRY seconds (SIGALRM) until it leaves the block
            signal.setitimer(signal.ITIMER_REAL, RETRY, RETRY)
            usual(signum, frame)

    def again(signum, frame):
        if got:
            previous[got[0]](got[0], frame)

    def restore():
        if not hold:
            signal.setitimer(signal.ITIMER_REAL, 0)
        for s, usual in previous.items():
            signal.signal(s, usual if usual is not None else signal.SIG_DFL)

    if not hold:
        previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, again)
    for s in SIGNALS:
        if previous[s] is not signal.SIG_IGN:  # an ignored signal (SIGINT of a background job) stays ignored
            signal.signal(s, handler)
    try:
        yield got
    except BaseException:
        restore()
        if got:  # the signal first: whatever failed after an import swallowed it (a half-loaded module) is moot
            signal.raise_signal(got[0])
        raise
    restore()
    if got:
        signal.raise_signal(got[0])  # held, or swallowed: the usual handler now


def signals_held() -> Iterator[list]:
    """Hold SIGINT and SIGTERM during the block; deliver the first one that came as it ends.

    Yields the list of signals held so far.  Outside the main thread (where
    Python cannot set handlers) nothing is held.

    Examples
    --------
    >>> with signals_held() as got:
    ...     got
    []
    """
    return _handled(True)


def never_lost() -> Iterator[list]:
    """Handle SIGINT and SIGTERM as usual during the block, and deliver again one that the block swallowed.

    Examples
    --------
    >>> with never_lost() as got:
    ...     got
    []
    """
    return _handled(False)


def preload(modules: Iterable[str]) -> None:
    """Import ``modules`` so that no signal is lost during the imports (see the module text)."""
    with never_lost() as got:
        for name in modules:
            if got:
                break
            importlib.import_module(name)
