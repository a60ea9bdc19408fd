"""Geometry that is not what it claims is named, not taken at face value.

- a hollow grain (an outer shell and an inward-facing inner shell in one file): ``analyse`` lists one
  grain flagged ``cavity`` (the inner shell is no row, in the table or the Sand Atlas table); ``dem``
  and ``simulate`` refuse it in one line;
- overlapping bodies: flagged by ``analyse`` (``not-solid`` when they share vertices, ``overlapping``
  when they do not), refused by ``dem`` and ``simulate`` with the same check;
- absurd sizes (a sphere scaled to 1e37 or 1e-9 mm) and coordinates too far from the origin for float32
  (a sphere at 1e9 mm): refused in one line naming the file, the problem and what to do, exit 2,
  nothing written; never "holds no triangles";
- ordinary grains are measured and decked as before.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from conftest import refused_in_one_line

from grainforge.analysis.measure import analyse_file, solid_grain
from grainforge.cli.main import cli
from grainforge.fabrication.scale import MESH_SIZE_RANGE_MM, SIZE_RANGE_MM
from grainforge.geometry.solid import FLOAT32_OFFSET_LIMIT, body_nesting, precision_problem

FAST = ["--no-fractal", "--no-fourier", "--workers", "1"]


def _sphere(radius=1.0, subdivisions=2):
    return trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("odd")
    outer, inner = _sphere(1.0), _sphere(0.5, 1)
    inner.invert()
    trimesh.util.concatenate([outer, inner]).export(d / "hollow.stl")
    # two overlapping spheres: sharing vertices (one body that pinches) and apart (two bodies)
    b = _sphere()
    b.apply_translation((1.0, 0.0, 0.0))
    trimesh.util.concatenate([_sphere(), b]).export(d / "overlap.stl")
    c = _sphere()
    c.apply_translation((0.7, 0.13, 0.05))
    trimesh.util.concatenate([_sphere(), c]).export(d / "overlap-apart.stl")
    for name, scale in (("huge", 1e37), ("tiny", 1e-9)):
        s = _sphere()
        s.apply_scale(scale)
        s.export(d / f"{name}.stl")
    far = _sphere()
    far.apply_translation((1e9, 0.0, 0.0))  # the shape mangled by float32 (faces collapse)
    far.export(d / "far.stl")
    gone = _sphere()
    gone.apply_translation((1e9, 1e9, 1e9))  # every vertex on one float32 point
    gone.export(d / "far-all.stl")
    _sphere().export(d / "sphere.stl")
    return d


def _one_line(r, *words):
    line = refused_in_one_line(r, *words)
    assert "holds no triangles" not in r.output
    return line


# ---- cavities ------------------------------------------------------------------------------------------------

def test_nesting_finds_the_inner_shell_and_overlaps():
    outer, inner = _sphere(1.0), _sphere(0.5, 1)
    assert body_nesting([(outer.vertices, outer.faces), (inner.vertices, inner.faces)]) == ([None, 0], set())
    inner.invert()  # a cavity's wall faces inward: inside all the same
    assert body_nesting([(outer.vertices, outer.faces), (inner.vertices, inner.faces)])[0] == [None, 0]
    apart = _sphere()
    apart.apply_translation((0.7, 0.13, 0.05))
    assert body_nesting([(outer.vertices, outer.faces), (apart.vertices, apart.faces)]) == ([None, None], {0, 1})
    far = _sphere()
    far.apply_translation((5.0, 0.0, 0.0))
    assert body_nesting([(outer.vertices, outer.faces), (far.vertices, far.faces)]) == ([None, None], set())


def test_analyse_lists_the_hollow_grain_once_flagged_cavity(files):
    row, = analyse_file(files / "hollow.stl", fractal=False, fourier=False)
    assert row["flags"] == "cavity" and row["bodies"] == 1
    assert row["volume"] == pytest.approx(_sphere().volume)  # the outer surface's (the void is not subtracted)
    r = CliRunner().invoke(cli, ["analyse", str(files / "hollow.stl"), *FAST])
    assert r.exit_code == 0, r.output
    assert len([line for line in r.stdout.splitlines() if "hollow.stl" in line]) == 1
    assert "cavity: encloses an inner shell" in r.stderr


def test_atlas_table_has_no_cavity_row(files, tmp_path):
    out = tmp_path / "atlas.csv"
    r = CliRunner().invoke(cli, ["analyse", str(files / "hollow.stl"), *FAST, "--voxels-across", "30",
                                 "--atlas-csv", str(out)])
    assert r.exit_code == 0, r.output
    rows = out.read_text(encoding="utf-8").strip().splitlines()[1:]
    assert len(rows) == 1  # the grain, not its 1 mm cavity
    d_um = float(rows[0].split(",")[2])
    assert d_um == pytest.approx(2000.0, rel=0.02)


def test_atlas_check_skips_the_inner_shell(tmp_path):
    """A nested shell (here outward, 0.6 mm) below 5 voxels across does not stop the grain's measure."""
    nested = trimesh.util.concatenate([_sphere(1.0), _sphere(0.3, 1)])
    nested.export(tmp_path / "nested.stl")
    out = tmp_path / "atlas.csv"
    r = CliRunner().invoke(cli, ["analyse", str(tmp_path / "nested.stl"), *FAST, "--voxel-size-mm", "0.3",
                                 "--atlas-csv", str(out)])
    assert r.exit_code == 0, r.output
    assert len(out.read_text(encoding="utf-8").strip().splitlines()) == 2
    assert "cavity" in r.stdout


# ---- overlapping bodies ------------------------------------------------------------------------------------

def test_analyse_flags_overlapping_bodies(files):
    shared, = analyse_file(files / "overlap.stl", fractal=False, fourier=False)
    assert "not-solid" in shared["flags"].split()
    rows = analyse_file(files / "overlap-apart.stl", fractal=False, fourier=False)
    assert [r["flags"] for r in rows] == ["multi-body overlapping"] * 2


@pytest.mark.parametrize(("name", "words"), [
    ("hollow", ["hollow.stl: not a closed solid (cavity: body 1 is an inner shell of body 0", "remove the inner shell"]),
    ("overlap", ["overlap.stl: not a closed solid (", "analyse flags it not-solid"]),
    ("overlap-apart", ["overlap-apart.stl: not a closed solid (2 overlapping bodies", "multi-body overlapping"]),
])
def test_dem_refuses_what_analyse_flags(files, tmp_path, name, words):
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(files / f"{name}.stl"), "--out", str(out), "--workers", "1"])
    _one_line(r, *words)
    assert not out.exists() or not any(out.iterdir())


def test_solid_grain_is_analyses_check(files):
    v, f = solid_grain(files / "sphere.stl")
    assert len(f) == len(_sphere().faces)
    with pytest.raises(ValueError, match="cavity"):
        solid_grain(files / "hollow.stl")


def test_simulate_refuses_a_hollow_grain_before_the_engine(files, tmp_path, monkeypatch):
    import grainforge.simulate
    import grainforge.simulate.pipeline as pipeline

    def no_engine(*args, **kwargs):
        raise AssertionError("the engine was started")

    monkeypatch.setattr(pipeline, "check_installed", lambda *a, **k: None)
    monkeypatch.setattr(grainforge.simulate.engine, "run_test", no_engine)
    out = tmp_path / "sim"
    r = CliRunner().invoke(cli, ["simulate", "repose", str(files / "hollow.stl"), "--quick", "--out", str(out),
                                 "--workers", "1"])
    _one_line(r, "hollow.stl: not a closed solid (cavity")
    assert not out.exists() or not any(out.iterdir())


# ---- absurd sizes and coordinates ----------------------------------------------------------------------------

def test_size_range_reuses_the_generators():
    assert MESH_SIZE_RANGE_MM == (SIZE_RANGE_MM[0] / 10, SIZE_RANGE_MM[1] * 10)


def test_precision_bound():
    s = _sphere()
    assert precision_problem(s.vertices + 0.9 * FLOAT32_OFFSET_LIMIT * 2.0) is None
    assert "translate the mesh near the origin" in precision_problem(s.vertices + 1.1 * FLOAT32_OFFSET_LIMIT * 2.0)


@pytest.mark.parametrize(("name", "words"), [
    ("huge", ["huge.stl: the mesh is 2e+37 mm across", "rescale the mesh to millimetres"]),
    ("tiny", ["tiny.stl: the mesh is 2e-09 mm across", "rescale the mesh to millimetres"]),
    ("far", ["far.stl: coordinates reach 1e+09", "translate the mesh near the origin"]),
    ("far-all", ["far-all.stl: every vertex of the mesh lies on one point", "translate the mesh near the origin"]),
])
@pytest.mark.parametrize("atlas", [False, True])
def test_analyse_refuses_absurd_geometry(files, tmp_path, name, words, atlas):
    csv, atlas_csv = tmp_path / "all.csv", tmp_path / "atlas.csv"
    extra = ["--voxels-across", "30", "--atlas-csv", str(atlas_csv)] if atlas else []
    r = CliRunner().invoke(cli, ["analyse", str(files / f"{name}.stl"), *FAST, "--csv", str(csv), *extra])
    _one_line(r, *words)
    assert not csv.exists() and not atlas_csv.exists()
    assert r.stdout == ""


@pytest.mark.parametrize(("name", "words"), [
    ("huge", ["huge.stl: equivalent diameter 1.98e+34 m is outside", "rescale the mesh or give its unit"]),
    ("tiny", ["tiny.stl: equivalent diameter 1.98e-12 m is outside", "rescale the mesh or give its unit"]),
    ("far", ["far.stl: coordinates reach 1e+09", "translate the mesh near the origin"]),
    ("far-all", ["far-all.stl: every vertex of the mesh lies on one point"]),
])
def test_dem_refuses_absurd_geometry(files, tmp_path, name, words):
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(files / f"{name}.stl"), "--out", str(out), "--workers", "1"])
    _one_line(r, *words)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("name", ["huge", "far"])
def test_check_refuses_absurd_geometry(files, name):
    r = CliRunner().invoke(cli, ["check", str(files / f"{name}.stl")])
    _one_line(r, f"{name}.stl: ")


# ---- ordinary grains -----------------------------------------------------------------------------------------

def test_ordinary_grains_are_unaffected(files, tmp_path):
    row, = analyse_file(files / "sphere.stl", fractal=False, fourier=False)
    assert row["flags"] == ""
    # a grain 1,000 sizes from the origin (a scan's frame) is measured as at the origin
    moved = _sphere()
    moved.apply_translation((2000.0, -1500.0, 300.0))
    moved.export(tmp_path / "moved.stl")
    far_row, = analyse_file(tmp_path / "moved.stl", fractal=False, fourier=False)
    assert far_row["flags"] == "" and far_row["sphericity"] == pytest.approx(row["sphericity"], abs=1e-4)
    # two grains apart stay two rows
    two = trimesh.util.concatenate([_sphere(), _sphere().apply_translation((5.0, 0.0, 0.0))])
    two.export(tmp_path / "two.stl")
    assert [r["flags"] for r in analyse_file(tmp_path / "two.stl", fractal=False, fourier=False)] == \
        ["multi-body"] * 2
    out = tmp_path / "deck"
    r = CliRunner().invoke(cli, ["dem", str(files / "sphere.stl"), "--out", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert (out / "run.py").is_file()
    assert np.isfinite(row["volume"])
