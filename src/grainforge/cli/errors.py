"""What a command says when it stops on an exception, and its exit code (docs/cli-contract.md).

- something the user can fix (a :class:`grainforge.errors.GrainforgeError`, an ``OSError`` on the user's path:
  not found, permission denied, a folder where a file is needed, an output that exists, the disk full;
  too little memory for the request): one line and exit code 2;
- anything else is a bug in grainforge: one line naming the exception and the file its traceback was written
  to (``grainforge-crash-PID.txt`` in the temporary folder), and exit code 1.

The library names a setting as Python does (``overwrite``); the command line names its option
(``--overwrite``): :func:`flag`, installed for a command's run by :func:`options_named`.
"""

from __future__ import annotations

import errno
import os
import sys
import tempfile
import traceback
from contextlib import contextmanager
from pathlib import Path

import click

from ..errors import GrainforgeError, name_settings

#: a setting whose option is not ``--`` and its name with dashes (``raw_shape`` -> ``--raw-shape``)
FLAGS = {
    "voxel_size": "--voxel-size-um",
    "targets": "--target",  # simulate calibrate material: one --target per test
}

#: the OSError numbers that are about the user's own paths (beside the FileNotFoundError, PermissionError,
#: IsADirectoryError, NotADirectoryError and FileExistsError kinds): a full disk or quota, a read-only file
#: system, a name too long, a loop of links, a file too large for the file system
USER_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.ENAMETOOLONG, errno.ELOOP, errno.EFBIG}

#: the OSError kinds that say what is wrong with a path the user gave
USER_OS_ERRORS = (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError, FileExistsError)

#: what a command that ran out of memory says, by command (the default suits the commands that make grains);
#: ``{what}`` is what the command was working on when it ran out (the MemoryError's argument), if it says
MEMORY_HINTS = {
    "check": "not enough memory to check {what}; files are read and checked one at a time, so check a "
             "version with fewer triangles, or a 3MF's objects in smaller files",
}
DEFAULT_MEMORY_HINT = "not enough memory for this request; ask for fewer or smaller grains"


def flag(setting: str) -> str:
    """The option that gives ``setting``.

    Examples
    --------
    >>> flag("overwrite"), flag("raw_shape"), flag("voxel_size")
    ('--overwrite', '--raw-shape', '--voxel-size-um')
    """
    return FLAGS.get(setting, "--" + setting.replace("_", "-"))


@contextmanager
def options_named():
    """While the block runs, the library's messages name options (``--overwrite``) instead of settings."""
    previous = name_settings(flag)
    try:
        yield
    finally:
        name_settings(previous)


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


def one_line(exc: BaseException) -> str:
    """``exc``'s message on one line."""
    return " ".join(str(exc).split())


def os_error(exc: OSError) -> str:
    """``out/x.png: permission denied`` rather than ``[Errno 13] ...``."""
    reason = (exc.strerror or type(exc).__name__).lower()
    name = exc.filename if exc.filename is not None else None
    return f"{name}: {reason}" if name is not None else one_line(exc) or reason


def users_os_error(exc: BaseException) -> bool:
    """Whether ``exc`` is an ``OSError`` about the user's own path (missing, not allowed, the disk full, ...).

    Examples
    --------
    >>> users_os_error(FileNotFoundError(2, "No such file or directory", "a.stl"))
    True
    >>> users_os_error(OSError(28, "No space left on device")), users_os_error(OSError("bad fd"))
    (True, False)
    """
    return isinstance(exc, USER_OS_ERRORS) or (isinstance(exc, OSError) and exc.errno in USER_ERRNOS)


def write_crash_report(exc: BaseException) -> Path:
    """Write ``exc``'s traceback, with the command line and the versions, to ``grainforge-crash-PID.txt`` in the
    temporary folder (whole or not at all: a temporary file renamed into place); its path."""
    from .._version import __version__

    path = Path(tempfile.gettempdir()) / f"grainforge-crash-{os.getpid()}.txt"
    text = (f"grainforge {__version__}, Python {sys.version.split()[0]}, {sys.platform}\n"
            f"command: {' '.join(sys.argv)}\n\n" + "".join(traceback.format_exception(exc)))
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", errors="replace") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


#: the most characters of a bug's message its line repeats (the whole is in the traceback's file)
BUG_MESSAGE_CHARS = 200


def bug_line(exc: BaseException, report: Path | None) -> str:
    """The one line of a bug: the exception, its message (cut at :data:`BUG_MESSAGE_CHARS`), where its traceback is.

    Examples
    --------
    >>> bug_line(TypeError("x" * 300), Path("/tmp/grainforge-crash-1.txt"))[:40]
    'a bug in grainforge (TypeError: xxxxxxxx'
    >>> bug_line(KeyError("volume"), None)
    "a bug in grainforge (KeyError: 'volume'); its traceback could not be written: please report it"
    """
    message = one_line(exc)
    if len(message) > BUG_MESSAGE_CHARS:
        message = message[:BUG_MESSAGE_CHARS - 1] + "…"
    what = type(exc).__qualname__ + (f": {message}" if message else "")
    if report is None:
        return f"a bug in grainforge ({what}); its traceback could not be written: please report it"
    return f"a bug in grainforge ({what}); the traceback is in {report}: please report it with that file"


def report(exc: Exception, command: str | None) -> int:
    """Say on stderr, in one line, why the command stopped on ``exc`` (not a signal's); its exit code.

    Parameters
    ----------
    exc : Exception
        What the command raised.
    command : str or None
        The command's name (what a ``MemoryError`` says depends on it).

    Returns
    -------
    int
        2 for what the user can fix, click's code for click's usage errors, 1 for a bug.
    """
    if isinstance(exc, click.ClickException):
        click.echo(f"Error: {exc.format_message()}", err=True)
        return exc.exit_code
    if isinstance(exc, GrainforgeError):
        click.echo(f"Error: {one_line(exc)}", err=True)
        return 2
    if users_os_error(exc):
        click.echo(f"Error: {os_error(exc)}", err=True)
        return 2
    if isinstance(exc, MemoryError):
        what = str(exc.args[0]) if exc.args and isinstance(exc.args[0], str) else ""
        click.echo(f"Error: {memory_message(command, what)}", err=True)
        return 2
    try:
        path = write_crash_report(exc)
    except OSError:
        path = None
    click.echo(f"Error: {bug_line(exc, path)}", err=True)
    return 1
