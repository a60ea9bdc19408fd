"""Rolling resistance (``--rolling-friction`` μ_r): what the decks carry, and a sphere on an incline in each engine.

The limit rolling moment is μ_r F_n min(r₁, r₂) in both engines: Yade's ``CohFrictMat`` (``etaRoll``), LIGGGHTS's
``rolling_friction epsd2`` with a coefficient per type pair (:func:`grainforge.simulate.liggghts_scenes.rolling_table`).
A sphere of radius r on a plane inclined at θ stays at rest while tan θ < μ_r (gravity's moment about the contact
point, m g sin θ r, against μ_r m g cos θ r) and rolls above, with the acceleration a = (5/7) g (sin θ − μ_r cos θ)
of a sphere (I = 2/5 m r²) braked by the constant limit moment.
"""

from __future__ import annotations

import csv
import json
import math
import re
import subprocess

import pytest
from conftest import require_engine

from grainforge.dem.yade import deck_files as yade_deck_files
from grainforge.simulate import QUICK, QUICK_TRIAXIAL, Settings, TriaxialSettings, build_population
from grainforge.simulate import liggghts_scenes as lg
from grainforge.simulate import liggghts_triaxial as lt
from grainforge.simulate.settings import scene_settings
from grainforge.simulate.triaxial import triaxial_scene_settings
from grainforge.simulate.yade_scenes import COMMON

MU_R = 0.2
#: the sphere (m) and its density (kg/m³); the settle under vertical gravity and the time on the incline (s)
RADIUS, DENSITY, SETTLE, HOLD = 0.005, 1000.0, 0.1, 0.3


@pytest.fixture(scope="module")
def templates(tmp_path_factory):
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    out = tmp_path_factory.mktemp("g") / "g"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return build_population([out], Settings(**QUICK))


def _rolling_coefficients(text: str) -> list[float]:
    line = next(row for row in text.splitlines() if "coefficientRollingFriction" in row)
    return [float(v) for v in line.split("peratomtypepair 3")[1].split()]


@pytest.mark.parametrize("test", ["repose", "tilt"])
def test_liggghts_scene_decks_carry_the_rolling_resistance_only_when_set(templates, test):
    plain = lg.run_deck_files(templates, test, Settings(**QUICK), 0)
    assert lg.run_deck_files(templates, test, Settings(**QUICK, rolling_friction=0.0), 0) == plain
    assert "rolling" not in plain["in.run"].lower()
    run = lg.run_deck_files(templates, test, Settings(**QUICK, rolling_friction=MU_R), 0)["in.run"]
    models = [row for row in run.splitlines() if row.startswith("pair_style") or "wall/gran" in row]
    assert models and all("rolling_friction epsd2" in row for row in models)
    c = _rolling_coefficients(run)  # types grain, base, wall: LIGGGHTS's c R* is μ_r min(r1, r2)
    assert c[0] == pytest.approx(2 * MU_R) and c[2] == pytest.approx(MU_R) and c[6] == pytest.approx(MU_R)
    assert MU_R <= c[1] <= 2 * MU_R + 1e-12 and c[1] == c[3]
    # the deck differs from the plain one only by the model words and the one fix line
    assert run.replace(" rolling_friction epsd2", "").replace(
        next(row for row in run.splitlines() if "coefficientRollingFriction" in row) + "\n", "") == plain["in.run"]


def test_liggghts_triaxial_deck_rolls_between_grains_not_on_its_frictionless_walls(templates):
    plain = lt.triaxial_deck_files(templates, TriaxialSettings(**QUICK_TRIAXIAL), 0)
    assert "rolling" not in plain["in.run"].lower()
    run = lt.triaxial_deck_files(templates, TriaxialSettings(**QUICK_TRIAXIAL, rolling_friction=MU_R), 0)["in.run"]
    assert "pair_style gran model hooke/stiffness tangential history rolling_friction epsd2" in run
    c = _rolling_coefficients(run)
    assert c[0] == pytest.approx(2 * MU_R) and c[2] == 0.0 and c[6] == 0.0


def test_yade_scene_settings_carry_the_rolling_resistance_only_when_set():
    assert "rolling_friction" not in scene_settings(Settings(), "tilt", 0)
    assert "rolling_friction" not in triaxial_scene_settings(TriaxialSettings(), 0)
    assert scene_settings(Settings(rolling_friction=MU_R), "repose", 0)["rolling_friction"] == MU_R
    assert triaxial_scene_settings(TriaxialSettings(rolling_friction=MU_R), 0)["rolling_friction"] == MU_R


def _rolled(theta_deg: float) -> float:
    """Distance (m) a sphere on a plane rolls in HOLD s at θ, from rest, braked by μ_r F_n r (0 below tan θ = μ_r)."""
    th = math.radians(theta_deg)
    a = 5.0 / 7.0 * 9.81 * max(0.0, math.sin(th) - MU_R * math.cos(th))
    return 0.5 * a * HOLD ** 2


#: the incline in Yade: the simulate scenes' helpers (``engines()``: the facet's ScGeom6D, CohFrictPhys and the
#: moment law) and the library's contact material, one sphere on a facet; gravity tilted after a settle; no
#: local damping on the incline (it brakes a rolling sphere: see docs/simulate.md)
YADE_INCLINE = '''
R = SETTINGS["radius"]
mat = contact_material()
if SETTINGS["support"] == "sphere":  # a fixed sphere of the same radius below: a grain-grain contact
    O.bodies.append(utils.sphere((0.0, 0.0, -R), R, fixed=True, material=mat))
else:
    O.bodies.append(utils.facet([(-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (0.0, 1.0, 0.0)], fixed=True, material=mat))
b = O.bodies[O.bodies.append(utils.sphere((0.0, 0.0, R), R, material=mat))]
b.state.mass = SETTINGS["density"] * 4.0 / 3.0 * math.pi * R ** 3
b.state.inertia = Vector3(1, 1, 1) * 0.4 * b.state.mass * R ** 2
O.engines = engines([Ig2_Facet_Sphere_ScGeom()], [Bo1_Facet_Aabb()])
O.dt = 0.3 * math.sqrt(b.state.mass / (SETTINGS["young"] * R))
advance(int(SETTINGS["settle"] / O.dt))
theta = math.radians(SETTINGS["incline_deg"])
newton.gravity = (SETTINGS["gravity"] * math.sin(theta), 0.0, -SETTINGS["gravity"] * math.cos(theta))
newton.damping = 0.0
x0 = b.state.pos[0]
advance(int(SETTINGS["hold"] / O.dt))
touching = O.interactions.all()  # none once a sphere has rolled off the one below
i = touching[0] if touching else None
write_result({"displacement": b.state.pos[0] - x0, "phys": type(i.phys).__name__ if i else None,
              "max_roll": i.phys.maxRollPl if i else None})
'''


def _yade_incline(tmp_path, theta_deg: float, support: str = "plane") -> dict:
    yade = require_engine("yade")
    scene = {**scene_settings(Settings(rolling_friction=MU_R, friction=1.0), "tilt", 0), "incline_deg": theta_deg,
             "radius": RADIUS, "density": DENSITY, "settle": SETTLE, "hold": HOLD, "support": support}
    out = tmp_path / f"yade-{support}-{theta_deg:g}"
    out.mkdir()
    for name, text in yade_deck_files([], scene=COMMON + "\n" + YADE_INCLINE, settings=scene).items():
        (out / name).write_text(text)
    r = subprocess.run([yade, "-n", "-x", "run.py"], cwd=out, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads((out / "result.json").read_text())


def _liggghts_incline(tmp_path, theta_deg: float) -> float:
    """One sphere on a ``wall/gran`` plane with the scenes' model, options and per-type-pair tables."""
    exe = require_engine("liggghts")
    m = DENSITY * 4.0 / 3.0 * math.pi * RADIUS ** 3
    s = Settings(rolling_friction=MU_R, friction=1.0)
    t = lg.contact_table(s, RADIUS, RADIUS, m)
    pairs = lg._per_type_pair
    model = lg.contact_model(s.rolling_friction)
    dt = 0.3 * math.sqrt(m / t["k_max"])
    th = math.radians(theta_deg)
    text = f"""atom_style sphere
atom_modify map array
boundary f f f
newton off
communicate single vel yes
units si
region domain block -0.5 0.5 -0.05 0.05 -0.01 0.05 units box
create_box 3 domain
neighbor {RADIUS / 5!r} bin
neigh_modify delay 0
fix kn all property/global kn peratomtypepair 3 {pairs(t["kn"])}
fix kt all property/global kt peratomtypepair 3 {pairs(t["kt"])}
fix gamman all property/global gamman peratomtypepair 3 {pairs(t["gamman"])}
fix gammat all property/global gammat peratomtypepair 3 {pairs(t["gamman"])}
fix m4 all property/global coefficientFriction peratomtypepair 3 {" ".join([repr(s.friction)] * 9)}\
{lg.rolling_fix(lg.rolling_table(s.rolling_friction, RADIUS, RADIUS))}
pair_style gran {model} {lg.CONTACT_OPTIONS}
pair_coeff * *
timestep {dt!r}
fix floor all wall/gran {model} primitive type {lg.WALL} zplane 0.0 {lg.CONTACT_OPTIONS}
create_atoms {lg.GRAIN} single 0.0 0.0 {RADIUS!r} units box
set atom 1 diameter {2 * RADIUS!r} density {DENSITY!r}
fix integr all nve/sphere
fix grav all gravity 9.81 vector 0.0 0.0 -1.0
run {int(SETTLE / dt)}
variable x0 equal x[1]
variable xs equal ${{x0}}
unfix grav
fix grav all gravity 9.81 vector {math.sin(th)!r} 0.0 {-math.cos(th)!r}
run {int(HOLD / dt)}
variable dx equal x[1]-${{xs}}
print "displacement ${{dx}}"
"""
    out = tmp_path / f"liggghts-{theta_deg:g}"
    out.mkdir()
    (out / "in.run").write_text(text)
    r = subprocess.run([exe, "-in", "in.run", "-echo", "none"], cwd=out, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:]
    return float(re.findall(r"^displacement (\S+)", r.stdout, re.M)[-1])


#: 10 % below and above the threshold tan θ = μ_r
BELOW, ABOVE = math.degrees(math.atan(0.9 * MU_R)), math.degrees(math.atan(1.1 * MU_R))


def test_yade_sphere_holds_below_tan_theta_mu_r_and_rolls_above(tmp_path):
    below, above = _yade_incline(tmp_path, BELOW), _yade_incline(tmp_path, ABOVE)
    assert below["phys"] == "CohFrictPhys" and below["max_roll"] == pytest.approx(MU_R * RADIUS)
    assert abs(below["displacement"]) < 0.01 * RADIUS  # the rolling spring's elastic turn only
    assert above["displacement"] == pytest.approx(_rolled(ABOVE), rel=0.15)


def test_liggghts_sphere_holds_below_tan_theta_mu_r_and_rolls_above(tmp_path):
    below, above = _liggghts_incline(tmp_path, BELOW), _liggghts_incline(tmp_path, ABOVE)
    assert abs(below) < 0.01 * RADIUS
    assert above == pytest.approx(_rolled(ABOVE), rel=0.15)


# ---- grainforge dem ---------------------------------------------------------------------------------------

def _dem(tmp_path, name, *extra):
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    grains = tmp_path / "grains"
    if not grains.exists():
        r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(grains), "--count", "2", "--size", "2",
                                     "--subdivisions", "3", "--preset", "rough-angular"])
        assert r.exit_code == 0, r.output
    out = tmp_path / name
    return CliRunner().invoke(cli, ["dem", str(grains), "--out", str(out), "--spheres", "4", *extra]), out


def test_dem_liggghts_deck_rolls_only_when_asked(tmp_path):
    r, plain = _dem(tmp_path, "plain", "--engine", "liggghts")
    assert r.exit_code == 0, r.output
    r, zero = _dem(tmp_path, "zero", "--engine", "liggghts", "--rolling-friction", "0")
    assert r.exit_code == 0, r.output
    assert (zero / "in.run").read_text() == (plain / "in.run").read_text()
    assert (zero / "grains.json").read_text() == (plain / "grains.json").read_text()
    r, rolls = _dem(tmp_path, "rolls", "--engine", "liggghts", "--rolling-friction", str(MU_R))
    assert r.exit_code == 0, r.output
    run = (rolls / "in.run").read_text()
    models = [row for row in run.splitlines() if row.startswith("pair_style") or "wall/gran" in row]
    assert len(models) == 6 and all("rolling_friction epsd2" in row for row in models)
    line = next(row for row in run.splitlines() if "coefficientRollingFriction" in row)
    assert float(line.split("peratomtypepair 1")[1]) == pytest.approx(2 * MU_R)


def test_dem_yade_deck_carries_the_setting_and_lammps_refuses_it(tmp_path):
    r, plain = _dem(tmp_path, "plain")
    assert r.exit_code == 0, r.output
    assert "rolling_friction" not in json.loads((plain / "grains.json").read_text())["scene"]
    r, rolls = _dem(tmp_path, "rolls", "--rolling-friction", str(MU_R))
    assert r.exit_code == 0, r.output
    assert json.loads((rolls / "grains.json").read_text())["scene"]["rolling_friction"] == MU_R
    assert (rolls / "run.py").read_text() == (plain / "run.py").read_text()  # the script reads the setting
    r, lammps = _dem(tmp_path, "lammps", "--engine", "lammps", "--rolling-friction", str(MU_R))
    assert r.exit_code == 2 and "--rolling-friction" in r.output and not lammps.exists()


def test_a_yade_sphere_on_a_grain_of_its_size_holds_below_tan_theta_mu_r_and_rolls_above(tmp_path):
    """The grain-grain limit is μ_r F_n r too: at 0.9 μ_r a limit of half that would let the sphere roll off.
    Above, it starts rolling over the sphere below (a falling motion)."""
    below, above = (_yade_incline(tmp_path, a, "sphere")["displacement"] for a in (BELOW, ABOVE))
    assert abs(below) < 0.01 * RADIUS
    assert above > 0.5 * RADIUS


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_rolling_resistance_raises_the_spheres_ultimate_friction_angle(engine, tmp_path):
    """Spheres fail by rolling: without rolling resistance their ultimate friction angle is low (about 18° at
    μ = 0.5 in LIGGGHTS's box of 500), with μ_r = 0.3 it rises by 10° and more (about 31°, docs/simulate.md,
    *Rolling resistance*). Here 100 volume-equivalent spheres of rough spheres, one seed each, sheared to 20 % at
    I = 2e-3 (the quick LIGGGHTS rate): the seed noise of so small a specimen is a few degrees, the rise asked
    for 5°."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    require_engine("liggghts" if engine == "liggghts" else "yade")
    if engine == "yade":
        from conftest import require_long_lane

        require_long_lane("Yade's two 100-sphere triaxial runs to 20 % (81 s idle, 4 min under load); in the suite the same "
                          "rise is checked in LIGGGHTS, and Yade's rolling law on a sphere on an incline")
    spheres = tmp_path / "grains"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(spheres), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-sphere"])
    assert r.exit_code == 0, r.output
    angle = {}
    for mu_r in (0.0, 0.3):
        out = tmp_path / f"mu_r-{mu_r}"
        r = CliRunner().invoke(cli, ["simulate", "triaxial", str(spheres), "--as-spheres",
                                     "--engine", engine, "--grains", "100", "--templates", "6", "--seeds", "1",
                                     "--axial-strain", "0.2", "--inertial-number", "2e-3",
                                     "--rolling-friction", str(mu_r), "--out", str(out)])
        assert r.exit_code == 0, r.output
        with open(out / "results.csv") as fh:
            (row,) = list(csv.DictReader(fh))
        assert row["problems"] == ""
        angle[mu_r] = float(row["ultimate_friction_deg"])
    assert angle[0.3] > angle[0.0] + 5.0, angle
