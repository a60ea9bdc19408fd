"""Controlled case for the level-set tilt: one cube resting face-down on a flat base, gravity tilted slowly.

A rigid cube of edge 2 mm (PolyJet density 1180 kg/m³) rests face-down on a flat base; the contact
friction μ is known, so the cube must slide at the tilt β = atan μ (it cannot tip before 45°).  This
script writes one Yade script per case, runs ``yade -n -x`` on it as a subprocess, and prints the
angle at which the cube slid, against atan μ.  Cases (``--cases``, comma-separated):

- ``ls-wall``: the cube a level set on a Yade ``Wall`` (``Ig2_Wall_LevelSet_ScGeom``: the normal is
  the wall's);
- ``ls-ls``: the cube a level set on a larger fixed level-set slab (``Ig2_LevelSet_LevelSet_ScGeom``:
  the normal is the gradient of the *smaller* body's field at its deepest surface node);
- ``ls-ls-flip``: the same with the slab smaller than the cube (a 1.5 mm square plate under the 2 mm
  cube), so that the slab's nodes and the slab's normal are used;
- ``ls-spheres``: the cube a level set on a square grid of fixed level-set spheres (the tilt scene's
  rough base, flat: radius 0.3 d_eq, ``--base-nodes`` surface nodes each, 50 as the scene's);
- ``clump-wall``: the cube a clump of 4 × 4 × 4 spheres on a Wall;
- ``clump-spheres``: the same clump on plain fixed spheres at the places of ``ls-spheres``;
- ``poly-poly``: the cube a Yade polyhedron on a larger polyhedron slab (Yade's volumetric law).

The cube's level set is made as ``grainforge dem --shape levelset`` makes a grain's: the exact signed
distance to the mesh (:func:`grainforge.dem.levelset.level_set`, grid ``--spacing`` × d_eq), given to
``utils.levelSetBody(grid=..., distField=..., nSurfNodes=--nodes, nodesPath=2)``, under the tilt
scene's contact law (``Ip2_FrictMat_FrictMat_FrictPhys``, ``Law2_ScGeom_FrictPhys_CundallStrack``),
local damping 0.3, ``dt = 0.3 sqrt(m / (E r))`` with r the cube's bounding radius, and the tilt
scene's schedule (gravity turned by ``--step`` degrees, held ``8 sqrt(d/g)`` each); the cube is a
single level-set body here (Yade's mass and inertia of the field), not a clump with mass spheres.
The cube's slide is recorded per tilt step: its travel down the slope, its rotation, and the
angle of the net normal force from the base normal (the mean over the hold); ``--turn`` turns the
cube about the vertical first.

``--contact-point-torque`` sets the law's ``sphericalBodies=False`` (torques from the contact point;
Yade's default takes each branch vector as a radius along the normal, which gives a level set's
normal force no moment); ``--periodic`` runs in a large periodic cell as the tilt scene does
(``--straddle``: the pair across the cell's boundary); ``--torque-fix`` instead replaces the cube's
torque in Python each step (a check of what the flag does).

    .venv/bin/python benchmarks/levelset_block.py                      # Yade's default torques
    .venv/bin/python benchmarks/levelset_block.py --contact-point-torque
    .venv/bin/python benchmarks/levelset_block.py --cases ls-ls --nodes 600 --spacing 0.025 --contact-point-torque

With Yade's default the level-set cube tips over at a tilt of 0–2° on every base and setting; with
the contact-point torques it slides at 26–29° (atan 0.5 = 26.6°), as the clump and the polyhedron
do with either (docs/simulate.md, *Is the shape converged?*).

Prints one row per case: the angle of first slip (a step's travel over 1 % of the edge), the
failure angle (total travel over half an edge, the tilt scene's criterion), atan μ, and the CPU.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

CASES = ("ls-wall", "ls-ls", "ls-ls-flip", "ls-spheres", "clump-wall", "clump-spheres", "poly-poly")

YADE_SCRIPT = r'''
import json, math, sys
CASE = json.loads(open("case.json").read())
a, mu, E, rho = CASE["edge"], CASE["friction"], CASE["young"], 1180.0
kind, base = CASE["kind"], CASE["base"]
g = 9.81
d = (6.0 * a ** 3 / math.pi) ** (1.0 / 3.0)       # the cube's volume-equivalent diameter
if kind == "poly":
    from yade import polyhedra_utils
    from yade import log
    log.setLevel("Polyhedra_support.cpp", log.ERROR)
    mat = O.materials.append(PolyhedraMat(young=CASE["poly_young"], poisson=0.3, frictionAngle=math.atan(mu),
                                          density=rho))
else:
    mat = O.materials.append(FrictMat(young=E, poisson=0.3, frictionAngle=math.atan(mu), density=rho))
fixed_mat = mat

def field_body(rec, center, dynamic):
    nx, ny, nz = rec["shape"]
    flat = rec["distance"]
    field = [[flat[(i * ny + j) * nz:(i * ny + j + 1) * nz] for j in range(ny)] for i in range(nx)]
    grid = RegularGrid(min=Vector3(*rec["origin"]), spacing=rec["spacing"], nGP=Vector3i(nx, ny, nz))
    b = utils.levelSetBody(grid=grid, distField=field, center=Vector3(*center), nSurfNodes=rec["nodes"],
                           nodesPath=2, dynamic=dynamic, material=mat)
    b.state.pos = Vector3(*center)
    return b

turn = Quaternion(Vector3(0, 0, 1), math.radians(CASE["turn"]))
z_block = 0.5 * a * 1.0005          # resting on z = 0 with a gap of 0.05 % of the edge
if CASE["periodic"]:
    # a periodic cell far larger than the scene: nothing crosses it, only Yade's periodic code paths run
    O.periodic = True
    O.cell.setBox(100.0 * a, 100.0 * a, 100.0 * a)
if kind == "ls":
    block = O.bodies.append(field_body(CASE["block_field"], ((100.0 - 0.25) * a * CASE["straddle"], 0, z_block), True))
    O.bodies[block].state.ori = turn
elif kind == "clump":
    n = CASE["clump_n"]
    r = 0.5 * a / n
    ids = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                p = Vector3(-0.5 * a + (2 * i + 1) * r, -0.5 * a + (2 * j + 1) * r, -0.5 * a + (2 * k + 1) * r)
                ids.append(O.bodies.append(utils.sphere(turn * p + Vector3(0, 0, z_block), r, material=mat)))
    block = O.bodies.clump(ids)
    # a solid cube's exact mass and inertia (the spheres' own fill 52 % of it)
    m = rho * a ** 3
    O.bodies[block].state.mass = m
    O.bodies[block].state.inertia = Vector3(m * a * a / 6.0, m * a * a / 6.0, m * a * a / 6.0)
else:
    h = 0.5 * a
    v = [Vector3(sx * h, sy * h, sz * h) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    b = polyhedra_utils.polyhedra(O.materials[mat], v=[turn * x for x in v])
    b.state.pos = Vector3(0, 0, z_block)
    block = O.bodies.append(b)

if base == "wall":
    O.bodies.append(utils.wall(0.0, axis=2, sense=1, material=fixed_mat))
elif base == "ls":
    rec = CASE["base_field"]
    t = rec["thickness"]
    O.bodies.append(field_body(rec, (0.25 * a * CASE["straddle"], 0, -0.5 * t), False))
elif base == "spheres":
    rb = 0.3 * d
    k = int(math.ceil(3.0 * a / (2.0 * rb)))
    for i in range(-k, k + 1):
        for j in range(-k, k + 1):
            c = Vector3(2 * rb * i, 2 * rb * j, -rb)
            if kind == "ls":
                O.bodies.append(utils.levelSetBody("sphere", center=c, radius=rb, spacing=rb / 5.0,
                                                   nSurfNodes=CASE["base_nodes"], dynamic=False, material=fixed_mat))
            else:
                O.bodies.append(utils.sphere(c, rb, fixed=True, material=fixed_mat))
elif base == "poly":
    L, t = 40.0 * a, a
    v = [Vector3(sx * 0.5 * L, sy * 0.5 * L, -t + 0.5 * t + sz * 0.5 * t) for sx in (-1, 1) for sy in (-1, 1)
         for sz in (-1, 1)]
    pb = polyhedra_utils.polyhedra(O.materials[fixed_mat], v=v, fixed=True)
    pb.state.pos = Vector3(0, 0, -0.5 * t)
    O.bodies.append(pb)

if kind == "poly":
    O.engines = [ForceResetter(), InsertionSortCollider([Bo1_Polyhedra_Aabb()]),
                 InteractionLoop([Ig2_Polyhedra_Polyhedra_PolyhedraGeom()],
                                 [Ip2_PolyhedraMat_PolyhedraMat_PolyhedraPhys()],
                                 [Law2_PolyhedraGeom_PolyhedraPhys_Volumetric()]),
                 NewtonIntegrator(gravity=(0, 0, -g), damping=CASE["damping"], label="newton")]
    m = O.bodies[block].state.mass
    O.dt = CASE["dt_safety"] * math.sqrt(m / (CASE["poly_young"] * a))
else:
    O.engines = [ForceResetter(),
                 InsertionSortCollider([Bo1_LevelSet_Aabb(), Bo1_Wall_Aabb(), Bo1_Sphere_Aabb()]),
                 InteractionLoop([Ig2_LevelSet_LevelSet_ScGeom(), Ig2_Wall_LevelSet_ScGeom(),
                                  Ig2_Wall_Sphere_ScGeom(), Ig2_Sphere_Sphere_ScGeom()],
                                 [Ip2_FrictMat_FrictMat_FrictPhys()],
                                 [Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=CASE["spherical_bodies"])]),
                 NewtonIntegrator(gravity=(0, 0, -g), damping=CASE["damping"], label="newton")]
    m = O.bodies[block].state.mass
    r_max = 0.5 * math.sqrt(3.0) * a
    O.dt = CASE["dt_safety"] * math.sqrt(m / (E * r_max))

if CASE["torque_fix"]:
    # Yade's Law2_ScGeom_FrictPhys_CundallStrack, in a periodic cell (or with sphericalBodies), applies each
    # contact's torque as if the branch vector were a radius along the normal: a level set's normal force then
    # has no moment.  Replace the torque on the cube by the sum of (contact point - centre) x force.
    def fix_torques():
        t = Vector3(0, 0, 0)
        for I in O.interactions.withBody(block):
            if not I.isReal:
                continue
            f = I.phys.normalForce + I.phys.shearForce             # on id2
            if I.id2 == block:
                shift = O.cell.hSize * Vector3(*I.cellDist) if O.periodic else Vector3(0, 0, 0)
                t += (I.geom.contactPoint - O.bodies[block].state.pos - shift).cross(f)
            else:
                t += (I.geom.contactPoint - O.bodies[block].state.pos).cross(-f)
        O.forces.addT(block, t - O.forces.t(block))
    O.engines = O.engines[:-1] + [PyRunner(command="fix_torques()", iterPeriod=1)] + O.engines[-1:]

s = O.bodies[block].state
hold = CASE["hold"] * math.sqrt(d / g)
O.run(max(1, int(2.0 * hold / O.dt)), True)     # settle under vertical gravity


def contact_normal_tilt():
    """Angle (deg) between the base normal (z) and the net contact force on the cube, and the force count."""
    f = Vector3(0, 0, 0)
    n = 0
    for I in O.interactions:
        if not I.isReal:
            continue
        n += 1
        sign = 1.0 if I.id2 == block or (kind == "clump" and O.bodies[I.id2].clumpId == block) else -1.0
        nf = I.phys.normalForce * sign
        f += nf
    if n == 0 or f.norm() == 0:
        return float("nan"), n
    return math.degrees(math.acos(max(-1.0, min(1.0, f[2] / f.norm())))), n


cell_dist = [list(I.cellDist) for I in O.interactions if I.isReal] if O.periodic else []
x0 = s.pos[0]
ori0 = Quaternion(s.ori)
history = []
beta = math.radians(CASE["start"])
slip = failed = None
while beta < math.radians(CASE["stop"]):
    newton.gravity = (g * math.sin(beta), 0.0, -g * math.cos(beta))
    xb = s.pos[0]
    steps = max(1, int(hold / O.dt))
    tilts = []
    for _ in range(10):
        O.run(max(1, steps // 10), True)
        tilts.append(contact_normal_tilt())
    travel = (s.pos[0] - x0) / a
    step_travel = (s.pos[0] - xb) / a
    q = ori0.conjugate() * s.ori
    rot = math.degrees(abs(q.toAxisAngle()[1]))
    rot = min(rot, 360.0 - rot)
    ntilt = float(sum(t[0] for t in tilts) / len(tilts))
    history.append([math.degrees(beta), travel, step_travel, rot, ntilt, tilts[-1][1], s.pos[2] / a])
    print("block beta=%.2f travel=%.5f step=%.5f rot=%.3f normal_tilt=%.2f contacts=%d z=%.4f" % tuple(history[-1]))
    sys.stdout.flush()
    if slip is None and step_travel > 0.01:
        slip = math.degrees(beta)
    if travel > 0.5:
        failed = math.degrees(beta)
        break
    beta += math.radians(CASE["step"])
json.dump({"slip": slip, "failed": failed, "cell_dist": cell_dist, "history": history, "dt": O.dt, "steps": O.iter,
           "nodes": len(O.bodies[block].shape.surfNodes) if kind == "ls" else None}, open("result.json", "w"))
'''


def cube_field(edge: float, spacing: float, nodes: int) -> dict:
    """The cube's level set as grainforge's dem writes a grain's (exact signed distance to the mesh)."""
    import trimesh

    from grainforge.dem.levelset import level_set

    box = trimesh.creation.box(extents=(edge, edge, edge))
    ls = level_set(box.vertices, box.faces, spacing=spacing)
    return {"origin": [float(x) for x in ls.grid.origin], "spacing": float(ls.grid.spacing),
            "shape": [int(n) for n in ls.grid.shape], "nodes": int(nodes),
            "distance": [float(x) for x in ls.distance.reshape(-1)]}


def slab_field(length: float, thickness: float, spacing: float, nodes: int) -> dict:
    """A flat square slab's exact signed distance (length × length × thickness, centred at the origin)."""
    half = np.array([0.5 * length, 0.5 * length, 0.5 * thickness])
    axes = [np.arange(-(h + 3 * spacing), h + 3.5 * spacing, spacing) for h in half]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    q = np.stack([np.abs(X), np.abs(Y), np.abs(Z)], axis=-1) - half
    dist = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
    return {"origin": [float(ax[0]) for ax in axes], "spacing": float(spacing),
            "shape": [len(ax) for ax in axes], "nodes": int(nodes), "thickness": float(thickness),
            "distance": [float(x) for x in dist.reshape(-1)]}


def run_case(case: str, args) -> dict:
    edge = args.edge
    d = (6.0 * edge ** 3 / math.pi) ** (1.0 / 3.0)
    kind, base = {"ls-wall": ("ls", "wall"), "ls-ls": ("ls", "ls"), "ls-ls-flip": ("ls", "ls"),
                  "ls-spheres": ("ls", "spheres"), "clump-wall": ("clump", "wall"),
                  "clump-spheres": ("clump", "spheres"), "poly-poly": ("poly", "poly")}[case]
    rec = {"kind": kind, "base": base, "edge": edge, "friction": args.friction, "young": args.young,
           "poly_young": args.poly_young, "damping": args.damping, "dt_safety": args.dt_safety,
           "hold": args.hold, "start": args.start, "stop": args.stop, "step": args.step, "turn": args.turn,
           "clump_n": args.clump_n,
           "spherical_bodies": not args.contact_point_torque, "periodic": args.periodic,
           "base_nodes": args.base_nodes, "torque_fix": args.torque_fix,
           "straddle": int(args.straddle)}
    if kind == "ls":
        rec["block_field"] = cube_field(edge, args.spacing, args.nodes)
    if base == "ls":
        # the slab's grid: the cube's spacing in metres; larger than the cube (ls-ls) or smaller (flip)
        length = 0.75 * edge if case == "ls-ls-flip" else 3.0 * edge
        rec["base_field"] = slab_field(length, 0.5 * edge, args.spacing * d, args.nodes)
    with tempfile.TemporaryDirectory(prefix="gf-lsblock-") as tmp:
        Path(tmp, "case.json").write_text(json.dumps(rec))
        Path(tmp, "block.py").write_text(YADE_SCRIPT)
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(["yade", "-n", "-x", "block.py"], cwd=tmp, capture_output=True, text=True,
                              env={**os.environ, "OMP_NUM_THREADS": "1"})
        wall = time.perf_counter() - t0
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        res_path = Path(tmp, "result.json")
        if proc.returncode != 0 or not res_path.is_file():
            sys.stderr.write(proc.stdout[-3000:] + proc.stderr[-3000:])
            raise RuntimeError(f"{case}: yade failed (exit {proc.returncode})")
        res = json.loads(res_path.read_text())
    res.update(case=case, cpu=(c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime), wall=wall)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated, of: " + ", ".join(CASES))
    ap.add_argument("--edge", type=float, default=2e-3, help="cube edge (m)")
    ap.add_argument("--friction", type=float, default=0.5, help="contact friction μ")
    ap.add_argument("--young", type=float, default=1e6, help="contact modulus E (Pa), k_n = E r")
    ap.add_argument("--poly-young", type=float, default=1e8, help="polyhedra's volumetric stiffness (Pa)")
    ap.add_argument("--damping", type=float, default=0.3, help="Yade's local damping")
    ap.add_argument("--dt-safety", type=float, default=0.3, help="dt = safety · sqrt(m / k)")
    ap.add_argument("--hold", type=float, default=8.0, help="hold per tilt step, in sqrt(d/g)")
    ap.add_argument("--spacing", type=float, default=0.05, help="level-set grid spacing, in d_eq")
    ap.add_argument("--nodes", type=int, default=150, help="level-set surface nodes")
    ap.add_argument("--base-nodes", type=int, default=50, help="surface nodes of each level-set base sphere")
    ap.add_argument("--clump-n", type=int, default=4, help="clump spheres per edge")
    ap.add_argument("--turn", type=float, default=0.0, help="cube turned about the vertical first (deg)")
    ap.add_argument("--start", type=float, default=0.0, help="first tilt (deg)")
    ap.add_argument("--stop", type=float, default=40.0, help="last tilt (deg)")
    ap.add_argument("--step", type=float, default=1.0, help="tilt increment (deg)")
    ap.add_argument("--contact-point-torque", action="store_true",
                    help="Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=False): torques from the contact "
                         "point, not from radii along the normal (Yade's default, and Yade's only way in a "
                         "periodic cell)")
    ap.add_argument("--torque-fix", action="store_true",
                    help="a PyRunner replaces the cube's torque by the sum of (contact point - centre) x force "
                         "each step (what sphericalBodies=False does, in a periodic cell too)")
    ap.add_argument("--periodic", action="store_true", help="run in a (large) periodic cell, as the tilt scene")
    ap.add_argument("--straddle", action="store_true",
                    help="with --periodic: the slab at x = a/4 and the cube at -a/4 of the next cell (x = 99.75 a), "
                         "a pair across the cell's boundary")
    ap.add_argument("--json", help="append every case's result (with its history) to this JSON-lines file")
    ap.add_argument("--verbose", action="store_true", help="print every tilt step")
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad:
        ap.error(f"unknown case(s) {', '.join(bad)}; choose from {', '.join(CASES)}")
    atan = math.degrees(math.atan(args.friction))
    print(f"cube {args.edge * 1e3:g} mm, μ = {args.friction:g} (atan μ = {atan:.1f}°), E = {args.young:g} Pa, "
          f"damping {args.damping:g}, dt safety {args.dt_safety:g}, hold {args.hold:g} sqrt(d/g), "
          f"step {args.step:g}°, level set: spacing {args.spacing:g} d_eq, {args.nodes} nodes, turn {args.turn:g}°")
    print(f"{'case':<12} {'first slip':>10} {'failure':>8} {'atan μ':>7} {'normal tilt':>11} "
          f"{'rotation':>8} {'contacts':>8} {'CPU s':>6}")
    for case in cases:
        res = run_case(case, args)
        hist = res["history"]
        # before the first slip: the largest mean contact-normal tilt and cube rotation, the last contact count
        before = [h for h in hist if res["slip"] is None or h[0] < res["slip"]] or hist
        ntilt = max(h[4] for h in before)
        rot = max(h[3] for h in before)

        def fmt(x):
            return "none" if x is None else f"{x:.1f}°"
        print(f"{case:<12} {fmt(res['slip']):>10} {fmt(res['failed']):>8} {atan:>6.1f}° {ntilt:>10.2f}° "
              f"{rot:>7.2f}° {before[-1][5]:>8d} {res['cpu']:>6.1f}")
        if args.verbose:
            for h in hist:
                print(f"   β {h[0]:.1f}° travel {h[1]:.4f} a, step {h[2]:.4f} a, rotation {h[3]:.3f}°, "
                      f"normal tilt {h[4]:.2f}°, contacts {h[5]}")
        if args.json:
            with open(args.json, "a") as fh:
                fh.write(json.dumps({"args": vars(args), **res}) + "\n")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
