"""``grainforge tray``: lay out many grains on a printer's build plates in one print file or several."""

from __future__ import annotations

from pathlib import Path

import click

from ..fabrication.tray import DEFAULT_TRIANGLE_BUDGET
from ..params import ParameterError
from .help_style import option
from .options import (
    FiniteFloatRange,
    bad_parameter,
    count_option,
    overwrite_option,
    seed_option,
    size_definition_option,
    workers_option,
)
from .paths import OutPath, output_file
from .progress import progress_bar


def parse_param_values(method: str, pairs, preset: str | None):
    """``name=value`` strings to a method's Params, converting by each field's declared kind."""
    from ..methods import get
    from ..params import specs
    from .options import FloatList, build_params

    module = get(method)
    by_name = {s.name: s for s in specs(module.Params)}
    values = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or not name:
            raise click.BadParameter(f"expected NAME=VALUE, got {pair!r}", param_hint="'--param'")
        spec = by_name.get(name)
        if spec is None:
            raise click.BadParameter(
                f"{method} has no parameter {name!r} (has {', '.join(by_name)})", param_hint="'--param'")
        try:
            if spec.kind == "int":
                values[name] = int(text)
            elif spec.kind == "float":
                values[name] = float(text)
            elif spec.kind == "floats":
                values[name] = FloatList().convert(text, None, None)
            else:
                values[name] = text
        except (ValueError, click.BadParameter):
            raise click.BadParameter(f"{name}: cannot read {text!r} as {spec.kind}", param_hint="'--param'") from None
    if preset is not None:
        if "preset" not in by_name:
            raise click.BadParameter(f"method {method!r} has no presets", param_hint="'--preset'")
        values["preset"] = preset
    return build_params(module.Params, values), values


class Plates(click.ParamType):
    """``--plates``: a positive number of print files, or ``auto``."""

    name = "N|auto"

    def convert(self, value, param, ctx):
        text = str(value).strip().lower()
        if text == "auto":
            return "auto"
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            self.fail(f"expected a positive whole number of print files or 'auto', got {value!r}", param, ctx)
        return n


def _say(line: str) -> None:
    """A line of the tray's plan, said before it makes any grain (stderr)."""
    click.echo(line, err=True)


@click.command()
@click.argument("inputs", nargs=-1, type=click.Path(path_type=Path))
@option("--printer", "printer_spec", default="objet-eden-250", show_default=True,
        help="Printer profile: objet-eden-250, generic-fdm, generic-sla, or FILE.toml[#NAME].")
@option("--out", required=True, type=OutPath(dir_okay=False),
        help="Print file: .3mf (one named object per grain) or .stl (binary). "
             "Also writes STEM.csv and STEM-plateK.png.")
@option("--method", default=None, help="Generate grains on the fly with this method (instead of INPUTS).")
@option("--preset", default=None, help="The method's preset (same as --param preset=NAME).")
@option("--param", "params", multiple=True, metavar="NAME=VALUE",
        help="A method parameter, repeatable (e.g. --param fractal_dimension=2.6).")
@count_option("Number of generated grains; grain i uses seed S + i.")
@seed_option()
@option("--size", default=None, type=FiniteFloatRange(min=1e-3, max=1e4),
        show_default="10 for generated grains; files keep their size",
        help="Grain size in mm, 0.001 (1 µm) to 10000 (10 m) (see --size-definition).")
@size_definition_option
@option("--gap", default=None, type=FiniteFloatRange(min=0, min_open=True),
        show_default="two printer resolutions", help="Minimum distance between grains in mm.")
@option("--max-subdivisions", default=None, type=click.IntRange(0, 7),
        show_default="6", help="Finest mesh level resolution matching may choose.")
@option("--max-triangles", default=DEFAULT_TRIANGLE_BUDGET, show_default=True, type=click.IntRange(min=20),
        help="Triangle budget of one print file, what a slicer takes (per grain: budget x plates / count).")
@option("--plates", default="1", show_default=True, type=Plates(),
        help="Print files to spread the grains over (STEM-plateK.EXT), each within --max-triangles; "
             "auto: as many as give every grain the printer's tolerance.")
@workers_option("Processes making grains (the output does not depend on it).", default=2)
@overwrite_option()
def tray(inputs, printer_spec, out, method, preset, params, count, seed, size, size_definition, gap,
         max_subdivisions, max_triangles, plates, workers, overwrite):
    """Lay out grains on the build plates of a printer, at least --gap apart, in one print file or several.

    Grains come from INPUTS (mesh files, folders of them, or manifest.csv files
    written by `grainforge generate`) or are generated on the fly with --method:

      grainforge tray --method cri --preset rough-angular --count 8000 --size 2 \\
          --printer objet-eden-250 --out tray.3mf

    Generated grains get the mesh resolution their printed size and the
    printer call for (unless --param subdivisions=N is given), within the
    triangle budget of the print files; the choice, and what the budget does
    to the surface, are said before any grain is made and recorded in the
    CSV.  --plates auto spreads the grains over as many files as the
    printer's tolerance needs.  PolyJet printers stack grains in 3D; others
    get one layer, each grain resting on a stable face.
    """
    from ..fabrication.printers import get_printer
    from ..fabrication.tray import FileSource, GeneratorSource, build_tray
    from ..io.inputs import mesh_paths

    output_file(out, overwrite=True, option="--out", suffixes=(".3mf", ".stl"))  # existing outputs: build_tray
    printer = get_printer(printer_spec)
    if method is not None:
        if inputs:
            raise click.UsageError("give either INPUTS or --method, not both")
        p, given = parse_param_values(method, params, preset)
        source = GeneratorSource(method, p, range(seed, seed + count), 10.0 if size is None else size,
                                 size_definition)
        match = "subdivisions" not in given
    else:
        if not inputs:
            raise click.UsageError("give grain files, folders or manifests, or --method to generate grains")
        if params or preset:
            raise click.UsageError("--param and --preset need --method")
        source = FileSource(tuple(mesh_paths(inputs)), size, size_definition)
        match = False
    try:
        result = build_tray(
            source, printer, out, gap=gap, workers=workers, overwrite=overwrite, match_resolution=match,
            max_subdivisions=max_subdivisions, max_triangles=max_triangles, plates=plates,
            progress=progress_bar(total=len(source), desc="tray"), say=_say,
        )
    except ParameterError as exc:
        raise bad_parameter(exc) from None
    except FileExistsError as exc:
        raise click.UsageError(str(exc)) from None
    warnings = []
    res = result.resolution
    if res is not None:
        budget = result.plan.warning()
        if budget is not None:
            warnings.append(budget)
        elif not res.converged:
            warnings.append(
                f"--max-subdivisions caps the mesh at level {res.subdivisions}: its chordal deviation "
                f"{res.deviation * 1000:.1f} µm exceeds the printer tolerance {res.tolerance * 1000:.1f} µm, so the "
                f"printed surface will show the mesh facets")
        shape = res.shape_warning(source.size)
        if shape is not None:
            warnings.append(shape + ("" if res.limited_by == "budget" else
                                     "  Print larger or on a finer printer, or give --param subdivisions=N."))
    small = printer.size_warning([row["equivalent_diameter"] for row in result.rows])
    if small is not None:
        warnings.append(small)
    layers = ", ".join(str(n) for n in result.layers)
    click.echo(f"wrote {len(result.rows)} grains on {result.plates} plate(s) ({layers} layer(s)), "
               f"gap {result.gap * 1000:g} µm: {', '.join(map(str, result.files))}; "
               f"positions in {result.csv}; previews {', '.join(map(str, result.previews))}", err=True)
    for w in warnings:  # last, so that they are seen
        click.echo(f"WARNING: {w}", err=True)
