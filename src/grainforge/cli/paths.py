"""The CLI contract for paths, shared by every command that reads or writes files.

Call these at the *start* of a command, before any work, so a mistake costs
the user nothing and no file is written:

- :func:`output_file` / :func:`output_dir`: empty path, an existing output
  without ``--overwrite``, a file where a folder is needed (or the reverse),
  a folder that cannot be written into, an unsupported extension;
- :func:`mesh_inputs`: mesh files, folders and manifests (:func:`grainforge.io.inputs.mesh_paths`);

Each raises :class:`click.UsageError` / :class:`click.BadParameter`, which the
``grainforge`` group prints as one line with exit code 2.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> output_file(d / "a.png", overwrite=False, suffixes=(".png",)).name
'a.png'
>>> (d / "a.png").write_bytes(b"x")
1
>>> output_file(d / "a.png", overwrite=False)
Traceback (most recent call last):
...
click.exceptions.UsageError: ... exists; use --overwrite
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

import click

from ..errors import InputError

__all__ = ["OutPath", "output_file", "output_dir", "check_writable", "mesh_inputs", "refuse_existing"]

#: suffixes of the mesh files a folder argument expands to


class OutPath(click.Path):
    """``click.Path`` that refuses an empty string (click would turn ``""`` into ``.``, the current folder).

    Use it for every output option: ``type=OutPath(dir_okay=False)`` for a
    file, ``OutPath(file_okay=False)`` for a folder.
    """

    def __init__(self, **kwargs):
        kwargs.setdefault("path_type", Path)
        super().__init__(**kwargs)

    def convert(self, value, param, ctx):
        if isinstance(value, str) and value.strip() == "":
            self.fail("the path is empty; give a file or folder name", param, ctx)
        return super().convert(value, param, ctx)


def _hint(option: str | None) -> str:
    return f"{option}: " if option else ""


def _non_empty(path, option: str | None) -> Path:
    if path is None or str(path).strip() == "":
        raise click.UsageError(f"{_hint(option)}the path is empty; give a file or folder name")
    return Path(path)


def _first_existing(path: Path) -> Path:
    """``path`` or its nearest existing ancestor (the folder a write would have to create things in)."""
    p = path if path.is_absolute() else Path.cwd() / path
    while not p.exists() and not p.is_symlink():
        p = p.parent
    return p


def check_writable(path: str | os.PathLike, option: str | None = None) -> None:
    """Refuse when ``path`` (a file or folder to be created or replaced) cannot be written.

    Walks up to the nearest existing ancestor: a *file* there means a folder
    is needed where a file is (``NotADirectoryError`` otherwise, later); a
    folder there must accept a new file (probed by creating and removing a
    temporary file, which also catches read-only mounts and, as root,
    immutable folders).
    """
    path = Path(path)
    target = path if path.is_dir() else path.parent
    base = _first_existing(target)
    if not base.is_dir():
        raise click.UsageError(f"{_hint(option)}cannot write {path}: {base} is a file, not a folder")
    from .work import signals_held

    with signals_held():  # a Ctrl-C between the probe's creation and removal must not leave it behind
        try:
            fd, probe = tempfile.mkstemp(prefix=".grainforge-probe-", dir=base)
        except OSError as exc:
            reason = exc.strerror or type(exc).__name__
            raise click.UsageError(f"{_hint(option)}cannot write into {base} ({reason.lower()})") from None
        os.close(fd)
        os.unlink(probe)


def refuse_existing(paths: Iterable[Path], overwrite: bool) -> None:
    """Refuse (one line) when any of ``paths`` exists and ``overwrite`` is false."""
    if overwrite:
        return
    existing = [p for p in paths if p.exists()]
    if existing:
        more = f" ({len(existing)} output files would be replaced)" if len(existing) > 1 else ""
        raise click.UsageError(f"{existing[0]} exists{more}; use --overwrite")


def output_file(
    path, *, overwrite: bool, option: str | None = "--out", suffixes: Sequence[str] | None = None,
    also: Iterable[Path] = (),
) -> Path:
    """Validate an output *file* before any work; return it as a Path.

    Parameters
    ----------
    path : path-like
        The file the command will write.
    overwrite : bool
        The command's ``--overwrite``.  Without it an existing ``path`` (or any of ``also``) is refused.
    option : str, optional
        The option name for the message.
    suffixes : sequence of str, optional
        Allowed extensions (lower case, with the dot), e.g. ``(".png",)``.
    also : iterable of Path
        Further files the command writes next to ``path`` (checked for existence too).
    """
    path = _non_empty(path, option)
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise click.UsageError(
            f"{_hint(option)}{path.name!r} must end in {' or '.join(suffixes)} (the format written)")
    if path.is_dir():
        raise click.UsageError(f"{_hint(option)}{path} is a folder; give a file name")
    refuse_existing([path, *also], overwrite)
    check_writable(path, option)
    return path


def output_dir(path, *, overwrite: bool | None = None, option: str | None = "--out",
               files: Iterable[Path] = ()) -> Path:
    """Validate an output *folder* before any work; return it as a Path.

    ``files`` are outputs the command will write into it (paths inside the
    folder); without ``overwrite`` an existing one is refused.  Pass
    ``overwrite=None`` when the command checks existence itself.
    """
    path = _non_empty(path, option)
    if path.exists() and not path.is_dir():
        raise click.UsageError(f"{_hint(option)}{path} is a file, not a folder")
    if overwrite is not None:
        refuse_existing(files, overwrite)
    check_writable(path if path.is_dir() else path / "x", option)
    return path


def mesh_inputs(paths: Iterable[str | os.PathLike], what: str = "FILES") -> list[Path]:
    """Mesh files named by ``paths`` (:func:`grainforge.io.inputs.mesh_paths`), refused in one line as ``what``."""
    from ..io.inputs import mesh_paths

    try:
        return mesh_paths(paths)
    except InputError as exc:
        raise click.BadParameter(str(exc), param_hint=what) from None


