"""Virtual bulk tests (grainforge simulate): the angle measurement, settings, CLI errors, and a
quick run in the real Yade.

Without Yade the engine test is skipped with the reason; with GRAINFORGE_REQUIRE_ENGINES=1
(set by .ci/run) a missing Yade is a failure.
"""

import csv
import json
import math
import re
import shutil

import numpy as np
import pytest
from conftest import refused_in_one_line, require_engine

from grainforge.cli.main import cli
from grainforge.params import ParameterError
from grainforge.simulate import QUICK, Settings, scene_settings, summarise
from grainforge.simulate.angles import heap_angle, tilt_failure_angle


def cone(angle_deg, n=30000, foot=20.0, r=0.1, seed=0):
    """Spheres filling a cone of the given angle (the heap's top surface is the cone)."""
    rng = np.random.default_rng(seed)
    rad = np.sqrt(rng.random(n)) * foot
    az = rng.random(n) * 2 * np.pi
    top = (foot - rad) * np.tan(np.radians(angle_deg))
    z = top * rng.random(n) ** 0.1 - r
    return np.column_stack([rad * np.cos(az) + 3.0, rad * np.sin(az) - 1.0, z, np.full(n, r)])


@pytest.mark.parametrize("angle", [18.0, 27.0, 38.0, 48.0])
def test_heap_angle_of_a_cone(angle):
    h = heap_angle(cone(angle), bin_width=0.5, grain_size=1.0)
    assert h.angle == pytest.approx(angle, abs=1.0)
    assert h.spread < 1.5
    # the foot is where the surface falls to one grain (1.0) above the base, to within a ring
    assert h.foot == pytest.approx(20.0 - 1.0 / np.tan(np.radians(angle)), abs=0.5)
    # the fitted slope starts where the cone is at 80 % of its height (r = 4), to within three rings
    assert h.fitted[0] == pytest.approx(4.0, abs=1.5)


def test_heap_angle_is_independent_of_where_the_heap_stands():
    a = heap_angle(cone(30.0), bin_width=0.5, grain_size=1.0).angle
    shifted = cone(30.0)
    shifted[:, :2] += 100.0
    shifted[:, 2] += 5.0
    assert heap_angle(shifted, bin_width=0.5, grain_size=1.0, base=5.0).angle == pytest.approx(a, abs=1e-9)


def test_heap_angle_leaves_out_a_flat_top():
    # a truncated cone (the flat top a lifted cylinder leaves): the plateau must not lower the angle
    pts = cone(35.0)
    cap = 0.7 * 20.0 * np.tan(np.radians(35.0))
    pts[:, 2] = np.minimum(pts[:, 2], cap - pts[:, 3])
    assert heap_angle(pts, bin_width=0.5, grain_size=1.0).angle == pytest.approx(35.0, abs=1.0)


def test_heap_angle_refuses_a_flat_layer():
    flat = cone(30.0)
    flat[:, 2] = 0.0
    with pytest.raises(ValueError, match="too flat"):
        heap_angle(flat, bin_width=0.5, grain_size=1.0)


def test_tilt_failure_angle_interpolates_and_reports_no_failure():
    h = np.array([[30.0, 0.0], [31.0, 0.2], [32.0, 0.8]])
    assert tilt_failure_angle(h) == pytest.approx(31.5)
    assert math.isnan(tilt_failure_angle(h[:2]))      # never failed
    assert math.isnan(tilt_failure_angle(h[2:]))      # had failed at the first angle: unknown


def _drawn_crossing(ax, line, threshold):
    """Where ``line`` as drawn (straight segments in display space: the log axis's) first rises above
    ``threshold``, in data units."""
    xy = ax.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
    level = ax.transData.transform([[0.0, threshold]])[0, 1]
    k = int(np.nonzero(xy[:, 1] > level)[0][0])
    (x0, y0), (x1, y1) = xy[k - 1], xy[k]
    x = x0 + (x1 - x0) * (level - y0) / (y1 - y0)
    return float(ax.transData.inverted().transform([[x, level]])[0, 0])


@pytest.mark.parametrize("history", [
    [[22.0, 0.0], [23.0, 0.004], [24.0, 0.05], [25.0, 1.5], [26.0, 3.0]],   # a slide: a jump of decades
    [[15.0, 1e-5], [16.0, -0.002], [17.0, 0.3], [18.0, 0.45], [19.0, 0.6]],  # creep; a displacement below 0
    [[30.0, 0.0], [30.5, 0.2], [31.0, 0.5], [31.5, 0.8]],                    # at the threshold, then over it
])
def test_the_tilt_figure_crosses_the_threshold_at_the_reported_failure_angle(history):
    """tilt.png's line of a seed (as the command draws it: simulate.results.figure) crosses half a grain diameter,
    read in the log axis's own space, at the angle results.csv reports (measure_result)."""
    import matplotlib.pyplot as plt

    from grainforge.simulate.engine import measure_result
    from grainforge.simulate.results import figure

    result = {"test": "tilt", "d_mean": 0.002, "grains": 30, "inserted": 30, "lost": 0, "steps": 1, "dt": 1e-5,
              "time": 1.0, "history": history, "failure_angle": 1.0}
    row = {"seed": 0, **measure_result(result)}
    fig = figure("tilt", [result], [row])
    ax = fig.axes[0]
    (line,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("seed 0")]
    assert ax.get_yscale() == "log" and f"fails at {row['angle_deg']:.1f}°" in line.get_label()
    assert _drawn_crossing(ax, line, 0.5) == pytest.approx(row["angle_deg"], abs=1e-9)
    # the markers are the record's own increments
    marks = np.column_stack([line.get_xdata(), line.get_ydata()])[line.get_markevery()]
    assert marks == pytest.approx(np.maximum(np.array(history), [-np.inf, 1e-4]))
    plt.close(fig)


def test_settings_refuse_negative_friction_and_convert_mu_to_an_angle():
    with pytest.raises(ParameterError, match="friction"):
        Settings(friction=-0.1)
    assert scene_settings(Settings(friction=1.0), "tilt", 0)["friction_deg"] == pytest.approx(45.0)
    with pytest.raises(ValueError, match="test must be"):
        scene_settings(Settings(), "triaxial", 0)


def test_summarise_over_seeds():
    s = summarise([{"angle_deg": 30.0}, {"angle_deg": 34.0}, {"angle_deg": float("nan")}])
    assert s["runs"] == 2 and s["angle_mean_deg"] == 32.0 and s["angle_sd_deg"] == pytest.approx(2 ** 1.5)


@pytest.fixture
def grains(tmp_path, runner):
    out = tmp_path / "g"
    r = runner.invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                            "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return out


@pytest.mark.parametrize("args, message", [
    (["--friction", "-0.2"], "friction"),
    (["--grains", "1"], "grains"),
    (["--density", "0"], "density"),
])
def test_bad_settings_give_one_line_and_exit_2(runner, grains, tmp_path, args, message):
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *args])
    refused_in_one_line(r)
    assert message in r.stderr
    assert not out.exists()


def test_a_folder_without_grains_is_refused(runner, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    r = runner.invoke(cli, ["simulate", "tilt", str(empty), "--out", str(tmp_path / "sim")])
    refused_in_one_line(r)
    assert "no grain files" in r.stderr
    assert not (tmp_path / "sim").exists()


def test_a_mesh_yade_cannot_load_is_refused(runner, tmp_path):
    require_engine("yade")
    bad = tmp_path / "open.stl"
    import trimesh

    box = trimesh.creation.box()
    trimesh.Trimesh(box.vertices, box.faces[:-1]).export(bad)
    r = runner.invoke(cli, ["simulate", "repose", str(bad), "--out", str(tmp_path / "sim"), "--quick"])
    refused_in_one_line(r)
    assert "open.stl" in r.stderr and re.search("not a (closed|valid) solid", r.stderr)
    assert not (tmp_path / "sim").exists()


@pytest.mark.slow
@pytest.mark.parametrize("test", ["repose", "tilt"])
def test_quick_run_in_yade(runner, grains, tmp_path, test):
    require_engine("yade")
    out = tmp_path / test
    # the plumbing at the tilt's 30 grains in both tests, of soft contacts (E = 1e5 Pa: a time step three times
    # longer, 8 s of CPU a repose instead of 15). The quick runs as --quick sets them (a repose heap of 120 grains,
    # which has a slope to measure, and the tilt, at E = 1e6 Pa) are the documented commands':
    # tests/project/test_documented_commands.py
    r = runner.invoke(cli, ["simulate", test, str(grains), "--out", str(out), "--quick", "--grains",
                            str(QUICK["grains"]), "--young", "1e5"])
    rows = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    # exit 0, or 3 when a run fails its own check (a heap of 30 grains may be too flat to measure), named on stderr
    assert r.exit_code == 0 or (r.exit_code == 3 and "check failed: seed" in r.stderr), r.output
    assert len(rows) == QUICK["seeds"]
    row = rows[0]
    assert int(row["inserted"]) == QUICK["grains"] and int(row["lost"]) == 0
    assert row["setting_friction"] == "0.5"
    if test == "repose":
        assert row["settled"] == "True"
        # a heap of 30 grains may be too small to have a slope: then the angle is NaN and the note says why
        angle = float(row["angle_deg"])
        assert 0.0 < angle < 60.0 or (math.isnan(angle) and "too flat" in row["note"])
    assert (out / f"{test}.png").stat().st_size > 10_000
    assert (out / f"{test}-seed0" / "run.py").is_file()
    assert "angle" in r.stderr + r.stdout
    check_placed_as_the_deck_says(out / f"{test}-seed0")
    # the temporary folder this run's Yade made (/tmp/yade-*, named in its log) is gone
    (named,) = yade_temp_folders(out / f"{test}-seed0" / "yade.log")
    assert named.name.startswith("yade-") and not named.exists()


def yade_temp_folders(log):
    """The temporary folders a Yade run named in its log (the deck's first line)."""
    from pathlib import Path

    from grainforge.simulate.process import TEMPDIR_LINE

    return [Path(ln.split(maxsplit=1)[1]) for ln in log.read_text().splitlines() if ln.startswith(TEMPDIR_LINE)]


class _Stop(Exception):
    """An interruption raised inside the engine run's progress callback (as a Ctrl-C is raised in its loop)."""


def test_a_yade_run_stopped_leaves_no_temporary_folder(grains, tmp_path, monkeypatch):
    """Yade makes /tmp/yade-XXXXXX whatever TMPDIR says, and leaves it when a -x script ends or when it is killed:
    a real Yade tilt run, with TMPDIR pointed at a fresh folder, stopped at its first progress line (the engine
    killed, as on Ctrl-C): the folder it named is gone, and none is in TMPDIR."""
    require_engine("yade")
    from grainforge.simulate import build_population, run_yade, write_test_deck

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    settings = Settings(**{**QUICK, "grains": 10, "templates": 2, "spheres": 2})
    deck = tmp_path / "deck"
    write_test_deck(build_population([grains], settings), "tilt", settings=settings, seed=0, out=deck)

    def stop(fraction, phase):
        raise _Stop(phase)

    with pytest.raises(_Stop):
        run_yade(deck, progress=stop)
    (named,) = yade_temp_folders(deck / "yade.log")
    assert named.name.startswith("yade-") and not named.exists()
    assert not list(tmp.glob("yade-*"))


@pytest.mark.parametrize("stopped", [True, False], ids=["stopped", "ended"])
def test_a_temporary_folder_the_engine_names_is_removed_after_it_however_it_ended(tmp_path, stopped):
    """A stand-in engine names two folders and is killed (the run stopped at its progress line), or ends by itself:
    the one whose name begins with the engine's prefix is removed with what it holds, the other one kept."""
    from grainforge.simulate.process import run_engine_process

    mine, other = tmp_path / "yade-x", tmp_path / "kept"
    engine = _fake_engine(tmp_path / "engine", f'mkdir "{mine}" "{other}"\ntouch "{mine}/file"\n'
                                               f'echo "grainforge-tempdir {mine}"\necho "grainforge-tempdir {other}"\n'
                                               'echo "grainforge-progress 0.5 running"\n'
                                               + ("sleep 60\n" if stopped else ""))

    def stop(fraction, phase):
        if stopped:
            raise _Stop(phase)

    run = lambda: run_engine_process([str(engine)], tmp_path, log_path=tmp_path / "log", env={},  # noqa: E731
                                     progress=stop, temp_prefix="yade-")
    if stopped:
        with pytest.raises(_Stop):
            run()
    else:
        assert run() == 0
    assert not mine.exists() and other.is_dir()


def check_placed_as_the_deck_says(run_dir):
    """Yade placed grain k turned by row k of grains.json's orientations: every contact sphere, as Yade
    held it right after insertion, sits at the grain's centre + R_k · (its template offset)."""
    from scipy.spatial.transform import Rotation

    deck = json.loads((run_dir / "grains.json").read_text())
    q = np.array(deck["scene"]["orientations"])
    R = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    placed = json.loads((run_dir / "result.json").read_text())["placed"]
    bodies = np.array(placed["bodies"])
    ids = np.unique(bodies[:, 3]).astype(int)
    assert len(ids) == len(placed["drawn"]) == len(placed["centres"])
    files = {t["name"]: t["xyzr"] for t in deck["grains"]}
    for k, (cid, name, centre) in enumerate(zip(ids, placed["drawn"], placed["centres"])):
        rows = np.loadtxt(run_dir / files[name], comments="#").reshape(-1, 4)
        mine = bodies[bodies[:, 3] == cid, :3]
        expect = np.array(centre) + rows[:, :3] @ R[k].T
        assert len(mine) == len(rows)
        d = np.linalg.norm(mine[:, None] - expect[None], axis=2).min(axis=1)
        assert d.max() < 1e-9 * np.abs(rows[:, 3]).max() * 1e3, (k, name)


# ---- settings an engine cannot run: one line, exit 2, before any engine starts or anything is written ----

REFUSED = [
    (["--engine", "lammps"], "--engine"),
    (["--mpi", "0"], "--mpi"),
    (["--mpi", "-3"], "--mpi"),
    (["--engine", "liggghts", "--mpi", "0"], "--mpi"),
    (["--mpi", "2"], "--mpi: yade runs one process per seed"),
    (["--shape", "polyhedron"], "'polyhedron' is not one of 'clump', 'levelset'"),
    (["--shape", "levelset", "--spheres", "20"], "--spheres sets a clump's size"),
    (["--shape", "levelset", "--as-spheres"], "--as-spheres is the sphere baseline"),
    (["--spacing", "0.1"], "--spacing is the level set's grid"),
    (["--shape", "levelset", "--spacing", "0.7"], "--spacing"),
    (["--shape", "levelset", "--grains", "20000", "--seeds", "100", "--spacing", "0.02"], "level sets of spacing"),
    (["--shape", "sphere"], "--shape"),
    (["--engine", "liggghts", "--shape", "levelset"], "--shape levelset: simulate's liggghts scenes take --shape clump only"),
    (["--engine", "liggghts", "--shape", "polyhedron", "--mpi", "2"], "'polyhedron' is not one of"),
]


@pytest.mark.parametrize("test", ["repose", "tilt"])
@pytest.mark.parametrize("args, message", REFUSED, ids=[" ".join(a) for a, _ in REFUSED])
def test_settings_an_engine_cannot_run_are_refused_up_front(runner, grains, tmp_path, test, args, message):
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", test, str(grains), "--out", str(out), "--quick", *args])
    refused_in_one_line(r)
    assert message in r.stderr
    assert not out.exists()


def test_a_level_set_tilt_too_narrow_for_yades_periodic_cell_is_refused(runner, grains, tmp_path):
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "tilt", str(grains), "--out", str(out), "--shape", "levelset",
                            "--grains", "30"])
    refused_in_one_line(r)
    assert "needs --grains ≥ 49" in r.stderr
    assert not out.exists()


@pytest.mark.slow
def test_quick_level_set_tilt_in_yade(runner, grains, tmp_path):
    """A level-set tilt completes: the fewest grains --quick allows, a coarse grid, few tilt steps, soft contacts
    (a larger time step: about 30 s; 60 s at --tilt-start 30 and --young 2e5)."""
    require_engine("yade")
    out = tmp_path / "ls"
    r = runner.invoke(cli, ["simulate", "tilt", str(grains), "--out", str(out), "--quick", "--shape", "levelset",
                            "--spacing", "0.15", "--templates", "2", "--tilt-start", "40", "--tilt-step", "5",
                            "--young", "5e4"])
    # exit 3: a run failed its own check (a quick run may measure no angle), named on stderr
    assert r.exit_code == 0 or (r.exit_code == 3 and "check failed: seed" in r.stderr), r.output
    (row,) = list(csv.DictReader((out / "results.csv").read_text().splitlines()))
    assert int(row["inserted"]) == 49 and int(row["lost"]) == 0
    assert row["shape"] == "levelset" and float(row["spacing"]) == 0.15
    # the layer was tilted: its displacement record starts at the first tilt angle
    result = json.loads((out / "tilt-seed0" / "result.json").read_text())
    assert result["history"][0][0] == pytest.approx(40.0)
    assert all(np.isfinite(h[1]) for h in result["history"])
    assert "Ig2_LevelSet_LevelSet_ScGeom" in (out / "tilt-seed0" / "run.py").read_text()
    assert any((out / "tilt-seed0").glob("*.levelset.json"))


def test_an_engine_that_is_not_installed_is_refused_up_front(runner, grains, tmp_path, monkeypatch):
    monkeypatch.setenv("GRAINFORGE_YADE", str(tmp_path / "no-such-yade"))
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), "--quick"])
    refused_in_one_line(r)
    assert "Yade is not installed" in r.stderr
    assert not out.exists()


@pytest.mark.parametrize("variable, args, message", [
    ("GRAINFORGE_LIGGGHTS", ["--engine", "liggghts"], "LIGGGHTS is not installed"),
    ("GRAINFORGE_LIGGGHTS", ["--engine", "liggghts", "--mpi", "2"], "LIGGGHTS is not installed"),
    ("GRAINFORGE_MPIRUN", ["--engine", "liggghts", "--mpi", "2"], "--mpi: mpirun is not installed"),
])
def test_liggghts_or_mpirun_not_installed_is_refused_up_front(runner, grains, tmp_path, monkeypatch, variable, args,
                                                              message):
    if variable == "GRAINFORGE_MPIRUN" and shutil.which("liggghts") is None:
        monkeypatch.setenv("GRAINFORGE_LIGGGHTS", str(_fake_engine(tmp_path / "liggghts", "exit 0\n")))
    monkeypatch.setenv(variable, str(tmp_path / "no-such-engine"))
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "tilt", str(grains), "--out", str(out), "--quick", *args])
    refused_in_one_line(r)
    assert message in r.stderr
    assert not out.exists()


def _fake_engine(path, body):
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(0o755)
    return path


def test_a_failed_engine_run_keeps_its_deck_and_log_and_says_where(runner, grains, tmp_path, monkeypatch):
    """An engine failure (not an interrupt) keeps that run's deck and log in --out/failed-<run>/, named in
    the error line; no result appears, and the rerun is not refused for it."""
    fake = _fake_engine(tmp_path / "yade", 'echo "run.py line 3: the scene broke"\nexit 3\n')
    monkeypatch.setenv("GRAINFORGE_YADE", str(fake))
    out = tmp_path / "sim"
    for _ in range(2):  # the second run replaces the first one's failed folder
        r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), "--quick"])
        assert r.exit_code == 1, r.output
        # the run's estimate (said once its grains are made) and the failure: one line of error
        lines = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith("estimated time: ")]
        assert len(lines) == 1 and "Traceback" not in r.output, r.stderr
        assert "Yade failed in repose-seed0 (exit 3): run.py line 3: the scene broke" in lines[0]
        assert str(out / "failed-repose-seed0") in lines[0]
        assert sorted(p.name for p in out.iterdir()) == ["failed-repose-seed0"]
        kept = out / "failed-repose-seed0"
        assert (kept / "run.py").is_file() and (kept / "grains.json").is_file()
        assert "the scene broke" in (kept / "yade.log").read_text()


def test_an_interrupt_kills_the_engine_with_its_children_and_leaves_nothing(grains, tmp_path):
    """The engine's whole process group goes (an mpirun's ranks are its children): a stand-in engine that
    starts a child and waits; SIGINT to the command; both gone, --out not created."""
    from _processes import interrupt_simulate_run

    interrupt_simulate_run(["repose", str(grains)], tmp_path)


def test_an_engine_process_starts_with_ctrl_c_ignored_and_sigterm_default_and_neither_blocked(tmp_path):
    """The owner blocks SIGINT/SIGTERM while it forks the engine (a signal to the whole group must not run the
    owner's handler in the half-made child); the engine must not inherit that block, or it could not be
    stopped with SIGTERM."""
    import signal

    from grainforge.simulate.process import run_engine_process

    rc = run_engine_process(["sh", "-c", "grep -E '^Sig(Blk|Ign)' /proc/self/status"], tmp_path,
                            log_path=tmp_path / "log.txt", env={}, progress=None)
    assert rc == 0
    masks = dict(line.split(":") for line in (tmp_path / "log.txt").read_text().splitlines())
    blocked, ignored = int(masks["SigBlk"], 16), int(masks["SigIgn"], 16)
    bit = {s: 1 << (s - 1) for s in (signal.SIGINT, signal.SIGTERM)}
    assert not blocked & (bit[signal.SIGINT] | bit[signal.SIGTERM])
    assert ignored & bit[signal.SIGINT] and not ignored & bit[signal.SIGTERM]
    # and the owner's own mask is as it was
    assert not signal.pthread_sigmask(signal.SIG_BLOCK, set()) & {signal.SIGINT, signal.SIGTERM}


def test_a_heap_whose_surface_does_not_fall_outwards_has_no_angle():
    """30 quick-run grains (a Yade heap's spheres, stored) whose fitted surface rises outwards: refused as too flat
    (the run then reports NaN with that note), not reported as a negative angle of repose (it was -11.9°)."""
    from pathlib import Path

    with np.load(Path(__file__).parents[1] / "data" / "tiny-heap.npz") as data:
        spheres, base, d = data["spheres"], float(data["base_top"]), float(data["d_mean"])
    with pytest.raises(ValueError, match="too flat or too small .*does not fall outwards"):
        heap_angle(spheres, bin_width=0.5 * d, grain_size=d, base=base)


def test_a_heap_measured_on_a_shelf_has_no_angle():
    """80 quick-run grains of rough spheres (a Yade heap two grain layers high, stored): the rings between 20 % and
    80 % of its height are a shelf whose line falls by 1 % of that band; refused as too flat, not reported as an
    angle of repose (it was 0.3°)."""
    from pathlib import Path

    with np.load(Path(__file__).parents[1] / "data" / "shelf-heap.npz") as data:
        spheres, base, d = data["spheres"], float(data["base_top"]), float(data["d_mean"])
    with pytest.raises(ValueError, match="too flat or too small .*a shelf, not a slope"):
        heap_angle(spheres, bin_width=0.5 * d, grain_size=d, base=base)


def test_a_short_slope_of_a_default_heap_is_measured():
    """A default repose heap of 200 rough-angular grains (Yade, seed 1, stored) whose slope has three rings in the
    20-80 % band, falling by 48 % of it: measured (36.7°), not taken for a shelf."""
    from pathlib import Path

    with np.load(Path(__file__).parents[1] / "data" / "short-slope-heap.npz") as data:
        spheres, base, d = data["spheres"], float(data["base_top"]), float(data["d_mean"])
    assert heap_angle(spheres, bin_width=0.5 * d, grain_size=d, base=base).angle == pytest.approx(36.7, abs=0.1)


def test_an_as_spheres_template_is_bounded_by_its_sphere():
    """--as-spheres: the template's clump is the volume-equivalent sphere and its bounding radius (by which the
    scenes space the grains) is that sphere's, not the one-sphere clump's it replaces (a grown clump sphere
    reached 11 % past the grain)."""
    from grainforge.methods import generate, get
    from grainforge.simulate.specimen import _template

    g = generate("cri", get("cri").Params(subdivisions=3), 2)
    v = np.asarray(g.vertices) * 2.0  # about 2 mm
    t = _template((v, np.asarray(g.faces), "g", Settings(), "test", 0, True, "clump", 0.05, None))
    assert t.clump.radii.tolist() == [pytest.approx(t.d_eq / 2.0)]
    assert t.bounding_radius == pytest.approx(t.d_eq / 2.0, rel=0.01)


def test_an_owned_engine_ends_as_its_command_and_dies_with_its_owner(tmp_path):
    """Engines start through runtime.children.run_owned (no preexec_fn): the command's exit status and its signal
    come back as they were; an owner killed by SIGKILL takes the command with it (the launcher polls the owner)."""
    import signal
    import subprocess
    import sys
    import time

    from _processes import alive, assert_gone

    from grainforge.runtime.children import owned_command

    assert subprocess.run(owned_command(["sh", "-c", "exit 3"])).returncode == 3
    assert subprocess.run(owned_command(["sh", "-c", "kill -TERM $$"])).returncode == -signal.SIGTERM
    pid_file = tmp_path / "engine.pid"
    engine = [sys.executable, "-c", f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); "
              "time.sleep(60)"]
    owner = subprocess.Popen([sys.executable, "-c", "import subprocess, time\n"
                              "from grainforge.runtime.children import owned_command\n"
                              f"subprocess.Popen(owned_command({engine!r}), start_new_session=True)\n"
                              "time.sleep(60)"])
    deadline = time.monotonic() + 30
    while not (pid_file.exists() and pid_file.read_text()):
        assert time.monotonic() < deadline, "the owned command never started"
        time.sleep(0.05)
    pid = int(pid_file.read_text())
    assert alive(pid)
    owner.kill()
    owner.wait()
    assert_gone([pid], wait=5.0)
