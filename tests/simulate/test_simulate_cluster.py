"""``simulate`` with ``--scheduler`` and ``--resume``: on a real distributed.LocalCluster (two worker processes) a
quick repose sweep gives the local run's files; a sweep whose driver is killed after its first seed resumes from
its journal without running that seed again and ends with the uninterrupted run's files; the refusals are one line
before any work; a scheduler lost mid-run is one line, exit 1, saying what the journal keeps.

Yade is deterministic across processes here: two local runs of the same settings give byte-identical
``result.json``, ``results.csv`` and figure.  Only each run's ``yade.log`` differs between any two runs (it names
the random auth cookie and port of Yade's Python prompt), so it is compared by presence only.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import require_engine

from grainforge.cli.main import cli

pytestmark = pytest.mark.slow

distributed = pytest.importorskip("distributed")

#: a two-seed quick repose sweep, one run at a time locally (the interrupt lands between the seeds). 10 grains and
#: soft contacts (E = 1e5 Pa: a time step three times longer, 7,500 steps instead of 18,000; 8 s of CPU a run of
#: 30 grains instead of 15): the plumbing, not a heap to measure
SOFT = ["--young", "1e5"]
ARGS = ["--quick", "--seeds", "2", "--grains", "10", *SOFT]
#: the file every engine run writes that differs between any two runs (see the module text)
ENGINE_LOG = "yade.log"


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) by relative path; an engine log by presence only."""
    return {str(p.relative_to(folder)): b"" if p.name == ENGINE_LOG else p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def grains(tmp_path_factory) -> Path:
    from click.testing import CliRunner

    out = tmp_path_factory.mktemp("grains") / "g"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="module")
def local(grains, tmp_path_factory) -> Path:
    """The uninterrupted local sweep: the reference of every other run here."""
    from click.testing import CliRunner

    require_engine("yade")
    out = tmp_path_factory.mktemp("local") / "sim"
    r = CliRunner().invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS, "--workers", "1"])
    assert r.exit_code in (0, 3), r.output  # 3: a quick heap may be too flat to measure (the files are written)
    return out


def test_a_sweep_on_the_cluster_writes_the_local_runs_files(cluster, grains, local, runner, tmp_path):
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS,
                            "--scheduler", cluster.scheduler_address])
    assert r.exit_code in (0, 3), r.output
    got, want = tree(out), tree(local)
    assert sorted(got) == sorted(want)  # the same files, and no journal left
    assert {"results.csv", "repose.png", "repose-seed0/result.json", f"repose-seed1/{ENGINE_LOG}"} <= set(got)
    assert got == want
    assert r.stdout.splitlines()[-1].startswith("g: ")


def test_an_interrupted_sweep_resumes_without_rerunning_its_finished_seed(cluster, grains, local, runner, tmp_path):
    from _processes import kill_sessions

    work = tmp_path / "work"
    work.mkdir()
    out = work / "sim"
    journal = out / ".grainforge-sweep"
    proc = subprocess.Popen([sys.executable, "-c", "from grainforge.cli.main import main; main()", "simulate",
                             "repose", str(grains), "--out", str(out), *ARGS, "--workers", "1"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    started = [proc]
    try:
        deadline = time.monotonic() + 120  # a hang guard
        while not list(journal.glob("repose-seed*")):
            assert proc.poll() is None, proc.communicate()[1].decode()
            assert time.monotonic() < deadline, "the first seed never finished"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        kill_sessions(started)
    assert proc.returncode == 128 + signal.SIGTERM, err.decode()
    kept = sorted(p.name for p in journal.glob("repose-seed*"))
    assert kept == ["repose-seed0"]  # one run at a time: the second was cut short, not journaled
    assert not (out / "results.csv").exists() and not list(out.glob("repose-seed*"))  # nothing committed
    finished = (journal / "repose-seed0" / "result.json").stat().st_mtime_ns

    # a rerun without --resume, or with other settings, is refused in one line before any work
    again = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS])
    assert again.exit_code == 2 and "use --resume" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    other = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS, "--friction", "0.6",
                                "--resume"])
    assert other.exit_code == 2, other.output
    assert "--friction 0.5 (now 0.6)" in other.stderr and len(other.stderr.strip().splitlines()) == 1

    # resumed on the cluster: seed 0 is the journal's (its result.json not rewritten), seed 1 runs
    resumed_at = time.time_ns()
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS, "--resume",
                            "--scheduler", cluster.scheduler_address])
    assert r.exit_code in (0, 3), r.output
    assert (out / "repose-seed0" / "result.json").stat().st_mtime_ns == finished < resumed_at
    assert (out / "repose-seed1" / "result.json").stat().st_mtime_ns > resumed_at
    assert not journal.exists()
    assert tree(out) == tree(local)


def test_refusals_are_one_line_before_any_work(cluster, grains, runner, tmp_path, monkeypatch):
    out = tmp_path / "sim"
    cases = [
        (["--scheduler", cluster.scheduler_address, "--workers", "2"], "--workers is for the local pool"),
        (["--scheduler", "http://node12"], "not a Dask scheduler address"),
        (["--resume", "--overwrite"], "--resume and --overwrite exclude each other"),
    ]
    for extra, message in cases:
        r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), "--quick", *extra])
        assert r.exit_code == 2, r.output
        assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.output
        assert not out.exists()
    calibrate = runner.invoke(cli, ["simulate", "calibrate", "tilt", str(grains), "--target-angle", "30", "--out",
                                    str(out), "--quick", "--scheduler", "node12"])
    assert calibrate.exit_code == 2 and "not a Dask scheduler address" in calibrate.stderr
    monkeypatch.setitem(sys.modules, "distributed", None)  # Dask not installed
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), "--quick",
                            "--scheduler", cluster.scheduler_address])
    assert r.exit_code == 2 and "--scheduler needs Dask distributed: pip install" in r.stderr, r.output
    assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()


class _LosingExecutor:
    """Runs the first task here, then answers as a client whose scheduler is gone."""

    workers = 2

    def submit(self, fn, *args, **kwargs):
        import concurrent.futures as cf

        from grainforge.runtime.cluster import SchedulerLost

        fut = cf.Future()
        if not hasattr(self, "ran"):
            self.ran = True
            fut.set_result(fn(*args, **kwargs))
        else:
            fut.set_exception(SchedulerLost("tcp://10.0.0.5:8786", 1, 2, "connection closed"))
        return fut


def test_a_scheduler_lost_mid_run_is_one_line_and_keeps_the_finished_runs(grains, runner, tmp_path, monkeypatch):
    require_engine("yade")
    from contextlib import nullcontext

    import grainforge.runtime.cluster as cluster

    monkeypatch.setattr(cluster, "dask_executor", lambda address: nullcontext(_LosingExecutor()))
    out = tmp_path / "sim"
    r = runner.invoke(cli, ["simulate", "repose", str(grains), "--out", str(out), *ARGS,
                            "--scheduler", "tcp://10.0.0.5:8786"])
    assert r.exit_code == 1, r.output
    # the run's estimate (said once its grains are made) and the loss: one line of error
    lines = [ln for ln in r.stderr.strip().splitlines() if not ln.startswith("estimated time: ")]
    assert len(lines) == 1 and "lost the Dask scheduler at tcp://10.0.0.5:8786" in lines[0], r.stderr
    assert "1 finished run(s) kept in" in lines[0] and "for --resume" in lines[0]
    assert sorted(p.name for p in out.iterdir()) == [".grainforge-sweep"]  # no output committed
    assert (out / ".grainforge-sweep" / "repose-seed0" / "result.json").is_file()


def test_an_interrupted_calibration_resumes_from_its_finished_friction_seed_runs(grains, runner, tmp_path):
    """Each friction tried is a set of runs: the (friction, seed) runs finished before the interrupt are reused."""
    from _processes import kill_sessions

    require_engine("yade")
    # the tilt from 20° in 2° steps, of soft contacts (SOFT): the reference calibration 13 s of CPU instead of 32.
    # The search tries μ = 0.5, then halves it while the angle is above the target: these grains measure about 39°
    # and 30° there, so a target of 36° is bracketed by the two frictions allowed (at 30° the second friction was
    # still above it: refused)
    args = ["simulate", "calibrate", "tilt", str(grains), "--target-angle", "36", "--quick", "--max-frictions", "2",
            "--workers", "1", "--tilt-start", "20", "--tilt-step", "2", *SOFT]
    ref = runner.invoke(cli, [*args, "--out", str(tmp_path / "ref")])
    assert ref.exit_code == 0, ref.output
    out = tmp_path / "cal"
    journal = out / ".grainforge-sweep"
    proc = subprocess.Popen([sys.executable, "-c", "from grainforge.cli.main import main; main()", *args,
                             "--out", str(out)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not list(journal.glob("runs+e0-*+tilt-seed0")):
            assert proc.poll() is None, proc.communicate()[1].decode()
            assert time.monotonic() < deadline, "the first friction never finished"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        kill_sessions([proc])
    assert proc.returncode == 128 + signal.SIGTERM, err.decode()
    [first] = journal.glob("runs+e0-*+tilt-seed0")
    finished = (first / "result.json").stat().st_mtime_ns
    r = runner.invoke(cli, [*args, "--out", str(out), "--resume"])
    assert r.exit_code == 0, r.output
    assert (out / "runs" / first.name.split("+")[1] / "tilt-seed0" / "result.json").stat().st_mtime_ns == finished
    assert not journal.exists()
    assert tree(out) == tree(tmp_path / "ref")
    assert r.stdout.replace(str(out), "OUT") == ref.stdout.replace(str(tmp_path / "ref"), "OUT")


def test_mpi_ranks_on_a_cluster_are_the_workers_to_decide(grains, runner, tmp_path, monkeypatch):
    """``--mpi`` beyond this machine's cores is refused locally, not with ``--scheduler`` (the command goes on to
    connect: a stand-in connection that stops it there)."""
    import click

    import grainforge.runtime.cluster as cluster

    args = ["simulate", "repose", str(grains), "--out", str(tmp_path / "sim"), "--quick", "--engine", "liggghts",
            "--mpi", "4096"]
    local = runner.invoke(cli, args, env={"SLURM_NTASKS": ""})
    assert local.exit_code == 2 and "--mpi 4096: only" in local.stderr, local.output

    def connect(address):
        raise click.UsageError(f"connected to {address}")

    monkeypatch.setattr(cluster, "dask_executor", connect)
    r = runner.invoke(cli, [*args, "--scheduler", "tcp://10.0.0.5:8786"])
    assert r.exit_code == 2 and "connected to tcp://10.0.0.5:8786" in r.stderr, r.output
