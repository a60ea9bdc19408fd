"""The ``grainforge`` command group: its commands, its help, and how a command's end becomes an exit code.

Every user mistake (bad option, unreadable file, an output that exists) ends as one line on stderr and exit
code 2, without a traceback; any other error is a bug in grainforge, reported in one line naming the file its
traceback was written to, with exit code 1 (:mod:`grainforge.cli.errors`).  Signals: :mod:`grainforge.cli.interrupts`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .._version import __version__
from .errors import options_named, report
from .interrupts import signals_raised
from .leaving import leave_if_signalled, leave_on_signal

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
        with signals_raised(args), options_named():
            try:
                rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            except click.exceptions.Abort as exc:
                if exc.__cause__ is not None:  # click turns Ctrl-C into Abort
                    leave_on_signal(exc.__cause__)
                click.echo("Aborted.", err=True)
                sys.exit(1)
            except Exception as exc:
                leave_if_signalled()  # an error on a signal's way is its echo
                sys.exit(report(exc, self._command_name(args)))
            except BaseException as exc:  # Terminated, KeyboardInterrupt: the signal's line and code; SystemExit
                leave_on_signal(exc)
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
        for sub_name, sub in sorted({**cmd.commands, **getattr(cmd, "two_words", {})}.items())
    ]
    return [("Generator methods (grainforge generate METHOD)", methods), ("Subcommands", subcommands)]


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
    from .simulate_material import material

    simulate.simulate.add_command(simulate_calibrate.calibrate)
    simulate.simulate.two_words["calibrate material"] = material

    for command in (
        generate.generate, render.render, demo.demo, check.check, tray.tray, batch.batch,
        fourier.fourier, analyse.analyse, plot.plot, figures.figures, calibrate.calibrate, dem.dem, fit.fit, simulate.simulate,
        scan.scan,
    ):
        cli.add_command(command)
    apply_help_style(cli)


_register()
