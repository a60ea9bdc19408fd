"""``grainforge generate METHOD``: write grains and a manifest into a folder."""

from __future__ import annotations

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
    from ..estimate import TooLargeError
    from ..run import write_run
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
            method, params, seeds, out, fmt=fmt, size=size, size_definition=size_definition,
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
    from ..estimate import SECONDS_LIMIT, check_job, duration, grain_seconds

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

    from ..fabrication.resolution import match_subdivisions, supports_matching

    if not supports_matching(method):
        raise click.BadParameter(
            f"resolution matching applies to methods with --subdivisions (fso, cri), not {method}",
            param_hint="'--printer'",
        )
    res = match_subdivisions(method, params, size, size_definition, printer, seeds[:3])
    click.echo(f"resolution matching ({printer.name}, {printer.resolution * 1000:g} µm): {res.describe()}", err=True)
    extras = {"printer": printer.name, "chordal_deviation": res.deviation, "deviation_tolerance": res.tolerance,
              "mean_edge": res.edge, "resolution_limited_by": res.limited_by}
    return dataclasses.replace(params, subdivisions=res.subdivisions), extras


def make_command(method: str) -> click.Command:
    """A ``generate METHOD`` command whose options come from the method's Params.

    A method module may define ``cli_command(run_generate)`` to build its own
    command (for options that are not plain parameters).
    """
    module = get(method)
    custom = getattr(module, "cli_command", None)
    if custom is not None:
        return custom(run_generate)

    @click.command(name=method, help=(module.__doc__ or "").strip().splitlines()[0])
    @output_options
    @param_options(module.Params)
    def command(out, count, seed, size, size_definition, fmt, overwrite, **values):
        params = build_params(module.Params, values)
        run_generate(method, params, out=out, count=count, seed=seed, size=size,
                     size_definition=size_definition, fmt=fmt, overwrite=overwrite)

    return command


for _name in METHODS:
    generate.add_command(make_command(_name))
