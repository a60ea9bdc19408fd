"""The CLI contract of ``grainforge fit`` and ``grainforge simulate``, case by case.

Every row of :data:`CASES` runs the command *in-process* (click's
``CliRunner``: no interpreter start per row) in a fresh folder and asserts
the contract as ``tests/cli/test_cli_contract.py`` does: the exit code, exactly
one line on stderr matching ``err``, no ``Traceback``, and no file or folder
appearing or disappearing in the case folder or the shared inputs.  The
refusals that come after the Yade check run with ``GRAINFORGE_YADE=true``
(any executable passes the check), so they need no Yade.

Two hypothesis tests draw ``fit`` and ``simulate`` options from their
declared ranges (read from the click commands themselves), with the time
budget lowered to nothing (:data:`grainforge.runtime.estimate.SECONDS_LIMIT` = 0):
every request, valid or not, must then be refused up front in one line,
before any heavy work.

Signals need real processes: the ``test_signal_*`` functions at the end
start the command as a subprocess, in its own session (marked slow: the
full suite runs them, the fast lane does not).  Before Yade starts
(the first second or two: imports, checks, clump templates) a stand-in
``yade`` that only sleeps keeps the command waiting, so a signal that were
ignored would show as a run that goes on; while Yade runs, the real engine
(skipped without it, failed with ``GRAINFORGE_REQUIRE_ENGINES=1``).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import click
import pytest
from _processes import kill_sessions, session_processes
from conftest import refused_in_one_line, require_engine
from hypothesis import given, settings
from hypothesis import strategies as st

from grainforge.cli.main import cli

ROOT = Path(__file__).resolve().parents[2]
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"


@dataclass
class Case:
    """One invocation (``{in}`` is the shared inputs folder) and what it must do."""

    id: str
    args: list[str]
    err: str
    code: int = 2
    lines: int = 1


def _sand_rows():
    lines = OTTAWA.read_text(encoding="utf-8").splitlines()
    return lines[0], lines[1:]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Sand tables, a folder of 3 angular grains and recipes; made once, never written by a case."""
    from grainforge.methods import get
    from grainforge.population.generate import write_run

    d = tmp_path_factory.mktemp("inputs")
    header, rows = _sand_rows()
    # 700 copies of one grain, each under its own Particle ID (a repeated ID is refused on its own)
    same = [f"{k}," + rows[0].split(",", 1)[1] for k in range(1, 701)]
    (d / "same.csv").write_text("\n".join([header] + same) + "\n", encoding="utf-8")
    (d / "two.csv").write_text("\n".join([header] + rows[:2]) + "\n", encoding="utf-8")
    (d / "few.csv").write_text("\n".join([header] + rows[:49]) + "\n", encoding="utf-8")
    (d / "fifty.csv").write_text("\n".join([header] + rows[:50]) + "\n", encoding="utf-8")
    col = header.split(",").index("True Sphericity (-)")
    bad = rows[0].split(",")
    bad[col] = "5.0"
    (d / "sph5.csv").write_text("\n".join([header, ",".join(bad)] + rows[1:100]) + "\n", encoding="utf-8")
    same_shape = []
    for r in rows[:100]:  # sizes vary, every sphericity the same
        cells = r.split(",")
        cells[col] = "0.9"
        same_shape.append(",".join(cells))
    (d / "same-sphericity.csv").write_text("\n".join([header] + same_shape) + "\n", encoding="utf-8")
    (d / "empty.csv").write_text("", encoding="utf-8")
    write_run("angular", get("angular").Params(subdivisions=3), seeds=[0, 1, 2], out=d / "ang", size=2.0)
    (d / "nogrinit").mkdir()
    recipe = 'method = "fso"\ncount = {count}\nseed = 1\n[params]\nsubdivisions = 2\n[size]\nmm = 1.0\n'
    (d / "huge.toml").write_text(recipe.format(count=2**63 - 1), encoding="utf-8")
    (d / "bad.toml").write_text("method = = 3\n", encoding="utf-8")
    return d


def _fit(*extra):
    return ["fit", f"{OTTAWA}", "--out", "o", *extra]


def _sim(test, *extra):
    return ["simulate", test, "{in}/ang", "--out", "o", *extra]


HUGE_SIM = ["--grains", "20000", "--templates", "20000", "--spheres", "200", "--seeds", "100"]

CASES = [
    # fit: tables that cannot be fitted
    Case("fit-700-identical-grains", ["fit", "{in}/same.csv", "--voxel-size-um", "7.3", "--out", "o", "--workers", "2"],
         r"same\.csv: every grain has the same equivalent diameter"),
    Case("fit-identical-sphericity", ["fit", "{in}/same-sphericity.csv", "--voxel-size-um", "7.3", "--out", "o"],
         r"same-sphericity\.csv: every grain has the same sphericity"),
    Case("fit-2-grains", ["fit", "{in}/two.csv", "--voxel-size-um", "7.3", "--out", "o"],
         r"two\.csv: 2 grain\(s\); a fit needs at least 50"),
    Case("fit-49-grains", ["fit", "{in}/few.csv", "--voxel-size-um", "7.3", "--out", "o"], r"few\.csv: 49 grain"),
    Case("fit-sphericity-5", ["fit", "{in}/sph5.csv", "--voxel-size-um", "7.3", "--out", "o"],
         r"sph5\.csv: line 2, column 'True Sphericity \(-\)': out of range \(at most 1\.2\): '5\.0'"),
    Case("fit-empty-table", ["fit", "{in}/empty.csv", "--voxel-size-um", "7.3", "--out", "o"], r"empty\.csv: empty"),
    Case("fit-missing-table", ["fit", "{in}/nope.csv", "--voxel-size-um", "7.3", "--out", "o"], r"nope\.csv"),
    # fit: voxel sizes (µm) that put the grains outside 5 to 1000 voxels across
    *[Case(f"fit-voxel-size-{v}", _fit("--voxel-size-um", v),
           r"ottawa-7\.3um\.csv: at a voxel size of .* voxels across; the fit measures grains 5 to 1000")
      for v in ("1e-30", "1e30", "1e6", "0.001", "0.4", "200")],
    *[Case(f"fit-voxel-size-{v}", _fit("--voxel-size-um", v), r"voxel.size") for v in ("nan", "inf", "0", "-1")],
    # the same voxel size in mm (--voxel-size-mm, as analyse and scan take it too)
    *[Case(f"fit-voxel-size-mm-{v}", _fit("--voxel-size-mm", v),
           r"ottawa-7\.3um\.csv: at a voxel size of .* voxels across; the fit measures grains 5 to 1000")
      for v in ("1e-33", "1e3")],
    Case("fit-voxel-size-um-and-mm", _fit("--voxel-size-um", "7.3", "--voxel-size-mm", "0.0073"),
         r"give --voxel-size-um or --voxel-size-mm, not both"),
    # fit: huge work refused up front, by the declared range or the estimate
    Case("fit-count-1e9", _fit("--voxel-size-um", "7.3", "--count", "1000000000"), r"--count.*not in the range"),
    Case("fit-design-grains-1e9", _fit("--voxel-size-um", "7.3", "--design-grains", "1000000000"),
         r"--design-grains.*not in the range"),
    Case("fit-auto-count-1e8", _fit("--voxel-size-um", "7.3", "--method", "auto", "--count", "100000000"),
         r"--count.*not in the range"),
    Case("fit-count-1e6", _fit("--voxel-size-um", "7.3", "--count", "1000000", "--workers", "1"),
         r"fit --method rf, measuring up to \d+ grains, would take about .* days? .*; lower --count"),
    Case("fit-auto-count-1e4", _fit("--voxel-size-um", "7.3", "--method", "auto", "--count", "10000", "--workers", "1"),
         r"fit --method auto would take about .* over --max-minutes 60: raise --max-minutes, lower --count or fit "
         r"one --method"),
    # fit: over the --max-minutes budget, or a resolution measured uncapped, refused up front saying what to change
    Case("fit-over-budget", _fit("--voxel-size-um", "7.3", "--count", "20000", "--workers", "1", "--max-minutes", "5"),
         r"fit --method rf would take about .* over --max-minutes 5: raise --max-minutes, lower --count or "
         r"--max-voxels-across \(now 150\)"),
    Case("fit-uncapped-1.3um", _fit("--voxel-size-um", "1.3", "--max-voxels-across", "0", "--workers", "1"),
         r"fit --method rf would take about .* h on 1 core.* voxels across\), over --max-minutes 60: raise "
         r"--max-minutes, lower --count or set --max-voxels-across \(e\.g\. 150\)"),
    Case("fit-workers-1000", _fit("--voxel-size-um", "7.3", "--workers", "1000"), r"--workers.*not in the range"),
    Case("fit-refine-minus-1", _fit("--voxel-size-um", "7.3", "--refine", "-1"), r"--refine"),
    Case("fit-method-nope", _fit("--voxel-size-um", "7.3", "--method", "nope"), r"--method"),
    # simulate: huge work refused up front with the estimate
    Case("simulate-repose-huge", _sim("repose", *HUGE_SIM),
         r"100 repose run\(s\) of 20000 grains of 200 sphere\(s\) .*would take about .*; lower --grains, --spheres "
         r"or --seeds"),
    Case("simulate-tilt-huge", _sim("tilt", *HUGE_SIM), r"100 tilt run\(s\) .*would take about"),
    Case("simulate-triaxial-huge", _sim("triaxial", *HUGE_SIM), r"100 triaxial run\(s\) .*would take about"),
    Case("simulate-triaxial-slow", _sim("triaxial", "--grains", "2000", "--inertial-number", "1e-6"),
         r"3 triaxial run\(s\) of 2000 grains .*would take about"),
    # simulate triaxial: a confining stress, an axial strain or a specimen no periodic test takes
    *[Case(f"simulate-triaxial-{'-'.join(a)}", _sim("triaxial", *a), message)
      for a, message in ((["--confining-kpa", "0"], r"--confining-kpa"), (["--confining-kpa", "1e5"], r"--confining-kpa"),
                         (["--axial-strain", "1"], r"--axial-strain"), (["--packing", "medium"], r"--packing"),
                         (["--grains", "50"], r"--grains 50: a periodic triaxial cell needs --grains ≥ 79"))],
    Case("simulate-recipe-count-2**63-1", ["simulate", "repose", "{in}/huge.toml", "--quick", "--out", "o"],
         r"huge\.toml: 9223372036854775807 fso grains would take about .*; lower count"),
    # simulate: bad options and inputs
    *[Case(f"simulate-{'-'.join(a)}", _sim("repose", *a), re.escape(a[0]))
      for a in (["--grains", "20001"], ["--grains", "1"], ["--seeds", "101"], ["--spheres", "0"],
                ["--templates", "0"], ["--friction", "nan"], ["--size", "0"], ["--workers", "0"],
                ["--workers", "1000"])],
    # --spheres: one range, 2-1000, in every command that makes clumps (dem's rows: tests/dem/test_dem_limits.py)
    *[Case(f"simulate-{'-'.join(cmd)}-spheres-{n}", ["simulate", *cmd, "{in}/ang", "--out", "o", *extra, "--spheres", n],
           r"'--spheres': must be in \[2, 1000\], got " + n)
      for cmd, extra in ((["repose"], []), (["tilt"], []), (["triaxial"], []),
                         (["calibrate", "tilt"], ["--target-angle", "30"]),
                         (["calibrate", "triaxial"], ["--target-angle", "30"]))
      for n in ("1", "1001")],
    # simulate: engine, MPI and representation combinations no scene runs
    Case("simulate-mpi-with-yade", _sim("repose", "--mpi", "2"), r"--mpi: yade runs one process per seed"),
    Case("simulate-liggghts-mpi-0", _sim("tilt", "--engine", "liggghts", "--mpi", "0"), r"--mpi"),
    Case("simulate-liggghts-mpi-5000", _sim("tilt", "--engine", "liggghts", "--mpi", "5000"), r"--mpi"),
    Case("simulate-liggghts-levelset", _sim("repose", "--engine", "liggghts", "--shape", "levelset"),
         r"--shape levelset: simulate's liggghts scenes take --shape clump only"),
    Case("simulate-liggghts-huge", _sim("repose", "--engine", "liggghts", "--mpi", "2", *HUGE_SIM),
         r"would take about"),
    Case("simulate-missing-input", ["simulate", "repose", "{in}/nothing", "--out", "o"], r"nothing"),
    # simulate calibrate: a target out of range, a calibration beyond a day, an unknown test
    Case("simulate-calibrate-target-85", ["simulate", "calibrate", "tilt", "{in}/ang", "--target-angle", "85",
                                          "--out", "o"], r"target angle 85° is outside 5–80°"),
    Case("simulate-calibrate-huge", ["simulate", "calibrate", "tilt", "{in}/ang", "--target-angle", "30", "--out",
                                     "o", "--grains", "20000", "--seeds", "30", "--workers", "1"],
         r"(calibration of up to 8 frictions|tilt run\(s\) of 20000 grains).*would take about"),
    Case("simulate-calibrate-shear", ["simulate", "calibrate", "shear", "{in}/ang", "--target-angle", "30",
                                      "--out", "o"], r"shear"),
    Case("simulate-empty-folder", ["simulate", "tilt", "{in}/nogrinit", "--out", "o"], r"no grain files"),
    Case("simulate-bad-recipe", ["simulate", "tilt", "{in}/bad.toml", "--out", "o"], r"bad\.toml"),
    Case("simulate-out-is-a-file", _sim("repose")[:-1] + ["afile"], r"afile'? is a file"),
    Case("simulate-existing-results", _sim("repose")[:-1] + ["done"], r"exists.*--overwrite"),
    Case("fit-existing-outputs", ["fit", str(OTTAWA), "--voxel-size-um", "7.3", "--out", "done"], r"exists.*--overwrite"),
]


def _snapshot(*folders: Path) -> set[str]:
    return {str(p) for f in folders for p in f.rglob("*")}


@pytest.fixture
def case_dir(tmp_path, monkeypatch):
    """A fresh folder as the working directory, holding ``afile`` and ``done/`` (earlier outputs)."""
    (tmp_path / "afile").write_text("a file\n")
    (tmp_path / "done").mkdir()
    for name in ("results.csv", "fit.csv"):
        (tmp_path / "done" / name).write_text("old\n")
    monkeypatch.chdir(tmp_path)
    for engine in ("YADE", "LIGGGHTS", "MPIRUN"):  # pass the engine checks; never run by a refused case
        monkeypatch.setenv(f"GRAINFORGE_{engine}", "true")
    return tmp_path


def _invoke(args):
    from click.testing import CliRunner

    return CliRunner().invoke(cli, args)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_cli_contract_fit_simulate(case: Case, case_dir, inputs):
    before = _snapshot(case_dir, inputs)
    r = _invoke([a.replace("{in}", str(inputs)) for a in case.args])
    err = r.stderr
    assert "Traceback" not in err, err
    assert r.exception is None or isinstance(r.exception, SystemExit), (err, r.exception)
    assert r.exit_code == case.code, f"exit {r.exit_code}; stderr:\n{err}"
    assert len(err.strip().splitlines()) == case.lines, f"expected {case.lines} line(s) on stderr:\n{err}"
    assert re.search(case.err, err), f"stderr does not match {case.err!r}:\n{err}"
    assert _snapshot(case_dir, inputs) == before


def test_spheres_has_one_range_in_every_command():
    """``--spheres`` of ``dem``, ``simulate TEST`` and ``simulate calibrate TEST``: the same declared range
    (:data:`grainforge.cli.options.SPHERES_RANGE`, the simulation settings' own declaration alike), stated in each
    command's help."""
    from click.testing import CliRunner

    from grainforge.cli.options import SPHERES_RANGE
    from grainforge.params import specs
    from grainforge.simulate.settings import GrainSettings

    spec = next(s for s in specs(GrainSettings) if s.name == "spheres")
    assert (spec.low, spec.high) == SPHERES_RANGE == (2, 1000)
    dem = next(p for p in cli.commands["dem"].params if p.name == "spheres")
    assert (dem.type.min, dem.type.max) == SPHERES_RANGE
    for command in (["dem"], ["simulate", "repose"], ["simulate", "tilt"], ["simulate", "triaxial"],
                    ["simulate", "calibrate", "tilt"]):
        out = CliRunner().invoke(cli, [*command, "--help"]).output
        text = " ".join(re.search(r"\n  --spheres (.*?)\n  -", out, re.S).group(1).split())
        assert "range: [2, 1000]" in text, (command, text)


class _Accepted(SystemExit):
    """Raised where a command has passed every check and would start its work (``ready_for_work``): a SystemExit,
    which the command group lets through as it is (any other exception would be reported as a bug, exit 1)."""

    def __init__(self):
        super().__init__(99)


#: MPI refusals whose line suggests another command: (test words, options, batch allocation or None)
MPI_REFUSALS = [
    (["triaxial"], ["--mpi", "3"], None),  # beyond 2 cores, and slabs too thin for 200 grains
    (["triaxial"], ["--mpi", "64"], "64"),  # slabs too thin for 200 grains, 64 ranks allocated
    (["triaxial"], ["--mpi", "27", "--grains", "100"], "27"),
    (["triaxial"], ["--mpi", "100"], "64"),  # beyond the allocation, and slabs too thin
    (["triaxial"], ["--mpi", "2", "--workers", "2"], None),
    (["repose"], ["--mpi", "3"], None),
    (["calibrate", "triaxial"], ["--target-angle", "30", "--mpi", "3"], None),
    (["calibrate", "triaxial"], ["--target-angle", "30", "--mpi", "64"], "64"),
]


def _suggestions(args: list[str], line: str) -> list[list[str]]:
    """The commands a refusal's line suggests: ``use --mpi N`` and ``--grains G or more``, each in place of the
    refused option in ``args`` (``fewer --workers``: without ``--workers``)."""
    def replaced(option: str, value: str | None) -> list[str]:
        out, skip = [], False
        for a in args:
            if skip:
                skip = False
                continue
            if a == option:
                skip = True
                continue
            out.append(a)
        return out + ([option, value] if value is not None else [])

    found = [replaced("--mpi", m) for m in re.findall(r"use --mpi (\d+)", line)]
    found += [replaced("--grains", g) for g in re.findall(r"--grains (\d+) or more", line)]
    if "fewer --workers" in line:
        found.append(replaced("--workers", None))
    return found


@pytest.mark.parametrize("test, options, allocation", MPI_REFUSALS,
                         ids=["-".join(t + o + ([f"slots{a}"] if a else [])) for t, o, a in MPI_REFUSALS])
def test_an_mpi_refusal_suggests_only_commands_that_are_accepted(test, options, allocation, case_dir, inputs,
                                                                  monkeypatch):
    """``simulate --engine liggghts --mpi N`` refused (beyond the cores or the allocation, or a triaxial specimen
    too small for N ranks' slabs): every command its line suggests (``--mpi M``, ``--grains G``, fewer
    ``--workers``) passes every check on the same machine, up to the start of the work, where the test stops it."""
    import grainforge.cli.work as work

    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})  # a 2-core machine
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    for name in ("SLURM_NTASKS", "SLURM_NPROCS", "PBS_NP", "NSLOTS", "LSB_DJOB_NUMPROC", "PBS_NODEFILE"):
        monkeypatch.delenv(name, raising=False)
    if allocation:
        monkeypatch.setenv("SLURM_NTASKS", allocation)

    def accepted(*args, **kwargs):
        raise _Accepted()

    monkeypatch.setattr(work, "ready_for_work", accepted)
    args = ["simulate", *test, str(inputs / "ang"), "--out", "o", "--engine", "liggghts", *options]
    r = _invoke(args)
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 2 and len(lines) == 1 and "--mpi" in lines[0], r.stderr
    suggested = _suggestions(args, lines[0])
    assert suggested, lines[0]
    for command in suggested:
        again = _invoke(command)
        assert isinstance(again.exception, _Accepted), (lines[0], command, again.stderr)
    assert not (case_dir / "o").exists()


def test_errors_of_workers_cross_the_process_pool():
    """A worker's RecipeError or ParameterError reaches the command as itself (it pickles), not as a
    BrokenProcessPool."""
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    from grainforge.params import ParameterError
    from grainforge.population import RecipeError

    for exc in (RecipeError("<fit>", "size.sieves_mm", "must be a list", 13), ParameterError("amplitude", "too big")):
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is type(exc) and str(back) == str(exc) and back.__dict__ == exc.__dict__
    import multiprocessing

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        with pytest.raises(RecipeError, match=r"<fit>:13: size\.sieves_mm"):
            pool.submit(_raise_recipe_error).result()


def _raise_recipe_error():
    from grainforge.population import RecipeError

    raise RecipeError("<fit>", "size.sieves_mm", "must be a list", 13)


# --------------------------------------------------------------------------- fuzz: declared ranges, no budget

def _range_strategy(kind: str, lo, hi, lo_open=False, hi_open=False):
    """Values inside [lo, hi] (twice as likely) or just outside it."""
    if kind == "int":
        lo = int(lo) if lo is not None else -10
        hi = int(hi) if hi is not None else 10**12
        return st.one_of(st.integers(lo, hi), st.integers(lo, hi), st.sampled_from([lo - 1, hi + 1]))
    lo = float(lo) if lo is not None else -1e30
    hi = float(hi) if hi is not None else 1e30
    inside = st.floats(lo, hi, allow_nan=False, exclude_min=lo_open, exclude_max=hi_open)
    return st.one_of(inside, inside, st.sampled_from([lo - 1.0, hi * 2 + 1.0, float("nan")]))


def _option_values(command: click.Command, settings_cls=None, skip=()) -> dict:
    """A strategy per numeric option of ``command``, from its declared range: click's, or for the options
    made from a settings class, the range of the parameter (:func:`grainforge.params.specs`)."""
    from grainforge.params import specs

    declared = {s.option: s for s in specs(settings_cls)} if settings_cls is not None else {}
    out = {}
    for p in command.params:
        if not isinstance(p, click.Option) or p.name in skip or p.is_flag:
            continue
        t, opt = p.type, p.opts[0]
        if isinstance(t, click.IntRange):
            out[opt] = _range_strategy("int", t.min, t.max)
        elif isinstance(t, click.FloatRange):
            out[opt] = _range_strategy("float", t.min, t.max, t.min_open, t.max_open)
        elif opt in declared and declared[opt].kind in ("int", "float"):
            s = declared[opt]
            out[opt] = _range_strategy(s.kind, s.low, s.high, s.low_open, s.high_open)
    return out


def _draw_args(data, strategies: dict) -> list[str]:
    args = []
    for opt, strategy in strategies.items():
        if data.draw(st.booleans(), label=f"give {opt}"):
            args += [opt, str(data.draw(strategy, label=opt))]
    return args


def _refused_in_one_line(args: list[str], cwd: Path) -> None:
    import grainforge.runtime.estimate as estimate

    before = _snapshot(cwd)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(estimate, "SECONDS_LIMIT", 0.0)  # no budget: every request is refused before any work
        mp.setenv("GRAINFORGE_YADE", "true")
        mp.chdir(cwd)
        r = _invoke(args)
    assert r.exit_code == 2, f"grainforge {' '.join(args)}: exit {r.exit_code}\n{r.stderr}{r.exception!r}"
    refused_in_one_line(r)
    assert _snapshot(cwd) == before


@settings(max_examples=20)
@given(data=st.data())
def test_fuzz_fit_options_are_refused_up_front_without_a_budget(data, tmp_path_factory):
    from grainforge.cli.fit import fit
    from grainforge.fit import FITS

    cwd = tmp_path_factory.mktemp("fuzz-fit")
    args = ["fit", str(OTTAWA), "--out", "o", "--voxel-size-um", str(data.draw(st.one_of(
        st.just(7.3), st.floats(1e-40, 1e40), st.sampled_from(["0", "-1", "nan", "inf"])), label="voxel"))]
    args += ["--method", data.draw(st.sampled_from(list(FITS) + ["auto"]), label="method")]
    strategies = _option_values(fit, skip=("voxel_size",))
    assert {"--count", "--refine", "--design-grains", "--max-voxels-across", "--max-minutes", "--workers"} <= set(strategies)
    args += _draw_args(data, strategies)
    _refused_in_one_line(args, cwd)


@settings(max_examples=20)
@given(data=st.data())
def test_fuzz_simulate_options_are_refused_up_front_without_a_budget(data, tmp_path_factory):
    from grainforge.cli.simulate import repose
    from grainforge.simulate import Settings

    inputs = tmp_path_factory.getbasetemp() / "fuzz-ang"
    if not inputs.exists():
        from grainforge.methods import get
        from grainforge.population.generate import write_run

        write_run("angular", get("angular").Params(subdivisions=2), seeds=[0, 1], out=inputs, size=2.0)
    cwd = tmp_path_factory.mktemp("fuzz-sim")
    test = data.draw(st.sampled_from(["repose", "tilt"]), label="test")
    args = ["simulate", test, str(inputs), "--out", "o"]
    for flag in ("--quick", "--as-spheres"):
        if data.draw(st.booleans(), label=flag):
            args.append(flag)
    strategies = _option_values(repose, Settings)
    assert {"--grains", "--spheres", "--seeds", "--templates", "--friction", "--workers"} <= set(strategies)
    args += _draw_args(data, strategies)
    _refused_in_one_line(args, cwd)


# --------------------------------------------------------------------------- signals (real processes)

CLI = [sys.executable, "-c", "from grainforge.cli.main import main; main()"]


def _processes_in(folder: Path) -> list[int]:
    """Processes (not zombies) whose working directory is inside ``folder`` (Yade runs in its deck)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cwd = os.readlink(entry / "cwd")
                state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if cwd.startswith(str(folder) + os.sep) and state not in ("Z", "X"):
                pids.append(int(entry.name))
    return pids


_STARTED: list[subprocess.Popen] = []


@pytest.fixture(autouse=True)
def _no_strays():
    yield
    kill_sessions(_STARTED)


def _start(args: list[str], cwd: Path, **env) -> subprocess.Popen:
    def preexec():
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # as a foreground job of a terminal's shell

    proc = subprocess.Popen(CLI + args, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True, preexec_fn=preexec,
                            env=dict(os.environ, COLUMNS="200", **env))
    _STARTED.append(proc)
    return proc


def _assert_gone(pids_of, grace: float = 5.0) -> None:
    deadline = time.monotonic() + grace
    while (left := pids_of()) and time.monotonic() < deadline:
        time.sleep(0.1)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not left, f"processes left behind: {left}"


def _stopped(proc: subprocess.Popen, sig: int) -> str:
    """Wait for the command after ``sig``; assert the code, the one line and no process left."""
    try:
        _, err = proc.communicate(timeout=60)  # a hang guard, not a timing assertion
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the command still ran 60 s after the signal")
    err = err.decode("utf-8", "replace")
    assert proc.returncode == 128 + sig and "Traceback" not in err, (proc.returncode, err)
    # the command's own report lines may come first (a fit says its estimate as soon as its checks
    # pass: within 1.5 s on an idle machine); the signal's line is the last, and nothing is an error
    lines = err.strip().splitlines()
    assert lines and lines[-1] == ("Interrupted." if sig == signal.SIGINT else "Terminated."), err
    assert not any(ln.startswith(("Error", "Traceback")) for ln in lines), err
    _assert_gone(lambda: session_processes(proc.pid))
    return err


@pytest.fixture
def sim_dir(tmp_path, inputs):
    """A folder with a stand-in ``yade`` that only sleeps (its pid written to yade.pid), and the grains."""
    fake = tmp_path / "fake-yade"
    fake.write_text(f'#!/bin/sh\necho $$ > "{tmp_path}/yade.pid"\nexec sleep 60\n')
    fake.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    return work, fake


@pytest.mark.slow  # a real process per signal and moment
@pytest.mark.parametrize("sig, delay", [(signal.SIGINT, 0.3), (signal.SIGTERM, 0.8), (signal.SIGINT, 1.3),
                                        (signal.SIGTERM, 1.8)], ids=["SIGINT-0.3", "SIGTERM-0.8", "SIGINT-1.3",
                                                                     "SIGTERM-1.8"])
def test_signal_before_yade_starts_is_honoured(sim_dir, inputs, sig, delay):
    """At any moment before the engine runs (imports, checks, templates): exit 130/143 in one line, nothing
    written, no process left. (An import that swallowed the KeyboardInterrupt used to let the run go on.)
    The moments alternate between the two signals: each signal early and late, each moment once."""
    work, fake = sim_dir
    proc = _start(["simulate", "repose", str(inputs / "ang"), "--quick", "--out", "o"], work,
                  GRAINFORGE_YADE=str(fake))
    time.sleep(delay)
    os.killpg(proc.pid, sig)  # the whole group, as a terminal sends Ctrl-C
    _stopped(proc, sig)
    pidfile = work.parent / "yade.pid"
    if pidfile.exists():  # the stand-in had started: it must be gone too
        pid = int(pidfile.read_text())
        _assert_gone(lambda: [pid] if Path(f"/proc/{pid}").exists() and
                     Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in "ZX" else [])
    assert list(work.iterdir()) == []


def _wait_for_yade(work: Path, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 120
    while not _processes_in(work):
        if proc.poll() is not None:
            pytest.fail(f"the command ended before Yade started: {proc.communicate()[1].decode()}")
        if time.monotonic() > deadline:
            pytest.fail("Yade never started")
        time.sleep(0.05)
    time.sleep(0.5)


@pytest.mark.parametrize("command", [["repose"], ["calibrate", "tilt", "--target-angle", "30"]],
                         ids=["repose", "calibrate"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.slow  # runs Yade
def test_signal_while_yade_runs_kills_it_and_leaves_nothing(tmp_path, inputs, sig, command):
    require_engine("yade")
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(["simulate", *command[:2 if command[0] == "calibrate" else 1], str(inputs / "ang"),
                   *command[2:], "--quick", "--out", "o"], work)
    _wait_for_yade(work, proc)
    os.killpg(proc.pid, sig)
    _stopped(proc, sig)
    _assert_gone(lambda: _processes_in(work))
    assert list(work.iterdir()) == []  # no deck folder: the rerun needs no --overwrite


@pytest.mark.slow  # runs Yade
def test_sigkill_while_yade_runs_leaves_nothing_that_blocks_the_rerun(tmp_path, inputs):
    require_engine("yade")
    work = tmp_path / "work"
    work.mkdir()
    args = ["simulate", "repose", str(inputs / "ang"), "--quick", "--out", "o"]
    proc = _start(args, work)
    _wait_for_yade(work, proc)
    proc.kill()
    proc.communicate(timeout=20)
    _assert_gone(lambda: _processes_in(work))  # Yade dies with its parent
    left = [p.name for p in (work / "o").iterdir()]
    assert len(left) == 1 and left[0].startswith(".grainforge-staging-"), left  # no deck folder in --out
    # the rerun is not refused for the killed run's leftovers, and removes them (here Yade "fails" at once:
    # the run gets past every check, and its own failure keeps only that run's deck and log, in failed-<run>)
    rerun = _start(args, work, GRAINFORGE_YADE="false")
    _, err = rerun.communicate(timeout=120)
    err = err.decode()
    assert rerun.returncode == 1 and "Yade failed in repose-seed0" in err and "--overwrite" not in err, err
    assert "failed-repose-seed0" in err, err
    assert [p.name for p in (work / "o").iterdir()] == ["failed-repose-seed0"]


@pytest.mark.slow  # a real process per signal and moment
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("delay", [0.8, 1.5])
def test_signal_early_in_a_fit_is_honoured(tmp_path, sig, delay):
    """A fit (minutes of work) stopped while it loads its modules or starts its pilot: one line, nothing left."""
    proc = _start(["fit", str(OTTAWA), "--voxel-size-um", "7.3", "--out", "o", "--workers", "1"], tmp_path)
    time.sleep(delay)
    os.killpg(proc.pid, sig)
    _stopped(proc, sig)
    assert list(tmp_path.iterdir()) == []


def test_simulate_stage_commits_all_outputs_together_and_a_killed_runs_stage_is_removed(tmp_path):
    """The staging behind "all outputs or none": nothing moves while one output would be refused; with
    --overwrite an earlier deck folder is replaced whole; a dead process's staging folder goes."""
    from grainforge.runtime.staging import STAGING_PREFIX
    from grainforge.simulate import commit_stage, discard_stage, open_stage

    out = tmp_path / "o"
    (out / "repose-seed0").mkdir(parents=True)
    (out / "repose-seed0" / "old.txt").write_text("old")
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale = out / f"{STAGING_PREFIX}{dead.pid}-x"
    (stale / "repose-seed0").mkdir(parents=True)
    stage, created = open_stage(out)
    assert not created and not stale.exists() and stage.parent == out
    (stage / "repose-seed0").mkdir()
    (stage / "repose-seed0" / "run.py").write_text("new")
    (stage / "results.csv").write_text("rows")
    with pytest.raises(FileExistsError, match="repose-seed0 exists; use overwrite"):
        commit_stage(stage, out)
    assert sorted(p.name for p in out.iterdir()) == sorted([stage.name, "repose-seed0"])
    assert [p.name for p in (out / "repose-seed0").iterdir()] == ["old.txt"]
    commit_stage(stage, out, overwrite=True)
    discard_stage(stage, out, created)
    assert sorted(p.name for p in out.iterdir()) == ["repose-seed0", "results.csv"]
    assert [p.name for p in (out / "repose-seed0").iterdir()] == ["run.py"]
    fresh = tmp_path / "fresh"
    stage, created = open_stage(fresh)
    discard_stage(stage, fresh, created)  # an interrupted run in a folder it created leaves no folder
    assert created and not fresh.exists()


@pytest.mark.parametrize("where", ["tempfile.mkdtemp", "grainforge.runtime.staging.remove_stale_staging"])
def test_a_signal_while_the_staging_folders_are_made_leaves_no_folder(tmp_path, monkeypatch, where):
    """A Ctrl-C that lands after --out is made but before its staging folder is (the moment a real signal once
    hit in CI, leaving an empty --out behind): the folder the run created is gone, one given is kept; in
    simulate's staging and in generate's writer."""
    from grainforge.simulate import staged

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(where, interrupted)
    fresh, given = tmp_path / "fresh", tmp_path / "given"
    given.mkdir()
    for out in (fresh, given):
        with pytest.raises(KeyboardInterrupt), staged(out):
            pytest.fail("the body must not run")
    assert not fresh.exists() and given.is_dir() and list(given.iterdir()) == []
    monkeypatch.undo()
    with staged(fresh) as stage:  # and without the interrupt, the stage is made and removed with the folder
        assert stage.parent == fresh and stage.is_dir()
    assert not fresh.exists()
    # generate's writer has the same moment
    import grainforge.methods
    from grainforge.population.generate import write_run

    monkeypatch.setattr(where, interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_run("fso", grainforge.methods.get("fso").Params(subdivisions=2), seeds=[0], out=fresh, size=5.0)
    assert not fresh.exists()


def _python(code: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)


def test_a_signal_swallowed_by_a_library_still_ends_the_command_after_the_grace():
    """A library's ``except BaseException`` (trimesh guards its optional imports so) can swallow the exception a
    SIGTERM raises; the command then still ends, with the usual line and code, SIGNAL_GRACE seconds later."""
    code = textwrap.dedent("""
        import signal, sys, time
        import grainforge.cli.interrupts as m
        m.SIGNAL_GRACE = 0.5
        signal.signal(signal.SIGTERM, m._terminate)
        while True:
            try:
                print("ready", flush=True)
                time.sleep(60)  # where the one signal lands (inside the try, not on the loop's own line)
            except BaseException:
                pass
    """)
    proc = _python(code)
    assert proc.stdout.readline() == b"ready\n"
    os.killpg(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signal.SIGTERM and err.decode().strip() == "Terminated.", err.decode()


def test_a_signal_raised_inside_a_finalizer_is_raised_again_in_the_main_thread():
    """Python reports an exception raised inside a finalizer and goes on; the command's hook turns a signal's
    exception there into the signal again, so the command stops at the next line of its own code, no traceback."""
    code = textwrap.dedent("""
        import sys
        import grainforge.cli.interrupts as m
        import signal
        signal.signal(signal.SIGTERM, m._terminate)
        sys.unraisablehook = m._signal_in_finalizer(sys.unraisablehook)
        class Finalized:
            def __del__(self):
                raise m.Terminated()
        import time
        try:
            Finalized()
            end = time.monotonic() + 5
            while time.monotonic() < end:
                pass
            print("ran on")
        except m.Terminated:
            print("stopped")
    """)
    proc = _python(code)
    out, err = proc.communicate(timeout=30)
    assert out.decode().strip() == "stopped" and b"Traceback" not in err, (out, err)


def test_a_signal_a_compiled_extension_cannot_pass_on_stops_the_command_without_a_traceback():
    """A compiled extension (SciPy's Sobol tables were one, in CI) reports an exception it cannot pass on twice:
    its traceback through ``sys.excepthook``, then the unraisable hook.  Here the command meets the same two
    calls (the second through a finalizer, as CPython makes it); it prints its one line and exits 143."""
    code = textwrap.dedent("""
        import sys, time
        import click
        import grainforge.cli.main as m

        class Finalized:
            def __del__(self):
                raise m.Terminated()

        @click.group(cls=m.GrainforgeGroup)
        def cli():
            pass

        @cli.command()
        def work():
            try:
                raise m.Terminated()
            except m.Terminated as exc:
                sys.excepthook(type(exc), exc, exc.__traceback__)  # the traceback Cython prints first
            Finalized()  # then the unraisable hook
            end = time.monotonic() + 5
            while time.monotonic() < end:
                pass
            print("ran on")

        cli(["work"])
    """)
    proc = _python(code)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and b"ran on" not in out, (proc.returncode, out, err)
    assert err.decode().strip() == "Terminated.", err.decode()
