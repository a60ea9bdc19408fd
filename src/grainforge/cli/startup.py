"""The first thing the console script does: from then until a command runs, SIGINT or SIGTERM ends the process
at once with its line and code (``Interrupted.``, 130; ``Terminated.``, 143), raising nothing into the modules
being loaded (nothing is written and no process started yet).

The standard library's ``os``, ``signal`` and ``sys`` only, so that the handlers are armed a moment after
Python starts; :mod:`grainforge.cli.interrupts` takes over from them.
"""

from __future__ import annotations

import os
import signal
import sys

#: the signals a command stops on, with the line it prints
SIGNALS = {signal.SIGINT: "Interrupted.", signal.SIGTERM: "Terminated."}


def usual(signum: int):
    """The handler Python starts with for ``signum`` (SIGINT raises ``KeyboardInterrupt``)."""
    return signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL


def exit_now(signum, frame):  # pragma: no cover - exercised by a real signal
    """Print the signal's line and end the process at once with 128 + the signal."""
    try:
        sys.stderr.write(SIGNALS[signum] + "\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signum)


def arm() -> None:
    """End the process at once on SIGINT or SIGTERM from now on, unless the signal was inherited ignored (a
    background job's SIGINT stays ignored) or has a handler of the program that runs the command line."""
    for s in SIGNALS:
        if signal.getsignal(s) in (usual(s), exit_now):
            signal.signal(s, exit_now)
