"""LAMMPS deck of convex polyhedra: ``atom_style body rounded/polyhedron`` with the mesh's mass properties.

``write_deck(templates, out)`` writes, run from inside ``out`` with
``lmp -in in.run``:

- ``<grain>.poly``: the hull vertices (``x y z`` per line, m, centroid at the
  origin, the grain's own orientation) and ``<grain>.hull.vtk`` (the hull as a
  legacy-VTK polygon mesh, m);
- ``data.bodies``: the ``read_data`` file — per body the mesh's mass at its
  lattice position (``Atoms``) and in ``Bodies`` the inertia tensor, hull
  vertices, edges and triangular faces, rotated into the box frame (seeded
  random orientation), plus the rounded diameter;
- ``in.run``: the example pour (the template ``grainforge/dem/texts/lammps-body-pour.in``) —
  ``pair_style body/rounded/polyhedron``,
  ``fix wall/body/polyhedron`` floor and side walls, ``fix gravity``,
  ``fix nve/body``, a settle loop on translational + rotational kinetic energy,
  the engine's own state written back (``data.initial``, ``data.final``,
  ``settle.txt``) and vertex dumps in ``post/`` converted to VTK by
  ``dump2vtk.py`` (run by ``in.run`` through ``shell``); the last line is ``SETTLED in N steps``
  (exit status 0) or ``NOT SETTLED after N steps (KE … > … pg um^2/us^2, micro units = 1e-15 J)`` (exit
  status 1).

Units: the deck runs in LAMMPS ``units micro`` (µm, pg, µs; force nN, energy
10⁻¹⁵ J). The BODY package's contact code compares lengths with absolute
tolerances of 10⁻³ (in the input's length unit): in SI that is 1 mm, larger
than the contacts of millimetre grains, and contacts would be missed. In µm it
is 1 nm. ``grains.json`` keeps SI values and states the conversion.

LAMMPS's ``read_data`` reads at most 32 lines of at most 255 characters per
body (``MAXBODY``/``MAXLINE``); a hull that does not fit raises ``ValueError``
(use fewer ``--vertices``: 56 always fits).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InputError
from ..rng import as_generator
from .deck import (
    GRAVITY,
    fmt,
    json_text,
    lattice_slots,
    settle_loop,
    settle_report,
    settle_schedule,
    settle_settings,
    template_record,
    updated_settings,
    write_files,
)
from .scripts import render as render_script
from .text import render

__all__ = ["write_deck", "deck_files", "pour_settings", "hull_topology", "body_lines", "MICRO",
           "MAX_VERTICES"]

#: SI value × factor = LAMMPS ``units micro`` value
MICRO = {"length": 1e6, "mass": 1e15, "time": 1e6, "velocity": 1.0, "force": 1e9,
         "energy": 1e15, "inertia": 1e27, "acceleration": 1e-6, "stiffness": 1e3, "damping": 1e9}

#: Boltzmann's constant in LAMMPS units micro (pg µm² µs⁻² K⁻¹), as LAMMPS defines it
BOLTZ_MICRO = 1.3806504e-8

#: hull vertices that always fit read_data's per-body limits (see :func:`body_lines`)
MAX_VERTICES = 56

# read_data: lines of one body (integer + double lines) ≤ MAXBODY − 1 = 31; a line < MAXLINE = 256 chars
_MAX_BODY_LINES = 31
_MAX_LINE = 250

def pour_settings(**kw) -> dict:
    """Default settings of the example pour (SI), updated with ``kw``.

    Parameters
    ----------
    **kw
        Settings to change: ``seed`` (int: the pour's order of grains and their orientations, drawn in
        Python; default 0), ``rounded_fraction`` (the rounded radius as a share of a grain's equivalent
        radius), ``impact_overlap`` (the stiffness lets the heaviest grain's impact compress a contact by this
        share of the smallest rounded radius), ``restitution`` (normal coefficient, in (0, 1)),
        ``tangential_damping`` (tangential damping as a share of the normal one), ``viscous_time`` (the
        background drag's time constant, in grain times ``t_g = sqrt(d/g)``), ``dt_fraction`` (time step as a
        share of the contact's period), ``dump_every`` (steps between dumps) and those of
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
    >>> pour_settings(seed=4)["seed"], pour_settings()["rounded_fraction"]
    (4, 0.05)
    """
    s = {"seed": 0, "rounded_fraction": 0.05, "impact_overlap": 0.5, "restitution": 0.3,
         "tangential_damping": 1.0, "viscous_time": 1.0, "dt_fraction": 0.04,
         **settle_settings(), "dump_every": 10000}
    return updated_settings(s, kw, "pour settings")


def hull_topology(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward triangles and unique edges of the convex hull of ``vertices``.

    Parameters
    ----------
    vertices : (K, 3) float64
        Every point a hull vertex (as :func:`grainforge.dem.polyhedron.convex_polyhedron` returns).

    Returns
    -------
    faces : (F, 3) int64
        Counter-clockwise seen from outside, rows sorted (deterministic).
    edges : (E, 2) int64
        ``i < j``, sorted.

    Examples
    --------
    >>> import trimesh
    >>> f, e = hull_topology(trimesh.creation.box().vertices)
    >>> len(f), len(e)
    (12, 18)
    """
    from scipy.spatial import ConvexHull

    v = np.asarray(vertices, dtype=np.float64)
    hull = ConvexHull(v)
    if len(hull.vertices) != len(v):
        raise InputError("every point must be a vertex of the convex hull")
    f = hull.simplices.astype(np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - v.mean(axis=0)) < 0
    f[inward] = f[inward][:, ::-1]
    f = _rotate_min_first(f)
    f = f[np.lexsort(f.T[::-1])]
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    e = np.unique(e, axis=0)
    return f, e


def _rotate_min_first(f: np.ndarray) -> np.ndarray:
    """Each triangle's indices cycled so that its smallest comes first (orientation kept)."""
    k = np.argmin(f, axis=1)
    idx = (k[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(f, idx, axis=1)


def _pack(tokens: Sequence[str]) -> list[str]:
    """Tokens joined into lines of at most ``_MAX_LINE`` characters."""
    lines, cur = [], ""
    for tok in tokens:
        if cur and len(cur) + 1 + len(tok) > _MAX_LINE:
            lines.append(cur)
            cur = tok
        else:
            cur = f"{cur} {tok}" if cur else tok
    if cur:
        lines.append(cur)
    return lines


def body_lines(body_id: int, vertices: np.ndarray, *, faces: np.ndarray, edges: np.ndarray,
               inertia: np.ndarray, rounded_diameter: float) -> list[str]:
    """The ``Bodies`` lines of one rounded/polyhedron body (values in the deck's units).

    ``vertices`` are displacements from the centre of mass in the box frame and
    ``inertia`` the tensor about the centre of mass in the box frame.

    Parameters
    ----------
    body_id : int
        The body's atom ID (1, 2, ...).
    vertices : (K, 3) float64
        Hull vertices, displacements from the centre of mass, box frame (the deck's units: µm).
    faces : (F, 3) int64
        Hull triangles as vertex indices, counter-clockwise seen from outside (:func:`hull_topology`).
    edges : (E, 2) int64
        Hull edges as vertex indices.
    inertia : (3, 3) float64
        Inertia tensor about the centre of mass, box frame (the deck's units: pg µm²).
    rounded_diameter : float
        Diameter of the rounding sphere swept over the hull (the deck's units: µm).

    Returns
    -------
    list of str
        The body's header line ``ID 3 Ndoubles``, then its integer line and the packed double lines.

    Raises
    ------
    ValueError
        If the body needs more than the 31 lines (≤ 250 characters each) that
        ``read_data`` reads per body.

    Examples
    --------
    >>> import trimesh
    >>> v = trimesh.creation.box().vertices
    >>> f, e = hull_topology(v)
    >>> lines = body_lines(1, v, faces=f, edges=e, inertia=np.eye(3), rounded_diameter=0.1)
    >>> lines[:2]
    ['1 3 115', '8 18 12']
    """
    I = inertia
    doubles = [fmt(x) for x in (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])]
    doubles += [fmt(x) for x in np.asarray(vertices).ravel()]
    doubles += [str(int(i)) for i in np.asarray(edges).ravel()]
    for tri in np.asarray(faces):
        doubles += [str(int(i)) for i in tri] + ["-1"]
    doubles.append(fmt(rounded_diameter))
    body = [f"{len(vertices)} {len(edges)} {len(faces)}"] + _pack(doubles)
    if len(body) > _MAX_BODY_LINES:
        raise InputError(f"a hull of {len(vertices)} vertices needs {len(body)} lines in LAMMPS's read_data "
                         f"(at most {_MAX_BODY_LINES}); use fewer vertices (≤ {MAX_VERTICES} always fits)")
    return [f"{body_id} 3 {len(doubles)}"] + body


def hull_vtk_text(vertices: np.ndarray, faces: np.ndarray, title: str) -> str:
    """A legacy-VTK POLYDATA file of a triangle mesh."""
    lines = ["# vtk DataFile Version 3.0", title[:250], "ASCII", "DATASET POLYDATA",
             f"POINTS {len(vertices)} double"]
    lines += [" ".join(fmt(x) for x in p) for p in vertices]
    lines += [f"POLYGONS {len(faces)} {4 * len(faces)}"] + [f"3 {a} {b} {c}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def _shape_files(templates: Sequence) -> tuple[dict, list]:
    """``({<grain>.poly, <grain>.hull.vtk: text}, [(faces, edges) per template])``."""
    files: dict[str, str] = {}
    topo = []
    for t in templates:
        if t.shape != "polyhedron" or t.polyhedron is None:
            raise InputError(f"the LAMMPS body deck writes convex polyhedra; {t.name} has shape {t.shape!r}")
        f, e = hull_topology(t.polyhedron)
        topo.append((f, e))
        head = (f"grainforge convex hull of {t.source or t.name}: x y z (m), centroid at the origin\n"
                f"vertices {len(t.polyhedron)}")
        lines = [f"# {h}" for h in head.splitlines()] + [" ".join(fmt(x) for x in row) for row in t.polyhedron]
        files[f"{t.name}.poly"] = "\n".join(lines) + "\n"
        files[f"{t.name}.hull.vtk"] = hull_vtk_text(t.polyhedron, f, f"grainforge hull {t.name} (m)")

    return files, topo


def _pour_plan(templates: Sequence, s: dict) -> SimpleNamespace:
    """The pour's population, box, contact stiffness and damping, time step and settle schedule (SI)."""
    population = [k for k, t in enumerate(templates) for _ in range(t.count)]
    rng = as_generator(s["seed"])
    order = rng.permutation(len(population))
    population = [population[i] for i in order]
    n = len(population)
    # contact shape = hull dilated by the rounded radius: cells leave room for it
    r_round = {k: s["rounded_fraction"] * t.d_eq / 2 for k, t in enumerate(templates)}  # radius, m
    cell = 2.2 * max(float(np.linalg.norm(t.polyhedron, axis=1).max()) + r_round[k]
                     for k, t in enumerate(templates))
    side = max(1, math.ceil(math.sqrt(n / 2.0)))  # a layer or two: polyhedron contacts are costly
    width = side * cell
    layers = math.ceil(n / (side * side))
    mean_d = sum(templates[k].d_eq for k in population) / n
    total_mass = sum(templates[k].mass for k in population)
    # The BODY contacts (and the walls: a vertex that passes the wall plane is pushed the wrong way)
    # hold only while overlaps stay inside the rounded radius: a linear spring stiff enough that
    # the heaviest grain, falling from the highest lattice node onto the floor (at most at the
    # terminal speed g·tau of the background drag), compresses one contact by at most
    # impact_overlap × the smallest rounded radius (SI). The drag's time constant tau is
    # viscous_time grain times t_g = sqrt(d/g): the impact speed, hence the stiffness and the
    # time step, then scale with the grains (a drag of fixed seconds lets millimetre grains hit
    # at several times sqrt(g d), which costs steps)
    top = (layers + 2) * cell
    tau = s["viscous_time"] * math.sqrt(mean_d / GRAVITY)
    v_impact = min(math.sqrt(2 * GRAVITY * layers * cell), GRAVITY * tau)
    kn = max(t.mass for t in templates) * (v_impact / (s["impact_overlap"] * min(r_round.values()))) ** 2
    # the smallest effective mass of a vertex contact between two grains: a push at distance r
    # from the centre also turns the grain (1/m + r²/I_min); the time step and the damping follow
    # it, otherwise the viscous contact damping is unstable (c dt / m > 2) and feeds energy in
    m_eff = min(0.5 / (1.0 / t.mass + float(np.linalg.norm(t.polyhedron, axis=1).max()) ** 2 / t.principal[0])
                for t in templates)
    omega = math.sqrt(kn / m_eff)
    dt = s["dt_fraction"] * 2 * math.pi / omega
    lne = math.log(s["restitution"])
    zeta = -lne / math.sqrt(math.pi**2 + lne**2)
    c_n = 2 * zeta * math.sqrt(kn * m_eff)  # viscous normal damping, kg/s
    c_t = s["tangential_damping"] * c_n
    ke_threshold = s["ke_ratio"] * total_mass * GRAVITY * mean_d
    sched = settle_schedule(dt, top=layers * cell, mean_d=mean_d, settings=s)
    cut_inner = 2 * max(r_round.values())
    gamma = total_mass / n / tau  # kg/s
    a_ua = math.pi * (2 * max(float(np.linalg.norm(t.polyhedron, axis=1).max()) for t in templates)) ** 2

    return SimpleNamespace(population=population, seed=s["seed"], n=n, r_round=r_round, cell=cell, side=side,
                           width=width, layers=layers, mean_d=mean_d, top=top, tau=tau, kn=kn, dt=dt, c_n=c_n,
                           c_t=c_t, ke_threshold=ke_threshold, sched=sched, cut_inner=cut_inner, gamma=gamma,
                           a_ua=a_ua)


def _data_file(templates: Sequence, topo: list, p: SimpleNamespace) -> tuple[str, list, int]:
    """``(data.bodies text, placements, nmax)``: the bodies at their lattice slots, units micro."""
    L, M = MICRO["length"], MICRO["mass"]
    population, side, cell, r_round = p.population, p.side, p.cell, p.r_round
    n, width, top = p.n, p.width, p.top
    atoms, bodies, placements = [], [], []
    nmax = 1
    for (slot, pos, axis, theta, R), k in zip(lattice_slots(len(population), side, cell, p.seed), population):
        t = templates[k]
        f, e = topo[k]
        atoms.append(f"{slot + 1} 1 1 {fmt(t.mass * M)} " + " ".join(fmt(x * L) for x in pos))
        bodies += body_lines(slot + 1, (t.polyhedron @ R.T) * L, faces=f, edges=e,
                             inertia=(R @ t.inertia @ R.T) * M * L * L, rounded_diameter=2 * r_round[k] * L)
        nv = len(t.polyhedron)
        nmax = max(nmax, nv, math.ceil((3 * nv + 2 * len(e) + 4 * len(f)) / 9))
        placements.append({"id": slot + 1, "grain": k, "name": t.name, "xcm": pos.tolist(), "axis": axis.tolist(),
                           "theta_deg": theta})
    lo = [-0.05 * cell, -0.05 * cell, -0.5 * cell]
    hi = [width + 0.05 * cell, width + 0.05 * cell, top]
    data = ["LAMMPS data file written by grainforge: rounded/polyhedron bodies, units micro (um, pg, us)", "",
            f"{n} atoms", f"{n} bodies", "1 atom types", "",
            f"{fmt(lo[0] * L)} {fmt(hi[0] * L)} xlo xhi", f"{fmt(lo[1] * L)} {fmt(hi[1] * L)} ylo yhi",
            f"{fmt(lo[2] * L)} {fmt(hi[2] * L)} zlo zhi", "",
            "Atoms # body: atom-ID atom-type bodyflag mass x y z", ""] + atoms + ["", "Bodies", ""] + bodies
    return "\n".join(data) + "\n", placements, nmax



def _run_text(p: SimpleNamespace, s: dict, nmax: int) -> str:
    """The ``in.run`` of the pour (units micro): the template ``grainforge/dem/texts/lammps-body-pour.in``
    filled with the plan's numbers, converted to micro units here."""
    L, T = MICRO["length"], MICRO["time"]
    sched = p.sched
    return render("lammps-body-pour.in", {
        "nmax": nmax, "c_n": fmt(p.c_n * MICRO["damping"]), "c_t": fmt(p.c_t * MICRO["damping"]),
        "a_ua": fmt(p.a_ua * L * L), "cut_inner": fmt(p.cut_inner * L), "kn": fmt(p.kn * MICRO["stiffness"]),
        "skin": fmt(0.2 * p.cell * L), "dt": fmt(p.dt * T), "gravity": fmt(9.81 * MICRO["acceleration"]),
        "drag": fmt(p.gamma * MICRO["damping"]), "width": fmt(p.width * L), "boltzmann": fmt(BOLTZ_MICRO),
        "ke_threshold": fmt(p.ke_threshold * MICRO["energy"]), "check_every": sched["check_every"],
        "dump_every": s["dump_every"],
        "settle_loop": settle_loop(sched["fall_steps"], sched["check_every"], sched["max_checks"],
                                   s["settle_checks"]),
        "settle_report": settle_report("quit 0", "quit 1", energy_unit="pg um^2/us^2, micro units = 1e-15 J")})


def deck_files(templates: Sequence, *, settings: dict | None = None) -> dict:
    """``{relative path: text}`` of a LAMMPS body deck (nothing written).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Convex-polyhedron templates (SI units), each placed ``count`` times; the pour's order of the copies
        and their orientations are drawn from ``settings["seed"]``.
    settings : dict, optional
        The pour's settings (default :func:`pour_settings`).

    Returns
    -------
    dict of str to str
        Relative path -> text: the files listed in the module text (``grains.json`` in SI, the LAMMPS
        files in units micro).

    Raises
    ------
    ValueError
        If a template is not a polyhedron, or a hull does not fit ``read_data``'s per-body limits.
    """
    s = settings or pour_settings()
    files, topo = _shape_files(templates)
    p = _pour_plan(templates, s)
    files["data.bodies"], placements, nmax = _data_file(templates, topo, p)
    files["in.run"] = _run_text(p, s, nmax)
    files["dump2vtk.py"] = render_script("lammps_body_dump2vtk.py")
    r_round, width, ke_threshold, dt, sched = p.r_round, p.width, p.ke_threshold, p.dt, p.sched
    kn, c_n, c_t, gamma = p.kn, p.c_n, p.c_t, p.gamma
    grains = []
    for k, (t, (f, e)) in enumerate(zip(templates, topo)):
        rec = template_record(t)
        rec.update({"polyhedron": f"{t.name}.poly", "vertices": len(t.polyhedron), "faces": f.tolist(),
                    "edges": len(e), "rounded_diameter": 2 * r_round[k]})
        grains.append(rec)
    deck = {"units": "SI (m, kg, s) here; the LAMMPS files use units micro: SI x factor", "micro": MICRO,
            "grains": grains, "placements": placements, "box": [width, width],
            "ke_threshold": ke_threshold, "dt": dt, "settle": sched, "kn": kn, "c_n": c_n, "c_t": c_t, "viscous_gamma": gamma,
            "scene": s}
    files["grains.json"] = json_text(deck)
    return files


def write_deck(templates: Sequence, out: str | Path, *, settings: dict | None = None,
               overwrite: bool = False) -> list[Path]:
    """Write a LAMMPS body deck for ``templates`` into ``out`` (see the module text).

    Parameters
    ----------
    templates : sequence of GrainTemplate
        Convex-polyhedron templates (SI units).
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
