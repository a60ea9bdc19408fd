"""``grainforge fourier``: Fourier descriptors of the grains in micrographs."""

from __future__ import annotations

import click

from .help_style import option
from .options import FINITE_FLOAT, FiniteFloatRange, overwrite_option
from .paths import OutPath, output_file

#: descriptors printed per grain (D2..D16)
N_MAX = 16


def descriptor_rows(path: str, *, min_area: int, threshold, foreground: str, rays: int,
                    pixel_size: float | None = None):
    """Rows (dicts) for every grain of one image, and the scan summary.

    Positions and sizes are in pixels (``x_px``, ``area_px2``, ...) and, with
    ``pixel_size`` (µm per pixel), also in millimetres (``x_mm``, ``area_mm2``, ...).
    """
    from ..outline.contours import scan_image

    scan = scan_image(path, min_area=min_area, threshold=threshold, foreground=foreground, n_angles=rays)
    rows = []
    for i, (c, area) in enumerate(zip(scan.contours, scan.areas)):
        D = c.descriptors(N_MAX)
        row = {
            "image": path, "grain": i, "x_px": round(float(c.centroid[0]), 3), "y_px": round(float(-c.centroid[1]), 3),
            "area_px2": area, "r0_px": round(c.scale, 4), "star_shaped": c.star_shaped,
            "elongation": float(D[2]), "irregularity": float(D[3]), "roughness": float(D[8]),
        }
        row.update({f"D{n}": float(D[n]) for n in range(2, N_MAX + 1)})
        if pixel_size is not None:
            mm = pixel_size / 1000.0
            row.update({"x_mm": row["x_px"] * mm, "y_mm": row["y_px"] * mm, "area_mm2": area * mm * mm,
                        "r0_mm": c.scale * mm})
        rows.append(row)
    return rows, scan


#: positions and sizes state their unit: pixels (x to the right from the left edge, y = −row: up) and,
#: with --pixel-size, millimetres (PHYSICAL); descriptors are dimensionless.
COLUMNS = ["image", "grain", "x_px", "y_px", "area_px2", "r0_px", "star_shaped", "elongation", "irregularity",
           "roughness"] + [f"D{n}" for n in range(2, N_MAX + 1)]
PHYSICAL = ["x_mm", "y_mm", "area_mm2", "r0_mm"]


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

    from ..io import atomic_write, csv_text

    if threshold is not None and not math.isfinite(threshold):
        raise click.BadParameter(f"must be a finite grey level, got {threshold}", param_hint="'--threshold'")
    if pixel_size is not None and not math.isfinite(pixel_size):
        raise click.BadParameter(f"must be a finite number of µm per pixel, got {pixel_size}", param_hint="'--pixel-size'")
    if csv_path is not None:
        output_file(csv_path, overwrite=overwrite, option="--csv", suffixes=(".csv",))
    _check_rays(rays)
    all_rows = []
    border = small = bad = 0
    failed: list[str] = []
    for path in images:
        try:
            rows, scan = descriptor_rows(path, min_area=min_area, threshold=threshold,
                                         foreground=foreground, rays=rays, pixel_size=pixel_size)
        except ValueError as exc:
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
    text = csv_text(all_rows, COLUMNS[:2] + (PHYSICAL if pixel_size is not None else []) + COLUMNS[2:])
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


#: memory one ray costs while a grain's radii are cast (bytes; 1e8 rays held 5.9 GB)
RAY_BYTES = 64
#: largest memory the rays of one grain may take
RAY_MEMORY = 2 * 1024**3


def _check_rays(rays: int) -> None:
    """Refuse --rays that would not fit in memory (estimate first)."""
    need = rays * RAY_BYTES
    if need > RAY_MEMORY:
        raise click.BadParameter(
            f"{rays} rays need about {need / 1024**3:.1f} GiB per grain (limit {RAY_MEMORY / 1024**3:.0f} GiB); "
            f"use at most {RAY_MEMORY // RAY_BYTES} (the descriptors need only {2 * N_MAX + 2})",
            param_hint="'--rays'")
