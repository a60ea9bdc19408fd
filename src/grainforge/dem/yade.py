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
  ``results-yade.json``).

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
``kinetic_energy(ids)`` and ``grain_report(ids)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .deck import clump_vtk_text, json_text, template_record, write_files, xyzr_text

__all__ = ["write_deck", "deck_files", "LIBRARY", "POUR_SCENE", "pour_settings"]

LIBRARY = r'''# Yade deck written by grainforge. Run from inside this folder:  yade -n -x run.py
# Units: SI (m, kg, s). Every grain is a clump whose mass, centre and inertia are the
# mesh's exact values (see grains.json and docs/dem.md).
import json
import math
import os
import random

from yade import *  # noqa: F401,F403  (Yade's own namespace)
from yade import utils

DECK = json.load(open("grains.json"))
SETTINGS = DECK["scene"]


def read_xyzr(path):
    """Rows (x, y, z, r) of a sphere file (metres, centroid frame)."""
    rows = []
    for line in open(path):
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append([float(v) for v in line.split()])
    return rows


def load_deck():
    """The templates of grains.json with their spheres loaded."""
    out = []
    for t in DECK["grains"]:
        t = dict(t)
        t["rows"] = read_xyzr(t["xyzr"])
        out.append(t)
    return out


_CONTACT = []
_PHANTOM_MATS = {}


def contact_material():
    """The (massless) contact material of every grain sphere."""
    if not _CONTACT:
        _CONTACT.append(O.materials.append(FrictMat(
            density=0.0, young=SETTINGS["young"], poisson=SETTINGS["poisson"],
            frictionAngle=math.radians(SETTINGS["friction_deg"]), label="grain")))
    return _CONTACT[0]


def _phantoms(t):
    """(radius, half-distance a, [3 material ids]) of the mass-carrying member spheres."""
    if t["name"] in _PHANTOM_MATS:
        return _PHANTOM_MATS[t["name"]]
    M = t["mass"]
    I = t["principal_inertia"]
    a0 = math.sqrt(sum(I) / (2.0 * M))
    r = 1e-6 * a0
    own = 0.4 * M * r * r  # the six spheres' own inertia, summed (isotropic)
    Ip = [x - own for x in I]
    S = sum(Ip)
    a = math.sqrt(S / (2.0 * M))
    mats = []
    for k in range(3):
        mu = (S - 2.0 * Ip[k]) / (4.0 * a * a)  # mass of each of the two spheres on axis k
        mats.append(O.materials.append(FrictMat(density=mu / (4.0 / 3.0 * math.pi * r ** 3),
                                                young=SETTINGS["young"], label="mass-" + t["name"] + str(k))))
    _PHANTOM_MATS[t["name"]] = (r, a, mats)
    return _PHANTOM_MATS[t["name"]]


def add_grain(t, position, rotation=Quaternion.Identity):
    """Insert template ``t`` with its centroid at ``position``; returns the clump id.

    The clump's mass, centre of mass and principal inertia are the mesh's.
    """
    pos = Vector3(*position)
    mat = contact_material()
    bodies = [sphere(pos + rotation * Vector3(x, y, z), rr, material=mat) for x, y, z, rr in t["rows"]]
    r, a, mats = _phantoms(t)
    axes = t["principal_axes"]
    for k in range(3):
        e = rotation * Vector3(axes[0][k], axes[1][k], axes[2][k])
        for sgn in (1.0, -1.0):
            bodies.append(sphere(pos + e * (sgn * a), r, material=mats[k], mask=0))
    ids = O.bodies.append(bodies)
    return O.bodies.clump(ids)


def kinetic_energy(ids):
    """Translational + rotational kinetic energy of clumps ``ids`` (J)."""
    e = 0.0
    for i in ids:
        s = O.bodies[i].state
        w = s.ori.conjugate() * s.angVel
        e += 0.5 * s.mass * s.vel.squaredNorm() + 0.5 * sum(s.inertia[k] * w[k] ** 2 for k in range(3))
    return e


def grain_report(ids, names, targets=None):
    """Per clump: name, mass, centre, principal inertia, as Yade holds them."""
    rows = []
    for n, (i, name) in enumerate(zip(ids, names)):
        s = O.bodies[i].state
        rows.append({"id": i, "name": name, "mass": s.mass, "pos": list(s.pos),
                     "target": None if targets is None else list(targets[n]),
                     "inertia": sorted(list(s.inertia)), "members": len(O.bodies[i].shape.members)})
    return rows


def time_step(grains):
    """A stable step for the spheres' contact stiffness and the grains' density."""
    rmin = min(t["r_min"] for t in grains)
    return SETTINGS["dt_safety"] * rmin * math.sqrt(max(t["density"] for t in grains) / SETTINGS["young"])
'''

POUR_SCENE = r'''

# ---- scene: pour the population into a box under gravity ----------------------------
def pour():
    grains = load_deck()
    rnd = random.Random(SETTINGS["seed"])
    population = [t for t in grains for _ in range(t["count"])]
    rnd.shuffle(population)
    n = len(population)
    cell = 2.2 * max(t["bounding_radius"] for t in grains)
    side = max(1, int(math.ceil(math.sqrt(n / 6.0))))  # a column about 6 grains high
    width = side * cell
    O.bodies.append([
        utils.wall(0.0, axis=2, sense=1, material=contact_material()),
        utils.wall(0.0, axis=0, sense=1, material=contact_material()),
        utils.wall(width, axis=0, sense=-1, material=contact_material()),
        utils.wall(0.0, axis=1, sense=1, material=contact_material()),
        utils.wall(width, axis=1, sense=-1, material=contact_material()),
    ])
    ids, names, targets = [], [], []
    for k, t in enumerate(population):
        i, j, layer = k % side, (k // side) % side, k // (side * side)
        pos = ((i + 0.5) * cell, (j + 0.5) * cell, (layer + 1.0) * cell)
        q = Quaternion(Vector3(rnd.gauss(0, 1), rnd.gauss(0, 1), rnd.gauss(0, 1)).normalized(),
                       rnd.uniform(0, 2 * math.pi))
        ids.append(add_grain(t, pos, q))
        names.append(t["name"])
        targets.append(pos)
    inserted = grain_report(ids, names, targets)
    os.makedirs("vtk", exist_ok=True)
    O.engines = [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),
        InteractionLoop(
            [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
            [Ip2_FrictMat_FrictMat_FrictPhys()],
            [Law2_ScGeom_FrictPhys_CundallStrack()],
        ),
        NewtonIntegrator(gravity=(0, 0, -9.81), damping=SETTINGS["damping"]),
        VTKRecorder(fileName="vtk/grains-", recorders=["spheres", "velocity", "clumpId"],
                    iterPeriod=SETTINGS["vtk_every"], mask=1),
    ]
    O.dt = time_step(grains)
    ref = sum(s["mass"] for s in inserted) * 9.81 * sum(t["d_eq"] for t in population) / n
    threshold = SETTINGS["ke_ratio"] * ref
    ke = kinetic_energy(ids)
    history = []
    while O.iter < SETTINGS["max_steps"]:
        O.run(SETTINGS["check_every"], True)
        ke = kinetic_energy(ids)
        history.append([O.iter, O.time, ke])
        if O.time > SETTINGS["min_time"] and ke < threshold:
            break
    final = grain_report(ids, names)
    lost = [r["id"] for r in final
            if not (-0.01 * cell < r["pos"][2] < (n // (side * side) + 2) * cell
                    and 0 <= r["pos"][0] <= width and 0 <= r["pos"][1] <= width)]
    report = {"engine": "yade", "grains": n, "inserted": inserted, "final": final, "lost": lost,
              "kinetic_energy": ke, "ke_threshold": threshold, "settled": ke < threshold,
              "steps": O.iter, "time": O.time, "dt": O.dt, "history": history, "box": [width, width]}
    with open("results-yade.json", "w") as fh:
        json.dump(report, fh, indent=1)
    print("grainforge: %d grains, %d steps, KE %.3g J (threshold %.3g J), lost %d"
          % (n, O.iter, ke, threshold, len(lost)))


pour()
'''


def pour_settings(**kw) -> dict:
    """Default settings of the pour scene (SI), updated with ``kw``.

    Examples
    --------
    >>> pour_settings(seed=3)["seed"]
    3
    """
    s = {"seed": 0, "young": 1e6, "poisson": 0.3, "friction_deg": 30.0, "damping": 0.7,
         "dt_safety": 0.3, "max_steps": 150000, "check_every": 1000, "min_time": 0.05,
         "ke_ratio": 1e-4, "vtk_every": 5000}
    unknown = set(kw) - set(s)
    if unknown:
        raise ValueError(f"unknown scene settings: {', '.join(sorted(unknown))}")
    s.update(kw)
    return s


def deck_files(templates: Sequence, *, scene: str | None = None, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a Yade deck (nothing written).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Clump templates (``shape == "clump"``).
    scene : str, optional
        Python text appended to :data:`LIBRARY` (default :data:`POUR_SCENE`).
    settings : dict, optional
        Scene settings stored in ``grains.json["scene"]`` (default
        :func:`pour_settings`).
    """
    files: dict[str, str] = {}
    records = []
    for t in templates:
        if t.shape != "clump" or t.clump is None:
            raise ValueError(f"the Yade deck writes clumps; {t.name} has shape {t.shape!r}")
        head = (f"grainforge clump of {t.source or t.name}: x y z r (m), centroid at the origin\n"
                f"spheres {t.clump.count}, coverage {t.clump.coverage:.4f}, spill {t.clump.spill:.4f}")
        files[f"{t.name}.xyzr"] = xyzr_text(t.clump.centres, t.clump.radii, header=head)
        files[f"{t.name}.clump.vtk"] = clump_vtk_text(t.clump.centres, t.clump.radii, f"grainforge clump {t.name}")
        records.append(template_record(t))
    deck = {"units": "SI (m, kg, s)", "grains": records, "scene": settings or pour_settings()}
    files["grains.json"] = json_text(deck)
    files["run.py"] = LIBRARY + (POUR_SCENE if scene is None else scene)
    return files


def write_deck(templates: Sequence, out: str | Path, *, scene: str | None = None,
               settings: dict | None = None, overwrite: bool = False) -> list[Path]:
    """Write a Yade deck for ``templates`` into ``out`` (see the module text).

    Returns the written paths. Raises ``FileExistsError`` before writing
    anything if a file exists and ``overwrite`` is false.
    """
    return write_files(deck_files(templates, scene=scene, settings=settings), out, overwrite=overwrite)
