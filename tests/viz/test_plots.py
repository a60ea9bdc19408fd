"""grainforge plot (population plots from manifests) and grainforge figures."""

import pytest

from grainforge.io import write_csv
from grainforge.viz.plots import KINDS, manifest_columns, plot

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def manifests(tmp_path_factory):
    """Two analyse-style manifests of FSO grains (smooth vs rough) and a generate manifest."""
    from grainforge import fso
    from grainforge.analysis.descriptors import describe
    from grainforge.methods.fso import Params
    from grainforge.population.generate import write_run

    d = tmp_path_factory.mktemp("m")
    out = {}
    for name, D in (("smooth", 2.1), ("rough", 2.7)):
        rows = [dict(describe(fso(fractal_dimension=D, subdivisions=3, rng=s), fractal=False), file=f"{s}")
                for s in range(4)]
        out[name] = write_csv(d / f"{name}.csv", rows)
    write_run("fso", Params(subdivisions=2), seeds=[0, 1, 2], out=d / "run")
    out["run"] = d / "run" / "manifest.csv"
    return out


@pytest.mark.parametrize("kind", list(KINDS))
def test_each_kind_overlays_two_manifests(manifests, tmp_path, kind):
    p = plot(kind, [manifests["smooth"], manifests["rough"]], tmp_path / f"{kind}.png", title="two")
    assert p.read_bytes()[:8] == PNG


@pytest.mark.parametrize("kind", ["zingg", "sphericity-convexity", "size-distribution"])
def test_generate_manifest_works(manifests, tmp_path, kind):
    assert plot(kind, [manifests["run"]], tmp_path / "x.png").read_bytes()[:8] == PNG


def test_fd_spectrum_needs_descriptors(manifests, tmp_path):
    with pytest.raises(ValueError, match="grainforge analyse"):
        plot("fd-spectrum", [manifests["run"]], tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_fd_spectrum_with_cri_input(tmp_path):
    from grainforge.methods.cri import Params
    from grainforge.population.generate import write_run

    write_run("cri", Params(descriptors=(0.15, 0.1, 0.03), subdivisions=2), seeds=[0, 1], out=tmp_path / "cri")
    table = manifest_columns(tmp_path / "cri" / "manifest.csv")
    assert table["descriptors"][0].split() == ["0.15", "0.1", "0.03"]
    assert plot("fd-spectrum", [tmp_path / "cri" / "manifest.csv"], tmp_path / "s.png").read_bytes()[:8] == PNG


def test_bad_manifests(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        manifest_columns(tmp_path / "none.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValueError, match="no rows"):
        manifest_columns(tmp_path / "empty.csv")
    (tmp_path / "nocols.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="no column 'L'"):
        plot("zingg", [tmp_path / "nocols.csv"], tmp_path / "z.png")
    with pytest.raises(ValueError, match="plot kind"):
        plot("pie", [tmp_path / "nocols.csv"], tmp_path / "z.png")


def test_cli_plot(runner, manifests, tmp_path):
    from grainforge.cli.main import cli

    out = tmp_path / "z.png"
    res = runner.invoke(cli, ["plot", "zingg", str(manifests["smooth"]), str(manifests["rough"]), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:8] == PNG
    res = runner.invoke(cli, ["plot", "zingg", str(manifests["smooth"]), "-o", str(out)])
    assert res.exit_code == 2 and "exists" in res.output
    res = runner.invoke(cli, ["plot", "fd-spectrum", str(manifests["run"]), "-o", str(tmp_path / "f.png")])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
    res = runner.invoke(cli, ["plot", "pie", str(manifests["run"]), "-o", str(tmp_path / "f.png")])
    assert res.exit_code == 2


def test_cli_figures_fso(runner, tmp_path):
    from grainforge.cli.main import cli

    res = runner.invoke(cli, ["figures", "--out", str(tmp_path), "--only", "2", "--subdivisions", "2"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "figure2-fso-dimension.png").read_bytes()[:8] == PNG
    res = runner.invoke(cli, ["figures", "--out", str(tmp_path), "--only", "2", "--subdivisions", "2"])
    assert res.exit_code == 2 and "exists" in res.output


def test_figures_contours_and_cri(tmp_path):
    from grainforge.viz.figures import make_figures

    written, skipped = make_figures(tmp_path, (3, 4), subdivisions=2)
    assert [p.name for p in written] == ["figure3-contours.png", "figure4-cri.png"] and not skipped


def test_figures_dpa_written_or_skipped_with_reason(tmp_path):
    from grainforge.methods import METHODS
    from grainforge.viz.figures import make_figures

    written, skipped = make_figures(tmp_path, (6,), subdivisions=2)
    if "dpa" in METHODS:
        assert [p.name for p in written] == ["figure6-dpa-octahedra.png"]
    else:
        assert skipped == [(6, "the DPA generator is not available in this build")]
    with pytest.raises(ValueError, match="1–9"):
        make_figures(tmp_path, (10,))


def test_shape_control_figures(tmp_path):
    """Figures 7–9 (FSO aspect, paper vs seamless views, CRI before/after) are written as PNGs."""
    from PIL import Image

    from grainforge.viz.figures import make_figures

    written, skipped = make_figures(tmp_path, (7, 8, 9), subdivisions=2)
    assert skipped == []
    assert [p.name for p in written] == ["figure7-fso-aspect.png", "figure8-fso-seamless.png",
                                         "figure9-cri-before-after.png"]
    for p in written:
        with Image.open(p) as im:
            assert im.size[0] > 800 and im.size[1] > 250


def test_demo_plots(tmp_path):
    from grainforge.methods.fso import Params
    from grainforge.population.generate import write_run
    from grainforge.viz.plots import demo_plots

    assert demo_plots(tmp_path) == []
    write_run("fso", Params(subdivisions=2), seeds=[0, 1, 2], out=tmp_path / "fso" / "L=7")
    write_run("fso", Params(subdivisions=2, length_ratio=2.0), seeds=[0, 1], out=tmp_path / "fso" / "L=2")
    written = demo_plots(tmp_path, quick=True)
    names = sorted(p.name for p in written)
    assert names == ["fd-spectrum.png", "fso-measured.csv", "fso.csv", "size-distribution.png",
                     "sphericity-convexity.png", "zingg.png"]
    assert len((tmp_path / "analysis" / "fso.csv").read_text().splitlines()) == 1 + 5  # pooled rows
