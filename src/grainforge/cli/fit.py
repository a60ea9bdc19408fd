"""``grainforge fit SAND.csv --out DIR``: a recipe whose grains match a real sand's measured shapes."""

from __future__ import annotations

from pathlib import Path

import click

from .help_style import option
from .options import (
    EXIT_CHECK_FAILED,
    FiniteFloatRange,
    overwrite_option,
    renamed_option,
    seed_option,
    voxel_size_options,
    workers_option,
)
from .paths import OutPath, output_dir
from .progress import progress_bar

#: exit status of a fit that ran to the end, wrote its outputs and does not pass its criteria
#: (docs/cli-contract.md): a script can tell it from success (0) and from a refusal (2)
EXIT_NOT_PASSED = EXIT_CHECK_FAILED

#: modules a fit loads before any work (see cli.work.preload)
HEAVY_MODULES = ("trimesh", "scipy.optimize", "scipy.stats", "scipy.ndimage", "skimage.measure",
                 "grainforge.analysis.atlas", "grainforge.methods", "grainforge.population", "grainforge.runtime.workers",
                 "grainforge.io", "matplotlib.pyplot")


@click.command()
@click.argument("sand", type=click.Path(dir_okay=False, path_type=Path))
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder for recipe.toml, fit.csv, fit-stats.csv and fit.png.")
@voxel_size_options("um", "Voxel size of the sand's scan in µm; required unless the CSV has a 'Voxel Size (µm)' "
                          "column.")
@renamed_option("--voxel-size", "--voxel-size-um", "µm")
@option("--method", default="rf", show_default=True,
        help="Generator to fit (a method registered in grainforge.fit.FITS), or auto: each, keep the best. "
             "rf grains respond smoothly to their settings, CRI grains less so (docs/fit.md).")
@option("--count", type=click.IntRange(min=500, max=10**7), default=500, show_default=True,
        help="Grains of the recipe (>= 500), each the twin of one sand grain: sand rows drawn without "
             "replacement, or all rows and then repeats when --count exceeds the sand's.")
@option("--refine", type=click.IntRange(min=0, max=10), default=4, show_default=True,
        help="Rounds of per-grain refinement of the twins that miss their sand grain.")
@option("--reseed", type=click.IntRange(min=0, max=20), default=6, show_default=True,
        help="Other seeds tried by each twin still off by more than 0.03 after the refinement (a kept seed "
             "is written to the recipe).")
@option("--population-grains", type=click.IntRange(min=10, max=10**7), default=300, show_default=True,
        help="Twins remade in each round that estimates the sand's mean settings (2 rounds; 4 with an "
             "opening-fraction column; at most --count): its standard errors shrink as 1/sqrt(grains), down "
             "to what the sand's grain count allows.")
@option("--population-slopes", type=click.Choice(["auto", "measured", "model"]), default="auto",
        show_default=True,
        help="Slopes the mean-settings estimate steps through: measured on the grains (2 x settings x up to "
             "300 grains more; matches the means to their noise on large tables), the design model's "
             "(free, off on angular sands), or auto: measured from --population-grains 1000. With an "
             "opening-fraction column they are always measured (the model does not predict it).")
@option("--design-grains", type=click.IntRange(min=50, max=20000), default=400, show_default=True,
        help="Grains of the method's design (the inverse model's data; measured once, then cached).")
@option("--max-voxels-across", "max_across", type=FiniteFloatRange(min=0), default=None,
        help="Measure generated grains at most this many voxels across; 0: at the sand's resolution, however "
             "fine. [default: the method's cap, where its grains' descriptors have converged: 150 for rf, cri "
             "and angular; none for fso (docs/fit.md)]")
@option("--max-minutes", type=FiniteFloatRange(min=0, min_open=True), default=60.0, show_default=True,
        help="Refuse a fit estimated to take longer (wall clock on --workers).")
@option("--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
        help="Where designs are cached (see docs/fit.md) [default: $GRAINFORGE_CACHE or ~/.cache/grainforge]")
@seed_option("Root seed of the recipe.", default=2024)
@workers_option("Worker processes.", default_text="CPU count")
@option("--scheduler", metavar="ADDRESS", default=None,
        help="Measure the grains on an existing Dask distributed cluster, e.g. tcp://host:8786 (needs "
             "grainforge[dask] and the same grainforge on the workers); the outputs are the same.")
@option("--sphericity-convention", "sphericity", type=click.Choice(["atlas", "whole"]), default="atlas",
        show_default=True,
        help="How the generated grains' true sphericity is measured: as the Sand Atlas did (spam's cube, "
             "clipped above the centre of mass) or on the whole grain; docs/validation.md.")
@overwrite_option("Replace recipe.toml, fit.csv, fit-stats.csv and fit.png in --out.")
def fit(sand, out, voxel_size, method, count, refine, reseed, population_grains, population_slopes, design_grains,
        max_across, max_minutes, cache_dir, seed, workers, scheduler, sphericity, overwrite):
    """Fit a generated population to the grains of SAND (a Sand Atlas CSV).

    Every generated grain is the twin of one sand grain: its size, and
    settings from an inverse model (a cached design of generated grains) so
    that, voxelised at the sand's voxel size relative to its size and
    measured as the Atlas measures, it has that grain's true sphericity,
    convexity, flatness and elongation; twins that miss are refined.  Passes
    when per descriptor KS <= 0.1 and mean within 0.01, each Spearman
    correlation within 0.1 of the sand's, and >= 90 % of the reachable twins
    within 0.03; twins still off after the refinement try other seeds.
    Writes DIR/recipe.toml (runs with `grainforge batch` as is), DIR/fit.csv
    (sand row beside twin), DIR/fit-stats.csv and DIR/fit.png.  A column
    'Opening Fraction (-)' (not the Atlas's: each grain's share of voxels a
    ball of 1/30 of its d_eq reaches inside it) is used, where present, by the
    estimate of the sand's mean settings.  Exit status 0 when the fit passes,
    3 when it ran and does not pass (outputs kept, the failed criteria named),
    1 when batch would refuse the recipe, 2 for a refused request.  See
    docs/fit.md.
    """
    import contextlib
    import sys

    from ..fit import FITS, OUTPUTS, check_sand, read_sand, write_outputs
    from .work import signals_held

    if method != "auto" and method not in FITS:
        raise click.BadParameter(f"must be one of {', '.join(list(FITS) + ['auto'])}, got {method!r}",
                                 param_hint="--method")
    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers is for the local processes; the Dask cluster (--scheduler) has its own")
    if scheduler is not None:
        from ..runtime.cluster import check_address

        check_address(scheduler)
    output_dir(out, overwrite=overwrite, files=[out / n for n in OUTPUTS])  # before any work
    s = read_sand(sand, voxel_size)
    check_sand(s)
    with contextlib.ExitStack() as stack:
        executor = None
        if scheduler is not None:
            from ..runtime.cluster import dask_executor

            executor = stack.enter_context(dask_executor(scheduler))  # refused in one line before any work
        result = _run_fit(s, out, executor, dict(
            method=method, count=count, refine=refine, reseed=reseed, population_grains=population_grains,
            population_slopes=population_slopes, rng=seed, workers=workers, sphericity=sphericity,
            max_across=max_across, design_grains=design_grains, cache=cache_dir), max_minutes)
    from ..runtime.staging import commit_stage, staged

    with staged(out) as stage:  # the four outputs appear together, or none of them (an interrupt while writing)
        write_outputs(s, result, stage)
        with signals_held():
            commit_stage(stage, out, overwrite=overwrite)
    paths = [out / n for n in OUTPUTS]
    verdict = "PASSES" if result.stats["pass"] else "does NOT pass"
    click.echo(f"{result.method}: {verdict} (KS <= 0.1, |mean diff| <= 0.01, |Spearman diff| <= 0.1, "
               f"{result.stats['twin_within']:.0%} of reachable twins within 0.03) in "
               f"{result.seconds:.0f} s ({result.grains_measured} grains measured, {result.cpu_seconds:.0f} s of "
               f"worker CPU); wrote {', '.join(str(p) for p in paths)}", err=True)
    sys.stdout.flush()
    # what `grainforge batch recipe.toml` checks before it starts: grains at every distribution's ends
    from ..population import RecipeError, check_extremes, parse_recipe

    try:
        check_extremes(parse_recipe(result.recipe, source=str(paths[0])))
    except RecipeError as exc:
        click.echo(f"warning: grainforge batch would refuse this recipe: {exc}", err=True)
        sys.exit(1)
    if not result.stats["pass"]:
        click.echo(f"not passed: {failed_criteria(result)} (the outputs are kept; see {paths[2]}); exit status "
                   f"{EXIT_NOT_PASSED}", err=True)
        sys.exit(EXIT_NOT_PASSED)


def _run_fit(s, out, executor, kw: dict, max_minutes: float):
    """Check the fit's size, announce it and run it (on ``executor``, a Dask cluster, if given); its result."""
    from ..fit import METHOD_CAP, check_fit_size, fit_sand
    from ..runtime.cluster import SchedulerLost
    from ..runtime.estimate import TooLargeError, duration
    from ..runtime.workers import default_workers
    from .work import ready_for_work

    cores = executor.workers if executor is not None else None
    kw["workers"] = default_workers(kw["workers"])
    kw["max_across"] = METHOD_CAP if kw["max_across"] is None else kw["max_across"] or None
    try:
        seconds = check_fit_size(s, kw["method"], count=kw["count"], design_grains=kw["design_grains"],
                                 refine=kw["refine"], reseed=kw["reseed"], population_grains=kw["population_grains"],
                                 population_slopes=kw["population_slopes"], max_across=kw["max_across"],
                                 workers=kw["workers"], max_minutes=max_minutes, convention=kw["sphericity"],
                                 cache=kw["cache"], cores=cores)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    ready_for_work(HEAVY_MODULES, 0.0)
    where = (f"the Dask cluster's {cores} worker thread(s)" if executor is not None
             else f"{min(kw['workers'], default_workers())} core(s)")
    click.echo(f"estimated time: about {duration(seconds)} on {where} (a rough model; each phase's progress bar "
               "shows the measured rate)", err=True)
    state = {"desc": "fit"}

    def progress(it, total):
        return progress_bar(total=total, desc=state["desc"])(it)

    click.echo(f"{s.name}: {s.count} grains, voxel {s.voxel_size:g} µm, d_eq {s.equivalent_diameter.mean():.0f} "
               f"± {s.equivalent_diameter.std():.0f} µm ({s.equivalent_diameter.mean() / s.voxel_size:.0f} voxels "
               "across)", err=True)
    method = kw.pop("method")
    try:
        return fit_sand(s, method, **kw, progress=progress, executor=executor,
                        log=lambda line: click.echo(line, err=True), desc=lambda d: state.update(desc=d))
    except SchedulerLost as exc:
        raise click.ClickException(f"{exc}; nothing written to {out} (the outputs are written once the fit ends; "
                                   "a design measured in full stays cached): rerun when the cluster is back") from None


def failed_criteria(result) -> str:
    """The criteria of ``fit-stats.csv`` a fit fails, in one line: ``'ks flatness 0.14 (KS statistic <= 0.1), …'``."""
    from ..fit import stat_rows

    # a row's "pass" is a (NumPy) boolean where the row is a criterion, "" where it is only reported
    bad = [r for r in stat_rows(result) if not isinstance(r["pass"], str) and not r["pass"]]
    return "; ".join(f"{r['statistic']} {r['quantity']} {_number(r)} ({r['criterion']})" for r in bad) or "none"


def _number(row) -> str:
    v = row["difference"] if row["statistic"] in ("ks", "mean", "spearman") else row["generated"]
    return f"{v:+.3g}" if row["statistic"] in ("mean", "spearman") else f"{v:.3g}"
