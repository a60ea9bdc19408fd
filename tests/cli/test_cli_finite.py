"""Every float option of the command line refuses ``nan``, ``inf`` and ``-inf`` up front.

The test walks the click command tree (:data:`grainforge.cli.main.cli`, subgroups included: ``generate fso``,
``simulate calibrate``, ...) and finds every option whose type holds floats: click's float types
(``FiniteFloatRange``, ``FiniteFloat``, the plain ``float`` of the options made from a parameter dataclass),
comma-separated lists of numbers (``FloatList``) and tuples of floats (``--friction-range``).  For each such
option and each of ``nan``, ``inf`` and ``-inf`` it runs the command in-process (click's ``CliRunner``) with
the command's minimal valid invocation from :data:`INVOCATIONS` plus that option, in a fresh folder, and
asserts: exit code 2, one line on stderr that names the option, no traceback, nothing written (the folder
and the shared inputs unchanged).

The time budget is lowered to nothing (:data:`grainforge.runtime.estimate.SECONDS_LIMIT` = 0) and the DEM engines are
stand-ins (``GRAINFORGE_YADE=true``), so a value that slipped through would be refused by the budget (a line
that does not name the option: the test fails) instead of starting a long run.

A new command with a float option needs a row in :data:`INVOCATIONS`
(:func:`test_every_command_with_a_float_option_has_an_invocation` says which).

Run: ``.venv/bin/python -m pytest tests/cli/test_cli_finite.py -q``.
"""

from __future__ import annotations

from pathlib import Path

import click
import pytest

from grainforge.cli.main import cli
from grainforge.cli.options import FiniteFloat, FloatList

ROOT = Path(__file__).resolve().parents[2]
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"
BAD = ("nan", "inf", "-inf")

#: the smallest invocation of each command that would run (``{in}``: the shared inputs); the option under
#: test is appended (click keeps the last value of an option given twice, e.g. fit's --voxel-size-um)
INVOCATIONS: dict[str, list[str]] = {
    "analyse": ["analyse", "{in}/grain.stl", "--csv", "out/a.csv"],
    "dem": ["dem", "{in}/grain.stl", "--out", "out"],
    "fit": ["fit", str(OTTAWA), "--voxel-size-um", "7.3", "--out", "out"],
    "fourier": ["fourier", "{in}/grain.png", "--csv", "out/f.csv"],
    "scan": ["scan", "{in}/labels.npy", "--voxel-size-um", "10", "--atlas-csv", "out/s.csv"],
    "tray": ["tray", "--method", "fso", "--out", "out/t.3mf"],
    **{f"generate {m}": ["generate", m, "--out", "out"] for m in ("angular", "cri", "dpa", "fso", "rf")},
    **{f"simulate {t}": ["simulate", t, "{in}/grain.stl", "--out", "out"] for t in ("repose", "tilt", "triaxial")},
    "simulate calibrate": ["simulate", "calibrate", "tilt", "{in}/grain.stl", "--target-angle", "30", "--out", "out"],
}

#: options that only apply with another option (given too, so the value is the only thing wrong); not for
#: ``simulate triaxial``, whose scene takes no level set (its --spacing is refused as such)
REQUIRES: dict[str, list[str]] = {
    "--spacing": ["--shape", "levelset"],
    "--marker-distance": ["--segment"],
    "--marker-depth": ["--segment"],
}
NO_REQUIRES = {("simulate triaxial", "--spacing")}

#: (command, option, value) known to get through click, with why: none today. An entry marks its case as a strict
#: xfail, so that the fix shows as an unexpected pass and the entry is removed
KNOWN: dict[tuple[str, str, str], str] = {}


def _commands(group: click.Group = cli, path: tuple[str, ...] = ()):
    for name, cmd in sorted(group.commands.items()):
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, path + (name,))
        else:
            yield " ".join(path + (name,)), cmd


def _holds_floats(t: click.ParamType) -> bool:
    if isinstance(t, click.Tuple):
        return any(_holds_floats(u) for u in t.types)
    return isinstance(t, (click.types.FloatParamType, FiniteFloat, FloatList))


def _float_options(cmd: click.Command) -> list[click.Option]:
    return [p for p in cmd.params if isinstance(p, click.Option) and not p.hidden and _holds_floats(p.type)]


def _values(command: str, option: click.Option, bad: str) -> list[str]:
    """The words after the option's name: ``bad`` where a number goes, valid numbers elsewhere."""
    t = option.type
    if isinstance(t, click.Tuple):  # e.g. --friction-range LOW HIGH
        return [bad] + ["1.0"] * (len(t.types) - 1)
    if isinstance(t, FloatList):  # the parameter's default with its first number replaced
        from grainforge.methods import get
        from grainforge.params import specs

        method = command.split()[-1]
        default = next(s.default for s in specs(get(method).Params) if s.option == option.opts[0]) or (1.0,)
        return [",".join([bad] + [repr(float(x)) for x in tuple(default)[1:]])]
    return [bad]


COMMANDS = dict(_commands())
CASES = [
    pytest.param(command, option.opts[0], bad,
                 id=f"{command} {option.opts[0]} {bad}",
                 marks=[pytest.mark.xfail(strict=True, reason=KNOWN[(command, option.opts[0], bad)])]
                 if (command, option.opts[0], bad) in KNOWN else [])
    for command, cmd in COMMANDS.items()
    for option in _float_options(cmd)
    for bad in BAD
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Tiny inputs every invocation may read (never written): a grain, a grain image, a labelled 3D image."""
    import numpy as np
    from PIL import Image

    import grainforge
    from grainforge.io import write_mesh
    from grainforge.outline.contours import Contour
    from grainforge.outline.imaging import draw_contours

    d = tmp_path_factory.mktemp("finite-inputs")
    write_mesh(grainforge.fso(subdivisions=2, rng=0), d / "grain.stl")
    img = draw_contours((160, 160), [(Contour.from_descriptors("rough-sphere", rng=0), (80, 80), 50.0)])
    Image.fromarray(img).save(d / "grain.png")
    z, y, x = np.indices((12, 12, 24))
    labels = np.zeros(z.shape, np.uint16)
    for k, cx in ((1, 6), (2, 17)):
        labels[((z - 6) ** 2 + (y - 6) ** 2 + (x - cx) ** 2) < 16] = k
    np.save(d / "labels.npy", labels)
    return d


def _snapshot(*folders: Path) -> set[str]:
    return {str(p) for f in folders for p in f.rglob("*")}


def test_the_walk_finds_the_float_options():
    found = {(c, o.opts[0]) for c, cmd in COMMANDS.items() for o in _float_options(cmd)}
    assert {("fit", "--max-minutes"), ("fourier", "--threshold"), ("generate fso", "--amplitude"),
            ("generate cri", "--decay"), ("simulate calibrate", "--friction-range"),
            ("simulate calibrate", "--target-angle"), ("dem", "--clump-accuracy")} <= found
    assert len(CASES) == 3 * len(found)


def test_every_command_with_a_float_option_has_an_invocation():
    assert {c for c, cmd in COMMANDS.items() if _float_options(cmd)} <= set(INVOCATIONS)


@pytest.mark.parametrize("command, option, bad", CASES)
def test_non_finite_value_is_refused_in_one_line(command, option, bad, inputs, tmp_path, monkeypatch):
    from click.testing import CliRunner

    import grainforge.runtime.estimate as estimate

    opt = next(o for o in _float_options(COMMANDS[command]) if o.opts[0] == option)
    args = [a.replace("{in}", str(inputs)) for a in INVOCATIONS[command]]
    if (command, option) not in NO_REQUIRES:
        args += REQUIRES.get(option, [])
    args += [option, *_values(command, opt, bad)]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(estimate, "SECONDS_LIMIT", 0.0)  # a value that slipped through does no work
    for engine in ("YADE", "LIGGGHTS", "MPIRUN"):
        monkeypatch.setenv(f"GRAINFORGE_{engine}", "true")
    before = _snapshot(tmp_path, inputs)
    r = CliRunner().invoke(cli, args)
    err = r.stderr
    assert "Traceback" not in err, err
    assert r.exit_code == 2, f"grainforge {' '.join(args)}: exit {r.exit_code}\n{err}{r.exception!r}"
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"grainforge {' '.join(args)}: {len(lines)} lines on stderr:\n{err}"
    assert option in lines[0], f"the line does not name {option}: {lines[0]}"
    assert _snapshot(tmp_path, inputs) == before
