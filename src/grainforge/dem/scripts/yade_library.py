# Yade deck written by grainforge. Run from inside this folder:  yade -n -x run.py
# Units: SI (m, kg, s). Every grain is a clump whose mass, centre and inertia are the
# mesh's exact values (see grains.json and docs/dem.md).
import atexit
import json
import math
import os
import random
import shutil
import sys

from yade import *  # noqa: F401,F403  (Yade's own namespace)
from yade import utils

# Yade makes a temporary folder, /tmp/yade-XXXXXX, that it leaves behind when a script run with -x ends: it is
# named first (grainforge removes it after the run, also after a run it stopped) and removed as this run ends
YADE_TEMP = os.path.dirname(O.tmpFilename())  # noqa: F405
print("grainforge-tempdir", YADE_TEMP, flush=True)
atexit.register(shutil.rmtree, YADE_TEMP, True)

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


def orientation(k):
    """Grain k's orientation: row k of the deck's orientations (w, x, y, z), drawn uniformly by grainforge."""
    w, x, y, z = SETTINGS["orientations"][k]
    return Quaternion(w, x, y, z)


def contact_members(ids):
    """(clump id, body) of every contact body (mask != 0) of clumps ids; the mass carriers have mask 0."""
    for i in ids:
        for m in O.bodies[i].shape.members:
            if O.bodies[m].mask != 0:
                yield i, O.bodies[m]


def contact_spheres(ids):
    """[x, y, z, r, clump id] of every contact sphere of clumps ids."""
    return [[b.state.pos[0], b.state.pos[1], b.state.pos[2], b.shape.radius, i] for i, b in contact_members(ids)]


def placed_spheres(ids):
    """[x, y, z, clump id, ax, ay, az, angle] of every contact body of clumps ids as Yade holds it: its
    position and its own turn (axis, radians): the record of what was placed."""
    out = []
    for i, b in contact_members(ids):
        p = b.state.pos
        axis, angle = b.state.ori.toAxisAngle()
        out.append([p[0], p[1], p[2], i, axis[0], axis[1], axis[2], angle])
    return out


_CONTACT = []
_PHANTOM_MATS = {}


def rolling_friction():
    """The rolling resistance coefficient mu_r of the contacts (0: none, the scene's Cundall-Strack contacts)."""
    return float(SETTINGS.get("rolling_friction", 0.0))


def shape_rolls():
    """Whether the contacts have rolling resistance: clumps of spheres (or single spheres) with rolling_friction."""
    return DECK["shape"] == "clump" and rolling_friction() > 0.0


def rolling_functors(geoms):
    """(Ig2, Ip2, Law2) of the sphere contacts with rolling resistance: ScGeom6D geometry where Yade has it
    (sphere-sphere, facet-sphere, box-sphere), CohFrictPhys and the moment law; a contact with a Wall keeps its
    ScGeom and gets the Cundall-Strack law, without rolling resistance (Yade has no Ig2_Wall_Sphere_ScGeom6D)."""
    six = {"Ig2_Sphere_Sphere_ScGeom": Ig2_Sphere_Sphere_ScGeom6D, "Ig2_Facet_Sphere_ScGeom": Ig2_Facet_Sphere_ScGeom6D}
    return ([six[type(g).__name__]() if type(g).__name__ in six else g for g in geoms],
            [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys()],
            [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(always_use_moment_law=True, useIncrementalForm=True),
             Law2_ScGeom_FrictPhys_CundallStrack()])


def contact_material():
    """The (massless) contact material of every grain's contact bodies, also used by the walls."""
    if not _CONTACT:
        kw = dict(density=0.0, poisson=SETTINGS["poisson"], frictionAngle=math.radians(SETTINGS["friction_deg"]),
                  label="grain")
        if DECK["shape"] == "polyhedron":
            mat = PolyhedraMat(young=SETTINGS["poly_young"], **kw)
        elif shape_rolls():
            # rolling resistance: the rolling moment of a contact is limited to etaRoll * F_n * min(r1, r2) (Yade's
            # CohFrictPhys.maxRollPl); no cohesion, no twisting resistance (etaTwist 0: no twisting moment)
            mat = CohFrictMat(young=SETTINGS["young"], isCohesive=False, momentRotationLaw=True,
                              etaRoll=rolling_friction(), etaTwist=0.0, **kw)
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
        # torques from the contact point: the default (sphericalBodies) takes each branch vector as a
        # radius along the normal, so a level set's normal forces would have no moment
        return ([Bo1_LevelSet_Aabb(), Bo1_Wall_Aabb(), Bo1_Sphere_Aabb()],
                [Ig2_LevelSet_LevelSet_ScGeom(), Ig2_Wall_LevelSet_ScGeom()],
                [Ip2_FrictMat_FrictMat_FrictPhys()],
                [Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=False)])
    if shape_rolls():
        return ([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()],) + rolling_functors([Ig2_Sphere_Sphere_ScGeom(),
                                                                           Ig2_Wall_Sphere_ScGeom()])
    return ([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()],
            [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
            [Ip2_FrictMat_FrictMat_FrictPhys()],
            [Law2_ScGeom_FrictPhys_CundallStrack()])


def advance(n):
    """Run n time steps in this thread.  O.run(n, True) starts the loop in a thread of its own and polls
    for its end: measured, about 36 ms of wall clock a call, which the pour's settling checks and the bulk
    tests' servo and checks (their scenes follow this library in run.py) paid thousands of times.  The
    steps are the same, so are the results."""
    for _ in range(int(n)):
        O.step()


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
