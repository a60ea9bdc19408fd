"""grainforge tray: layout with a gap checked on the meshes, streaming writers, round trips."""

import csv

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import Delaunay

from grainforge.cli.main import cli
from grainforge.fabrication.printers import get_printer
from grainforge.fabrication.tray import (
    FileSource,
    GeneratorSource,
    ShelfPacker,
    build_tray,
    min_mesh_distance,
    orient_stable,
)
from grainforge.geometry.solid import solid_problems, volume_centroid
from grainforge.io.stl import read_stl_parts
from grainforge.io.threemf import read_3mf
from grainforge.methods.fso import Params as FsoParams
from grainforge.population.generate import write_run

SMALL = FsoParams(subdivisions=2)


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture
def small_polyjet(tmp_path):
    """A PolyJet profile whose plate holds about eight 2 mm grains in two layers."""
    f = tmp_path / "small.toml"
    f.write_text('[printer.small]\ntechnology = "polyjet"\nbuild_volume = [6, 6, 5]\nresolution = 0.05\n')
    return get_printer(str(f))


@given(
    st.lists(st.tuples(*[st.floats(0.1, 3.0)] * 3), min_size=1, max_size=40),
    st.booleans(), st.floats(0.01, 0.5),
)
def test_packer_keeps_boxes_apart_and_inside(extents, stacking, gap):
    volume = (7.0, 5.0, 6.0)
    p = ShelfPacker(volume, gap, stacking)
    p.compact(len(extents), extents[0])
    placed = [(p.place(e), np.array(e)) for e in extents]
    for (_plate, *xyz), e in placed:
        lo = np.array(xyz)
        assert (lo >= 0).all() and (lo + e <= np.array(volume) + 1e-12).all()
        assert stacking or lo[2] == 0
    for k, ((pa, *a), ea) in enumerate(placed):
        for (pb, *b), eb in placed[k + 1:]:
            if pa != pb:
                continue
            a, b = np.array(a), np.array(b)
            sep = np.maximum(b - (a + ea), a - (b + eb))  # per-axis separation
            assert sep.max() >= gap - 1e-9


def test_packer_rejects_a_grain_larger_than_the_printer():
    with pytest.raises(ValueError, match="does not fit the build volume"):
        ShelfPacker((5, 5, 5), 0.1, True).place((6, 1, 1))


def test_polyjet_tray_gap_bodies_and_round_trip(tmp_path, small_polyjet):
    n = 12
    out = tmp_path / "tray.3mf"
    res = build_tray(GeneratorSource("fso", SMALL, tuple(range(n)), 2.0), small_polyjet, out, workers=1,
                     match_resolution=False)
    assert res.plates == 2 and max(res.layers) == 2  # stacked in 3D, then a second plate
    files = [tmp_path / "tray-plate1.3mf", tmp_path / "tray-plate2.3mf"]
    assert res.files == files and all(f.is_file() for f in files) and not out.exists()
    assert all(p.is_file() and p.stat().st_size > 1000 for p in res.previews)
    rows = _rows(tmp_path / "tray.csv")
    assert len(rows) == n
    parts = [read_3mf(f) for f in files]
    assert sum(len(p) for p in parts) == n  # one body per grain, across plates
    gap = small_polyjet.default_gap
    for k, plate in enumerate(parts):
        for part in plate:
            assert solid_problems(part.vertices, part.faces) == []
        plate_rows = [r for r in rows if int(r["plate"]) == k + 1]
        assert [p.name for p in plate] == [r["name"] for r in plate_rows]
        for part, r in zip(plate, plate_rows):
            assert part.vertices.min(axis=0) == pytest.approx([float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])], abs=1e-4)
            assert part.mesh.volume == pytest.approx(float(r["volume_mm3"]), rel=1e-5)
            assert float(r["equivalent_diameter_mm"]) == pytest.approx(2.0, rel=1e-4)
        d = min_mesh_distance(plate, within=3 * gap)
        assert gap <= d < 3 * gap  # never closer than the gap, and the packing is tight
    assert len({p.name for plate in parts for p in plate}) == n


def test_fdm_tray_single_layer_on_stable_faces_stl(tmp_path):
    n = 6
    res = build_tray(GeneratorSource("fso", SMALL, tuple(range(n)), 6.0), "generic-fdm", tmp_path / "t.stl",
                     workers=1, match_resolution=False)
    assert res.plates == 1 and res.layers == [1]
    bodies = read_stl_parts(tmp_path / "t.stl")
    assert len(bodies) == n
    data = (tmp_path / "t.stl").read_bytes()
    assert int.from_bytes(data[80:84], "little") == n * 320  # level-2 grains
    assert len(data) == 84 + 50 * n * 320
    gap = get_printer("generic-fdm").default_gap
    assert min_mesh_distance(bodies, within=3 * gap) >= gap * (1 - 1e-6)
    for b in bodies:
        assert solid_problems(b.vertices, b.faces) == []
        z = b.vertices[:, 2]
        assert z.min() == pytest.approx(0.0, abs=1e-5)  # on the bed
        contact = b.vertices[z < 1e-4, :2]
        c = volume_centroid(b.vertices, b.faces)
        assert len(contact) >= 3 and Delaunay(contact).find_simplex(c[:2]) >= 0  # centroid over its footprint


def test_stable_orientation_of_a_wedge():
    import trimesh

    # a right prism with a triangular cross-section: it rests on one of its rectangular faces
    tri = np.array([[0, 0], [3, 0], [0, 1.0]])
    prism = trimesh.convex.convex_hull(np.vstack([np.c_[tri, np.zeros(3)], np.c_[tri, np.full(3, 2.0)]]))
    v = orient_stable(np.asarray(prism.vertices), np.asarray(prism.faces))
    bottom = v[np.isclose(v[:, 2], v[:, 2].min(), atol=1e-9)]
    assert len(bottom) == 4  # a whole rectangular face is on the bed


def test_output_identical_whatever_the_workers(tmp_path):
    src = GeneratorSource("fso", SMALL, tuple(range(40, 50)), 2.0)
    for ext in (".3mf", ".stl"):
        a = build_tray(src, "objet-eden-250", tmp_path / ext[1:] / f"one{ext}", workers=1,
                       max_subdivisions=2)
        b = build_tray(src, "objet-eden-250", tmp_path / ext[1:] / f"two{ext}", workers=2,
                       max_subdivisions=2)
        assert a.files[0].read_bytes() == b.files[0].read_bytes()
        assert a.csv.read_bytes() == b.csv.read_bytes()


def test_tray_from_folder_and_manifest(tmp_path):
    folder = tmp_path / "grains"
    write_run("fso", SMALL, seeds=[0, 1, 2], out=folder, size=2.0)
    a = build_tray(FileSource(tuple(sorted(folder.glob("*.stl")))), "objet-eden-250",
                   tmp_path / "a.3mf", workers=1)
    assert [p.name for p in read_3mf(a.files[0])] == ["fso-0000", "fso-0001", "fso-0002"]
    from grainforge.io.inputs import mesh_paths

    assert tuple(mesh_paths([folder])) == tuple(mesh_paths([folder / "manifest.csv"]))
    b = build_tray(FileSource(tuple(mesh_paths([folder / "manifest.csv"]))), "objet-eden-250", tmp_path / "b.3mf", workers=1)
    assert a.files[0].read_bytes() == b.files[0].read_bytes()
    c = build_tray(FileSource(tuple(mesh_paths([folder])), size=4.0), "objet-eden-250", tmp_path / "c.3mf", workers=1)
    assert [float(r["equivalent_diameter"]) for r in c.rows] == pytest.approx([4.0] * 3)


def test_tray_failures_leave_no_files(tmp_path, small_polyjet):
    with pytest.raises(ValueError, match="does not fit"):
        build_tray(GeneratorSource("fso", SMALL, (0, 1), 20.0), small_polyjet, tmp_path / "big.3mf", workers=1,
                   match_resolution=False)
    with pytest.raises(ValueError, match="gap must be a positive"):
        build_tray(GeneratorSource("fso", SMALL, (0,), 2.0), small_polyjet, tmp_path / "g.3mf", gap=0.0)
    with pytest.raises(ValueError, match=r"\.3mf or \.stl"):
        build_tray(GeneratorSource("fso", SMALL, (0,), 2.0), small_polyjet, tmp_path / "g.obj")
    assert list(tmp_path.iterdir()) == [tmp_path / "small.toml"]


def test_tray_failure_after_a_plate_was_started_leaves_no_files(tmp_path, small_polyjet):
    """The second grain does not fit: the first one's plate file was already being written."""
    write_run("fso", SMALL, seeds=[0], out=tmp_path / "small", size=2.0)
    write_run("fso", SMALL, seeds=[1], out=tmp_path / "big", size=20.0)
    files = (tmp_path / "small" / "fso-0000.stl", tmp_path / "big" / "fso-0000.stl")
    out = tmp_path / "out" / "t.3mf"
    with pytest.raises(ValueError, match="does not fit"):
        build_tray(FileSource(files), small_polyjet, out, workers=1)
    assert not out.parent.exists()  # the folder it created is removed too (no empty folder is left behind)


def test_cli_tray(runner, tmp_path):
    out = tmp_path / "t.3mf"
    args = ["tray", "--method", "fso", "--param", "amplitude=0", "--count", "4", "--size", "2",
            "--printer", "objet-eden-250", "--out", str(out)]
    res = runner.invoke(cli, args)
    assert res.exit_code == 0, res.output
    assert "resolution matching" in res.stderr and "subdivisions 2" in res.stderr
    rows = _rows(tmp_path / "t.csv")
    assert [int(r["subdivisions"]) for r in rows] == [2] * 4  # a 2 mm sphere at 32 µm: sagitta rule
    assert all(r["resolution_limited_by"] == "tolerance" for r in rows)
    assert float(rows[0]["chordal_deviation_mm"]) <= 0.016
    assert len(read_3mf(out)) == 4 and (tmp_path / "t-plate1.png").is_file()
    res = runner.invoke(cli, args)
    assert res.exit_code == 2 and "exists" in res.output
    res = runner.invoke(cli, args + ["--overwrite", "--param", "subdivisions=1"])
    assert res.exit_code == 0 and "resolution matching" not in res.stderr
    assert {r["subdivisions"] for r in _rows(tmp_path / "t.csv")} == {"1"}


def test_cli_tray_warns_when_grains_are_below_the_printers_reliable_size(runner, tmp_path):
    import trimesh

    s = trimesh.creation.icosphere(2, radius=1.0)  # d_eq 1.98 mm
    s.export(tmp_path / "a.stl")
    trimesh.Trimesh(s.vertices * 3, s.faces).export(tmp_path / "b.stl")  # 5.9 mm
    warned = {}
    for printer in ("generic-fdm", "objet-eden-250"):
        res = runner.invoke(cli, ["tray", str(tmp_path / "a.stl"), str(tmp_path / "b.stl"), "--printer", printer,
                                  "--out", str(tmp_path / printer / "t.stl")])
        assert res.exit_code == 0, res.output
        warned[printer] = [ln for ln in res.stderr.splitlines() if "reliable size" in ln]
    p = get_printer("generic-fdm")
    assert warned["generic-fdm"] == [(
        "WARNING: 1 of 2 grains (equivalent diameter 1.98 mm) are below the reliable size of generic-fdm "
        f"({p.min_size:g} mm, min wall {p.min_wall:g} mm, resolution {p.resolution:g} mm): they will not print "
        f"reliably; print them at {p.min_size:g} mm or more, or on a finer printer.")]
    assert warned["objet-eden-250"] == []  # 0.3 mm reliable size


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--method", "fso", "--out", "x.obj"], ".3mf or .stl"),
        (["--method", "fso", "--preset", "rough-angular", "--out", "x.3mf"], "has no presets"),
        (["--method", "fso", "--param", "fractal_dimension=3.5", "--out", "x.3mf"], "--fractal-dimension"),
        (["--method", "fso", "--param", "nope", "--out", "x.3mf"], "NAME=VALUE"),
        (["--method", "nope", "--out", "x.3mf"], "method must be one of"),
        (["--out", "x.3mf"], "give grain files"),
        (["--method", "fso", "--printer", "eden", "--out", "x.3mf"], "printer must be one of"),
        (["missing-folder", "--out", "x.3mf"], "no such file"),
    ],
)
def test_cli_tray_bad_input(runner, tmp_path, monkeypatch, extra, message):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(cli, ["tray", *extra])
    assert res.exit_code == 2 and message in res.output
    assert list(tmp_path.iterdir()) == []


def test_a_3mf_tray_is_read_back_by_trimesh_as_written(tmp_path):
    """An independent reader (trimesh's 3MF loader, on lxml) sees every grain of the tray: one watertight body
    per grain, named as in the CSV, at its CSV corner, with its CSV volume (our own reader is not the judge)."""
    pytest.importorskip("lxml")
    import trimesh

    res = build_tray(GeneratorSource("fso", SMALL, tuple(range(4)), 3.0), "generic-fdm", tmp_path / "t.3mf",
                     workers=1, match_resolution=False)
    scene = trimesh.load(res.files[0], file_type="3mf")
    meshes = {m.metadata.get("name"): m for m in scene.dump(concatenate=False)}
    rows = _rows(tmp_path / "t.csv")
    assert sorted(meshes) == sorted(r["name"] for r in rows)
    for r in rows:
        m = meshes[r["name"]]
        assert m.is_watertight and m.body_count == 1
        assert m.bounds[0] == pytest.approx([float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])], abs=1e-4)
        assert m.volume == pytest.approx(float(r["volume_mm3"]), rel=1e-5)
