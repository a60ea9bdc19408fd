"""Files shared by every engine deck: sphere lists, clump VTK, the file set writer."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputExistsError
from ..rng import RNGLike

__all__ = ["xyzr_text", "clump_vtk_text", "write_files", "template_record", "fmt", "updated_settings", "settle_loop",
           "settle_report", "settle_schedule", "settle_settings", "GRAVITY",
           "rotation_matrix", "lattice_slots", "grain_orientations", "orientation_rows", "exact_unit_quaternions",
           "ORIENTATION_STREAM"]


def updated_settings(defaults: dict, kw: dict, what: str = "scene settings") -> dict:
    """``defaults`` updated with ``kw``; an unknown key raises ``ValueError`` naming it.

    Parameters
    ----------
    defaults : dict
        Every setting the caller knows, with its default value.
    kw : dict
        The settings given (a subset of ``defaults``' keys).
    what : str
        What the settings are, for the error message (``"scene settings"``, ``"pour settings"``).

    Returns
    -------
    dict
        A new dict: ``defaults`` with the values of ``kw`` (``defaults`` is not changed).

    Raises
    ------
    ValueError
        If ``kw`` has a key ``defaults`` lacks (all such keys named, sorted).

    Examples
    --------
    >>> updated_settings({"seed": 0, "dt": 1.0}, {"seed": 3})
    {'seed': 3, 'dt': 1.0}
    """
    unknown = set(kw) - set(defaults)
    if unknown:
        raise InputError(f"unknown {what}: {', '.join(sorted(unknown))}")
    return {**defaults, **kw}


#: gravity of every example pour, m/s²
GRAVITY = 9.81


def settle_settings() -> dict:
    """Default settle criterion and budget shared by the example pours (see :func:`settle_schedule`).

    Returns
    -------
    dict
        ``ke_ratio`` (the kinetic-energy threshold as a share of the pour's ``m g d``: total mass, gravity,
        mean equivalent diameter), ``check_time`` (time between checks, in grain times ``t_g``),
        ``settle_checks`` (checks in a row below the threshold) and ``settle_time`` (the most settling
        time after the fall, in ``t_g``).

    Examples
    --------
    >>> sorted(settle_settings())
    ['check_time', 'ke_ratio', 'settle_checks', 'settle_time']
    """
    return {"ke_ratio": 1e-4, "check_time": 0.2, "settle_checks": 3, "settle_time": 60.0}


def settle_schedule(dt: float, *, top: float, mean_d: float, settings: dict, g_fall: float = GRAVITY) -> dict:
    """Step counts of a pour's settle check, from times in the grains' own time scale.

    The natural time of a grain of diameter ``d`` under gravity is ``t_g = sqrt(d/g)``. The pour
    first runs the fall (the time a grain released at rest at ``top`` takes to reach the floor at
    acceleration ``g_fall``), then checks the kinetic energy every ``check_time · t_g`` for at most
    ``settle_time · t_g``. The same numbers of ``t_g`` hold at every grain size: a fixed step count
    would give millimetre grains less settling time than centimetre ones (the stable time step
    shrinks with the grain, ``t_g`` only with its square root).

    Parameters
    ----------
    dt : float
        Time step, s.
    top : float
        Height of the highest grain's centre above the floor, m.
    mean_d : float
        Mean equivalent diameter of the population, m.
    settings : dict
        ``check_time``, ``settle_time`` (in ``t_g``) and ``settle_checks`` (as :func:`settle_settings`).
    g_fall : float
        Acceleration of the fall, m/s² (less than g under Yade's local damping; default :data:`GRAVITY`).

    Returns
    -------
    dict
        ``fall_steps``, ``check_every``, ``max_checks`` (≥ ``settle_checks``) and ``t_g`` (s).

    Examples
    --------
    >>> s = settle_schedule(1e-5, top=0.02, mean_d=0.002, settings=settle_settings())
    >>> s["fall_steps"], s["check_every"], s["max_checks"]
    (6386, 286, 300)
    """
    t_g = math.sqrt(mean_d / GRAVITY)
    fall = math.sqrt(2.0 * top / g_fall)
    check_every = max(1, int(round(settings["check_time"] * t_g / dt)))
    max_checks = max(int(settings["settle_checks"]),
                     int(math.ceil(settings["settle_time"] * t_g / (check_every * dt))))
    return {"fall_steps": int(math.ceil(fall / dt)), "check_every": check_every, "max_checks": max_checks,
            "t_g": t_g}


def settle_loop(fall_steps: int, check_every: int, max_checks: int, window: int = 3) -> str:
    """LIGGGHTS/LAMMPS input lines of the settle check on the variable ``ke`` against ``kethr``.

    Runs ``fall_steps`` steps, then ``check_every`` steps at a time (at most ``max_checks``
    times) until the largest ``ke`` of the last ``window`` checks is below ``kethr``. Leaves
    ``settled`` (1 or 0), ``kewin`` (that largest ke) and ``nsteps`` (the step count) defined and
    writes them with ``kethr`` to ``settle.txt``. The report line comes from :func:`settle_report`.

    Parameters
    ----------
    fall_steps : int
        Time steps run before the first check (0: none), from :func:`settle_schedule`.
    check_every : int
        Time steps between two checks (≥ 1).
    max_checks : int
        The most checks (≥ ``window``): the settle budget.
    window : int
        Checks in a row whose largest ``ke`` must be below ``kethr`` (≥ 1).

    Returns
    -------
    str
        Input lines joined by newlines, without a final newline (the deck defines ``ke`` and ``kethr``,
        in its own energy unit).

    Raises
    ------
    ValueError
        If ``window < 1`` or ``max_checks < window``.

    Examples
    --------
    >>> print(settle_loop(500, 1000, 5).splitlines()[0])
    run 500
    """
    w = int(window)
    if w < 1 or int(max_checks) < w:
        raise InputError(f"need 1 ≤ window ≤ max_checks, got window {window}, max_checks {max_checks}")
    lines = [f"run {int(fall_steps)}"] if int(fall_steps) > 0 else []
    lines += [f"variable ke{k} equal 1e300" for k in range(1, w + 1)]
    # pre no post no: a check continues the run without LAMMPS's set-up (which also re-counts
    # degrees of freedom: in LIGGGHTS one "Energy calculated for multisphere particles is
    # currently not correct" warning per set-up, docs/dem.md) and without the timing summary
    lines += [f"variable i loop {int(max_checks)}", "label settle", f"run {int(check_every)} pre no post no"]
    lines += [f"variable ke{k} equal ${{ke{k - 1}}}" for k in range(w, 1, -1)]
    lines += ["variable ke1 equal ${ke}", "variable kewin equal ${ke1}"]
    for k in range(2, w + 1):  # the formula language's max() is a vector function: max by comparisons
        lines.append(f"variable kewin equal (${{kewin}}>${{ke{k}}})*${{kewin}}+(${{kewin}}<=${{ke{k}}})*${{ke{k}}}")
    lines += ['if "${kewin} < ${kethr}" then "jump SELF settled"', "next i", "jump SELF settle",
              "variable settled equal 0", "jump SELF report", "label settled", "variable settled equal 1",
              "label report", "variable nsteps equal step", "variable nsteps equal ${nsteps}",
              'print "ke ${kewin} threshold ${kethr} settled ${settled} steps ${nsteps}" file settle.txt']
    return "\n".join(lines)


def settle_report(quit_settled: str, quit_not_settled: str, energy_unit: str = "J") -> str:
    """The last input lines: one ``SETTLED in N steps`` or ``NOT SETTLED after N steps (KE … > … J)``
    line, then the given quit commands (``""`` for none) — see :func:`settle_loop`. ``energy_unit`` names the
    unit of the deck's kinetic energies (``"J"`` in SI decks; LAMMPS's micro units are pg µm²/µs² = 1e-15 J).

    Parameters
    ----------
    quit_settled : str
        The input line that ends a settled run (``"quit 0"``; ``""``: none, the input goes on).
    quit_not_settled : str
        The command run after the ``NOT SETTLED`` line (``"quit 1"``; ``""``: none).
    energy_unit : str
        The unit printed after the kinetic energies.

    Returns
    -------
    str
        Input lines joined by newlines, without a final newline.

    Examples
    --------
    >>> print(settle_report("quit 0", "quit 1").splitlines()[-1])
    quit 0
    """
    fail = f" '{quit_not_settled}'" if quit_not_settled else ""
    lines = ["if \"${settled} == 1\" then 'print \"SETTLED in ${nsteps} steps\"' "
             "else 'print \"NOT SETTLED after ${nsteps} steps (KE ${kewin} > ${kethr} " + energy_unit + ")\"'" + fail]
    if quit_settled:
        lines.append(quit_settled)
    return "\n".join(lines)


def rotation_matrix(axis: np.ndarray, theta: float) -> np.ndarray:
    """Right-handed rotation by ``theta`` radians about ``axis``: :func:`grainforge.geometry.rotations.axis_angle_matrix`.

    Parameters
    ----------
    axis : (3,) array_like of float
        Rotation axis, any non-zero length.
    theta : float
        Angle, radians, counter-clockwise seen from the tip of ``axis``.

    Returns
    -------
    (3, 3) float64
        The rotation matrix (acting on column vectors).

    Examples
    --------
    >>> np.round(rotation_matrix(np.array([0.0, 0.0, 1.0]), np.pi / 2) @ [1.0, 0.0, 0.0], 12).tolist()
    [0.0, 1.0, 0.0]
    """
    from ..geometry.rotations import axis_angle_matrix

    return axis_angle_matrix(axis, theta)


#: the second word of the seed of every deck's orientation stream, ``SeedSequence([seed, ORIENTATION_STREAM])``:
#: its own stream, so that the orientations do not move when another draw of the deck changes
ORIENTATION_STREAM = 0x6F7269


def grain_orientations(count: int, rng: RNGLike) -> np.ndarray:
    """The orientations of the ``count`` grains a deck or scene of seed ``rng`` places: ``(count, 4)`` unit
    quaternions ``(w, x, y, z)``, uniformly random (:func:`grainforge.geometry.rotations.random_quaternions`).

    Every engine's deck gets its grains' orientations from here, written out as numbers (the engine
    scripts draw none); grain ``k`` of the deck's placement order takes row ``k``.

    Parameters
    ----------
    count : int
        Grains to orient (≥ 0).
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The deck's seed. An int ``s`` draws from the deck's own orientation stream,
        ``SeedSequence([s, ORIENTATION_STREAM])``: other draws of the deck seeded by ``s`` do not move
        the orientations, and row ``k`` is the same for every ``count``. Any other value is normalised
        by :func:`grainforge.rng.as_generator` (a Generator is advanced by ``4 · count`` draws).

    Returns
    -------
    (count, 4) float64
        Unit quaternions, scalar first, ``w ≥ 0``.

    Raises
    ------
    ValueError
        If ``count`` is negative or ``rng`` is not an accepted value (a negative int, ...).

    Examples
    --------
    >>> q = grain_orientations(4, rng=0)
    >>> q.shape, bool(np.array_equal(q, grain_orientations(4, rng=0)))
    ((4, 4), True)
    >>> bool(np.array_equal(q[:2], grain_orientations(2, rng=0)))
    True
    """
    from ..geometry.rotations import random_quaternions

    if isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)):
        rng = np.random.SeedSequence([int(rng), ORIENTATION_STREAM])
    return random_quaternions(count, rng)


def orientation_rows(q: np.ndarray) -> list[list[float]]:
    """Quaternions as JSON rows (each component exactly as float64 holds it).

    Parameters
    ----------
    q : (N, 4) or (4,) array_like of float
        Quaternions ``(w, x, y, z)``.

    Returns
    -------
    list of list of float
        ``N`` rows of four Python floats (what ``grains.json`` holds).

    Examples
    --------
    >>> orientation_rows(np.array([[1.0, 0.0, 0.0, 0.0]]))
    [[1.0, 0.0, 0.0, 0.0]]
    """
    return [[float(x) for x in row] for row in np.asarray(q, dtype=np.float64).reshape(-1, 4)]


def exact_unit_quaternions(q) -> np.ndarray:
    """Each row of ``q`` normalised and nudged (by a few units in the last place of its components) until
    ``w² + x² + y² + z²``, summed in that order in float64, is exactly 1 — what LIGGGHTS demands of an
    insertion's ``orientation constant`` (it stops with "quaternion not valid" otherwise).

    The turn moves by about 1e-15 rad at most.

    Parameters
    ----------
    q : (N, 4) or (4,) array_like of float
        Quaternions ``(w, x, y, z)``, any non-zero lengths.

    Returns
    -------
    (N, 4) float64
        The unit quaternions, each with ``w*w + x*x + y*y + z*z == 1.0`` exactly in float64.

    Raises
    ------
    ValueError
        If no exactly unit quaternion is found near a row (not met in practice).

    Examples
    --------
    >>> q = exact_unit_quaternions([[0.3, 0.4, 0.5, 0.6]])[0]
    >>> float(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) == 1.0
    True
    """
    q = np.array(q, dtype=np.float64).reshape(-1, 4)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = np.empty_like(q)
    todo = np.arange(len(q))
    base = q.copy()
    for attempt in range(64):
        if not len(todo):
            return out
        found = _unit_candidates(q[todo])
        done = ~np.isnan(found[:, 0])
        out[todo[done]] = found[done]
        todo = todo[~done]
        # the few rows with no exact neighbour: start again from a direction turned by ~1e-15
        tilt = base[todo] + (attempt + 1) * 1e-15 * np.array([0.0, 1.0, -1.0, 1.0])
        q[todo] = tilt / np.linalg.norm(tilt, axis=1, keepdims=True)
    raise InputError(f"no float64 quaternion of exact unit norm near {base[todo[0]].tolist()}")


#: offsets (units in the last place) tried on each component, nearest first
_OFFSETS = np.stack(np.meshgrid(*([np.arange(-3, 4)] * 4), indexing="ij"), axis=-1).reshape(-1, 4)
_OFFSETS = _OFFSETS[np.argsort(np.abs(_OFFSETS).sum(axis=1), kind="stable")]


def _unit_candidates(q: np.ndarray) -> np.ndarray:
    """Per row, the candidate with the fewest ulp moves whose squared norm sums to 1 exactly (NaN: none)."""
    out = np.full_like(q, np.nan)
    for lo in range(0, len(q), 256):
        rows = q[lo:lo + 256]
        # candidate components: x + n ulp(x), with the ulp of x itself (spacing gives it, sign-aware)
        ulp = np.spacing(np.abs(rows))[:, None, :]
        cand = rows[:, None, :] + _OFFSETS[None, :, :] * ulp
        w, x, y, z = (cand[..., k] for k in range(4))
        norm2 = w * w + x * x
        norm2 = norm2 + y * y
        norm2 = norm2 + z * z
        ok = norm2 == 1.0
        hit = ok.any(axis=1)
        first = np.argmax(ok, axis=1)
        idx = np.flatnonzero(hit)
        out[lo + idx] = cand[idx, first[idx]]
    return out


def lattice_slots(count: int, side: int, cell: float, rng: RNGLike):
    """Pour positions on a ``side`` × ``side`` lattice of ``cell``, layer after layer, each with the
    uniformly random orientation :func:`grain_orientations` gives slot ``k`` for ``rng``: yields
    ``(slot, pos, axis, theta_deg, R)`` for slots 0..count-1 (the turn by ``theta_deg`` about the unit
    ``axis``, and its matrix).

    Parameters
    ----------
    count : int
        Slots (grains) to place (≥ 0).
    side : int
        Lattice nodes per side of a layer (≥ 1).
    cell : float
        Lattice spacing, m (the deck's length unit): node ``(i, j)`` of layer ``l`` is at
        ``((i + 1/2) cell, (j + 1/2) cell, (l + 1) cell)``.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The deck's seed, as for :func:`grain_orientations` (an int: the deck's orientation stream).

    Yields
    ------
    slot : int
        0, 1, ..., ``count - 1``.
    pos : (3,) float64
        The node's position.
    axis : (3,) float64
        Unit axis of the slot's turn.
    theta_deg : float
        Angle of the turn, degrees, in [0, 180].
    R : (3, 3) float64
        The turn's matrix.

    Examples
    --------
    >>> [(s, p.tolist()) for s, p, *_ in lattice_slots(3, 2, 1.0, 0)]
    [(0, [0.5, 0.5, 1.0]), (1, [1.5, 0.5, 1.0]), (2, [0.5, 1.5, 1.0])]
    """
    from ..geometry.rotations import quaternion_axis_angle, quaternion_matrix

    for slot, q in enumerate(grain_orientations(count, rng)):
        i, j, layer = slot % side, (slot // side) % side, slot // (side * side)
        pos = np.array([(i + 0.5) * cell, (j + 0.5) * cell, (layer + 1.0) * cell])
        axis, theta = quaternion_axis_angle(q)
        yield slot, pos, axis, math.degrees(theta), quaternion_matrix(q)


def fmt(x: float) -> str:
    """A float with 17 significant digits (round-trips exactly).

    Parameters
    ----------
    x : float
        Any number ``float()`` takes.

    Returns
    -------
    str
        ``repr(float(x))``: the shortest text that reads back to the same float64.

    Examples
    --------
    >>> fmt(0.1), fmt(2), fmt(1e-7)
    ('0.1', '2.0', '1e-07')
    """
    return repr(float(x))


def xyzr_text(centres: np.ndarray, radii: np.ndarray, *, header: str = "") -> str:
    """``x y z r`` per line (full precision), after ``#`` comment lines from ``header``.

    Parameters
    ----------
    centres : (N, 3) float64
        Sphere centres, m (the grain's frame, centroid at the origin in the decks).
    radii : (N,) float64
        Sphere radii, m.
    header : str
        Comment text; each of its lines becomes a ``# `` line (``""``: none).

    Returns
    -------
    str
        The file's text, ending with a newline.

    Examples
    --------
    >>> print(xyzr_text(np.zeros((1, 3)), np.array([0.5]), header="one sphere"), end="")
    # one sphere
    0.0 0.0 0.0 0.5
    """
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    lines += [" ".join(fmt(v) for v in (*c, r)) for c, r in zip(centres, radii)]
    return "\n".join(lines) + "\n"


def clump_vtk_text(centres: np.ndarray, radii: np.ndarray, title: str = "grainforge clump") -> str:
    """A legacy-VTK POLYDATA file: one vertex per sphere with a ``radius`` scalar.

    In ParaView apply *Glyph* (sphere, scale by ``radius``, factor 2 for diameter).

    Parameters
    ----------
    centres : (N, 3) float64
        Sphere centres, m.
    radii : (N,) float64
        Sphere radii, m.
    title : str
        The file's title line (cut to 250 characters, as the format allows 256).

    Returns
    -------
    str
        The file's text (ASCII), ending with a newline.

    Examples
    --------
    >>> print(clump_vtk_text(np.zeros((1, 3)), np.array([0.5])).splitlines()[-1])
    0.5
    """
    n = len(radii)
    lines = ["# vtk DataFile Version 3.0", title[:250], "ASCII", "DATASET POLYDATA", f"POINTS {n} double"]
    lines += [" ".join(fmt(v) for v in c) for c in centres]
    lines += [f"VERTICES {n} {2 * n}"] + [f"1 {i}" for i in range(n)]
    lines += [f"POINT_DATA {n}", "SCALARS radius double 1", "LOOKUP_TABLE default"]
    lines += [fmt(r) for r in radii]
    return "\n".join(lines) + "\n"


def template_record(t) -> dict:
    """JSON-able summary of a GrainTemplate (SI units): one record of a deck's ``grains.json``.

    Parameters
    ----------
    t : grainforge.dem.template.GrainTemplate
        The template.

    Returns
    -------
    dict
        ``name``, ``source``, ``count``, ``shape``, ``density`` (kg/m³), ``volume`` (m³), ``mass`` (kg),
        ``d_eq`` (m), ``centroid`` (always the origin), ``inertia_tensor`` (kg m², the grain's frame),
        ``principal_inertia`` (kg m², ascending), ``principal_axes`` (columns), ``bounding_radius`` (m);
        for a clump also its sphere file ``xyzr``, ``spheres``, ``coverage``, ``spill``, ``r_min`` (m) and, when
        it was built to an accuracy target, :func:`grainforge.dem.clump.accuracy_record`.
    """
    rec = {
        "name": t.name, "source": t.source, "count": t.count, "shape": t.shape,
        "density": t.density, "volume": t.props.volume, "mass": t.mass, "d_eq": t.d_eq,
        "centroid": [0.0, 0.0, 0.0],
        "inertia_tensor": t.inertia.tolist(), "principal_inertia": t.principal.tolist(),
        "principal_axes": t.props.axes.tolist(), "bounding_radius": t.bounding_radius,
    }
    if t.clump is not None:
        rec.update({"xyzr": f"{t.name}.xyzr", "spheres": t.clump.count, "coverage": t.clump.coverage,
                    "spill": t.clump.spill, "r_min": float(t.clump.radii.min())})
        from .clump import accuracy_record

        rec.update(accuracy_record(t.clump))  # a clump built to an accuracy target: its figures (else nothing)
    return rec


def json_text(obj) -> str:
    return json.dumps(obj, indent=1, sort_keys=False) + "\n"


def write_files(files: Mapping[str, str | bytes], out: str | Path, *, overwrite: bool = False) -> list[Path]:
    """Write ``{relative path: data}`` under ``out``, each atomically.

    A deck whose ``grains.json`` records clumps built to an accuracy target
    gets ``clumps.csv`` beside it (:func:`grainforge.dem.clump.clump_table`).

    Parameters
    ----------
    files : mapping of str to str or bytes
        Relative path (``/``-separated, may name sub-folders) -> the file's text or bytes.
    out : str or path
        The deck's folder (created if missing).
    overwrite : bool
        Replace existing files.

    Returns
    -------
    list of Path
        The files written, in the order of ``files`` (then ``clumps.csv`` when added).

    Raises
    ------
    ValueError
        If ``out`` exists and is not a folder.
    FileExistsError
        If any of the files exists and ``overwrite`` is false (checked before
        anything is written).
    """
    from ..io import atomic_write

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} exists and is not a folder")
    if "grains.json" in files and "clumps.csv" not in files:  # clumps built to an accuracy target: their table
        from .clump import clump_table

        table = clump_table(json.loads(files["grains.json"]).get("grains", []))
        if table is not None:
            files = {**files, "clumps.csv": table}
    if not overwrite:
        existing = [out / p for p in files if (out / p).exists()]
        if existing:
            raise OutputExistsError(f"{existing[0]} exists; use {{overwrite}}", setting="overwrite")
    return [atomic_write(out / p, data) for p, data in files.items()]
