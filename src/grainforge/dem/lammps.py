"""LAMMPS deck: molecule templates as rigid/small bodies with the grain's exact mass properties.

``write_deck(templates, out)`` writes, run from inside ``out`` with
``lmp -in in.run``:

- ``<grain>.xyzr`` and ``<grain>.clump.vtk`` per grain (as for the other engines);
- ``<grain>.mol``: a LAMMPS molecule file (Coords, Types, Diameters, Masses;
  ``com`` 0 0 0 = the mesh centroid, ``mass`` and ``inertia`` of the mesh);
- ``in.insert``: one ``create_atoms ... single x y z mol <grain> ... rotate θ axis``
  per population member (lattice above the box, seeded random orientation);
- ``rigid.infile``: the rigid/small ``infile`` — per body the mesh's mass,
  the centre of mass where it was placed, and the inertia tensor rotated into
  the box frame (LAMMPS otherwise sums the overlapping member spheres);
- ``in.run``: the example pour (the template ``grainforge/dem/texts/lammps-pour.in``, filled by
  :func:`deck_files`) — ``pair_style gran/hooke/history`` with the
  rigid bodies' masses, walls, gravity applied through ``fix rigid/small ...
  gravity`` on the bodies' mesh masses (the ``fix gravity`` group is empty),
  a settle loop on the rigid kinetic energy, body read-back files
  (``bodies-initial.txt``, ``bodies-final.txt``, ``atoms-initial.txt``,
  ``settle.txt``) and text dumps in ``post/`` converted to VTK by
  ``dump2vtk.py`` (run by ``in.run`` through ``shell``); its last line is ``SETTLED in N steps``
  (exit status 0) or ``NOT SETTLED after N steps (KE … > … J)`` (exit status 1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..rng import as_generator
from .deck import (
    GRAVITY,
    clump_vtk_text,
    fmt,
    json_text,
    lattice_slots,
    rotation_matrix,
    settle_loop,
    settle_report,
    settle_schedule,
    settle_settings,
    template_record,
    updated_settings,
    write_files,
    xyzr_text,
)
from .scripts import render as render_script
from .text import render

__all__ = ["write_deck", "deck_files", "pour_settings", "rotation_matrix"]

def pour_settings(**kw) -> dict:
    """Default settings of the example pour (SI), updated with ``kw``.

    Parameters
    ----------
    **kw
        Settings to change: ``seed`` (int: the pour's order of grains and their orientations, drawn in
        Python; default 0), ``kn_weight_overlap`` (the Hooke stiffness lets the heaviest grain's weight
        compress a contact by this share of the mean equivalent diameter), ``restitution`` (normal
        coefficient, in (0, 1)), ``friction`` (contact friction coefficient), ``dt_fraction`` (time step as a
        share of the contact's period), ``dump_every`` (steps between dumps) and those of
        :func:`grainforge.dem.deck.settle_settings`.

    Returns
    -------
    dict
        Every setting, the defaults updated with ``kw``.

    Raises
    ------
    ValueError
        If ``kw`` names an unknown setting.

    Examples
    --------
    >>> pour_settings(friction=0.3)["friction"], pour_settings()["seed"]
    (0.3, 0)
    """
    s = {"seed": 0, "kn_weight_overlap": 0.005, "restitution": 0.3, "friction": 0.5, "dt_fraction": 0.02,
         **settle_settings(), "dump_every": 5000}
    return updated_settings(s, kw, "pour settings")


def molecule_text(t) -> str:
    """A LAMMPS molecule file of the clump (com at the origin, mesh mass and inertia)."""
    c, r = t.clump.centres, t.clump.radii
    I = t.inertia
    lines = [f"# grainforge: {t.name} ({t.source or 'mesh'}), SI units, centroid at the origin", "",
             f"{len(r)} atoms", f"{fmt(t.mass)} mass", "0.0 0.0 0.0 com",
             " ".join(fmt(x) for x in (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])) + " inertia",
             "", "Coords", ""]
    lines += [f"{i + 1} " + " ".join(fmt(x) for x in p) for i, p in enumerate(c)]
    lines += ["", "Types", ""] + [f"{i + 1} 1" for i in range(len(r))]
    lines += ["", "Diameters", ""] + [f"{i + 1} {fmt(2 * x)}" for i, x in enumerate(r)]
    member = t.density * 4.0 / 3.0 * np.pi * r**3  # per-atom masses: overridden by the infile for the body
    lines += ["", "Masses", ""] + [f"{i + 1} {fmt(m)}" for i, m in enumerate(member)]
    return "\n".join(lines) + "\n"


def mol_id(name: str) -> str:
    """A LAMMPS molecule-template ID for a grain name (alphanumerics and underscores only)."""
    return "g_" + "".join(c if c.isalnum() else "_" for c in name)


def _shape_files(templates: Sequence) -> dict:
    """Per grain ``<grain>.xyzr``, ``<grain>.clump.vtk`` and the molecule file ``<grain>.mol``."""
    files: dict[str, str] = {}
    for t in templates:
        if t.shape != "clump" or t.clump is None:
            raise InputError(f"the LAMMPS deck writes rigid clumps; {t.name} has shape {t.shape!r}")
        head = (f"grainforge clump of {t.source or t.name}: x y z r (m), centroid at the origin\n"
                f"spheres {t.clump.count}, coverage {t.clump.coverage:.4f}, spill {t.clump.spill:.4f}")
        files[f"{t.name}.xyzr"] = xyzr_text(t.clump.centres, t.clump.radii, header=head)
        files[f"{t.name}.clump.vtk"] = clump_vtk_text(t.clump.centres, t.clump.radii, f"grainforge clump {t.name}")
        files[f"{t.name}.mol"] = molecule_text(t)
    return files


def _placement_files(templates: Sequence, population: list[int], side: int, cell: float, seed: int):
    """``in.insert`` (one ``create_atoms`` per grain), ``rigid.infile`` (each body's mesh mass, centre and
    inertia in the box frame) and the placements' records, for the grains ``population`` (template indices)."""
    n = len(population)
    ins = ["# grainforge: one rigid grain per line (molecule IDs 1..N in this order)"]
    infile = ["# grainforge rigid/small infile: ID mass xcm ycm zcm ixx iyy izz ixy ixz iyz vxcm vycm vzcm lx ly lz"
              " ixcm iycm izcm (SI, box frame)", str(n)]
    placements = []
    for (slot, pos, axis, theta, R), k in zip(lattice_slots(n, side, cell, seed), population):
        t = templates[k]
        # create_atoms puts the molecule's geometric centre (mean of the atom coordinates) at the
        # point and rotates about it: aim it so that the centroid (file origin) lands on pos
        point = pos + R @ t.clump.centres.mean(axis=0)
        ins.append(f"create_atoms 0 single {fmt(point[0])} {fmt(point[1])} {fmt(point[2])} mol {mol_id(t.name)} "
                   f"{1000003 + slot} rotate {fmt(theta)} {fmt(axis[0])} {fmt(axis[1])} {fmt(axis[2])} units box")
        placements.append({"mol": slot + 1, "name": t.name, "xcm": pos.tolist(), "axis": axis.tolist(),
                           "theta_deg": theta})
        I = R @ t.inertia @ R.T
        infile.append(" ".join([str(slot + 1), fmt(t.mass), *(fmt(x) for x in pos),
                                *(fmt(x) for x in (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])),
                                *["0"] * 9]))
    return {"in.insert": "\n".join(ins) + "\n", "rigid.infile": "\n".join(infile) + "\n"}, placements


def deck_files(templates: Sequence, *, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a LAMMPS deck (nothing written).

    ``in.run`` is the template ``grainforge/dem/texts/lammps-pour.in`` filled with the numbers computed
    here (:mod:`grainforge.dem.text`).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Clump templates (SI units), each placed ``count`` times; the pour's order of the copies and
        their orientations are drawn from ``settings["seed"]``.
    settings : dict, optional
        The pour's settings (default :func:`pour_settings`).

    Returns
    -------
    dict of str to str
        Relative path -> text: the files listed in the module text.

    Raises
    ------
    ValueError
        If a template is not a clump.
    """
    s = settings or pour_settings()
    files = _shape_files(templates)
    population = [k for k, t in enumerate(templates) for _ in range(t.count)]
    rng = as_generator(s["seed"])
    order = rng.permutation(len(population))
    population = [population[i] for i in order]
    n = len(population)
    cell = 2.2 * max(t.bounding_radius for t in templates)
    side = max(1, math.ceil(math.sqrt(n / 6.0)))
    width = side * cell
    layers = math.ceil(n / (side * side))
    mmin = min(t.mass for t in templates)
    mean_d = sum(templates[k].d_eq for k in population) / n
    total_mass = sum(templates[k].mass for k in population)
    # Hooke stiffness: a grain's weight compresses a contact by kn_weight_overlap · d_eq
    kn = max(t.mass for t in templates) * 9.81 / (s["kn_weight_overlap"] * mean_d)
    m_eff = 0.5 * mmin
    omega = math.sqrt(kn / m_eff)
    dt = s["dt_fraction"] * 2 * math.pi / omega
    lne = math.log(s["restitution"])
    zeta = -lne / math.sqrt(math.pi**2 + lne**2)
    gamman = 2 * zeta * omega
    ke_threshold = s["ke_ratio"] * total_mass * GRAVITY * mean_d
    sched = settle_schedule(dt, top=layers * cell, mean_d=mean_d, settings=s)
    placed, placements = _placement_files(templates, population, side, cell, s["seed"])
    files.update(placed)
    # under MPI, rigid/small reaches a body's atoms on other ranks as ghosts: the ghost cutoff spans
    # a whole body plus the neighbour skin (the pair cutoff alone, ~ one sphere diameter, is shorter;
    # LAMMPS stops with "Rigid body extent > ghost cutoff" or "Rigid body atoms missing" then)
    ghost = 2 * max(t.bounding_radius for t in templates) + 0.2 * cell
    lo, hi = fmt(-0.05 * cell), fmt(width + 0.05 * cell)
    files["in.run"] = render("lammps-pour.in", {
        "ghost": fmt(ghost), "x0": lo, "x1": hi, "y0": lo, "y1": hi, "z0": fmt(-0.5 * cell),
        "z1": fmt((layers + 2) * cell),
        "molecules": "\n".join(f"molecule {mol_id(t.name)} {t.name}.mol" for t in templates),
        "kn": fmt(kn), "gamman": fmt(gamman), "friction": fmt(s["friction"]), "skin": fmt(0.2 * cell),
        "dt": fmt(dt), "width": fmt(width), "ke_threshold": fmt(ke_threshold), "check_every": sched["check_every"],
        "dump_every": s["dump_every"],
        "settle_loop": settle_loop(sched["fall_steps"], sched["check_every"], sched["max_checks"],
                                   s["settle_checks"]),
        "settle_report": settle_report("quit 0", "quit 1")})
    files["dump2vtk.py"] = render_script("lammps_dump2vtk.py")
    deck = {"units": "SI (m, kg, s)", "grains": [template_record(t) for t in templates],
            "placements": placements, "box": [width, width],
            "ke_threshold": ke_threshold, "dt": dt, "kn": kn, "settle": sched, "scene": s}
    files["grains.json"] = json_text(deck)
    return files


def write_deck(templates: Sequence, out: str | Path, *, settings: dict | None = None,
               overwrite: bool = False) -> list[Path]:
    """Write a LAMMPS deck for ``templates`` into ``out`` (see the module text).

    Templates of shape ``"polyhedron"`` take the rounded/polyhedron body deck of
    :func:`grainforge.dem.lammps_body.write_deck` (:func:`grainforge.dem.engines.write_deck`
    chooses it).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Clump templates (SI units).
    out : str or path
        The deck's folder (created if missing).
    settings : dict, optional
        The pour's settings (default :func:`pour_settings`).
    overwrite : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    ValueError
        If a template is a polyhedron or not a clump.
    FileExistsError
        If a file of the deck exists and ``overwrite`` is false (nothing is written).
    """
    if any(t.shape == "polyhedron" for t in templates):
        raise InputError("polyhedron templates take grainforge.dem.lammps_body.write_deck")
    return write_files(deck_files(templates, settings=settings), out, overwrite=overwrite)
