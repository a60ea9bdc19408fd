"""``grainforge dem INPUTS --out DIR``: DEM decks for Yade, LIGGGHTS and LAMMPS."""

from __future__ import annotations

import os
from pathlib import Path

import click

from .paths import OutPath, output_dir

#: grainforge.dem.inputs.MAX_POUR_GRAINS, spelt out so that the help does not import numpy (a test compares them)
MAX_POUR_GRAINS = 100_000

ENGINE_COMMAND = {"yade": "yade -n -x run.py", "liggghts": "liggghts -in in.run", "lammps": "lmp -in in.run"}
#: option (parameter name, flag) -> the --shape it applies to
SHAPE_OPTIONS = {("spheres", "--spheres"): "clump", ("refine", "--refine-iterations"): "clump",
                 ("vertices", "--vertices"): "polyhedron", ("spacing", "--spacing"): "levelset"}


def _refuse_foreign_options(ctx: click.Context, shape: str) -> None:
    """One line when an option of another --shape was given (it would be ignored silently)."""
    for (name, flag), owner in SHAPE_OPTIONS.items():
        source = ctx.get_parameter_source(name)
        if owner != shape and source not in (None, click.core.ParameterSource.DEFAULT):
            raise click.UsageError(f"{flag} applies to --shape {owner} only, not to --shape {shape}")


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out", required=True, type=OutPath(file_okay=False),
              help="Folder of the deck.")
@click.option("--engine", type=click.Choice(["yade", "liggghts", "lammps"]), default="yade", show_default=True)
@click.option("--shape", type=click.Choice(["clump", "polyhedron", "levelset"]), default="clump",
              show_default=True, help="Grain representation (what the engine supports).")
@click.option("--density", type=click.FloatRange(1.0, 1e5), default=2650.0, show_default=True,
              help="Solid density, kg/m³.")
@click.option("--spheres", type=click.IntRange(2, 1000), default=30, show_default=True,
              help="Clump: spheres per clump (the accuracy/cost knob; at most, fewer when more add no coverage).")
@click.option("--refine-iterations", "refine", type=click.IntRange(0, 10000), default=0, show_default=True,
              help="Clump: L-BFGS iterations refining all spheres after the greedy placement "
                   "(30: a few points more coverage for several times the CPU; 0: off).")
@click.option("--vertices", type=click.IntRange(4, 10000), default=None,
              help="Polyhedron: at most this many convex-hull vertices (fewer: faster contacts). "
                   "Default: 16 for Yade, 12 for LAMMPS (LAMMPS reads at most 56).")
@click.option("--spacing", type=click.FloatRange(0.01, 0.5), default=0.05, show_default=True,
              help="Level set: grid spacing as a fraction of the equivalent diameter.")
@click.option("--unit", type=click.FloatRange(1e-9, 1e3), default=1e-3, show_default=True,
              help="Metres per file unit (grainforge files are in mm: 0.001).")
@click.option("--count", type=click.IntRange(1), default=None, show_default="1",
              help="Copies of each grain in the example pour.")
@click.option("--grains", type=click.IntRange(1, MAX_POUR_GRAINS), default=None,
              help="Instead of --count: the pour's total number of grains, drawn from the input grains in "
                   "proportion (each taken grains // inputs times; the rest go to inputs drawn with --seed).")
@click.option("--seed", type=click.IntRange(0), default=None, show_default="0",
              help="Seed of the --grains draw.")
@click.option("--workers", type=click.IntRange(1), default=None, help="Processes (default: CPU count).")
@click.option("--overwrite", is_flag=True, help="Replace existing deck files.")
def dem(inputs, out, engine, shape, density, spheres, refine, vertices, spacing, unit, count, grains, seed, workers,
        overwrite):
    """Write a DEM deck of the grains in INPUTS (mesh files, generate/batch folders, manifests).

    Every grain keeps its exact mass, centroid and inertia from the mesh.  Run
    the deck from inside --out: `yade -n -x run.py`, `liggghts -in in.run` or
    `lmp -in in.run` (docs/dem.md).
    """
    from ..dem import SUPPORTED
    from ..dem.inputs import build_templates, grain_paths, pour_counts
    from .progress import progress_bar

    _refuse_foreign_options(click.get_current_context(), shape)
    if shape not in SUPPORTED[engine]:
        raise click.UsageError(f"--engine {engine} does not support --shape {shape} "
                               f"(supported: {', '.join(SUPPORTED[engine])})")
    if shape == "polyhedron":
        from ..dem.lammps_body import MAX_VERTICES
        from ..dem.polyhedron import DEFAULT_VERTICES

        if vertices is None:
            vertices = DEFAULT_VERTICES[engine]
        elif engine == "lammps" and vertices > MAX_VERTICES:
            raise click.BadParameter(f"LAMMPS reads at most {MAX_VERTICES} vertices per body, got {vertices}",
                                     param_hint="--vertices")
    if grains is not None and count is not None:
        raise click.UsageError("give --count (copies of each grain) or --grains (the total), not both")
    if seed is not None and grains is None:
        raise click.UsageError("--seed draws the --grains pour; give --grains")
    output_dir(out)  # writable, not a file: before any work (write_deck applies the overwrite rule)
    paths = grain_paths(inputs)
    if grains is None:
        count = 1 if count is None else count
        if count * len(paths) > MAX_POUR_GRAINS:
            raise click.BadParameter(f"{len(paths)} grain files × {count} = {count * len(paths)} grains; a pour "
                                     f"holds at most {MAX_POUR_GRAINS}", param_hint="--count")
        counts = [count] * len(paths)
    else:
        counts = pour_counts(len(paths), grains, 0 if seed is None else seed).tolist()
    workers = workers or os.cpu_count() or 1
    files = sum(c > 0 for c in counts)
    announce = _estimate(files, shape, spheres, refine, spacing, min(workers, files))
    if shape == "levelset":  # a spacing too fine for a grain: refused before the estimate is said and any work
        _check_level_set_budget([p for p, c in zip(paths, counts) if c > 0], unit, spacing)
    announce()
    from ..dem.inputs import GRAIN_SIZE_RANGE, MIN_GRAIN_SIZE

    # every grain's size is checked before its representation is built (the costly part)
    size_range = (MIN_GRAIN_SIZE.get((engine, shape), GRAIN_SIZE_RANGE[0]), GRAIN_SIZE_RANGE[1])
    templates = build_templates(paths, workers=workers, progress=progress_bar(files, "dem"),
                                counts=counts, unit=unit, density=density, shape=shape, spheres=spheres,
                                refine_iterations=refine, polyhedron_vertices=vertices, levelset_spacing=spacing,
                                size_range=size_range)
    from ..dem.decks import write_deck

    placed = [t.clump.count for t in templates if t.clump is not None]
    if placed and min(placed) < spheres:
        click.echo(f"clumps have {min(placed)}–{max(placed)} spheres (at most {spheres} asked): the placement "
                   "stops when another sphere adds no coverage", err=True)
    written = write_deck(engine, templates, out, overwrite=overwrite)
    click.echo(f"wrote {len(written)} files to {out}; run from inside it: {ENGINE_COMMAND[engine]}", err=True)


def _check_level_set_budget(paths, unit: float, spacing: float) -> None:
    from ..dem.inputs import read_grain
    from ..dem.template import check_level_set_budget

    for p in paths:
        v, f = read_grain(p, check=False)
        try:
            check_level_set_budget(v, f, unit=unit, spacing=spacing)
        except ValueError as exc:
            raise ValueError(f"{p}: {exc}") from None


def _estimate(files: int, shape: str, spheres: int, refine: int, spacing: float, workers: int):
    """Refuse template work estimated beyond a day, naming what to change; return the call that announces
    work over a minute."""
    from ..estimate import TooLargeError, check_job, dem_template_seconds
    from .interrupts import say_estimate

    each = dem_template_seconds(shape, spheres=spheres, refine_iterations=refine, spacing=spacing)
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
