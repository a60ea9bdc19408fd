"""Grain, parameters, solid checks and file writing."""

import dataclasses
import os

import numpy as np
import pytest
import trimesh

import grainforge
from grainforge.geometry.solid import require_solid, solid_problems
from grainforge.io import atomic_write, export_bytes, read_mesh
from grainforge.params import ParameterError


def test_grain_is_immutable():
    g = grainforge.fso(subdivisions=1, rng=0)
    with pytest.raises(ValueError):
        g.vertices[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.method = "x"
    m = g.mesh
    m.vertices[0] = 0.0  # a copy: the grain is untouched
    assert not np.allclose(g.vertices[0], 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.params.fractal_dimension = 2.9
    assert g.version == grainforge.__version__


def test_scaled():
    g = grainforge.fso(subdivisions=2, rng=0)
    h = g.scaled(3.0)
    np.testing.assert_allclose(h.vertices, 3.0 * g.vertices)
    assert h.info["scale"] == 3.0 and h.seed == g.seed and h.params is g.params
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError, match="scale"):
            g.scaled(bad)


def test_solid_problems_detects_defects():
    box = trimesh.creation.box()
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    assert solid_problems(v, f) == []
    assert any("watertight" in p for p in solid_problems(v, f[:-1]))
    assert any("volume" in p for p in solid_problems(v, f[:, ::-1]))
    flipped_one = f.copy()
    flipped_one[0] = flipped_one[0, ::-1]
    assert any("orientation" in p for p in solid_problems(v, flipped_one))
    two_v = np.vstack([v, v + 5])
    two_f = np.vstack([f, f + len(v)])
    assert any("bodies" in p for p in solid_problems(two_v, two_f))
    with pytest.raises(ValueError, match="^amplitude "):
        require_solid(v, f[:-1], "amplitude")


def test_parameter_error_is_value_error():
    assert issubclass(ParameterError, ValueError)


def test_atomic_write_leaves_nothing_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "x.bin"
    atomic_write(target, b"old")

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        atomic_write(target, b"new")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.bin"]


def test_stl_bytes_deterministic_and_binary():
    g = grainforge.fso(subdivisions=2, rng=4)
    a, b = export_bytes(g, "stl"), export_bytes(grainforge.fso(subdivisions=2, rng=4), "stl")
    assert a == b
    assert not a[:5].lower() == b"solid"
    assert int.from_bytes(a[80:84], "little") == len(g.faces)
    with pytest.raises(ValueError, match="format"):
        export_bytes(g, "step")


def test_read_mesh_errors(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        read_mesh(tmp_path / "missing.stl")
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    with pytest.raises(ValueError):
        read_mesh(empty)
