"""``grainforge scan IMAGE``: the Sand-Atlas descriptors of every grain of a μCT scan (a 3D image)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from ..errors import InputError
from .analyse import table_text
from .help_style import option
from .options import FiniteFloatRange, overwrite_option, voxel_size_flag, voxel_size_options, workers_option
from .paths import OutPath, output_dir, output_file

#: the terminal table
TABLE = (
    ("label", "label", "{}"), ("voxels", "voxels", "{}"), ("flags", "flags", "{}"),
    ("equivalent_diameter", "d_eq_um", "{:.4g}"), ("voxels_across", "vox/d", "{:.3g}"),
    ("sphericity", "a_sph", "{:.3f}"), ("convexity", "a_conv", "{:.3f}"), ("flatness", "a_flat", "{:.3f}"),
    ("elongation", "a_elong", "{:.3f}"), ("opening_fraction", "a_open", "{:.4f}"),
    ("centroid_x", "x_um", "{:.5g}"), ("centroid_y", "y_um", "{:.5g}"), ("centroid_z", "z_um", "{:.5g}"),
)
#: mesh file of a grain
MESH_NAME = "grain-{:06d}.stl"


@click.command()
@click.argument("image", type=click.Path(path_type=Path))
@voxel_size_options("um", "Voxel edge in µm (default: from the TIFF's metadata, where it says).",
                    name="voxel_size_um")
@option("--raw-shape", type=click.IntRange(min=1), nargs=3, default=None, metavar="Z Y X",
        help="IMAGE is raw binary (no header, C order) of this shape.")
@option("--raw-dtype", default=None, metavar="DTYPE",
        help="The raw image's NumPy dtype (uint8, uint16, uint32, <u2 for little-endian ...; default uint16).")
@option("--atlas-csv", type=OutPath(dir_okay=False), default=None,
        help="Write the measured grains as a Sand Atlas table that `grainforge fit` reads (µm), with each "
             "grain's opening fraction, voxels, centroid and border flag.")
@option("--segment", is_flag=True,
        help="IMAGE is binary (non-zero is grain): split touching grains by a distance-transform watershed "
             "first.")
@option("--ignore-labels", is_flag=True,
        help="With --segment: segment an image that holds several non-zero values (already labelled) as "
             "binary, every non-zero voxel grain; without it such an image is refused.")
@option("--marker-distance", type=FiniteFloatRange(min=0, min_open=True), default=None, show_default="0.4",
        help="With --segment: least distance between two grains' markers, as a fraction of the typical "
             "grain diameter; larger merges more, smaller splits more.")
@option("--marker-depth", type=FiniteFloatRange(min=0), default=None, show_default="0.08",
        help="With --segment: how far a distance-map maximum must rise above its saddle to seed a grain, "
             "as a fraction of the typical grain diameter; larger ignores more shallow maxima.")
@option("--labels-out", type=OutPath(dir_okay=False), default=None,
        help="With --segment: write the labels (.npy, .tif or .tiff).")
@option("--meshes", "meshes", type=OutPath(file_okay=False), default=None,
        help="Write each measured grain as a closed one-body STL in mm, at its place in the scan, into "
             "this folder (grain-LABEL.stl).")
@option("--min-voxels", type=click.IntRange(min=1), default=66, show_default=True,
        help="Labels of fewer voxels are counted, not measured (66: a ball 5 voxels across).")
@option("--keep-border", is_flag=True,
        help="Also measure grains that touch the image's faces (flagged `border`; left out by default).")
@option("--sphericity-convention", "convention", type=click.Choice(["atlas", "whole"]), default="atlas",
        show_default=True, help="True sphericity as the Sand Atlas computed it or on the whole grain "
                                "(as `analyse`).")
@overwrite_option("Replace existing outputs.")
@workers_option("Processes measuring grains; the rows do not depend on it.", default_text="one per CPU")
def scan(image, voxel_size_um, raw_shape, raw_dtype, atlas_csv, segment, ignore_labels, marker_distance, marker_depth,
         labels_out, meshes, min_voxels, keep_border, convention, overwrite, workers):
    """Sand-Atlas descriptors of every grain of a 3D image IMAGE (a μCT scan).

    IMAGE is a labelled volume (one integer per grain, 0 the void) or, with
    --segment, a binary one: a multi-page TIFF, a folder of TIFF slices, a
    .npy array, or raw binary (--raw-shape, --raw-dtype).  Each grain is cut
    out of the image and measured as `analyse --voxel-size-um` measures a
    mesh's voxel image; the image is read slab by slab, never whole (but
    for --segment).  Grains touching the image's faces and labels under
    --min-voxels are counted and left out.  The table goes to stdout;
    --atlas-csv writes the table `grainforge fit` reads.  See
    docs/guide/scan.md.
    """
    import numpy as np

    from ..analysis import scan as sc
    from ..io.outputs import OutputSet
    from ..runtime.estimate import TooLargeError, check_memory
    from ..runtime.workers import default_workers
    from .progress import progress_bar
    from .work import preload, say_estimate

    marker_distance, marker_depth = _check_options(image, segment, marker_distance, marker_depth, labels_out,
                                                   atlas_csv, meshes, voxel_size_um, overwrite, ignore_labels)
    volume, voxel_size_um = _open_image(image, raw_shape, raw_dtype, voxel_size_um)
    total = int(np.prod(volume.shape, dtype=np.int64))
    preload(["scipy.ndimage", "skimage.measure", "skimage.segmentation", "skimage.feature", "skimage.morphology",
             "trimesh"])
    if segment:
        volume = _segment_image(volume, image, marker_distance, marker_depth, ignore_labels)
    Z = volume.shape[0]
    slabs = progress_bar(total=-(-Z // sc._slab_size(volume)), desc="boxes", unit="slab")
    boxes = sc.label_boxes(volume, progress=slabs)
    problem = sc.image_problem(boxes, total, segmented=segment, name=str(image))
    if problem:
        raise click.UsageError(problem)
    todo = [b for b in boxes if b.voxels >= min_voxels and (keep_border or not b.touches(volume.shape))]
    n_small = sum(1 for b in boxes if b.voxels < min_voxels)
    n_border = sum(1 for b in boxes if b.voxels >= min_voxels and b.touches(volume.shape))
    n_workers = max(1, min(default_workers(workers), len(todo)))
    if not todo:
        raise click.UsageError(f"{image}: no grain to measure among {len(boxes)} label(s): {n_border} touch the "
                               f"image's faces (--keep-border measures them), {n_small} are under --min-voxels "
                               f"{min_voxels}")
    try:
        check_memory(sc.scan_memory(boxes, volume.shape, itemsize=volume.dtype.itemsize, min_voxels=min_voxels,
                                    border=keep_border, workers=n_workers), what="measuring the largest grain",
                     option="--workers, or the image (its largest label's box is too large)")
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    say_estimate(sc.scan_seconds(todo, n_workers))

    h_um = float(voxel_size_um)
    outputs = OutputSet()
    try:
        stage = outputs.mesh_stage(Path(meshes), overwrite) if meshes is not None else None
        bar = progress_bar(total=len(boxes), desc="grains", unit="grain")
        rows, bad_meshes, pieces, thin = sc.measure_scan(
            volume, boxes, voxel_size_um=h_um, min_voxels=min_voxels, border=keep_border, convention=convention,
            workers=n_workers, mesh_folder=stage, mesh_name=MESH_NAME, progress=bar)
        if atlas_csv is not None:
            from ..fit.sand import scan_sand_text

            outputs.temp(Path(atlas_csv)).write_text(scan_sand_text(rows, h_um), encoding="utf-8", newline="")
        if labels_out is not None:
            from ..io.volume import write_labels

            write_labels(outputs.temp(Path(labels_out)), volume.whole(), voxel_size_um=h_um,
                         fmt=Path(labels_out).suffix)
        outputs.commit()
    finally:
        outputs.discard()
    _report(rows, boxes, n_border, n_small, thin, keep_border, min_voxels, atlas_csv, labels_out, meshes,
            bad_meshes, pieces)


def _check_options(image, segment, marker_distance, marker_depth, labels_out, atlas_csv, meshes, voxel_size_um,
                   overwrite, ignore_labels=False):
    """Every option checked before the image is read; the marker settings with their defaults."""
    from ..analysis import scan as sc
    from ..io.volume import LABEL_SUFFIXES

    if not segment:
        for name, given in (("--marker-distance", marker_distance), ("--marker-depth", marker_depth),
                            ("--labels-out", labels_out), ("--ignore-labels", ignore_labels or None)):
            if given is not None:
                raise click.UsageError(f"{name} needs --segment (the labels of a labelled image are its own)")
    marker_distance = sc.MARKER_DISTANCE if marker_distance is None else marker_distance
    marker_depth = sc.MARKER_DEPTH if marker_depth is None else marker_depth
    if voxel_size_um is not None and not math.isfinite(voxel_size_um):
        raise click.BadParameter(f"must be a finite size, got {voxel_size_um}", param_hint=f"'{voxel_size_flag()}'")
    if not math.isfinite(marker_distance):
        raise click.BadParameter(f"must be finite, got {marker_distance}", param_hint="'--marker-distance'")
    if not math.isfinite(marker_depth):
        raise click.BadParameter(f"must be finite, got {marker_depth}", param_hint="'--marker-depth'")
    if str(image).strip() == "":
        raise click.BadParameter("an empty path", param_hint="IMAGE")
    outs = [p for p in (atlas_csv, labels_out) if p is not None]
    if len({Path(p).resolve() for p in outs}) < len(outs):
        raise click.UsageError("--atlas-csv and --labels-out must be different files")
    if atlas_csv is not None:
        output_file(atlas_csv, overwrite=overwrite, option="--atlas-csv", suffixes=(".csv",))
    if labels_out is not None:
        output_file(labels_out, overwrite=overwrite, option="--labels-out", suffixes=LABEL_SUFFIXES)
    if meshes is not None:
        output_dir(meshes, overwrite=None, option="--meshes")
        if not overwrite and Path(meshes).is_dir() and any(Path(meshes).glob("grain-*.stl")):
            raise click.UsageError(f"{meshes} holds grain meshes; use --overwrite")
    return marker_distance, marker_depth


def _open_image(image, raw_shape, raw_dtype, voxel_size_um):
    """The image and its voxel size (given, or from the file's metadata)."""
    from ..analysis import scan as sc
    from ..io.volume import open_volume
    from ..runtime.estimate import TooLargeError

    try:
        volume = open_volume(image, raw_shape=raw_shape, raw_dtype=raw_dtype)
        if voxel_size_um is None:
            voxel_size_um = volume.voxel_size_um
            if voxel_size_um is None:
                raise click.UsageError(f"{image}: no voxel size in the file: give --voxel-size-um (or "
                                       "--voxel-size-mm)")
            click.echo(f"voxel size from {image}'s metadata: {voxel_size_um:g} µm", err=True)
        sc.check_labels(volume.dtype, str(image))
    except TooLargeError as exc:
        raise click.UsageError(str(exc)) from None
    return volume, voxel_size_um


def _segment_image(volume, image, marker_distance, marker_depth, ignore_labels=False):
    """A binary image split into labelled grains (:func:`grainforge.analysis.scan.segment_volume`)."""
    from ..analysis import scan as sc

    try:
        volume, seg_info = sc.segment_volume(volume, marker_distance=marker_distance, marker_depth=marker_depth,
                                             ignore_labels=ignore_labels, name=str(image))
    except InputError as exc:
        raise click.UsageError(str(exc)) from None
    click.echo(f"segmented: {seg_info['grains']} grain(s) from {seg_info['markers']} marker(s) (typical "
               f"diameter {seg_info['typical_diameter']:.3g} voxels; markers at least {seg_info['min_distance']} "
               f"voxels apart and {seg_info['depth']:.2g} voxels deep)", err=True)
    return volume


def _report(rows, boxes, n_border, n_small, thin, keep_border, min_voxels, atlas_csv, labels_out, meshes,
            bad_meshes, pieces) -> None:
    """What was measured, left out and written, on stderr."""
    click.echo(table_text(rows, TABLE))
    parts = [f"{len(rows)} grain(s) measured of {len(boxes)} label(s)"]
    if n_border:
        parts.append(f"{n_border} touch the image's faces" + (" (measured, flagged border)" if keep_border
                                                              else " (left out; --keep-border measures them)"))
    if n_small:
        parts.append(f"{n_small} under {min_voxels} voxels (left out)")
    if thin:
        parts.append(f"{len(thin)} a voxel or so thin, without a surface at the Atlas's smoothing (left out: label "
                     + ", ".join(map(str, thin[:5])) + (" ..." if len(thin) > 5 else "") + ")")
    click.echo("; ".join(parts), err=True)
    if atlas_csv is not None:
        click.echo(f"wrote {len(rows)} grain(s) to {atlas_csv} as a Sand Atlas table (µm)", err=True)
    if labels_out is not None:
        click.echo(f"wrote the labels to {labels_out}", err=True)
    if meshes is not None:
        click.echo(f"wrote {len(rows) - len(bad_meshes)} mesh(es) to {meshes}"
                   + (f"; {pieces} grain(s) in several pieces: their largest piece" if pieces else ""), err=True)
    if bad_meshes:
        click.echo(f"warning: {len(bad_meshes)} grain mesh(es) not written, not a valid solid: "
                   + ", ".join(bad_meshes[:5]) + (" ..." if len(bad_meshes) > 5 else ""), err=True)
