"""``grainforge demo``: the gallery that ``make demo`` runs."""

from __future__ import annotations

import time
from pathlib import Path

import click

from .help_style import option
from .options import overwrite_option
from .paths import OutPath, output_dir


@click.command()
@option("--out", default=Path("out/demo"), show_default=True, type=OutPath(file_okay=False))
@option("--quick", is_flag=True, help="Fewer, coarser grains (for a fast check).")
@overwrite_option("Replace the outputs of an earlier demo in --out (make demo does).")
def demo(out, quick, overwrite):
    """Generate the paper-style galleries (grains, manifests, contact sheets) into OUT."""
    from ..viz.demo import run_demo

    output_dir(out)
    earlier = out.is_dir() and any(out.iterdir())
    if earlier and not overwrite:
        raise click.UsageError(f"{out} exists and is not empty; use --overwrite to replace the demo's outputs in it")
    if earlier:
        click.echo(f"overwriting the demo's outputs in {out}", err=True)
    t0 = time.perf_counter()
    written = run_demo(out, quick=quick, echo=lambda s: click.echo(s, err=True))
    click.echo(f"\nDemo finished in {time.perf_counter() - t0:.0f} s. Results in {out.resolve()}:")
    for p in written:
        click.echo(f"  {p}{'/' if p.is_dir() else ''}")
