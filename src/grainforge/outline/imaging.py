"""Grain images: reading, thresholding, the grain mask, and drawing contours back into an image.

The pixel side of :mod:`grainforge.outline.contours`: a grey or colour image is read
(:func:`load_image`), thresholded (Otsu's threshold, :func:`otsu_threshold`)
into a mask of grain pixels (:func:`grain_masks`); the contours module turns
masks into :class:`~grainforge.outline.contours.Contour` objects
(:func:`~grainforge.outline.contours.mask_contour`, :func:`~grainforge.outline.contours.scan_image`).
:func:`draw_contours` is the inverse: it rasterises contours (anything with a
``points()`` method), for tests and figures. Nothing here knows a contour's
polar form.

Examples
--------
>>> import numpy as np
>>> from grainforge.outline.contours import Contour, scan_image
>>> img = draw_contours((128, 128), [(Contour(np.ones(64)), (64, 64), 40)])
>>> scan = scan_image(img)
>>> len(scan.contours), round(scan.contours[0].scale)
(1, 40)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import FileFormatError, InputError

__all__ = ["load_image", "otsu_threshold", "grain_masks", "draw_contours"]


def load_image(image) -> np.ndarray:
    """A grey-level float image from a path or an array.

    Parameters
    ----------
    image : str, Path or array_like
        An image file readable by Pillow (PNG, TIFF, JPEG ...; palette, alpha and colour modes are
        converted to grey), or a (H, W) grey / (H, W, C) colour array (the mean of its first three
        channels is taken).

    Returns
    -------
    (H, W) float64
        Grey levels in the source's range (0–255 for 8-bit files).

    Raises
    ------
    ValueError
        If the file is missing or unreadable, the array is empty, not 2-D once grey, smaller than
        3 pixels on a side, or holds non-finite values.

    Examples
    --------
    >>> load_image(np.dstack([np.full((4, 4), 30.0)] * 3)).shape
    (4, 4)
    """
    if isinstance(image, (str, Path)):
        path = Path(image)
        if not path.is_file():
            raise InputError(f"{path}: no such image file")
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                im.load()
                if im.mode in ("P", "PA", "LA", "RGBA", "RGB", "CMYK", "1"):
                    im = im.convert("L")
                arr = np.asarray(im, dtype=np.float64)
        except (UnidentifiedImageError, OSError, ValueError) as exc:
            raise FileFormatError(f"{path}: cannot read image ({exc})") from None
    else:
        arr = np.asarray(image, dtype=np.float64)
    if arr.ndim == 3:
        arr = arr[..., :3].mean(axis=2) if arr.shape[2] >= 3 else arr[..., 0]
    if arr.ndim != 2 or arr.size == 0 or min(arr.shape) < 3:
        raise InputError(f"image must be a non-empty 2D grey or colour image, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError("image holds non-finite values")
    return arr


def otsu_threshold(image: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold (maximum between-class variance) of a grey image.

    Pixels above the returned value form one class.  Integer-valued images
    are histogrammed per grey level; others in ``bins`` bins.  (Equivalent
    to ``skimage.filters.threshold_otsu``, without importing
    ``skimage.filters``, which costs about a second.)

    Parameters
    ----------
    image : array_like of float
        Grey levels, any shape.
    bins : int, default 256
        Histogram bins for images that are not integer-valued (or span 65536 levels or more).

    Returns
    -------
    float
        The threshold, a grey level (the bin centre); the single value of a uniform image.

    Examples
    --------
    >>> img = np.r_[np.full(50, 10.0), np.full(50, 200.0)]
    >>> 10 <= otsu_threshold(img) < 200
    True
    """
    a = np.asarray(image, dtype=np.float64).ravel()
    lo, hi = float(a.min()), float(a.max())
    if hi <= lo:
        return lo
    if np.array_equal(a, np.round(a)) and hi - lo < 65536:
        counts = np.bincount((a - lo).astype(np.int64)).astype(np.float64)
        centers = lo + np.arange(len(counts))
    else:
        counts, edges = np.histogram(a, bins=bins, range=(lo, hi))
        counts = counts.astype(np.float64)
        centers = (edges[:-1] + edges[1:]) / 2
    w1 = np.cumsum(counts)
    w2 = np.cumsum(counts[::-1])[::-1]
    m1 = np.cumsum(counts * centers) / np.maximum(w1, 1e-300)
    m2 = (np.cumsum((counts * centers)[::-1]) / np.maximum(np.cumsum(counts[::-1]), 1e-300))[::-1]
    between = w1[:-1] * w2[1:] * (m1[:-1] - m2[1:]) ** 2
    return float(centers[int(np.argmax(between))])


def grain_masks(image: np.ndarray, *, threshold: float | None = None, foreground: str = "auto") -> np.ndarray:
    """Boolean mask of grain pixels (threshold, then the chosen side).

    Parameters
    ----------
    image : (H, W) ndarray of float
        Grey image (:func:`load_image`).
    threshold : float, optional
        Grey level separating grain and background (default: :func:`otsu_threshold`).
    foreground : {"auto", "dark", "bright"}, default "auto"
        Which side is grain; ``"auto"`` takes the side covering fewer of the border pixels (grains lie
        on a background).

    Returns
    -------
    (H, W) bool
        True on grain pixels.

    Raises
    ------
    ValueError
        If the image is uniform (no threshold separates anything), or ``foreground`` is unknown.
    """
    if foreground not in ("auto", "dark", "bright"):
        raise InputError(f"foreground must be auto, dark or bright, got {foreground!r}")
    lo, hi = float(image.min()), float(image.max())
    if hi <= lo:
        raise InputError("image is uniform: it holds no grain")
    if threshold is None:
        threshold = otsu_threshold(image)
    bright = image > threshold
    if foreground == "bright":
        return bright
    if foreground == "dark":
        return ~bright
    border = np.concatenate([bright[0], bright[-1], bright[1:-1, 0], bright[1:-1, -1]])
    return ~bright if border.mean() > 0.5 else bright


def draw_contours(shape: tuple[int, int], items, *, background: int = 0, fill: int = 255) -> np.ndarray:
    """Rasterise contours into a grey image (the inverse of :func:`scan_image`).

    Parameters
    ----------
    shape : (rows, cols)
    items : iterable of (Contour, (x, y), radius)
        Each contour, its centre in pixels (x = column, y = row) and its mean
        radius in pixels.  Angles run counter-clockwise as displayed.
    background, fill : int
        Grey levels (0–255).

    Returns
    -------
    (rows, cols) uint8

    Examples
    --------
    >>> from grainforge.outline.contours import Contour
    >>> img = draw_contours((64, 64), [(Contour(np.ones(64)), (32, 32), 20)])
    >>> img.dtype.name, abs(float((img > 0).sum()) / (np.pi * 20**2) - 1) < 0.02
    ('uint8', True)
    """
    from skimage.draw import polygon

    img = np.full(shape, background, dtype=np.uint8)
    for contour, (x, y), radius in items:
        p = contour.points() * float(radius)
        rr, cc = polygon(y - p[:, 1], x + p[:, 0], shape=shape)
        img[rr, cc] = fill
    return img
