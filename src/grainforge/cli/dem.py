"""``grainforge dem INPUTS --out DIR``: DEM decks for Yade, LIGGGHTS and LAMMPS."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..errors import InputError
from .help_style import option
from .options import (
    EXIT_CHECK_FAILED,
    SPHERES_RANGE,
    FiniteFloatRange,
    clump_accuracy_option,
    overwrite_option,
    seed_option,
    workers_option,
)
from .paths import OutPath, output_dir

#: grainforge.dem.inputs.MAX_POUR_GRAINS, spelt out so that the help does not import numpy (a test compares them)
MAX_POUR_GRAINS = 100_000

ENGINE_COMMAND = {"yade": "yade -n -x run.py", "liggghts": "liggghts -in in.run", "lammps": "lmp -in in.run"}
#: option (parameter name, flag) -> the --shape it applies to
SHAPE_OPTIONS = {("spheres", "--spheres"): "clump", ("refine", "--refine-iterations"): "clump",
                 ("clump_accuracy", "--clump-accuracy"): "clump",
                 ("vertices", "--vertices"): "polyhedron", ("spacing", "--spacing"): "levelset"}
#: engines that refuse a rigid body of one sphere: a clump built to an accuracy target takes two at least there
TWO_SPHERE_ENGINES = ("liggghts", "lammps")


def _refuse_foreign_options(ctx: click.Context, shape: str) -> None:
    """One line when an option of another --shape was given (it would be ignored silently)."""
    for (name, flag), owner in SHAPE_OPTIONS.items():
        source = ctx.get_parameter_source(name)
        if owner != shape and source not in (None, click.core.ParameterSource.DEFAULT):
            raise click.UsageError(f"{flag} applies to --shape {owner} only, not to --shape {shape}")


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("--out", "out", required=True, type=OutPath(file_okay=False),
        help="Folder of the deck.")
@option("--engine", type=click.Choice(["yade", "liggghts", "lammps"]), default="yade", show_default=True)
@option("--shape", type=click.Choice(["clump", "polyhedron", "levelset"]), default="clump",
        show_default=True, help="Grain representation (what the engine supports).")
@option("--density", type=FiniteFloatRange(1.0, 1e5), default=2650.0, show_default=True,
        help="Solid density, kg/m³.")
@option("--rolling-friction", type=FiniteFloatRange(0.0, 1.0), default=0.0, show_default=True,
        help="Rolling resistance μ_r of the contacts: a contact's rolling moment is limited to μ_r·F_n·r, r the "
             "smaller sphere's radius (Yade and LIGGGHTS clumps; docs/simulate.md, Rolling resistance).")
@option("--spheres", type=click.IntRange(*SPHERES_RANGE), default=30, show_default=True,
        help="Clump: spheres per clump (the accuracy/cost knob; at most, fewer when more add no coverage). "
             "With --clump-accuracy, the most a clump may take (100 when --spheres is not given).")
@option("--refine-iterations", "refine", type=click.IntRange(0, 10000), default=0, show_default=True,
        help="Clump: L-BFGS iterations refining all spheres after the greedy placement "
             "(30: a few points more coverage for several times the CPU; 0: off).")
@clump_accuracy_option
@option("--vertices", type=click.IntRange(4, 10000), default=None,
        help="Polyhedron: at most this many convex-hull vertices (fewer: faster contacts). "
             "Default: 16 for Yade, 12 for LAMMPS (LAMMPS reads at most 56).")
@option("--spacing", type=FiniteFloatRange(0.01, 0.5), default=0.05, show_default=True,
        help="Level set: grid spacing as a fraction of the equivalent diameter.")
@option("--unit", type=FiniteFloatRange(1e-9, 1e3), default=1e-3, show_default=True,
        help="Metres per file unit (grainforge files are in mm: 0.001).")
@option("--count", type=click.IntRange(1), default=None, show_default="1",
        help="Copies of each grain in the example pour.")
@option("--grains", type=click.IntRange(1, MAX_POUR_GRAINS), default=None,
        help="Instead of --count: the pour's total number of grains, drawn from the input grains in "
             "proportion (each taken grains // inputs times; the rest go to inputs drawn with --seed).")
@seed_option("Seed of the --grains draw.", default=None, default_text="0")
@option("--templates", "template_count", type=click.IntRange(1), default=None,
        show_default="every input grain",
        help="Write K templates chosen from the input grains so that their sphericity, convexity, flatness, "
             "elongation and size are distributed as all the inputs' (KS figures printed and written to "
             "templates.csv); --count or --grains then apply to them.")
@workers_option("Processes.", default_text="CPU count")
@overwrite_option("Replace existing deck files.")
def dem(inputs, out, engine, shape, density, rolling_friction, spheres, refine, clump_accuracy, vertices, spacing, unit, count, grains,
        seed, workers, overwrite, template_count=None):
    """Write a DEM deck of the grains in INPUTS (mesh files, generate/batch folders, manifests).

    Every grain keeps its exact mass, centroid and inertia from the mesh.  Run
    the deck from inside --out: `yade -n -x run.py`, `liggghts -in in.run` or
    `lmp -in in.run` (docs/dem.md).
    """
    from ..dem.inputs import build_templates, check_level_set_files, pour_copies, pour_counts
    from ..io.inputs import mesh_paths
    from ..runtime.workers import default_workers
    from .progress import progress_bar

    spheres, vertices = _representation(engine, shape, spheres, clump_accuracy, vertices)
    if rolling_friction > 0 and (engine == "lammps" or shape != "clump"):
        raise click.UsageError("--rolling-friction is written for --shape clump in Yade and LIGGGHTS decks only")
    if grains is not None and count is not None:
        raise click.UsageError("give --count (copies of each grain) or --grains (the total), not both")
    if seed is not None and grains is None:
        raise click.UsageError("--seed draws the --grains pour; give --grains")
    output_dir(out)  # writable, not a file: before any work (write_deck applies the overwrite rule)
    paths = mesh_paths(inputs)
    chosen, n_templates = None, len(paths)
    if template_count is not None:  # K representative grains (those without a manifest's measures are measured)
        n_templates = _templates_plan(inputs, paths, template_count, out, overwrite)
    if grains is None:
        try:
            counts = pour_copies(n_templates, 1 if count is None else count)
        except InputError as exc:
            raise click.BadParameter(str(exc), param_hint="--count") from None
    else:
        counts = pour_counts(n_templates, grains, rng=0 if seed is None else seed).tolist()
    workers = default_workers(workers)
    files = sum(c > 0 for c in counts)
    announce = _estimate(files, shape, spheres, refine, spacing, min(workers, files), clump_accuracy is not None)
    # a spacing too fine for a grain: refused before the estimate is said and any work (--templates: once chosen)
    if shape == "levelset" and template_count is None:
        check_level_set_files([p for p, c in zip(paths, counts) if c > 0], unit=unit, spacing=spacing)
    announce()  # (the measuring of --templates, minutes at most, shows its own progress bar)
    if template_count is not None:
        chosen = _choose_templates(inputs, paths, template_count, workers)
        paths = chosen.paths
        if shape == "levelset":
            check_level_set_files([p for p, c in zip(paths, counts) if c > 0], unit=unit, spacing=spacing)
    from ..dem.inputs import GRAIN_SIZE_RANGE, MIN_GRAIN_SIZE

    # every grain's size is checked before its representation is built (the costly part)
    size_range = (MIN_GRAIN_SIZE.get((engine, shape), GRAIN_SIZE_RANGE[0]), GRAIN_SIZE_RANGE[1])
    templates = build_templates(paths, workers=workers, progress=progress_bar(files, "dem"),
                                counts=counts, unit=unit, density=density, shape=shape, spheres=spheres,
                                refine_iterations=refine, polyhedron_vertices=vertices, levelset_spacing=spacing,
                                size_range=size_range, **({} if clump_accuracy is None else
                                                          {"target_iou": clump_accuracy,
                                                           "min_spheres": 2 if engine in TWO_SPHERE_ENGINES else 1}))
    placed = [t.clump.count for t in templates if t.clump is not None]
    if clump_accuracy is None and placed and min(placed) < spheres:
        click.echo(f"clumps have {min(placed)}–{max(placed)} spheres (at most {spheres} asked): the placement "
                   "stops when another sphere adds no coverage", err=True)
    from ..dem.engines import write_deck
    from ..dem.template_choice import write_chosen_templates
    from .work import signals_held

    with signals_held():  # the deck's files appear together: a signal meanwhile is answered once they are all written
        written = write_deck(engine, templates, out, overwrite=overwrite, rolling_friction=rolling_friction)
        if chosen is not None:
            written.append(write_chosen_templates(out, chosen, unit))
    if clump_accuracy is None:
        click.echo(f"wrote {len(written)} files to {out}; run from inside it: {ENGINE_COMMAND[engine]}", err=True)
        return
    from ..dem.template import accuracy_summary, accuracy_warning

    warning = accuracy_warning(templates, spheres, out / "clumps.csv")
    if warning:
        click.echo(warning, err=True)
    click.echo(f"wrote {len(written)} files to {out}; {accuracy_summary(templates, spheres)}; run from inside it: "
               f"{ENGINE_COMMAND[engine]}", err=True)
    if warning:  # the deck is written and usable; its clumps fail their own check (docs/cli-contract.md)
        sys.exit(EXIT_CHECK_FAILED)


def _representation(engine: str, shape: str, spheres: int, clump_accuracy, vertices):
    """The --shape options checked against the engine; the sphere cap and the polyhedra's vertex cap."""
    from ..dem import SUPPORTED

    ctx = click.get_current_context()
    _refuse_foreign_options(ctx, shape)
    if clump_accuracy is not None and ctx.get_parameter_source("spheres") in (None, click.core.ParameterSource.DEFAULT):
        from ..dem.clump import DEFAULT_SPHERE_CAP

        spheres = DEFAULT_SPHERE_CAP  # the cap of a clump built to an accuracy target, --spheres not given
    if shape not in SUPPORTED[engine]:
        raise click.UsageError(f"--engine {engine} does not support --shape {shape} "
                               f"(supported: {', '.join(SUPPORTED[engine])})")
    if shape == "polyhedron":
        from ..dem.polyhedron import engine_vertices

        try:
            vertices = engine_vertices(engine, vertices)
        except InputError as exc:
            raise click.BadParameter(str(exc), param_hint="--vertices") from None
    return spheres, vertices


def _templates_plan(inputs, paths, k: int, out: Path, overwrite: bool) -> int:
    """--templates K: the templates of the deck; refuses an earlier templates.csv without --overwrite before
    any work."""
    from ..dem.template_choice import TEMPLATES_CSV

    if (out / TEMPLATES_CSV).exists() and not overwrite:
        raise click.UsageError(f"{out / TEMPLATES_CSV} exists; use --overwrite")
    return min(k, len(paths))


def _choose_templates(inputs, paths, k: int, workers: int):
    """The K representative grain files (a progress bar while files are measured); prints the KS line."""
    from tqdm import tqdm

    from ..dem.template_choice import choose_files

    with tqdm(desc="choosing templates", unit="grain", disable=None, leave=False, dynamic_ncols=True) as bar:
        def step(done, total):
            bar.total = total
            bar.update(1)

        chosen = choose_files(inputs, paths, k=k, workers=workers, progress=step)
    click.echo(chosen.summary(k) + "; templates.csv", err=True)
    return chosen


def _estimate(files: int, shape: str, spheres: int, refine: int, spacing: float, workers: int,
              accuracy: bool = False):
    """Refuse template work estimated beyond a day, naming what to change; return the call that announces
    work over a minute."""
    from ..dem.inputs import template_seconds
    from ..runtime.estimate import TooLargeError, check_job
    from .work import say_estimate

    each = template_seconds(shape, spheres=spheres, refine_iterations=refine, spacing=spacing, accuracy=accuracy)
    refining = shape == "clump" and refine > 0  # the model counts every iteration: an upper bound
    if refining:
        advice = "lower --refine-iterations (or --spheres), or give fewer grain files"
    elif shape == "levelset":
        advice = "raise --spacing, or give fewer grain files"
    else:
        advice = "give fewer grain files"
    try:
        seconds = check_job(files, each, what=f"{files} {shape} template(s)", option="", workers=workers,
                            advice=advice)
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    return lambda: say_estimate(seconds, bound="at most about" if refining else "about")
