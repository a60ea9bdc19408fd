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
  template into its own cell of a lattice above the box (random orientation);
- ``in.run``: the example — a box under gravity, Hertz contacts, VTK output in
  ``post/``, run until the multisphere kinetic energy falls below
  ``ke_threshold`` (J) at three checks in a row (docs/dem.md), writing ``bodies-initial.txt`` / ``bodies-final.txt``
  (id, clump type, mass, xcm, principal inertia per body) and ``settle.txt``; its last line
  is ``SETTLED in N steps`` or ``NOT SETTLED after N steps (KE … > … J)`` (exit status 1).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from .deck import (GRAVITY, clump_vtk_text, fmt, json_text, settle_loop, settle_report, settle_schedule,
                   settle_settings, template_record, updated_settings, write_files, xyzr_text)

__all__ = ["write_deck", "deck_files", "pour_settings"]

_PRIMES = (15485863, 15485867, 32452843, 32452867, 49979687, 49979693, 67867967, 67867979, 86028121, 86028157)


def pour_settings(**kw) -> dict:
    """Default settings of the example pour (SI), updated with ``kw``."""
    s = {"young": 5e6, "poisson": 0.3, "restitution": 0.3, "friction": 0.5, "dt_safety": 0.3,
         **settle_settings(), "vtk_every": 5000}
    return updated_settings(s, kw, "pour settings")


def _seed(k: int) -> int:
    """A distinct prime > 10000 for the k-th random fix (LIGGGHTS wants primes)."""
    base = _PRIMES[k % len(_PRIMES)]
    return base + 0 if k < len(_PRIMES) else _next_prime(base + 1000 * (k // len(_PRIMES)))


_WITNESSES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37)


def _is_prime(n: int) -> bool:
    """Whether ``n`` is prime: Miller–Rabin with the first twelve primes as witnesses, exact for
    n < 3.3e24 (Sorenson & Webster 2015); decks need primes below 1e10.

    Examples
    --------
    >>> [k for k in range(30) if _is_prime(k)]
    [2, 3, 5, 7, 11, 13, 17, 19, 23, 29]
    """
    if n < 2:
        return False
    for p in _WITNESSES:
        if n % p == 0:
            return n == p
    d, r = n - 1, 0
    while d % 2 == 0:
        d //= 2
        r += 1
    for a in _WITNESSES:
        x = pow(a, d, n)
        if x == 1 or x == n - 1:
            continue
        for _ in range(r - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


def _next_prime(n: int) -> int:
    """The smallest prime ≥ ``n`` (``n`` itself if odd and prime), for odd candidates from ``n`` up."""
    n += 1 - n % 2
    while not _is_prime(n):
        n += 2
    return n


def deck_files(templates: Sequence, *, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a LIGGGHTS deck (nothing written)."""
    s = settings or pour_settings()
    files: dict[str, str] = {}
    tpl = ["# grainforge: one multisphere template per grain (SI units), exact mesh mass and inertia",
           "# inertia_tensor Ixx Ixy Ixz Iyy Iyz Izz about the centroid, grain frame (kg m^2)"]
    names, masses = [], []
    for k, t in enumerate(templates):
        if t.shape != "clump" or t.clump is None:
            raise ValueError(f"the LIGGGHTS deck writes multisphere clumps; {t.name} has shape {t.shape!r}")
        head = (f"grainforge clump of {t.source or t.name}: x y z r (m), centroid at the origin\n"
                f"spheres {t.clump.count}, coverage {t.clump.coverage:.4f}, spill {t.clump.spill:.4f}")
        files[f"{t.name}.xyzr"] = xyzr_text(t.clump.centres, t.clump.radii, header=head)
        files[f"{t.name}.clump.vtk"] = clump_vtk_text(t.clump.centres, t.clump.radii, f"grainforge clump {t.name}")
        I = t.inertia
        tensor = " ".join(fmt(x) for x in (I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]))
        tpl.append(f"fix pts{k + 1} all particletemplate/multisphere {_seed(k)} atom_type 1 "
                   f"density constant {fmt(t.density)} nspheres {t.clump.count} ntry 1000000 "
                   f"spheres file {t.name}.xyzr scale 1.0 type {k + 1} "
                   f"mass {fmt(t.mass)} inertia_tensor {tensor} use_density")
        names.append(f"pts{k + 1}")
        masses.append(t.mass * t.count)
    frac = np.asarray(masses) / np.sum(masses)
    frac_text = [f"{x:.17g}" for x in frac]
    # the fractions must sum to 1 in LIGGGHTS' check; put the round-off on the largest
    frac_text[int(np.argmax(frac))] = f"{1.0 - (frac.sum() - frac.max()):.17g}"
    tpl.append(f"fix pdd all particledistribution/discrete {_seed(len(templates))} {len(templates)} "
               + " ".join(f"{n} {f}" for n, f in zip(names, frac_text)))
    files["in.templates"] = "\n".join(tpl) + "\n"

    # lattice of insertion cells above the box: one per population member
    n = sum(t.count for t in templates)
    cell = 2.2 * max(t.bounding_radius for t in templates)
    side = max(1, math.ceil(math.sqrt(n / 6.0)))
    width = side * cell
    layers = math.ceil(n / (side * side))
    rmin = min(float(t.clump.radii.min()) for t in templates)
    dt = s["dt_safety"] * rmin * math.sqrt(max(t.density for t in templates) / s["young"])
    total_mass = sum(t.mass * t.count for t in templates)
    mean_d = sum(t.d_eq * t.count for t in templates) / n
    ke_threshold = s["ke_ratio"] * total_mass * GRAVITY * mean_d
    # the highest insertion cell's top: where the last grain can start
    sched = settle_schedule(dt, (layers + 0.5) * cell, mean_d, s)
    ins = ["# grainforge: insert every grain `count` times, each copy into its own lattice cell"]
    slot = 0
    for k, t in enumerate(templates):
        ins.append(f"fix pdd{k + 1} all particledistribution/discrete {_seed(len(templates) + 1 + 2 * k)} 1 "
                   f"pts{k + 1} 1.0")
        for c in range(t.count):
            i, j, layer = slot % side, (slot // side) % side, slot // (side * side)
            lo = np.array([i * cell, j * cell, (layer + 0.5) * cell])
            hi = lo + cell
            ins.append(f"region r{slot} block {fmt(lo[0])} {fmt(hi[0])} {fmt(lo[1])} {fmt(hi[1])} "
                       f"{fmt(lo[2])} {fmt(hi[2])} units box")
            ins.append(f"fix i{slot} all insert/pack seed {_seed(len(templates) + 2 + 2 * k)} "
                       f"distributiontemplate pdd{k + 1} maxattempt 1000 insert_every once overlapcheck yes "
                       f"orientation random all_in no region r{slot} particles_in_region 1 ntry_mc 100000")
            slot += 1
    files["in.insert"] = "\n".join(ins) + "\n"

    top = (layers + 2) * cell
    run = f"""# LIGGGHTS deck written by grainforge. Run from inside this folder:  liggghts -in in.run
# Units: SI (m, kg, s). Grains are multisphere bodies with the mesh's exact mass and inertia.
atom_style sphere
atom_modify map array sort 0 0
boundary f f f
newton off
communicate single vel yes
units si

region domain block {fmt(-0.05 * cell)} {fmt(width + 0.05 * cell)} {fmt(-0.05 * cell)} {fmt(width + 0.05 * cell)} {fmt(-0.5 * cell)} {fmt(top)} units box
create_box 1 domain
neighbor {fmt(0.5 * rmin)} bin
neigh_modify delay 0

fix m1 all property/global youngsModulus peratomtype {fmt(s["young"])}
fix m2 all property/global poissonsRatio peratomtype {fmt(s["poisson"])}
fix m3 all property/global coefficientRestitution peratomtypepair 1 {fmt(s["restitution"])}
fix m4 all property/global coefficientFriction peratomtypepair 1 {fmt(s["friction"])}
pair_style gran model hertz tangential history
pair_coeff * *
timestep {fmt(dt)}
fix gravi all gravity 9.81 vector 0.0 0.0 -1.0
fix floor all wall/gran model hertz tangential history primitive type 1 zplane 0.0
fix wx0 all wall/gran model hertz tangential history primitive type 1 xplane 0.0
fix wx1 all wall/gran model hertz tangential history primitive type 1 xplane {fmt(width)}
fix wy0 all wall/gran model hertz tangential history primitive type 1 yplane 0.0
fix wy1 all wall/gran model hertz tangential history primitive type 1 yplane {fmt(width)}

include in.templates
include in.insert
fix ms all multisphere

compute kems all ke/multisphere
compute erms all erotate/multisphere
variable ke equal c_kems+c_erms
variable kethr equal {fmt(ke_threshold)}
compute bid all multisphere property id_multisphere
compute btype all multisphere property clumptype
compute bmass all multisphere property masstotal
compute bx all multisphere property xcm
compute binert all multisphere property inertia
compute bv all multisphere property vcm
thermo_style custom step atoms c_kems c_erms
thermo {sched["check_every"]}
thermo_modify lost ignore norm no

run 1
dump bodies0 all local 1 bodies-initial.txt c_bid c_btype c_bmass c_bx[1] c_bx[2] c_bx[3] c_binert[1] c_binert[2] c_binert[3]
dump_modify bodies0 format "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g"
dump atoms0 all custom 1 atoms-initial.txt id x y z radius
dump_modify atoms0 format "%d %.17g %.17g %.17g %.17g"
run 1
undump bodies0
undump atoms0

dump vtk all custom/vtk {s["vtk_every"]} post/grains_*.vtk id type x y z vx vy vz radius
{settle_loop(sched["fall_steps"], sched["check_every"], sched["max_checks"], s["settle_checks"])}
dump bodies1 all local 1 bodies-final.txt c_bid c_btype c_bmass c_bx[1] c_bx[2] c_bx[3] c_bv[1] c_bv[2] c_bv[3]
dump_modify bodies1 format "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g"
run 1
# the last line: SETTLED in N steps, or NOT SETTLED after N steps (KE ... > ... J) and exit
# status 1 (LIGGGHTS's quit takes no status and always exits 1)
{settle_report("", "quit")}
"""
    files["in.run"] = run
    deck = {"units": "SI (m, kg, s)", "grains": [template_record(t) for t in templates],
            "box": [width, width], "ke_threshold": ke_threshold, "dt": dt, "settle": sched, "scene": s}
    files["grains.json"] = json_text(deck)
    return files


def write_deck(templates: Sequence, out: str | Path, *, settings: dict | None = None,
               overwrite: bool = False) -> list[Path]:
    """Write a LIGGGHTS deck for ``templates`` into ``out`` (see the module text)."""
    return write_files(deck_files(templates, settings=settings), out, overwrite=overwrite)
