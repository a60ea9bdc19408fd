"""The one mass-integral implementation (grainforge.geometry.moments.second_moments) and the one equivalent
diameter (grainforge.geometry.moments.sphere_diameter) against trimesh and analytic solids."""

import numpy as np
import pytest
import trimesh

from grainforge.analysis.mass import mesh_moments as analysis_mass
from grainforge.dem.massprops import mass_properties as dem_mass
from grainforge.geometry.moments import second_moments, sphere_diameter

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_tetrahedron_analytic():
    vol, c, C = second_moments(TETRA_V, TETRA_F)
    assert vol == pytest.approx(1 / 6, rel=1e-14)
    assert np.allclose(c, 0.25, atol=1e-15)
    # unit corner tetrahedron: ∫x² dV = 1/60, ∫xy dV = 1/120 about the origin
    about_origin = np.full((3, 3), 1 / 120) + np.eye(3) / 120
    assert np.allclose(C, about_origin - vol * np.outer(c, c), atol=1e-15)


def test_box_analytic():
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    vol, c, C = second_moments(box.vertices, box.faces)
    assert vol == pytest.approx(6.0, rel=1e-14)
    assert np.allclose(c, 0, atol=1e-15)
    assert np.allclose(C, np.diag([1.0, 4.0, 9.0]) * 6.0 / 12.0, atol=1e-13)


def test_icosphere_approaches_the_sphere():
    s = trimesh.creation.icosphere(5)
    vol, c, C = second_moments(s.vertices, s.faces)
    # inscribed polyhedron: a little under the sphere (≈ 0.1 % at 5 subdivisions)
    assert vol == pytest.approx(4 / 3 * np.pi, rel=2e-3)
    assert np.allclose(C, np.eye(3) * 4 * np.pi / 15, rtol=4e-3, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_both_callers_match_trimesh(seed):
    import grainforge

    g = grainforge.angular(rng=seed)
    m = trimesh.Trimesh(g.vertices, g.faces, process=False)
    d, a = dem_mass(g.vertices, g.faces), analysis_mass(g.vertices, g.faces)
    assert d.volume == a["volume"] == pytest.approx(m.volume, rel=1e-12)
    assert np.array_equal(d.centroid, a["centroid"])
    assert np.allclose(d.centroid, m.center_mass, atol=1e-12 * m.scale)
    assert np.allclose(d.inertia, m.moment_inertia, rtol=1e-10, atol=1e-12 * np.abs(m.moment_inertia).max())
    # the two views of one integral: inertia = tr(C) 1 − C with C = V · covariance
    C = a["covariance"] * a["volume"]
    assert np.allclose(d.inertia, np.trace(C) * np.eye(3) - C, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("r", [0.5, 1.0, 3.0, 1e-3, 2.5e4])
def test_sphere_diameter_of_analytic_balls(r):
    """d = (6V/π)^(1/3) of a ball's volume 4πr³/3 is its diameter 2r, to rounding."""
    assert float(sphere_diameter(4.0 / 3.0 * np.pi * r**3)) == pytest.approx(2 * r, rel=4e-16)
    assert np.allclose(sphere_diameter(np.array([np.pi / 6, 36 * np.pi])), [1.0, 6.0], rtol=4e-16, atol=0)


def test_every_equivalent_diameter_is_the_one_function():
    """The mesh's d_eq as the printer check, the descriptors, the DEM templates, the clumps and the level-set
    grid see it: the same bits, all from sphere_diameter (a grain far from a ball, so that no rounding hides)."""
    from grainforge.analysis.descriptors import basic_descriptors
    from grainforge.dem.clump import _equivalent_diameter as clump_d
    from grainforge.fabrication.printability import equivalent_diameter
    from grainforge.fabrication.scale import to_size
    from grainforge.geometry.moments import signed_volume
    from grainforge.grain import Grain

    g = trimesh.creation.box((1.0, 2.0, 3.1))  # (6V/π)**(1/3) and np.cbrt(6V/π) differ in the last bit here
    v, f = np.asarray(g.vertices, float), np.asarray(g.faces, np.int64)
    d = float(sphere_diameter(signed_volume(v, f)))
    assert d == pytest.approx((6 * 6.2 / np.pi) ** (1 / 3), rel=1e-14)
    assert equivalent_diameter(v, f) == d
    assert equivalent_diameter(v, f[:, ::-1]) == d  # |V|: an inward mesh has the same size
    assert basic_descriptors(g)["equivalent_diameter"] == d
    assert dem_mass(v, f).equivalent_diameter == d
    assert clump_d(v, f) == d
    grain = Grain(v, f, method="box", params=None, seed=0)
    sized = to_size(grain, 2.0)
    assert float(sphere_diameter(signed_volume(sized.vertices, sized.faces))) == pytest.approx(2.0, rel=1e-14)


def test_the_equivalent_diameter_is_written_once():
    """No module but geometry/moments.py writes d = (6V/π)^(1/3) itself (as a cube root or a power of 1/3)."""
    import re
    from pathlib import Path

    formula = re.compile(r"cbrt\(\s*6(\.0)?\s*\*|\(\s*6(\.0)?\s*\*[^()\n]*(\([^()\n]*\))?[^()\n]*/\s*(np|math)\.pi\s*\)"
                         r"\s*\*\*\s*\(\s*1(\.0)?\s*/\s*3")
    src = Path(__file__).resolve().parents[2] / "src" / "grainforge"
    found = sorted({p.relative_to(src).as_posix() for p in src.rglob("*.py")
                    for line in p.read_text(encoding="utf-8").splitlines() if formula.search(line)})
    assert found == ["geometry/moments.py"]
