"""DEM inputs at the edges of their ranges: bounded memory, clear refusals."""

from __future__ import annotations

import re

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from grainforge.cli.main import cli
from grainforge.dem import levelset


def _flat_box():
    box = trimesh.creation.box(extents=(4.0, 4.0, 0.2)).subdivide().subdivide()
    return np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)


def test_level_set_blocks_give_the_same_field(monkeypatch):
    v, f = _flat_box()
    small = levelset.level_set(v, f, spacing=0.2).distance
    monkeypatch.setattr(levelset, "DISTANCE_BLOCK", 10**9)
    whole = levelset.level_set(v, f, spacing=0.2).distance
    assert small.tobytes() == whole.tobytes()


def test_level_set_refuses_a_grid_over_the_node_budget(monkeypatch):
    v, f = _flat_box()
    monkeypatch.setattr(levelset, "MAX_NODES", 5_000)
    with pytest.raises(ValueError, match=r"spacing 0\.05 .* nodes, more than 5,000.*at least"):
        levelset.level_set(v, f, spacing=0.05)
    # the spacing the message proposes is accepted
    import re

    try:
        levelset.level_set(v, f, spacing=0.05)
    except ValueError as exc:
        proposed = float(re.search(r"at least ([0-9.e-]+)", str(exc)).group(1))
    assert levelset.level_set(v, f, spacing=proposed).distance.size <= 5_000


def test_a_level_set_spacing_too_fine_is_refused_in_one_line_before_the_estimate(angular_grains, tmp_path):
    """The node budget is checked for every grain up front: one line naming the file, exit 2, no deck (it
    used to come from the first template built, after the time estimate had been printed: two lines)."""
    out = tmp_path / "d"
    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(out), "--engine", "yade",
                                   "--shape", "levelset", "--spacing", "0.01", "--workers", "1"])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and re.match(r"Error: .*angular-0000\.stl: level-set spacing 0\.01 of d_eq needs .* "
                                        r"use a spacing of at least", lines[0]), res.stderr
    assert not out.exists()


def test_a_manifest_of_random_bytes_is_named(tmp_path):
    from grainforge.io.inputs import mesh_paths

    bad = tmp_path / "manifest.csv"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    with pytest.raises(ValueError, match=r"manifest\.csv: not a grainforge manifest"):
        mesh_paths([bad])
    with pytest.raises(ValueError, match=r"manifest\.csv: not a grainforge manifest"):
        mesh_paths([tmp_path])


def _cli() -> list[str]:
    """The installed ``grainforge`` script when there is one: pool workers then import it as their
    main module, as they do for a user (a ``-c`` command has no main module to import)."""
    import shutil
    import sys
    from pathlib import Path

    script = Path(sys.executable).parent / "grainforge"
    if script.is_file():
        return [str(script)]
    found = shutil.which("grainforge")
    return [found] if found else [sys.executable, "-c", "from grainforge.cli.main import main; main()"]


_CLI = _cli()


def _processes_with(marker: str) -> list[int]:
    import os

    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/environ", "rb") as fh:
                    if marker.encode() in fh.read():
                        found.append(int(name))
            except OSError:
                pass
    return found


def _heavy_dem_run(tmp_path, **popen):
    """A marked ``dem`` of 8 angular grains with 48 s of clump work: (process, marker, deck folder)."""
    import os
    import subprocess
    import uuid

    grains = tmp_path / "grains"
    subprocess.run([*_CLI, "generate", "angular", "--count", "8", "--size", "2",
                    "--subdivisions", "3", "--out", str(grains)], check=True, capture_output=True)
    marker = f"GRAINFORGE_TEST_{uuid.uuid4().hex}"
    out = tmp_path / "deck"
    p = subprocess.Popen([*_CLI, "dem", str(grains), "--out", str(out),
                          "--spheres", "300", "--refine-iterations", "100", "--workers", "2"],
                         env=dict(os.environ, **{marker: "1"}), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, **popen)
    return p, marker, out


@pytest.mark.slow
@pytest.mark.parametrize("signame, delay", [("SIGINT", 0.8), ("SIGTERM", 1.6), ("SIGINT", 2.5), ("SIGTERM", 4.0)])
def test_dem_honours_signals_at_any_moment(tmp_path, delay, signame):
    """While the pool starts and while it works: one line, the usual code, no process and no deck left.
    Each signal is sent once while the pool starts (0.8, 1.6 s) and once while it works (2.5, 4 s): the
    moment decides what there is to stop, the signal only which line and code the command ends with.
    (How quickly the command stops is a figure for docs/benchmarks.md, not an assertion: the 60 s
    below only guards against a hang.)"""
    import signal
    import time

    p, marker, out = _heavy_dem_run(tmp_path, text=True,
                                    preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(delay)
    p.send_signal(getattr(signal, signame))
    _, err = p.communicate(timeout=60)
    expected = {"SIGINT": (130, "Interrupted."), "SIGTERM": (143, "Terminated.")}[signame]
    if p.returncode == 0:  # finished before the signal: nothing to test at this delay
        pytest.skip("the command finished before the signal")
    assert (p.returncode, err.strip()) == expected, err
    assert not out.exists()
    time.sleep(1.0)
    assert _processes_with(marker) == []


@pytest.mark.parametrize("args,says", [
    (["--density", "1e300"], "'--density': 1e+300 is not in the range"),
    (["--density", "0"], "'--density': 0.0 is not in the range"),
    (["--unit", "1e30"], "'--unit': 1e+30 is not in the range"),
    (["--unit", "1e-30"], "'--unit': 1e-30 is not in the range"),
    (["--unit", "1e-9"], "equivalent diameter 2e-09 m is outside 1e-05–10 m"),
    (["--unit", "100"], "equivalent diameter 200 m is outside 1e-05–10 m"),
    (["--spheres", "1"], "'--spheres': 1 is not in the range 2<=x<=1000"),
    # Yade's polyhedra crash the engine at 12 µm
    (["--shape", "polyhedron", "--unit", "6e-6"], "equivalent diameter 1.2e-05 m is outside 2e-05–10 m"),
])
def test_dem_refuses_unphysical_settings(angular_grains, tmp_path, args, says):
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    out = tmp_path / "deck"
    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(out), "--workers", "1", *args])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and says in lines[0], res.output
    assert not out.exists()


def test_dem_says_when_clumps_have_fewer_spheres_than_asked(angular_grains, tmp_path):
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(tmp_path / "d"), "--workers", "1",
                                   "--spheres", "500"])
    assert res.exit_code == 0, res.output
    import json

    placed = [g["spheres"] for g in json.loads((tmp_path / "d" / "grains.json").read_text())["grains"]]
    assert max(placed) < 500
    assert f"clumps have {min(placed)}–{max(placed)} spheres (at most 500 asked)" in res.output


def test_liggghts_takes_grains_of_ten_microns(angular_grains, tmp_path):
    """LIGGGHTS refuses templates below 1e-12 m³ unless told otherwise; the deck tells it."""
    import subprocess

    from click.testing import CliRunner
    from test_dem_engines import require

    from grainforge.cli.main import cli

    require("liggghts")
    deck = tmp_path / "d"
    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(deck), "--workers", "1", "--engine",
                                   "liggghts", "--spheres", "10", "--unit", "5.5e-6"])  # 2 mm in the file: 11 µm
    assert res.exit_code == 0, res.output
    run = subprocess.run(["liggghts", "-in", "in.run"], cwd=deck, capture_output=True, text=True, timeout=300)
    assert "Volume expectancy too small" not in run.stdout
    assert "ERROR" not in run.stdout, run.stdout[-2000:]
    assert (deck / "bodies-final.txt").is_file()


def test_an_ascii_stl_with_text_coordinates_is_named(tmp_path):
    from grainforge.io import read_mesh

    bad = tmp_path / "text.stl"
    bad.write_text("solid x\nfacet normal 0 0 1\nouter loop\nvertex a b c\nvertex 1 0 0\nvertex 0 1 0\n"
                   "endloop\nendfacet\nendsolid x\n")
    with pytest.raises(ValueError, match=r"text\.stl: corrupt or unsupported mesh file"):
        read_mesh(bad)


def test_grain_size_is_refused_before_the_representation_is_built(monkeypatch):
    """The size check comes before the clump (the costly part): a refused grain never reaches it."""
    import trimesh

    from grainforge.dem import clump as clump_module
    from grainforge.dem.template import prepare

    def no_clump(*args, **kwargs):
        raise AssertionError("the clump was built for a grain outside the size range")

    monkeypatch.setattr(clump_module, "clump", no_clump)
    box = trimesh.creation.box((2.0, 2.0, 2.0))
    with pytest.raises(ValueError, match=r"box.stl: equivalent diameter 2.48e-06 m is outside 1e-05–10 m"):
        prepare(box.vertices, box.faces, name="box", unit=1e-6, source="box.stl", size_range=(1e-5, 10.0))
    t = prepare(box.vertices, box.faces, name="box", spheres=4, shape="polyhedron", size_range=(1e-5, 10.0))
    assert abs(t.d_eq - 2.48e-3) < 1e-5


@pytest.mark.parametrize("args,says", [
    (["--refine-iterations", "10000", "--spheres", "1000"],
     "2000 clump template(s) would take about 1.9 days of computing (2.8 min each on 2 workers; limit 1 day); "
     "lower --refine-iterations (or --spheres), or give fewer grain files"),
    (["--shape", "levelset", "--spacing", "0.01"],
     "2000 levelset template(s) would take about 4.2 days of computing (6.1 min each on 2 workers; limit 1 day); "
     "raise --spacing, or give fewer grain files"),
])
def test_dem_refuses_template_work_beyond_a_day_up_front(angular_grains, tmp_path, args, says):
    """Heavy but valid settings on many files: the estimate refuses them before any template is built."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    many = tmp_path / "many"
    many.mkdir()
    grain = sorted(angular_grains.glob("*.stl"))[0]
    for k in range(2000):
        (many / f"g{k:04d}.stl").symlink_to(grain)
    out = tmp_path / "deck"
    res = CliRunner().invoke(cli, ["dem", str(many), "--out", str(out), "--workers", "2", *args])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert lines == [f"Error: {says}"], res.output
    assert not out.exists()


def test_dem_announces_template_work_over_a_minute(angular_grains, tmp_path, monkeypatch):
    """Valid heavy work runs, saying first how long it may take (the model's upper bound)."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli
    from grainforge.runtime import estimate

    # a model 1000 times slower than measured: three grains look like minutes of work
    monkeypatch.setattr(estimate, "DEM_TEMPLATE_SECONDS", 80.0)
    res = CliRunner().invoke(cli, ["dem", str(angular_grains), "--out", str(tmp_path / "d"), "--workers", "1",
                                   "--spheres", "4"])
    assert res.exit_code == 0, res.output
    assert "estimated time: about 4 min (a rough model" in res.output


@pytest.mark.slow
def test_dem_killed_leaves_no_process_and_says_nothing(tmp_path):
    """SIGKILL of the owner: its workers, fork server and resource tracker exit by themselves, the
    tracker cleans up the pool's semaphores without a warning on the user's terminal, no deck."""
    import signal
    import time

    p, marker, out = _heavy_dem_run(tmp_path)
    deadline = time.monotonic() + 60
    while len(_processes_with(marker)) < 4 and time.monotonic() < deadline:  # owner, server, 2 workers
        time.sleep(0.1)
    time.sleep(1.0)
    if p.poll() is not None:
        pytest.skip("the command finished before the signal")
    p.send_signal(signal.SIGKILL)
    _, err = p.communicate(timeout=60)
    for _ in range(50):  # the workers notice their owner's death within a second
        if not _processes_with(marker):
            break
        time.sleep(0.1)
    assert _processes_with(marker) == []
    assert err == b"", err  # the pipe stays open until every process holding it has exited
    assert not out.exists()
