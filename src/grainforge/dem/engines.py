"""Dispatch: engine name -> deck writer."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError

__all__ = ["write_deck"]


def write_deck(engine: str, templates: Sequence, out: str | Path, *, overwrite: bool = False,
               rolling_friction: float = 0.0) -> list[Path]:
    """Write the ``engine`` deck (``"yade"``, ``"liggghts"``, ``"lammps"``) of ``templates`` into ``out``.

    LAMMPS: templates that are all ``"polyhedron"`` take the body deck (:mod:`grainforge.dem.lammps_body`),
    clumps the rigid-body deck (:mod:`grainforge.dem.lammps`).

    Parameters
    ----------
    engine : {"yade", "liggghts", "lammps"}
        The engine the deck is for.
    templates : sequence of GrainTemplate
        The grains (SI units), each placed ``count`` times by the example pour; shapes the engine
        supports (:data:`grainforge.dem.SUPPORTED`).
    out : str or path
        The deck's folder (created if missing).
    overwrite : bool
        Replace existing files (otherwise an existing file is refused before anything is written).
    rolling_friction : float
        Rolling resistance μ_r of the contacts, written with the engine's pour settings (Yade and LIGGGHTS
        clumps); 0 (the default) writes no rolling resistance: the deck as without it.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        For an unknown engine, a template shape the engine does not support, or rolling resistance where
        it is not written (LAMMPS, shapes other than clumps).
    FileExistsError
        If a file of the deck exists and ``overwrite`` is false.
    """
    from . import SUPPORTED

    if engine not in SUPPORTED:
        raise InputError(f"engine must be one of {', '.join(SUPPORTED)}, got {engine!r}")
    for t in templates:
        if t.shape not in SUPPORTED[engine]:
            raise InputError(f"{engine} does not support shape {t.shape!r}")
    if rolling_friction > 0:
        if engine == "lammps" or any(t.shape != "clump" for t in templates):
            raise InputError("rolling resistance is written for clumps in Yade and LIGGGHTS decks only")
        if engine == "yade":
            from . import yade as engine_deck
        else:
            from . import liggghts as engine_deck
        settings = {**engine_deck.pour_settings(), "rolling_friction": rolling_friction}
        return engine_deck.write_deck(templates, out, overwrite=overwrite, settings=settings)
    if engine == "yade":
        from .yade import write_deck as w
    elif engine == "liggghts":
        from .liggghts import write_deck as w
    elif templates and all(t.shape == "polyhedron" for t in templates):
        from .lammps_body import write_deck as w
    else:
        from .lammps import write_deck as w
    return w(templates, out, overwrite=overwrite)
