"""What a misnamed file is, from its first bytes (for the messages of the mesh readers)."""

from __future__ import annotations

__all__ = ["what_is"]

#: first bytes of common non-mesh files, to say what a misnamed file is
_MAGIC = (
    (b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
    (b"%PDF", "a PDF document"), (b"PK\x03\x04", "a zip archive"), (b"PK\x05\x06", "an empty zip archive"),
    (b"\x1f\x8b", "a gzip archive"),
    (b"II*\x00", "a TIFF image; a 3D scan's labels or grains are measured by `grainforge scan`"),
    (b"MM\x00*", "a TIFF image; a 3D scan's labels or grains are measured by `grainforge scan`"),
    (b"\x93NUMPY", "a NumPy array; a 3D scan's labels or grains are measured by `grainforge scan`"),
)


def what_is(head: bytes) -> str | None:
    """The kind of file ``head`` (its first bytes) starts, e.g. ``"a PNG image"``; ``None`` if not known.

    Parameters
    ----------
    head : bytes
        The file's first bytes (16 suffice).

    Returns
    -------
    str or None
        A phrase for messages (``"a PNG image"``), or ``None`` if no known signature matches.

    Examples
    --------
    >>> what_is(b"%PDF-1.7")
    'a PDF document'
    """
    for magic, name in _MAGIC:
        if head.startswith(magic):
            return name
    return None
