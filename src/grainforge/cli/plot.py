"""``grainforge plot KIND MANIFEST.csv... -o OUT.png``: population plots."""

from __future__ import annotations

from pathlib import Path

import click

from ..viz.plots import KINDS
from .help_style import option
from .options import overwrite_option
from .paths import OutPath, output_file


@click.command()
@click.argument("kind", type=click.Choice(tuple(KINDS)))
@click.argument("manifests", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("-o", "--out", required=True, type=OutPath(dir_okay=False), help="PNG to write.")
@option("--title", default=None, help="Plot title.")
@overwrite_option("Replace an existing OUT.")
def plot(kind, manifests, out, title, overwrite):
    """Plot KIND for one or more MANIFEST CSVs (overlaid, with a legend).

    \b
    zingg                 S/I against I/L with the Zingg classes (columns L, I, S)
    sphericity-convexity  Wadell sphericity against convexity
    fd-spectrum           Fourier descriptors D2..D16, log-log (columns of `analyse --csv`;
                          a CRI manifest's input spectrum is drawn dashed)
    size-distribution     % finer by volume against equivalent diameter
    """
    from ..viz.plots import plot as draw

    out = output_file(out, overwrite=overwrite, option="-o", suffixes=(".png",))
    draw(kind, manifests, out, title=title)
    click.echo(f"wrote {out}", err=True)
