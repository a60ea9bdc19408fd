"""Ctrl-C and SIGTERM at the edges of a run's life, for every command that writes files.

The CLI contract (docs/cli-contract.md) promises that a signal at any moment ends the command
quickly with exit 130 (SIGINT) or 143 (SIGTERM) and one line (``Interrupted.`` / ``Terminated.``),
with nothing partial in or beside the output and no process left.  The moments tested here are
the ones that used to lose the signal:

- start-up, while the command line loads its modules (trimesh swallowed a KeyboardInterrupt raised
  during its import: the command ran to its end and exited 0, or stopped only after the 15 s
  fallback, leaving a tray's temporary file);
- the end of a short run, the moment its first output (or the temporary file it is written to)
  appears (the signal came while the interpreter was finishing: exit 0, or death by the signal
  with no line);
- an MPI LIGGGHTS run, whose interrupted ``mpirun`` used to leave Open MPI's session folder
  (``ompi.HOST.UID/pid.N``) behind.

Each command runs as a real process, as a terminal's foreground job (SIGINT at its default), in
its own session, and the signal goes to its whole process group, as a terminal sends Ctrl-C.  At
the end of a run the test freezes the group (SIGSTOP) before signalling it, so it knows whether
the command had already finished (exited before the signal: then it must have succeeded) or
was still running (then the signal must be honoured).

Run: ``.venv/bin/python -m pytest tests/cli/test_cli_signals.py -q -n 0`` (a few minutes; all slow).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _processes import child_processes, kill_sessions, session_processes
from test_cli_contract_fit_simulate import _assert_gone

ROOT = Path(__file__).resolve().parents[2]
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"
#: the console script a user runs (the package this interpreter imports), else the same entry point
_SCRIPT = Path(sys.executable).parent / "grainforge"
CLI = [str(_SCRIPT)] if _SCRIPT.is_file() else [sys.executable, "-c", "from grainforge.cli.main import main; main()"]
#: seconds from the signal to the command's exit: the contract says 2; measured 0.01-0.2 s, the margin is for
#: a machine loaded by other jobs (and well under the 15 s fallback, SIGNAL_GRACE, that a lost signal meets)
STOP_WITHIN = 5.0
LINES = {signal.SIGINT: "Interrupted.", signal.SIGTERM: "Terminated."}

#: every command that writes files (``check`` prints its table only, and is here for its start-up), short
#: runs: name -> (arguments, the files of a complete run, relative to the command's folder). ``{in}`` is the
#: shared inputs folder, ``{yade}`` a stand-in Yade that only sleeps (the start-up cases never reach it).
COMMANDS = {
    "generate": (["generate", "fso", "--count", "3", "--subdivisions", "2", "--out", "g"],
                 ["g/fso-0000.stl", "g/fso-0001.stl", "g/fso-0002.stl", "g/manifest.csv"]),
    "batch": (["batch", "{in}/r.toml", "--out", "b", "--workers", "1"],
              ["b/fso-0000.stl", "b/fso-0001.stl", "b/manifest.csv", "b/manifest.json", "b/population.png",
               "b/.grainforge-batch/recipe.toml", "b/.grainforge-batch/grain-000000.json",
               "b/.grainforge-batch/grain-000001.json"]),
    "tray": (["tray", "{in}/grains", "--out", "t.3mf", "--workers", "1"], ["t.3mf", "t.csv", "t-plate1.png"]),
    "check": (["check", "{in}/grains"], []),
    "render": (["render", "{in}/grains", "-o", "r.png"], ["r.png"]),
    "analyse": (["analyse", "{in}/grains", "--csv", "a.csv", "--workers", "1"], ["a.csv"]),
    "dem": (["dem", "{in}/grains", "--out", "d", "--workers", "1"],
            ["d/grains.json", "d/run.py"] + [f"d/fso-000{k}.{ext}" for k in range(3) for ext in ("clump.vtk", "xyzr")]),
    "dem-levelset": (["dem", "{in}/grains", "--shape", "levelset", "--out", "d", "--workers", "1"],
                     ["d/grains.json", "d/run.py"] + [f"d/fso-000{k}.levelset.json" for k in range(3)]),
    "calibrate-dpa": (["calibrate", "dpa", "--primaries", "10", "--exponents", "1:2:1", "--repeats", "2",
                       "--workers", "1", "--out", "c"], ["c/calibration.csv", "c/calibration.png"]),
    "scan": (["scan", "{in}/scan.npy", "--voxel-size-um", "10", "--atlas-csv", "s.csv", "--meshes", "m",
              "--workers", "1"], ["s.csv", "m/grain-000001.stl", "m/grain-000002.stl", "m/grain-000003.stl"]),
    "fit": (["fit", str(OTTAWA), "--voxel-size-um", "7.3", "--out", "f", "--workers", "1"], None),
    "simulate": (["simulate", "repose", "{in}/ang", "--quick", "--out", "o"], None),
    "simulate-calibrate": (["simulate", "calibrate", "tilt", "{in}/ang", "--target-angle", "30", "--quick",
                            "--out", "o"], None),
}

#: commands whose interrupted run keeps what it finished, for ``--resume`` (``batch`` writes its grains as they
#: are made): command -> its journal, which must then be there (and no file outside the complete run's)
RESUMABLE = {"batch": "b/.grainforge-batch/recipe.toml"}

#: the start-up moments (seconds after the start), each signal early and late
START_UP = [(signal.SIGINT, 0.1), (signal.SIGTERM, 0.4), (signal.SIGINT, 0.8), (signal.SIGTERM, 1.2)]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Three small grains, three angular ones (simulate), a four-grain recipe, a labelled image of three grains
    (scan) and a stand-in Yade."""
    from grainforge.methods import get
    from grainforge.population.generate import write_run

    d = tmp_path_factory.mktemp("inputs")
    write_run("fso", get("fso").Params(subdivisions=2), seeds=[0, 1, 2], out=d / "grains", size=5.0)
    write_run("angular", get("angular").Params(subdivisions=3), seeds=[0, 1, 2], out=d / "ang", size=2.0)
    (d / "r.toml").write_text('method = "fso"\ncount = 2\nseed = 1\n[params]\nsubdivisions = 2\n[size]\nmm = 1.0\n')
    import numpy as np

    z, y, x = np.indices((40, 40, 60))
    scan = np.zeros(z.shape, np.uint16)
    for k, cx in enumerate((12, 30, 48), start=1):  # three ellipsoids, clear of the image's faces
        scan[((z - 20) / 12.0) ** 2 + ((y - 20) / 10.0) ** 2 + ((x - cx) / 8.0) ** 2 <= 1] = k
    np.save(d / "scan.npy", scan)
    fake = d / "fake-yade"
    fake.write_text("#!/bin/sh\nexec sleep 60\n")
    fake.chmod(0o755)
    return d


_STARTED: list[subprocess.Popen] = []


@pytest.fixture(autouse=True)
def _no_strays():
    """After each test, even a failed one: kill whatever its command left running."""
    yield
    kill_sessions(_STARTED)


def _start(args: list[str], cwd: Path, inputs: Path, **env) -> subprocess.Popen:
    def foreground():
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # as a foreground job of a terminal's shell

    argv = CLI + [a.replace("{in}", str(inputs)) for a in args]
    env = {**os.environ, "COLUMNS": "200", "GRAINFORGE_YADE": str(inputs / "fake-yade"), **env}
    proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True, preexec_fn=foreground, env=env)
    _STARTED.append(proc)
    return proc


def _stat(pid: int) -> list[str]:
    """/proc/PID/stat's fields after the command name (state, parent, group, session, tty, tpgid, flags, ...)."""
    try:
        return (Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1]).split()
    except OSError:
        return ["X", "0", "0", "0", "0", "0", "4"]


def _signal_running(proc: subprocess.Popen, sig: int) -> bool:
    """Send ``sig`` to the command's group if it still runs; whether it did (False: it had finished).

    The group is frozen first (SIGSTOP), so that "still running" is not a guess: a process that has begun
    to exit (PF_EXITING) or is gone has finished; a stopped one gets the signal as it resumes."""
    try:
        os.killpg(proc.pid, signal.SIGSTOP)
    except ProcessLookupError:
        return False
    while True:
        fields = _stat(proc.pid)
        if fields[0] in "ZX" or int(fields[6]) & 0x4:  # PF_EXITING
            os.killpg(proc.pid, signal.SIGCONT)
            return False
        if fields[0] == "T":
            break
        time.sleep(0.001)
    os.killpg(proc.pid, sig)
    os.killpg(proc.pid, signal.SIGCONT)
    return True


def _processes_in(folder: Path) -> list[int]:
    """Processes (not zombies) whose working directory is inside ``folder`` (engines run in their decks)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cwd = os.readlink(entry / "cwd")
            except OSError:
                continue
            if cwd.startswith(str(folder) + os.sep) and _stat(int(entry.name))[0] not in "ZX":
                pids.append(int(entry.name))
    return pids


def _stopped(proc: subprocess.Popen, sig: int, sent: float, folder: Path) -> list[str]:
    """Wait for the command after ``sig``: exit 128 + sig within STOP_WITHIN, the signal's line last, no error
    or traceback, no process of its session or working in ``folder`` left; its stderr lines."""
    try:
        _, err = proc.communicate(timeout=60)  # a hang guard; the time is asserted below
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the command still ran 60 s after the signal")
    took = time.monotonic() - sent
    err = err.decode("utf-8", "replace")
    lines = err.strip().splitlines()
    assert proc.returncode == 128 + sig and "Traceback" not in err, (proc.returncode, err)
    # the command's own report lines may come first (a run that ended as the signal came says what it wrote)
    assert lines and lines[-1] == LINES[sig] and lines.count(LINES[sig]) == 1, err
    assert not any(ln.startswith(("Error", "Traceback", "Exception ignored")) for ln in lines), err
    assert took < STOP_WITHIN, f"the command left {took:.1f} s after the signal"
    _assert_gone(lambda: session_processes(proc.pid) + _processes_in(folder))
    return lines


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir()}


@pytest.mark.slow  # a real process per command, signal and moment
@pytest.mark.parametrize("sig, delay", START_UP, ids=[f"{signal.Signals(s).name}-{d}" for s, d in START_UP])
@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_signal_at_start_up_is_honoured(tmp_path, inputs, command, sig, delay):
    """While the command line loads its modules (well before any work): exit 130/143 in one line, nothing
    written, no process left."""
    args, files = COMMANDS[command]
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(args, work, inputs)
    time.sleep(delay)
    sent = time.monotonic()
    if not _signal_running(proc, sig):  # a very fast machine: done before the signal
        proc.communicate(timeout=60)
        assert proc.returncode == 0
        pytest.skip("the command finished before the signal")
    _stopped(proc, sig, sent, work)
    left = _files(work)
    if not left:
        assert list(work.iterdir()) == []
    elif command in RESUMABLE:  # a loaded machine: past start-up already, stopped mid-way (--resume continues)
        assert left <= set(files) and RESUMABLE[command] in left, sorted(left)
    else:  # a loaded machine: past start-up already, the outputs are complete or absent
        assert left == set(files), sorted(left)


@pytest.mark.slow  # runs each short command to its end
# not yet reliable: on a loaded machine one case in a full run has failed each time (generate SIGTERM left its
# grains without the manifest; tray SIGINT printed a finalizer's message, since silenced): reported, not gating
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("command", [c for c, (_, files) in COMMANDS.items() if files])
def test_a_signal_as_the_outputs_appear_is_honoured(tmp_path, inputs, command, sig):
    """The signal the moment the run's first output, or the temporary file it is written to, appears (most
    commands move their outputs into place together, under held signals, at their very end): exit 130/143 in
    one line, the outputs complete or absent (a batch: what --resume continues from), no temporary file beside
    them, no process left; or, if the command had already finished, its success."""
    args, files = COMMANDS[command]
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(args, work, inputs)
    deadline = time.monotonic() + 300
    folders = {(work / f).parent for f in files}
    while not (any((work / f).exists() for f in files) or any(g for d in folders for g in d.glob(".*.tmp"))):
        if proc.poll() is not None:
            pytest.fail(f"the command ended before its outputs appeared: {proc.communicate()[1].decode()}")
        assert time.monotonic() < deadline, "the outputs never appeared"
        time.sleep(0.005)
    sent = time.monotonic()
    if _signal_running(proc, sig):
        _stopped(proc, sig, sent, work)
    else:  # it had finished: the signal came too late to count
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 0 and _files(work) == set(files), err.decode()
        pytest.skip("the command had finished before the signal")
    left = _files(work)
    if command in RESUMABLE and left and left != set(files):  # stopped mid-way: what --resume continues from
        assert left <= set(files) and RESUMABLE[command] in left, sorted(left)
    else:
        assert left in (set(), set(files)), sorted(left)


@pytest.mark.slow  # a real batch, stopped, then resumed by the command it names
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stopped_batch_says_what_it_kept_and_how_to_resume(tmp_path, inputs, sig):
    """``batch`` is the exception to "all outputs or none": stopped mid-way, it keeps its finished grains and their
    journal for ``--resume``, and says so before the signal's line: how many of how many grains, where, and the
    command that continues; that command, run as printed, makes the rest and keeps the grains it names."""
    import re
    import shlex

    recipe = tmp_path / "big.toml"
    recipe.write_text('method = "fso"\ncount = 150\nseed = 1\n[params]\nsubdivisions = 3\n[size]\nmm = 1.0\n')
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(["batch", str(recipe), "--out", "b", "--workers", "1"], work, inputs)
    deadline = time.monotonic() + 300
    while len(list(work.glob("b/.grainforge-batch/grain-*.json"))) < 3:
        if proc.poll() is not None:
            pytest.fail(f"the batch ended before the signal: {proc.communicate()[1].decode()}")
        assert time.monotonic() < deadline, "no grain was recorded"
        time.sleep(0.02)
    sent = time.monotonic()
    if not _signal_running(proc, sig):
        pytest.skip("the batch had finished before the signal")
    lines = _stopped(proc, sig, sent, work)
    kept = len(list(work.glob("b/.grainforge-batch/grain-*.json")))
    assert kept >= 3 and not (work / "b" / "manifest.csv").exists()
    m = re.fullmatch(r"kept (\d+) of 150 fso grain\(s\) in b \(no manifest\.csv yet\); to make the rest: (.*)",
                     lines[-2])
    assert m and int(m.group(1)) == kept, lines
    command = shlex.split(m.group(2))
    assert command == ["grainforge", "batch", str(recipe), "--out", "b", "--resume"]
    resumed = subprocess.run(CLI + command[1:], cwd=work, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert f"wrote {150 - kept} fso grain(s) (kept {kept} intact from the interrupted batch)" in resumed.stderr
    assert len((work / "b" / "manifest.csv").read_text().splitlines()) == 151


@pytest.mark.parametrize("writer", ["generate", "commit_stage"])
def test_a_signal_while_outputs_move_into_place_waits_for_the_last(tmp_path, monkeypatch, writer):
    """The window the test above can only hit by chance, made certain: a SIGINT raised as the first output is
    moved into place is answered after the last one (grains and manifest, or every staged file), not between."""
    import pathlib

    from grainforge.methods import get
    from grainforge.population.generate import write_run
    from grainforge.runtime.staging import commit_stage, staged

    moved, usual = [], pathlib.Path.replace

    def replace(self, target):
        if not moved:
            signal.raise_signal(signal.SIGINT)
        moved.append(Path(target).name)
        return usual(self, target)

    monkeypatch.setattr(pathlib.Path, "replace", replace)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        if writer == "generate":
            write_run("fso", get("fso").Params(subdivisions=2), seeds=range(3), out=out, size=5.0)
        else:
            with staged(out) as stage:
                for name in ("a.csv", "b.png", "c.json"):
                    (stage / name).write_text(name)
                commit_stage(stage, out)
    expected = ({"fso-0000.stl", "fso-0001.stl", "fso-0002.stl", "manifest.csv"} if writer == "generate"
                else {"a.csv", "b.png", "c.json"})
    assert set(moved) == expected
    assert {p.name for p in out.iterdir()} == expected  # every output, and no staging folder left


def require(*engines: str) -> None:
    missing = [e for e in engines if shutil.which(e) is None]
    if missing:
        reason = f"{', '.join(missing)} not installed"
        if os.environ.get("GRAINFORGE_REQUIRE_ENGINES") == "1":
            pytest.fail(reason + " but GRAINFORGE_REQUIRE_ENGINES=1")
        pytest.skip(reason)


#: a quick repose of 30 grains, not --quick's 120, of soft contacts (E = 1e5 Pa: a time step three times longer,
#: 7,500 steps instead of 18,000): the signal lands as the outputs are committed, whatever their heap (30 grains
#: make none to measure: exit 3, the outputs written all the same)
QUICK_30 = ["--quick", "--grains", "30", "--young", "1e5"]


@pytest.mark.slow  # runs Yade (a 30-grain quick repose of soft contacts: 8 s of CPU)
def test_a_signal_as_a_simulation_commits_its_outputs_is_honoured(tmp_path, inputs):
    """A quick Yade repose run, Ctrl-C the moment its results table is written (then all its outputs move into
    --out together): exit 130, one line, all outputs or none, no Yade left — or, when the signal came before
    the outputs moved, only the sweep's journal of finished runs, from which ``--resume`` completes the run."""
    require("yade")
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(["simulate", "repose", "{in}/ang", *QUICK_30, "--out", "o"], work, inputs,
                  GRAINFORGE_YADE=shutil.which("yade"))
    deadline = time.monotonic() + 600
    # the results table appears in the staging folder, then everything moves into --out under held signals
    while not (any(work.glob("o/.grainforge-staging-*/results.csv")) or (work / "o" / "results.csv").exists()):
        if proc.poll() is not None:
            pytest.fail(f"the run ended before its results appeared: {proc.communicate()[1].decode()}")
        assert time.monotonic() < deadline, "the results never appeared"
        time.sleep(0.005)
    sent = time.monotonic()
    if _signal_running(proc, signal.SIGINT):
        _stopped(proc, signal.SIGINT, sent, work)
    else:  # 3: a quick run's heap may be too small to give an angle (its outputs are written all the same)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode in (0, 3), err.decode()
        pytest.skip("the run had finished before the signal")
    complete = ["repose-seed0", "repose.png", "results.csv", "templates.csv"]
    left = sorted(p.name for p in (work / "o").iterdir()) if (work / "o").exists() else []
    assert left in ([], complete, [".grainforge-sweep"]), left
    if left == [".grainforge-sweep"]:  # what --resume continues from: the finished run is not made again
        resumed = _start(["simulate", "repose", "{in}/ang", *QUICK_30, "--out", "o", "--resume"], work, inputs,
                         GRAINFORGE_YADE=shutil.which("yade"))
        _, err = resumed.communicate(timeout=300)
        assert resumed.returncode in (0, 3), err.decode()
        assert sorted(p.name for p in (work / "o").iterdir()) == complete


def _mpi_session_folders(pid: int, *bases: Path) -> list[Path]:
    """Open MPI 4's session folders of the mpirun ``pid`` (``ompi.HOST.UID/pid.PID``) under ``bases``."""
    return [p for base in bases for p in base.glob(f"ompi.*/pid.{pid}")]


@pytest.mark.slow  # runs LIGGGHTS under mpirun
@pytest.mark.parametrize("sig, test", [(signal.SIGINT, "repose"), (signal.SIGTERM, "repose"),
                                       (signal.SIGINT, "triaxial")],
                         ids=["SIGINT", "SIGTERM", "SIGINT-triaxial"])
def test_a_signal_while_mpi_ranks_run_leaves_no_rank_and_no_session_folder(tmp_path, inputs, sig, test):
    """``simulate repose|triaxial --engine liggghts --mpi 2`` stopped while its ranks run: mpirun and both ranks
    gone, Open MPI's session folder of that run gone (it lies in a folder of the run's own, under $TMPDIR),
    nothing in --out."""
    require("liggghts", "mpirun")
    work, tmp = tmp_path / "work", tmp_path / "tmp"
    work.mkdir()
    tmp.mkdir()
    proc = _start(["simulate", test, "{in}/ang", "--quick", "--engine", "liggghts", "--mpi", "2", "--out", "o"],
                  work, inputs, TMPDIR=str(tmp))

    def engines() -> dict[int, str]:
        out = {}
        for pid in child_processes(proc.pid):
            try:
                out[pid] = Path(f"/proc/{pid}/comm").read_text().strip()
            except OSError:
                pass
        return out

    deadline = time.monotonic() + 300
    while list(engines().values()).count("liggghts") < 2:
        if proc.poll() is not None:
            pytest.fail(f"the run ended before its ranks started: {proc.communicate()[1].decode()}")
        assert time.monotonic() < deadline, "the ranks never started"
        time.sleep(0.05)
    time.sleep(1.0)  # mid-way: the ranks stepping, the session folder in use
    running = engines()
    mpirun = [pid for pid, name in running.items() if name == "mpirun"]
    assert mpirun and _mpi_session_folders(mpirun[0], *tmp.glob("grainforge-mpi-*")), \
        "the session folder is not in the run's own folder"
    sent = time.monotonic()
    os.killpg(proc.pid, sig)
    _stopped(proc, sig, sent, work)
    _assert_gone(lambda: [pid for pid in running if _stat(pid)[0] not in "ZX"])  # mpirun and every rank
    assert list(tmp.iterdir()) == []  # the run's own folder, with the session folder, removed
    assert not _mpi_session_folders(mpirun[0], Path("/tmp"), tmp)
    assert list(work.iterdir()) == []


def _marked(marker: str) -> list[int]:
    """Processes whose command line holds ``marker`` (zombies aside)."""
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if marker.encode() in (d / "cmdline").read_bytes() and _stat(int(d.name))[0] not in "ZX":
                    found.append(int(d.name))
            except OSError:
                pass
    return found


@pytest.mark.slow  # starts mpirun with 64 ranks
@pytest.mark.parametrize("delay", [0.0, 0.3, 1.5], ids=["as-mpirun-starts", "ranks-starting", "ranks-running"])
def test_a_killed_run_of_many_ranks_leaves_none(tmp_path, inputs, delay):
    """``--mpi 64`` in a 64-slot batch allocation (on any machine: the ranks are a stand-in engine that only
    sleeps), stopped as mpirun starts its ranks or once they run: mpirun and every rank gone, none adopted by
    init (a run stopped while mpirun was still starting ranks used to leave hundreds)."""
    require("mpirun")
    marker = f"{tmp_path.name}-fake-liggghts"
    fake = tmp_path / marker
    fake.write_text("#!/bin/sh\nsleep 3600\n")
    fake.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    proc = _start(["simulate", "repose", "{in}/ang", "--quick", "--engine", "liggghts", "--mpi", "64", "--out", "o"],
                  work, inputs, GRAINFORGE_LIGGGHTS=str(fake), SLURM_NTASKS="64")
    deadline = time.monotonic() + 300
    while "mpirun" not in {Path(f"/proc/{pid}/comm").read_text().strip() for pid in child_processes(proc.pid)
                           if Path(f"/proc/{pid}/comm").exists()}:
        if proc.poll() is not None:
            pytest.fail(f"the run ended before mpirun started: {proc.communicate()[1].decode()}")
        assert time.monotonic() < deadline, "mpirun never started"
        time.sleep(0.01)
    time.sleep(delay)
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGTERM)
    _stopped(proc, signal.SIGTERM, sent, work)
    _assert_gone(lambda: _marked(marker))  # every rank (and the shell of the stand-in)
    assert list(work.iterdir()) == []


def test_more_ranks_than_cores_are_refused_before_anything_starts(tmp_path, inputs):
    """``--mpi`` beyond the cores (no batch allocation or hostfile giving more): one line naming the cores, exit 2,
    before any engine or folder exists; the same with the ranks of --workers runs at once."""
    cores = len(os.sched_getaffinity(0))
    env = {k: v for k, v in os.environ.items() if k not in ("SLURM_NTASKS", "SLURM_NPROCS", "PBS_NP", "NSLOTS",
                                                              "LSB_DJOB_NUMPROC", "PBS_NODEFILE")}
    for extra in (["--mpi", str(cores + 1)], ["--mpi", "1000"], ["--mpi", str(cores), "--workers", "2"]):
        for cmd in (["simulate", "repose", str(inputs / "ang")],
                    ["simulate", "calibrate", "tilt", str(inputs / "ang"), "--target-angle", "30"]):
            r = subprocess.run(CLI + cmd + ["--quick", "--engine", "liggghts", *extra, "--out", str(tmp_path / "o")],
                               capture_output=True, text=True, env=env, timeout=120)
            lines = r.stderr.strip().splitlines()
            assert r.returncode == 2 and len(lines) == 1, r.stderr
            assert f"{cores} core(s) here" in lines[0] and "--mpi" in lines[0], lines[0]
            assert not (tmp_path / "o").exists()


def _group_script(body: str) -> str:
    """A program whose one command ``work`` runs ``body`` under grainforge's command group (its signal handling)."""
    import textwrap

    return textwrap.dedent("""
        import sys, time
        import click
        import grainforge.cli.main as m

        @click.group(cls=m.GrainforgeGroup)
        def cli():
            pass

        @cli.command()
        def work():
        {body}

        cli(["work"])
    """).format(body=textwrap.indent(textwrap.dedent(body), "    "))


def _python(code: str, cwd: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    _STARTED.append(proc)
    return proc


@pytest.mark.slow  # a real process
def test_a_signal_a_library_swallows_is_sent_again_at_once(tmp_path):
    """A library's ``except BaseException`` swallows the KeyboardInterrupt; the command works on.  The signal is
    sent again within a second (RESEND_AFTER), not at the 15 s fallback, and the command leaves by its clean-up."""
    proc = _python(_group_script("""
        try:
            print("ready", flush=True)
            time.sleep(30)  # the signal lands here, and is swallowed
        except BaseException:
            pass
        try:
            end = time.monotonic() + 20
            while time.monotonic() < end:  # the command works on
                sum(range(1000))
            print("ran on", flush=True)
        finally:
            open("cleaned", "w").close()
    """), tmp_path)
    assert proc.stdout.readline() == b"ready\n"
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.decode().strip() == "Interrupted." and b"ran on" not in out, (out, err)
    assert time.monotonic() - sent < STOP_WITHIN and (tmp_path / "cleaned").exists()


@pytest.mark.slow  # a real process
def test_a_second_signal_does_not_cut_the_clean_up_short(tmp_path):
    """Ctrl-C twice: the second, while the command cleans up after the first, does not stop the clean-up."""
    proc = _python(_group_script("""
        try:
            print("ready", flush=True)
            time.sleep(30)
        finally:
            print("cleaning", flush=True)
            end = time.monotonic() + 1.5  # a clean-up that takes a while (removing a large staging folder)
            while time.monotonic() < end:
                sum(range(1000))
            open("cleaned", "w").close()
    """), tmp_path)
    assert proc.stdout.readline() == b"ready\n"
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.stdout.readline() == b"cleaning\n"
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and err.decode().strip() == "Interrupted.", err
    assert (tmp_path / "cleaned").exists()
