"""``grainforge generate METHOD``: write grains and a manifest into a folder.

One command per registered method (:data:`grainforge.methods.METHODS`), built
by :func:`make_command` from the method's ``Params`` dataclass alone: one
option per declared parameter (help, unit, default and range from
:func:`grainforge.params.param`), plus the output options.  A new generator
needs nothing here.

A method that needs options which are not plain parameters (``--aspect
L:I:S``, ``--target-fractal-dimension``) gets a *hook*: a module
``grainforge/cli/generate_<name>.py`` (see ``generate_cri.py`` and
``generate_dpa.py``) that may define

``HELP`` : str
    Text appended to the command's help (the method module's first docstring
    line).
``EXCLUDE`` : tuple of str
    Parameters whose derived option the hook replaces.
``OPTIONS`` : list of click options
    Extra options; their values reach ``prepare`` with the parameter values.
``prepare(values: dict) -> dict``
    Turns the option values into ``Params`` field values (``None`` = not
    given); may raise :class:`click.UsageError` / :class:`click.BadParameter`.
``check(params) -> None``
    Extra validation of the built ``Params`` before any work.

Method modules (``grainforge.methods.*``) never import click or this package.
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType, SimpleNamespace

import click

from ..methods import METHODS, get
from ..params import ParameterError
from .options import PRINTER_KEY, bad_parameter, build_params, output_options, param_options
from .progress import progress_bar


@click.group()
def generate():
    """Generate grains with one of the methods into a folder."""


def run_generate(method: str, params, *, out, count, seed, size, size_definition, fmt, overwrite, extra_columns=()):
    """Shared body of every ``generate METHOD`` command."""
    from ..population.generate import write_run
    from ..runtime.estimate import TooLargeError
    from .paths import output_dir

    output_dir(out)  # write_run refuses existing outputs without --overwrite
    seeds = range(seed, seed + count)  # not a list: memory does not grow with --count
    printer = click.get_current_context().meta.get(PRINTER_KEY)
    row_extra = {}
    try:
        if printer is not None:
            params, row_extra = _match_resolution(method, params, seeds, size, size_definition, printer)
            extra_columns = tuple(extra_columns) + tuple(row_extra)
        announce_estimate(method, params, count)
        write_run(
            method, params, seeds=seeds, out=out, fmt=fmt, size=size, size_definition=size_definition,
            overwrite=overwrite, progress=progress_bar(total=count, desc=f"{method} grains"),
            extra_columns=extra_columns, row_extra=row_extra,
        )
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    except (FileExistsError, TooLargeError) as exc:
        raise click.UsageError(str(exc)) from None
    click.echo(f"wrote {count} {method} grain(s) and manifest.csv to {out}", err=True)


#: options that make one grain of a method cheaper (named when a single grain is too long)
GRAIN_COST_OPTIONS = {"fso": "--subdivisions, --ridges or --frequencies", "cri": "--subdivisions",
                      "dpa": "--primaries or --smooth"}


def announce_estimate(method: str, params, count: int, workers: int = 1, count_option: str = "--count") -> float:
    """Refuse a job estimated beyond a day (naming the option that shortens it); announce one over a minute."""
    from ..runtime.estimate import SECONDS_LIMIT, check_job, duration, grain_seconds

    each = grain_seconds(method, params)
    option = count_option if each * 2 <= SECONDS_LIMIT else GRAIN_COST_OPTIONS.get(method, "--subdivisions")
    total = check_job(count, each, what=f"{count} {method} grain(s)", option=option, workers=workers)
    if total > 60:
        click.echo(f"estimated time: about {duration(total)} for {count} {method} grain(s) "
                   "(a rough model; the progress bar shows the measured rate)", err=True)
    return total


def _match_resolution(method, params, seeds, size, size_definition, printer):
    """Choose ``subdivisions`` for ``printer`` at ``size``; report it; return (params, manifest extras)."""
    import dataclasses

    from ..fabrication.resolution import match_subdivisions

    res = match_subdivisions(method, params, size=size, size_definition=size_definition, printer=printer,
                             seeds=seeds[:3])
    click.echo(f"resolution matching ({printer.name}, {printer.resolution * 1000:g} µm): {res.describe()}", err=True)
    warning = res.shape_warning(size)
    if warning is not None:
        click.echo(f"WARNING: {warning}  Print larger or on a finer printer, or give --subdivisions (without "
                   "--printer) to keep the detail in the file; recorded in manifest.csv (resolution_warning).", err=True)
    extras = {"printer": printer.name, "chordal_deviation": res.deviation, "deviation_tolerance": res.tolerance,
              "mean_edge": res.edge, "resolution_limited_by": res.limited_by,
              "retained_wavelength": res.retained_wavelength(), "resolution_warning": warning or ""}
    return dataclasses.replace(params, subdivisions=res.subdivisions), extras


_NO_HOOK = SimpleNamespace()


def hook(method: str) -> ModuleType | SimpleNamespace:
    """The CLI hook module ``grainforge.cli.generate_<method>``, or an empty namespace if there is none."""
    name = f"{__package__}.generate_{method}"
    if importlib.util.find_spec(name) is None:
        return _NO_HOOK
    return importlib.import_module(name)


def make_command(method: str) -> click.Command:
    """The ``generate METHOD`` command: options from the method's Params, plus its hook's (if any)."""
    from ..fabrication.resolution import supports_matching

    module = get(method)
    extra = hook(method)
    help_text = (module.__doc__ or "").strip().splitlines()[0] + getattr(extra, "HELP", "")

    def command(out, count, seed, size, size_definition, fmt, overwrite, **values):
        prepare = getattr(extra, "prepare", None)
        if prepare is not None:
            values = prepare(values)
        params = build_params(module.Params, values)
        check = getattr(extra, "check", None)
        if check is not None:
            check(params)
        run_generate(method, params, out=out, count=count, seed=seed, size=size,
                     size_definition=size_definition, fmt=fmt, overwrite=overwrite)

    for option in reversed(getattr(extra, "OPTIONS", ())):
        command = option(command)
    command = param_options(module.Params, exclude=tuple(getattr(extra, "EXCLUDE", ())))(command)
    command = output_options(command, printer=supports_matching(method))
    return click.command(name=method, help=help_text)(command)


for _name in METHODS:
    generate.add_command(make_command(_name))
