"""Units: numbers are numbers, and every column name states its unit."""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest
import trimesh

from grainforge.cli.main import cli


def _csv(text):
    return list(csv.DictReader(io.StringIO(text)))


def test_check_csv_min_wall_is_always_a_number(runner, tmp_path):
    sphere = tmp_path / "sphere.stl"
    trimesh.creation.icosphere(3, radius=5.0).export(sphere)     # walls far thicker than the horizon
    slab = tmp_path / "slab.stl"
    trimesh.creation.box(extents=(5.0, 5.0, 0.3)).export(slab)   # a 0.3 mm wall, measured
    res = runner.invoke(cli, ["check", str(sphere), str(slab), "--csv"])
    rows = _csv(res.stdout)
    assert [r["min_wall_status"] for r in rows] == ["thicker", "measured"]
    walls = [float(r["min_wall_mm"]) for r in rows]     # a word here would raise
    assert walls[0] == pytest.approx(4 * 0.1)            # the horizon, 4 x min_wall of objet-eden-250: a lower bound
    assert walls[1] == pytest.approx(0.3, rel=1e-3)
    for r in rows:
        float(r["min_neck_mm"])
        assert r["min_neck_status"] in ("measured", "thicker")


def test_fourier_pixel_size_adds_physical_columns(runner, tmp_path):
    from skimage.draw import disk
    from skimage.io import imsave

    img = np.zeros((200, 200), dtype=np.uint8)
    img[disk((100, 100), 40)] = 255
    path = tmp_path / "disk.png"
    imsave(path, img, check_contrast=False)
    plain = _csv(runner.invoke(cli, ["fourier", str(path)]).stdout)[0]
    assert {"x_px", "y_px", "area_px2", "r0_px"} <= set(plain) and not {"x", "area", "r0"} & set(plain)
    assert not any(c.endswith("_mm") or c.endswith("_mm2") for c in plain)
    res = runner.invoke(cli, ["fourier", str(path), "--pixel-size", "2.5"])   # 2.5 µm per pixel
    row = _csv(res.stdout)[0]
    assert float(row["r0_mm"]) == pytest.approx(float(row["r0_px"]) * 2.5e-3, rel=1e-3)
    assert float(row["r0_mm"]) == pytest.approx(40 * 2.5e-3, rel=0.03)
    assert float(row["area_mm2"]) == pytest.approx(float(row["area_px2"]) * 2.5e-3 ** 2, rel=1e-9)
    assert float(row["x_mm"]) == pytest.approx(float(row["x_px"]) * 2.5e-3, rel=1e-9)
    for bad in ("0", "-1", "nan", "inf"):
        r = runner.invoke(cli, ["fourier", str(path), "--pixel-size", bad])
        assert r.exit_code == 2 and "--pixel-size" in r.output


#: manifest columns that are dimensionless, counts, identities or words (everything else must carry a unit)
UNITLESS = {
    "file", "method", "seed", "size_definition", "version", "sha256", "printer", "resolution_limited_by",
    "K", "D_A", "D_A_scaling", "porosity", "sphericity", "convexity", "modes_used", "correction",
    "target_aspect", "axis_scale", "target_fractal_dimension", "aspect_residual",
}


def _unit_ok(header, params):
    from grainforge.units import UNITS

    if header in UNITLESS or header in params or header.startswith(("contour_", "section_")):
        return True
    return any(header == f"{c}_{u}" for c, u in UNITS.items())


def test_manifest_headers_state_units_and_R_g_is_mm_like_analyse(runner, tmp_path):
    from grainforge.methods import get
    from grainforge.params import specs

    out = tmp_path / "dpa"
    res = runner.invoke(cli, ["generate", "dpa", "--out", str(out), "--primaries", "12", "--exponent", "0.5",
                              "--size", "3", "--seed", "2"])
    assert res.exit_code == 0, res.output
    with open(out / "manifest.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    params = {s.name for s in specs(get("dpa").Params)}
    assert [h for h in rows[0] if not _unit_ok(h, params)] == []
    for plain in ("R_g", "volume", "L", "size", "primary_size", "cavity_volume", "equivalent_diameter"):
        assert plain not in rows[0]
    m = rows[0]
    assert float(m["cavity_volume_mm3"]) == 0.0
    res = runner.invoke(cli, ["analyse", str(out / m["file"]), "--no-fractal", "--no-fourier",
                              "--primary-volume", str(float(m["primary_size_mm"]) ** 3), "--csv", str(tmp_path / "a.csv")])
    assert res.exit_code == 0, res.output
    with open(tmp_path / "a.csv", newline="") as fh:
        a = next(csv.DictReader(fh))
    assert "radius_of_gyration_mm" in a and "volume_mm3" in a and "L_mm" in a
    # the manifest's R_g (aggregate of primaries) and analyse's (the written solid) are the same quantity, in mm
    assert float(m["R_g_mm"]) == pytest.approx(float(a["radius_of_gyration_mm"]), rel=1e-3)
    assert float(m["volume_mm3"]) == pytest.approx(float(a["volume_mm3"]), rel=1e-5)


def test_analyse_table_and_json_state_units(runner, tmp_path):
    import json

    path = tmp_path / "s.stl"
    trimesh.creation.icosphere(2, radius=2.0).export(path)
    table = runner.invoke(cli, ["analyse", str(path), "--no-fractal", "--no-fourier"]).stdout
    header = table.splitlines()[0].split()
    assert {"V_mm3", "d_eq_mm", "L_mm", "I_mm", "S_mm"} <= set(header)
    row = json.loads(runner.invoke(cli, ["analyse", str(path), "--no-fractal", "--no-fourier", "--json"]).stdout)[0]
    assert row["equivalent_diameter_mm"] == pytest.approx(4.0, rel=0.02) and "volume" not in row


#: small, fast runs of each method (a new generator with no entry runs with its defaults at level 1)
SMALL = {"dpa": ["--primaries", "6"], "rf": ["--subdivisions", "1"]}
#: info columns of the methods that are dimensionless ratios, indices or labels
RATIOS = {"flat_fraction", "field_rms", "spectrum_misfit", "spectrum_row", "spectrum_grain"}


@pytest.mark.parametrize("method", sorted(__import__("grainforge.methods", fromlist=["METHODS"]).METHODS))
def test_every_method_manifest_header_states_units(runner, tmp_path, method):
    from grainforge.fabrication.resolution import supports_matching
    from grainforge.methods import get
    from grainforge.params import specs

    args = SMALL.get(method, ["--subdivisions", "1"] if supports_matching(method) else [])
    res = runner.invoke(cli, ["generate", method, "--out", str(tmp_path / method), "--size", "2", *args])
    assert res.exit_code == 0, res.output
    with open(tmp_path / method / "manifest.csv", newline="") as fh:
        header = next(csv.reader(fh))
    params = {s.name for s in specs(get(method).Params)}
    bad = [h for h in header if not (_unit_ok(h, params) or h in RATIOS)]
    assert bad == [], f"{method}: columns without a unit: {bad}"
