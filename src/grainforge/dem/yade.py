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
``kinetic_energy(ids)`` and ``grain_report(ids)``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .deck import (
    clump_vtk_text,
    fmt,
    json_text,
    settle_settings,
    template_record,
    updated_settings,
    write_files,
    xyzr_text,
)

__all__ = ["write_deck", "deck_files", "LIBRARY", "POUR_SCENE", "pour_settings"]

LIBRARY = r'''# Yade deck written by grainforge. Run from inside this folder:  yade -n -x run.py
# Units: SI (m, kg, s). Every grain is a clump whose mass, centre and inertia are the
# mesh's exact values (see grains.json and docs/dem.md).
import json
import math
import os
import random
import sys

from yade import *  # noqa: F401,F403  (Yade's own namespace)
from yade import utils

DECK = json.load(open("grains.json"))
SETTINGS = DECK["scene"]


def read_xyzr(path):
    """Rows of numbers of a sphere file (x y z r) or hull file (x y z); metres, centroid frame."""
    rows = []
    for line in open(path):
        line = line.strip()
        if line and not line.startswith("#"):
            rows.append([float(v) for v in line.split()])
    return rows


def load_deck():
    """The templates of grains.json with their contact geometry loaded (spheres, hull or level set)."""
    out = []
    for t in DECK["grains"]:
        t = dict(t)
        shape = t["shape"]
        if shape == "clump":
            t["rows"] = read_xyzr(t["xyzr"])
        elif shape == "polyhedron":
            t["rows"] = read_xyzr(t["polyhedron"])
        else:
            t["field"] = json.load(open(t["levelset"]))
        out.append(t)
    return out


_CONTACT = []
_PHANTOM_MATS = {}


def contact_material():
    """The (massless) contact material of every grain's contact bodies, also used by the walls."""
    if not _CONTACT:
        kw = dict(density=0.0, poisson=SETTINGS["poisson"], frictionAngle=math.radians(SETTINGS["friction_deg"]),
                  label="grain")
        if DECK["shape"] == "polyhedron":
            mat = PolyhedraMat(young=SETTINGS["poly_young"], **kw)
        else:
            mat = FrictMat(young=SETTINGS["young"], **kw)
        _CONTACT.append(O.materials.append(mat))
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


def _contact_bodies(t, pos, rotation):
    """The massless contact bodies of template ``t`` placed with its centroid at ``pos``."""
    shape = t["shape"]
    if shape == "clump":
        mat = contact_material()
        return [sphere(pos + rotation * Vector3(x, y, z), rr, material=mat) for x, y, z, rr in t["rows"]]
    if shape == "polyhedron":
        from yade import polyhedra_utils
        b = polyhedra_utils.polyhedra(O.materials[contact_material()], v=[Vector3(*row) for row in t["rows"]])
        # Yade moves the hull to its own centroid and principal frame; place that frame in the box
        b.state.pos = pos + rotation * b.state.pos
        b.state.ori = rotation * b.state.ori
        b.state.mass, b.state.inertia = 0.0, Vector3(0, 0, 0)
        return [b]
    # level set: the distance field in the grain's principal frame (centroid at the origin)
    ls = t["field"]
    rotation = rotation * Quaternion(Vector3(*ls["axis"]), ls["angle"])
    grid = RegularGrid(min=Vector3(*ls["origin"]), spacing=ls["spacing"], nGP=Vector3i(*ls["shape"]))
    nx, ny, nz = ls["shape"]
    flat = ls["distance"]
    field = [[flat[(i * ny + j) * nz:(i * ny + j + 1) * nz] for j in range(ny)] for i in range(nx)]
    b = utils.levelSetBody(grid=grid, distField=field, center=pos, orientation=rotation,
                           nSurfNodes=SETTINGS["ls_nodes"], nodesPath=2, material=contact_material())
    b.state.mass, b.state.inertia = 0.0, Vector3(0, 0, 0)
    return [b]


def add_grain(t, position, rotation=Quaternion.Identity):
    """Insert template ``t`` with its centroid at ``position``; returns the clump id.

    The grain's contact geometry (spheres, a convex polyhedron or a level set)
    is massless; six mass-carrying member spheres make the clump's mass, centre
    of mass and principal inertia the mesh's.
    """
    pos = Vector3(*position)
    bodies = _contact_bodies(t, pos, rotation)
    r, a, mats = _phantoms(t)
    axes = t["principal_axes"]
    for k in range(3):
        e = rotation * Vector3(axes[0][k], axes[1][k], axes[2][k])
        for sgn in (1.0, -1.0):
            bodies.append(sphere(pos + e * (sgn * a), r, material=mats[k], mask=0))
    ids = O.bodies.append(bodies)
    return O.bodies.clump(ids)


def contact_engines():
    """(bound functors, Ig2, Ip2, Law2) for the deck's grain shape against grains and walls."""
    shape = DECK["shape"]
    if shape == "polyhedron":
        # Yade's polyhedron overlap test caches a separating plane per pair and warns
        # "Unhandled switch case:0" whenever a pair has none cached yet (a new pair, or one that
        # overlapped at the last step), then runs the full test: harmless, one line per such
        # check, thousands per pour. Silence that file's warnings (its errors still show).
        from yade import log
        log.setLevel("Polyhedra_support.cpp", log.ERROR)
        return ([Bo1_Polyhedra_Aabb(), Bo1_Wall_Aabb(), Bo1_Sphere_Aabb()],
                [Ig2_Polyhedra_Polyhedra_PolyhedraGeom(), Ig2_Wall_Polyhedra_PolyhedraGeom()],
                [Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys()],
                [Law2_PolyhedraGeom_PolyhedraPhys_Volumetric()])
    if shape == "levelset":
        return ([Bo1_LevelSet_Aabb(), Bo1_Wall_Aabb(), Bo1_Sphere_Aabb()],
                [Ig2_LevelSet_LevelSet_ScGeom(), Ig2_Wall_LevelSet_ScGeom()],
                [Ip2_FrictMat_FrictMat_FrictPhys()],
                [Law2_ScGeom_FrictPhys_CundallStrack()])
    return ([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()],
            [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
            [Ip2_FrictMat_FrictMat_FrictPhys()],
            [Law2_ScGeom_FrictPhys_CundallStrack()])


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
    """A stable step for the grains' contact stiffness and density.

    Spheres and level sets (linear springs k ~ E r): ``dt_safety · r_min · sqrt(ρ/E)``;
    polyhedra (volumetric law F = k_V · overlap volume, k ~ k_V r²):
    ``dt_safety · sqrt(ρ r_min / k_V)``.
    """
    rmin = min(t["r_min"] for t in grains)
    rho = max(t["density"] for t in grains)
    if DECK["shape"] == "polyhedron":
        return SETTINGS["dt_safety"] * math.sqrt(rho * rmin / SETTINGS["poly_young"])
    return SETTINGS["dt_safety"] * rmin * math.sqrt(rho / SETTINGS["young"])


def vtk_engine():
    """Writes the grains' contact geometry to ``vtk/`` every ``vtk_every`` steps."""
    os.makedirs("vtk", exist_ok=True)
    if DECK["shape"] == "polyhedron":  # VTKRecorder has no polyhedra: Yade's legacy-VTK exporter
        return PyRunner(command="export_polyhedra()", iterPeriod=SETTINGS["vtk_every"], initRun=True)
    recorders = ["lsBodies", "velocity"] if DECK["shape"] == "levelset" else ["spheres", "velocity", "clumpId"]
    return VTKRecorder(fileName="vtk/grains-", recorders=recorders, iterPeriod=SETTINGS["vtk_every"], mask=1)


_EXPORTER = []


def export_polyhedra():
    """One legacy-VTK snapshot of every polyhedron (with its velocity) in ``vtk/``."""
    from yade import export
    if not _EXPORTER:
        _EXPORTER.append(export.VTKExporter("vtk/grains"))
    _EXPORTER[0].exportPolyhedra(what=dict(velocity="b.state.vel"))


def contact_points(cid, position, rotation, limit=64):
    """Up to ``limit`` points of a clump's contact geometry, as Yade holds it, mapped back into
    the grain's frame with the insertion's ``position`` and ``rotation`` (sphere centres, hull
    vertices or level-set surface nodes): a check that the contact shape sits where the mesh is."""
    pts = []
    for mid in O.bodies[cid].shape.members.keys():
        b = O.bodies[mid]
        if b.mask == 0:
            continue
        sh = b.shape
        if isinstance(sh, Polyhedra):
            local = list(sh.v)
        elif isinstance(sh, LevelSet):
            local = list(sh.surfNodes)
        else:
            local = [Vector3(0, 0, 0)]
        for x in local:
            g = rotation.conjugate() * (b.state.pos + b.state.ori * x - Vector3(*position))
            pts.append([g[0], g[1], g[2]])
    step = max(1, len(pts) // limit)
    return pts[::step][:limit]
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
    ids, names, targets, points = [], [], [], []
    for k, t in enumerate(population):
        i, j, layer = k % side, (k // side) % side, k // (side * side)
        pos = ((i + 0.5) * cell, (j + 0.5) * cell, (layer + 1.0) * cell)
        q = Quaternion(Vector3(rnd.gauss(0, 1), rnd.gauss(0, 1), rnd.gauss(0, 1)).normalized(),
                       rnd.uniform(0, 2 * math.pi))
        ids.append(add_grain(t, pos, q))
        names.append(t["name"])
        targets.append(pos)
        points.append(contact_points(ids[-1], pos, q))
    inserted = grain_report(ids, names, targets)
    for rec, pts in zip(inserted, points):
        rec["contact_points"] = pts
    bounds, ig2, ip2, law2 = contact_engines()
    O.engines = [
        ForceResetter(),
        InsertionSortCollider(bounds),
        InteractionLoop(ig2, ip2, law2),
        NewtonIntegrator(gravity=(0, 0, -9.81), damping=SETTINGS["damping"]),
        vtk_engine(),
    ]
    O.dt = time_step(grains)
    g = 9.81
    mean_d = sum(t["d_eq"] for t in population) / n
    threshold = SETTINGS["ke_ratio"] * sum(s["mass"] for s in inserted) * g * mean_d
    # times in the grains' own time scale t_g = sqrt(d/g) (the same at every grain size), the fall
    # at the acceleration that local damping leaves to a free fall, g (1 - damping)
    t_g = math.sqrt(mean_d / g)
    top = max(p[2] for p in targets)
    fall = math.sqrt(2.0 * top / (g * max(1.0 - SETTINGS["damping"], 0.05)))
    check_every = max(1, int(round(SETTINGS["check_time"] * t_g / O.dt)))
    window = int(SETTINGS["settle_checks"])
    max_checks = max(window, int(math.ceil(SETTINGS["settle_time"] * t_g / (check_every * O.dt))))
    O.run(int(math.ceil(fall / O.dt)), True)
    ke = kinetic_energy(ids)
    history = [[O.iter, O.time, ke]]
    recent = []
    for _ in range(max_checks):
        O.run(check_every, True)
        ke = kinetic_energy(ids)
        history.append([O.iter, O.time, ke])
        recent = (recent + [ke])[-window:]
        # settled: the largest kinetic energy of the last `window` checks is below the threshold
        if len(recent) == window and max(recent) < threshold:
            break
    ke_window = max(recent)
    settled = len(recent) == window and ke_window < threshold
    final = grain_report(ids, names)
    lost = [r["id"] for r in final
            if not (-0.01 * cell < r["pos"][2] < (n // (side * side) + 2) * cell
                    and 0 <= r["pos"][0] <= width and 0 <= r["pos"][1] <= width)]
    report = {"engine": "yade", "grains": n, "inserted": inserted, "final": final, "lost": lost,
              "kinetic_energy": ke, "ke_window": ke_window, "ke_threshold": threshold, "settled": settled,
              "steps": O.iter, "time": O.time, "dt": O.dt, "t_g": t_g, "fall_steps": history[0][0],
              "check_every": check_every, "max_checks": max_checks, "history": history, "box": [width, width]}
    with open("results-yade.json", "w") as fh:
        json.dump(report, fh, indent=1)
    print("grainforge: %d grains, %d steps, KE %.3g J (threshold %.3g J), lost %d"
          % (n, O.iter, ke, threshold, len(lost)))
    # the last line, and the exit status (1: not settled)
    if settled:
        print("SETTLED in %d steps" % O.iter)
    else:
        print("NOT SETTLED after %d steps (KE %.4g > %.4g J)" % (O.iter, ke_window, threshold))
    sys.stdout.flush()
    return settled


sys.exit(0 if pour() else 1)
'''


def pour_settings(**kw) -> dict:
    """Default settings of the pour scene (SI), updated with ``kw``.

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
            raise ValueError(f"{t.name}: clump template without spheres")
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
    raise ValueError(f"{t.name}: unknown shape {t.shape!r}")


def deck_files(templates: Sequence, *, scene: str | None = None, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a Yade deck (nothing written).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Templates of one shape: ``"clump"``, ``"polyhedron"`` or ``"levelset"``.
    scene : str, optional
        Python text appended to :data:`LIBRARY` (default :data:`POUR_SCENE`).
    settings : dict, optional
        Scene settings stored in ``grains.json["scene"]`` (default
        :func:`pour_settings`).
    """
    files: dict[str, str] = {}
    records = []
    shapes = {t.shape for t in templates}
    if len(shapes) > 1:
        raise ValueError(f"a Yade deck holds one grain shape; got {', '.join(sorted(shapes))}")
    for t in templates:
        files.update(shape_files(t))
        rec = template_record(t)
        if t.shape == "polyhedron":
            rec.update({"polyhedron": f"{t.name}.poly", "vertices": len(t.polyhedron), "r_min": 0.5 * t.d_eq})
        elif t.shape == "levelset":
            rec.update({"levelset": f"{t.name}.levelset.json", "r_min": 0.5 * t.d_eq})
        records.append(rec)
    deck = {"units": "SI (m, kg, s)", "shape": shapes.pop() if shapes else "clump", "grains": records,
            "scene": settings or pour_settings()}
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
