"""``grainforge simulate repose|tilt|triaxial INPUTS --out DIR``: virtual bulk tests in Yade or LIGGGHTS (under
mpirun; the triaxial test in a periodic cell in Yade, in a box of servo-controlled walls in LIGGGHTS)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..errors import InputError
from ..simulate.capabilities import TILT_ONLY
from .help_style import option
from .options import EXIT_CHECK_FAILED, param_options
from .paths import OutPath, output_dir
from .simulate_options import Reporter, run_failures, run_options, run_settings

__all__ = ["simulate", "repose", "tilt", "triaxial", "run_settings", "check_options", "settings_cls"]


def check_options(test: str | None, values: dict, *, engine: str, mpi: int | None, shape: str, spacing: float | None,
                  as_spheres: bool, clump_accuracy: float | None, scheduler: str | None, workers: int | None,
                  resume: bool, overwrite: bool) -> None:
    """:func:`grainforge.simulate.pipeline.check_options` with the settings given (``values``), refused in one line
    (exit 2) before any work."""
    from ..simulate.pipeline import check_options as check

    try:
        check(test, engine=engine, mpi=mpi, shape=shape, spacing=spacing, as_spheres=as_spheres,
              spheres=values.get("spheres"), clump_accuracy=clump_accuracy,
              rolling_friction=values.get("rolling_friction"), scheduler=scheduler, workers=workers, resume=resume,
              overwrite=overwrite)
    except InputError as exc:
        raise click.UsageError(str(exc)) from None


def settings_cls(test: str = "repose"):
    """The settings class of ``test``'s options and runs."""
    from ..simulate import Settings, TriaxialSettings

    return TriaxialSettings if test == "triaxial" else Settings


def _command(test: str, doc: str):
    @click.command(name=test, help=doc)
    @click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
    @option("--out", "out", required=True, type=OutPath(file_okay=False),
            help="Folder for the decks (one per seed), results.csv and the figure.")
    @run_options()
    @param_options(settings_cls(test), exclude=TILT_ONLY if test == "repose" else ())
    def command(inputs, out, quick, as_spheres, label, workers, engine, mpi, shape, spacing, overwrite, scheduler,
                resume, clump_accuracy, **values):
        options = dict(engine=engine, mpi=mpi, shape=shape, spacing=spacing, as_spheres=as_spheres,
                       clump_accuracy=clump_accuracy, scheduler=scheduler, workers=workers, resume=resume,
                       overwrite=overwrite)
        check_options(test, values, **options)
        _run(test, inputs, out, values, quick=quick, label=label, **options)

    return command


def _run(test: str, inputs, out: Path, values: dict, *, quick: bool, label: str | None, **options) -> None:
    """The virtual test (:func:`grainforge.simulate.pipeline.run_virtual_test`) and its lines; exit 3 when a run or
    a clump fails its own check (the outputs are written)."""
    from ..simulate.pipeline import run_virtual_test, virtual_test_outputs

    settings = run_settings(test, values, quick, options["shape"], options["clump_accuracy"], engine=options["engine"],
                            mpi=options["mpi"], workers=options["workers"], scheduler=options["scheduler"])
    out = output_dir(out, overwrite=options["overwrite"],
                     files=virtual_test_outputs(test, settings, out, options["clump_accuracy"]))
    with Reporter(test, options["engine"], options["mpi"], settings) as reporter, run_failures():
        result = run_virtual_test(test, inputs, out=out, settings=settings, quick=quick, label=label, progress=reporter,
                                  **options)
    if result.clump_warning:
        click.echo(result.clump_warning, err=True)
    click.echo(result.line)
    if not result.passed:  # the outputs are written; the runs or the clumps fail their own check
        if result.failed_runs:
            click.echo(f"check failed: {result.failed_runs} (results.csv has every run)", err=True)
        sys.exit(EXIT_CHECK_FAILED)


repose = _command("repose", """Angle of repose: a cylinder of grains on a rough base is lifted and the heap measured.

    INPUTS: mesh files (mm), a generate/batch folder, a manifest, or one TOML recipe.
    --templates of their grains, chosen so that their shapes and sizes are distributed as the
    population's (the KS figures are printed and written to templates.csv), each becomes a clump
    with the mesh's exact mass and inertia (grainforge dem);
    Yade (or LIGGGHTS, --engine liggghts [--mpi N]) runs headless once per seed; the heap's slope is
    fitted in 8 sectors.  See docs/simulate.md.
    """)
tilt = _command("tilt", """Tilt table: a layer of grains on a rough plate is tilted until it slides.

    INPUTS as for `simulate repose`.  The layer is periodic (an infinite slope); failure is the
    tilt at which the layer's mean downslope displacement exceeds half a grain diameter.
    """)
triaxial = _command("triaxial", """Drained triaxial compression: a periodic cell (Yade) or a walled box (LIGGGHTS).

    In LIGGGHTS (--engine liggghts [--mpi N]) six servo-controlled walls close the box.

    INPUTS as for `simulate repose`.  The grains are compacted isotropically to --confining-kpa
    (dense: without friction; loose: with it), then the specimen is shortened in z at the strain rate
    of --inertial-number while x and y are held at the confining stress, to --axial-strain.
    Writes each seed's triaxial.csv (q/p', volumetric strain, void ratio, coordination against the
    axial strain), results.csv (peak and ultimate friction angles, largest dilatancy angle) and
    triaxial.png.  Stresses and strains compression positive.  See docs/simulate.md.
    """)


class _SimulateGroup(click.Group):
    """``simulate``'s commands, and commands of two words (``simulate calibrate material``, whose second word
    would otherwise be ``calibrate``'s TEST), registered in :attr:`two_words` by :mod:`grainforge.cli.group`."""

    two_words: dict = {}

    def resolve_command(self, ctx, args):
        name = " ".join(args[:2])
        if name in self.two_words:
            return name, self.two_words[name], args[2:]
        return super().resolve_command(ctx, args)


@click.group(cls=_SimulateGroup)
def simulate():
    """Virtual bulk tests in Yade or LIGGGHTS (angle of repose, tilt table, drained triaxial test): shape's effect
    on bulk friction."""


simulate.add_command(repose)
simulate.add_command(tilt)
simulate.add_command(triaxial)
