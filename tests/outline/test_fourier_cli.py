"""``grainforge fourier`` and ``grainforge generate cri`` through the CLI."""

import csv
import io

import numpy as np
import pytest

from grainforge.cli.main import cli
from grainforge.outline.contours import Contour
from grainforge.outline.imaging import draw_contours


def _save(path, img):
    from PIL import Image

    Image.fromarray(img).save(path)
    return str(path)


@pytest.fixture(scope="module")
def field(tmp_path_factory):
    """A 600×600 image with 4 measurable grains, 2 touching the border and 1 speck."""
    d = tmp_path_factory.mktemp("fourier")
    truths = [Contour.from_descriptors("rough-angular", rng=i) for i in range(4)]
    items = [(c, (150 + 300 * (i % 2), 150 + 300 * (i // 2)), 90.0) for i, c in enumerate(truths)]
    items += [(Contour.from_descriptors("rough-sphere", rng=9), (0, 300), 40.0),
              (Contour.from_descriptors("rough-sphere", rng=8), (300, 599), 40.0)]
    img = draw_contours((600, 600), items)
    img[300:304, 300:304] = 255  # a 16-px speck
    return _save(d / "field.png", img), truths


def _rows(text):
    return list(csv.DictReader(io.StringIO(text)))


def test_fourier_one_row_per_grain(runner, field):
    path, truths = field
    res = runner.invoke(cli, ["fourier", path], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    rows = _rows(res.stdout)
    assert len(rows) == 4
    assert "4 grain(s) measured in 1 image(s); skipped 2 touching the border, 1 below 50 px" in res.stderr
    assert list(rows[0])[:10] == ["image", "grain", "x_px", "y_px", "area_px2", "r0_px", "star_shaped", "elongation",
                                  "irregularity", "roughness"]
    assert list(rows[0])[-1] == "D16"
    # label order is row-major: the grains come out in the order they were drawn
    for row, truth in zip(rows, truths):
        known = truth.recentred().descriptors()
        assert float(row["elongation"]) == pytest.approx(known[2], rel=0.05)
        assert float(row["irregularity"]) == pytest.approx(known[3], rel=0.05)
        assert float(row["D2"]) == float(row["elongation"]) and float(row["D8"]) == float(row["roughness"])
        assert abs(float(row["roughness"]) - known[8]) < 0.004
        assert float(row["r0_px"]) == pytest.approx(90 * truth.recentred().scale, rel=0.02)


def test_fourier_csv_and_min_area(runner, field, tmp_path):
    path, _ = field
    out = tmp_path / "fd.csv"
    res = runner.invoke(cli, ["fourier", path, path, "--csv", str(out), "--min-area", "10"])
    assert res.exit_code == 0, res.output
    assert res.stdout == ""
    rows = _rows(out.read_text())
    assert len(rows) == 10  # 4 grains + the speck, twice
    assert "skipped 4 touching the border, 0 below 10 px" in res.stderr


@pytest.mark.parametrize("kind", ["missing", "garbage", "blank", "all-border"])
def test_fourier_bad_images(runner, tmp_path, kind):
    path = tmp_path / "x.png"
    if kind == "garbage":
        path.write_bytes(b"\x89PNG not really")
    elif kind == "blank":
        _save(path, np.zeros((64, 64), np.uint8))
    elif kind == "all-border":
        img = np.zeros((64, 64), np.uint8)
        img[:, :10] = 255
        _save(path, img)
    res = runner.invoke(cli, ["fourier", str(path)])
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:")
    assert {"missing": "no such image", "garbage": "cannot read image", "blank": "uniform",
            "all-border": "no grain measured"}[kind] in lines[0]


# ---------------------------------------------------------------- generate cri
def test_fourier_binary_ellipse(runner, tmp_path):
    """A binary ellipse image (outline vertices exactly on the rays at 0 and π) gives one grain
    (such images were once refused with "no grain measured")."""
    yy, xx = np.mgrid[:300, :300]
    img = ((((xx - 150) / 80) ** 2 + ((yy - 150) / 50) ** 2 <= 1) * 255).astype(np.uint8)
    res = runner.invoke(cli, ["fourier", _save(tmp_path / "ellipse.png", img)])
    assert res.exit_code == 0, res.output
    (row,) = _rows(res.stdout)
    assert row["star_shaped"] == "True"
    assert float(row["elongation"]) > 0.1  # an 80 x 50 ellipse is elongated


def test_generate_cri_files_and_manifest(runner, tmp_path):
    out = tmp_path / "run"
    args = ["generate", "cri", "--out", str(out), "--count", "2", "--seed", "4", "--preset", "rough-angular",
            "--subdivisions", "3", "--size", "2"]
    res = runner.invoke(cli, args, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["cri-0000.stl", "cri-0001.stl", "manifest.csv"]
    rows = _rows((out / "manifest.csv").read_text())
    assert [r["seed"] for r in rows] == ["4", "5"]
    assert rows[0]["preset"] == "rough-angular" and rows[0]["descriptors"] == "0.15 0.1 0.03"
    assert float(rows[0]["contour_xy_D2"]) == pytest.approx(0.15)
    assert float(rows[0]["contour_yz_D8"]) == pytest.approx(0.03)
    for plane in ("xy", "xz", "yz"):
        assert 0 < float(rows[0][f"section_{plane}_D8"]) < 0.1
    assert float(rows[0]["equivalent_diameter_mm"]) == pytest.approx(2.0)
    first = (out / "cri-0000.stl").read_bytes()
    # byte-identical again
    res = runner.invoke(cli, args + ["--overwrite"])
    assert res.exit_code == 0 and (out / "cri-0000.stl").read_bytes() == first


def test_generate_cri_options(runner, tmp_path):
    out = tmp_path / "a"
    res = runner.invoke(cli, ["generate", "cri", "--out", str(out), "--descriptors", "0.1,0.05,0.02",
                              "--descriptors-xz", "0.2,0.1,0.03", "--decay", "-2,-1.5", "--aspect", "2:1.5:1",
                              "--subdivisions", "2", "--format", "ply"])
    assert res.exit_code == 0, res.output
    row = _rows((out / "manifest.csv").read_text())[0]
    assert row["aspect"] == "2.0 1.5 1.0" and row["decay"] == "-2.0 -1.5"
    assert float(row["contour_xz_D2"]) == pytest.approx(0.2)
    res = runner.invoke(cli, ["generate", "cri", "--out", str(tmp_path / "f"), "--contour", "fractal",
                              "--subdivisions", "2"])
    assert res.exit_code == 0, res.output


def test_generate_cri_from_images(runner, tmp_path):
    paths = []
    for i in range(3):
        c = Contour.from_descriptors("rough-angular", rng=20 + i)
        paths.append(_save(tmp_path / f"g{i}.png", draw_contours((256, 256), [(c, (128, 128), 90.0)])))
    out = tmp_path / "img"
    res = runner.invoke(cli, ["generate", "cri", "--out", str(out), "--images", ",".join(paths),
                              "--subdivisions", "2"])
    assert res.exit_code == 0, res.output
    row = _rows((out / "manifest.csv").read_text())[0]
    assert row["contour"] == "image" and row["images"] == ",".join(paths)
    assert float(row["contour_xy_D2"]) == pytest.approx(Contour.from_image(paths[0]).descriptors()[2])


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--descriptors", "0.1,0.2"], "--descriptors"),
        (["--preset", "rough-sphere", "--descriptors", "0.1,0.1,0.1"], "--preset"),
        (["--aspect", "1:2:3"], "--aspect"),
        (["--aspect", "2:x:1"], "--aspect"),
        (["--images", "a.png,b.png"], "--images"),
        (["--images", "a.png,b.png,c.png"], "no such image"),
        (["--contour", "image"], "--images"),
        (["--descriptors", "0.9,0.9,0.5"], "--descriptors"),
    ],
)
def test_generate_cri_bad_input(runner, tmp_path, extra, message):
    out = tmp_path / "bad"
    res = runner.invoke(cli, ["generate", "cri", "--out", str(out), "--subdivisions", "1"] + extra)
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]
    assert not out.exists()
