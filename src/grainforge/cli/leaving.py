"""After the command: the console script's exit with the command's code, or by a stop signal's path (its line
once, 128 + the signal), from an exit hook that skips the interpreter's teardown.

The signals' state and handlers are :mod:`grainforge.cli.interrupts`'; this module reads and records it.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading

from .interrupts import _CODE, _CONSOLE, _LATE, _LEAVING, _SAID, _SIGNAL_EXCEPTIONS, Terminated, _say, arm_starting
from .startup import SIGNALS

__all__ = ["leave_on_signal", "leave_if_signalled", "run_as_console_script"]


def _at_exit() -> None:  # pragma: no cover - runs as the console script leaves
    """The console script's last exit hook (registered first, so run last): leave now, with the code of the
    signal that came while the command ended or the interpreter finished (threads, other exit hooks), if any;
    the interpreter's teardown, during which a signal would be lost, is skipped."""
    if threading.current_thread() is threading.main_thread():
        signal.pthread_sigmask(signal.SIG_BLOCK, set(SIGNALS))
    pending = (_LEAVING + _LATE)[:1]
    if not _CODE and not pending:  # an unexpected error: Python reports it and leaves as usual
        return
    code = _CODE[0] if _CODE else 1
    if pending and not _SAID:
        code = _say(pending[0])
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a closed pipe: nothing more can be said
            pass
    if code is None or isinstance(code, int):
        os._exit(code or 0)


def leave_on_signal(exc: BaseException) -> None:
    """Leave by the signal's path (its line once, exit 128 + the signal) if ``exc`` is a stop signal's exception;
    else return."""
    if isinstance(exc, Terminated):
        sys.exit(_say(signal.SIGTERM))
    if isinstance(exc, KeyboardInterrupt):
        sys.exit(_say(signal.SIGINT))


def leave_if_signalled() -> None:
    """Leave by the signal's path if a stop signal is being honoured: an error on its way is its echo, not an
    error (an extension whose initialisation the signal broke raises "ImportError: initialization failed")."""
    if _LEAVING:
        sys.exit(_say(_LEAVING[0]))


def run_as_console_script(run) -> None:
    """Run ``run()`` (the command line) as the process: its signals at every moment, its exit code kept for the
    last exit hook, which leaves without the interpreter's teardown (see the top of this module)."""
    _CONSOLE.append(True)
    arm_starting()
    atexit.register(_at_exit)  # the first exit hook, so the last to run
    try:
        run()
    except SystemExit as exc:
        _CODE.append(exc.code)
        raise
    except _SIGNAL_EXCEPTIONS as exc:  # raised as the command ended, before its handlers were switched
        code = _say(signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)  # (once)
        _CODE.append(code)
        raise SystemExit(code) from None
