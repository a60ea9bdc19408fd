"""Physical scale by size definition, against analytic shapes."""

import csv

import numpy as np
import pytest
import trimesh

from grainforge.analysis.descriptors import basic_descriptors
from grainforge.cli.main import cli
from grainforge.fabrication.scale import SIZE_DEFINITIONS, scale_factor, to_size
from grainforge.grain import Grain


def _grain(mesh):
    return Grain(vertices=mesh.vertices, faces=mesh.faces, method="test", params=None, seed=None)


BOX = _grain(trimesh.creation.box(extents=(3.0, 2.0, 1.0)))


def _ellipsoid(a, b, c, level=5):
    s = trimesh.creation.icosphere(level)
    return _grain(trimesh.Trimesh(s.vertices * [a, b, c], s.faces, process=False))


def test_box_scaled_by_each_definition():
    # L = 3, I = 2, S = 1; volume 6
    assert scale_factor(BOX, 4.0, "sieve") == pytest.approx(2.0)
    assert scale_factor(BOX, 6.0, "longest") == pytest.approx(2.0)
    d_eq = (6 * 6 / np.pi) ** (1 / 3)
    assert scale_factor(BOX, 2 * d_eq, "equivalent") == pytest.approx(2.0)
    big = to_size(BOX, 5.0, "sieve")
    assert sorted(np.ptp(big.vertices, axis=0)) == pytest.approx([2.5, 5.0, 7.5])


@pytest.mark.parametrize("definition, expected", [("longest", 6.0), ("sieve", 4.0), ("equivalent", 2 * 6**(1 / 3))])
def test_ellipsoid_dimensions(definition, expected):
    """Ellipsoid with semi-axes 3, 2, 1: L = 6, I = 4, d_eq = 2(abc)^(1/3) (to the mesh's resolution)."""
    e = _ellipsoid(3.0, 2.0, 1.0)
    # the size of the mesh under the definition, from the factor that maps it to 1 mm
    assert 1.0 / scale_factor(e, 1.0, definition) == pytest.approx(expected, rel=0.005)


@pytest.mark.parametrize("definition", list(SIZE_DEFINITIONS))
def test_to_size_hits_the_target(definition):
    e = _ellipsoid(1.3, 1.0, 0.6, level=3)
    g = to_size(e, 2.0, definition)
    d = basic_descriptors(g)
    measured = {"equivalent": d["equivalent_diameter"], "sieve": d["I"], "longest": d["L"]}[definition]
    assert measured == pytest.approx(2.0, rel=1e-9)


def test_bad_sizes():
    with pytest.raises(ValueError, match="size_definition must be one of"):
        scale_factor(BOX, 1.0, "diameter")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="size must be between"):
            scale_factor(BOX, bad)


@pytest.mark.parametrize("definition, column", [("equivalent", "equivalent_diameter_mm"), ("sieve", "I_mm"), ("longest", "L_mm")])
def test_generate_size_options(runner, tmp_path, definition, column):
    out = tmp_path / definition
    res = runner.invoke(cli, ["generate", "fso", "--subdivisions", "2", "--count", "2", "--size", "2",
                              "--size-definition", definition, "--out", str(out)])
    assert res.exit_code == 0, res.output
    with open(out / "manifest.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r[column]) for r in rows] == pytest.approx([2.0, 2.0], rel=1e-9)
    assert all(r["size_definition"] == definition for r in rows)


def test_generate_rejects_bad_size(runner, tmp_path):
    res = runner.invoke(cli, ["generate", "fso", "--size", "0", "--out", str(tmp_path / "x")])
    assert res.exit_code == 2 and not (tmp_path / "x").exists()
    res = runner.invoke(cli, ["generate", "fso", "--size-definition", "mean", "--out", str(tmp_path / "x")])
    assert res.exit_code == 2
