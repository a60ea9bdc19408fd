"""Every figure of `grainforge simulate` and `simulate calibrate` names the engine, the population (the inputs'
name, grain count, templates and their representation) and the test's rate, as the commands draw it: run on a
stand-in engine, each figure's text read as it is saved, and the PNG's Description read back."""

from __future__ import annotations

import csv
import json
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image
from test_simulate_calibrate import STAND_IN_TRIAXIAL

from grainforge.cli.main import cli
from grainforge.simulate import Settings, TriaxialSettings
from grainforge.simulate.results import figure_caption

#: a stand-in Yade for the gravity scenes: a tilt record that fails 5° above the contact friction angle, or a
#: 30° cone of small spheres for a repose heap
STAND_IN_GRAVITY = '''
import json, math
import numpy as np
scene = json.load(open("grains.json"))["scene"]
d = 0.002
out = {"test": scene["test"], "grains": scene["grains"], "inserted": scene["grains"], "lost": 0, "d_mean": d,
       "steps": 1000, "time": 1.0, "dt": 1e-5}
if scene["test"] == "tilt":
    fails = scene["friction_deg"] + 5.0
    angles = np.arange(scene["tilt_start_deg"], fails + 2 * scene["tilt_step_deg"], scene["tilt_step_deg"])
    out.update(history=[[a, 0.5 * math.exp(a - fails), 0.0] for a in angles], failure_angle=fails)
else:
    rng = np.random.default_rng(scene["seed"])
    n, foot = 20000, 20 * d
    rad, az = np.sqrt(rng.random(n)) * foot, rng.random(n) * 2 * np.pi
    z = (foot - rad) * math.tan(math.radians(30.0)) * rng.random(n) ** 0.1
    out.update(spheres=np.column_stack([rad * np.cos(az), rad * np.sin(az), z, np.full(n, 0.05 * d)]).tolist(),
               base_top=0.0, settled=True)
print("grainforge-progress 1.0 done", flush=True)
json.dump(out, open("result.json", "w"))
'''


@pytest.fixture
def grains(three_cri_grains):
    return three_cri_grains


@pytest.fixture
def saved_texts(monkeypatch):
    """Every figure the command saves: its file name → all its text (title, caption, labels), read as saved."""
    import matplotlib.text

    import grainforge.io
    import grainforge.simulate.results

    texts = {}
    save = grainforge.io.save_figure

    def capture(fig, path, **kw):
        texts[path.name] = "\n".join(t.get_text() for t in fig.findobj(matplotlib.text.Text))
        return save(fig, path, **kw)

    monkeypatch.setattr(grainforge.io, "save_figure", capture)
    monkeypatch.setattr(grainforge.simulate.results, "save_figure", capture)
    return texts


def _stand_in(tmp_path, monkeypatch, test):
    fake = tmp_path / "stand-in-yade"
    fake.write_text(f"#!{sys.executable}\n" + (STAND_IN_TRIAXIAL if test == "triaxial" else STAND_IN_GRAVITY))
    fake.chmod(0o755)
    monkeypatch.setenv("GRAINFORGE_YADE", str(fake))


def _expected(out, run, test, friction):
    """The parts the caption must name, from what the command wrote: the deck's scene and grains (the clumps'
    sphere counts), templates.csv, results.csv."""
    deck = json.loads((run / "grains.json").read_text())
    scene = deck["scene"]
    spheres = sorted({len(np.loadtxt(run / g["xyzr"], comments="#").reshape(-1, 4)) for g in deck["grains"]})
    chosen = [r for r in csv.DictReader((out / "templates.csv").read_text().splitlines()) if r["template"] != "KS"]
    counts = f"{spheres[0]}" if len(spheres) == 1 else f"{spheres[0]}–{spheres[-1]}"
    parts = ["Yade", f"g: {scene['grains']} grains from {len(chosen)} templates, clumps of {counts} spheres"]
    if friction:
        parts.append(f"μ = {friction:g}")
    if test == "tilt":
        parts.append(f"tilt {scene['tilt_step_deg']:g}° every {scene['tilt_hold']:g} √(d/g) from "
                     f"{scene['tilt_start_deg']:g}°")
    elif test == "repose":
        parts.append(f"cylinder lifted at {scene['lift_speed']:g} √(g d)")
    else:
        rate = json.loads((run / "result.json").read_text())["strain_rate"]
        parts.append(f"sheared at I = {scene['inertial_number']:g} (ε̇ = {rate:.3g}/s)")
    return parts


def _check(text, parts):
    flat = " ".join(text.split())  # the caption wrapped between its parts
    for part in parts:
        assert part in flat, (part, text)


@pytest.mark.parametrize("test", ["tilt", "repose", "triaxial"])
def test_a_simulate_figure_names_the_engine_the_population_and_the_rate(grains, tmp_path, monkeypatch, saved_texts,
                                                                         test):
    _stand_in(tmp_path, monkeypatch, test)
    out = tmp_path / "sim"
    r = CliRunner().invoke(cli, ["simulate", test, str(grains), "--out", str(out), "--quick"])
    assert r.exit_code == 0, r.output
    parts = _expected(out, out / f"{test}-seed0", test, 0.5)
    _check(saved_texts[f"{test}.png"], parts)
    _check(Image.open(out / f"{test}.png").text["Description"], parts)


@pytest.mark.parametrize("test, target", [("tilt", 31.6), ("triaxial", 25.4)])
def test_a_calibration_figure_names_the_engine_the_population_and_the_rate(grains, tmp_path, monkeypatch,
                                                                           saved_texts, test, target):
    """The calibration's runs vary μ: its figure names the rest (the stand-ins reach the target at the start)."""
    _stand_in(tmp_path, monkeypatch, test)
    out = tmp_path / "cal"
    r = CliRunner().invoke(cli, ["simulate", "calibrate", test, str(grains), "--out", str(out), "--quick",
                                 "--target-angle", str(target)])
    assert r.exit_code == 0, r.output
    run = next((out / "runs").iterdir()) / f"{test}-seed0"
    parts = _expected(out, run, test, None)
    _check(saved_texts["calibration.png"], parts)
    description = Image.open(out / "calibration.png").text["Description"]
    _check(description, parts)
    assert "μ =" not in description


def _templates(shape="clump", spheres=(6,)):
    return [SimpleNamespace(shape=shape, clump=SimpleNamespace(radii=np.ones(n)) if shape == "clump" else None)
            for n in spheres]


@pytest.mark.parametrize("kw, expected", [
    (dict(test="repose", engine="liggghts", mpi=2), ["LIGGGHTS, 2 MPI ranks", "cylinder removed at once"]),
    (dict(test="repose"), ["Yade", "cylinder lifted at 0.5 √(g d)"]),
    (dict(test="tilt", templates=_templates(spheres=(4, 9, 6))), ["3 templates, clumps of 4–9 spheres"]),
    (dict(test="tilt", templates=_templates(spheres=(1, 1))), ["2 templates, one sphere a grain"]),
    (dict(test="tilt", templates=_templates("levelset", (0,)), spacing=0.1), ["1 template, level sets (grid 0.1 d)"]),
    (dict(test="triaxial"), ["sheared at I = 0.001"]),
])
def test_the_caption_names_each_engine_representation_and_rate(kw, expected):
    test = kw.pop("test")
    settings = TriaxialSettings() if test == "triaxial" else Settings()
    caption = figure_caption(test, settings, templates=kw.pop("templates", _templates()), label="sand", **kw)
    for part in expected:
        assert part in caption, (part, caption)
    assert caption.startswith(("Yade · sand: 200 grains", "LIGGGHTS, 2 MPI ranks · sand: 200 grains"))


def test_a_run_of_a_minute_or_less_says_its_estimate_once_its_grains_are_made(grains, tmp_path, monkeypatch):
    """A quick tilt (estimated at 10 s to a minute) says its estimate on stderr after the templates' line, before
    the engine runs; a calibration says its usual time and its longest (all --max-frictions)."""
    import re

    _stand_in(tmp_path, monkeypatch, "tilt")
    r = CliRunner().invoke(cli, ["simulate", "tilt", str(grains), "--out", str(tmp_path / "s"),
                                                 "--quick"])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()  # stdout and stderr as they came
    said = [k for k, ln in enumerate(lines) if ln.startswith("estimated time: about ")]
    assert len(said) == 1 and lines[said[0]] in r.stderr, r.output
    assert any(ln.startswith("templates: ") for ln in lines[:said[0]]), r.output
    seconds = float(re.match(r"estimated time: about ([\d.]+) s", lines[said[0]]).group(1))
    assert 10 <= seconds <= 60
    cal = CliRunner().invoke(cli, ["simulate", "calibrate", "tilt", str(grains), "--out",
                                                   str(tmp_path / "c"), "--quick", "--target-angle", "31.6"])
    assert cal.exit_code == 0, cal.output
    line = next(ln for ln in cal.stderr.splitlines() if ln.startswith("estimated time: "))
    usual, most = re.match(r"estimated time: about ([\d.]+) (?:s|min) \(at most ([\d.]+) (?:s|min);", line).groups()
    assert float(most) > float(usual) or "min" in line.split("(at most")[1]
