"""LIGGGHTS-PUBLIC deck: multisphere templates carrying the grain's exact mass and inertia.

``write_deck(templates, out)`` writes, run from inside ``out`` with
``liggghts -in in.run``:

- ``<grain>.xyzr`` (the template's spheres: ``x y z r`` in metres, the mesh
  centroid at the origin — LIGGGHTS takes the file origin as the centre of
  mass when ``mass`` is given) and ``<grain>.clump.vtk`` per grain;
- ``in.templates``: one ``fix particletemplate/multisphere`` per grain with
  ``mass`` (kg) and ``inertia_tensor`` (kg m², the grain's frame) from the
  mesh and ``use_density``; then ``fix particledistribution/discrete pdd``
  over all templates by **mass fraction** (the population's size/shape
  distribution);
- ``in.insert``: the example's insertion — every grain ``count`` times, each
  copy by its own ``insert/pack`` at its own node of a lattice above the box
  (random orientation); every random fix has its own prime seed
  (:func:`deck_seeds`);
- ``in.run``: the example (the template ``grainforge/dem/texts/liggghts-pour.in``, filled by
  :func:`deck_files`) — a box under gravity, Hertz contacts, VTK output in
  ``post/``, run until the multisphere kinetic energy falls below
  ``ke_threshold`` (J) at three checks in a row (docs/dem.md), writing ``bodies-initial.txt`` /
  ``bodies-final.txt`` (id, clump type, mass, xcm, principal inertia per body) and ``settle.txt``;
  its last line is ``SETTLED in N steps`` or ``NOT SETTLED after N steps (KE … > … J)`` (exit
  status 1). It runs as written under ``mpirun -np P`` too (columns of ranks; see the notes above
  ``_NODE_BOX``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from .deck import (
    GRAVITY,
    clump_vtk_text,
    exact_unit_quaternions,
    fmt,
    grain_orientations,
    json_text,
    settle_loop,
    settle_report,
    settle_schedule,
    settle_settings,
    template_record,
    updated_settings,
    write_files,
    xyzr_text,
)
from .text import block, render

__all__ = ["write_deck", "deck_files", "pour_settings", "template_fix", "node_insertion", "seed_table", "deck_seeds",
           "SEED_MIN", "SEED_LIMIT", "MULTISPHERE_SETUP"]  # noqa: F822

#: LIGGGHTS takes a random seed only if it is a prime > 10000 (it stops otherwise), and the seeds
#: of an insertion fix, its particle distribution and that distribution's templates must differ
SEED_MIN = 10000
#: seeds are drawn from the primes SEED_MIN < p < SEED_LIMIT (far below INT_MAX, which LIGGGHTS
#: also checks after adding the MPI rank to some seeds); its 347,284 primes cover the largest deck,
#: 2 × templates + 1 + grains ≤ 300,001 seeds for a pour of MAX_POUR_GRAINS
SEED_LIMIT = 5_000_000
# seed j is prime number (j * _SEED_STRIDE) mod len(table) of the table: a stride coprime to the
# table's length (a prime larger than it) visits every entry once, and spreads neighbouring seeds
# over the whole range (Park-Miller streams of close seeds start with close numbers)
_SEED_STRIDE = 1_000_003

# Under MPI (mpirun -np P liggghts -in in.run) ``processors * * 1`` cuts the box into columns,
# P_x × P_y equal parts of its x and y extent. An insertion fix whose region spans two parts
# lets each rank decide on its own whether to insert (LIGGGHTS adds a random number in [0, 1)
# to the rank's share of the region), which can insert a grain twice or not at all. So every
# region is a box of _NODE_BOX cells around its lattice node (``volume_limit`` below its volume:
# LIGGGHTS refuses so small a region otherwise), and the box margins beyond the
# walls (lower _MARGIN_LO, upper _MARGIN_HI cells, an irrational ratio) keep every cut of up to
# 32 parts per side at least 4e-5 cells away from every node of a lattice up to 300 cells
# wide (tests/dem/test_dem.py) — 400 times the region's half-width.
_NODE_BOX = 2e-7
_MARGIN_LO = 0.05
_MARGIN_HI = 0.05 * (1 + math.sqrt(5)) / 2


def template_fix(t, k: int, seed: int, atom_type: int = 1) -> str:
    """The ``fix pts<k+1> ... particletemplate/multisphere`` line of template ``t`` (clump type ``k + 1``):
    the spheres of ``<name>.xyzr``, the mesh's exact mass and inertia tensor (grain frame).

    Parameters
    ----------
    t : GrainTemplate
        A clump template (SI units: mass kg, inertia kg m², density kg/m³, volume m³).
    k : int
        The template's index (0, 1, ...): the fix is ``pts<k+1>``, its clump type ``k + 1``.
    seed : int
        LIGGGHTS's own random seed of the fix, written into the line (a prime > :data:`SEED_MIN` from
        :func:`deck_seeds`, distinct from the deck's other seeds); no random number is drawn here.
    atom_type : int
        The atom type of the template's spheres (1: the grains' material).

    Returns
    -------
    str
        One input line, without a newline.
    """
    I = t.inertia
    tensor = " ".join(fmt(x) for x in (I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]))
    # LIGGGHTS refuses a template below volume_limit (default 1e-12 m³, a 12 µm sphere) as a
    # likely unit error; grainforge's volumes are exact and in SI, so the limit sits far below
    return (f"fix pts{k + 1} all particletemplate/multisphere {seed} atom_type {atom_type} "
            f"density constant {fmt(t.density)} volume_limit {fmt(1e-3 * t.props.volume)} "
            f"nspheres {t.clump.count} ntry 1000000 "
            f"spheres file {t.name}.xyzr scale 1.0 type {k + 1} "
            f"mass {fmt(t.mass)} inertia_tensor {tensor} use_density")


def node_insertion(slot: int, node, *, cell: float, seed: int, distribution: str, quat) -> list[str]:
    """The region and ``insert/pack`` lines that insert one grain of ``distribution`` at ``node``
    in the orientation ``quat`` (``w x y z``, a row of :func:`grainforge.dem.deck.grain_orientations` made
    exactly unit by :func:`grainforge.dem.deck.exact_unit_quaternions`), within a box of ``_NODE_BOX`` cells
    around it (see the notes above ``_NODE_BOX``).

    LIGGGHTS's own ``orientation random`` turns the template by three angles each uniform in [0, 2π): not
    uniformly random, so the deck gives every grain its orientation instead.

    Parameters
    ----------
    slot : int
        The grain's index in the deck's insertion order: names the region ``r<slot>`` and the fix ``i<slot>``.
    node : (3,) array_like of float
        The lattice node the grain's centre of mass is inserted at, m.
    cell : float
        The lattice spacing, m (the region is ``_NODE_BOX · cell`` wide).
    seed : int
        LIGGGHTS's own random seed of the ``insert/pack`` fix, written into the deck (a prime from
        :func:`deck_seeds`); no random number is drawn here.
    distribution : str
        The ID of the ``particledistribution/discrete`` fix the grain is taken from (one template).
    quat : (4,) array_like of float
        The grain's orientation ``w x y z``, of exactly unit norm.

    Returns
    -------
    list of str
        The ``region`` line and the ``fix ... insert/pack`` line.
    """
    lo, hi = np.asarray(node) - 0.5 * _NODE_BOX * cell, np.asarray(node) + 0.5 * _NODE_BOX * cell
    return [f"region r{slot} block {fmt(lo[0])} {fmt(hi[0])} {fmt(lo[1])} {fmt(hi[1])} "
            f"{fmt(lo[2])} {fmt(hi[2])} units box volume_limit {fmt(0.5 * (_NODE_BOX * cell) ** 3)}",
            f"fix i{slot} all insert/pack seed {seed} "
            f"distributiontemplate {distribution} insert_every once overlapcheck no "
            f"orientation constant {' '.join(fmt(x) for x in quat)} all_in no region r{slot} particles_in_region 1 "
            "ntry_mc 1000"]


def __getattr__(name):
    # MULTISPHERE_SETUP: input lines that insert the grains as multisphere bodies and define their kinetic energy
    # ``ke`` (J), the template grainforge/dem/texts/liggghts-multisphere.in (package data)
    if name == "MULTISPHERE_SETUP":
        return block("liggghts-multisphere.in")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def pour_settings(**kw) -> dict:
    """Default settings of the example pour (SI), updated with ``kw``.

    Parameters
    ----------
    **kw
        Settings to change: ``seed`` (int: the grains' orientations, drawn in Python; default 0; LIGGGHTS's
        own seeds come from :func:`deck_seeds`), ``young`` (Young's modulus, Pa), ``poisson`` (Poisson's
        ratio), ``restitution`` (coefficient, in (0, 1)), ``friction`` (contact friction coefficient),
        ``dt_safety`` (time step as a share of the smallest sphere's Rayleigh-like time
        ``r_min sqrt(ρ / E)``), ``vtk_every`` (steps between VTK dumps) and those of
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
    >>> pour_settings(young=1e7)["young"], pour_settings()["seed"]
    (10000000.0, 0)
    """
    s = {"seed": 0, "young": 5e6, "poisson": 0.3, "restitution": 0.3, "friction": 0.5, "dt_safety": 0.3,
         **settle_settings(), "vtk_every": 5000}
    return updated_settings(s, kw, "pour settings")


@functools.lru_cache(maxsize=1)
def seed_table() -> np.ndarray:
    """The primes ``SEED_MIN < p < SEED_LIMIT`` in ascending order (sieve of Eratosthenes), read-only.

    Returns
    -------
    (347284,) int64
        The primes, a read-only array computed once per process.

    Examples
    --------
    >>> seed_table()[:4].tolist(), len(seed_table())
    ([10007, 10009, 10037, 10039], 347284)
    """
    sieve = np.ones(SEED_LIMIT, dtype=bool)
    sieve[:2] = False
    for p in range(2, math.isqrt(SEED_LIMIT - 1) + 1):
        if sieve[p]:
            sieve[p * p::p] = False
    table = np.flatnonzero(sieve[SEED_MIN + 1:]) + SEED_MIN + 1
    table.setflags(write=False)
    return table


def deck_seeds(count: int) -> list[int]:
    """``count`` distinct primes in ``(SEED_MIN, SEED_LIMIT)`` for the random fixes of one deck.

    Distinct by construction (different entries of :func:`seed_table`) and the
    same for the same ``count``.

    Parameters
    ----------
    count : int
        Seeds wanted (≥ 0): one per random fix of the deck.

    Returns
    -------
    list of int
        Seed ``j`` is entry ``(j · 1000003) mod len(table)`` of :func:`seed_table`: the first seeds of a
        larger count are those of a smaller one.

    Raises
    ------
    ValueError
        If the table holds fewer than ``count`` primes.

    Examples
    --------
    >>> deck_seeds(3)
    [10007, 4359001, 3721379]
    """
    table = seed_table()
    if count > len(table):
        raise InputError(f"a deck needs {count} random seeds; the seed table holds {len(table)}")
    return [int(x) for x in table[(np.arange(count, dtype=np.int64) * _SEED_STRIDE) % len(table)]]


def _template_files(templates: Sequence, seeds: list[int]) -> dict:
    """The grains' sphere files and ``in.templates``: one multisphere template per grain, and the
    distribution ``pdd`` over them by mass fraction."""
    files: dict[str, str] = {}
    n_t = len(templates)
    tpl = ["# grainforge: one multisphere template per grain (SI units), exact mesh mass and inertia",
           "# inertia_tensor Ixx Ixy Ixz Iyy Iyz Izz about the centroid, grain frame (kg m^2)"]
    names, masses = [], []
    for k, t in enumerate(templates):
        if t.shape != "clump" or t.clump is None:
            raise InputError(f"the LIGGGHTS deck writes multisphere clumps; {t.name} has shape {t.shape!r}")
        head = (f"grainforge clump of {t.source or t.name}: x y z r (m), centroid at the origin\n"
                f"spheres {t.clump.count}, coverage {t.clump.coverage:.4f}, spill {t.clump.spill:.4f}")
        files[f"{t.name}.xyzr"] = xyzr_text(t.clump.centres, t.clump.radii, header=head)
        files[f"{t.name}.clump.vtk"] = clump_vtk_text(t.clump.centres, t.clump.radii, f"grainforge clump {t.name}")
        tpl.append(template_fix(t, k, seeds[k]))
        names.append(f"pts{k + 1}")
        masses.append(t.mass * t.count)
    frac = np.asarray(masses) / np.sum(masses)
    frac_text = [f"{x:.17g}" for x in frac]
    # the fractions must sum to 1 in LIGGGHTS' check; put the round-off on the largest
    frac_text[int(np.argmax(frac))] = f"{1.0 - (frac.sum() - frac.max()):.17g}"
    tpl.append(f"fix pdd all particledistribution/discrete {seeds[n_t]} {n_t} "
               + " ".join(f"{n} {f}" for n, f in zip(names, frac_text)))
    files["in.templates"] = "\n".join(tpl) + "\n"
    return files


def _insert_text(templates: Sequence, seeds: list[int], side: int, cell: float, seed: int) -> str:
    """``in.insert``: every grain ``count`` times, each copy at its own node of a lattice of ``side`` × ``side``
    cells per layer above the box, in its own uniformly random orientation."""
    n_t, n = len(templates), sum(t.count for t in templates)
    head = f"each copy at its own lattice node (within {_NODE_BOX:g} cells)"
    ins = [f"# grainforge: insert every grain `count` times, {head}, uniformly random orientation"]
    quats = exact_unit_quaternions(grain_orientations(n, seed))
    slot = 0
    for k, t in enumerate(templates):
        ins.append(f"fix pdd{k + 1} all particledistribution/discrete {seeds[n_t + 1 + k]} 1 "
                   f"pts{k + 1} 1.0")
        for _ in range(t.count):
            i, j, layer = slot % side, (slot // side) % side, slot // (side * side)
            node = np.array([i + 0.5, j + 0.5, layer + 1.0]) * cell
            ins += node_insertion(slot, node, cell=cell, seed=seeds[2 * n_t + 1 + slot], distribution=f"pdd{k + 1}",
                                  quat=quats[slot])
            slot += 1
    return "\n".join(ins) + "\n"


def deck_files(templates: Sequence, *, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a LIGGGHTS deck (nothing written).

    ``in.run`` is the template ``grainforge/dem/texts/liggghts-pour.in`` filled with the numbers computed
    here (:mod:`grainforge.dem.text`).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Clump templates (SI units), each inserted ``count`` times; the orientations are drawn from
        ``settings["seed"]`` (:func:`grainforge.dem.deck.grain_orientations`).
    settings : dict, optional
        The pour's settings (default :func:`pour_settings`), and ``rolling_friction`` (μ_r, only when > 0: the
        rolling resistance, ``rolling_friction epsd2``).

    Returns
    -------
    dict of str to str
        Relative path -> text: the files listed in the module text.

    Raises
    ------
    ValueError
        If a template is not a clump, or the deck needs more seeds than :func:`seed_table` holds.
    """
    s = settings or pour_settings()
    rolling = float(s.get("rolling_friction", 0.0))
    n_t = len(templates)
    n = sum(t.count for t in templates)
    # one distinct seed per random fix: templates, the mass-fraction distribution, one distribution
    # per template, one insertion per grain (each copy its own orientation)
    seeds = deck_seeds(2 * n_t + 1 + n)
    files = _template_files(templates, seeds)
    # lattice of insertion cells above the box: one per population member
    cell = 2.2 * max(t.bounding_radius for t in templates)
    side = max(1, math.ceil(math.sqrt(n / 6.0)))
    width = side * cell
    layers = math.ceil(n / (side * side))
    rmin = min(float(t.clump.radii.min()) for t in templates)
    dt = s["dt_safety"] * rmin * math.sqrt(max(t.density for t in templates) / s["young"])
    total_mass = sum(t.mass * t.count for t in templates)
    mean_d = sum(t.d_eq * t.count for t in templates) / n
    ke_threshold = s["ke_ratio"] * total_mass * GRAVITY * mean_d
    # the highest insertion node's top: where the last grain can start
    sched = settle_schedule(dt, top=(layers + 0.5) * cell, mean_d=mean_d, settings=s)
    files["in.insert"] = _insert_text(templates, seeds, side, cell, s.get("seed", 0))
    lo, hi = fmt(-_MARGIN_LO * cell), fmt(width + _MARGIN_HI * cell)
    files["in.run"] = render("liggghts-pour.in", {
        "x0": lo, "x1": hi, "y0": lo, "y1": hi, "z0": fmt(-0.5 * cell), "z1": fmt((layers + 2) * cell),
        "skin": fmt(0.5 * rmin), "young": fmt(s["young"]), "poisson": fmt(s["poisson"]),
        "restitution": fmt(s["restitution"]), "friction": fmt(s["friction"]), "dt": fmt(dt), "width": fmt(width),
        # rolling resistance (``rolling_friction`` μ_r, set only when > 0): grains and walls share atom type 1, whose
        # coefficient 2 μ_r gives two equal spheres the limit μ_r F_n r (a wall, where R* = r: 2 μ_r F_n r)
        "model": "model hertz tangential history" + (" rolling_friction epsd2" if rolling > 0 else ""),
        "rolling": (f"\nfix rf all property/global coefficientRollingFriction peratomtypepair 1 {fmt(2.0 * rolling)}"
                    if rolling > 0 else ""),
        "multisphere": block("liggghts-multisphere.in"), "ke_threshold": fmt(ke_threshold),
        "check_every": sched["check_every"], "vtk_every": s["vtk_every"],
        "settle_loop": settle_loop(sched["fall_steps"], sched["check_every"], sched["max_checks"],
                                   s["settle_checks"]),
        "settle_report": settle_report("", "quit")})
    deck = {"units": "SI (m, kg, s)", "grains": [template_record(t) for t in templates],
            "box": [width, width], "ke_threshold": ke_threshold, "dt": dt, "settle": sched, "scene": s}
    files["grains.json"] = json_text(deck)
    return files


def write_deck(templates: Sequence, out: str | Path, *, settings: dict | None = None,
               overwrite: bool = False) -> list[Path]:
    """Write a LIGGGHTS deck for ``templates`` into ``out`` (see the module text).

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
        As :func:`deck_files`.
    FileExistsError
        If a file of the deck exists and ``overwrite`` is false (nothing is written).
    """
    return write_files(deck_files(templates, settings=settings), out, overwrite=overwrite)
