"""``grainforge simulate repose|tilt INPUTS --out DIR``: virtual bulk tests in Yade or LIGGGHTS (under mpirun)."""

from __future__ import annotations

from pathlib import Path

import click

from .options import build_params, param_options
from .paths import OutPath, output_dir

#: settings only the tilt test reads: not offered by `simulate repose`
TILT_ONLY = ("tilt_step", "tilt_start")
#: engines and grain representations the options name (the DEM decks' ones, grainforge dem)
ENGINES = ("yade", "liggghts")
SHAPES = ("clump", "polyhedron", "levelset")
#: what simulate's scenes can run, per engine
RUNS = {"yade": ("clump",), "liggghts": ("clump",)}
#: engines simulate runs under mpirun (--mpi)
MPI_ENGINES = ("liggghts",)


def check_engine(engine: str, mpi: int | None, shape: str) -> None:
    """Refuse, in one line and before any work, an engine/representation/MPI combination simulate cannot run.

    Raises
    ------
    click.UsageError
        For an engine simulate has no scene for, ``--mpi`` with an engine
        that does not run under MPI, a ``--shape`` the engine's scenes cannot
        take, or an engine that is not installed.
    """
    if not RUNS[engine]:
        raise click.UsageError(f"--engine {engine}: simulate has no {engine} scenes yet (grainforge dem "
                               f"--engine {engine} writes a pour deck); use --engine yade")
    if mpi is not None and engine not in MPI_ENGINES:
        raise click.UsageError(f"--mpi: {engine} runs one process per seed here, not under mpirun; "
                               "use --workers for runs at once (or --engine liggghts --mpi N)")
    if shape not in RUNS[engine]:
        raise click.UsageError(f"--shape {shape}: simulate's {engine} scenes take "
                               f"{', '.join('--shape ' + s for s in RUNS[engine])} only (grainforge dem "
                               f"--shape {shape} writes the deck)")
    from ..simulate import yade_executable
    from ..simulate.liggghts import liggghts_executable, mpirun_executable

    checks = {"yade": [yade_executable], "liggghts": [liggghts_executable]}[engine]
    if mpi is not None:
        checks.append(mpirun_executable)
    for check in checks:
        try:
            check()
        except FileNotFoundError as exc:
            raise click.UsageError(str(exc)) from None


def _command(test: str, doc: str):
    @click.command(name=test, help=doc)
    @click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
    @click.option("--out", "out", required=True, type=OutPath(file_okay=False),
                  help="Folder for the decks (one per seed), results.csv and the figure.")
    @click.option("--quick", is_flag=True,
                  help="A few tens of grains, seconds per run: checks the set-up, measures nothing meaningful.")
    @click.option("--as-spheres", is_flag=True,
                  help="Replace every grain by its volume-equivalent sphere (the sphere baseline).")
    @click.option("--label", default=None, show_default="the inputs' names",
                  help="Name of this population in results.csv.")
    @click.option("--workers", type=click.IntRange(min=1, max=256), default=None,
                  help="Engine runs (seeds) at once, each on one core or on --mpi ranks (default: CPU count "
                       "divided by --mpi).")
    @click.option("--engine", type=click.Choice(ENGINES), default="yade", show_default=True,
                  help="DEM engine of the runs: Yade, or LIGGGHTS (the same scenes as multisphere clumps; "
                       "docs/simulate.md says where the engines differ).")
    @click.option("--mpi", type=click.IntRange(min=1, max=4096), default=None,
                  help="LIGGGHTS only: run each seed under `mpirun -np N` (the box cut into N columns). "
                       "Yade runs one process per seed: use --workers.")
    @click.option("--shape", type=click.Choice(SHAPES), default="clump", show_default=True,
                  help="Grain representation (simulate's Yade and LIGGGHTS scenes take clumps; --spheres sets "
                       "their size).")
    @click.option("--overwrite", is_flag=True, help="Replace an earlier result in --out.")
    @param_options(_settings_cls(), exclude=TILT_ONLY if test != "tilt" else ())
    def command(inputs, out, quick, as_spheres, label, workers, engine, mpi, shape, overwrite, **values):
        check_engine(engine, mpi, shape)
        _run(test, inputs, out, quick, as_spheres, label, workers, overwrite, values, engine=engine, mpi=mpi)

    return command


def _settings_cls():
    from ..simulate import Settings

    return Settings


#: modules a run loads before any work (cli.interrupts.preload: a lazy import later could swallow a Ctrl-C)
HEAVY_MODULES = ("tqdm", "trimesh", "scipy.optimize", "scipy.ndimage", "scipy.spatial", "scipy.spatial.transform",
                 "grainforge.io", "grainforge.solid", "grainforge.methods", "grainforge.population",
                 "grainforge.fabrication.scale", "grainforge.dem.inputs", "grainforge.dem.template",
                 "grainforge.dem.clump", "grainforge.dem.enclosure", "grainforge.dem.yade", "grainforge.dem.deck",
                 "grainforge.dem.liggghts", "grainforge.simulate.liggghts", "grainforge.simulate.report",
                 "matplotlib.pyplot", "matplotlib.collections")


def _run(test, inputs, out, quick, as_spheres, label, workers, overwrite, values, engine="yade", mpi=None):
    import os

    from ..estimate import TooLargeError
    from ..simulate import QUICK, Settings, check_inputs, check_size
    from .interrupts import ready_for_work, signals_held

    if quick:
        values = {**QUICK, **{k: v for k, v in values.items() if v is not None}}
    settings = build_params(Settings, values)
    outputs = [out / "results.csv", out / f"{test}.png"] + [out / f"{test}-seed{settings.seed + k}"
                                                             for k in range(settings.seeds)]
    out = output_dir(out, overwrite=overwrite, files=outputs)
    available, make_seconds = check_inputs(inputs)
    workers = workers or max(1, (os.cpu_count() or 1) // (mpi or 1))
    try:
        seconds = check_size(test, settings, available=available, make_seconds=make_seconds,
                             as_spheres=as_spheres, workers=workers)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    ready_for_work(HEAVY_MODULES, seconds, bound="about")
    from tqdm import tqdm

    from ..simulate import (
        EngineFailed,
        build_population,
        commit_stage,
        discard_stage,
        keep_failed,
        open_stage,
        run_test,
        summarise,
    )
    from ..simulate.report import write_report

    label = label or ("spheres from " if as_spheres else "") + ", ".join(Path(p).name for p in inputs)
    with tqdm(desc="clumps", unit="grain", disable=None, leave=False, dynamic_ncols=True) as bar:
        def step(done, total):
            bar.total = total
            bar.update(1)

        templates = build_population(inputs, settings, as_spheres=as_spheres, progress=step)
    name = "Yade" if engine == "yade" else "LIGGGHTS" + (f", {mpi} MPI ranks" if mpi else "")
    runs = tqdm(total=settings.seeds * 1000, desc=f"{test} ({name})", unit="‰", disable=None, leave=False,
                dynamic_ncols=True, bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining} {postfix}")

    done = [0.0] * settings.seeds

    def progress(k, fraction, phase):
        done[k] = fraction
        runs.n = int(1000 * sum(done))
        runs.set_postfix_str(f"seed {settings.seed + k}: {phase}", refresh=False)
        runs.refresh()

    # every output is made in a hidden staging folder and moved into --out when all are complete: an
    # interrupt or a failed run leaves nothing (a SIGKILL leaves the staging folder, which the next run removes)
    stage, created = open_stage(out)
    try:
        try:
            rows = run_test(test, templates, settings, stage, label=label, progress=progress,
                            workers=workers, engine=engine, mpi=mpi)
        except EngineFailed as exc:
            # an engine failure (not an interrupt): its deck and log are kept for the diagnosis, nothing else
            kept = keep_failed(exc.deck, out)
            message = str(exc).replace(f"{stage}{os.sep}", "")
            raise click.ClickException(f"{message}; its deck and log are in {kept}") from None
        finally:
            runs.close()
        write_report(rows, stage, test, settings)
        with signals_held():  # the outputs appear together
            commit_stage(stage, out, overwrite=overwrite)
    finally:
        discard_stage(stage, out, created)
    summary = summarise(rows)
    sd = summary["angle_sd_deg"]
    spread = f" ± {sd:.1f}° (sd over {summary['runs']} seeds)" if summary["runs"] > 1 else " (one seed)"
    name = "angle of repose" if test == "repose" else "tilt failure angle"
    if summary["runs"] == 0:
        click.echo(f"{label}: no {name} measured ({rows[0].get('note', '')}); {out / 'results.csv'}")
    else:
        click.echo(f"{label}: {name} {summary['angle_mean_deg']:.1f}°{spread}; "
                   f"{out / 'results.csv'}, {out / (test + '.png')}")


repose = _command("repose", """Angle of repose: a cylinder of grains on a rough base is lifted and the heap measured.

    INPUTS: mesh files (mm), a generate/batch folder, a manifest, or one TOML recipe.
    Each grain becomes a clump with the mesh's exact mass and inertia (grainforge dem);
    Yade (or LIGGGHTS, --engine liggghts [--mpi N]) runs headless once per seed; the heap's slope is
    fitted in 8 sectors.  See docs/simulate.md.
    """)
tilt = _command("tilt", """Tilt table: a layer of grains on a rough plate is tilted until it slides.

    INPUTS as for `simulate repose`.  The layer is periodic (an infinite slope); failure is the
    tilt at which the layer's mean downslope displacement exceeds half a grain diameter.
    """)


@click.group()
def simulate():
    """Virtual bulk tests in Yade or LIGGGHTS (angle of repose, tilt table): shape's effect on bulk friction."""


simulate.add_command(repose)
simulate.add_command(tilt)
