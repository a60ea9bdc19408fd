"""``grainforge check FILE... --printer P``: will these grains print?"""

from __future__ import annotations

from pathlib import Path

import click

from .help_style import option

#: every column states its unit (``_mm``, ``_%``) or is a count or a word; ``*_status`` says whether the
#: number next to it was measured or is the measuring horizon (``thicker``: a lower bound).
COLUMNS = ("file", "part", "status", "faces", "d_eq_mm", "solid", "self_intersections", "min_wall_mm",
           "min_wall_status", "thin_area_%", "min_neck_mm", "min_neck_status", "problems")


def _table(rows: list[dict]) -> str:
    widths = {c: max(len(c), *(len(str(r[c])) for r in rows)) for c in COLUMNS if c != "problems"}
    lines = ["  ".join(c.ljust(widths[c]) for c in widths) + "  problems"]
    for r in rows:
        lines.append("  ".join(str(r[c]).ljust(widths[c]) for c in widths) + "  " + str(r["problems"]))
    return "\n".join(lines)


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("--printer", "printer_spec", default="objet-eden-250", show_default=True,
        help="Printer profile: objet-eden-250, generic-fdm, generic-sla, or FILE.toml[#NAME].")
@option("--csv", "as_csv", is_flag=True, help="Print the table as CSV instead of aligned text.")
def check(files, printer_spec, as_csv):
    """Check mesh FILES (STL, OBJ, PLY, 3MF, or folders of them; every object of a 3MF) against a printer.

    Checks: grains below the printer's reliable size (said first, one line
    per part on stderr), watertight, manifold, one body, no
    self-intersection, wall thickness / minimum feature and thin necks
    against the printer's minimum wall.  Prints a table on stdout; exits with
    1 when something will not print (FAIL), 0 otherwise (WARN rows print but
    are fragile).  Files are read and checked one at a time.
    """
    import sys

    from ..fabrication.printability import check_mesh, equivalent_diameter
    from ..fabrication.printers import get_printer
    from ..geometry.solid import mesh_size_problem
    from ..io import csv_text, read_parts
    from .paths import mesh_inputs
    from .progress import progress_bar

    printer = get_printer(printer_spec)
    files = mesh_inputs(files)
    rows = []
    for path in progress_bar(total=len(files), desc="check", unit="file")(files):
        try:
            parts = read_parts(path)  # ValueError -> exit 2; one file in memory at a time
            for part in parts:  # a file in another unit than mm: refused before any part is checked
                problem = mesh_size_problem(part.vertices, "the mesh" if len(parts) == 1 else f"part {part.name}")
                if problem is not None:
                    raise click.UsageError(f"{path}: {problem}")
            for part in parts:
                small = printer.size_problem(equivalent_diameter(part.vertices, part.faces))
                if small is not None:  # before the slower tests, so that it is seen at once
                    _say(f"{path}: {part.name}: will not print reliably on {printer.name}: {small}", sys.stderr)
                r = check_mesh(part.vertices, part.faces, printer, name=part.name).row()
                rows.append({"file": str(path), **r})
        except MemoryError:
            raise MemoryError(str(path)) from None  # the message names the file
        finally:
            parts = part = None  # let this file go before the next one is read
    click.echo(csv_text(rows, COLUMNS) if as_csv else _table(rows), nl=not as_csv)
    failed = sum(r["status"] == "FAIL" for r in rows)
    warned = sum(r["status"] == "WARN" for r in rows)
    click.echo(f"{printer.name}: {len(rows)} part(s), {failed} will not print, {warned} fragile "
               f"(min wall {printer.min_wall:g} mm, reliable size {printer.min_size:g} mm)", err=True)
    if failed:
        raise SystemExit(1)


def _say(line: str, stream) -> None:
    """One line on stderr that does not break a progress bar."""
    from tqdm import tqdm

    tqdm.write(line, file=stream)
