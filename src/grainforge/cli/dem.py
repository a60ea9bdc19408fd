"""``grainforge dem INPUTS --out DIR``: DEM decks for Yade, LIGGGHTS and LAMMPS."""

from __future__ import annotations

import os
from pathlib import Path

import click

from .paths import OutPath, output_dir

ENGINE_COMMAND = {"yade": "yade -n -x run.py", "liggghts": "liggghts -in in.run", "lammps": "lmp -in in.run"}


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out", required=True, type=OutPath(file_okay=False),
              help="Folder of the deck.")
@click.option("--engine", type=click.Choice(["yade", "liggghts", "lammps"]), default="yade", show_default=True)
@click.option("--shape", type=click.Choice(["clump", "polyhedron", "levelset"]), default="clump",
              show_default=True, help="Grain representation (what the engine supports).")
@click.option("--density", type=float, default=2650.0, show_default=True, help="Solid density, kg/m³ (> 0).")
@click.option("--spheres", type=click.IntRange(1, 1000), default=30, show_default=True,
              help="Spheres per clump (the accuracy/cost knob).")
@click.option("--refine-iterations", "refine", type=click.IntRange(0, 10000), default=0, show_default=True,
              help="Clump: L-BFGS iterations refining all spheres after the greedy placement "
                   "(30: a few points more coverage for several times the CPU; 0: off).")
@click.option("--vertices", type=click.IntRange(4, 10000), default=None,
              help="Polyhedron: at most this many convex-hull vertices (fewer: faster contacts). "
                   "Default: 16 for Yade, 12 for LAMMPS (LAMMPS reads at most 56).")
@click.option("--spacing", type=click.FloatRange(0.01, 0.5), default=0.05, show_default=True,
              help="Level set: grid spacing as a fraction of the equivalent diameter.")
@click.option("--unit", type=float, default=1e-3, show_default=True,
              help="Metres per file unit (grainforge files are in mm: 0.001).")
@click.option("--count", type=click.IntRange(1), default=1, show_default=True,
              help="Copies of each grain in the example pour.")
@click.option("--workers", type=click.IntRange(1), default=None, help="Processes (default: CPU count).")
@click.option("--overwrite", is_flag=True, help="Replace existing deck files.")
def dem(inputs, out, engine, shape, density, spheres, refine, vertices, spacing, unit, count, workers, overwrite):
    """Write a DEM deck of the grains in INPUTS (mesh files, generate/batch folders, manifests).

    Every grain keeps its exact mass, centroid and inertia from the mesh.  Run
    the deck from inside --out: `yade -n -x run.py`, `liggghts -in in.run` or
    `lmp -in in.run` (docs/dem.md).
    """
    from ..dem import SUPPORTED
    from ..dem.inputs import build_templates, grain_paths
    from .progress import progress_bar

    if shape not in SUPPORTED[engine]:
        raise click.UsageError(f"--engine {engine} does not support --shape {shape} "
                               f"(supported: {', '.join(SUPPORTED[engine])})")
    if not (density > 0):
        raise click.BadParameter(f"must be > 0 kg/m³, got {density}", param_hint="--density")
    if not (unit > 0):
        raise click.BadParameter(f"must be > 0, got {unit}", param_hint="--unit")
    if shape == "polyhedron":
        from ..dem.lammps_body import MAX_VERTICES
        from ..dem.polyhedron import DEFAULT_VERTICES

        if vertices is None:
            vertices = DEFAULT_VERTICES[engine]
        elif engine == "lammps" and vertices > MAX_VERTICES:
            raise click.BadParameter(f"LAMMPS reads at most {MAX_VERTICES} vertices per body, got {vertices}",
                                     param_hint="--vertices")
    output_dir(out)  # writable, not a file: before any work (write_deck applies the overwrite rule)
    paths = grain_paths(inputs)
    workers = workers or os.cpu_count() or 1
    templates = build_templates(paths, workers=workers, progress=progress_bar(len(paths), "dem"),
                                unit=unit, density=density, shape=shape, spheres=spheres, refine_iterations=refine, count=count,
                                polyhedron_vertices=vertices, levelset_spacing=spacing)
    from ..dem.decks import write_deck

    written = write_deck(engine, templates, out, overwrite=overwrite)
    click.echo(f"wrote {len(written)} files to {out}; run from inside it: {ENGINE_COMMAND[engine]}", err=True)
