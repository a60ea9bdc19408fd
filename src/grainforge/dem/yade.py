"""Yade deck: clumps carrying the grain's exact mass, centre and inertia.

``write_deck(templates, out)`` writes, run from inside ``out`` with
``yade -n -x run.py``:

- ``<grain>.xyzr`` and ``<grain>.clump.vtk`` per grain (spheres, metres, centroid
  at the origin, the grain's own orientation);
- ``grains.json``: every template's mass (kg), volume, inertia (kg m²),
  principal axes, sphere file, count; and the scene settings;
- ``run.py``: a library part (read the templates, insert a grain with exact
  mass properties) followed by a scene (by default: pour the population into a
  box under gravity, write VTK to ``vtk/``, stop when settled, write
  ``results-yade.json``; the last line printed is ``SETTLED in N steps`` or
  ``NOT SETTLED after N steps (KE … > … J)``, the exit status 0 or 1).

Exact mass properties in Yade: a clump's mass, centre and inertia are those
of its members (``Clump::updateProperties``). The contact spheres get a
material of density 0; six extra point-like member spheres of groupMask 0
(no contacts), placed in pairs at ±a along the mesh's principal axes about the
mesh centroid, carry masses chosen so that the members' sum equals the mesh's
mass, centroid and inertia tensor exactly (their own tiny sphere inertia is
subtracted first). The clump then has the mesh's principal frame.

The scene is a Python text appended to the library part, so other virtual
tests (``grainforge simulate``) reuse the grain insertion: it may call
``load_deck()``, ``add_grain(template, position, rotation)``,
``kinetic_energy(ids)`` and ``grain_report(ids)``. Both parts are real Python
files shipped with grainforge, ``scripts/yade_library.py`` and
``scripts/yade_pour.py``, read by :func:`grainforge.dem.scripts.render` when a
deck is written (also as the module attributes ``LIBRARY`` and ``POUR_SCENE``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from .deck import (
    clump_vtk_text,
    fmt,
    grain_orientations,
    json_text,
    orientation_rows,
    settle_settings,
    template_record,
    updated_settings,
    write_files,
    xyzr_text,
)
from .scripts import render

# LIBRARY and POUR_SCENE: the texts of scripts/yade_library.py and scripts/yade_pour.py (module __getattr__)
__all__ = ["write_deck", "deck_files", "LIBRARY", "POUR_SCENE", "pour_settings"]  # noqa: F822


def __getattr__(name):
    # the scripts are package data, read when asked for (grainforge.dem.scripts)
    if name in _SCRIPTS:
        return render(_SCRIPTS[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: module attributes holding a script's text: ``LIBRARY`` (the grain library), ``POUR_SCENE``
_SCRIPTS = {"LIBRARY": "yade_library.py", "POUR_SCENE": "yade_pour.py"}


def pour_settings(**kw) -> dict:
    """Default settings of the pour scene (SI), updated with ``kw``.

    Parameters
    ----------
    **kw
        Settings to change: ``seed`` (int: the grains' orientations, drawn in Python by
        :func:`grainforge.dem.deck.grain_orientations`, and the seed of the pour scene's own shuffle of
        the grains in Yade's Python; default 0), ``young`` (Young's modulus of spheres and level sets, Pa),
        ``poisson`` (Poisson's ratio), ``friction_deg`` (contact friction angle, degrees), ``damping``
        (Yade's local damping, in [0, 1)), ``dt_safety`` (the time step as a share of the smallest grain's
        ``r_min sqrt(ρ / E)``), ``vtk_every`` (steps between VTK files), ``poly_young`` (the polyhedra's
        contact modulus, Pa), ``ls_nodes`` (surface nodes of a level set) and those of
        :func:`grainforge.dem.deck.settle_settings`.

    Returns
    -------
    dict
        Every setting, the defaults updated with ``kw`` (stored in ``grains.json["scene"]``).

    Raises
    ------
    ValueError
        If ``kw`` names an unknown setting.

    Examples
    --------
    >>> pour_settings(seed=3)["seed"]
    3
    """
    s = {"seed": 0, "young": 1e6, "poisson": 0.3, "friction_deg": 30.0, "damping": 0.7,
         "dt_safety": 0.3, **settle_settings(), "vtk_every": 5000, "poly_young": 1e9, "ls_nodes": 150}
    return updated_settings(s, kw, "scene settings")


def shape_files(t) -> dict:
    """``{relative path: text}`` of one template's contact geometry (metres, centroid at the origin).

    Clump: ``<grain>.xyzr`` and ``<grain>.clump.vtk``; polyhedron: ``<grain>.poly``
    (``x y z`` per hull vertex); level set: ``<grain>.levelset.json`` (the field's frame —
    the grain's principal frame, as a turn of the grain frame —, grid origin, spacing,
    node counts and the signed distances, x-major: index ``(i·ny + j)·nz + k``).
    """
    if t.shape == "clump":
        if t.clump is None:
            raise InputError(f"{t.name}: clump template without spheres")
        head = (f"grainforge clump of {t.source or t.name}: x y z r (m), centroid at the origin\n"
                f"spheres {t.clump.count}, coverage {t.clump.coverage:.4f}, spill {t.clump.spill:.4f}")
        return {f"{t.name}.xyzr": xyzr_text(t.clump.centres, t.clump.radii, header=head),
                f"{t.name}.clump.vtk": clump_vtk_text(t.clump.centres, t.clump.radii, f"grainforge clump {t.name}")}
    if t.shape == "polyhedron":
        head = (f"grainforge convex hull of {t.source or t.name}: x y z (m), grain centroid at the origin\n"
                f"vertices {len(t.polyhedron)}")
        lines = [f"# {h}" for h in head.splitlines()] + [" ".join(fmt(x) for x in row) for row in t.polyhedron]
        return {f"{t.name}.poly": "\n".join(lines) + "\n"}
    if t.shape == "levelset":
        ls = t.levelset
        from scipy.spatial.transform import Rotation

        rotvec = Rotation.from_matrix(t.props.axes).as_rotvec()
        angle = float(np.linalg.norm(rotvec))
        axis = (rotvec / angle).tolist() if angle > 0 else [1.0, 0.0, 0.0]
        rec = {"frame": "principal: x_grain = R x_local, R a turn by angle (rad) about axis",
               "axis": [float(x) for x in axis], "angle": angle,
               "origin": [float(x) for x in ls.grid.origin], "spacing": float(ls.grid.spacing),
               "shape": [int(n) for n in ls.grid.shape], "units": "m, signed distance negative inside",
               "distance": [float(x) for x in np.asarray(ls.distance, dtype=np.float64).reshape(-1)]}
        return {f"{t.name}.levelset.json": json.dumps(rec) + "\n"}
    raise InputError(f"{t.name}: unknown shape {t.shape!r}")


def deck_files(templates: Sequence, *, scene: str | None = None, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a Yade deck (nothing written).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Templates of one shape: ``"clump"``, ``"polyhedron"`` or ``"levelset"``.
    scene : str, optional
        Python text appended to the grain library ``scripts/yade_library.py``
        (default: the pour, ``render("yade_pour.py")``).
    settings : dict, optional
        Scene settings stored in ``grains.json["scene"]`` (default
        :func:`pour_settings`). Without ``orientations``, the scene gets those of
        :func:`grainforge.dem.deck.grain_orientations` for its ``seed`` (0 if none), one per grain placed.

    Returns
    -------
    dict of str to str
        Relative path -> text: the grains' shape files, ``grains.json`` and ``run.py``.

    Raises
    ------
    ValueError
        If the templates are of more than one shape, or a template lacks its representation.
    """
    files: dict[str, str] = {}
    records = []
    shapes = {t.shape for t in templates}
    if len(shapes) > 1:
        raise InputError(f"a Yade deck holds one grain shape; got {', '.join(sorted(shapes))}")
    for t in templates:
        files.update(shape_files(t))
        rec = template_record(t)
        if t.shape == "polyhedron":
            rec.update({"polyhedron": f"{t.name}.poly", "vertices": len(t.polyhedron), "r_min": 0.5 * t.d_eq})
        elif t.shape == "levelset":
            rec.update({"levelset": f"{t.name}.levelset.json", "r_min": 0.5 * t.d_eq})
        records.append(rec)
    scene_settings = dict(settings or pour_settings())
    if "orientations" not in scene_settings:
        # the pour places sum(count) grains, grain k of its order in orientation k (uniformly random)
        n = sum(t.count for t in templates)
        scene_settings["orientations"] = orientation_rows(grain_orientations(n, scene_settings.get("seed", 0)))
    deck = {"units": "SI (m, kg, s)", "shape": shapes.pop() if shapes else "clump", "grains": records,
            "scene": scene_settings}
    files["grains.json"] = json_text(deck)
    files["run.py"] = render("yade_library.py") + (render("yade_pour.py") if scene is None else scene)
    return files


def write_deck(templates: Sequence, out: str | Path, *, scene: str | None = None,
               settings: dict | None = None, overwrite: bool = False) -> list[Path]:
    """Write a Yade deck for ``templates`` into ``out`` (see the module text).

    Returns the written paths. Raises ``FileExistsError`` before writing
    anything if a file exists and ``overwrite`` is false.

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Templates of one shape (SI units).
    out : str or path
        The deck's folder (created if missing).
    scene : str, optional
        The scene's Python text (default: the pour), as for :func:`deck_files`.
    settings : dict, optional
        The scene's settings (default :func:`pour_settings`).
    overwrite : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        As :func:`deck_files`.
    FileExistsError
        If a file of the deck exists and ``overwrite`` is false.
    """
    return write_files(deck_files(templates, scene=scene, settings=settings), out, overwrite=overwrite)
