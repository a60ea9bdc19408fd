"""Printer profiles (built-in and TOML) and resolution matching."""

import dataclasses

import numpy as np
import pytest

import grainforge
from grainforge.fabrication.printers import PRINTERS, get_printer, load_printers
from grainforge.fabrication.resolution import _midpoint_index, chordal_deviation, match_subdivisions
from grainforge.geometry.geodesic import icosphere
from grainforge.methods.fso import Params as FsoParams


def test_builtin_profiles():
    pj = get_printer("objet-eden-250")
    assert pj.build_volume == (250.0, 250.0, 200.0) and pj.resolution == 0.032 and pj.stacking
    assert pj.default_gap == pytest.approx(0.064) and pj.max_deviation == pytest.approx(0.016)
    fdm = get_printer("generic-fdm")
    assert fdm.resolution == 0.4 and fdm.layer_height == 0.2 and not fdm.stacking
    sla = get_printer("generic-sla")
    assert sla.resolution == 0.05 and not sla.stacking
    assert set(PRINTERS) == {"objet-eden-250", "generic-fdm", "generic-sla"}


def test_toml_profiles(tmp_path):
    f = tmp_path / "printers.toml"
    f.write_text(
        '[printer.tiny]\ntechnology = "polyjet"\nbuild_volume = [10, 10, 6]\nresolution = 0.02\n\n'
        '[printer.desk-fdm]\ntechnology = "fdm"\nbuild_volume = [180, 180, 180]\nresolution = 0.4\n'
        'min_wall = 1.2\nstacking = false\n'
    )
    profiles = load_printers(f)
    assert set(profiles) == {"tiny", "desk-fdm"}
    tiny = get_printer(f"{f}#tiny")
    assert tiny.stacking and tiny.min_wall == pytest.approx(0.08) and tiny.min_size == pytest.approx(0.2)
    assert get_printer(f"{f}#desk-fdm").min_wall == 1.2
    with pytest.raises(ValueError, match="several printers"):
        get_printer(str(f))
    one = tmp_path / "one.toml"
    one.write_text('[printer.x]\ntechnology = "sla"\nbuild_volume = [1, 2, 3]\nresolution = 0.05\n')
    assert get_printer(str(one)).name == "x"


@pytest.mark.parametrize(
    "body, match",
    [
        ('technology = "sla"\nbuild_volume = [1, 2, 3]\nresolution = -1\n', "resolution must be a positive"),
        ('technology = "laser"\nbuild_volume = [1, 2, 3]\nresolution = 0.1\n', "technology must be one of"),
        ('technology = "sla"\nbuild_volume = [1, 2]\nresolution = 0.1\n', "build_volume"),
        ('technology = "sla"\nbuild_volume = [1, 2, 3]\n', "missing 'resolution'"),
        ('technology = "sla"\nbuild_volume = [1, 2, 3]\nresolution = 0.1\nspeed = 3\n', "unknown key 'speed'"),
        ('technology = "sla"\nbuild_volume = [1, 2, 3]\nresolution = 0.1\nstacking = "yes"\n', "stacking"),
    ],
)
def test_bad_toml_profiles(tmp_path, body, match):
    f = tmp_path / "bad.toml"
    f.write_text("[printer.bad]\n" + body)
    with pytest.raises(ValueError, match=match):
        get_printer(str(f))


def test_bad_printer_names(tmp_path):
    with pytest.raises(ValueError, match="printer must be one of"):
        get_printer("objet")
    with pytest.raises(ValueError, match="no such printer profile file"):
        get_printer(str(tmp_path / "none.toml"))
    (tmp_path / "broken.toml").write_text("[printer.a\n")
    with pytest.raises(ValueError, match="not a valid TOML"):
        get_printer(str(tmp_path / "broken.toml"))


def test_chordal_deviation_of_a_sphere_is_the_sagitta():
    """On a unit sphere the midpoint deviation of an edge spanning angle α is 1 − cos(α/2)."""
    for level in (1, 2, 3):
        g = grainforge.generate("fso", FsoParams(amplitude=0.0, subdivisions=level + 1), rng=0)
        v, _ = icosphere(level)
        e, _ = _midpoint_index(level)
        alpha = np.arccos(np.einsum("ij,ij->i", v[e[:, 0]], v[e[:, 1]]))
        expected = (1 - np.cos(alpha / 2)).max()
        assert chordal_deviation(g, level) == pytest.approx(expected, rel=1e-9)


def test_matching_a_sphere_follows_the_sagitta_rule():
    # a sphere of radius R: the level whose largest sagitta is <= res/2
    p = FsoParams(amplitude=0.0)
    for size, printer in [(2.0, "objet-eden-250"), (20.0, "objet-eden-250"), (2.0, "generic-fdm")]:
        r = match_subdivisions("fso", p, size=size, size_definition="equivalent", printer=printer, seeds=[0])
        tol = get_printer(printer).resolution / 2
        assert r.converged and r.deviation <= tol and r.limited_by == "tolerance"
        if r.subdivisions > 0:  # the next coarser level would not do
            g = grainforge.generate("fso", dataclasses.replace(p, subdivisions=r.subdivisions), rng=0)
            assert chordal_deviation(g, r.subdivisions - 1) * size / 2 > tol
        assert r.faces == 20 * 4**r.subdivisions


def test_finer_printer_or_bigger_grain_needs_finer_mesh():
    p = FsoParams(amplitude=0.05, length_ratio=7, frequencies=8)
    levels = [match_subdivisions("fso", p, size=s, size_definition="equivalent", printer="objet-eden-250",
                                 seeds=[0, 1]).subdivisions for s in (1, 4, 16)]
    assert levels == sorted(levels) and levels[0] < levels[-1]


def test_triangle_budget_caps_the_level():
    r = match_subdivisions("fso", FsoParams(amplitude=0.0), size=20.0, size_definition="equivalent",
                           printer="objet-eden-250", seeds=[0], max_faces=400)
    assert r.subdivisions == 2 and not r.converged and r.limited_by == "budget"
    assert r.deviation > r.tolerance
    assert "budget" in r.describe()


def test_matching_needs_pilot_seeds():
    with pytest.raises(ValueError, match="at least one pilot seed"):
        match_subdivisions("fso", FsoParams(), size=2.0, size_definition="equivalent", printer="objet-eden-250",
                           seeds=[])
