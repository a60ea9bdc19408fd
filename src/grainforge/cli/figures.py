"""``grainforge figures --out DIR``: the paper's Figures 1–6 and the shape-control Figures 7–9 as PNGs."""

from __future__ import annotations

import click

from .help_style import option
from .options import overwrite_option
from .paths import OutPath, output_dir


@click.command()
@option("--out", required=True, type=OutPath(file_okay=False), help="Folder for the PNGs.")
@option("--only", "only", multiple=True, type=click.IntRange(1, 9), help="Only this figure (repeatable).")
@option("--subdivisions", type=click.IntRange(2, 6), default=5, show_default=True,
        help="Icosphere level of the FSO and CRI grains (lower is faster).")
@overwrite_option("Replace existing figure files.")
def figures(out, only, subdivisions, overwrite):
    """Regenerate the paper's Figures 1-6 (FSO, contours, CRI, DPA) into OUT, plus 7-9.

    Same panels and parameters as the paper's captions, fixed seeds.  7: FSO aspects; 8: paper vs
    seamless FSO (pole and equator views); 9: CRI before/after the shape-control changes.
    """
    from ..viz.figures import FIGURES, make_figures

    numbers = tuple(sorted(set(only))) or tuple(FIGURES)
    output_dir(out, overwrite=overwrite, files=[out / FIGURES[n][0] for n in numbers])
    written, skipped = make_figures(out, numbers, subdivisions=subdivisions,
                                    echo=lambda msg: click.echo(msg, err=True))
    for n, reason in skipped:
        click.echo(f"skipped Figure {n}: {reason}", err=True)
