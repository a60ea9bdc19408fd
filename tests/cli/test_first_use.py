"""What a new user meets first: advice that names real options, help that lists what applies,
units in option names, refusals of options that would be ignored, plain messages, honest docs."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import click
import numpy as np
import pytest
import trimesh

from grainforge.cli.main import cli

ROOT = Path(__file__).resolve().parents[2]


def options_of(*path: str) -> set[str]:
    """Every option name (visible or not) of the grainforge subcommand ``path``."""
    cmd = cli
    for name in path:
        cmd = cmd.commands[name]
    return {o for p in cmd.params if isinstance(p, click.Option) for o in p.opts + p.secondary_opts}


@pytest.fixture(scope="module")
def sphere_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("mesh") / "sphere.stl"
    trimesh.creation.icosphere(2, radius=2.0).export(p)
    return p


# -- simulate -----------------------------------------------------------------------------------

def test_repose_note_on_a_heap_too_small_names_an_option_of_the_command():
    """A heap with no slope (a flat layer) gives NaN and a note whose advice is a real option."""
    from grainforge.simulate import measure_result

    d = 0.002
    xy = np.stack(np.meshgrid(np.arange(6) * d, np.arange(6) * d), -1).reshape(-1, 2)
    spheres = np.column_stack([xy, np.full(len(xy), d / 2), np.full(len(xy), d / 2)])
    result = {"test": "repose", "grains": len(xy), "inserted": len(xy), "lost": 0, "steps": 10, "dt": 1e-5,
              "time": 0.1, "d_mean": d, "spheres": spheres.tolist(), "base_top": 0.0, "settled": True}
    row = measure_result(result)
    assert np.isnan(row["angle_deg"])
    advised = re.findall(r"--[a-z][a-z-]*", row["note"])
    assert advised and set(advised) <= options_of("simulate", "repose"), row["note"]
    assert "_" not in row["note"], row["note"]  # no Python parameter names (bin_width) in user advice


def test_repose_help_lists_no_tilt_only_option(runner):
    repose = runner.invoke(cli, ["simulate", "repose", "--help"])
    tilt = runner.invoke(cli, ["simulate", "tilt", "--help"])
    assert repose.exit_code == tilt.exit_code == 0
    assert "--tilt-step" in tilt.output and "--tilt-start" in tilt.output
    assert "tilt" not in repose.output.lower()
    r = runner.invoke(cli, ["simulate", "repose", "x.toml", "--out", "o", "--tilt-step", "1"])
    assert r.exit_code == 2 and "--tilt-step" in r.stderr


# -- voxel sizes ----------------------------------------------------------------------------------

def test_voxel_size_options_carry_their_unit():
    """One voxel size in two units: both spellings in every command that takes one (meshes and images alike)."""
    for command in ("fit", "analyse", "scan"):
        assert {"--voxel-size-um", "--voxel-size-mm"} <= options_of(command), command


@pytest.mark.parametrize("command, new", [("fit", "--voxel-size-um"), ("analyse", "--voxel-size-mm")])
def test_the_old_voxel_size_name_is_refused_naming_the_new_one(runner, tmp_path, sphere_file, command, new):
    # fit: a sand file that is not there, so that nothing long runs if the refusal ever goes
    args = (["fit", str(tmp_path / "sand.csv"), "--out", str(tmp_path / "o")]
            if command == "fit" else ["analyse", str(sphere_file)])
    r = runner.invoke(cli, args + ["--voxel-size", "7.3"])
    assert r.exit_code == 2 and f"write {new} 7.3" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert not (tmp_path / "o").exists()
    help_text = runner.invoke(cli, [command, "--help"]).output
    assert new in help_text and not re.search(r"--voxel-size(?![-\w])", help_text)


def test_analyse_voxel_size_mm_measures_at_that_voxel_size(runner, sphere_file):
    import json

    r = runner.invoke(cli, ["analyse", str(sphere_file), "--voxel-size-mm", "0.1", "--no-fractal", "--no-fourier",
                            "--json"])
    assert r.exit_code == 0, r.output
    row = json.loads(r.stdout)[0]
    assert row["atlas_voxel_size_mm"] == pytest.approx(0.1)
    assert row["atlas_voxels_across"] == pytest.approx(row["equivalent_diameter_mm"] / 0.1)


# -- dem --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, flag, owner", [
    (["--shape", "polyhedron", "--spheres", "30"], "--spheres", "clump"),
    (["--shape", "levelset", "--refine-iterations", "5"], "--refine-iterations", "clump"),
    (["--vertices", "20"], "--vertices", "polyhedron"),
    (["--shape", "levelset", "--vertices", "20"], "--vertices", "polyhedron"),
    (["--spacing", "0.1"], "--spacing", "levelset"),
    (["--shape", "polyhedron", "--spacing", "0.1"], "--spacing", "levelset"),
])
def test_dem_refuses_an_option_of_another_shape(runner, tmp_path, sphere_file, args, flag, owner):
    out = tmp_path / "deck"
    r = runner.invoke(cli, ["dem", str(sphere_file), "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    assert f"{flag} applies to --shape {owner} only" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert not out.exists()


@pytest.mark.parametrize("args", [["--spheres", "8"], ["--shape", "polyhedron", "--vertices", "20"],
                                  ["--shape", "levelset", "--spacing", "0.1"]])
def test_dem_takes_each_shapes_own_options(runner, tmp_path, sphere_file, args):
    r = runner.invoke(cli, ["dem", str(sphere_file), "--out", str(tmp_path / "deck"), "--workers", "1", *args])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "deck" / "grains.json").is_file()


# -- help text ------------------------------------------------------------------------------------

def test_ratio_defaults_are_shown_in_the_notation_the_help_asks_for(runner):
    """A parameter whose help writes A:B:C (or L:I:S) shows its default that way, not 1,1,1."""
    from grainforge.methods import METHODS, get
    from grainforge.params import format_number, specs

    checked = 0
    for name in METHODS:
        for spec in specs(get(name).Params):
            if spec.kind == "floats" and re.search(r"\b[A-Z]:[A-Z]:[A-Z]\b", spec.help) and spec.default:
                assert spec.default_text() == ":".join(format_number(v) for v in spec.default), (name, spec.name)
                checked += 1
    assert checked >= 2  # fso and angular
    text = " ".join(runner.invoke(cli, ["generate", "fso", "--help"]).output.split())
    assert "[default: 1:1:1;" in text


# -- demo --------------------------------------------------------------------------------------------

@pytest.fixture
def fake_demo(monkeypatch):
    """``run_demo`` replaced by one that writes a single file (the command's own logic is under test)."""
    import grainforge.viz.demo

    def run_demo(out, quick=False, echo=print):
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "gallery.png").write_bytes(b"png")
        return [out / "gallery.png"]

    monkeypatch.setattr(grainforge.viz.demo, "run_demo", run_demo)


def test_demo_refuses_an_earlier_demo_without_overwrite(runner, tmp_path, fake_demo):
    out = tmp_path / "demo"
    first = runner.invoke(cli, ["demo", "--out", str(out)])
    assert first.exit_code == 0 and "overwriting" not in first.stderr
    again = runner.invoke(cli, ["demo", "--out", str(out)])
    assert again.exit_code == 2 and "use --overwrite" in again.stderr and again.stderr.count("\n") == 1
    replaced = runner.invoke(cli, ["demo", "--out", str(out), "--overwrite"])
    assert replaced.exit_code == 0 and f"overwriting the demo's outputs in {out}" in replaced.stderr


def test_make_demo_runs_on_a_fresh_clone_and_again(runner, tmp_path, monkeypatch, fake_demo):
    """The Makefile's demo recipe: it works with no out/ yet, and a second time, saying it overwrites."""
    text = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^demo:[^\n]*\n\t([^\n]+)", text, re.M).group(1)
    args = shlex.split(recipe.replace("$(BIN)/", ""))
    assert args[0] == "grainforge"
    monkeypatch.chdir(tmp_path)
    fresh = runner.invoke(cli, args[1:])
    second = runner.invoke(cli, args[1:])
    assert fresh.exit_code == 0 and second.exit_code == 0, second.output
    assert "overwriting" not in fresh.stderr and "overwriting" in second.stderr


# -- batch -----------------------------------------------------------------------------------------

def test_resume_of_a_finished_batch_says_it_is_complete(runner, tmp_path):
    recipe = tmp_path / "pop.toml"
    recipe.write_text('method = "fso"\ncount = 3\nseed = 5\n[params]\nfrequencies = 8\nridges = 8\n'
                      'subdivisions = 2\n')
    out = tmp_path / "pop"
    first = runner.invoke(cli, ["batch", str(recipe), "--out", str(out), "--workers", "1"])
    assert first.exit_code == 0, first.output
    again = runner.invoke(cli, ["batch", str(recipe), "--out", str(out), "--workers", "1", "--resume"])
    assert again.exit_code == 0, again.output
    assert "already complete" in again.stderr and "all 3 fso grains" in again.stderr
    assert "interrupted" not in again.stderr


# -- reading a file that is not a mesh -------------------------------------------------------------

@pytest.mark.parametrize("command", ["check", "analyse"])
def test_an_image_is_not_a_mesh_file(runner, tmp_path, command):
    from grainforge.io.inputs import MESH_SUFFIXES

    png = tmp_path / "sheet.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    r = runner.invoke(cli, [command, str(png)])
    assert r.exit_code == 2
    assert "not a mesh file (it is a PNG image)" in r.stderr and "PNG mesh" not in r.stderr, r.stderr
    assert all(s.lstrip(".").upper() in r.stderr for s in MESH_SUFFIXES), r.stderr


# -- docs checked against behaviour ----------------------------------------------------------------

def test_dpa_files_pass_check_as_docs_dem_says(runner, tmp_path):
    for primitive in ("cube", "octahedron"):
        r = runner.invoke(cli, ["generate", "dpa", "--out", str(tmp_path / primitive), "--count", "2",
                                "--primitive", primitive, "--primaries", "60"])
        assert r.exit_code == 0, r.output
    r = runner.invoke(cli, ["check", str(tmp_path / "cube"), str(tmp_path / "octahedron")])
    assert r.exit_code == 0, r.output
    text = " ".join((ROOT / "docs" / "dem.md").read_text().split())
    assert "`generate dpa` files have no such edge" in text and "pass `grainforge check`" in text
    assert "have such edges and fail" not in text


@pytest.mark.slow
def test_printing_doc_shows_the_level_generate_chooses(runner, tmp_path):
    """The docs/printing.md example: its command's resolution line is the one the docs print."""
    text = (ROOT / "docs" / "printing.md").read_text()
    block = re.search(r"```\n(grainforge generate cri [^\n]*--printer[^\n]*)\n((?:#[^\n]*\n)+)```", text)
    command, comment = block.group(1), block.group(2)
    documented = " ".join(line.lstrip("#").strip() for line in comment.splitlines())
    args = shlex.split(command)[1:]
    args[args.index("--out") + 1] = str(tmp_path / "cri")
    r = runner.invoke(cli, args)
    assert r.exit_code == 0, r.output
    line = next(s for s in r.stderr.splitlines() if s.startswith("resolution matching"))
    assert " ".join(line.split()) == documented


# -- pictures ----------------------------------------------------------------------------------------

def _scale_bars(fig):
    """(panel, label, length in mesh units) of every scale bar of a sheet."""
    bars = []
    for k, ax in enumerate(fig.axes):
        for line in (ln for ln in ax.lines if ln.get_label() == "scale bar"):
            x = line.get_xdata()
            text = next(t.get_text() for t in ax.texts if t.get_text().endswith(" mm"))
            bars.append((k, text, round(float(x[1] - x[0]), 6)))
    return bars


def _grain_pixels(fig):
    """Each panel's grain: its pixels (not the white background)."""
    return [float((np.asarray(ax.images[0].get_array())[..., :3].sum(-1) < 2.9).sum()) for ax in fig.axes]


def test_common_scale_sheet_has_one_scale_bar_and_true_relative_sizes():
    import matplotlib.pyplot as plt

    from grainforge.viz.render import contact_sheet_figure

    small, large = trimesh.creation.icosphere(3, radius=1.0), trimesh.creation.icosphere(3, radius=4.0)
    fig = contact_sheet_figure([small, large], ["1 mm", "4 mm"], unit="mm", dpi=60, common_scale=True)
    # one bar, under the first panel of the last row, as long as it says (the axes are in mm)
    assert [(k, text) for k, text, _ in _scale_bars(fig)] == [(0, "2 mm")]
    assert _scale_bars(fig)[0][2] == 2.0
    # the small sphere covers (1/4)² of the large one's pixels
    areas = _grain_pixels(fig)
    assert areas[0] / areas[1] == pytest.approx(1 / 16, rel=0.1)
    plt.close(fig)
    own = contact_sheet_figure([small, large], ["1 mm", "4 mm"], unit="mm", dpi=60)
    assert [(k, text) for k, text, _ in _scale_bars(own)] == [(0, "0.5 mm"), (1, "2 mm")]  # each filling its panel
    plt.close(own)


def test_render_draws_grains_at_one_scale_with_one_scale_bar(tmp_path, monkeypatch):
    """`grainforge render` of grains of 1 and 4 mm: every panel at one scale (equal axis limits, in mm), one
    scale bar for the sheet, their sizes compare; --own-scale: each filling its panel, a bar each."""
    import grainforge.io

    figures = []
    save = grainforge.io.save_figure

    def capture(fig, path, **kw):
        figures.append(fig)
        return save(fig, path, **kw)

    monkeypatch.setattr(grainforge.io, "save_figure", capture)
    files = []
    for r in (0.5, 2.0, 1.0):
        files.append(tmp_path / f"grain-{r:g}.stl")
        trimesh.creation.icosphere(3, radius=r).export(files[-1])
    from click.testing import CliRunner

    runner = CliRunner()
    r = runner.invoke(cli, ["render", *map(str, files), "-o", str(tmp_path / "sheet.png"), "--columns", "2"])
    assert r.exit_code == 0, r.output
    fig = figures[-1]
    limits = {(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes}
    assert len(limits) == 1  # one scale: the same limits, in mm, on every panel
    (xlim, _), = limits
    assert xlim[1] == pytest.approx(2.0, rel=0.03)  # half a panel: the largest grain's radius, in mm
    bars = _scale_bars(fig)
    assert len(bars) == 1 and bars[0][0] == 2 and bars[0][1].endswith(" mm")  # under the last row's first panel
    areas = _grain_pixels(fig)
    assert areas[0] / areas[1] == pytest.approx(1 / 16, rel=0.1) and areas[2] / areas[1] == pytest.approx(1 / 4, rel=0.1)
    assert (tmp_path / "sheet.png").stat().st_size > 1000
    r = runner.invoke(cli, ["render", *map(str, files), "-o", str(tmp_path / "own.png"), "--own-scale"])
    assert r.exit_code == 0, r.output
    own = figures[-1]
    assert len({(ax.get_xlim(), ax.get_ylim()) for ax in own.axes}) == 3
    assert [k for k, _, _ in _scale_bars(own)] == [0, 1, 2]


def test_dpa_figure_sheets_use_one_scale(monkeypatch, tmp_path):
    import grainforge.viz.render
    from grainforge.viz import figures

    seen = {}

    def capture(meshes, labels, out, **kw):
        seen.update(kw)
        return Path(out)

    monkeypatch.setattr(grainforge.viz.render, "contact_sheet", capture)
    monkeypatch.setattr(figures, "DPA_PRIMARIES", 20)
    figures.figure6(tmp_path / "f6.png")
    assert seen["common_scale"] is True and seen["unit"] == "mm"


def test_demo_dpa_gallery_is_drawn_at_one_scale(monkeypatch, tmp_path):
    """The demo's three DPA sheets share one scale: that of the largest aggregate of all three."""
    import grainforge.viz.demo as demo
    import grainforge.viz.render

    sizes = iter([1.0, 2.0, 5.0])  # the largest aggregate of each sweep (mm)

    def panels(out, method, make_params, values, label, seeds):
        r = next(sizes)
        return [trimesh.creation.icosphere(1, radius=r)], [f"{out.name}"]

    sheets = {}

    def capture(meshes, labels, out, **kw):
        sheets[Path(out).name] = kw
        return Path(out)

    monkeypatch.setattr(demo, "_sweep_panels", panels)
    monkeypatch.setattr(grainforge.viz.render, "contact_sheet", capture)
    demo.dpa_sweeps(tmp_path, quick=True)
    assert sorted(sheets) == ["dpa-cubes-smoothed.png", "dpa-cubes.png", "dpa-octahedra.png"]
    assert [kw["radius"] for kw in sheets.values()] == pytest.approx([5.0, 5.0, 5.0])
    assert all(kw["unit"] == "mm" for kw in sheets.values())


def _overlapping_tick_labels(fig):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    bad = []
    for ax in fig.axes:
        for axis, (lo, hi) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            ticks = [(t.get_text(), t.get_window_extent(r)) for t, v in
                     zip(axis.get_ticklabels(which="both"), list(axis.get_majorticklocs()) + list(axis.get_minorticklocs()))
                     if t.get_visible() and t.get_text() and min(lo, hi) <= v <= max(lo, hi)]
            bad += [(a[0], b[0]) for i, a in enumerate(ticks) for b in ticks[i + 1:] if a[1].overlaps(b[1])]
    return bad


@pytest.mark.parametrize("lo, hi", [(0.5, 3.0), (0.2, 2.0), (0.35, 0.9), (0.1, 1.18), (9.9, 10.1), (0.01, 50.0)])
def test_size_distribution_tick_labels_do_not_overlap(tmp_path, lo, hi):
    import matplotlib.pyplot as plt

    from grainforge.viz.plots import figure

    d = np.linspace(lo, hi, 20)
    p = tmp_path / "m.csv"
    p.write_text("equivalent_diameter,volume\n" + "".join(f"{x},{x ** 3}\n" for x in d))
    fig = figure("size-distribution", [p])
    assert _overlapping_tick_labels(fig) == []
    labels = [t.get_text() for t in fig.axes[0].xaxis.get_ticklabels() if t.get_text()]
    assert len(labels) >= 2 and all(re.fullmatch(r"[0-9.]+", s) for s in labels), labels  # 0.5, 1, 2: plain mm
    plt.close(fig)


def test_zingg_legend_is_inside_the_figure_and_class_names_are_not_hidden(tmp_path):
    import matplotlib.pyplot as plt

    from grainforge.viz.plots import figure

    rng = np.random.default_rng(0)
    manifests = []
    for k in range(8):  # eight populations, most grains equant, as in the demo
        L = np.ones(20)
        I = rng.uniform(0.7, 1.0, 20)
        S = I * rng.uniform(0.7, 1.0, 20)
        p = tmp_path / f"population-{k}.csv"
        p.write_text("L,I,S\n" + "".join(f"{a},{b},{c}\n" for a, b, c in zip(L, I, S)))
        manifests.append(p)
    fig = figure("zingg", manifests)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent(r)
    assert legend.y0 >= fig.bbox.y0 and legend.y1 <= fig.bbox.y1 and legend.x0 >= 0 and legend.x1 <= fig.bbox.x1
    names = {t.get_text(): t for t in ax.texts}
    assert set(names) == {"blade", "disc", "rod", "equant"}
    top = max(c.get_zorder() for c in ax.collections)
    for t in names.values():
        box = t.get_window_extent(r)
        assert ax.bbox.x0 <= box.x0 and box.x1 <= ax.bbox.x1 and ax.bbox.y0 <= box.y0 and box.y1 <= ax.bbox.y1
        patch = t.get_bbox_patch()
        assert t.get_zorder() > top and patch is not None and patch.get_alpha() >= 0.8
    plt.close(fig)
