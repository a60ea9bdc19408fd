"""Ctrl-C and SIGTERM honoured at every moment of a command, imports included.

Some libraries guard their optional imports with ``except BaseException``
(trimesh does), so a ``KeyboardInterrupt`` raised while such a module loads
is swallowed and the command would run on to its end as if nothing had
happened; and an exception raised in the middle of a C extension's import
can leave it half made (a crash at exit was seen).  So a command loads its
heavy modules with :func:`grainforge.cli.work.preload`, after its checks and
before any work: a signal meanwhile ends the command at once with the usual
line and code (nothing is written yet, no process started), without raising
anything into the importing code.  :func:`grainforge.cli.work.signals_held`
instead holds the signals for a block that must not stop half-way (moving
finished outputs into place) and delivers the first one as it ends.  How the
process leaves after the command: :mod:`grainforge.cli.leaving`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager

from .startup import SIGNALS
from .startup import exit_now as _exit_now
from .startup import usual as _usual
from .work import preload

__all__ = ["STARTUP_MODULES", "Terminated", "arm_starting", "signals_raised", "SIGNAL_GRACE", "RESEND_AFTER"]

#: modules every working command needs, loaded by ``cli.main`` at start-up, while a signal still ends the
#: process at once (nothing written, no process started): trimesh swallows a ``KeyboardInterrupt`` raised
#: while it loads, and it is the longest import (a second or more on a busy machine)
STARTUP_MODULES = ("numpy", "scipy.spatial", "trimesh")



class Terminated(BaseException):
    """Raised in the main thread on SIGTERM, so every ``finally`` cleans up (staging folders, temp files, pools)."""


# A signal is honoured at every moment of a command's life, one mechanism for every command:
#
# 1. start-up (the console script, ``cli.main.main``, arms them before it imports the command group; then click's
#    parsing and the heavy modules every working command needs, ``STARTUP_MODULES``): nothing is written and no process started yet, so SIGINT or SIGTERM
#    ends the process at once with its line and code (``_exit_now``), raising nothing into the code
#    that imports (trimesh swallows a KeyboardInterrupt raised while it loads);
# 2. the command (``GrainforgeGroup.main``): the signal raises ``KeyboardInterrupt`` or ``Terminated`` in the
#    main thread, so every ``finally`` cleans up (staging folders, temp files, pools, engine processes); a
#    watcher sends the signal again while its exception seems lost (swallowed by a library, or raised inside
#    a finalizer) and ends the process after ``SIGNAL_GRACE`` whatever happens;
# 3. after the command (the outputs are in place or removed): a signal is recorded, and the process leaves
#    from an exit hook the moment the interpreter is done, with the signal's line and code if one came
#    (``grainforge.cli.leaving``), so none is lost during the interpreter's (slow) teardown.
#
# An inherited *ignored* SIGINT stays ignored (the POSIX convention for background jobs), so does an
# ignored SIGTERM.  A multiprocessing worker imports the program's main module too (as ``__mp_main__``): it
# keeps the default handlers, or a worker stopped by its owner would print the owner's line.

_WORKER = "__mp_main__" in sys.modules


def _owned() -> list[int]:
    """The stop signals this process handles itself (not inherited ignored), outside a pool worker."""
    if _WORKER or threading.current_thread() is not threading.main_thread():
        return []
    return [s for s in SIGNALS if signal.getsignal(s) in (_usual(s), _exit_now)]


def arm_starting() -> None:
    """Start-up: from now until a command runs, SIGINT or SIGTERM ends the process at once with its line and code
    (nothing is written and no process started yet).  The console script calls it first of all (importing
    :mod:`grainforge.cli` changes no handler)."""
    for s in _owned():
        signal.signal(s, _exit_now)


#: the exceptions the command's signal handlers raise
_SIGNAL_EXCEPTIONS = (Terminated, KeyboardInterrupt)


#: seconds a command has, after SIGINT or SIGTERM, to clean up and leave by the usual path; past them it prints
#: the signal's line and ends at once (a cleanup that hangs, a compiled extension that never returns).
SIGNAL_GRACE = 15.0
#: seconds the main thread may run on while the signal's exception seems lost before the signal is sent again.
#: The exception can be lost: raised inside a finalizer (Python then reports it and goes on) or inside a
#: library's ``except BaseException`` (trimesh guards its optional imports so); the command would otherwise
#: run on to its end.  A finalizer that runs while the exception unwinds hides it for a moment, hence the wait.
RESEND_AFTER = 0.4
#: the signals that stopped the command, the first first (its handlers raise once; the watcher runs once)
_LEAVING: list[int] = []
#: the signal whose line was printed (the command has left its code by the signal's path)
_SAID: list[int] = []
#: signals that came after the command ended (recorded, answered as the process leaves)
_LATE: list[int] = []
#: the exit code of the command (set by ``main``, the console script)
_CODE: list = []
#: set by ``main``: this process is the console script (not click's test runner in another program)
_CONSOLE: list[bool] = []


def _say(signum: int) -> int:
    """Print the signal's line (once in the console script's life) and return its exit code."""
    if not (_CONSOLE and _SAID):
        _SAID.append(signum)
        sys.stderr.write(SIGNALS[signum] + "\n")
        sys.stderr.flush()
    if _CONSOLE:  # the process is leaving on the signal: a finalizer that an interrupted write left half-closed
        sys.unraisablehook = lambda unraisable: None  # (a ZipFile's __del__) says nothing after the line
    return 128 + _SAID[0] if _CONSOLE else 128 + signum


def _carries_signal(exc) -> bool:
    """Whether ``exc`` is a signal's exception, or was raised while one was handled (chained to it)."""
    seen, todo = set(), [exc]
    while todo:
        e = todo.pop()
        if e is None or id(e) in seen:
            continue
        if isinstance(e, _SIGNAL_EXCEPTIONS):
            return True
        seen.add(id(e))
        todo += [e.__cause__, e.__context__]
    return False


def _unwinding(thread_id: int) -> bool:
    """Whether thread ``thread_id`` is handling a signal's exception (cleaning up in an ``except`` or
    ``finally``, or in a ``with`` block's exit)."""
    exc = sys._current_exceptions().get(thread_id)
    if isinstance(exc, tuple):  # Python 3.11: sys.exc_info()'s triple
        exc = exc[1]
    return _carries_signal(exc)


def _watch(signum: int) -> None:
    """After a signal: send it again to the main thread while its exception seems lost; past the grace, leave."""
    main = threading.main_thread().ident
    deadline = time.monotonic() + SIGNAL_GRACE
    lost_since = None
    while (now := time.monotonic()) < deadline:
        time.sleep(0.1)
        if _SAID or _LATE:  # the command has left its code: only the grace remains (in the console script)
            if not _CONSOLE:
                return
            continue
        if _unwinding(main):
            lost_since = None
        elif lost_since is None:
            lost_since = now
        elif now - lost_since >= RESEND_AFTER:
            lost_since = None
            signal.pthread_kill(main, signum)
    _exit_now(signum, None)  # the signal's line, then exit 128 + signum


def _leave_within_grace(signum: int) -> bool:
    """Note the signal; False if the command is already cleaning up after one (let it finish)."""
    if _LEAVING:
        return not _carries_signal(sys.exc_info()[1])
    _LEAVING.append(signum)
    threading.Thread(target=_watch, args=(signum,), name="grainforge-signal", daemon=True).start()
    return True


def _terminate(signum, frame):
    if _leave_within_grace(signum):
        raise Terminated()


def _interrupt(signum, frame):
    if _leave_within_grace(signum):
        raise KeyboardInterrupt


#: the handler that raises each stop signal's exception during the command
_RAISING = {signal.SIGINT: _interrupt, signal.SIGTERM: _terminate}


def _late(signum, frame):  # pragma: no cover - exercised by a real signal
    """A signal after the command ended: its outputs are in place (or removed); answered as the process leaves."""
    _LATE.append(signum)


def _signal_in_finalizer(hook):
    """An unraisable-exception hook: a signal's exception raised inside a finalizer (where Python would print it
    and go on) is raised again, by the signal, in the main thread; anything else goes to ``hook``."""

    def unraisable(args) -> None:
        if isinstance(args.exc_value, _SIGNAL_EXCEPTIONS):
            # sent again a moment later, so that its handler runs after this hook, in the main thread's own code
            sig = signal.SIGTERM if isinstance(args.exc_value, Terminated) else signal.SIGINT
            timer = threading.Timer(0.05, os.kill, (os.getpid(), sig))
            timer.daemon = True
            timer.start()
        else:
            hook(args)

    return unraisable


def _quiet_signal(hook):
    """An exception hook that prints nothing for a signal's exception, nor for any once a signal is honoured.  Compiled extensions (SciPy's Sobol
    tables, for one) report an exception they cannot pass on twice: its traceback through this hook, then the
    unraisable hook; the second raises the signal again, so the first must stay silent."""

    def excepthook(kind, value, tb) -> None:
        # once a stop signal is being honoured, an exception reported on its way (an extension whose
        # initialisation the signal broke reports "ImportError: initialization failed") is its echo: silent
        if not isinstance(value, _SIGNAL_EXCEPTIONS) and not _LEAVING:
            hook(kind, value, tb)

    return excepthook


def _will_work(args) -> bool:
    """Whether the command line runs a command (not only help or the version)."""
    words = [str(w) for w in (sys.argv[1:] if args is None else args)]
    return bool(words) and not any(w in ("-h", "--help", "--version") for w in words)


@contextmanager
def signals_raised(args=None):
    """The command's phase (``GrainforgeGroup.main``): the heavy modules loaded first (:data:`STARTUP_MODULES`,
    unless ``args`` only ask for help or the version), then SIGINT and SIGTERM raise ``KeyboardInterrupt`` and
    :class:`Terminated` in the main thread until the block ends; then the console script records a later signal
    (answered as the process leaves), and in-process (a test's runner) the handlers are those before."""
    owned = _owned()
    if owned and _will_work(args):
        # still at start-up: a signal meanwhile ends the process at once (nothing to clean up yet)
        preload(STARTUP_MODULES)
    previous = {s: signal.getsignal(s) for s in owned}
    for s in owned:
        signal.signal(s, _RAISING[s])
    hook, sys.unraisablehook = sys.unraisablehook, _signal_in_finalizer(sys.unraisablehook)
    excepthook, sys.excepthook = sys.excepthook, _quiet_signal(sys.excepthook)
    try:
        yield
    finally:
        for s in owned:  # the console script records a later signal; in-process, the usual handlers
            signal.signal(s, _late if _CONSOLE else _usual(s) if previous[s] is _exit_now else previous[s])
        if not (_CONSOLE and _SAID):  # leaving on a signal: _say's silence stays
            sys.unraisablehook, sys.excepthook = hook, excepthook
