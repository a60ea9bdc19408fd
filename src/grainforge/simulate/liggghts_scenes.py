"""The virtual bulk tests in LIGGGHTS, serial or under ``mpirun``: deck writing and the engine run.

The scenes are the Yade ones of :mod:`grainforge.simulate.yade_scenes`, laid out
here in Python (grainforge draws the population, the lattice, the jitter and
the rough base for the seed) and written as a LIGGGHTS input deck (``in.run``:
the template ``grainforge/dem/texts/liggghts-<test>.in`` with the numbers
computed and formatted here, :func:`run_deck_files`):

- every grain is a ``particletemplate/multisphere`` with the mesh's exact mass
  and inertia tensor (:func:`grainforge.dem.liggghts.template_fix`, as
  ``grainforge dem --engine liggghts`` writes it), inserted once at its own
  lattice node in a random orientation (LIGGGHTS's random numbers, seeded by
  primes drawn for the seed);
- the rough base is a grid of fixed spheres (``fix freeze``), the repose
  cylinder a granular cylinder wall removed at once (not lifted: see :func:`run_deck_files`), the tilt
  layer periodic in x and y with gravity turned step by step;
- contacts are linear springs with Coulomb friction (``hooke/stiffness`` with
  tangential history) with the Yade scenes' k_n, k_s/k_n and μ, and a viscous
  contact damping with the restitution of Yade's local damping
  (:func:`contact_table`; docs/simulate.md says where the engines differ).

The deck prints ``grainforge-progress <fraction> <phase>`` lines (read by
:func:`run_liggghts`) and writes plain text files (``record.txt``,
``history.txt``, ``spheres-final.txt``, ``bodies-*.txt``); :func:`run_liggghts`
turns them into the ``result.json`` a Yade scene writes, with the same
fields, so that :func:`grainforge.simulate.measure_result`, ``results.csv``
and the figure are shared.

Under ``mpirun -np P`` the box is cut into columns (``processors * * 1``):
gravity stacks the grains in z, so a cut across z would leave the upper
ranks idle; every insertion node is kept clear of the column cuts of up to
:data:`MAX_CUTS` ranks per side (see :func:`grainforge.dem.liggghts.node_insertion`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InputError
from ..rng import as_generator
from .settings import Settings, scene_settings

__all__ = ["liggghts_executable", "mpirun_executable", "contact_table", "contact_model", "rolling_table",
           "rolling_fix", "run_deck_files", "write_test_deck",
           "engine_command", "run_liggghts", "MAX_CUTS"]

#: atom types of the scenes: grain spheres, fixed base spheres, walls (plane and cylinder)
GRAIN, BASE, WALL = 1, 2, 3
#: insertion nodes stay clear of the column cuts of up to this many ranks along x and along y
MAX_CUTS = 64
#: the contact model of the grains, the base and the walls (``pair_style gran`` and every ``fix wall/gran``) and its
#: options
CONTACT_MODEL = "model hooke/stiffness tangential history"
CONTACT_OPTIONS = "absolute_damping off tangential_damping on limitForce on"
#: the rolling resistance model added to :data:`CONTACT_MODEL` when ``rolling_friction`` > 0: elastic-plastic
#: spring (Iwashita and Oda), its moment limited to μ_r F_n R* with R* = r₁r₂/(r₁+r₂) (r for a wall)
ROLLING_MODEL = "rolling_friction epsd2"
#: a prime larger than the seed table: seeds k * _STRIDE (mod its length) are distinct within a deck
_STRIDE = 1_000_003


def liggghts_executable() -> str:
    """Path of the ``liggghts`` command (``GRAINFORGE_LIGGGHTS`` overrides it).

    Returns
    -------
    str
        The command's absolute path.

    Raises
    ------
    FileNotFoundError
        If LIGGGHTS is not installed (Debian: ``apt-get install liggghts``).
    """
    from .process import find_executable

    return find_executable("GRAINFORGE_LIGGGHTS", "liggghts",
                           "LIGGGHTS is not installed (on Debian: apt-get install liggghts)")


def mpirun_executable() -> str:
    """Path of the ``mpirun`` command (``GRAINFORGE_MPIRUN`` overrides it).

    Returns
    -------
    str
        The command's absolute path.

    Raises
    ------
    FileNotFoundError
        If no MPI launcher is installed (Debian: ``apt-get install openmpi-bin``).
    """
    from .process import find_executable

    return find_executable("GRAINFORGE_MPIRUN", "mpirun",
                           "{mpi}: mpirun is not installed (on Debian: apt-get install openmpi-bin)", setting="mpi")


def restitution_of_local_damping(damping: float) -> float:
    """Restitution of a linear contact under Yade's local damping λ: e = √((1 − λ)/(1 + λ)).

    Local damping scales the force by 1 + λ while the contact closes (force
    against velocity) and by 1 − λ while it opens: the stored energy
    ½ k (1 + λ) δ² comes back as ½ k (1 − λ) δ².

    Examples
    --------
    >>> round(restitution_of_local_damping(0.3), 4)
    0.7338
    """
    return math.sqrt((1.0 - damping) / (1.0 + damping))


def contact_table(settings: Settings, r_grain: float, r_base: float, m_grain: float) -> dict:
    """Per type pair k_n, k_t, γ_n, γ_t of the ``hooke/stiffness`` contacts and the time step.

    Parameters
    ----------
    settings : Settings
        ``young`` (k_n = E r), ``poisson`` (k_t / k_n), ``damping`` (Yade's local damping λ).
    r_grain, r_base : float
        Mean contact-sphere radius of the grains, radius of the base spheres (m).
    m_grain : float
        Mean grain mass (kg): the effective mass of a grain pair is m/2, of a grain on the fixed
        base or a wall m.

    Returns
    -------
    dict
        ``kn``, ``kt``, ``gamman`` (3 × 3 nested lists, types GRAIN, BASE, WALL), ``restitution``,
        ``damping_ratio`` and ``k_max``.

    Notes
    -----
    Yade's ``Ip2_FrictMat_FrictMat_FrictPhys`` gives two spheres k_n = 2 E r₁ r₂ / (r₁ + r₂)
    (E r for equal spheres); ``hooke/stiffness`` takes one k_n per type pair, here that formula
    at the mean contact-sphere radius (exact for spheres of one size).  The damping is viscous
    (γ_n m_eff v_n, ``absolute_damping off``) with the damping ratio ζ whose restitution
    e = exp(−π ζ / √(1 − ζ²)) equals that of Yade's local damping
    (:func:`restitution_of_local_damping`): γ_n = 2 ζ √(k_n / m_eff).

    Examples
    --------
    >>> t = contact_table(Settings(), 1e-3, 3e-4, 4.9e-6)
    >>> t["kn"][0][0], round(t["kt"][0][0], 6), round(t["restitution"], 3)
    (1000.0, 300.0, 0.734)
    """
    E = settings.young
    k_gg = E * r_grain
    k_gb = 2.0 * E * r_grain * r_base / (r_grain + r_base)
    k_gw = E * r_grain
    e = restitution_of_local_damping(settings.damping)
    zeta = -math.log(e) / math.sqrt(math.pi ** 2 + math.log(e) ** 2)
    g_gg = 2.0 * zeta * math.sqrt(k_gg / (0.5 * m_grain))
    g_gb = 2.0 * zeta * math.sqrt(k_gb / m_grain)
    g_gw = 2.0 * zeta * math.sqrt(k_gw / m_grain)
    # pairs of two fixed things never touch: they take the grain pair's values
    kn = [[k_gg, k_gb, k_gw], [k_gb, k_gg, k_gg], [k_gw, k_gg, k_gg]]
    gn = [[g_gg, g_gb, g_gw], [g_gb, g_gg, g_gg], [g_gw, g_gg, g_gg]]
    return {"kn": kn, "kt": [[settings.poisson * k for k in row] for row in kn], "gamman": gn,
            "restitution": e, "damping_ratio": zeta, "k_max": max(k_gg, k_gb, k_gw)}


def _multisphere(t):
    """``t`` as LIGGGHTS takes it: it refuses a multisphere of one sphere ("illegal number of spheres"),
    so a one-sphere clump gets a second sphere of 1 % its radius at its centre, inside it: it never
    touches anything, and the mass and inertia stay the mesh's (given explicitly)."""
    import dataclasses

    c = t.clump
    if c.count > 1:
        return t
    inner = dataclasses.replace(c, centres=np.vstack([c.centres, c.centres[:1]]),
                                radii=np.append(c.radii, 0.01 * c.radii[0]))
    return dataclasses.replace(t, clump=inner)


def _seeds(count: int, seed: int) -> list[int]:
    """``count`` distinct primes for the random fixes of one deck, a different set for each seed."""
    from ..dem.liggghts import seed_table

    table = seed_table()
    if count > len(table):
        raise InputError(f"a deck needs {count} random seeds; the seed table holds {len(table)}")
    k = (np.arange(count, dtype=np.int64) * _STRIDE + int(seed) * 7919 * count) % len(table)
    return [int(x) for x in table[k]]


def _clear_of_cuts(x: np.ndarray, lo: float, length: float, margin: float) -> np.ndarray:
    """``x`` moved by a few ``margin`` (towards the middle) where it lies within ``margin`` of a cut of
    [lo, lo + length] into 1..MAX_CUTS equal parts (LIGGGHTS's processor columns) or of its ends (a
    periodic boundary is a cut too)."""
    cuts = np.unique(np.concatenate([lo + length * np.arange(0, p + 1) / p for p in range(1, MAX_CUTS + 1)]))
    x = np.array(x, dtype=np.float64)
    for _ in range(8):
        near = np.abs(x[:, None] - cuts[None, :]).min(axis=1) < margin
        if not near.any():
            return x
        x[near] += 2.5 * margin * np.where(x[near] < lo + 0.5 * length, 1.0, -1.0)
    raise AssertionError("insertion nodes could not be moved clear of the processor cuts")


def _settle(name: str, threshold: float, min_checks: int, max_checks: int, every: int, f0: float, f1: float,
            phase: str) -> str:
    """Input lines of a settle phase, as the Yade scenes' ``settle``: run ``every`` steps at a time until
    the kinetic energy ``ke`` is below ``threshold`` at three checks in a row past ``min_checks`` checks,
    or ``max_checks`` checks have run; leaves ``<name>_ke`` and prints progress per check (the template
    ``grainforge/dem/texts/liggghts-settle.in``)."""
    from ..dem.text import block

    return block("liggghts-settle.in", {"name": name, "f0": repr(f0), "df": repr(f1 - f0), "max_checks": max_checks,
                                        "every": every, "threshold": repr(threshold), "phase": phase,
                                        "min_checks": min_checks})


def _layout(templates: Sequence, test: str, settings: Settings, seed: int) -> dict:
    """The scene of one seed, as the Yade scene lays it out: the drawn templates, their nodes, the base."""
    rng = as_generator(np.random.SeedSequence([int(seed), 28]))  # the run's seed, stream 28: the layout
    counts = np.array([t.count for t in templates], dtype=np.float64)
    n = settings.grains
    pick = rng.choice(len(templates), size=n, p=counts / counts.sum())
    d_eq = np.array([t.d_eq for t in templates])[pick]
    d = float(d_eq.mean())
    cell = 2.05 * max(templates[k].bounding_radius for k in set(pick.tolist()))
    r_base = settings.base_roughness * d
    z0 = 2.2 * r_base + 0.5 * cell
    jitter = 0.1 * d * rng.uniform(-1.0, 1.0, size=(n, 2))
    geo = {"pick": pick, "d": d, "cell": cell, "r_base": r_base, "n": n}
    if test == "repose":
        volume = float(sum(templates[k].props.volume for k in pick))
        R = (volume / (0.5 * 2.0 * math.pi)) ** (1.0 / 3.0) + d
        k = int(R / cell)
        ii, jj = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
        xy = np.column_stack([ii.ravel(), jj.ravel()]) * cell
        xy = xy[np.hypot(xy[:, 0], xy[:, 1]) + 0.5 * cell <= R - 0.05 * d]
        if len(xy) == 0:
            xy = np.zeros((1, 2))
        q = np.arange(n)
        layer = q // len(xy)
        p = xy[q % len(xy)]
        turned = (layer % 2).astype(bool)
        c = 0.7071067811865476
        p = np.where(turned[:, None], np.column_stack([(p[:, 0] - p[:, 1]) * c, (p[:, 0] + p[:, 1]) * c]), p)
        nodes = np.column_stack([p + jitter, z0 + layer * cell])
        layers = int(layer.max()) + 1
        height = z0 + layers * cell + cell
        foot = (3.0 * volume / 0.55 / (math.pi * math.tan(math.radians(15.0)))) ** (1.0 / 3.0)
        half = max(foot, R) + 2.0 * d
        m = max(1, int(math.ceil(2.0 * half / (2.0 * r_base))))
        centres = -half + (np.arange(m) + 0.5) * 2.0 * half / m
        box = half + 4.0 * d
        geo.update(R=R, height=height, half=half, box=(-box, box, -box, box), base_x=centres, base_y=centres,
                   fall=math.sqrt(2.0 * height / 9.81), top=2.0 * height + 2.0 * d + cell)
    else:
        per_row = max(2, int(round(math.sqrt(n / _layer_depth(settings)))))
        width = per_row * cell
        q = np.arange(n)
        i, j, layer = q % per_row, (q // per_row) % per_row, q // (per_row * per_row)
        odd = layer % 2
        x = (i + 0.5) * cell + 0.5 * cell * odd + jitter[:, 0]
        y = (j + 0.5) * cell + 0.5 * cell * odd + jitter[:, 1]
        nodes = np.column_stack([np.mod(x, width), np.mod(y, width), z0 + layer * cell])
        layers = int(layer.max()) + 1
        m = int(round(width / (2.0 * r_base)))
        centres = (np.arange(m) + 0.5) * width / m
        geo.update(width=width, box=(0.0, width, 0.0, width), base_x=centres, base_y=centres,
                   fall=math.sqrt(2.0 * (z0 + layers * cell) / 9.81), top=z0 + (layers + 4) * cell)
    x0, x1, y0, y1 = geo["box"]
    margin = 1e-4 * cell
    nodes[:, 0] = _clear_of_cuts(nodes[:, 0], x0, x1 - x0, margin)
    nodes[:, 1] = _clear_of_cuts(nodes[:, 1], y0, y1 - y0, margin)
    bx, by = np.meshgrid(geo["base_x"], geo["base_y"], indexing="ij")
    bz = r_base * (1.0 + 0.3 * rng.random(bx.size))
    geo.update(nodes=nodes, base=np.column_stack([bx.ravel(), by.ravel(), bz]))
    return geo


def _layer_depth(settings: Settings) -> float:
    """Depth of the tilt layer in grains (the Yade scene's ``layer_depth``)."""
    return float(scene_settings(settings, "tilt", 0)["layer_depth"])


def _plan(templates: Sequence, test: str, settings: Settings, seed: int) -> SimpleNamespace:
    """The numbers of one run's deck: the scene settings, the layout (:func:`_layout`), the drawn templates,
    the contacts (:func:`contact_table`), the time step, the kinetic-energy threshold and the checks."""
    for t in templates:
        if t.shape != "clump" or t.clump is None:
            raise InputError(f"the LIGGGHTS scenes take multisphere clumps; {t.name} has shape {t.shape!r}")
    scene = scene_settings(settings, test, seed)
    geo = _layout(templates, test, settings, seed)
    pick, d = geo["pick"], geo["d"]
    used = sorted(set(pick.tolist()))
    # contact radius: the mean contact sphere of the drawn grains; mass: the mean grain
    r_grain = float(np.mean([templates[k].clump.radii.mean() for k in pick]))
    m_mean = float(np.mean([templates[k].mass for k in pick]))
    m_min = min(templates[k].mass for k in used)
    table = contact_table(settings, r_grain, geo["r_base"], m_mean)
    dt = scene["dt_safety"] * math.sqrt(m_min / table["k_max"])
    g = scene["gravity"]
    total_mass = float(sum(templates[k].mass for k in pick))
    every = int(scene["check_every"])
    return SimpleNamespace(
        scene=scene, geo=geo, pick=pick, d=d, cell=geo["cell"], n=geo["n"], used=used, r_grain=r_grain,
        table=table, dt=dt, g=g, threshold=scene["ke_ratio"] * total_mass * g * d, every=every,
        max_checks=max(3, int(math.ceil(scene["max_time_factor"] * geo["fall"] / (every * dt)))))


def _grain_files(templates: Sequence, plan: SimpleNamespace, settings: Settings, seed: int) -> dict:
    """The drawn templates' sphere files, ``in.templates``, ``in.insert``, ``in.unfix`` and (if ``plan.geo`` has a
    ``base``) ``in.base``."""
    from ..dem.deck import exact_unit_quaternions, fmt, xyzr_text
    from ..dem.liggghts import node_insertion, template_fix

    used, geo = plan.used, plan.geo
    files: dict[str, str] = {}
    seeds = _seeds(2 * len(used) + plan.n, seed)
    tpl = ["# grainforge: one multisphere template per grain drawn (SI units), exact mesh mass and inertia"]
    for q, k in enumerate(used):
        t = _multisphere(templates[k])
        files[f"{t.name}.xyzr"] = xyzr_text(t.clump.centres, t.clump.radii, header=f"grainforge clump of {t.source or t.name}")
        # LIGGGHTS numbers the clump types of the drawn templates 1, 2, ... with no gap
        tpl.append(template_fix(t, q, seeds[q], atom_type=GRAIN))
        tpl.append(f"fix pdd{q + 1} all particledistribution/discrete {seeds[len(used) + q]} 1 pts{q + 1} 1.0")
    files["in.templates"] = "\n".join(tpl) + "\n"
    ins = ["# grainforge: every grain at its own node of the scene's lattice, uniformly random orientation"]
    clump_type = {k: q + 1 for q, k in enumerate(used)}
    # the scene's orientations (grains.json's, the same as the Yade scene's grain k), exactly unit for LIGGGHTS
    quats = exact_unit_quaternions(plan.scene["orientations"])
    for slot, (k, node) in enumerate(zip(plan.pick, geo["nodes"])):
        ins += node_insertion(slot, node, cell=plan.cell, seed=seeds[2 * len(used) + slot],
                              distribution=f"pdd{clump_type[int(k)]}", quat=quats[slot])
    files["in.insert"] = "\n".join(ins) + "\n"
    files["in.unfix"] = "\n".join(f"unfix i{slot}\nregion r{slot} delete" for slot in range(plan.n)) + "\n"
    if "base" not in geo:  # a scene without a rough base (the triaxial box)
        return files
    files["in.base"] = "\n".join([f"create_atoms {BASE} single {fmt(x)} {fmt(y)} {fmt(z)} units box"
                                  for x, y, z in geo["base"]]
                                 + [f"set type {BASE} diameter {fmt(2.0 * geo['r_base'])}",
                                    f"set type {BASE} density {fmt(settings.density)}"]) + "\n"
    return files


def contact_model(rolling_friction: float) -> str:
    """The ``pair_style gran`` / ``fix wall/gran`` model: :data:`CONTACT_MODEL`, with :data:`ROLLING_MODEL`
    when there is rolling resistance.

    Parameters
    ----------
    rolling_friction : float
        The settings' μ_r (0: none, the model as without the setting).

    Returns
    -------
    str
        The model words of the deck.

    Examples
    --------
    >>> contact_model(0.0)
    'model hooke/stiffness tangential history'
    >>> contact_model(0.1)
    'model hooke/stiffness tangential history rolling_friction epsd2'
    """
    return CONTACT_MODEL + (" " + ROLLING_MODEL if rolling_friction > 0 else "")


def rolling_table(rolling_friction: float, r_grain: float, r_base: float | None, walls: bool = True) -> list:
    """Per type pair (GRAIN, BASE, WALL) LIGGGHTS's coefficient of rolling friction for the limit moment
    μ_r F_n min(r₁, r₂) of Yade's ``CohFrictPhys``.

    LIGGGHTS limits the rolling moment to c F_n R*, R* = r₁r₂/(r₁+r₂) (r for a wall); the coefficient
    c = μ_r min(r₁, r₂)(r₁ + r₂)/(r₁ r₂) gives the same limit: 2 μ_r for two spheres of one size, μ_r for a
    sphere on a wall, at the mean contact-sphere radius (exact for spheres of one size).

    Parameters
    ----------
    rolling_friction : float
        μ_r.
    r_grain : float
        Mean contact-sphere radius of the grains (m).
    r_base : float or None
        Radius of the fixed base spheres (m); None: no base (the grains' pair value).
    walls : bool
        Whether the walls have rolling resistance (the triaxial box's frictionless walls have none).

    Returns
    -------
    list
        3 × 3 nested lists of coefficients.

    Examples
    --------
    >>> [round(c, 6) for c in rolling_table(0.1, 1e-3, 1e-3)[0]]
    [0.2, 0.2, 0.1]
    >>> [round(c, 6) for c in rolling_table(0.1, 1e-3, None, walls=False)[0]]
    [0.2, 0.2, 0.0]
    """
    def coefficient(r1, r2):
        return rolling_friction * min(r1, r2) * (r1 + r2) / (r1 * r2)

    c_gg = coefficient(r_grain, r_grain)
    c_gb = c_gg if r_base is None else coefficient(r_grain, r_base)
    c_gw = rolling_friction if walls else 0.0
    # pairs of two fixed things never touch: they take the grain pair's value
    return [[c_gg, c_gb, c_gw], [c_gb, c_gg, c_gg], [c_gw, c_gg, c_gg]]


def rolling_fix(table: list) -> str:
    """The line after the ``coefficientFriction`` fix that sets the rolling friction per type pair.

    Parameters
    ----------
    table : list
        :func:`rolling_table`'s 3 × 3 coefficients.

    Returns
    -------
    str
        A newline and the ``fix ... property/global coefficientRollingFriction`` command.

    Examples
    --------
    >>> rolling_fix(rolling_table(0.1, 1e-3, None, walls=False)).split()[:6]
    ['fix', 'rf', 'all', 'property/global', 'coefficientRollingFriction', 'peratomtypepair']
    """
    return "\nfix rf all property/global coefficientRollingFriction peratomtypepair 3 " + _per_type_pair(table)


def _per_type_pair(values) -> str:
    """A 3 × 3 per-type-pair table as ``property/global ... peratomtypepair 3`` takes it (row by row)."""
    from ..dem.deck import fmt

    return " ".join(fmt(values[a][b]) for a in range(3) for b in range(3))


def _head_values(test: str, seed: int, plan: SimpleNamespace, settings: Settings) -> dict:
    """The values of ``liggghts-scene-head.in``: box, contacts per type pair, time step, gravity."""
    from ..dem.deck import fmt
    from ..dem.text import block

    x0, x1, y0, y1 = plan.geo["box"]
    table = plan.table
    return {"test": test, "seed": seed, "boundary": "p p f" if test == "tilt" else "f f f",
            "x0": fmt(x0), "x1": fmt(x1), "y0": fmt(y0), "y1": fmt(y1), "z0": fmt(-plan.cell),
            "z1": fmt(plan.geo["top"]), "skin": fmt(0.25 * plan.d), "kn": _per_type_pair(table["kn"]),
            "kt": _per_type_pair(table["kt"]), "gamman": _per_type_pair(table["gamman"]),
            "gammat": _per_type_pair(table["gamman"]), "friction": " ".join([fmt(settings.friction)] * 9),
            "rolling": (rolling_fix(rolling_table(settings.rolling_friction, plan.r_grain, plan.geo["r_base"]))
                        if settings.rolling_friction > 0 else ""),
            "model": contact_model(settings.rolling_friction), "options": CONTACT_OPTIONS, "dt": fmt(plan.dt),
            "gravity": fmt(plan.g), "base_type": BASE, "multisphere": block("liggghts-multisphere.in"), "every": plan.every}


def _repose_values(plan: SimpleNamespace) -> dict:
    """The values of ``liggghts-repose.in`` beyond the shared parts: the walls, the fill and the collapse.

    The cylinder: LIGGGHTS 3.8 as packaged can neither move a mesh wall (any fix move/mesh stops with
    "Illegal situation in MultiNodeMesh::registerMove") nor swap mesh walls during a run (a crash), so the
    cylinder is a primitive granular wall, removed at once where the Yade scene lifts it."""
    from ..dem.deck import fmt

    x0, x1, y0, y1 = plan.geo["box"]
    fall_checks = plan.geo["fall"] / (plan.every * plan.dt)
    return {"x0": fmt(x0), "x1": fmt(x1), "y0": fmt(y0), "y1": fmt(y1), "radius": fmt(plan.geo["R"]),
            "fill": _settle("fill", 10.0 * plan.threshold, int(math.ceil(3.0 * fall_checks)), plan.max_checks,
                            plan.every, 0.0, 0.3, "fill"),
            "dt": fmt(plan.dt),
            "collapse": _settle("collapse", plan.threshold, int(math.ceil(0.5 * fall_checks)), plan.max_checks,
                                plan.every, 0.7, 1.0, "collapse"),
            "threshold": repr(plan.threshold)}


def _tilt_values(plan: SimpleNamespace) -> dict:
    """The values of ``liggghts-tilt.in`` beyond the shared parts: the roof, the deposit and the tilt steps."""
    from ..dem.deck import fmt

    scene, d, g, dt = plan.scene, plan.d, plan.g, plan.dt
    hold = max(1, int(scene["tilt_hold"] * math.sqrt(d / g) / dt))
    start, step = scene["tilt_start_deg"], scene["tilt_step_deg"]
    deposit_min = int(math.ceil(3.0 * plan.geo["fall"] / (plan.every * dt)))
    return {"roof": fmt(plan.geo["top"] - 0.5 * plan.cell),
            "deposit": _settle("deposit", 10.0 * plan.threshold, deposit_min, plan.max_checks, plan.every, 0.0, 0.3,
                               "deposit"),
            "hold": hold, "tilts": max(1, int(math.ceil((89.0 - start) / step))), "start": repr(start),
            "step": repr(step), "gravity": fmt(g), "hold_time": fmt(hold * dt), "d": fmt(d),
            "v_scale": fmt(math.sqrt(g * d)), "failure": repr(scene["failure_displacement"])}


def _run_text(test: str, seed: int, plan: SimpleNamespace, settings: Settings) -> str:
    """``in.run``: the template ``liggghts-<test>.in`` with the shared head, insertion and final dumps."""
    from ..dem.text import block, render

    own = _repose_values(plan) if test == "repose" else _tilt_values(plan)
    return render(f"liggghts-{test}.in", {
        "head": block("liggghts-scene-head.in", _head_values(test, seed, plan, settings)),
        "model": contact_model(settings.rolling_friction), "options": CONTACT_OPTIONS, "wall_type": WALL,
        "insert": block("liggghts-scene-insert.in"), "tail": block("liggghts-scene-tail.in", {"grain_type": GRAIN}),
        **own})


def run_deck_files(templates: Sequence, test: str, settings: Settings, seed: int) -> dict:
    """``{relative path: text}`` of the LIGGGHTS deck of one run of ``test`` (nothing written).

    Run from inside the folder with ``liggghts -in in.run`` or ``mpirun -np P liggghts -in in.run``.
    ``in.run`` is the template ``grainforge/dem/texts/liggghts-<test>.in`` whose ``@{head}``,
    ``@{insert}`` and ``@{tail}`` are the scenes' shared parts (``liggghts-scene-head.in``, ...) and whose
    settle phases are ``liggghts-settle.in``, every number computed and formatted here.

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Multisphere clumps (:func:`grainforge.simulate.build_population`).
    test : {"repose", "tilt"}
        The virtual test under gravity.
    settings : Settings
        The run's settings (SI units in the deck: m, kg, Pa, s; angles in degrees).
    seed : int
        The run's seed number (``settings.seed + k``), written into ``grains.json``: the grains drawn, their
        layout and orientations, and LIGGGHTS's random seeds (primes of the seed table) are derived from it.

    Returns
    -------
    dict of str to str
        Relative path → text (``in.run``, the grains' files, ``grains.json``); the same for the same templates,
        settings and seed.

    Raises
    ------
    ValueError
        If a template is not a multisphere clump.

    Notes
    -----
    The repose cylinder is a primitive granular wall (``zcylinder``, the grains' contact law)
    removed in one step after the fill, where the Yade scene lifts a facet cylinder at
    0.5 √(g d): LIGGGHTS 3.8 as packaged stops at any ``fix move/mesh`` ("Illegal situation in
    MultiNodeMesh::registerMove") and crashes when mesh walls are swapped during a run.  Every
    other step of the scenes follows the Yade text, with the differences of :func:`contact_table`.
    A fix added or removed between runs needs LIGGGHTS's set-up (``run N`` with ``pre yes``): a
    ``pre no`` run after it keeps the old fix lists and integrates nothing.
    """
    from ..dem.deck import json_text, template_record

    plan = _plan(templates, test, settings, seed)
    geo = plan.geo
    files = _grain_files(templates, plan, settings, seed)
    files["in.run"] = _run_text(test, seed, plan, settings)
    rec = {"test": test, "seed": int(seed), "grains": plan.n, "d_mean": plan.d,
           "base_top": 1.3 * geo["r_base"] + geo["r_base"], "base_sphere_radius": geo["r_base"], "dt": plan.dt,
           "ke_threshold": plan.threshold, "contact": plan.table, "contact_radius": plan.r_grain,
           "scene": plan.scene}
    if test == "repose":
        rec.update(cylinder_radius=geo["R"], base_half_width=geo["half"])
    else:
        rec.update(width=geo["width"])
    files["grains.json"] = json_text({"units": "SI (m, kg, s)", "engine": "liggghts", "result": rec,
                                      "grains": [template_record(templates[k]) for k in plan.used],
                                      "drawn": [templates[k].name for k in plan.pick]})
    return files


def write_test_deck(templates: Sequence, test: str, *, settings: Settings, seed: int, out: str | os.PathLike,
                    overwrite: bool = False) -> list[Path]:
    """Write the LIGGGHTS deck of one run of ``test`` into ``out`` (see :func:`run_deck_files`).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Multisphere clumps.
    test : {"repose", "tilt"}
        The virtual test under gravity.
    settings : Settings
        The run's settings.
    seed : int
        The run's seed number (:func:`run_deck_files`).
    out : path
        The deck's folder (created).
    overwrite : bool
        Replace a deck already in ``out``; otherwise one is refused.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    FileExistsError
        If ``out`` already holds a deck and ``overwrite`` is False.
    """
    from ..dem.deck import write_files

    return write_files(run_deck_files(templates, test, settings, seed), out, overwrite=overwrite)


def engine_command(mpi: int | None = None) -> tuple[list[str], dict]:
    """The command line and extra environment of a LIGGGHTS run, under ``mpirun -np mpi`` if given.

    Open MPI refuses to run as root and to start more ranks than cores unless told: both are
    allowed through its environment variables, and a waiting rank yields its core.

    Parameters
    ----------
    mpi : int, optional
        MPI ranks; None runs LIGGGHTS alone.

    Returns
    -------
    cmd : list of str
        The command line, run from inside the deck's folder.
    env : dict
        Environment variables to add (Open MPI's, empty without ``mpirun``).

    Raises
    ------
    FileNotFoundError
        If LIGGGHTS (or, with ``mpi``, ``mpirun``) is not installed.
    """
    exe = liggghts_executable()
    if mpi is None:
        return [exe, "-in", "in.run", "-log", "none"], {}
    env = {"OMPI_MCA_mpi_yield_when_idle": "1"}
    from ..runtime.workers import default_workers

    if mpi > default_workers():  # more ranks than CPUs
        env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return [mpirun_executable(), "-np", str(int(mpi)), exe, "-in", "in.run", "-log", "none"], env


def _rows(path: Path, columns: int) -> np.ndarray:
    """The numeric rows of a LIGGGHTS dump or print file (header lines skipped)."""
    rows = []
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) != columns:
            continue
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            continue
    return np.array(rows, dtype=np.float64).reshape(-1, columns)


def _record(path: Path) -> dict:
    words = path.read_text().split()
    return {k: float(v) for k, v in zip(words[::2], words[1::2])}


def collect_result(deck: str | os.PathLike) -> dict:
    """The Yade scene's ``result.json`` record, from a finished LIGGGHTS run's files (and written there)."""
    deck = Path(deck)
    rec = dict(json.loads((deck / "grains.json").read_text())["result"])
    initial = _rows(deck / "bodies-initial.txt", 4)
    final = _rows(deck / "bodies-final.txt", 4)
    spheres = _rows(deck / "spheres-final.txt", 4)
    run = _record(deck / "record.txt")
    lost = len(initial) - len(final) + int(np.sum(final[:, 3] < 0.0))
    out = {k: rec[k] for k in ("test", "grains", "d_mean", "base_top", "base_sphere_radius")}
    out.update(inserted=len(initial), lost=lost, steps=int(run["steps"]), time=run["steps"] * rec["dt"],
               dt=rec["dt"])
    if rec["test"] == "repose":
        out.update(cylinder_radius=rec["cylinder_radius"], base_half_width=rec["base_half_width"],
                   kinetic_energy=run["kinetic_energy"], ke_threshold=rec["ke_threshold"],
                   settled=bool(run["settled"]), t_fill=run["t_fill"], t_lift=run["t_lift"])
    else:
        hist = _rows(deck / "history.txt", 3) if (deck / "history.txt").is_file() else np.zeros((0, 3))
        out.update(width=rec["width"], failure_angle=None if run["failed"] < 0 else run["failed"],
                   history=hist.tolist())
    # the Yade record's fifth column is the clump id; LIGGGHTS's dump gives the spheres in atom order
    out["spheres"] = np.column_stack([spheres, np.full(len(spheres), -1.0)]).tolist()
    (deck / "result.json").write_text(json.dumps(out))
    return out


def run_liggghts(deck: str | os.PathLike, *, mpi: int | None = None,
                 progress: Callable[[float, str], None] | None = None, timeout: float | None = None,
                 collect: Callable[[Path], dict] | None = None) -> dict:
    """Run the deck in ``deck`` (``liggghts -in in.run``, under ``mpirun -np mpi`` if given); its result, made by
    ``collect(deck)`` (default :func:`collect_result`; a triaxial deck's:
    :func:`grainforge.simulate.liggghts_triaxial.collect_triaxial`).

    The deck's ``grainforge-progress`` lines go to ``progress(fraction, phase)``; LIGGGHTS's output to
    ``deck/liggghts.log``.  An interrupt kills mpirun with every rank, and removes its session folder
    (:func:`grainforge.simulate.process.mpi_session_folder`).

    Parameters
    ----------
    deck : path
        The deck's folder (:func:`write_test_deck`).
    mpi : int, optional
        MPI ranks under ``mpirun``; None runs LIGGGHTS alone.
    progress : callable, optional
        ``progress(fraction, phase)`` for each progress line of the deck.
    timeout : float, optional
        Seconds to wait for the engine after its output has ended; None waits for ever.
    collect : callable, optional
        ``collect(deck)`` → the run's result.

    Returns
    -------
    dict
        The run's result (lengths in m, times in s), as ``collect`` makes it.

    Raises
    ------
    EngineFailed
        If LIGGGHTS exits with an error or writes no final state.
    """
    from contextlib import nullcontext

    from .process import EngineFailed, mpi_session_folder, run_engine_process

    deck = Path(deck)
    cmd, env = engine_command(mpi)
    # mpirun's session folder in one of this run's own, removed after the run (a killed mpirun leaves its own)
    with mpi_session_folder() if mpi is not None else nullcontext({}) as session:
        rc = run_engine_process(cmd, deck, log_path=deck / "liggghts.log", env={**env, **session}, progress=progress,
                                timeout=timeout)
    needed = ("record.txt", "bodies-initial.txt", "bodies-final.txt", "spheres-final.txt")
    if rc != 0 or not all((deck / f).is_file() for f in needed):
        tail = [ln.strip() for ln in (deck / "liggghts.log").read_text(errors="replace").splitlines() if ln.strip()]
        raise EngineFailed(f"LIGGGHTS failed in {deck} (exit {rc}): {tail[-1] if tail else 'no output'}", deck)
    return (collect or collect_result)(deck)
