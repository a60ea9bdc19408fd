"""The ``grainforge`` command group and its error handling.

Every user mistake (bad option, unreadable file, an output that exists)
ends as one line on stderr and exit code 2; no traceback.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
import time

from .interrupts import SIGNALS, Terminated, _exit_now  # the standard library only: quick

# A signal is honoured at every moment of a command's life, one mechanism for every command:
#
# 1. start-up (this module's imports, click's parsing, the heavy modules every working command needs:
#    ``interrupts.STARTUP_MODULES``): nothing is written and no process started yet, so SIGINT or SIGTERM
#    ends the process at once with its line and code (``_exit_now``), raising nothing into the code
#    that imports (trimesh swallows a KeyboardInterrupt raised while it loads);
# 2. the command (``GrainforgeGroup.main``): the signal raises ``KeyboardInterrupt`` or ``Terminated`` in the
#    main thread, so every ``finally`` cleans up (staging folders, temp files, pools, engine processes); a
#    watcher sends the signal again while its exception seems lost (swallowed by a library, or raised inside
#    a finalizer) and ends the process after ``SIGNAL_GRACE`` whatever happens;
# 3. after the command (the outputs are in place or removed): a signal is recorded, and the process leaves
#    from an exit hook the moment the interpreter is done, with the signal's line and code if one came
#    (``_at_exit``), so none is lost during the interpreter's (slow) teardown.
#
# An inherited *ignored* SIGINT stays ignored (the POSIX convention for background jobs), so does an
# ignored SIGTERM.  A multiprocessing worker imports the program's main module too (as ``__mp_main__``): it
# keeps the default handlers, or a worker stopped by its owner would print the owner's line.

_WORKER = "__mp_main__" in sys.modules


def _usual(signum: int):
    return signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL


def _owned() -> list[int]:
    """The stop signals this process handles itself (not inherited ignored), outside a pool worker."""
    if _WORKER or threading.current_thread() is not threading.main_thread():
        return []
    return [s for s in SIGNALS if signal.getsignal(s) in (_usual(s), _exit_now)]


def _arm_starting() -> None:
    for s in _owned():
        signal.signal(s, _exit_now)


# loading click and the commands takes a second on a busy machine
_arm_starting()

from pathlib import Path  # noqa: E402 (after the handlers: pathlib loads urllib and ipaddress, 30 ms)

import click  # noqa: E402

from .._version import __version__  # noqa: E402
from ..params import ParameterError  # noqa: E402
from .interrupts import STARTUP_MODULES, preload  # noqa: E402

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
        click.echo(SIGNALS[signum], err=True)
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


#: suffixes of a 3D image (a μCT scan's volume) that ``analyse`` hands to ``scan``
IMAGE_SUFFIXES = (".tif", ".tiff", ".npy", ".raw")


def _is_image_request(args: list[str]) -> bool:
    """Whether ``analyse``'s arguments name a 3D image (measured by ``scan``) rather than meshes: the first
    argument a file with an image suffix, a folder of TIFF slices only, or a raw image (``--raw-shape``)."""
    if "--raw-shape" in args:
        return True
    first = next((a for a in args if not a.startswith("-")), None)
    if first is None:
        return False
    path = Path(first)
    if path.suffix.lower() in IMAGE_SUFFIXES:
        return True
    if path.is_dir():
        try:
            suffixes = {q.suffix.lower() for q in path.iterdir() if q.is_file() and not q.name.startswith(".")}
        except OSError:
            return False
        return bool(suffixes) and suffixes <= {".tif", ".tiff"}
    return False


class GrainforgeGroup(click.Group):
    """A click group that reports errors as a single line; ``analyse`` of a 3D image runs ``scan``."""

    def format_help_text(self, ctx, formatter):
        """The docstring, then the generator methods (from :data:`grainforge.methods.METHODS`) and the
        subcommands of every group, so that ``grainforge --help`` names everything a user can run."""
        super().format_help_text(ctx, formatter)
        if ctx.parent is not None:
            return
        for title, rows in help_sections(self):
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)

    def resolve_command(self, ctx, args):
        name, command, rest = super().resolve_command(ctx, args)
        if name == "analyse" and _is_image_request(rest) and "scan" in self.commands:
            return "scan", self.commands["scan"], rest
        return name, command, rest

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
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
            rv = self._main(args, prog_name, complete_var, standalone_mode, **extra)
        finally:
            for s in owned:  # the console script records a later signal; in-process, the usual handlers
                signal.signal(s, _late if _CONSOLE else _usual(s) if previous[s] is _exit_now else previous[s])
            if not (_CONSOLE and _SAID):  # leaving on a signal: _say's silence stays
                sys.unraisablehook, sys.excepthook = hook, excepthook
        return rv

    def _main(self, args, prog_name, complete_var, standalone_mode, **extra):
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except Terminated:
            sys.exit(_say(signal.SIGTERM))
        except click.exceptions.Abort as exc:
            if isinstance(exc.__cause__, KeyboardInterrupt):  # click turns Ctrl-C into Abort
                sys.exit(_say(signal.SIGINT))
            click.echo("Aborted.", err=True)
            sys.exit(1)
        except click.ClickException as exc:
            click.echo(f"Error: {exc.format_message()}", err=True)
            sys.exit(exc.exit_code)
        except (ParameterError, FileExistsError, FileNotFoundError, ValueError) as exc:
            click.echo(f"Error: {_one_line(exc)}", err=True)
            sys.exit(2)
        except OSError as exc:  # permission denied, not a directory, disk full, ...: name the path
            click.echo(f"Error: {_os_error(exc)}", err=True)
            sys.exit(2)
        except MemoryError as exc:
            what = str(exc.args[0]) if exc.args and isinstance(exc.args[0], str) else ""
            click.echo(f"Error: {memory_message(self._command_name(args), what)}", err=True)
            sys.exit(2)
        except KeyboardInterrupt:
            sys.exit(_say(signal.SIGINT))
        except Exception:
            # a stop signal is being honoured and broke something on its way (an extension whose
            # initialisation it interrupted raises "ImportError: initialization failed"): its echo, not an error
            if _LEAVING:
                sys.exit(_say(_LEAVING[0]))
            raise
        if standalone_mode:
            sys.exit(rv if isinstance(rv, int) else 0)
        return rv


    def _command_name(self, args) -> str | None:
        """The subcommand named on the command line (the first word that is not an option), if any."""
        for word in sys.argv[1:] if args is None else args:
            if not str(word).startswith("-"):
                return str(word) if str(word) in self.commands else None
        return None


#: what a command that ran out of memory says, by command (the default suits the commands that make grains);
#: ``{what}`` is what the command was working on when it ran out (the MemoryError's argument), if it says
MEMORY_HINTS = {
    "check": "not enough memory to check {what}; files are read and checked one at a time, so check a "
             "version with fewer triangles, or a 3MF's objects in smaller files",
}
DEFAULT_MEMORY_HINT = "not enough memory for this request; ask for fewer or smaller grains"


def help_sections(group: click.Group) -> list[tuple[str, list[tuple[str, str]]]]:
    """The sections ``grainforge --help`` adds to its docstring: the registered generator methods
    (``generate METHOD``, with the first sentence of the method's docstring) and the subcommands of the other
    groups (``simulate repose``, with their short help).

    Parameters
    ----------
    group : click.Group
        The root group (:func:`cli`).

    Returns
    -------
    list of (str, list of (str, str))
        Each section's title and its (name, description) rows.
    """
    from ..methods import METHODS, get
    from .options import _first_sentence

    generate = group.commands.get("generate")
    methods = [(name, _first_sentence(get(name).__doc__ or "")) for name in sorted(METHODS)] if generate else []
    subcommands = [
        (f"{name} {sub_name}", sub.get_short_help_str(limit=200))
        for name, cmd in sorted(group.commands.items())
        if isinstance(cmd, click.Group) and cmd is not generate
        for sub_name, sub in sorted(cmd.commands.items())
    ]
    return [("Generator methods (grainforge generate METHOD)", methods), ("Subcommands", subcommands)]


def memory_message(command: str | None, what: str = "") -> str:
    """The one line said when ``command`` runs out of memory while working on ``what``.

    Examples
    --------
    >>> memory_message("check", "tray.3mf")[:53]
    'not enough memory to check tray.3mf; files are read a'
    >>> memory_message("check")[:39]
    'not enough memory to check these meshes'
    >>> memory_message("tray")
    'not enough memory for this request; ask for fewer or smaller grains'
    """
    hint = MEMORY_HINTS.get(command or "")
    if hint is None:
        return DEFAULT_MEMORY_HINT
    return hint.format(what=what or "these meshes")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _os_error(exc: OSError) -> str:
    """``cannot write out/x.png: permission denied`` rather than ``[Errno 13] ...``."""
    reason = (exc.strerror or type(exc).__name__).lower()
    name = exc.filename if exc.filename is not None else None
    return f"{name}: {reason}" if name is not None else _one_line(exc) or reason


@click.group(cls=GrainforgeGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="grainforge")
def cli():
    """grainforge: realistic, printable 3D grain shapes for geotechnical research.

    FSO, CRI and DPA follow the paper (Hanaor et al., 3D printable
    geomaterials).  Populations from a TOML recipe: `grainforge batch` (local
    processes or Dask).  Run `grainforge COMMAND --help` for each command.
    """


def _register():
    from . import analyse, batch, check, dem, demo, figures, fit, fourier, generate, plot, render, scan, simulate, tray
    from . import calibrate_dpa as calibrate
    from . import simulate_friction as simulate_calibrate
    from .options import apply_help_style

    simulate.simulate.add_command(simulate_calibrate.calibrate)

    for command in (
        generate.generate, render.render, demo.demo, check.check, tray.tray, batch.batch,
        fourier.fourier, analyse.analyse, plot.plot, figures.figures, calibrate.calibrate, dem.dem, fit.fit, simulate.simulate,
        scan.scan,
    ):
        cli.add_command(command)
    apply_help_style(cli)


_register()
if os.path.basename(sys.argv[0]) != "grainforge":  # imported by another program (tests): its usual handlers
    for _s in SIGNALS:
        if signal.getsignal(_s) is _exit_now:
            signal.signal(_s, _usual(_s))


def main() -> None:  # console-script entry point
    """Run the command line as the process: signals at every moment (see the top of this module)."""
    _CONSOLE.append(True)
    _arm_starting()
    atexit.register(_at_exit)  # the first exit hook, so the last to run
    try:
        cli.main(prog_name="grainforge")
    except SystemExit as exc:
        _CODE.append(exc.code)
        raise
    except _SIGNAL_EXCEPTIONS as exc:  # raised as the command ended, before its handlers were switched
        code = _say(signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)  # (once)
        _CODE.append(code)
        raise SystemExit(code) from None
