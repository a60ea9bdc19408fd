"""``grainforge fourier``: Fourier descriptors of the grains in micrographs."""

from __future__ import annotations

import click

from ..errors import InputError
from .help_style import option
from .options import FINITE_FLOAT, FiniteFloatRange, overwrite_option
from .paths import OutPath, output_file

#: descriptors printed per grain (D2..D16: grainforge.analysis.fourier.FD_ORDERS; a number here, so that
#: --help loads no numpy)
N_MAX = 16


@click.command()
@click.argument("images", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=str))
@option("--csv", "csv_path", type=OutPath(dir_okay=False), default=None,
        help="Write the table to this CSV file instead of stdout.")
@overwrite_option("Replace an existing --csv file.")
@option("--min-area", default=50, show_default=True, type=click.IntRange(min=0),
        help="Skip specks smaller than this many pixels.")
@option("--threshold", type=FINITE_FLOAT, default=None, show_default="Otsu", help="Grey level separating grains and background.")
@option("--foreground", type=click.Choice(["auto", "dark", "bright"]), default="auto", show_default=True,
        help="Which side of the threshold the grains are; auto: the side covering fewer border pixels.")
@option("--pixel-size", type=FiniteFloatRange(min=0, min_open=True), default=None, metavar="UM",
        help="Micrometres per pixel: adds x_mm, y_mm, area_mm2 and r0_mm (physical) columns.")
@option("--rays", default=128, show_default=True, type=click.IntRange(min=2 * N_MAX + 2),
        help="Rays cast from each grain's area centroid.")
def fourier(images, csv_path, overwrite, min_area, threshold, foreground, rays, pixel_size):
    """Fourier descriptors D2..D16 of every grain in IMAGE... (one CSV row per grain).

    Grains are segmented by thresholding (holes filled); D_n = 2|c_n|/c_0 of the
    radius r(theta) cast from each grain's area centroid.  elongation,
    irregularity and roughness are D2, D3 and D8.  Grains touching the image
    border and specks below --min-area are skipped and counted on stderr.
    An image that cannot be read or holds no grain is named on stderr and
    skipped; the others are measured, and the exit code is then 1.
    """
    import math

    from ..analysis.fourier import MICROGRAPH_COLUMNS, MICROGRAPH_MM_COLUMNS, check_rays, micrograph_rows
    from ..io import atomic_write, csv_text

    if threshold is not None and not math.isfinite(threshold):
        raise click.BadParameter(f"must be a finite grey level, got {threshold}", param_hint="'--threshold'")
    if pixel_size is not None and not math.isfinite(pixel_size):
        raise click.BadParameter(f"must be a finite number of µm per pixel, got {pixel_size}", param_hint="'--pixel-size'")
    if csv_path is not None:
        output_file(csv_path, overwrite=overwrite, option="--csv", suffixes=(".csv",))
    try:
        check_rays(rays)
    except InputError as exc:
        raise click.BadParameter(str(exc), param_hint="'--rays'") from None
    all_rows = []
    border = small = bad = 0
    failed: list[str] = []
    for path in images:
        try:
            rows, scan = micrograph_rows(path, min_area=min_area, threshold=threshold,
                                          foreground=foreground, rays=rays, pixel_size=pixel_size)
        except InputError as exc:
            message = " ".join(str(exc).split())
            failed.append(path)
            if len(images) == 1:
                raise click.BadParameter(message, param_hint="IMAGE") from None
            click.echo(f"skipped {message if path in message else f'{path}: {message}'}", err=True)
            continue
        if not rows:
            failed.append(path)
            if len(images) > 1:
                click.echo(f"skipped {path}: no grain measured ({scan.border} touching the border, "
                           f"{scan.small} below {min_area} px)", err=True)
        all_rows += rows
        border += scan.border
        small += scan.small
        bad += scan.unmeasurable
    if not all_rows:
        raise click.UsageError(
            f"no grain measured in {len(images)} image(s) (skipped {border} touching the border, "
            f"{small} below {min_area} px" + (f", {len(failed)} image(s) unreadable or empty" if failed else "") + ")"
        )
    mm = MICROGRAPH_MM_COLUMNS if pixel_size is not None else []
    text = csv_text(all_rows, MICROGRAPH_COLUMNS[:2] + mm + MICROGRAPH_COLUMNS[2:])
    if csv_path is not None:
        atomic_write(csv_path, text)
    else:
        click.echo(text, nl=False)
    click.echo(
        f"{len(all_rows)} grain(s) measured in {len(images)} image(s); skipped {border} touching the border, "
        f"{small} below {min_area} px" + (f", {bad} not measurable from their centroid" if bad else ""),
        err=True,
    )
    if failed:
        click.echo(f"skipped {len(failed)} of {len(images)} image(s): {', '.join(failed)}", err=True)
        raise SystemExit(1)

