"""Does a collision of two Yade level-set bodies keep its kinetic energy?  Two bodies, no friction, no damping.

Two equal bodies approach each other at 0.3 m/s each, off-centre (their centres 0.6 mm and 0.3 mm apart across the
line of approach), touch once and part.  With a frictionless linear spring and no damping the collision is
elastic: the kinetic energy after it (translation and rotation) must equal the energy before.  The ratio after /
before is printed for each case; 1 is a conservative contact.  The contact is Yade's level-set contact under the
law grainforge's scenes use (``Ig2_LevelSet_LevelSet_ScGeom``, ``Ip2_FrictMat_FrictMat_FrictPhys``,
``Law2_ScGeom_FrictPhys_CundallStrack``; E = 10⁸ Pa, ν = 0.3, friction 0).  Cases:

- ``plain-sphere``: the control, two plain Yade spheres of radius 1 mm (``Ig2_Sphere_Sphere_ScGeom``);
- ``sphere``: Yade's own level-set sphere of radius 1 mm (``utils.levelSetBody("sphere")``), grid spacing r/10;
- ``sphere-fine``: the same at spacing r/40;
- ``sphere-normal-torque``: the sphere with the law's default ``sphericalBodies=True`` (no moment from a normal
  force: a sphere's normal passes through its centre);
- ``box``: Yade's level-set box of 2 × 1.4 × 1 mm;
- ``grain``: a rough-angular CRI grain of 2 mm, its level set as ``grainforge dem --shape levelset`` writes it
  (the exact signed distance on a grid of 0.05 d_eq), each body a single level set (Yade's mass and inertia of
  the field), not the clump with mass spheres of the scenes;
- ``grain-dt/4``: the same at a quarter of the time step (a time-step effect would shrink).

The time step is 0.1 sqrt(m / (E r)) (a third of the scenes'), the collision lasting some 25 steps.

    .venv/bin/python benchmarks/levelset_energy.py
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

YADE_SCRIPT = r'''
import json, math
CASE = json.loads(open("case.json").read())
mat = O.materials.append(FrictMat(young=1e8, poisson=0.3, frictionAngle=0.0, density=1180))
O.engines = [ForceResetter(), InsertionSortCollider([Bo1_LevelSet_Aabb(), Bo1_Sphere_Aabb()], verletDist=0),
             InteractionLoop([Ig2_LevelSet_LevelSet_ScGeom(), Ig2_Sphere_Sphere_ScGeom()],
                             [Ip2_FrictMat_FrictMat_FrictPhys()],
                             [Law2_ScGeom_FrictPhys_CundallStrack(sphericalBodies=CASE["spherical_bodies"])]),
             NewtonIntegrator(gravity=(0, 0, 0), damping=0.0)]


def body(c):
    kind = CASE["kind"]
    if kind == "plain-sphere":
        return utils.sphere(c, 1e-3, material=mat)
    if kind == "sphere":
        return utils.levelSetBody("sphere", center=c, radius=1e-3, spacing=1e-3 / CASE["per_radius"],
                                  nSurfNodes=150, material=mat)
    if kind == "box":
        return utils.levelSetBody("box", center=c, extents=Vector3(1e-3, 0.7e-3, 0.5e-3), spacing=1e-4,
                                  nSurfNodes=150, material=mat)
    ls = CASE["field"]
    nx, ny, nz = ls["shape"]
    flat = ls["distance"]
    field = [[flat[(i * ny + j) * nz:(i * ny + j + 1) * nz] for j in range(ny)] for i in range(nx)]
    grid = RegularGrid(min=Vector3(*ls["origin"]), spacing=ls["spacing"], nGP=Vector3i(*ls["shape"]))
    return utils.levelSetBody(grid=grid, distField=field, center=c, nSurfNodes=150, nodesPath=2, material=mat)


gap = CASE["gap"]
a = O.bodies.append(body(Vector3(0, 0, 0)))
b = O.bodies.append(body(Vector3(gap, 0.6e-3, 0.3e-3)))
O.bodies[a].state.vel = Vector3(0.3, 0, 0)
O.bodies[b].state.vel = Vector3(-0.3, 0, 0)


def kinetic():
    e = 0.0
    for i in (a, b):
        st = O.bodies[i].state
        w = st.ori.conjugate() * st.angVel  # in the body's principal frame
        e += 0.5 * st.mass * st.vel.squaredNorm() + 0.5 * sum(st.inertia[k] * w[k] ** 2 for k in range(3))
    return e


r = CASE["radius"]
O.dt = CASE["dt_factor"] * math.sqrt(O.bodies[a].state.mass / (1e8 * r))
e0 = kinetic()
touched, steps_in_contact = False, 0
while O.time < 4.0 * gap / 0.6:
    O.step()
    n = len([c for c in O.interactions if c.isReal])
    if n:
        touched = True
        steps_in_contact += 1
    elif touched:
        break
open("result.json", "w").write(json.dumps({"ratio": kinetic() / e0, "touched": touched,
                                           "contact_steps": steps_in_contact}))
'''

CASES = {
    "plain-sphere": dict(kind="plain-sphere", spherical_bodies=True, dt_factor=0.1),
    "sphere": dict(kind="sphere", per_radius=10, spherical_bodies=False, dt_factor=0.1),
    "sphere-fine": dict(kind="sphere", per_radius=40, spherical_bodies=False, dt_factor=0.1),
    "sphere-normal-torque": dict(kind="sphere", per_radius=10, spherical_bodies=True, dt_factor=0.1),
    "box": dict(kind="box", spherical_bodies=False, dt_factor=0.1),
    "grain": dict(kind="grain", spherical_bodies=False, dt_factor=0.1),
    "grain-dt/4": dict(kind="grain", spherical_bodies=False, dt_factor=0.025),
}


def grain_field(work: Path) -> dict:
    """The level set of a rough-angular CRI grain of 2 mm, as ``grainforge dem --shape levelset`` writes it."""
    cli = [sys.executable, "-c", "import sys; from grainforge.cli.main import main; sys.exit(main())"]
    subprocess.run([*cli, "generate", "cri", "--count", "1", "--size", "2", "--preset", "rough-angular",
                    "--out", str(work / "grain")], check=True, capture_output=True)
    subprocess.run([*cli, "dem", str(work / "grain"), "--engine", "yade", "--shape", "levelset",
                    "--out", str(work / "deck")], check=True, capture_output=True)
    (path,) = (work / "deck").glob("*.levelset.json")
    return json.loads(path.read_text())


def run_case(name: str, case: dict, field: dict | None, yade: str, work: Path) -> dict:
    folder = work / ("case-" + name.replace("/", "-"))
    folder.mkdir()
    if case["kind"] == "grain":
        r = max(abs(v) for v in field["origin"])  # about the bounding radius (the grid's half-width)
        case = {**case, "field": field, "radius": r, "gap": 2.2 * r}
    else:
        case = {**case, "radius": 1e-3, "gap": 2.3e-3}
    (folder / "case.json").write_text(json.dumps(case))
    (folder / "run.py").write_text(YADE_SCRIPT)
    proc = subprocess.run([yade, "-n", "-x", "run.py"], cwd=folder, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL)
    if proc.returncode != 0 or not (folder / "result.json").exists():
        raise SystemExit(f"{name}: yade failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return json.loads((folder / "result.json").read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated cases (default: all)")
    args = ap.parse_args(argv)
    yade = shutil.which("yade")
    if yade is None:
        print("yade is not installed", file=sys.stderr)
        return 2
    names = args.cases.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        field = grain_field(work) if any(CASES[n]["kind"] == "grain" for n in names) else None
        print("| case | kinetic energy after / before | steps in contact |")
        print("|---|---|---|")
        for name in names:
            res = run_case(name, CASES[name], field, yade, work)
            ratio = f"{res['ratio']:.3f}" if res["touched"] else "no contact"
            print(f"| {name} | {ratio} | {res['contact_steps']} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
