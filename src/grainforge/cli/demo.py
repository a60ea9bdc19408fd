"""``grainforge demo``: the gallery that ``make demo`` runs."""

from __future__ import annotations

import time
from pathlib import Path

import click

from .paths import OutPath, output_dir


@click.command()
@click.option("--out", default=Path("out/demo"), show_default=True, type=OutPath(file_okay=False))
@click.option("--quick", is_flag=True, help="Fewer, coarser grains (for a fast check).")
def demo(out, quick):
    """Generate the paper-style galleries (grains, manifests, contact sheets) into OUT."""
    from ..demo import run_demo

    output_dir(out)  # demo always replaces its own outputs
    t0 = time.perf_counter()
    written = run_demo(out, quick=quick, echo=lambda s: click.echo(s, err=True))
    click.echo(f"\nDemo finished in {time.perf_counter() - t0:.0f} s. Results in {out.resolve()}:")
    for p in written:
        click.echo(f"  {p}{'/' if p.is_dir() else ''}")
