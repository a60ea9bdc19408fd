"""The drained triaxial test in LIGGGHTS, serial or under ``mpirun``: a box of six servo-controlled walls.

``grainforge simulate triaxial --engine liggghts [--mpi N]`` runs the test of :mod:`grainforge.simulate.triaxial`
(the Yade scene: a periodic cell) with walls instead of a periodic cell:

- the grains are the same multisphere templates as the tilt and repose scenes (the mesh's exact mass and
  inertia; :func:`grainforge.simulate.liggghts_scenes.contact_table`'s contacts), grain ``k`` in row ``k`` of the
  scene's uniformly random orientations (:func:`grainforge.simulate.triaxial.triaxial_scene_settings`), inserted at
  the nodes of a loose cubic lattice with a jitter of 0.1 d, as the Yade scene lays them out but 0.2 d wider (no
  grain starts in contact) and spread evenly over a cube; grainforge draws the grains and the jitter from its own
  stream, so not the Yade run's grains;
- six square plates (``wall-*.stl``), each a ``fix mesh/surface/stress/servo`` wall moving along its inward
  normal, frictionless (the periodic cell's boundary carries no shear either), close the box; each plate
  reaches past the box, so the plates cross at its edges and leave no gap;
- **isotropic compaction** (``--packing dense``: at μ = 0, then the contact friction switched on and the grains at
  rest again; ``loose``: at μ): every wall servo-controls its force to σ′₃ times its area (from the other walls'
  positions, every step) until the three normal stresses are within 1 % of σ′₃ and the net force on every grain
  is below :data:`UNBALANCED` σ′₃ d² along every axis, at three checks in a row;
- **drained shearing**: the z walls approach each other at the constant speed of the axial strain rate of
  ``--inertial-number`` (a constant engineering strain rate), the x and y walls servo-held at σ′₃
  (proportional-integral), the records every 1/200 of the axial strain: the walls' forces over their areas (the
  stresses), their positions (the volume), the grains' contacts (the coordination and overlaps).

LIGGGHTS's servo walls move at ``vel_max · (kp e + ki ∫e dt)``, e the relative force error. A wall meets the
stiffness of its own contacts before the packing's, so its gain is set by them: G = vel_max · kp closes an error
against about (L/d)² grain contacts of stiffness k_n in :data:`SERVO_STEPS` ``["wall"]`` steps; the lateral walls
add an integral term while shearing.  The time step is the Yade scene's, 0.3 √(m_min/(E r_max)).

:func:`collect_triaxial` turns the run's files into the ``result.json`` the Yade scene writes (the same fields but
its ``placed`` record and its Love–Weber check), so that :func:`grainforge.simulate.triaxial.measure_triaxial`,
``results.csv``, ``triaxial.csv`` and the figure are shared.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InputError
from ..rng import as_generator
from .settings import DENSEST_FRACTION, TriaxialSettings

__all__ = ["WALLS", "triaxial_deck_files", "write_deck", "collect_triaxial", "processor_grid", "check_ranks", "largest_ranks",
           "MIN_RANK_DIAMETERS", "SERVO_STEPS", "UNBALANCED"]

#: the walls, by the axis they move along and their side (0: low, 1: high)
WALLS = ("x0", "x1", "y0", "y1", "z0", "z1")
#: time constants of the walls' servo, in time steps: ``wall``, of a wall's force against the stiffness of its own
#: contacts (about (L/d)² grains of normal stiffness k_n: a wall moving at G per unit relative force error closes
#: an error in σ′₃ d² / (G k_n)); ``integral``, of the integral part while shearing
SERVO_STEPS = {"wall": 4.0, "integral": 200.0}
#: the grains are at rest when the largest net force on any grain, along any axis, is below this fraction of
#: σ′₃ d² (about the mean contact force): LIGGGHTS cannot sum the Yade scene's mean norm of the net forces (bound at
#: 1 % of the mean contact force), only its extremes; over a few hundred grains the largest component of a normally
#: spread net force is about twice the mean norm. A rattler (no contact) has none. Kinetic energy is no measure
#: here: under LIGGGHTS's contact damping a rattler keeps its velocity
UNBALANCED = 0.02
#: steps between two checks of the isotropic state (the Yade scene's servo: 10)
CHECK_EVERY = 50
#: under ``mpirun -np P`` each rank's slab of the compacted specimen is at least this many mean grain diameters
#: thick (see :func:`check_ranks`)
MIN_RANK_DIAMETERS = 2.0
#: the lateral walls may move out to this many times the specimen's initial width over √(1 − ε_a) (the plates and
#: the box reach that far: a specimen sheared to ε_a and dilating by half its volume)
LATERAL_REACH = math.sqrt(1.5)


def processor_grid(ranks: int) -> tuple[int, int, int]:
    """The ``processors * * *`` grid LIGGGHTS picks for ``ranks`` on a cubic box: the factorisation P_x P_y P_z
    with the least sub-domain surface (the first found, P_x largest, on a tie).

    Parameters
    ----------
    ranks : int
        MPI ranks of the run.

    Returns
    -------
    tuple of int
        (P_x, P_y, P_z), their product ``ranks`` (the order LIGGGHTS gives the axes may differ).

    Examples
    --------
    >>> processor_grid(1), processor_grid(2), processor_grid(8), processor_grid(12)
    ((1, 1, 1), (2, 1, 1), (2, 2, 2), (3, 2, 2))
    """
    ranks = int(ranks)
    best, best_area = (ranks, 1, 1), math.inf
    for px in range(ranks, 0, -1):
        if ranks % px:
            continue
        for py in range(ranks // px, 0, -1):
            if (ranks // px) % py:
                continue
            pz = ranks // px // py
            area = 1.0 / (px * py) + 1.0 / (px * pz) + 1.0 / (py * pz)
            if area < best_area - 1e-12:
                best, best_area = (px, py, pz), area
    return best


def _width(settings: TriaxialSettings) -> float:
    """The compacted specimen's side in grain diameters (``settings.grains`` spheres at the densest solid
    fraction)."""
    return (settings.grains * (math.pi / 6.0) / DENSEST_FRACTION) ** (1.0 / 3.0)


def largest_ranks(settings: TriaxialSettings, most: int) -> int:
    """The most ranks, ``most`` at most, among which a LIGGGHTS triaxial specimen of ``settings`` can be cut (every
    rank's slab at least :data:`MIN_RANK_DIAMETERS` grain diameters thick: :func:`check_ranks` accepts it).

    Parameters
    ----------
    settings : TriaxialSettings
        The run's settings (``grains``).
    most : int
        The ranks available (``--mpi`` asked, or the cores).

    Returns
    -------
    int
        At least 1 (one rank cuts nothing).

    Examples
    --------
    >>> largest_ranks(TriaxialSettings(grains=200), 64), largest_ranks(TriaxialSettings(grains=200), 3)
    (8, 2)
    """
    allowed = max(1, int(_width(settings) // MIN_RANK_DIAMETERS))
    top = min(int(most), allowed**3)  # more ranks than that cut some side more than ``allowed`` ways
    return next((r for r in range(top, 1, -1) if max(processor_grid(r)) <= allowed), 1)


def check_ranks(settings: TriaxialSettings, mpi: int | None, available: int | None = None) -> None:
    """Refuse (``ValueError``, one line) a LIGGGHTS triaxial specimen too small for ``mpi`` ranks: the compacted
    cube (``settings.grains`` spheres at the densest solid fraction) cut by :func:`processor_grid` would leave a
    rank a slab under :data:`MIN_RANK_DIAMETERS` grain diameters thick.

    Every remedy the line offers passes the other checks: the ``--mpi`` it names is within ``available`` ranks,
    and ``--grains`` is offered only where ``mpi`` ranks are available and the grains within the setting's range.

    Parameters
    ----------
    settings : TriaxialSettings
        The run's settings (``grains``).
    mpi : int or None
        Ranks of each run (``--mpi``); ``None`` or 1: nothing to check.
    available : int, optional
        Ranks a run may have here (:func:`grainforge.simulate.process.mpi_slots` over the runs at once); None: no
        limit known (the cluster's workers decide).

    Raises
    ------
    ValueError
        Naming the slab's thickness, a rank count that fits and the grains that would take ``mpi`` ranks.

    Examples
    --------
    >>> check_ranks(TriaxialSettings(grains=100), 2)
    >>> check_ranks(TriaxialSettings(grains=100), 64)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: mpi 64: a triaxial specimen of 100 grains is about 4.3 grain diameters wide; cut 4 ways (the 4 × 4 × 4 ranks' grid) a rank's slab would be 1.1 diameters thick, under the 2 a rank needs: use mpi 8 (or another count cut at most 2 ways per side), or grains 626 or more
    >>> check_ranks(TriaxialSettings(grains=200), 3, available=2)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: mpi 3: a triaxial specimen of 200 grains is about 5.5 grain diameters wide; cut 3 ways (the 3 × 1 × 1 ranks' grid) a rank's slab would be 1.8 diameters thick, under the 2 a rank needs: use mpi 2 (or another count cut at most 2 ways per side)
    """
    from ..params import specs

    if mpi is None or mpi <= 1:
        return
    width = _width(settings)
    grid = processor_grid(mpi)
    cuts = max(grid)
    if width / cuts >= MIN_RANK_DIAMETERS:
        return
    allowed = int(width // MIN_RANK_DIAMETERS)
    fits = largest_ranks(settings, mpi if available is None else min(mpi, available))
    grains = math.ceil((MIN_RANK_DIAMETERS * cuts) ** 3 * DENSEST_FRACTION / (math.pi / 6.0))
    most_grains = next(s.high for s in specs(TriaxialSettings) if s.name == "grains")
    more = (available is None or mpi <= available) and grains <= most_grains
    raise InputError(f"{{mpi}} {mpi}: a triaxial specimen of {settings.grains} grains is about {width:.1f} grain "
                     f"diameters wide; cut {cuts} ways (the {' × '.join(map(str, grid))} ranks' grid) a rank's slab "
                     f"would be {width / cuts:.1f} diameters thick, under the {MIN_RANK_DIAMETERS:g} a rank needs: "
                     f"use {{mpi}} {fits} (or another count cut at most {allowed} ways per side)"
                     + (f", or {{grains}} {grains} or more" if more else ""), setting=("mpi", "grains"))


def _plan(templates: Sequence, settings: TriaxialSettings, seed: int) -> SimpleNamespace:
    """The numbers of one run's deck: the drawn grains, their lattice, the walls, the contacts and the servo."""
    from .liggghts_scenes import _clear_of_cuts, contact_table
    from .triaxial import COMPACTION_INERTIAL_NUMBER, triaxial_scene_settings

    for t in templates:
        if t.shape != "clump" or t.clump is None:
            raise InputError(f"the LIGGGHTS scenes take multisphere clumps; {t.name} has shape {t.shape!r}")
    scene = triaxial_scene_settings(settings, seed)
    n = settings.grains
    rng = as_generator(np.random.SeedSequence([int(seed), 28]))  # the run's seed, stream 28: the layout
    counts = np.array([t.count for t in templates], dtype=np.float64)
    pick = rng.choice(len(templates), size=n, p=counts / counts.sum())
    used = sorted(set(pick.tolist()))
    d = float(np.mean([templates[k].d_eq for k in pick]))
    # a loose cubic lattice, m grains a side, as the Yade scene's, with a jitter of 0.1 d, but 0.2 d wider (no two
    # bounding spheres overlap however far the jitter moves them: a start without contacts) and walls 0.1 d beyond
    # it; the box centred on the origin
    cell = 2.05 * max(templates[k].bounding_radius for k in used) + 0.2 * d
    m = 1
    while m ** 3 < n:
        m += 1
    gap = 0.1 * d
    length = np.full(3, m * cell + 2.0 * gap)
    # the n grains spread evenly over the m³ nodes (a cube, not a cube with a part-filled top layer)
    q = (np.arange(n) * m ** 3) // n
    ijk = np.column_stack([q % m, (q // m) % m, q // (m * m)]).astype(np.float64)
    jitter = 0.1 * d * rng.uniform(-1.0, 1.0, size=(n, 3))
    nodes = -0.5 * length + gap + (ijk + 0.5) * cell + jitter
    # the plates reach past the widest the lateral walls can go; the box holds them
    half_plate = 0.5 * float(length.max()) * LATERAL_REACH / math.sqrt(1.0 - settings.axial_strain) + d
    half_box = half_plate + d
    for a in range(3):  # every insertion node clear of the cuts of up to MAX_CUTS ranks along each axis
        nodes[:, a] = _clear_of_cuts(nodes[:, a], -half_box, 2.0 * half_box, 1e-4 * cell)
    r_grain = float(np.mean([templates[k].clump.radii.mean() for k in pick]))
    mass = np.array([templates[k].mass for k in pick])
    table = contact_table(settings, r_grain, r_grain, float(mass.mean()))
    # the Yade scene's time step, 0.3 √(m_min / (E r_max)) with r_max the largest contact sphere: the type pairs'
    # k_n (at the mean sphere radius) would allow a longer one, at which frictional clumps of large and small
    # spheres chatter (their contacts' forces flip from step to step: the grains never come to rest)
    m_min = min(templates[k].mass for k in used)
    r_max = max(float(templates[k].clump.radii.max()) for k in used)
    dt = scene["dt_safety"] * math.sqrt(m_min / (settings.young * r_max))
    solid = float(sum(templates[k].props.volume for k in pick))
    # the clumps' volumes: their spheres' union, coverage x mesh volume / (1 - spill) (measured on a grid)
    solid_clumps = float(sum(templates[k].props.volume * templates[k].clump.coverage
                             / (1.0 - templates[k].clump.spill) for k in pick))
    rho = float(mass.sum()) / solid
    sigma = 1e3 * settings.confining_kpa
    rate = settings.inertial_number * math.sqrt(sigma / rho) / d
    rate_c = COMPACTION_INERTIAL_NUMBER * math.sqrt(sigma / rho) / d
    return SimpleNamespace(scene=scene, n=n, pick=pick, used=used, d=d, cell=cell, nodes=nodes, length=length,
                           half_plate=half_plate, half_box=half_box, r_grain=r_grain, table=table, dt=dt,
                           solid=solid, solid_clumps=solid_clumps, rho=rho, mass=float(mass.sum()), sigma=sigma,
                           rate=rate, rate_c=rate_c)


def _plate_stl(axis: int, position: float, half: float) -> str:
    """An ASCII STL square plate of half-width ``half`` normal to ``axis`` at ``position``, centred on the axis."""
    from ..dem.deck import fmt

    b, c = (axis + 1) % 3, (axis + 2) % 3
    corners = []
    for u, v in ((-half, -half), (half, -half), (half, half), (-half, half)):
        p = [0.0, 0.0, 0.0]
        p[axis], p[b], p[c] = position, u, v
        corners.append(p)
    normal = [0.0, 0.0, 0.0]
    normal[axis] = 1.0
    lines = [f"solid wall{'xyz'[axis]}"]
    for tri in ((0, 1, 2), (0, 2, 3)):
        lines += [f"  facet normal {' '.join(fmt(x) for x in normal)}", "    outer loop"]
        lines += [f"      vertex {' '.join(fmt(x) for x in corners[k])}" for k in tri]
        lines += ["    endloop", "  endfacet"]
    lines.append(f"endsolid wall{'xyz'[axis]}")
    return "\n".join(lines) + "\n"


def _run_text(plan: SimpleNamespace, settings: TriaxialSettings, seed: int) -> str:
    """``in.run``: the template ``liggghts-triaxial.in`` with its compaction (``liggghts-triaxial-isotropic.in``),
    the dense specimen's friction phase (``liggghts-triaxial-friction.in``) and the scenes' shared parts."""
    from ..dem.deck import fmt
    from ..dem.text import block, render
    from .liggghts_scenes import CONTACT_OPTIONS, GRAIN, WALL, _per_type_pair, contact_model, rolling_fix, rolling_table

    scene, dt, sigma = plan.scene, plan.dt, plan.sigma
    mu = settings.friction
    dense = settings.packing == "dense"
    # frictionless walls; the grains at μ (at 0 while a dense specimen is compacted)
    friction = _per_type_pair([[mu, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    compaction_mu = 0.0 if dense else mu
    max_checks = max(3, math.ceil(scene["compaction_time_factor"] / plan.rate_c / (CHECK_EVERY * dt)))

    def isotropic(name, checks, f0, f1, phase):
        return block("liggghts-triaxial-isotropic.in", {
            "name": name, "max_checks": checks, "every": CHECK_EVERY, "tolerance": repr(scene["stress_tolerance"]),
            "unbalanced": repr(UNBALANCED), "f0": repr(f0), "df": repr(f1 - f0), "phase": phase})

    if dense:
        friction_on = block("liggghts-triaxial-friction.in", {
            "friction": friction, "isotropic": isotropic("friction", max(3, max_checks // 4), 0.15, 0.2,
                                                         "friction on")})
    else:
        friction_on = "# loose: compacted with the contact friction"
    # the servo: a wall moves at vel_max · (kp e + ki ∫e dt), e its relative force error; G = vel_max · kp, the
    # speed per unit error, closes an error against the wall's own contacts in SERVO_STEPS["wall"] steps
    gain = sigma * plan.d ** 2 / (SERVO_STEPS["wall"] * dt * plan.table["kn"][0][2])
    vmax_c = 0.5 * plan.rate_c * float(plan.length.max())
    lateral = scene["lateral_rate_factor"] * plan.rate
    record_every = max(1, math.ceil(settings.axial_strain / (scene["records"] * plan.rate * dt)))
    values = {
        "seed": seed, "lo": fmt(-plan.half_box), "hi": fmt(plan.half_box), "skin": fmt(0.25 * plan.d),
        "kn": _per_type_pair(plan.table["kn"]), "kt": _per_type_pair(plan.table["kt"]),
        "gamman": _per_type_pair(plan.table["gamman"]), "gammat": _per_type_pair(plan.table["gamman"]),
        "friction_compaction": _per_type_pair([[compaction_mu, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
        "friction_compaction_text": f"μ = {compaction_mu:g}", "packing": settings.packing,
        "model": contact_model(settings.rolling_friction), "options": CONTACT_OPTIONS, "dt": fmt(dt),
        "sigma": fmt(sigma), "wall_type": WALL,
        # the grains' rolling resistance from the start (as in Yade's cell); the frictionless walls have none
        "rolling": (rolling_fix(rolling_table(settings.rolling_friction, plan.r_grain, None, walls=False))
                    if settings.rolling_friction > 0 else ""),
        "multisphere": block("liggghts-multisphere.in"), "every": CHECK_EVERY,
        "insert": block("liggghts-scene-insert.in"), "tail": block("liggghts-scene-tail.in", {"grain_type": GRAIN}),
        "compaction": isotropic("compaction", max_checks, 0.0, 0.15, "compaction"), "friction_on": friction_on,
        "z_target": fmt(1e3 * sigma * float(plan.length.max()) ** 2), "records": scene["records"],
        "record_every": record_every, "force_scale": fmt(sigma * plan.d ** 2), "half_rate": fmt(0.5 * plan.rate), "half_lateral_rate": fmt(0.5 * lateral),
        "lateral_rate_factor": repr(scene["lateral_rate_factor"]), "kp_compaction": fmt(gain / vmax_c),
        "vmax": fmt(vmax_c), "gain": fmt(gain), "integral_time": fmt(SERVO_STEPS["integral"] * dt),
    }
    for a, name in enumerate("xyz"):
        for side, sign in ((0, -1.0), (1, 1.0)):
            com = [0.0, 0.0, 0.0]
            com[a] = sign * 0.5 * float(plan.length[a])
            values[f"com_{name}{side}"] = " ".join(fmt(x) for x in com)
        values[f"p{name}"] = 7 + a  # the servo's vector follows the stress module's six (force, torque)
    return render("liggghts-triaxial.in", values)


def triaxial_deck_files(templates: Sequence, settings: TriaxialSettings, seed: int) -> dict:
    """``{relative path: text}`` of the LIGGGHTS deck of one triaxial run (nothing written).

    Run from inside the folder with ``liggghts -in in.run`` or ``mpirun -np P liggghts -in in.run``: the grains'
    files of :func:`grainforge.simulate.liggghts_scenes._grain_files`, the six plates ``wall-*.stl``, ``in.run``
    (:func:`_run_text`) and ``grains.json`` (the scene's settings, with the orientations, and the numbers
    :func:`collect_triaxial` needs).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Multisphere clumps (:func:`grainforge.simulate.build_population`).
    settings : TriaxialSettings
        The test's settings.
    seed : int
        The run's seed: the grains drawn, their lattice's jitter, their orientations, LIGGGHTS's random seeds.

    Returns
    -------
    dict of str to str
        Relative path → text; the same for the same templates, settings and seed.
    """
    from ..dem.deck import json_text, template_record
    from .liggghts_scenes import _grain_files

    plan = _plan(templates, settings, seed)
    files = _grain_files(templates, SimpleNamespace(used=plan.used, n=plan.n, pick=plan.pick, cell=plan.cell,
                                                    scene=plan.scene, geo={"nodes": plan.nodes}), settings, seed)
    for a, name in enumerate("xyz"):
        for side, sign in ((0, -1.0), (1, 1.0)):
            files[f"wall-{name}{side}.stl"] = _plate_stl(a, sign * 0.5 * float(plan.length[a]), plan.half_plate)
    files["in.run"] = _run_text(plan, settings, seed)
    rec = {"test": "triaxial", "seed": int(seed), "grains": plan.n, "d_mean": plan.d, "dt": plan.dt,
           "grain_density": plan.rho, "solid_volume": plan.solid,
           "solid_volume_clumps": plan.solid_clumps, "confining": plan.sigma,
           "packing": settings.packing, "strain_rate": plan.rate, "compaction_strain_rate": plan.rate_c,
           "inertial_number": plan.rate * plan.d * math.sqrt(plan.rho / plan.sigma), "contact": plan.table,
           "contact_radius": plan.r_grain,
           "box_initial": plan.length.tolist(), "plate_half_width": plan.half_plate, "nodes": plan.nodes.tolist(),
           "scene": plan.scene}
    files["grains.json"] = json_text({"units": "SI (m, kg, s)", "engine": "liggghts", "result": rec,
                                      "grains": [template_record(templates[k]) for k in plan.used],
                                      "drawn": [templates[k].name for k in plan.pick]})
    return files


def write_deck(templates: Sequence, settings: TriaxialSettings, *, seed: int, out: str | os.PathLike,
               overwrite: bool = False) -> list[Path]:
    """Write the LIGGGHTS deck of one triaxial run into ``out`` (see :func:`triaxial_deck_files`).

    Parameters
    ----------
    templates, settings, seed
        As :func:`triaxial_deck_files`.
    out : path
        The run's folder.
    overwrite : bool
        Replace an existing deck (refused otherwise).

    Returns
    -------
    list of Path
        The files written.
    """
    from ..dem.deck import write_files

    return write_files(triaxial_deck_files(templates, settings, seed), out, overwrite=overwrite)


def _snapshots(path: Path) -> dict[int, np.ndarray]:
    """The rows of each timestep of a LIGGGHTS ``dump local`` file (``ITEM: TIMESTEP`` ... ``ITEM: ENTRIES``)."""
    out: dict[int, np.ndarray] = {}
    lines = path.read_text().splitlines()
    k = 0
    while k < len(lines):
        if lines[k].startswith("ITEM: TIMESTEP"):
            step = int(lines[k + 1])
            count = int(lines[k + 3])
            start = next(j for j in range(k + 4, len(lines)) if lines[j].startswith("ITEM: ENTRIES")) + 1
            rows = [ln.split() for ln in lines[start:start + count]]
            out[step] = np.array(rows, dtype=np.float64).reshape(count, -1)
            k = start + count
        else:
            k += 1
    return out


def contact_state(contacts: np.ndarray, grain_of: dict, radius_of: dict, grains: int) -> tuple[float, float]:
    """Coordination (2 × pairs of grains in contact / grains) and mean overlap of one snapshot of the contacts
    dump (rows: atom id 1, atom id 2, x₁ y₁ z₁, x₂ y₂ z₂); a pair listed twice (two ranks) counts once.

    Parameters
    ----------
    contacts : (K, 8) ndarray
        The snapshot's rows.
    grain_of, radius_of : dict of int
        Each atom id's grain (its multisphere body) and radius (m).
    grains : int
        Grains in the specimen.

    Returns
    -------
    (float, float)
        The coordination and the mean overlap (m) of the contacts between two grains.

    Examples
    --------
    >>> rows = np.array([[1, 3, 0, 0, 0, 0.9, 0, 0], [2, 3, 0, 0, 0, 0.95, 0, 0], [3, 1, 0.9, 0, 0, 0, 0, 0]])
    >>> z, overlap = contact_state(rows, {1: 0, 2: 0, 3: 1}, {1: 0.5, 2: 0.5, 3: 0.5}, 2)  # grains 0, 1 touch twice
    >>> z, round(overlap, 12)
    (1.0, 0.075)
    """
    if len(contacts) == 0:
        return 0.0, 0.0
    ids = contacts[:, :2].astype(np.int64)
    key = np.sort(ids, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    ids, xyz = ids[first], contacts[first, 2:8]
    g = np.array([[grain_of[int(i)], grain_of[int(j)]] for i, j in ids])
    r = np.array([[radius_of[int(i)], radius_of[int(j)]] for i, j in ids])
    other = g[:, 0] != g[:, 1]
    pairs = np.unique(np.sort(g[other], axis=1), axis=0)
    overlap = r.sum(axis=1) - np.linalg.norm(xyz[:, :3] - xyz[:, 3:], axis=1)
    return 2.0 * len(pairs) / grains, float(overlap[other].mean()) if other.any() else 0.0


def collect_triaxial(deck: str | os.PathLike) -> dict:
    """The Yade scene's ``result.json`` record of a finished LIGGGHTS triaxial run (and written there).

    The stresses are the walls' forces over their areas (the mean of the two walls of an axis), the volume the
    walls' box; the coordination and overlaps come from the contacts dump (``contacts.txt``, removed once read)
    and ``atoms.txt`` (every sphere's grain, radius and place as inserted).

    Parameters
    ----------
    deck : path
        The finished run's folder.

    Returns
    -------
    dict
        The record (:func:`grainforge.simulate.triaxial.measure_triaxial` reads it), also written to
        ``deck/result.json``.

    Raises
    ------
    ValueError
        If the records and the contact snapshots do not match one to one.
    """
    from .liggghts_scenes import _record, _rows

    deck = Path(deck)
    rec = dict(json.loads((deck / "grains.json").read_text())["result"])
    run = _record(deck / "record.txt")
    initial = _rows(deck / "bodies-initial.txt", 4)
    final = _rows(deck / "bodies-final.txt", 4)
    spheres = _rows(deck / "spheres-final.txt", 4)
    shear = _rows(deck / "shear.txt", 7)
    atoms = _rows(deck / "atoms.txt", 6)
    grain_of = {int(i): int(m) for i, m in atoms[:, :2]}
    radius_of = {int(i): float(r) for i, r in atoms[:, [0, 2]]}
    snapshots = _snapshots(deck / "contacts.txt")
    n, d, solid = rec["grains"], rec["d_mean"], rec["solid_volume"]
    lx, ly, lz, sx, sy, sz, ke = shear.T
    volume = lx * ly * lz
    steps = sorted(snapshots)
    state = np.array([contact_state(snapshots[s], grain_of, radius_of, n) for s in steps]).reshape(-1, 2)
    if len(state) != len(shear):
        raise InputError(f"{deck}: {len(shear)} records but {len(state)} contact snapshots")
    q, p = sz - 0.5 * (sx + sy), (sx + sy + sz) / 3.0
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(p > 0, q / p, np.nan)
    columns = ["axial_strain", "sigma_x", "sigma_y", "sigma_z", "q", "p", "q_over_p", "volumetric_strain",
               "void_ratio", "coordination", "kinetic_energy", "overlap_over_d"]
    records = np.column_stack([1.0 - lz / lz[0], sx, sy, sz, q, p, ratio, 1.0 - volume / volume[0],
                               (volume - solid) / solid, state[:, 0], ke, state[:, 1] / d])
    lost = len(initial) - len(final)
    out = {k: rec[k] for k in ("test", "grains", "d_mean", "grain_density", "solid_volume", "confining", "packing",
                               "strain_rate", "compaction_strain_rate", "inertial_number", "dt")}
    out["solid_volume_clumps"] = rec.get("solid_volume_clumps", solid)  # a deck written before it was recorded
    out.update(inserted=len(initial), lost=lost, compacted=bool(run["compacted"]), settled=bool(run["settled"]),
               void_ratio_compacted=(run["volume_compacted"] - solid) / solid,
               void_ratio_initial=float((volume[0] - solid) / solid), cell_final=[lx[-1], ly[-1], lz[-1]],
               t_compaction=run["steps_compaction"] * rec["dt"], steps_compaction=int(run["steps_compaction"]),
               t_shear=run["shear_start"] * rec["dt"], columns=columns, records=records.tolist(),
               steps=int(run["steps"]), time=run["steps"] * rec["dt"],
               spheres=np.column_stack([spheres, np.full(len(spheres), -1.0)]).tolist())
    (deck / "result.json").write_text(json.dumps(out))
    (deck / "contacts.txt").unlink()
    return out
