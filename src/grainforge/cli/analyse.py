"""``grainforge analyse FILE... [--csv OUT] [--json]``: shape descriptors of mesh files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from ..errors import InputError
from ..units import with_unit
from .help_style import option
from .options import (
    FiniteFloatRange,
    overwrite_option,
    renamed_option,
    voxel_size_flag,
    voxel_size_options,
    workers_option,
)
from .paths import OutPath, mesh_inputs, output_file

#: columns of the terminal table (all columns go to --csv and --json)
TABLE = (
    ("file", "file", "{}"), ("body", "body", "{}"), ("faces", "faces", "{}"), ("flags", "flags", "{}"),
    ("volume", "V_mm3", "{:.4g}"), ("equivalent_diameter", "d_eq_mm", "{:.4g}"), ("sphericity", "sph", "{:.3f}"),
    ("convexity", "conv", "{:.3f}"), ("L", "L_mm", "{:.4g}"), ("I", "I_mm", "{:.4g}"), ("S", "S_mm", "{:.4g}"),
    ("krumbein_sphericity", "krumb", "{:.3f}"), ("roughness", "rough", "{:.4f}"),
    ("fractal_dimension", "D_s", "{:.2f}"), ("fd_LI_2", "FD2", "{:.3f}"), ("fd_LI_3", "FD3", "{:.3f}"),
    ("fd_LI_8", "FD8", "{:.4f}"), ("atlas_voxels_across", "vox/d", "{:.3g}"),
    ("atlas_sphericity", "a_sph", "{:.3f}"), ("atlas_convexity", "a_conv", "{:.3f}"),
    ("atlas_flatness", "a_flat", "{:.3f}"), ("atlas_elongation", "a_elong", "{:.3f}"),
    ("atlas_opening_fraction", "a_open", "{:.4f}"),
)


def _fmt(value, spec: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    try:
        return spec.format(value)
    except (ValueError, TypeError):
        return str(value)


def table_text(rows, columns=TABLE) -> str:
    """A plain aligned table of ``rows`` (only the columns present)."""
    cols = [c for c in columns if any(c[0] in r for r in rows)]
    cells = [[h for _, h, _ in cols]] + [[_fmt(r.get(k), s) for k, _, s in cols] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(cols))]
    lines = ["  ".join(c.ljust(w) if i < 4 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))) for row in cells]
    return "\n".join(line.rstrip() for line in lines)


def _write_atlas_table(path: Path, rows) -> None:
    """The closed bodies' atlas_* columns as a Sand Atlas CSV (mm to µm); one line on stderr says what was written."""
    from ..analysis.atlas import OPENING_RADIUS
    from ..fit import DESCRIPTORS, write_sand

    grains = [r for r in rows if math.isfinite(r.get("atlas_sphericity", math.nan))]
    if not grains:
        raise click.UsageError("--atlas-csv: no closed body to measure; nothing written")
    write_sand(path, [1000.0 * r["atlas_equivalent_diameter"] for r in grains],
               {k: [r["atlas_" + k] for r in grains] for k in DESCRIPTORS},
               voxel_size=[1000.0 * r["atlas_voxel_size"] for r in grains],
               opening=[r["atlas_opening_fraction"] for r in grains])
    left = len(rows) - len(grains)
    click.echo(f"wrote {len(grains)} grain(s) to {path} as a Sand Atlas table (µm; opening fraction at a ball of "
               f"{OPENING_RADIUS:.4g} d_eq)" + (f"; {left} open body/bodies left out" if left else ""), err=True)


def _json_value(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _check_atlas(files, atlas: dict, workers: int, option: str) -> None:
    """Before any image is made: every body's image means something and the largest fits in memory."""
    from ..analysis.atlas import check_atlas_request
    from ..analysis.measure import grain_sizes
    from ..runtime.estimate import TooLargeError
    from .progress import progress_bar

    bodies = []
    for path in progress_bar(total=len(files), desc="check", unit="file")(files):
        bodies += grain_sizes(path)
    try:
        check_atlas_request(bodies, voxel_size=atlas.get("voxel_size"), voxels_across=atlas.get("voxels_across"),
                            workers=workers, unit="mm")
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    except InputError as exc:
        raise click.BadParameter(str(exc), param_hint=option) from None


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@option("--csv", "csv_out", type=OutPath(dir_okay=False), default=None,
        help="Also write every column to this CSV file.")
@option("--json", "as_json", is_flag=True, help="Print JSON (a list of rows, all columns) instead of the table.")
@option("--fractal/--no-fractal", default=True, show_default=True, help="Estimate the surface fractal dimension.")
@option("--fourier/--no-fourier", default=True, show_default=True,
        help="Fourier descriptors D2…D16 of the three principal projections.")
@option("--primary-volume", type=FiniteFloatRange(min=0, min_open=True), default=None,
        help="Volume of an aggregate's primary particle (file units³): reports D_A (paper Eq. 5).")
@voxel_size_options("mm", "Also measure the Sand-Atlas way (atlas_* columns) on a voxel image of this voxel size "
                          "in mm (the files' unit: 7.3 µm is 0.0073); see docs/validation.md.")
@renamed_option("--voxel-size", "--voxel-size-mm", "mm")
@option("--voxels-across", type=FiniteFloatRange(min=2), default=None,
        help="As --voxel-size-um/--voxel-size-mm, with the voxel size set to d_eq / this number.")
@option("--sphericity-convention", "sphericity", type=click.Choice(["atlas", "whole"]), default="atlas",
        show_default=True,
        help="atlas_sphericity as the Sand Atlas computed it (spam's cube, clipped above the centre of "
             "mass) or on the whole grain; docs/validation.md.")
@option("--atlas-csv", type=OutPath(dir_okay=False), default=None,
        help="Also write the atlas_* columns as a Sand Atlas table that `grainforge fit` reads (lengths in "
             "µm, the files being in mm), with each grain's opening fraction; needs a voxel size or "
             "--voxels-across. Bodies that are not closed are left out.")
@overwrite_option("Replace an existing --csv or --atlas-csv file.")
@workers_option("Processes measuring files; rows do not depend on it.", default_text="one per CPU, at most one per file")
@option("--scheduler", metavar="ADDRESS", default=None,
        help="Measure the files on an existing Dask distributed cluster, e.g. tcp://host:8786 (each file is "
             "sent to a worker; needs grainforge[dask] and the same grainforge on the workers); the rows are "
             "the same.")
def analyse(files, csv_out, as_json, fractal, fourier, primary_volume, voxel_size, voxels_across, sphericity,
            atlas_csv, overwrite, workers, scheduler):
    """Shape descriptors of mesh FILES (STL, OBJ, PLY, 3MF, or folders of them), one row per body.

    Volume, area, d_eq, Wadell sphericity, convexity, L ≥ I ≥ S (minimum-volume
    box, and principal axes), Zingg ratios, Krumbein sphericity, roughness,
    surface fractal dimension, Fourier descriptors of the three principal
    projections and, for aggregates, porosity, R_g and D_A.  Bodies that are not
    closed are analysed and flagged `open`; files with several bodies are
    flagged `multi-body`; a body with a cavity (an inner shell inside it) is
    flagged `cavity` and the inner shell is no row.  Files in another unit than
    mm (a body outside 0.0001–100000 mm) or too far from the origin for float32
    are refused.  The table goes to stdout; see docs/validation.md.
    With --atlas-csv the grains' Sand-Atlas measures also become a table that
    `grainforge fit` reads (docs/fit.md).

    A 3D image instead of meshes (a labelled or binary μCT volume: .tif/.tiff,
    a folder of TIFF slices, .npy, or raw with --raw-shape) is measured grain by
    grain with the options of `grainforge scan` (docs/guide/scan.md).
    """
    import contextlib

    from ..analysis.measure import ANALYSE_COLUMNS
    from ..io import write_csv
    from ..runtime.workers import default_workers

    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers is for the local processes; the Dask cluster (--scheduler) has its own")
    if scheduler is not None:
        from ..runtime.cluster import check_address

        check_address(scheduler)
    if primary_volume is not None and not math.isfinite(primary_volume):
        raise click.BadParameter(f"must be a finite volume, got {primary_volume}", param_hint="'--primary-volume'")
    if voxel_size is not None and voxels_across is not None:
        raise click.UsageError(f"give {voxel_size_flag('--voxel-size-mm')} or --voxels-across, not both")
    atlas = None
    if voxel_size is not None:
        atlas = {"voxel_size": voxel_size, "convention": sphericity}
    elif voxels_across is not None:
        atlas = {"voxels_across": voxels_across, "convention": sphericity}
    if csv_out is not None:
        output_file(csv_out, overwrite=overwrite, option="--csv", suffixes=(".csv",))
    if atlas_csv is not None:
        if atlas is None:
            raise click.UsageError("--atlas-csv needs --voxel-size-mm (or --voxel-size-um) or --voxels-across (the "
                                   "scan's resolution)")
        output_file(atlas_csv, overwrite=overwrite, option="--atlas-csv", suffixes=(".csv",))
        if csv_out is not None and Path(csv_out).resolve() == Path(atlas_csv).resolve():
            raise click.UsageError("--csv and --atlas-csv must be different files")
    files = mesh_inputs(files)
    with contextlib.ExitStack() as stack:
        executor = None
        if scheduler is not None:
            from ..runtime.cluster import dask_executor

            executor = stack.enter_context(dask_executor(scheduler))  # refused in one line before any work
            n = executor.workers
        else:
            n = min(len(files), default_workers(workers))
        if atlas is not None:  # the memory a worker needs: each Dask worker has its own
            _check_atlas(files, atlas, 1 if executor else n,
                         voxel_size_flag("--voxel-size-mm") if voxel_size is not None else "--voxels-across")
        rows = _measure_files(files, n, executor, dict(fractal=fractal, fourier=fourier,
                                                       primary_volume=primary_volume, atlas=atlas))
    columns = ANALYSE_COLUMNS(fourier, atlas=atlas is not None)
    if csv_out is not None:
        write_csv(csv_out, rows, columns, units=True)
        click.echo(f"wrote {len(rows)} row(s) to {csv_out}", err=True)
    if atlas_csv is not None:
        _write_atlas_table(atlas_csv, rows)
    if as_json:
        click.echo(json.dumps([{with_unit(c): _json_value(r.get(c)) for c in columns} for r in rows], indent=1))
    else:
        click.echo(table_text(rows))
    flagged = [r for r in rows if r["flags"]]
    if flagged:
        seen = {w for r in flagged for w in r["flags"].split()}
        said = "; ".join(f"{flag}: {meaning}" for flag, meaning in FLAG_NOTES.items() if flag in seen)
        click.echo(f"note: {len(flagged)} body/bodies flagged ({said})", err=True)


def _measure_files(files, workers: int, executor, options: dict) -> list:
    """Every file's rows, in the files' order, under a progress bar; a lost Dask scheduler is one line (exit 1)."""
    from ..analysis.measure import analyse_files
    from ..runtime.cluster import SchedulerLost
    from .progress import progress_bar

    rows = []
    bar = progress_bar(total=len(files), desc="analyse", unit="file")
    try:
        for file_rows in bar(analyse_files(files, workers=workers, executor=executor, **options)):
            rows += file_rows
    except SchedulerLost as exc:
        raise click.ClickException(f"{exc}; nothing written (the rows are written once every file is "
                                   "measured): rerun when the cluster is back") from None
    return rows


#: what each flag means, in the note after the table (only the flags present are explained)
FLAG_NOTES = {
    "open": "volume-based values approximate",
    "multi-body": "one row per body",
    "cavity": "encloses an inner shell, a void: the row measures the outer surface, the void is no row",
    "overlapping": "overlaps another body of the file: each row measures one body",
    "inverted": "inside out, measured after flipping",
    "not-solid": "not a valid solid, `grainforge check` says why",
}
