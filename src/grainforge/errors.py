"""The errors grainforge raises for what its user can fix.

Every refusal of a setting, an input file or an output in the way is a :class:`GrainforgeError`; any other
exception that escapes grainforge is a bug in it.  The command line (docs/cli-contract.md) turns a
``GrainforgeError`` into one line and exit code 2, and anything else into one line naming the bug and the
file its traceback was written to, with exit code 1.

::

    GrainforgeError              something the user can fix
    ├── InputError (ValueError)  a bad setting or input: ParameterError, RecipeError, TooLargeError, ...
    │   └── FileFormatError      an input file that cannot be read (corrupt, truncated, another format)
    ├── OutputExistsError (FileExistsError)  an output is there already (``overwrite`` replaces it)
    └── EngineMissing (FileNotFoundError)    a DEM engine (Yade, LIGGGHTS, mpirun) is not installed

Each keeps the built-in exception it subclasses, so ``except ValueError`` (and ``pytest.raises(ValueError)``)
still catches an :class:`InputError`.

A message names the setting to change as Python names it, written ``{name}`` in the message and listed in
``setting``: ``InputError("out exists; use {overwrite}", setting="overwrite")`` reads "out exists; use
overwrite".  The command line names its option instead ("use --overwrite", :func:`name_settings`).

Examples
--------
>>> e = OutputExistsError("out/a.stl exists; use {overwrite}", setting="overwrite")
>>> str(e), isinstance(e, FileExistsError), e.settings
('out/a.stl exists; use overwrite', True, ('overwrite',))
>>> e.naming(lambda name: "--" + name)
'out/a.stl exists; use --overwrite'
>>> isinstance(InputError("count must be positive"), ValueError)
True
"""

from __future__ import annotations

import os
from collections.abc import Callable

__all__ = ["GrainforgeError", "InputError", "FileFormatError", "OutputExistsError", "EngineMissing",
           "name_settings"]


def _python_name(name: str) -> str:
    return name


#: how a message names a setting (:func:`name_settings`): as Python names it, unless the command line says otherwise
_NAMING: list[Callable[[str], str]] = [_python_name]


def name_settings(naming: Callable[[str], str] | None) -> Callable[[str], str]:
    """Name the settings in every :class:`GrainforgeError`'s message by ``naming`` from now on (the command
    line names its options: ``overwrite`` -> ``--overwrite``); ``None`` goes back to the Python names.

    Parameters
    ----------
    naming : callable or None
        The setting's Python name -> the name the message gives it.

    Returns
    -------
    callable
        The naming in force before (to restore it).

    Examples
    --------
    >>> previous = name_settings(lambda name: "--" + name.replace("_", "-"))
    >>> str(InputError("check {raw_shape}", setting="raw_shape"))
    'check --raw-shape'
    >>> _ = name_settings(previous)
    >>> str(InputError("check {raw_shape}", setting="raw_shape"))
    'check raw_shape'
    """
    previous = _NAMING[0]
    _NAMING[0] = naming or _python_name
    return previous


class GrainforgeError(Exception):
    """Something the user can fix: a setting, an input, an output in the way.

    Parameters
    ----------
    message : str
        What is wrong and, where it helps, what to change; each setting of ``setting`` written ``{name}``.
    setting : str or tuple of str, optional
        The setting(s) the message names (Python names: ``overwrite``, ``raw_shape``).

    Attributes
    ----------
    setting : str, tuple of str or None
        As given.
    """

    def __init__(self, message: str = "", *, setting: str | tuple[str, ...] | None = None):
        super().__init__(message)
        self.setting = setting

    @property
    def settings(self) -> tuple[str, ...]:
        """The settings the message names (``()`` if none)."""
        if self.setting is None:
            return ()
        return (self.setting,) if isinstance(self.setting, str) else tuple(self.setting)

    def naming(self, name_of: Callable[[str], str]) -> str:
        """The message, each of its settings named by ``name_of``.

        Parameters
        ----------
        name_of : callable
            A setting's Python name -> its name in the message.

        Returns
        -------
        str
        """
        text = str(self.args[0]) if self.args else ""
        for name in self.settings:
            text = text.replace("{" + name + "}", name_of(name))
        return text

    def __str__(self) -> str:
        return self.naming(_NAMING[0])


class InputError(GrainforgeError, ValueError):
    """A setting or an input that grainforge refuses (out of range, inconsistent, too large a job).

    Parameters
    ----------
    message : str
        What is wrong (see :class:`GrainforgeError`).
    setting : str or tuple of str, optional
        The setting(s) the message names.
    """


class FileFormatError(InputError):
    """An input file that cannot be read: corrupt, truncated, empty, or not the format its name says.

    Parameters
    ----------
    message : str
        What is wrong; it names the file.
    path : path, optional
        The file.
    setting : str or tuple of str, optional
        The setting(s) the message names.

    Examples
    --------
    >>> e = FileFormatError("a.stl: not an STL file", path="a.stl")
    >>> e.path.name, isinstance(e, ValueError)
    ('a.stl', True)
    """

    def __init__(self, message: str = "", *, path: str | os.PathLike | None = None,
                 setting: str | tuple[str, ...] | None = None):
        from pathlib import Path

        super().__init__(message, setting=setting)
        self.path = Path(path) if path is not None else None

    @classmethod
    def wrap(cls, path: str | os.PathLike, exc: BaseException) -> FileFormatError:
        """The error saying ``path`` cannot be read, for a reader's own exception ``exc`` (raise it ``from exc``).

        Parameters
        ----------
        path : path
            The file being read.
        exc : BaseException
            What the reader raised.

        Returns
        -------
        FileFormatError
            ``PATH: cannot read it (REASON)``, REASON being ``exc``'s message on one line (or its type).

        Examples
        --------
        >>> str(FileFormatError.wrap("scan.tif", ValueError("not a TIFF file")))
        'scan.tif: cannot read it (not a TIFF file)'
        """
        reason = " ".join(str(exc).split()) or type(exc).__name__
        return cls(f"{os.fspath(path)}: cannot read it ({reason})", path=path)


class OutputExistsError(GrainforgeError, FileExistsError):
    """An output file or folder exists and the call was not asked to replace it (``overwrite``).

    Parameters
    ----------
    message : str
        Which output exists and what to do (see :class:`GrainforgeError`).
    setting : str or tuple of str, optional
        The setting(s) the message names (``overwrite``, ``resume``).
    """


class EngineMissing(GrainforgeError, FileNotFoundError):
    """A program grainforge runs is not installed: a DEM engine (Yade, LIGGGHTS) or ``mpirun``.

    Parameters
    ----------
    message : str
        Which program, and how to install it.
    setting : str or tuple of str, optional
        The setting(s) the message names.
    """
