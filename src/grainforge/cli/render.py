"""``grainforge render FILES... -o sheet.png``: a contact sheet of grain pictures."""

from __future__ import annotations

from pathlib import Path

import click

from .help_style import option
from .options import overwrite_option
from .paths import OutPath, mesh_inputs, output_file

#: image formats the sheet can be written in (by the suffix of -o)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("-o", "--out", required=True, type=OutPath(dir_okay=False),
        help="Image to write: .png, or .jpg/.jpeg (JPEG).")
@option("--columns", type=click.IntRange(min=1), default=None, show_default="about square",
        help="Panels per row (at most the number of panels).")
@option("--title", default=None, help="Title above the panels.")
@option("--common-scale/--own-scale", default=True, show_default=True,
        help="Draw every grain at one scale (the largest's) with one scale bar, so that their sizes compare; "
             "or each filling its own panel, with a scale bar of its own.")
@overwrite_option("Replace an existing OUT.")
def render(files, out, columns, title, common_scale, overwrite):
    """Render mesh FILES (STL, OBJ, PLY, 3MF, or folders of them) as a labelled contact sheet.

    Every grain is drawn at one scale, with one scale bar in mm (--own-scale: each filling its panel).
    """
    from ..io import read_mesh
    from ..viz.render import contact_sheet

    out = output_file(out, overwrite=overwrite, option="-o", suffixes=IMAGE_SUFFIXES)
    files = mesh_inputs(files)
    meshes = [read_mesh(f) for f in files]  # ValueError -> one line, exit 2
    if columns is not None:
        columns = min(columns, len(meshes))  # more columns than panels would only be empty space
    # mesh files are in mm (what grainforge writes; STL carries no unit): a scale bar in mm, one for the sheet at
    # one scale, one a panel at their own
    contact_sheet(meshes, [f.name for f in files], out, columns=columns, title=title, unit="mm",
                  common_scale=common_scale)
    click.echo(f"wrote {out}", err=True)
