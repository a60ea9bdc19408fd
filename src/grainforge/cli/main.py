"""The ``grainforge`` command group and its error handling.

Every user mistake (bad option, unreadable file, an output that exists)
ends as one line on stderr and exit code 2; no traceback.
"""

from __future__ import annotations

import os
import signal
import sys
import threading


def _interrupted_while_starting(signum, frame):  # pragma: no cover - exercised by a real signal
    """Ctrl-C while the command line loads its modules: nothing is written yet, so leave at once."""
    try:
        sys.stderr.write("Interrupted.\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


# Loading click and the commands (NumPy, SciPy, ...) takes a second or two: a Ctrl-C meanwhile ends
# the command with the usual line and code instead of an import traceback. (An inherited *ignored*
# SIGINT stays ignored, the POSIX convention for background jobs.)
# A multiprocessing worker imports the program's main module too (as ``__mp_main__``): it must keep
# the default handlers, or a worker stopped by its owner would print the owner's line.
_WORKER = "__mp_main__" in sys.modules
_STARTING = not _WORKER and threading.current_thread() is threading.main_thread() \
    and signal.getsignal(signal.SIGINT) is signal.default_int_handler
if _STARTING:
    signal.signal(signal.SIGINT, _interrupted_while_starting)


def _terminated_while_starting(signum, frame):  # pragma: no cover - exercised by a real signal
    """SIGTERM while the command line loads its modules: the usual line and code, as later."""
    try:
        sys.stderr.write("Terminated.\n")
        sys.stderr.flush()
    finally:
        os._exit(128 + signal.SIGTERM)


_TERM_STARTING = not _WORKER and threading.current_thread() is threading.main_thread() \
    and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
if _TERM_STARTING:
    signal.signal(signal.SIGTERM, _terminated_while_starting)

import click  # noqa: E402

from .._version import __version__  # noqa: E402
from ..params import ParameterError  # noqa: E402
from .interrupts import _exit_now  # noqa: E402


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM, so every ``finally`` cleans up (staging folders, temp files, pools)."""


#: the exceptions the command's signal handlers raise
_SIGNAL_EXCEPTIONS = (Terminated, KeyboardInterrupt)


#: seconds a command has, after SIGINT or SIGTERM, to clean up and leave by the usual path; past them it prints
#: the signal's line and ends at once.  The exception a signal raises can be lost: raised inside a finalizer
#: (Python then reports it and goes on) or inside a library's ``except BaseException`` (trimesh guards its
#: optional imports so), the command would otherwise run on to its end.
SIGNAL_GRACE = 15.0
_LEAVING: list[int] = []


def _leave_within_grace(signum: int) -> None:
    if _LEAVING:
        return
    _LEAVING.append(signum)
    timer = threading.Timer(SIGNAL_GRACE, _exit_now, (signum, None))  # the signal's line, then exit 128 + signum
    timer.daemon = True
    timer.start()


def _terminate(signum, frame):
    _leave_within_grace(signum)
    raise Terminated()


def _interrupt(signum, frame):
    _leave_within_grace(signum)
    raise KeyboardInterrupt


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
    """An exception hook that prints nothing for a signal's exception.  Compiled extensions (SciPy's Sobol
    tables, for one) report an exception they cannot pass on twice: its traceback through this hook, then the
    unraisable hook; the second raises the signal again, so the first must stay silent."""

    def excepthook(kind, value, tb) -> None:
        if not isinstance(value, _SIGNAL_EXCEPTIONS):
            hook(kind, value, tb)

    return excepthook


class GrainforgeGroup(click.Group):
    """A click group that reports errors as a single line."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        import signal
        import threading

        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
        # Ctrl-C: KeyboardInterrupt as usual, with the same grace (an inherited ignored SIGINT stays ignored)
        own_int = main_thread and signal.getsignal(signal.SIGINT) is signal.default_int_handler
        if own_int:
            signal.signal(signal.SIGINT, _interrupt)
        hook, sys.unraisablehook = sys.unraisablehook, _signal_in_finalizer(sys.unraisablehook)
        excepthook, sys.excepthook = sys.excepthook, _quiet_signal(sys.excepthook)
        try:
            rv = self._main(args, prog_name, complete_var, standalone_mode, **extra)
        finally:
            sys.unraisablehook, sys.excepthook = hook, excepthook
            if own_int:
                signal.signal(signal.SIGINT, signal.default_int_handler)
            if main_thread:
                signal.signal(signal.SIGTERM, previous)
        return rv

    def _main(self, args, prog_name, complete_var, standalone_mode, **extra):
        import signal

        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except Terminated:
            click.echo("Terminated.", err=True)
            sys.exit(128 + signal.SIGTERM)
        except click.exceptions.Abort as exc:
            if isinstance(exc.__cause__, KeyboardInterrupt):  # click turns Ctrl-C into Abort
                click.echo("Interrupted.", err=True)
                sys.exit(130)
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
            click.echo("Interrupted.", err=True)
            sys.exit(130)
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

    Generators (paper: Hanaor et al., 3D printable geomaterials): FSO (fractal
    surface overlay), CRI (contour rotation interpolation; `grainforge fourier`
    measures the Fourier descriptors of grain images), DPA (directed polyhedra
    aggregation; `grainforge calibrate dpa` links its exponent to D_A).
    Populations from a TOML recipe: `grainforge batch` (local processes or
    Dask).  Run `grainforge COMMAND --help` for each command.
    """


def _register():
    from . import (
        analyse,
        batch,
        calibrate,
        check,
        dem,
        demo,
        figures,
        fit,
        fourier,
        generate,
        plot,
        render,
        scan,
        simulate,
        simulate_calibrate,
        tray,
    )
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
if _STARTING and signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
    signal.signal(signal.SIGINT, signal.default_int_handler)  # from here on: KeyboardInterrupt, cleaned up
if _TERM_STARTING and signal.getsignal(signal.SIGTERM) is _terminated_while_starting:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # GrainforgeGroup.main raises Terminated from here on


def main() -> None:  # console-script entry point
    cli.main(prog_name="grainforge")
