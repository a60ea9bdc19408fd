"""``grainforge batch RECIPE.toml``: generate a population described by a recipe."""

from __future__ import annotations

from pathlib import Path

import click

from .help_style import option
from .options import overwrite_option, workers_option
from .paths import OutPath, output_dir
from .progress import progress_bar


@click.command()
@click.argument("recipe", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder for the grains, manifest.csv, manifest.json and population.png.")
@workers_option("Local worker processes.", default_text="the CPU count")
@option("--scheduler", metavar="ADDRESS", default=None,
        help="Run on an existing Dask distributed cluster, e.g. tcp://host:8786 "
             "(needs grainforge[dask]; workers must import the same grainforge).")
@option("--resume", is_flag=True, help="Continue an interrupted batch: keep intact grains, make the rest.")
@overwrite_option("Replace the outputs of an earlier batch in --out.")
def batch(recipe, out, workers, scheduler, resume, overwrite):
    """Generate the population described by RECIPE (TOML) into --out.

    Grain i's seed comes from the recipe's root seed alone, so the files are
    byte-identical for any number of workers and on a Dask cluster.
    """
    from ..population import load_recipe, run_batch

    if resume and overwrite:
        raise click.UsageError("--resume and --overwrite exclude each other")
    if scheduler and workers:
        raise click.UsageError("--workers is for the local pool; the Dask cluster decides its own workers")
    output_dir(out)  # run_batch decides what may be replaced (--resume, --overwrite)
    r = load_recipe(recipe)
    from ..runtime.cluster import SchedulerLost

    if scheduler:
        from ..runtime.cluster import check_address

        check_address(scheduler)
    from .interrupts import Terminated

    try:
        result = run_batch(r, out, workers=workers, scheduler=scheduler, resume=resume, overwrite=overwrite,
                           progress=progress_bar(total=r.count, desc=f"{r.method} population"))
    except FileExistsError as exc:
        raise click.UsageError(str(exc)) from None
    except SchedulerLost as exc:
        kept = _kept(out)
        raise click.ClickException(
            f"{exc}; kept the {kept} grain(s) finished in {out} (no manifest.csv yet): rerun with --resume "
            "to make the rest" if kept else f"{exc}; nothing kept in {out}: rerun when the cluster is back") from None
    except (KeyboardInterrupt, Terminated) as exc:
        # the exception to "all outputs or none": the finished grains stay, with their journal, for --resume
        kept = _kept(out)
        if not kept:
            raise
        click.echo(f"kept {kept} of {r.count} {r.method} grain(s) in {out} (no manifest.csv yet); to make the "
                   f"rest: {resume_command(recipe, out)}", err=True)
        if isinstance(exc, KeyboardInterrupt):  # as click's own Abort, without the blank line it echoes first
            raise click.exceptions.Abort() from exc
        raise
    if result["generated"] == 0 and result["reused"] == r.count:
        click.echo(f"the batch in {out} is already complete: all {r.count} {r.method} grains are intact, "
                   "none generated; manifest.csv, manifest.json and population.png rewritten", err=True)
    else:
        msg = f"wrote {result['generated']} {r.method} grain(s)"
        if result["reused"]:
            msg += f" (kept {result['reused']} intact from the interrupted batch)"
        click.echo(f"{msg}, manifest.csv, manifest.json and population.png to {out}", err=True)
    grading = (result["summary"] or {}).get("grading")
    if grading:
        click.echo(f"grading curve: max deviation from target {grading['max_abs_deviation_percent']:.1f} "
                   f"percentage points (by {grading['basis']})", err=True)


def _kept(out: Path) -> int:
    """Grains a stopped batch recorded in ``out``'s journal (kept for ``--resume``)."""
    from ..population import JOURNAL

    return len(list((out / JOURNAL).glob("grain-*.json"))) if (out / JOURNAL).is_dir() else 0


def resume_command(recipe, out) -> str:
    """The command that continues a stopped batch of ``recipe`` in ``out``, quoted for a POSIX shell.

    Parameters
    ----------
    recipe, out : path
        As given to the stopped command.

    Returns
    -------
    str
        ``grainforge batch RECIPE --out OUT --resume``.

    Examples
    --------
    >>> resume_command("sand.toml", "my grains")
    "grainforge batch sand.toml --out 'my grains' --resume"
    """
    import shlex

    return f"grainforge batch {shlex.quote(str(recipe))} --out {shlex.quote(str(out))} --resume"
