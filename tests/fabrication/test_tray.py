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
        (["--method", "fso", "--plates", "0", "--out", "x.3mf"], "positive whole number of print files or 'auto'"),
        (["--method", "fso", "--plates", "some", "--out", "x.3mf"], "positive whole number of print files or 'auto'"),
        (["--method", "fso", "--param", "subdivisions=1", "--count", "1001", "--plates", "1001", "--out", "x.3mf"],
         "1001 print files is more than 1000"),
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


# ------------------------------------------------------------------ the plan, and print files within a budget

#: a coarse PolyJet profile (tolerance 60 µm) on which the 2 mm grains of ``PLATES`` need subdivisions 3
COARSE = '[printer.coarse]\ntechnology = "polyjet"\nbuild_volume = [100, 100, 50]\nresolution = 0.12\n'
#: rough-angular CRI grains with 8 contour modes: CRI band-limits a grain's contours to the 2^s modes its level
#: resolves, so with 8 modes levels 3 and finer sample one surface, and the grain made one level finer than a
#: written one shows the true surface above the written edges.  10 grains: the tolerance's 1,280 faces a grain
#: fit 3 grains in a file of 4,000 triangles.
PLATES = ["tray", "--method", "cri", "--preset", "rough-angular", "--param", "modes=8", "--count", "10", "--size",
          "2", "--max-triangles", "4000"]


@pytest.fixture
def coarse(tmp_path):
    f = tmp_path / "coarse.toml"
    f.write_text(COARSE)
    return f


def _rough_angular():
    from grainforge.cli.tray import parse_param_values

    return parse_param_values("cri", ["modes=8"], "rough-angular")[0]


def _written_deviation(mesh, params, seed: int, size: float) -> float:
    """Chordal deviation of a grain as written: the largest distance between the midpoint of an edge of the mesh
    read back and the grain's surface point above it (on the grain made one level finer: its vertex above each
    edge, that surface's point in the direction of the edge's midpoint), in mm."""
    import dataclasses

    from scipy.spatial import cKDTree

    from grainforge.geometry.geodesic import icosphere
    from grainforge.methods import generate

    w = np.asarray(mesh.vertices, dtype=np.float64)
    level = int(round(np.log((len(w) - 2) / 10) / np.log(4)))
    assert len(w) == 10 * 4**level + 2  # a geodesic mesh of that level
    f = generate("cri", dataclasses.replace(params, subdivisions=level + 1), seed).vertices
    a = f[: len(w)]  # the level's vertices come first on the finer sphere
    ca, cw = a.mean(axis=0), w.mean(axis=0)
    u, sv, vt = np.linalg.svd((a - ca).T @ (w - cw))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = (u @ d @ vt).T  # the tray's rotation, and its scale to the printed size (Umeyama)
    scale = float(np.trace(np.diag(sv) @ d) / ((a - ca) ** 2).sum())
    moved = scale * (f - ca) @ rot.T + cw
    assert np.abs(moved[: len(w)] - w).max() < 2e-3  # the file holds this grain, at this size (within 2 µm)
    sphere, _ = icosphere(level + 1)
    edges = np.asarray(mesh.edges_unique)
    mid = sphere[edges[:, 0]] + sphere[edges[:, 1]]
    dist, above = cKDTree(sphere).query(mid / np.linalg.norm(mid, axis=1, keepdims=True))
    assert dist.max() < 1e-9
    return float(np.linalg.norm(moved[above] - w[edges].mean(axis=1), axis=1).max())


def test_plates_auto_keeps_every_file_within_the_budget_and_every_grain_within_the_tolerance(runner, tmp_path,
                                                                                           coarse):
    pytest.importorskip("lxml")
    import trimesh

    out = tmp_path / "t.3mf"
    res = runner.invoke(cli, PLATES + ["--printer", str(coarse), "--plates", "auto", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "WARNING" not in res.stderr
    files = sorted(tmp_path.glob("t-plate*.3mf"))
    assert [f.name for f in files] == [f"t-plate{k}.3mf" for k in range(1, 5)] and not out.exists()
    rows = _rows(tmp_path / "t.csv")
    params, tolerance = _rough_angular(), get_printer(str(coarse)).max_deviation
    seen = []
    for k, f in enumerate(files, 1):
        meshes = trimesh.load(f, file_type="3mf", process=False).dump(concatenate=False)
        assert 2 <= len(meshes) <= 3  # 10 grains over 4 files, as evenly as they divide
        assert sum(len(m.faces) for m in meshes) <= 4000  # the file's triangle budget
        assert sorted(m.metadata["name"] for m in meshes) == [r["name"] for r in rows if int(r["plate"]) == k]
        for m in meshes:
            seed = int(m.metadata["name"].split("-")[1])
            seen.append(seed)
            assert len(m.faces) == 1280  # the tolerance's level for every grain, not a budget's
            assert _written_deviation(m, params, seed, 2.0) <= tolerance
    assert sorted(seen) == list(range(10))


def test_one_file_caps_the_mesh_and_the_plan_says_so_before_any_grain_is_made(tmp_path, coarse):
    events = []

    def progress(grains):
        for p in grains:
            events.append(("grain", p.index))
            yield p

    res = build_tray(GeneratorSource("cri", _rough_angular(), tuple(range(10)), 2.0), str(coarse),
                     tmp_path / "t.3mf", max_triangles=4000, workers=1, progress=progress,
                     say=lambda line: events.append(("say", line)))
    said = [text for kind, text in events if kind == "say"]
    first_grain = next(k for k, (kind, _) in enumerate(events) if kind == "grain")
    assert all(kind == "say" for kind, _ in events[:first_grain]) and len(said) == first_grain  # all said first
    # one file of 4,000 triangles: 400 faces a grain, so subdivisions 2 (320 faces), above the tolerance
    assert res.files == [tmp_path / "t.3mf"] and {r["faces"] for r in res.rows} == {320}
    text = "\n".join(said)
    assert "plan: 10 grains in 1 print file, 320 faces a grain" in text
    assert f"caps the mesh at level 2 (320 faces): its chordal deviation {res.resolution.deviation * 1000:.1f} µm " \
           "exceeds the printer tolerance 60.0 µm" in text
    assert "level 3 (1280 faces a grain" in text and "--plates auto (here --plates 4) writes as 4 print files" in text


def test_the_plan_is_printed_even_when_the_run_is_interrupted(tmp_path, coarse):
    """Ctrl-C once the plan is out (the grains being made): exit 130, the plan was said, nothing written."""
    import os
    import signal
    import subprocess
    import sys

    from tests._processes import kill_sessions

    out = tmp_path / "out" / "t.3mf"
    argv = [sys.executable, "-c", "from grainforge.cli.main import main; main()", *PLATES[:7], "--count", "3000",
            "--size", "2", "--max-triangles", "60000", "--printer", str(coarse), "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, env=dict(os.environ, COLUMNS="200"))
    try:
        said = []
        for line in iter(proc.stderr.readline, b""):
            said.append(line.decode())
            if said[-1].startswith("plan: level 3"):  # the last line of the plan
                break
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        kill_sessions([proc])
    assert proc.returncode == 130
    assert any(s.startswith("plan: 3000 grains in 1 print file, 20 faces a grain") for s in said), said
    assert any("caps the mesh at level 0 (20 faces)" in s for s in said)
    assert "Traceback" not in err.decode()
    assert not out.parent.exists()  # nothing written, not even the folder


def test_plates_n_spreads_grains_evenly_at_the_finest_level_that_fits(coarse):
    from grainforge.fabrication.tray import plan_tray

    src = GeneratorSource("cri", _rough_angular(), tuple(range(10)), 2.0)
    three = plan_tray(src, str(coarse), plates=3, max_triangles=4000)  # 4 grains a file: 1,000 faces a grain
    four = plan_tray(src, str(coarse), plates=4, max_triangles=4000)   # 3 grains a file: 1,333 faces a grain
    assert (three.resolution.subdivisions, three.files, three.per_file) == (2, 3, 4)
    assert three.needed.subdivisions == 3 and three.needed_files() == 4
    assert (four.resolution.subdivisions, four.files, four.per_file) == (3, 4, 3) and four.needed is None
    assert [four.file_of(i) for i in range(10)] == [0, 0, 0, 1, 1, 2, 2, 2, 3, 3]


def test_plate_split_is_byte_identical_for_any_worker_count(runner, tmp_path, coarse):
    args = PLATES + ["--printer", str(coarse), "--plates", "auto", "--count", "7"]
    for workers in ("1", "2"):
        res = runner.invoke(cli, args + ["--workers", workers, "--out", str(tmp_path / workers / "t.3mf")])
        assert res.exit_code == 0, res.output
    one = sorted(p.name for p in (tmp_path / "1").iterdir())
    assert one == sorted(p.name for p in (tmp_path / "2").iterdir())
    assert len([n for n in one if n.endswith(".3mf")]) == 3  # 7 grains, 3 to a file
    for name in one:
        if not name.endswith(".png"):
            assert (tmp_path / "1" / name).read_bytes() == (tmp_path / "2" / name).read_bytes(), name


def test_plates_auto_on_mesh_files_starts_a_file_where_the_budget_is_reached(runner, tmp_path):
    folder = tmp_path / "grains"
    write_run("fso", SMALL, seeds=range(5), out=folder, size=2.0)  # 320 faces each
    res = runner.invoke(cli, ["tray", str(folder), "--max-triangles", "700", "--plates", "auto", "--workers", "1",
                              "--out", str(tmp_path / "t.stl")])
    assert res.exit_code == 0, res.output
    assert "plan: 5 grains in print files of at most 700 triangles" in res.stderr
    counts = [int.from_bytes(f.read_bytes()[80:84], "little") for f in sorted(tmp_path.glob("t-plate*.stl"))]
    assert counts == [640, 640, 320]
