"""Yade scene texts of the virtual bulk tests.

Each scene is Python text for Yade's own interpreter, appended to the grain
library of :mod:`grainforge.dem.yade` (``load_deck``, ``add_grain``,
``kinetic_energy``, ...), so every grain enters the simulation as a clump
with the mesh's exact mass, centre and inertia.  Settings come from
``grains.json["scene"]`` (:data:`SETTINGS` inside Yade).  A scene prints
``grainforge-progress <fraction> <phase>`` lines (read by
:func:`grainforge.simulate.run_yade`) and writes ``result.json``: the contact
spheres of every grain at the end (x, y, z, r in metres, clump id), the
phases' step counts and times, and the test's own record.  The angle itself
is measured afterwards, in grainforge, from that file
(:mod:`grainforge.simulate.measure`).

These texts run inside Yade (its Python, its numpy); they never import
grainforge.  They draw no orientation: grain ``k`` is placed in row ``k`` of
``grains.json["scene"]["orientations"]`` (the library's ``orientation``),
drawn uniformly by :func:`grainforge.dem.deck.grain_orientations`, the one
draw every deck and scene uses.  ``result.json["placed"]`` records, right after
insertion and as Yade holds them, every contact body (``bodies``: position,
clump id, its own turn), each grain's centre of mass (``centres``) and the
template drawn for it (``drawn``), so the orientations the engine received
can be read back and checked.
"""

from __future__ import annotations

__all__ = ["COMMON", "REPOSE", "TILT", "TRIAXIAL"]

COMMON = r'''

# ---- grainforge virtual bulk test: helpers shared by the scenes -------------------------
import sys

from yade import geom


def progress(fraction, phase):
    print("grainforge-progress %.4f %s" % (min(max(fraction, 0.0), 1.0), phase))
    sys.stdout.flush()


def population(grains, n, rnd):
    """n templates drawn (with replacement, weighted by count) from the deck's grains."""
    weights = [t["count"] for t in grains]
    return [rnd.choices(grains, weights)[0] for _ in range(n)]


def engines(extra_geoms=(), extra_bounds=()):
    """The same contact model for every shape: linear spring + Coulomb friction (Cundall-Strack)."""
    return [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb()] + list(extra_bounds)),
        InteractionLoop(
            [Ig2_Sphere_Sphere_ScGeom()] + list(extra_geoms),
            [Ip2_FrictMat_FrictMat_FrictPhys()],
            [Law2_ScGeom_FrictPhys_CundallStrack()],
        ),
        NewtonIntegrator(gravity=(0, 0, -SETTINGS["gravity"]), damping=SETTINGS["damping"], label="newton"),
    ]


def stable_dt(grains):
    """Time step from the stability rule of a mass on a linear spring.

    dt = safety * sqrt(m_min / k_max), with m_min the lightest grain and
    k_max = E * r_max the stiffest sphere contact (Ip2_FrictMat_FrictMat_FrictPhys
    gives k_n = E r for two equal spheres); for clumps this is the grain's
    own mass on its stiffest contact, not a member sphere's.
    """
    m_min = min(t["mass"] for t in grains)
    r_max = max(max(row[3] for row in t["rows"]) for t in grains)
    return SETTINGS["dt_safety"] * math.sqrt(m_min / (SETTINGS["young"] * r_max))


def rough_base(x0, x1, y0, y1, r, rnd, periodic=False):
    """Fixed spheres of radius r on a square grid with a little height jitter (a rough plate)."""
    ids = []
    step = 2.0 * r
    nx = int(round((x1 - x0) / step)) if periodic else int(math.ceil((x1 - x0) / step))
    ny = int(round((y1 - y0) / step)) if periodic else int(math.ceil((y1 - y0) / step))
    mat = contact_material()
    for i in range(nx):
        for j in range(ny):
            c = (x0 + (i + 0.5) * (x1 - x0) / nx, y0 + (j + 0.5) * (y1 - y0) / ny, r * (1.0 + 0.3 * rnd.random()))
            ids.append(O.bodies.append(utils.sphere(c, r, fixed=True, material=mat)))
    return ids


def unbound_mass_carriers(ids):
    """Take the mass-carrying member spheres (mask 0: no contacts) out of the collider (they never touch)."""
    for i in ids:
        for m in O.bodies[i].shape.members:
            if O.bodies[m].mask == 0:
                O.bodies[m].bounded = False


def settle(ids, threshold, max_time, phase, f0, f1, min_time=0.0):
    """Run until the grains' kinetic energy falls below threshold (J) or max_time (s) passes."""
    t0 = O.time
    ke = kinetic_energy(ids)
    below = 0
    while O.time - t0 < max_time:
        O.run(SETTINGS["check_every"], True)
        ke = kinetic_energy(ids)
        progress(f0 + (f1 - f0) * (O.time - t0) / max_time, phase)
        print("grainforge-state t=%.4f steps=%d ke=%.3g threshold=%.3g" % (O.time, O.iter, ke, threshold))
        below = below + 1 if ke < threshold else 0
        # at rest: past min_time, and below the threshold at three checks in a row
        if O.time - t0 >= min_time and below >= 3:
            break
    return ke


def write_result(record):
    with open("result.json", "w") as fh:
        json.dump(record, fh)
'''

REPOSE = COMMON + r'''

# ---- scene: angle of repose, lifted cylinder on a rough base -----------------------------
def repose():
    rnd = random.Random(SETTINGS["seed"])
    grains = load_deck()
    pop = population(grains, SETTINGS["grains"], rnd)
    n = len(pop)
    d = sum(t["d_eq"] for t in pop) / n
    volume = sum(t["volume"] for t in pop)
    # cylinder holding the grains at a loose packing 0.5, filled to 2 radii high
    R = (volume / (0.5 * 2.0 * math.pi)) ** (1.0 / 3.0) + d
    cell = 2.05 * max(t["bounding_radius"] for t in pop)
    per_layer = []
    k = int(R / cell)
    for i in range(-k, k + 1):
        for j in range(-k, k + 1):
            if math.hypot(i * cell, j * cell) + 0.5 * cell <= R - 0.05 * d:
                per_layer.append((i * cell, j * cell))
    if not per_layer:
        per_layer = [(0.0, 0.0)]
    layers = int(math.ceil(n / len(per_layer)))
    r_base = SETTINGS["base_roughness"] * d
    z0 = 2.2 * r_base + 0.5 * cell
    height = z0 + layers * cell + cell
    # rough base: a disc of fixed spheres wide enough for a 15-degree heap, over a plane wall
    foot = (3.0 * volume / 0.55 / (math.pi * math.tan(math.radians(15.0)))) ** (1.0 / 3.0)
    half = max(foot, R) + 2.0 * d
    O.bodies.append(utils.wall(0.0, axis=2, sense=1, material=contact_material()))
    base = rough_base(-half, half, -half, half, r_base, rnd)
    cylinder = O.bodies.append(geom.facetCylinder((0, 0, 0.5 * height + 0.5 * r_base), radius=R, height=height,
                                                  segmentsNumber=32, wallMask=4, material=contact_material()))
    ids = []
    for q, t in enumerate(pop):
        x, y = per_layer[q % len(per_layer)]
        layer = q // len(per_layer)
        z = z0 + layer * cell
        # alternate layers turned by 45 degrees and a little jitter: no grain stands on top of another
        if layer % 2:
            x, y = (x - y) * 0.7071067811865476, (x + y) * 0.7071067811865476
        ids.append(add_grain(t, (x + 0.1 * d * rnd.uniform(-1, 1), y + 0.1 * d * rnd.uniform(-1, 1), z),
                             orientation(q)))
    inserted = len(ids)
    placed = {"bodies": placed_spheres(ids), "centres": [list(O.bodies[i].state.pos) for i in ids],
              "drawn": [t["name"] for t in pop]}
    unbound_mass_carriers(ids)
    O.engines = engines([Ig2_Facet_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],
                        [Bo1_Facet_Aabb(), Bo1_Wall_Aabb()])
    O.engines = O.engines + [TranslationEngine(ids=cylinder, translationAxis=(0, 0, 1), velocity=0.0, label="lift")]
    O.dt = stable_dt(pop)
    g = SETTINGS["gravity"]
    threshold = SETTINGS["ke_ratio"] * sum(t["mass"] for t in pop) * g * d
    fall = math.sqrt(2.0 * height / g)
    # the fill only needs a packing at rest to the eye: ten times the final threshold
    # (grains start at rest on a lattice: their energy is small before they land, hence min_time)
    settle(ids, 10.0 * threshold, SETTINGS["max_time_factor"] * fall, "fill", 0.0, 0.3, min_time=3.0 * fall)
    t_fill = O.time
    top = max(O.bodies[i].state.pos[2] for i in ids) + 0.5 * cell
    lift.velocity = SETTINGS["lift_speed"] * math.sqrt(g * d)
    while O.time - t_fill < (top + d) / lift.velocity:
        O.run(SETTINGS["check_every"], True)
        if O.iter % (20 * SETTINGS["check_every"]) == 0:
            print("grainforge-state t=%.4f steps=%d ke=%.3g" % (O.time, O.iter, kinetic_energy(ids)))
        progress(0.3 + 0.4 * (O.time - t_fill) / ((top + d) / lift.velocity), "lift")
    for i in cylinder:
        O.bodies.erase(i)
    t_lift = O.time
    ke = settle(ids, threshold, SETTINGS["max_time_factor"] * fall, "collapse", 0.7, 1.0, min_time=0.5 * fall)
    progress(1.0, "done")
    lost = [i for i in ids if O.bodies[i].state.pos[2] < 0.0]
    write_result({"test": "repose", "grains": n, "inserted": inserted, "lost": len(lost),
                  "d_mean": d, "base_top": 1.3 * r_base + r_base, "cylinder_radius": R, "base_half_width": half, "base_sphere_radius": r_base,
                  "kinetic_energy": ke, "ke_threshold": threshold, "settled": ke < threshold,
                  "steps": O.iter, "time": O.time, "dt": O.dt, "t_fill": t_fill, "t_lift": t_lift,
                  "spheres": contact_spheres(ids), "placed": placed})


repose()
'''

TILT = COMMON + r'''

# ---- scene: tilt table, a periodic layer on a rough plate tilted until it slides ----------
def tilt():
    rnd = random.Random(SETTINGS["seed"])
    grains = load_deck()
    pop = population(grains, SETTINGS["grains"], rnd)
    n = len(pop)
    d = sum(t["d_eq"] for t in pop) / n
    cell = 2.05 * max(t["bounding_radius"] for t in pop)
    per_row = max(2, int(round(math.sqrt(n / SETTINGS["layer_depth"]))))
    width = per_row * cell
    layers = int(math.ceil(n / (per_row * per_row)))
    r_base = SETTINGS["base_roughness"] * d
    z0 = 2.2 * r_base + 0.5 * cell
    O.periodic = True
    O.cell.setBox(width, width, z0 + (layers + 4) * cell)
    base = rough_base(0.0, width, 0.0, width, r_base, rnd, periodic=True)
    ids = []
    for q, t in enumerate(pop):
        i, j, layer = q % per_row, (q // per_row) % per_row, q // (per_row * per_row)
        # every other layer shifted by half a cell, and a little jitter: no grain stands on top of
        # another (a column of spheres is an inverted pendulum that topples much later)
        shift = 0.5 * cell * (layer % 2) + 0.1 * d * rnd.uniform(-1, 1)
        ids.append(add_grain(t, ((i + 0.5) * cell + shift, (j + 0.5) * cell + 0.5 * cell * (layer % 2)
                                 + 0.1 * d * rnd.uniform(-1, 1), z0 + layer * cell), orientation(q)))
    placed = {"bodies": placed_spheres(ids), "centres": [list(O.bodies[i].state.pos) for i in ids],
              "drawn": [t["name"] for t in pop]}
    unbound_mass_carriers(ids)
    O.engines = engines()
    O.dt = stable_dt(pop)
    g = SETTINGS["gravity"]
    threshold = SETTINGS["ke_ratio"] * sum(t["mass"] for t in pop) * g * d
    fall = math.sqrt(2.0 * (z0 + layers * cell) / g)
    settle(ids, 10.0 * threshold, SETTINGS["max_time_factor"] * fall, "deposit", 0.0, 0.3, min_time=3.0 * fall)
    # cumulative downslope travel of each grain, unwrapped across the periodic boundary
    prev = {i: O.bodies[i].state.pos[0] for i in ids}
    travel = {i: 0.0 for i in ids}
    rate = math.radians(SETTINGS["tilt_step_deg"])
    hold = SETTINGS["tilt_hold"] * math.sqrt(d / g)
    beta = math.radians(SETTINGS["tilt_start_deg"])
    history = []
    failed = None
    while beta < math.radians(89.0):
        newton.gravity = (g * math.sin(beta), 0.0, -g * math.cos(beta))
        O.run(max(1, int(hold / O.dt)), True)
        for i in ids:
            x = O.bodies[i].state.pos[0]
            travel[i] += (x - prev[i] + 0.5 * width) % width - 0.5 * width
            prev[i] = x
        dx = sum(travel.values()) / n
        vx = sum(O.bodies[i].state.vel[0] for i in ids) / n
        history.append([math.degrees(beta), dx / d, vx / math.sqrt(g * d)])
        progress(0.3 + 0.7 * (math.degrees(beta) / 60.0), "tilt %.1f deg" % math.degrees(beta))
        if dx > SETTINGS["failure_displacement"] * d:
            failed = math.degrees(beta)
            break
        beta += rate
    progress(1.0, "done")
    lost = [i for i in ids if O.bodies[i].state.pos[2] < 0.0]
    write_result({"test": "tilt", "grains": n, "inserted": len(ids), "lost": len(lost), "d_mean": d,
                  "base_top": 1.3 * r_base + r_base, "width": width,
                  "base_sphere_radius": r_base, "failure_angle": failed, "history": history,
                  "steps": O.iter, "time": O.time, "dt": O.dt, "spheres": contact_spheres(ids), "placed": placed})


tilt()
'''

TRIAXIAL = COMMON + r'''

# ---- scene: drained triaxial compression of a periodic cell ---------------------------------
import numpy


def grain_index(ids):
    """{member body id: grain index k} of every body of clumps ids (a contact names member spheres)."""
    out = {}
    for k, i in enumerate(ids):
        for m in O.bodies[i].shape.members:
            out[m] = k
    return out


def set_friction(mu):
    """Contact friction mu for new contacts (the grains' material) and for every existing one."""
    O.materials[contact_material()].frictionAngle = math.atan(mu)
    for c in O.interactions:
        if c.isReal:
            c.phys.tangensOfFrictionAngle = mu


def cell_state(ids, index):
    """The cell's stress and contacts.

    stress: 3x3, Pa, compression positive: Yade's getStress (a Love-Weber sum over the contacts: in this
    Yade each branch vector joins the two grains' centres of mass, the clumps', across the periodic boundary).
    p_love_weber: the mean stress of the same sum done here over the grains' centres (a check of the above).
    modulus: per axis, (1/V) sum k_n n_i^2 l_i^2 (Pa): the affine stiffness the servo divides by.
    unbalanced: mean norm of the net contact force on a grain over the mean contact force.
    coordination: 2 x (pairs of grains in contact) / grains.
    """
    n = len(ids)
    X = numpy.array([[O.bodies[i].state.pos[0], O.bodies[i].state.pos[1], O.bodies[i].state.pos[2]] for i in ids])
    k1, k2, f, cd, kn, nrm, pen = [], [], [], [], [], [], []
    for c in O.interactions:
        if not c.isReal:
            continue
        a, b = index.get(c.id1), index.get(c.id2)
        if a is None or b is None:
            continue
        F = c.phys.normalForce + c.phys.shearForce  # the force on body 2
        s, nv = c.cellDist, c.geom.normal
        k1.append(a)
        k2.append(b)
        f.append((F[0], F[1], F[2]))
        cd.append((s[0], s[1], s[2]))
        kn.append(c.phys.kn)
        nrm.append((nv[0], nv[1], nv[2]))
        pen.append(c.geom.penetrationDepth)
    V = O.cell.volume
    h = O.cell.hSize
    H = numpy.array([[h[r, q] for q in range(3)] for r in range(3)])
    g = utils.getStress()
    S = -numpy.array([[g[r, q] for q in range(3)] for r in range(3)])
    S = 0.5 * (S + S.T)
    if not k1:
        return {"stress": S, "modulus": numpy.zeros(3), "unbalanced": 1.0, "coordination": 0.0, "overlap": 0.0,
                "contacts": 0, "p_love_weber": 0.0}
    k1, k2, f, cd = numpy.array(k1), numpy.array(k2), numpy.array(f), numpy.array(cd, dtype=float)
    kn, nrm, pen = numpy.array(kn), numpy.array(nrm), numpy.array(pen)
    L = X[k1] - X[k2] - cd.dot(H.T)  # grain 1's centre minus grain 2's image next to it
    p_love_weber = -numpy.einsum("ci,ci->", f, L) / (3.0 * V)
    modulus = (kn[:, None] * nrm ** 2 * L ** 2).sum(axis=0) / V
    net = numpy.zeros((n, 3))
    numpy.add.at(net, k2, f)
    numpy.add.at(net, k1, -f)
    fmean = numpy.linalg.norm(f, axis=1).mean()
    unbalanced = numpy.linalg.norm(net, axis=1).mean() / fmean if fmean > 0 else 1.0
    pairs = numpy.unique(numpy.minimum(k1, k2) * n + numpy.maximum(k1, k2)).size
    return {"stress": S, "modulus": modulus, "unbalanced": float(unbalanced), "coordination": 2.0 * pairs / n,
            "overlap": float(pen.mean()), "contacts": int(len(k1)), "p_love_weber": float(p_love_weber)}


def servo(st, axes, goal, limit, every, held, integral, gain, deadband=0.0):
    """Strain rates (1/s, positive = the cell grows) that bring the stress on ``axes`` to ``goal`` (Pa).

    A proportional-integral servo on the rate c that would close the error in the next ``every`` steps were
    the packing as stiff as its affine modulus: rate = SETTINGS["servo_gain"] * c + the integral term, which
    adds ``integral`` * c at every call (while shearing: the packing is softer than affine, and a dilating
    specimen needs a lateral strain rate of its own at no error, which the integral term learns; none while
    compacting, where the rate at rest is 0 and an integral term would keep the cell swinging about the goal).
    Both are kept within ``limit``; an axis without contacts closes at ``-limit``; an axis within
    ``deadband`` (a fraction of ``goal``) of it is left still. ``held`` (the integral terms) is updated.
    """
    rates = [0.0, 0.0, 0.0]
    for a in axes:
        m = st["modulus"][a]
        if abs(st["stress"][a, a] - goal) < deadband * goal:
            r = 0.0
        elif m > 0:
            c = (st["stress"][a, a] - goal) / (m * every * O.dt)
            held[a] = max(-limit, min(limit, held[a] + integral * c))
            r = held[a] + gain * c
        else:
            r = -limit
        rates[a] = max(-limit, min(limit, r))
    return rates


def strain_rates(r):
    O.cell.velGrad = Matrix3(r[0], 0, 0, 0, r[1], 0, 0, 0, r[2])


def isotropic(ids, index, goal, limit, max_time, phase, f0, f1):
    """Servo the three axes to ``goal`` until the stress is within the tolerance on every axis and the grains
    are in equilibrium (unbalanced force below its bound) at three checks in a row, or ``max_time`` passes."""
    every = SETTINGS["control_every"]
    t0 = O.time
    ok = 0
    held = [0.0, 0.0, 0.0]
    st = cell_state(ids, index)
    while O.time - t0 < max_time:
        # proportional only, gently, and the cell left still near the goal: the grains come to rest
        strain_rates(servo(st, (0, 1, 2), goal, limit, every, held, 0.0, SETTINGS["compaction_servo_gain"],
                           0.5 * SETTINGS["stress_tolerance"]))
        O.run(every, True)
        st = cell_state(ids, index)
        err = max(abs(st["stress"][a, a] / goal - 1.0) for a in range(3))
        ok = ok + 1 if err < SETTINGS["stress_tolerance"] and st["unbalanced"] < SETTINGS["unbalanced"] else 0
        p = sum(st["stress"][a, a] for a in range(3)) / 3.0
        progress(f0 + (f1 - f0) * min(0.99, max(0.0, p / goal)), phase)
        if O.iter % (50 * every) == 0:
            print("grainforge-state t=%.5f steps=%d p=%.4g unbalanced=%.3g contacts=%d" % (
                O.time, O.iter, p, st["unbalanced"], st["contacts"]))
        if ok >= 3:
            break
    strain_rates((0.0, 0.0, 0.0))
    return st, ok >= 3


def triaxial():
    rnd = random.Random(SETTINGS["seed"])
    grains = load_deck()
    pop = population(grains, SETTINGS["grains"], rnd)
    n = len(pop)
    d = sum(t["d_eq"] for t in pop) / n
    solid = sum(t["volume"] for t in pop)  # the meshes' exact volumes
    rho = sum(t["mass"] for t in pop) / solid
    # a loose cubic lattice in a periodic cube (no gravity), a little jitter
    cell = 2.05 * max(t["bounding_radius"] for t in pop)
    m = 1
    while m ** 3 < n:
        m += 1
    width = m * cell
    O.periodic = True
    O.cell.setBox(width, width, width)
    ids = []
    for q, t in enumerate(pop):
        i, j, k = q % m, (q // m) % m, q // (m * m)
        ids.append(add_grain(t, ((i + 0.5) * cell + 0.1 * d * rnd.uniform(-1, 1),
                                 (j + 0.5) * cell + 0.1 * d * rnd.uniform(-1, 1),
                                 (k + 0.5) * cell + 0.1 * d * rnd.uniform(-1, 1)), orientation(q)))
    placed = {"bodies": placed_spheres(ids), "centres": [list(O.bodies[i].state.pos) for i in ids],
              "drawn": [t["name"] for t in pop]}
    unbound_mass_carriers(ids)
    O.engines = engines()
    O.dt = stable_dt(pop)
    index = grain_index(ids)
    goal = 1e3 * SETTINGS["confining_kpa"]
    mu = math.tan(math.radians(SETTINGS["friction_deg"]))
    # strain rates from the inertial number I = rate * d * sqrt(rho / p'), at p' = the confining stress
    # (the smallest p' of the test: the largest I)
    rate = SETTINGS["inertial_number"] * math.sqrt(goal / rho) / d
    rate_c = SETTINGS["compaction_inertial_number"] * math.sqrt(goal / rho) / d
    every = SETTINGS["control_every"]
    # isotropic compaction: frictionless for a dense specimen, with the contact friction for a loose one
    dense = SETTINGS["packing"] == "dense"
    set_friction(0.0 if dense else mu)
    max_time = SETTINGS["compaction_time_factor"] / rate_c
    st, compacted = isotropic(ids, index, goal, rate_c, max_time, "compaction", 0.0, 0.15)
    e_compacted = (O.cell.volume - solid) / solid
    t_compaction, steps_compaction = O.time, O.iter
    if dense:  # the contact friction back on, then in equilibrium again at the confining stress
        set_friction(mu)
        st, settled = isotropic(ids, index, goal, rate_c, 0.25 * max_time, "friction on", 0.15, 0.2)
        compacted = compacted and settled
    # drained shearing: z shortened at a constant engineering strain rate, x and y held at the confining stress
    L0, V0 = O.cell.size[2], O.cell.volume
    e0 = (V0 - solid) / solid
    target = SETTINGS["axial_strain"]
    lateral = SETTINGS["lateral_rate_factor"] * rate
    record_step = target / SETTINGS["records"]
    held = [0.0, 0.0, 0.0]
    records = []
    next_record = 0.0
    t_shear = O.time
    while True:
        ea = 1.0 - O.cell.size[2] / L0
        if ea >= next_record or ea >= target:
            s = st["stress"]
            sx, sy, sz = s[0, 0], s[1, 1], s[2, 2]
            q, p = sz - 0.5 * (sx + sy), (sx + sy + sz) / 3.0
            V = O.cell.volume
            records.append([ea, sx, sy, sz, q, p, q / p if p > 0 else float("nan"), 1.0 - V / V0,
                            (V - solid) / solid, st["coordination"], st["p_love_weber"], st["unbalanced"],
                            st["overlap"] / d])
            while next_record <= ea:
                next_record += record_step
        if ea >= target:
            break
        r = servo(st, (0, 1), goal, lateral, every, held, SETTINGS["servo_integral"], SETTINGS["servo_gain"])
        r[2] = -rate * L0 / O.cell.size[2]  # dLz/dt = -rate * L0: constant engineering strain rate
        strain_rates(r)
        O.run(every, True)
        st = cell_state(ids, index)
        progress(0.2 + 0.8 * ea / target, "shear %.3f" % ea)
    strain_rates((0.0, 0.0, 0.0))
    progress(1.0, "done")
    write_result({"test": "triaxial", "grains": n, "inserted": len(ids), "lost": 0, "d_mean": d,
                  "grain_density": rho, "solid_volume": solid, "confining": goal, "packing": SETTINGS["packing"],
                  "strain_rate": rate, "compaction_strain_rate": rate_c,
                  "inertial_number": rate * d * math.sqrt(rho / goal), "compacted": compacted,
                  "void_ratio_compacted": e_compacted, "void_ratio_initial": e0, "cell_final": list(O.cell.size),
                  "t_compaction": t_compaction, "steps_compaction": steps_compaction, "t_shear": t_shear,
                  "columns": ["axial_strain", "sigma_x", "sigma_y", "sigma_z", "q", "p", "q_over_p",
                              "volumetric_strain", "void_ratio", "coordination", "p_love_weber", "unbalanced",
                              "overlap_over_d"],
                  "records": records, "steps": O.iter, "time": O.time, "dt": O.dt,
                  "spheres": contact_spheres(ids), "placed": placed})


triaxial()
'''
