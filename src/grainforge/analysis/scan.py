"""A μCT scan's grains: the Sand-Atlas descriptors of every label of a 3D image, its segmentation and meshes.

A lab's scan is a labelled volume (one integer per grain, 0 the void) or a binary one.  This module measures
it grain by grain with the one implementation of the Atlas's measures, :func:`~grainforge.analysis.atlas.
voxel_descriptors` and :func:`~grainforge.analysis.atlas.opening_fraction`, each on the grain's own cropped
binary mask:

1. **Boxes** (:func:`label_boxes`): one pass over the image, a slab of slices at a time, gives each label's
   bounding box (:func:`scipy.ndimage.find_objects` per slab, merged) and voxel count.
2. **Grains** (:func:`measure_labels`): a second pass, slab by slab in order of the boxes' first slice,
   keeps only the slices the current grains span; each grain is cut out of them (``crop == label``) and
   measured.  Memory is one grain's box (and its measurement) plus the slices of the tallest box, never the
   image.
3. A grain whose box touches a face of the image is flagged ``border`` (part of it may lie outside the scan);
   a label of fewer voxels than a stated minimum is counted as ``small`` and not measured.

A binary image is split into grains first (:func:`segment`): the standard distance-transform watershed.

Axes are the image's ``(Z, Y, X)``; physical coordinates are ``x`` along the image's last axis, ``y`` its
middle one and ``z`` its slices, voxel centres at ``h·(index + ½)``.

Examples
--------
Two touching boxes of labels 1 and 2, and a label of 2 voxels:

>>> from grainforge.io.volume import Volume
>>> img = np.zeros((20, 20, 30), np.uint16)
>>> img[4:16, 4:16, 3:15] = 1
>>> img[5:15, 5:15, 15:26] = 2
>>> img[1, 1, 1:3] = 3
>>> boxes = label_boxes(Volume.from_array(img))
>>> [(b.label, b.voxels) for b in boxes]
[(1, 1728), (2, 1100), (3, 2)]
>>> rows = sorted(measure_labels(Volume.from_array(img), boxes, voxel_size=1.0, min_voxels=66), key=lambda r: r["label"])
>>> [(r["label"], r["status"]) for r in rows]
[(1, 'measured'), (2, 'measured'), (3, 'small')]
>>> round(rows[0]["convexity"], 3), round(rows[0]["centroid_x"], 2)
(1.0, 9.0)
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .atlas import OPENING_RADIUS, SIGMA, opening_fraction, voxel_descriptors

__all__ = ["LabelBox", "measure_scan", "scan_seconds", "label_boxes", "measure_labels", "measure_grain", "check_labels", "segment", "segment_volume",
           "image_problem", "grain_mesh",
           "compare_labels", "MIN_VOXELS", "MAX_LABEL", "SLAB_VOXELS", "SEGMENT_BYTES_PER_VOXEL",
           "MARKER_DISTANCE", "MARKER_DEPTH", "typical_diameter", "scan_memory", "MEASURE_BYTES_PER_CELL"]

#: labels of fewer voxels are counted, not measured: a ball of 66 voxels is 5 voxels across, the least at
#: which the Atlas descriptors measure shape (:data:`grainforge.analysis.atlas.MIN_VOXELS_ACROSS`)
MIN_VOXELS = 66
#: seconds per cell of a measured grain's box, and per grain (one core: 0.085 s for a grain 45 voxels across in
#: a box of 57³; benchmarks/bench_scan.py)
SECONDS_PER_CELL, SECONDS_PER_GRAIN = 4.5e-7, 0.01
#: largest label value read (bounding boxes are indexed by label): relabel sequentially above it
MAX_LABEL = 2**24
#: voxels read per slab of the first pass (its label count takes 8 bytes a voxel)
SLAB_VOXELS = 2**23
#: memory of one grain's measurement per cell of its box (:data:`grainforge.analysis.atlas.IMAGE_BYTES_PER_CELL`
#: and the crop and mask)
MEASURE_BYTES_PER_CELL = 90.0
#: memory of :func:`segment` per voxel of the image (scipy's feature transform behind the distance map, the
#: h-maxima reconstruction's float64 arrays, the local-maximum filter, the watershed's queue, markers and labels;
#: tracemalloc's peak: 138 bytes at 100³ and 114 at 190 × 190 × 115 voxels, on examples/scan/make_scan.py's image)
SEGMENT_BYTES_PER_VOXEL = 150.0
#: :func:`segment`'s default marker distance, a fraction of the typical grain diameter (:func:`typical_diameter`)
MARKER_DISTANCE = 0.4
#: :func:`segment`'s default marker depth, a fraction of the typical grain diameter: a maximum of the distance map
#: must rise this much above the saddle that joins it to a higher one to seed a grain of its own (2 voxels for
#: grains 24 voxels across: exact recovery of examples/scan/make_scan.py's 64 CRI grains, where 1 voxel
#: splits off 6 fragments of a few voxels at the contacts and a distance of 0.5 merges 2 pairs)
MARKER_DEPTH = 0.08


@dataclass(frozen=True)
class LabelBox:
    """One label's bounding box (``(z0, y0, x0)`` to ``(z1, y1, x1)``, ends excluded) and voxel count."""

    label: int
    lo: tuple[int, int, int]
    hi: tuple[int, int, int]
    voxels: int

    @property
    def cells(self) -> int:
        """Voxels of the box."""
        return int(np.prod(np.subtract(self.hi, self.lo), dtype=np.int64))

    def touches(self, shape) -> bool:
        """Whether the box reaches a face of an image of ``shape``.

        Parameters
        ----------
        shape : (3,) sequence of int
            The image's (Z, Y, X).

        Returns
        -------
        bool
        """
        return min(self.lo) == 0 or any(h == s for h, s in zip(self.hi, shape))


def check_labels(dtype, path: str = "the image") -> None:
    """Refuse an image whose values cannot be labels: floats (a greyscale or a probability map), complex.

    Parameters
    ----------
    dtype : numpy dtype or dtype-like
        The image's.
    path : str, default "the image"
        How the message names the image.

    Raises
    ------
    ValueError
        For a float, complex or non-numeric dtype.

    Examples
    --------
    >>> check_labels(np.dtype("float32"), "scan.tif")
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: scan.tif: a float32 image cannot hold labels (one integer per grain, 0 the void): threshold a greyscale image to a binary one first and give it with segment
    """
    dtype = np.dtype(dtype)
    if dtype.kind not in "biu":
        raise InputError(f"{path}: a {dtype.name} image cannot hold labels (one integer per grain, 0 the void): "
                         "threshold a greyscale image to a binary one first and give it with {segment}",
                         setting="segment")


def _slab_size(volume) -> int:
    return max(1, SLAB_VOXELS // max(1, volume.shape[1] * volume.shape[2]))


def label_boxes(volume, *, progress=None) -> list[LabelBox]:
    """Every label's bounding box and voxel count, read a slab at a time (:func:`scipy.ndimage.find_objects`).

    Parameters
    ----------
    volume : grainforge.io.volume.Volume
        A labelled image (integers, 0 the void).
    progress : callable, optional
        Wraps the iterable of slabs (a progress bar).

    Returns
    -------
    list of LabelBox
        In label order; labels absent from the image are absent.

    Raises
    ------
    ValueError
        Not integer labels, negative labels, labels beyond :data:`MAX_LABEL`.
    """
    from scipy import ndimage

    check_labels(volume.dtype, str(volume.path))
    Z = volume.shape[0]
    step = _slab_size(volume)
    lo = hi = counts = None
    top = 0
    starts = range(0, Z, step)
    for z0 in (progress(starts) if progress else starts):
        slab = volume.read(z0, min(Z, z0 + step))
        if slab.dtype == bool:
            slab = slab.view(np.uint8)
        if slab.dtype.kind == "i" and slab.size and slab.min() < 0:
            raise InputError(f"{volume.path}: negative values ({int(slab.min())}): labels are 0 (void) and positive "
                             "integers")
        m = int(slab.max()) if slab.size else 0
        if m > MAX_LABEL:
            raise InputError(f"{volume.path}: label {m} is beyond {MAX_LABEL}: number the labels 1, 2, 3, ... "
                             "(skimage.segmentation.relabel_sequential)")
        if m > top:  # grow the tables
            grow = m + 1 - (0 if counts is None else len(counts))
            if counts is None:
                counts = np.zeros(m + 1, np.int64)
                lo = np.full((m + 1, 3), np.iinfo(np.int64).max, np.int64)
                hi = np.full((m + 1, 3), -1, np.int64)
            else:
                counts = np.concatenate([counts, np.zeros(grow, np.int64)])
                lo = np.concatenate([lo, np.full((grow, 3), np.iinfo(np.int64).max, np.int64)])
                hi = np.concatenate([hi, np.full((grow, 3), -1, np.int64)])
            top = m
        if m == 0:
            continue
        counts[: m + 1] += np.bincount(slab.ravel(), minlength=m + 1)[: m + 1]
        if slab.dtype.itemsize > 4 or slab.dtype == np.uint32:
            slab = slab.astype(np.int64 if m > np.iinfo(np.int32).max else np.int32)
        for k, sl in enumerate(ndimage.find_objects(slab, max_label=m), start=1):
            if sl is None:
                continue
            a = (sl[0].start + z0, sl[1].start, sl[2].start)
            b = (sl[0].stop + z0, sl[1].stop, sl[2].stop)
            lo[k] = np.minimum(lo[k], a)
            hi[k] = np.maximum(hi[k], b)
    if counts is None:
        return []
    present = np.flatnonzero(counts[1:] > 0) + 1
    return [LabelBox(int(k), tuple(int(x) for x in lo[k]), tuple(int(x) for x in hi[k]), int(counts[k]))
            for k in present]


def measure_grain(mask: np.ndarray, voxel_size: float, *, convention: str = "atlas") -> dict[str, float]:
    """The Atlas descriptors of one grain's binary mask, as ``grainforge analyse`` measures a mesh's image.

    :func:`~grainforge.analysis.atlas.voxel_descriptors` and the opening fraction at a ball of
    :data:`~grainforge.analysis.atlas.OPENING_RADIUS` times the grain's equivalent diameter (here the voxel
    image's own, a scan having no mesh).

    Parameters
    ----------
    mask : (Z, Y, X) array_like of bool
        The grain's voxels.
    voxel_size : float
        Voxel edge, in the unit wanted for lengths.
    convention : {"atlas", "whole"}, default "atlas"
        True sphericity's convention (:func:`~grainforge.analysis.atlas.voxel_descriptors`).

    Returns
    -------
    dict of str to float
        :func:`~grainforge.analysis.atlas.voxel_descriptors`' values, ``voxel_size``, ``voxels_across`` and
        ``opening_fraction``.

    Examples
    --------
    >>> g = np.indices((31, 31, 31)) - 15
    >>> d = measure_grain((g ** 2).sum(0) <= 12 ** 2, 10.0)
    >>> round(d["equivalent_diameter"] / 10.0, 1), round(d["flatness"], 3), d["opening_fraction"] > 0.99
    (23.9, 1.0, True)
    """
    d = voxel_descriptors(mask, voxel_size, convention=convention)
    d["voxel_size"] = float(voxel_size)
    d["voxels_across"] = d["equivalent_diameter"] / voxel_size
    d["opening_fraction"] = opening_fraction(mask, OPENING_RADIUS * d["voxels_across"])
    return d


def _window(volume, boxes: list[LabelBox]) -> Iterator[tuple[LabelBox, np.ndarray]]:
    """Each box's crop of the image, boxes in order of their first slice; only the slices in use are held."""
    Z = volume.shape[0]
    step = _slab_size(volume)
    held: deque[np.ndarray] = deque()  # one slice each, slices base … base + len − 1
    base = 0
    for box in sorted(boxes, key=lambda b: (b.lo[0], b.label)):
        z0, z1 = box.lo[0], box.hi[0]
        while held and base < z0:
            held.popleft()
            base += 1
        if not held:
            base = z0
        while base + len(held) < z1:
            start = base + len(held)
            slab = volume.read(start, min(Z, max(z1, start + step)))
            held.extend(slab)
        crop = np.stack([held[z - base][box.lo[1]:box.hi[1], box.lo[2]:box.hi[2]] for z in range(z0, z1)])
        yield box, crop


def _measure_task(task) -> dict:
    """Measure one grain (a pool worker's task): its row, and its mesh when asked."""
    row, mask, lo, h, convention, mesh_h = task
    idx = [np.arange(n, dtype=np.float64) for n in mask.shape]
    pz, py, px = (mask.sum(axis=axes, dtype=np.int64) for axes in ((1, 2), (0, 2), (0, 1)))
    n = int(pz.sum())
    row = dict(row, voxels=n, status="measured",
               centroid_z=(float(pz @ idx[0]) / n + lo[0] + 0.5) * h,
               centroid_y=(float(py @ idx[1]) / n + lo[1] + 0.5) * h,
               centroid_x=(float(px @ idx[2]) / n + lo[2] + 0.5) * h)
    try:
        row.update(measure_grain(mask, h, convention=convention))
    except ValueError:  # no voxel of the smoothed image reaches 0.5: a grain a voxel or so thick has no surface
        row["status"] = "thin"
        return row
    if mesh_h is not None:
        from ..geometry.solid import solid_problems

        try:
            v, f, dropped = grain_mesh(mask, lo, mesh_h)
            row["mesh"] = (v, f, dropped, solid_problems(v, f, intersections=False))
        except ValueError as exc:  # too thin for a surface at level 0.5 once smoothed
            row["mesh"] = (None, None, 0, [str(exc)])
    return row


def measure_labels(volume, boxes: Iterable[LabelBox], *, voxel_size: float, min_voxels: int = MIN_VOXELS,
                   border: bool = False, convention: str = "atlas", workers: int = 1,
                   mesh_voxel_size: float | None = None) -> Iterator[dict]:
    """Measure each label of a labelled image, one grain's crop at a time (bounded memory).

    Parameters
    ----------
    volume : grainforge.io.volume.Volume
    boxes : iterable of LabelBox
        From :func:`label_boxes`.
    voxel_size : float
        Voxel edge, in the units wanted for lengths.
    min_voxels : int
        Labels of fewer voxels are not measured (``status`` ``"small"``).
    border : bool
        Also measure grains whose box touches the image's faces (else ``status`` ``"border"``, not measured).
    convention : {"atlas", "whole"}
        True sphericity's convention (:func:`~grainforge.analysis.atlas.voxel_descriptors`).
    workers : int
        Processes measuring grains (:func:`grainforge.runtime.workers.ordered_map`); this process reads the image.
    mesh_voxel_size : float, optional
        Also make each measured grain's mesh (:func:`grainforge.analysis.scan.grain_mesh`) at this voxel
        size: ``row["mesh"]`` is ``(vertices, faces, bodies dropped, solid problems)``.

    Yields
    ------
    dict
        Per label, the unmeasured first, then in order of the boxes' first slice: ``label``, ``voxels``,
        ``status`` (``"measured"``, ``"border"``, ``"small"``, or ``"thin"``: so thin — a voxel or so — that
        the Atlas's smoothed image has no surface, left unmeasured), ``border`` (bool) and, when measured,
        ``centroid_x``, ``centroid_y``, ``centroid_z`` (voxel centres at ``h·(index + ½)``) and
        :func:`measure_grain`'s values.
    """
    from ..runtime.workers import ordered_map

    h = float(voxel_size)
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"voxel size must be a positive number, got {voxel_size!r}")
    shape = volume.shape
    boxes = list(boxes)
    todo = [b for b in boxes if b.voxels >= min_voxels and (border or not b.touches(shape))]
    wanted = {b.label for b in todo}
    for b in sorted(boxes, key=lambda b: (b.lo[0], b.label)):
        if b.label not in wanted:
            yield {"label": b.label, "voxels": b.voxels, "border": b.touches(shape),
                   "status": "small" if b.voxels < min_voxels else "border"}

    def tasks():
        for box, crop in _window(volume, todo):
            yield ({"label": box.label, "border": box.touches(shape)}, crop == box.label, box.lo, h, convention,
                   mesh_voxel_size)

    yield from ordered_map(_measure_task, tasks(), workers=min(int(workers), max(1, len(todo))),
                           preload=["grainforge.analysis.scan"])


def scan_memory(boxes: Iterable[LabelBox], volume_shape, *, itemsize: int, min_voxels: int = MIN_VOXELS,
                border: bool = False, workers: int = 1) -> float:
    """Bytes :func:`measure_labels` needs at most: the largest measured box (in each worker, and a few queued),
    and the slices of the tallest.

    Parameters
    ----------
    boxes : iterable of LabelBox
        From :func:`label_boxes`.
    volume_shape : (3,) sequence of int
        The image's (Z, Y, X).
    itemsize : int
        Bytes per voxel of the image.
    min_voxels : int, default MIN_VOXELS
        As :func:`measure_labels`.
    border : bool, default False
        As :func:`measure_labels`.
    workers : int, default 1
        As :func:`measure_labels`.

    Returns
    -------
    float
        Bytes.

    Examples
    --------
    >>> scan_memory([LabelBox(1, (2, 2, 2), (12, 12, 12), 700)], (100, 100, 100), itemsize=2)
    2090000.0
    """
    shape = tuple(volume_shape)
    plane = shape[1] * shape[2] * itemsize
    cells = tall = 0
    for b in boxes:
        if b.voxels >= min_voxels and (border or not b.touches(shape)):
            cells = max(cells, b.cells)
            tall = max(tall, b.hi[0] - b.lo[0])
    slab = max(1, SLAB_VOXELS // max(1, shape[1] * shape[2]))
    busy = max(1, int(workers))
    queued = 3 * busy if busy > 1 else 0  # ordered_map's tasks in flight: a mask (1 byte a cell) each
    return float(cells * (MEASURE_BYTES_PER_CELL * busy + queued) + min(tall + slab, shape[0]) * plane)


# --------------------------------------------------------------------------------------------- segmentation
def typical_diameter(distance: np.ndarray, binary: np.ndarray) -> float:
    """The typical grain diameter of a binary image, in voxels: 8 × the mean distance of its voxels to the void.

    A ball of radius R has a mean distance to its surface of R/4 over its volume, so this is the diameter of
    balls whose voxels lie, on average, as deep as the image's.

    Parameters
    ----------
    distance : (Z, Y, X) ndarray of float
        Distance of each voxel to the void, in voxels (a Euclidean distance transform).
    binary : (Z, Y, X) ndarray of bool
        The grains' voxels.

    Returns
    -------
    float
        Voxels (0 for an image without grain voxels).

    Examples
    --------
    >>> from scipy import ndimage
    >>> g = np.indices((61, 61, 61)) - 30
    >>> ball = (g ** 2).sum(0) <= 25 ** 2
    >>> round(typical_diameter(ndimage.distance_transform_edt(ball), ball))
    52
    """
    vals = distance[binary]
    return 8.0 * float(vals.mean()) if vals.size else 0.0


def segment(binary: np.ndarray, *, marker_distance: float = MARKER_DISTANCE,
            marker_depth: float = MARKER_DEPTH) -> tuple[np.ndarray, dict]:
    """Split a binary image's touching grains: the distance-transform watershed.

    1. ``D`` = the Euclidean distance of each grain voxel to the void
       (:func:`scipy.ndimage.distance_transform_edt`).
    2. Markers: the maxima of ``D`` that rise at least ``marker_depth`` × the typical grain diameter ``d``
       (:func:`typical_diameter`) above the saddle joining them to a higher one (h-maxima,
       :func:`skimage.morphology.h_maxima`), at least ``marker_distance`` × ``d`` apart
       (:func:`skimage.feature.peak_local_max`).
    3. :func:`skimage.segmentation.watershed` of ``−D`` from the markers, inside the grains.  A connected piece
       of the image that got no marker becomes a grain of its own.

    Parameters
    ----------
    binary : (Z, Y, X) array_like
        Non-zero is grain.
    marker_distance : float
        Least distance between two grains' markers, as a fraction of the typical diameter (> 0).  Larger
        merges more (an elongated grain keeps one marker), smaller splits more.
    marker_depth : float
        Fraction of the typical diameter (≥ 0); larger ignores more of the shallow maxima that rough surfaces
        and the necks between grains make (each of which would split a fragment off a grain).

    Returns
    -------
    labels : (Z, Y, X) int32 ndarray
        1 … n, 0 the void.
    info : dict
        ``typical_diameter``, ``min_distance`` and ``depth`` (voxels), ``markers``, ``grains``.

    Examples
    --------
    Two balls of radius 10 that overlap by 2 voxels are two grains:

    >>> z, y, x = np.indices((30, 30, 50))
    >>> two = ((z - 15) ** 2 + (y - 15) ** 2 + (x - 14) ** 2 <= 100) | ((z - 15) ** 2 + (y - 15) ** 2 + (x - 32) ** 2 <= 100)
    >>> labels, info = segment(two)
    >>> info["grains"], int(labels[15, 15, 14]) != int(labels[15, 15, 32])
    (2, True)
    """
    from scipy import ndimage
    from skimage.feature import peak_local_max
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    if not (math.isfinite(marker_distance) and marker_distance > 0):
        raise InputError(f"marker distance must be a positive fraction of the typical grain size, got {marker_distance!r}")
    if not (math.isfinite(marker_depth) and marker_depth >= 0):
        raise InputError(f"marker depth must be a fraction of the typical grain size >= 0, got {marker_depth!r}")
    b = np.asarray(binary) != 0
    if not b.any():
        raise InputError("the binary image has no grain voxel")
    d = ndimage.distance_transform_edt(b).astype(np.float32)
    typical = typical_diameter(d, b)
    md = max(1, int(round(marker_distance * typical)))
    depth = marker_depth * typical
    if depth > 0:
        peaks_mask = h_maxima(d.astype(np.float64), depth).astype(bool)
        cand = np.where(peaks_mask, d, 0.0).astype(np.float32)
        del peaks_mask
    else:
        cand = d
    peaks = peak_local_max(cand, min_distance=md, threshold_abs=0.0, exclude_border=False)
    peaks = peaks[cand[tuple(peaks.T)] > 0] if len(peaks) else peaks
    del cand
    markers = np.zeros(b.shape, np.int32)
    markers[tuple(peaks.T)] = np.arange(1, len(peaks) + 1, dtype=np.int32)
    labels = watershed(-d, markers, mask=b).astype(np.int32)
    del d, markers
    left = b & (labels == 0)  # pieces without a marker
    if left.any():
        extra, n_extra = ndimage.label(left)
        labels[left] = extra[left] + len(peaks)
    n = int(labels.max())
    return labels, {"typical_diameter": typical, "min_distance": md, "depth": depth, "markers": int(len(peaks)),
                    "grains": n}


def segment_volume(volume, *, marker_distance: float = MARKER_DISTANCE, marker_depth: float = MARKER_DEPTH,
                   ignore_labels: bool = False, name: str = "the image"):
    """A binary 3-D image split into labelled grains (:func:`segment`), its memory estimated first.

    An image of several non-zero values (labelled already, or greyscale) is refused unless
    ``ignore_labels``: its labels would be lost.

    Parameters
    ----------
    volume : grainforge.io.volume.Volume
        The image; non-zero is grain.
    marker_distance, marker_depth : float
        As :func:`segment`.
    ignore_labels : bool
        Segment an image of several non-zero values as binary, every non-zero voxel grain.
    name : str
        The image as messages name it.

    Returns
    -------
    labels : grainforge.io.volume.Volume
        The grains' labels (uint16 when they fit, else int32), named ``name``.
    info : dict
        :func:`segment`'s.

    Raises
    ------
    ValueError
        An image without void or without grain, or already labelled (without ``ignore_labels``), one line
        naming ``name``; :class:`grainforge.runtime.estimate.TooLargeError` if segmenting it would not fit
        in memory.

    Examples
    --------
    >>> from grainforge.io.volume import Volume
    >>> z, y, x = np.indices((30, 30, 50))
    >>> two = ((z - 15) ** 2 + (y - 15) ** 2 + (x - 14) ** 2 <= 100) | ((z - 15) ** 2 + (y - 15) ** 2 + (x - 32) ** 2 <= 100)
    >>> labels, info = segment_volume(Volume.from_array(two.astype(np.uint8)))
    >>> info["grains"], labels.dtype.name
    (2, 'uint16')
    >>> segment_volume(Volume.from_array(two.astype(np.uint8) * (1 + (x > 23))), name="scan.npy")
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: scan.npy: already labelled (2 labels, 1–2): --segment takes a binary image (0 void, one value grain); drop --segment to measure its labels, or add --ignore-labels to segment its non-zero voxels anew (a greyscale image: threshold it first)
    """
    from ..io.volume import Volume
    from ..runtime.estimate import check_memory

    total = int(np.prod(volume.shape, dtype=np.int64))
    check_memory(total * (SEGMENT_BYTES_PER_VOXEL + volume.dtype.itemsize),
                 what=f"segmenting a {' x '.join(map(str, volume.shape))} image", option="the image's size "
                 "(segment sub-volumes)")
    whole = volume.whole()
    binary = whole != 0
    if not binary.any():
        raise InputError(f"{name}: no grain: every voxel is 0")
    if binary.all():
        raise InputError(f"{name}: every voxel is grain: no void, so no grains to tell apart")
    if not ignore_labels:
        first = whole.flat[int(np.argmax(binary))]
        if np.any(binary & (whole != first)):
            values = np.unique(whole[binary])
            raise InputError(
                f"{name}: already labelled ({len(values)} labels, {values[0]}–{values[-1]}): --segment takes a binary "
                "image (0 void, one value grain); drop --segment to measure its labels, or add --ignore-labels to "
                "segment its non-zero voxels anew (a greyscale image: threshold it first)")
    del whole
    labels, info = segment(binary, marker_distance=marker_distance, marker_depth=marker_depth)
    del binary
    if labels.max() < 2**16:
        labels = labels.astype(np.uint16)
    return Volume.from_array(labels, name), info


def image_problem(boxes: list[LabelBox], total: int, *, segmented: bool, name: str = "the image") -> str | None:
    """Why an image holds no grains to measure (empty, one label everywhere, one label: a binary image), or None.

    Parameters
    ----------
    boxes : list of LabelBox
        The image's labels (:func:`label_boxes`).
    total : int
        The image's voxels.
    segmented : bool
        The labels come from :func:`segment_volume` (one label is then one grain).
    name : str
        The image as the line names it.

    Returns
    -------
    str or None
        One line, or None for an image with grains to tell apart.

    Examples
    --------
    >>> image_problem([LabelBox(1, (0, 0, 0), (2, 2, 2), 8)], 8, segmented=False, name="a.npy")
    'a.npy: every voxel is label 1: no void, so no grains to tell apart'
    >>> image_problem([LabelBox(1, (0, 0, 0), (2, 2, 2), 8)], 64, segmented=True) is None
    True
    """
    if not boxes:
        return f"{name}: no grain: every voxel is 0"
    if len(boxes) == 1 and boxes[0].voxels == total:
        return f"{name}: every voxel is label {boxes[0].label}: no void, so no grains to tell apart"
    if len(boxes) == 1 and not segmented:
        return f"{name}: one label only ({boxes[0].label}): a binary image? add --segment to split its grains"
    return None


def compare_labels(truth: np.ndarray, found: np.ndarray, *, share: float = 0.5, min_voxels: int = 0) -> dict[str, int]:
    """How a segmentation recovers known grains, by their overlaps.

    A true grain is **found** when one segmented label holds more than ``share`` of its voxels and that label
    is more than ``share`` this grain; **split** when no label holds ``share`` of it but several hold part;
    **merged** when the label that holds most of it is mostly made of other grains too (it holds more than
    ``share`` of two or more true grains).  ``spurious`` counts segmented labels of at least ``min_voxels``
    voxels that hold no true grain's majority and are not mostly one true grain (smaller ones are the
    ``small`` labels :func:`measure_labels` counts apart).

    Parameters
    ----------
    truth : array_like of int
        Known labels (0 the void).
    found : array_like of int
        Segmented labels, same shape.
    share : float, default 0.5
        The majority that counts as holding a grain.
    min_voxels : int, default 0
        Smallest segmented label counted as ``spurious``.

    Returns
    -------
    dict of str to int
        ``truth``, ``segmented``, ``found``, ``merged``, ``split``, ``missed``, ``spurious``.

    Examples
    --------
    >>> t = np.array([[[1, 1, 2, 2, 3, 3]]])
    >>> compare_labels(t, np.array([[[1, 1, 2, 2, 2, 2]]]))
    {'truth': 3, 'segmented': 2, 'found': 1, 'merged': 2, 'split': 0, 'missed': 0, 'spurious': 0}
    """
    t = np.asarray(truth).ravel().astype(np.int64)
    f = np.asarray(found).ravel().astype(np.int64)
    both = (t > 0) & (f > 0)
    pairs, overlap = np.unique(np.stack([t[both], f[both]]), axis=1, return_counts=True)
    t_size = np.bincount(t[t > 0])
    f_size = np.bincount(f[f > 0])
    true_ids = np.flatnonzero(t_size)
    found_ids = np.flatnonzero(f_size)
    holds = {}  # found label -> true grains it holds more than `share` of
    for (a, c), k in zip(pairs.T, overlap):
        if k > share * t_size[a]:
            holds.setdefault(int(c), []).append(int(a))
    out = {"truth": len(true_ids), "segmented": len(found_ids), "found": 0, "merged": 0, "split": 0, "missed": 0,
           "spurious": 0}
    best = {}
    for (a, c), k in zip(pairs.T, overlap):
        if k > best.get(int(a), (0, 0))[1]:
            best[int(a)] = (int(c), int(k))
    for a in true_ids:
        if a not in best:
            out["missed"] += 1
            continue
        c, k = best[a]
        if k > share * t_size[a]:
            if len(holds.get(c, [])) > 1:
                out["merged"] += 1
            elif k > share * f_size[c]:
                out["found"] += 1
            else:
                out["merged"] += 1
        else:
            out["split"] += 1
    majority = {}
    for (a, c), k in zip(pairs.T, overlap):
        if k > share * f_size[c]:
            majority[int(c)] = int(a)
    out["spurious"] = int(sum(1 for c in found_ids if int(c) not in majority and int(c) not in holds
                              and f_size[c] >= min_voxels))
    return out


# -------------------------------------------------------------------------------------------------- meshes
def grain_mesh(mask: np.ndarray, lo=(0, 0, 0), voxel_size: float = 1.0, *,
               sigma: float = SIGMA) -> tuple[np.ndarray, np.ndarray, int]:
    """A closed one-body triangle mesh of a grain's mask, in physical coordinates.

    The mask is padded with two empty voxels a side, smoothed by a Gaussian of ``sigma`` voxels
    (:func:`scipy.ndimage.gaussian_filter`, the Atlas's 0.75 by default) and its level-0.5 surface taken by
    marching cubes (:func:`skimage.measure.marching_cubes`); vertices go to ``x, y, z`` = the image's last,
    middle and first axes, voxel centres at ``voxel_size·(index + ½)`` with ``lo`` the mask's first voxel in the
    image.  Where the surface has several bodies (a label in several pieces), the largest by volume is kept.

    Parameters
    ----------
    mask : (Z, Y, X) array_like of bool
        The grain's voxels (a crop of the image).
    lo : (3,) sequence of int, default (0, 0, 0)
        The crop's first voxel in the image, (z, y, x).
    voxel_size : float, default 1.0
        Voxel edge, in the unit wanted for the mesh.
    sigma : float, default SIGMA
        Gaussian smoothing, voxels (0: none).

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
        Outward-oriented.
    dropped : int
        Bodies left out (0 for a grain in one piece).

    Raises
    ------
    ValueError
        If the smoothed mask has no surface.

    Examples
    --------
    >>> from grainforge.geometry.solid import solid_problems, signed_volume
    >>> g = np.indices((21, 21, 21)) - 10
    >>> v, f, dropped = grain_mesh((g ** 2).sum(0) <= 8 ** 2, voxel_size=0.01)
    >>> solid_problems(v, f, intersections=False), dropped
    ([], 0)
    >>> round(signed_volume(v, f) / (4 / 3 * math.pi * 0.08 ** 3), 2)  # smoothing rounds in convex parts a little
    0.95
    """
    from scipy.ndimage import gaussian_filter
    from skimage.measure import marching_cubes

    from ..geometry.solid import signed_volume, split_bodies

    pad = 2
    m = np.pad(np.asarray(mask, dtype=np.float32), pad)
    smooth = gaussian_filter(m, sigma, mode="constant") if sigma > 0 else m
    verts, faces, _, _ = marching_cubes(smooth, level=0.5, allow_degenerate=False)
    bodies = split_bodies(verts.astype(np.float64), faces.astype(np.int64))
    if not bodies:
        raise InputError("the grain's surface is empty")
    vols = [abs(signed_volume(v, f)) for v, f in bodies]
    v, f = bodies[int(np.argmax(vols))]
    xyz = (v[:, ::-1] - pad + np.asarray(lo, np.float64)[::-1] + 0.5) * float(voxel_size)
    f = f[:, ::-1].copy()  # the axes' reversal mirrors: reverse the faces to keep them outward
    if signed_volume(xyz, f) < 0:
        f = f[:, ::-1].copy()
    return xyz, f, len(bodies) - 1


def scan_seconds(boxes: Iterable[LabelBox], workers: int = 1) -> float:
    """Estimated seconds to measure ``boxes`` on ``workers`` processes (:data:`SECONDS_PER_CELL`, :data:`SECONDS_PER_GRAIN`).

    Parameters
    ----------
    boxes : iterable of LabelBox
        The grains to measure.
    workers : int
        Processes measuring them.

    Returns
    -------
    float
        Seconds of wall time.
    """
    boxes = list(boxes)
    return (sum(b.cells for b in boxes) * SECONDS_PER_CELL + len(boxes) * SECONDS_PER_GRAIN) / max(1, workers)


def measure_scan(volume, boxes: list[LabelBox], *, voxel_size_um: float, min_voxels: int = MIN_VOXELS,
                 border: bool = False, convention: str = "atlas", workers: int = 1, mesh_folder=None,
                 mesh_name: str = "grain-{:06d}.stl", progress=None) -> tuple[list[dict], list[str], int, list[int]]:
    """Measure the grains of a scan (:func:`measure_labels`), writing each one's mesh into ``mesh_folder``.

    Parameters
    ----------
    volume, boxes
        The image and its labels' boxes (:func:`label_boxes`).
    voxel_size_um : float
        Voxel edge in µm.
    min_voxels, border, convention, workers
        As :func:`measure_labels`.
    mesh_folder : path-like, optional
        Where each measured grain's closed one-body STL (mm, at its place in the scan) is written as
        ``mesh_name.format(label)``; a grain whose mesh is not a valid solid is not written and is named.
    mesh_name : str, default "grain-{:06d}.stl"
        The meshes' file names, formatted with the label.
    progress : callable, optional
        Wraps the iterator of grains (a progress bar).

    Returns
    -------
    rows : list of dict
        The measured grains, sorted by label, each with a ``flags`` cell.
    bad_meshes : list of str
        Grains whose mesh was not written, and why.
    pieces : int
        Grains in several pieces (their largest piece written).
    thin : list of int
        Labels a voxel or so thin, without a surface at the Atlas's smoothing (left out).
    """
    from pathlib import Path

    rows: list[dict] = []
    bad_meshes: list[str] = []
    thin: list[int] = []
    pieces = 0
    stage = None if mesh_folder is None else Path(mesh_folder)
    found = measure_labels(volume, boxes, voxel_size=voxel_size_um, min_voxels=min_voxels, border=border,
                           convention=convention, workers=workers,
                           mesh_voxel_size=None if stage is None else voxel_size_um / 1000.0)
    for row in (progress or (lambda it: it))(found):
        if row["status"] == "thin":
            thin.append(row["label"])
        if row["status"] != "measured":
            continue
        mesh = row.pop("mesh", None)
        if mesh is not None:
            v, f, dropped, problems = mesh
            pieces += bool(dropped)
            if problems:
                bad_meshes.append(f"label {row['label']}: {'; '.join(problems)}")
            else:
                import trimesh

                from ..io import write_mesh

                write_mesh(trimesh.Trimesh(v, f, process=False), stage / mesh_name.format(row["label"]))
        row["flags"] = "border" if row["border"] else ""
        rows.append(row)
    rows.sort(key=lambda r: r["label"])
    return rows, bad_meshes, pieces, thin
