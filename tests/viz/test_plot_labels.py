"""Every plot the project writes has labelled axes with units, and legends that hide nothing.

The Figure objects are inspected (labels, legends, limits, artists), not pixels.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _data_axes(fig):
    """Visible axes that show data (not colour bars, not pictures with their axis switched off)."""
    return [ax for ax in fig.axes if ax.get_visible() and ax.axison and ax.get_label() != "<colorbar>"]


def _labelled(fig):
    for ax in _data_axes(fig):
        assert ax.get_xlabel().strip(), f"no x label on {ax.get_title()!r}"
        assert ax.get_ylabel().strip(), f"no y label on {ax.get_title()!r}"


def _manifest(path, sizes, name_col="equivalent_diameter_mm"):
    lines = [f"file,{name_col},volume_mm3,L_mm,I_mm,S_mm,sphericity,convexity"]
    for i, d in enumerate(sizes):
        lines.append(f"g{i}.stl,{d},{np.pi / 6 * d**3},{1.3 * d},{d},{0.8 * d},0.9,0.95")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("kind", ["zingg", "sphericity-convexity", "size-distribution"])
def test_population_plots_are_labelled(tmp_path, kind):
    from grainforge.viz.plots import figure

    a = _manifest(tmp_path / "a.csv", [1.0, 2.0, 3.0])
    fig = figure(kind, [a])
    _labelled(fig)
    assert fig.axes[0].get_legend() is not None


def test_size_distribution_has_mm_and_does_not_hide_equal_sets(tmp_path):
    from grainforge.viz.plots import figure

    a = _manifest(tmp_path / "a.csv", [10.0] * 4)
    b = _manifest(tmp_path / "b.csv", [10.0] * 3)     # the same sizes: the same curve
    c = _manifest(tmp_path / "c.csv", [0.2, 0.3, 0.5, 0.6])
    ax = figure("size-distribution", [a, b, c]).axes[0]
    assert "(mm)" in ax.get_xlabel()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    # one entry names both equal sets (one line, not two hiding each other); every set is named
    assert len(labels) == len(ax.get_lines()) == 2
    assert any("a (n=4)" in t and "b (n=3)" in t and "10 mm" in t for t in labels)
    assert any("c (n=4)" in t for t in labels)
    # the legend is outside the axes, so it covers no curve
    fig = ax.figure
    fig.canvas.draw()
    leg = ax.get_legend().get_window_extent()
    assert not leg.overlaps(ax.get_window_extent())


def test_fd_spectrum_is_labelled(tmp_path):
    from grainforge.viz.plots import figure

    cols = [f"fd_{p}_{n}" for p in ("LI", "LS", "IS") for n in (2, 3, 4, 8)]
    rows = [",".join(["g.stl"] + [str(0.1 / n) for _ in ("LI", "LS", "IS") for n in (2, 3, 4, 8)])] * 3
    path = tmp_path / "fd.csv"
    path.write_text("file," + ",".join(cols) + "\n" + "\n".join(rows) + "\n")
    fig = figure("fd-spectrum", [path])
    _labelled(fig)


def _calibration():
    from grainforge.methods.dpa.calibration import Calibration

    e = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    m = np.array([2.6, 2.4, 2.2, 2.0, 1.9])
    return Calibration(primitive="cube", primaries=50, repeats=3, seed=0, exponent=e, D_A_mean=m,
                       D_A_std=0.05 + 0 * e, porosity_mean=np.linspace(0.3, 0.6, 5), porosity_std=0.02 + 0 * e,
                       R_g_mean=np.linspace(2, 4, 5), R_g_std=0.1 + 0 * e)


def test_calibration_figure_legend_covers_no_curve():
    fig = _calibration().figure()
    ax, ax2 = fig.axes[0], fig.axes[1]
    assert ax.get_xlabel() and ax.get_ylabel() and ax2.get_ylabel()
    fig.canvas.draw()
    leg = ax.get_legend()
    assert leg is not None and len(leg.get_texts()) >= 3
    assert not leg.get_window_extent().overlaps(ax.get_window_extent())


def test_population_figure_has_y_labels_and_no_empty_panels(tmp_path):
    from grainforge.population import parse_recipe, run_batch
    from grainforge.population.report import population_figure, summary

    recipe = parse_recipe(
        'method = "fso"\ncount = 5\nseed = 3\n[params]\nsubdivisions = 1\n'
        'fractal_dimension = { distribution = "uniform", low = 2.2, high = 2.5 }\n'
        '[size]\nmm = 2.0\n', source=str(tmp_path / "r.toml"))
    rows = run_batch(recipe, tmp_path / "pop", workers=1, report=False)["rows"]
    fig = population_figure(recipe, rows, summary(recipe, rows))
    assert all(ax.get_visible() for ax in fig.axes)          # no hidden, empty panels
    assert len(fig.axes) == 4                                 # size, fractal_dimension, sphericity, convexity
    _labelled(fig)
    assert "(mm)" in fig.axes[0].get_xlabel()
    assert all(ax.get_ylabel() == "number of grains" for ax in fig.axes)


def test_cri_sections_share_one_scale_and_state_units():
    from grainforge.viz.demo import cri_sections

    fig = cri_sections(subdivisions=2)
    axes = fig.axes
    assert len(axes) == 3
    _labelled(fig)
    assert all("r0" in ax.get_xlabel() and "r0" in ax.get_ylabel() for ax in axes)
    lims = {(ax.get_xlim(), ax.get_ylim()) for ax in axes}
    assert len(lims) == 1                                     # the same limits on every panel
    xlim, ylim = lims.pop()
    assert xlim == pytest.approx(ylim)
    assert all(ax.get_aspect() == 1.0 for ax in axes)          # equal axis scales
    assert fig.legends and not any(ax.get_legend() for ax in axes)


def test_render_has_a_scale_bar_when_the_grain_has_a_physical_size():
    import trimesh

    from grainforge.viz.render import contact_sheet_figure

    sphere = trimesh.creation.icosphere(2, radius=1.0)   # a 2 mm grain
    fig = contact_sheet_figure([sphere, sphere], ["a", "b"], unit="mm", panel_size=1.0, dpi=60)
    for ax in fig.axes:
        bars = [ln for ln in ax.get_lines() if ln.get_label() == "scale bar"]
        assert len(bars) == 1
        texts = [t.get_text() for t in ax.texts]
        assert texts == ["0.5 mm"]
        # the panel's axes are in mm: the bar is 0.5 long, and the 2 mm grain spans 2 of the picture's width
        x = bars[0].get_xdata()
        assert (x[1] - x[0]) == pytest.approx(0.5)
        image = ax.images[0]
        left, right, _, _ = image.get_extent()
        grain = np.asarray(image.get_array())[..., :3].sum(-1) < 2.9
        columns = np.flatnonzero(grain.any(axis=0))
        assert (columns[-1] - columns[0] + 1) * (right - left) / grain.shape[1] == pytest.approx(2.0, rel=0.05)
    plain = contact_sheet_figure([sphere], ["a"], panel_size=1.0, dpi=60)
    assert not plain.axes[0].get_lines() and not plain.axes[0].texts   # model units: no bar


def test_tray_preview_is_labelled_in_mm_with_a_layer_scale():
    from grainforge.fabrication.tray import preview_figure

    square = np.array([[0, 0], [5, 0], [5, 5], [0, 5]], dtype=float)
    fig = preview_figure([square, square + 10, square + 20], [0, 0, 1], (100.0, 80.0, 50.0), "plate 1")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x (mm)" and ax.get_ylabel() == "y (mm)"
    assert any(a.get_label() == "<colorbar>" and "layer" in a.get_ylabel() for a in fig.axes)


def test_figure3_traces_the_whole_grain_not_its_lit_half():
    from grainforge.viz.figures import _traced_micrograph

    image, traced = _traced_micrograph(subdivisions=2)
    grain = image > 0.11  # every pixel brighter than the 0.08-0.10 background
    p = traced.points(physical=True)
    x, y = p[:, 0], p[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert area == pytest.approx(grain.sum(), rel=0.03)


@pytest.mark.parametrize("number", [1, 2, 4, 5, 6])
def test_figure_contact_sheets_have_mm_scale_bars(monkeypatch, tmp_path, number):
    """The paper's 3D figures show grains at a printed size (d_eq = 10 mm) with a scale bar in mm per panel."""
    import trimesh

    from grainforge.viz import figures, render

    seen = {}

    def capture(meshes, labels, out, **kw):
        seen.update(meshes=meshes, **kw)
        return out

    monkeypatch.setattr(render, "contact_sheet", capture)
    figures.FIGURES[number][1](tmp_path / "f.png", 2)
    assert seen["unit"] == "mm" and "d_eq = 10 mm" in seen["title"]
    for m in seen["meshes"]:
        volume = trimesh.Trimesh(m.vertices, m.faces, process=False).volume
        assert np.cbrt(6 * volume / np.pi) == pytest.approx(figures.PRINTED_SIZE, rel=1e-6)
