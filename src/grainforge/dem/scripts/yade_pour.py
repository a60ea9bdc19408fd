# Pour scene of the Yade deck. grainforge writes run.py as yade_library.py followed by the text below
# the marker line (grainforge.dem.scripts.render drops everything above it, this import included:
# it is here so that linters see where the library's names come from).
from yade_library import *  # noqa: F403

# @grainforge-script-start@


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
        q = orientation(k)
        ids.append(add_grain(t, pos, q))
        names.append(t["name"])
        targets.append(pos)
        points.append(contact_points(ids[-1], pos, q))
    placed = placed_spheres(ids)
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
        advance(check_every)
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
              "check_every": check_every, "max_checks": max_checks, "history": history, "box": [width, width],
              "placed": placed}
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
