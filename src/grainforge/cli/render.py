"""``grainforge render FILES... -o sheet.png``: a contact sheet of grain pictures."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--out", required=True, type=click.Path(dir_okay=False, path_type=Path), help="PNG to write.")
@click.option("--columns", type=click.IntRange(min=1), default=None, help="Panels per row.")
@click.option("--title", default=None, help="Title above the panels.")
def render(files, out, columns, title):
    """Render mesh FILES (STL, OBJ, PLY, 3MF) as a labelled contact sheet PNG."""
    from ..io import read_mesh
    from ..render import contact_sheet

    meshes = [read_mesh(f) for f in files]  # ValueError -> one line, exit 2
    contact_sheet(meshes, [f.name for f in files], out, columns=columns, title=title)
    click.echo(f"wrote {out}", err=True)
