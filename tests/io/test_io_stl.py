"""The one STL reader (grainforge.io.stl) against trimesh's own loader, binary and ASCII."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from trimesh.exchange.stl import export_stl_ascii

import grainforge
from grainforge.io import read_mesh, read_parts, write_mesh
from grainforge.io.stl import check_stl, read_stl, read_stl_parts


@pytest.fixture(scope="module")
def grain():
    return grainforge.cri(rng=3)


@pytest.mark.parametrize("kind", ["binary", "ascii"])
def test_read_stl_is_trimesh_loads_triangle_soup(tmp_path, grain, kind):
    path = tmp_path / f"g-{kind}.stl"
    if kind == "binary":
        write_mesh(grain, path)
    else:
        path.write_text(export_stl_ascii(trimesh.Trimesh(grain.vertices, grain.faces, process=False)))
    ref = trimesh.load(path, file_type="stl", force="mesh", process=False)
    for got in (read_stl(path), read_mesh(path)):
        assert np.array_equal(got.vertices, ref.vertices) and np.array_equal(got.faces, ref.faces)
        assert np.array_equal(got.face_normals, ref.face_normals)
        assert len(got.vertices) == 3 * len(grain.faces)  # a soup: nothing merged
    (part,) = read_parts(path)
    assert len(part.faces) == len(grain.faces) and len(part.vertices) == len(grain.vertices)
    bodies = read_stl_parts(path)
    assert [b.name for b in bodies] == ["body-0"] and len(bodies[0].faces) == len(grain.faces)


def test_header_never_starts_with_solid(tmp_path, grain):
    path = tmp_path / "g.stl"
    write_mesh(grain, path)
    assert not path.read_bytes()[:5].lower().startswith(b"solid")
    check_stl(path)


def test_a_truncated_binary_stl_is_refused_before_parsing(tmp_path, grain):
    path = tmp_path / "g.stl"
    write_mesh(grain, path)
    path.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(ValueError, match="truncated binary STL"):
        read_stl(path)
