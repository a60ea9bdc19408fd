"""The solid contract as readers see it, and the commands that once wrote invalid solids
(each fails on the old code)."""

import numpy as np
import pytest
import trimesh

import grainforge
from grainforge.cli.main import cli
from grainforge.geometry.solid import (
    AREA_TOLERANCE,
    is_closed,
    require_solid,
    self_intersections,
    solid_problems,
    star_certificate,
)
from grainforge.params import ParameterError


def _two_boxes(offset):
    a = trimesh.creation.box()
    b = trimesh.creation.box().apply_translation(offset)
    both = trimesh.util.concatenate([a, b])
    return both.vertices, both.faces


def test_edge_contact_with_split_indices_is_caught_by_position():
    # the old check worked on indices: two cubes touching along an edge, kept apart by index, passed
    v, f = _two_boxes((1, 1, 0))
    assert solid_problems(v, f) == ["1 edges shared by more than two faces"]


def test_vertex_contact_is_a_pinch():
    v, f = _two_boxes((1, 1, 1))
    assert any("pinches" in p for p in solid_problems(v, f))


def test_sliver_below_float32_collapses():
    box = trimesh.creation.box()
    v = np.concatenate([box.vertices, box.vertices[:1] + 1e-10])  # a vertex 1e-10 from another
    f = box.faces.copy()
    f[0, 0] = len(v) - 1 if f[0, 0] == 0 else f[0, 0]
    sliver = np.array([[0, len(v) - 1, 1]])
    problems = solid_problems(v, np.concatenate([f, sliver]))
    assert any("collapse when written" in p for p in problems)


def _box_with_inner_triangle(delta):
    """A closed unit box whose first face holds a triangle ``delta`` times its size at its centroid.

    The face (a, b, c) becomes the small triangle (p, q, r) and a ring of six
    triangles joining it to a, b and c: still closed, consistently oriented.
    """
    box = trimesh.creation.box()
    v, f = np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)
    a, b, c = f[0]
    g = v[f[0]].mean(axis=0)
    n = len(v)
    p, q, r = n, n + 1, n + 2
    v = np.concatenate([v, g + delta * (v[f[0]] - g)])
    ring = [[p, q, r], [a, b, q], [a, q, p], [b, c, r], [b, r, q], [c, a, p], [c, p, r]]
    return v, np.concatenate([f[1:], ring])


def test_near_zero_area_face_threshold_is_relative_to_size():
    for scale in (1.0, 1000.0):
        # a triangle 1e-6 of the face's size: 5e-13 of the face area, below 1e-12·d² (d² = 3)
        v, f = _box_with_inner_triangle(1e-6)
        assert is_closed(f, len(v)), "the construction is closed"
        problems = solid_problems(v * scale, f)
        assert any("1 faces of near-zero area" in p for p in problems), problems
        assert not any("collapse" in p or "open" in p for p in problems), problems
        # ten times larger: 5e-11 of the face area, above the threshold
        v, f = _box_with_inner_triangle(1e-5)
        assert not any("near-zero area" in p for p in solid_problems(v * scale, f))
    assert AREA_TOLERANCE == 1e-12


def test_self_intersection_is_found():
    v, f = _two_boxes((0.5, 0.3, 0.2))
    assert self_intersections(v, f) > 0
    box = trimesh.creation.box()
    assert self_intersections(box.vertices, box.faces) == 0


def test_star_certificate_is_a_proof_and_fails_off_centre():
    v, f = trimesh.creation.icosphere(3).vertices, trimesh.creation.icosphere(3).faces
    assert star_certificate(v, f) and self_intersections(v, f) == 0
    assert not star_certificate(v, f, centre=(0, 0, 1.5))
    # a folded surface around the centre: wraps twice -> certificate refuses
    assert not star_certificate(np.concatenate([v, v * 1.5]), np.concatenate([f, f + len(v)]))


def test_require_solid_raises_parameter_error_naming_the_parameter():
    v, f = _two_boxes((1, 1, 0))
    with pytest.raises(ParameterError) as exc:
        require_solid(v, f, "smooth")
    assert exc.value.name == "smooth"


@pytest.mark.parametrize("kwargs", [
    dict(primitive="cube", exponent=1.0, primaries=200),  # README example (wrote an invalid solid before)
    dict(primitive="cube", primaries=200),  # `generate dpa --primitive cube --seed 0`
])
def test_dpa_cube_repros_are_valid_as_written(kwargs, tmp_path):
    g = grainforge.dpa(**kwargs, rng=0)
    path = tmp_path / "g.stl"
    grainforge.io.write_mesh(g, path)
    m = trimesh.load(path)  # merges vertices by position
    assert m.is_watertight and m.is_winding_consistent and m.body_count == 1 and m.volume > 0
    assert solid_problems(m.vertices, m.faces) == []


def test_dpa_cube_pinch_separation_volume_effect():
    from grainforge.methods.dpa import aggregation as D

    for seed in range(3):
        agg = D.aggregate("cube", 300, exponent=1.0, rng=np.random.default_rng(seed))
        v, f, cav = D.lattice_surface(agg.cells)
        pinch_points = int((np.unique(v, axis=0, return_counts=True)[1] > 1).sum())
        w = D.separate_pinches(v, f)
        assert solid_problems(w, f) == []
        from grainforge.geometry.solid import signed_volume

        removed = 300 + cav - signed_volume(w, f)
        # documented in docs/validation.md: about 4e-4 primary volumes per pinch point, never more than 1e-3
        assert 0 <= removed <= 1e-3 * max(pinch_points, 1)


def test_fso_gamma_overflow_is_a_parameter_error():
    with pytest.raises(ParameterError) as exc:
        grainforge.fso(gamma=10, frequencies=400)
    assert exc.value.name == "frequencies"


def test_cri_fractal_errors_name_fractal_amplitude(monkeypatch):
    from grainforge.outline import contours

    def boom(**kw):
        raise ParameterError("amplitude", "gives a contour with non-positive radii")

    monkeypatch.setattr(contours.Contour, "from_fractal", staticmethod(boom))
    with pytest.raises(ParameterError) as exc:
        grainforge.cri(contour="fractal", rng=0)
    assert exc.value.name == "fractal_amplitude"


def test_cri_validity_parameter_follows_the_input():
    from grainforge.methods import cri

    assert cri.validity_parameter(cri.Params(aspect=(3, 2, 1))) == "aspect"
    assert cri.validity_parameter(cri.Params(contour="fractal")) == "fractal_amplitude"
    assert cri.validity_parameter(cri.Params()) == "descriptors"


@pytest.mark.parametrize("size", ["1e-300", "1e308", "0.0005", "20000"])
def test_size_outside_physical_range_is_refused(size, tmp_path, runner):
    res = runner.invoke(cli, ["generate", "fso", "--subdivisions", "1", "--size", size, "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "--size" in res.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_check_target_size_range():
    from grainforge.fabrication.scale import check_target_size

    assert check_target_size(1e-3) == 1e-3 and check_target_size(1e4) == 1e4
    with pytest.raises(ParameterError):
        check_target_size(1e-300)


def test_check_does_not_crash_on_zero_area_faces(tmp_path, runner):
    # a readable mesh with many zero-area faces (the 3MF repro's cause: rng.choice with p = 0 entries)
    s = trimesh.creation.icosphere(3)  # 1280 faces with area, fewer than MAX_RAYS = 4000 ...
    v = np.concatenate([s.vertices, s.vertices[:1]])
    extra = np.array([[0, 0, len(v) - 1]] * 3000)  # ... plus 3000 of zero area: 4280 faces in all
    m = trimesh.Trimesh(v, np.concatenate([s.faces, extra]), process=False)
    path = tmp_path / "bad.ply"
    m.export(path)
    res = runner.invoke(cli, ["check", str(path)])
    # the table, with the part refused for the faces that collapse, and the summary: exit 1 for a part that
    # will not print (docs/cli-contract.md), not a bug's line
    assert res.exit_code == 1 and "a bug in grainforge" not in res.stderr, res.output
    (row,) = [line for line in res.stdout.splitlines() if line.startswith(str(path))]
    assert " FAIL " in row and "3000 faces collapse when written" in row, res.stdout
    assert res.stderr.strip().endswith("1 part(s), 1 will not print, 0 fragile (min wall 0.1 mm, reliable size 0.3 mm)")
    assert "Fewer non-zero" not in res.output


def test_cri_fractal_tiny_length_ratio_is_a_parameter_error():
    # found by the slow sweep: L at the open edge of its range (5e-324) overflowed (RuntimeWarning)
    with pytest.raises(ParameterError) as exc:
        grainforge.cri(contour="fractal", length_ratio=5e-324, modes=8, subdivisions=0, rng=0)
    assert exc.value.name == "length_ratio"


def test_cri_extreme_aspect_is_a_parameter_error():
    # found by the slow sweep: S at the open edge of its range (5e-324) overflowed in the stretching
    with pytest.raises(ParameterError) as exc:
        grainforge.cri(aspect=(88.0, 88.0, 5e-324), subdivisions=0, rng=0)
    assert exc.value.name == "aspect"


def _admesh_report(path) -> dict[str, float]:
    """admesh (an independent STL checker) on ``path``: its statistics by name (final column)."""
    import re
    import shutil
    import subprocess

    if shutil.which("admesh") is None:
        pytest.skip("admesh is not installed")
    # admesh echoes the 80-byte STL header as an unterminated string: whatever follows it in memory
    # is printed too, so its output is not always valid UTF-8
    out = subprocess.run(["admesh", str(path)], capture_output=True, check=True).stdout.decode(errors="replace")
    stats = {}
    for name in ("Number of parts", "Degenerate facets", "Edges fixed", "Facets removed", "Facets added",
                 "Facets reversed", "Backwards edges", "Normals fixed", "Total disconnected facets", "Volume"):
        m = re.search(rf"{name}\s*:\s*(-?[\d.]+)(?:\s+(-?[\d.]+))?", out)
        assert m, f"admesh printed no {name!r}"
        stats[name] = float(m.group(2) or m.group(1))
    return stats


def assert_valid_stl(path, volume=None):
    """The file as two independent readers see it: trimesh (merging by position) and admesh."""
    m = trimesh.load(path)
    assert m.is_watertight and m.is_winding_consistent and m.body_count == 1 and m.volume > 0
    assert solid_problems(m.vertices, m.faces) == []
    a = _admesh_report(path)
    assert a["Number of parts"] == 1
    for name in ("Degenerate facets", "Edges fixed", "Facets removed", "Facets added", "Facets reversed",
                 "Backwards edges", "Total disconnected facets"):
        assert a[name] == 0, (name, a)
    assert a["Volume"] == pytest.approx(m.volume, rel=1e-4)
    if volume is not None:
        assert m.volume == pytest.approx(volume, rel=1e-5)


@pytest.mark.parametrize("args", [
    ["--primitive", "octahedron", "--primaries", "2", "--seed", "1"],  # before the exact union: 9 float32 vertices
    ["--primitive", "octahedron", "--primaries", "4", "--seed", "1"],  # ... read as 2 parts
    ["--primitive", "octahedron", "--exponent", "3", "--primaries", "300", "--seed", "0"],  # was invalid too
    ["--primitive", "tetrahedron", "--primaries", "150", "--smooth", "1", "--seed", "3"],
    ["--primitive", "truncated-octahedron", "--primaries", "80", "--exponent", "0.3", "--seed", "2"],
])
def test_dpa_polyhedra_repros_are_valid_as_written(args, tmp_path, runner):
    out = tmp_path / "o"
    res = runner.invoke(cli, ["generate", "dpa", *args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    stl = out / "dpa-0000.stl"
    size = 10.0  # the default --size: equivalent diameter in mm
    sharp = "--smooth" not in args
    assert_valid_stl(stl, volume=np.pi * size**3 / 6.0 if sharp else None)  # N primaries = one sphere of d_eq
    res = runner.invoke(cli, ["check", str(stl)])
    assert res.exit_code == 0, res.output


def test_dpa_octahedron_tray_repro_checks(tmp_path, runner):
    # the tray of octahedron aggregates is checked part by part without error (it reported errors before)
    out = tmp_path / "o3.3mf"
    res = runner.invoke(cli, ["tray", "--method", "dpa", "--param", "primitive=octahedron", "--param", "primaries=200",
                              "--param", "exponent=5", "--count", "4", "--size", "2", "--out", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["check", str(out)])
    assert res.exit_code == 0, res.output
    assert "Error" not in res.output


def test_cri_tiny_equal_aspect_is_scale_free():
    # found by the slow sweep (spectral consistency): aspect 5e-324:5e-324:5e-324 underflowed to log(0)
    g = grainforge.cri(aspect=(5e-324, 5e-324, 5e-324), subdivisions=2, rng=65)
    h = grainforge.cri(aspect=(1.0, 1.0, 1.0), subdivisions=2, rng=65)
    np.testing.assert_allclose(g.vertices, h.vertices, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", ["fso", "cri", "rf", "angular"])
def test_star_shaped_generators_prove_it(name):
    """Every star-shaped generator declares it, and its grains (as written) carry the star
    certificate about the origin of ``build``, so the contract needs no pair test for them."""
    from grainforge.geometry.solid import as_written
    from grainforge.methods import get

    module = get(name)
    assert getattr(module, "STAR_SHAPED", False)
    for seed in range(3):
        v, f, _ = module.build(module.Params(), np.random.default_rng(seed))
        vw, fw = as_written(v, f)
        assert star_certificate(vw, fw, np.zeros(3))


@pytest.mark.parametrize("block", [1, 977, 1 << 30])
def test_candidate_pairs_in_blocks_are_the_overlapping_boxes_once(block):
    # self_intersections builds its candidate pairs block by block (bounded memory); a pair is reported
    # once, by the first cell of its boxes' overlap, so the blocks hold exactly the overlapping pairs
    from grainforge.geometry.solid import _candidate_pairs

    s = trimesh.creation.icosphere(3)
    big = trimesh.creation.box(extents=(1.5, 0.2, 0.2))  # a few large triangles across many cells
    tri = np.concatenate([s.triangles, big.triangles])
    blocks = list(_candidate_pairs(tri, block=block))
    pairs = np.concatenate(blocks)
    assert (pairs[:, 0] < pairs[:, 1]).all()
    packed = pairs[:, 0].astype(np.int64) * len(tri) + pairs[:, 1]
    assert len(np.unique(packed)) == len(packed)  # no pair twice, across blocks too
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    i, j = np.triu_indices(len(tri), 1)
    overlap = ((lo[i] <= hi[j]) & (lo[j] <= hi[i])).all(axis=1)
    assert set(packed.tolist()) == set((i[overlap] * len(tri) + j[overlap]).tolist())
    if block == 977:
        assert len(blocks) > 10
