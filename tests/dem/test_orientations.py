"""Grain orientations as the engines receive them: read back from written decks, uniformly random.

Every deck and scene places its grains in orientations drawn by grainforge and written into the
deck as numbers.  These tests write each engine's deck, read the orientations back from the
written files the way the engine reads them (the LIGGGHTS ``orientation constant`` quaternions,
LAMMPS's ``rotate`` angle and axis, the vertices of LAMMPS's bodies, the Yade scene's
orientations), and test them against the uniform (Haar) distribution on SO(3) with a check
written here, independent of grainforge's own: the rotation angle ω of a uniform rotation has
the CDF (ω − sin ω)/π and its trace 1 + 2 cos ω has mean 0 and variance 1.

The same check fails on the draws the decks used before (an axis uniform on the sphere and an
angle uniform in [0, 2π), and LIGGGHTS's own three angles uniform in [0, 2π)):
``test_the_check_fails_on_the_old_draws``.  The engine runs (``test_dem_engines.py``,
``test_simulate.py``) check that the engines place each grain exactly as its deck says.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation
from scipy.stats import kstest

from grainforge.dem.template import prepare

#: grains per deck: the check's power against the old draws is overwhelming at this size (KS ≈ 0.3)
N = 600
#: the p-value below which a set of orientations is called not uniform
P_MIN = 1e-3


def uniformity(R) -> tuple[float, float]:
    """(KS p-value of the rotation angles against the uniform law, mean trace in standard errors)."""
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    trace = np.trace(R, axis1=1, axis2=2)
    w = np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))
    p = kstest(w, lambda x: (x - np.sin(x)) / np.pi).pvalue
    return float(p), float(trace.mean() * np.sqrt(len(trace)))


def assert_uniform(R):
    assert len(R) >= N // 2
    p, z = uniformity(R)
    assert p > P_MIN, f"rotation angles not uniform on SO(3): KS p = {p:.2g}"
    assert abs(z) < 4.0, f"mean trace {z:.1f} standard errors from 0"


def test_the_check_fails_on_the_old_draws():
    rng = np.random.default_rng(5)
    # uniform axis, angle uniform in [0, 2π): what every deck and scene drew before
    axis = rng.normal(size=(N, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    old = Rotation.from_rotvec(axis * rng.uniform(0, 2 * np.pi, size=(N, 1))).as_matrix()
    p, z = uniformity(old)
    assert p < 1e-6 and z > 4.0
    # LIGGGHTS's "orientation random": turns about x, y and z by angles uniform in [0, 2π); closer to
    # uniform (too few turns near 90°: 16 % within 90° of the identity instead of 18 %), so it takes
    # more draws to tell apart
    euler = Rotation.from_euler("xyz", rng.uniform(0, 2 * np.pi, size=(40 * N, 3))).as_matrix()
    assert uniformity(euler)[0] < 1e-6
    # and scipy's uniform rotations pass
    assert_uniform(Rotation.random(N, random_state=6).as_matrix())


@pytest.fixture(scope="module")
def templates():
    """Two grains without symmetry (boxes 1 x 2 x 3 and 2 x 3 x 5 mm), N copies in all."""
    out = []
    for k, extents in enumerate(((1.0, 2.0, 3.0), (2.0, 3.0, 5.0))):
        m = trimesh.creation.box(extents)
        out.append(prepare(m.vertices, m.faces, name=f"box{k}", spheres=6, count=N // 2))
    return out


@pytest.fixture(scope="module")
def polyhedra():
    out = []
    for k, extents in enumerate(((1.0, 2.0, 3.0), (2.0, 3.0, 5.0))):
        m = trimesh.creation.box(extents)
        out.append(prepare(m.vertices, m.faces, name=f"poly{k}", shape="polyhedron", count=N // 2))
    return out


def liggghts_quaternions(text: str) -> np.ndarray:
    """The ``orientation constant w x y z`` of every insertion, as LIGGGHTS parses them."""
    q = np.array([[float(x) for x in m] for m in re.findall(
        r"orientation constant (\S+) (\S+) (\S+) (\S+)", text)])
    # LIGGGHTS refuses a quaternion whose squared norm, summed in this order, is not exactly 1
    assert all(a * a + b * b + c * c + d * d == 1.0 for a, b, c, d in q.tolist())
    return q


def matrices(q_wxyz) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=np.float64)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()


def test_liggghts_pour_deck(templates, tmp_path):
    from grainforge.dem.liggghts import write_deck

    write_deck(templates, tmp_path)
    text = (tmp_path / "in.insert").read_text()
    assert "orientation random" not in text
    q = liggghts_quaternions(text)
    assert len(q) == N
    assert_uniform(matrices(q))


def test_lammps_pour_deck(templates, tmp_path):
    from grainforge.dem.lammps import write_deck

    write_deck(templates, tmp_path)
    rows = re.findall(r"rotate (\S+) (\S+) (\S+) (\S+) units box", (tmp_path / "in.insert").read_text())
    assert len(rows) == N
    theta = np.radians([float(r[0]) for r in rows])
    axis = np.array([[float(x) for x in r[1:]] for r in rows])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    assert_uniform(Rotation.from_rotvec(axis * theta[:, None]).as_matrix())


def test_lammps_body_deck(polyhedra, tmp_path):
    """The bodies' vertices, as data.bodies gives them to LAMMPS, turned from the templates' hulls."""
    from test_dem_engines import read_lammps_body_data

    from grainforge.dem.lammps_body import write_deck

    write_deck(polyhedra, tmp_path)
    bodies = read_lammps_body_data(tmp_path / "data.bodies")
    placements = {p["id"]: p for p in json.loads((tmp_path / "grains.json").read_text())["placements"]}
    hulls = {t.name: t.polyhedron for t in polyhedra}
    R = []
    for bid, b in bodies.items():
        hull = hulls[placements[bid]["name"]]
        rot, _ = Rotation.align_vectors(b["vertices"], hull)  # the turn taking the hull onto the body
        R.append(rot.as_matrix())
    assert len(R) == N
    assert_uniform(R)


def test_yade_pour_deck(templates, tmp_path):
    from grainforge.dem.yade import write_deck

    write_deck(templates, tmp_path)
    scene = json.loads((tmp_path / "grains.json").read_text())["scene"]
    assert len(scene["orientations"]) == N
    assert_uniform(matrices(scene["orientations"]))
    run = (tmp_path / "run.py").read_text()
    assert "rnd.gauss" not in run and "q = orientation(k)" in run


@pytest.mark.parametrize("test", ["tilt", "repose"])
@pytest.mark.parametrize("engine", ["yade", "liggghts"])
def test_virtual_test_scenes(templates, tmp_path, test, engine):
    """The tilt and repose scenes of both engines: the same orientation for grain k of a seed."""
    from grainforge.simulate.engine import write_test_deck
    from grainforge.simulate.settings import Settings

    write_test_deck(templates, test, settings=Settings(grains=N), seed=3, out=tmp_path, engine=engine)
    deck = json.loads((tmp_path / "grains.json").read_text())
    scene = deck["result"]["scene"] if engine == "liggghts" else deck["scene"]
    if engine == "liggghts":
        q = liggghts_quaternions((tmp_path / "in.insert").read_text())
        assert np.allclose(q, scene["orientations"], rtol=0, atol=1e-14)
    else:
        q = np.array(scene["orientations"])
        assert "random_rotation" not in (tmp_path / "run.py").read_text()
    assert len(q) == N
    assert_uniform(matrices(q))


def test_seeds_give_other_orientations():
    from grainforge.simulate.settings import Settings, scene_settings

    a = scene_settings(Settings(grains=50), "tilt", 0)["orientations"]
    b = scene_settings(Settings(grains=50), "tilt", 1)["orientations"]
    assert a == scene_settings(Settings(grains=50), "tilt", 0)["orientations"] and a != b
