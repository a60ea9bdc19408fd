"""Dispatch: engine name -> deck writer."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

__all__ = ["write_deck"]


def write_deck(engine: str, templates: Sequence, out: str | Path, *, overwrite: bool = False) -> list[Path]:
    """Write the ``engine`` deck (``"yade"``, ``"liggghts"``, ``"lammps"``) of ``templates`` into ``out``."""
    from . import SUPPORTED

    if engine not in SUPPORTED:
        raise ValueError(f"engine must be one of {', '.join(SUPPORTED)}, got {engine!r}")
    for t in templates:
        if t.shape not in SUPPORTED[engine]:
            raise ValueError(f"{engine} does not support shape {t.shape!r}")
    if engine == "yade":
        from .yade import write_deck as w
    elif engine == "liggghts":
        from .liggghts import write_deck as w
    elif templates and all(t.shape == "polyhedron" for t in templates):
        from .lammps_body import write_deck as w
    else:
        from .lammps import write_deck as w
    return w(templates, out, overwrite=overwrite)
