"""``analyse`` and ``fit`` (and ``batch``) with ``--scheduler``: a real distributed.LocalCluster (two worker
processes) gives byte-identical outputs to the local run, also when a worker dies mid-run; the refusals are one
line, before any work; a scheduler lost mid-run is one line, exit 1, nothing partial written."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from grainforge.cli.main import cli
from grainforge.population import parse_recipe, run_batch

# a LocalCluster starts in seconds and the fit takes tens of them: the full suite runs these, the fast lane not
pytestmark = pytest.mark.slow

distributed = pytest.importorskip("distributed")

#: twelve small FSO grains (1280 faces each): a few tenths of a second each to analyse
RECIPE = """\
method = "fso"
count = 12
seed = 8787
[params]
fractal_dimension = { distribution = "uniform", low = 2.2, high = 2.5 }
length_ratio = { distribution = "uniform", low = 3.0, high = 8.0 }
ridges = 8
frequencies = 8
subdivisions = 3
[size]
mm = 1.0
"""

RF_SAND = Path(__file__).resolve().parents[1] / "data" / "synthetic-rf-sand.csv"

#: a fit small enough for a test (the CLI's --count floor is 500; the test shrinks the population, see below)
FIT_ARGS = ["--method", "rf", "--refine", "1", "--reseed", "1", "--design-grains", "50", "--population-grains", "10",
            "--population-slopes", "model", "--max-voxels-across", "12"]
FIT_OUTPUTS = ("recipe.toml", "fit.csv", "fit-stats.csv", "fit.png")


def tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def grains(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("grains") / "pop"
    run_batch(parse_recipe(RECIPE, source="grains.toml"), out, workers=1, report=False)
    return out


def worker_pids(address: str) -> dict[str, int]:
    with distributed.Client(address, set_as_default=False) as client:
        return client.run(os.getpid)


def test_analyse_on_the_cluster_is_byte_identical_to_the_local_run(cluster, grains, runner, tmp_path):
    pids = worker_pids(cluster.scheduler_address)
    assert len(pids) == 2 and os.getpid() not in pids.values()  # two worker processes of their own
    local = runner.invoke(cli, ["analyse", str(grains), "--csv", str(tmp_path / "local.csv"), "--workers", "1"])
    assert local.exit_code == 0, local.output
    dask = runner.invoke(cli, ["analyse", str(grains), "--csv", str(tmp_path / "dask.csv"),
                               "--scheduler", cluster.scheduler_address])
    assert dask.exit_code == 0, dask.output
    assert (tmp_path / "dask.csv").read_bytes() == (tmp_path / "local.csv").read_bytes()
    assert dask.stdout == local.stdout and dask.stdout.count(".stl") == 12  # the table too, rows in input order
    # the rows name the files as given (the workers measured copies sent to them)
    assert str(grains / "fso-0000.stl") in dask.stdout and "grainforge-analyse-" not in dask.output


def test_a_worker_killed_mid_run_has_its_files_rerun_and_the_table_is_the_same(cluster, grains, runner, tmp_path,
                                                                                  monkeypatch):
    """One worker is SIGKILLed while files are assigned to it (its nanny starts another); Dask reruns them."""
    import grainforge.cli.progress as progress

    local = runner.invoke(cli, ["analyse", str(grains), "--csv", str(tmp_path / "local.csv"), "--workers", "1"])
    assert local.exit_code == 0, local.output
    killed = {}
    real_bar = progress.progress_bar

    def bar_that_kills_a_worker(**kw):
        wrap = real_bar(**kw)

        def it(items):
            for item in wrap(items):
                # kill at the first result after which a worker still holds files (the first one's files may
                # all be done by the time it arrives: the workers' first imports make file 0 the slowest)
                if "pid" not in killed:
                    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
                        busy = {w: keys for w, keys in client.processing().items() if keys}
                        if busy:
                            victim = sorted(busy)[0]
                            killed["tasks"] = len(busy[victim])
                            killed["pid"] = client.run(os.getpid, workers=[victim])[victim]
                    if "pid" in killed:
                        os.kill(killed["pid"], signal.SIGKILL)
                yield item

        return it

    monkeypatch.setattr(progress, "progress_bar", bar_that_kills_a_worker)
    dask = runner.invoke(cli, ["analyse", str(grains), "--csv", str(tmp_path / "dask.csv"),
                               "--scheduler", cluster.scheduler_address])
    assert dask.exit_code == 0, dask.output
    assert killed.get("tasks", 0) >= 1  # the killed worker held files: they were measured again elsewhere
    assert (tmp_path / "dask.csv").read_bytes() == (tmp_path / "local.csv").read_bytes()
    deadline = time.monotonic() + 60  # the nanny replaces the worker: the next tests have two again
    while time.monotonic() < deadline:
        pids = worker_pids(cluster.scheduler_address)
        if len(pids) == 2 and killed["pid"] not in pids.values():
            break
        time.sleep(0.5)
    assert len(pids) == 2 and killed["pid"] not in pids.values()


@pytest.fixture
def small_fit(monkeypatch):
    """The CLI's fit on 10 twins instead of its 500 minimum: every other step is the command's own."""
    import grainforge.fit as fitmod

    real = fitmod.fit_sand

    def fit_sand(sand, method, **kw):
        return real(sand, method, **{**kw, "count": 10})

    monkeypatch.setattr(fitmod, "fit_sand", fit_sand)


def test_fit_on_the_cluster_is_byte_identical_to_the_local_run(cluster, small_fit, runner, tmp_path):
    local = runner.invoke(cli, ["fit", str(RF_SAND), "--out", str(tmp_path / "local"), *FIT_ARGS,
                                "--cache-dir", str(tmp_path / "cache-local"), "--workers", "1"])
    assert local.exit_code in (0, 3), local.output  # a fit this small need not pass; it ran and wrote
    dask = runner.invoke(cli, ["fit", str(RF_SAND), "--out", str(tmp_path / "dask"), *FIT_ARGS,
                               "--cache-dir", str(tmp_path / "cache-dask"), "--scheduler", cluster.scheduler_address])
    assert dask.exit_code == local.exit_code, dask.output
    assert "on the Dask cluster's 2 worker thread(s)" in dask.stderr
    assert sorted(tree(tmp_path / "dask")) == sorted(FIT_OUTPUTS)
    assert tree(tmp_path / "dask") == tree(tmp_path / "local")  # recipe.toml, fit.csv, fit-stats.csv, fit.png
    # the design was measured on the cluster (nothing cached beforehand) and cached alike
    assert tree(tmp_path / "cache-dask") == tree(tmp_path / "cache-local")


COMMANDS = {
    "analyse": lambda grains, tmp: ["analyse", str(grains), "--csv", str(tmp / "out.csv")],
    "fit": lambda grains, tmp: ["fit", str(RF_SAND), "--out", str(tmp / "out"), *FIT_ARGS],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("address, words", [
    ("http://node12", "not a Dask scheduler address; give tcp://HOST:PORT"),
    ("tcp://node12", "not a Dask scheduler address"),
    ("tcp://node12:99999", "not a Dask scheduler address"),
    ("tcp://127.0.0.1:9", "cannot connect to the Dask scheduler at tcp://127.0.0.1:9"),
])
def test_a_bad_or_unreachable_scheduler_is_one_line_before_any_work(command, address, words, grains, runner,
                                                                     tmp_path, monkeypatch):
    monkeypatch.setattr("grainforge.runtime.cluster.CONNECT_TIMEOUT", "1s")
    t0 = time.monotonic()
    res = runner.invoke(cli, [*COMMANDS[command](grains, tmp_path), "--scheduler", address])
    assert res.exit_code == 2, res.output
    assert words in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written
    assert time.monotonic() - t0 < 30


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_scheduler_with_workers_missing_dask_or_another_version_is_refused(command, cluster, grains, runner,
                                                                           tmp_path, monkeypatch):
    args = [*COMMANDS[command](grains, tmp_path), "--scheduler", cluster.scheduler_address]
    res = runner.invoke(cli, [*args, "--workers", "2"])
    assert res.exit_code == 2 and "--workers is for the local processes" in res.stderr, res.output
    # the workers run this grainforge; this process pretends to run another
    monkeypatch.setattr("grainforge.runtime.cluster.__version__", "0.0.0+other")
    res = runner.invoke(cli, args)
    import grainforge

    assert res.exit_code == 2, res.output
    assert f"runs grainforge {grainforge.__version__}, this process grainforge 0.0.0+other" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    res = runner.invoke(cli, args)
    assert res.exit_code == 2 and "pip install 'grainforge[dask]'" in res.stderr, res.output
    assert list(tmp_path.iterdir()) == []


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def own_scheduler():
    """A scheduler and one worker as separate processes (``dask scheduler``, ``dask worker``), to be killed."""
    dask = str(Path(sys.executable).with_name("dask"))
    if not Path(dask).exists():
        pytest.skip("no dask command line next to the interpreter")
    address = f"tcp://127.0.0.1:{_free_port()}"
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                               "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        procs.append(subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                                       "--no-dashboard", "--no-nanny"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with distributed.Client(address, timeout="60s", set_as_default=False) as client:
            client.wait_for_workers(1, timeout=60)
        yield address, procs[0]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=30)


def _bar_that_kills(real_bar, scheduler):
    """A progress bar like ``real_bar`` that kills the scheduler process as the first result comes in."""

    def bar(**kw):
        wrap = real_bar(**kw)

        def it(items):
            for k, item in enumerate(wrap(items)):
                if k == 0:
                    scheduler.kill()
                    scheduler.wait(timeout=30)
                yield item

        return it

    return bar


def test_a_scheduler_lost_mid_run_is_one_line_exit_1_and_nothing_written(own_scheduler, grains, runner, tmp_path,
                                                                          monkeypatch):
    import grainforge.cli.progress as progress

    address, scheduler = own_scheduler
    monkeypatch.setattr("grainforge.runtime.cluster.CONNECT_TIMEOUT", "2s")
    monkeypatch.setattr(progress, "progress_bar", _bar_that_kills(progress.progress_bar, scheduler))
    t0 = time.monotonic()
    res = runner.invoke(cli, ["analyse", str(grains), "--csv", str(tmp_path / "out.csv"), "--scheduler", address])
    assert res.exit_code == 1, res.output
    assert f"lost the Dask scheduler at {address}" in res.stderr and "nothing written" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert list(tmp_path.iterdir()) == []
    assert time.monotonic() - t0 < 60


@pytest.mark.parametrize("sig, code, line", [(signal.SIGINT, 130, "Interrupted."), (signal.SIGTERM, 143, "Terminated.")],
                         ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_a_fit_on_the_cluster_stops_it_and_its_tasks(sig, code, line, cluster, tmp_path):
    """A real `grainforge fit --scheduler` process (500 twins: minutes of work) signalled mid-run: its line, its
    code, nothing in --out, and the cluster's tasks cancelled."""
    exe = Path(sys.executable).with_name("grainforge")
    out = tmp_path / "out"
    proc = subprocess.Popen([str(exe), "fit", str(RF_SAND), "--out", str(out), *FIT_ARGS, "--cache-dir",
                             str(tmp_path / "cache"), "--scheduler", cluster.scheduler_address],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not any(client.processing().values()):
                time.sleep(0.1)  # until the fit's grains run on the workers
            assert any(client.processing().values()), "the fit never reached the cluster"
            t0 = time.monotonic()
            proc.send_signal(sig)
            _, err = proc.communicate(timeout=30)
            assert time.monotonic() - t0 < 10
            assert proc.returncode == code, err
            assert err.strip().splitlines()[-1] == line, err
            assert not out.exists()
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and any(client.processing().values()):
                time.sleep(0.2)
            assert not any(client.processing().values())  # its tasks were dropped, not left running on
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_bad_file_is_named_as_the_local_run_names_it(cluster, grains, runner, tmp_path):
    """The workers measure copies of the files: an error still names the file as given, in the local run's line."""
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "a.stl").write_bytes((grains / "fso-0000.stl").read_bytes())
    (folder / "b.stl").write_bytes((grains / "fso-0001.stl").read_bytes()[:1000])  # truncated
    local = runner.invoke(cli, ["analyse", str(folder), "--workers", "1"])
    dask = runner.invoke(cli, ["analyse", str(folder), "--scheduler", cluster.scheduler_address])
    assert local.exit_code == dask.exit_code == 2, (local.output, dask.output)
    assert dask.stderr == local.stderr and str(folder / "b.stl") in dask.stderr, dask.stderr


def test_a_batch_that_lost_its_scheduler_keeps_its_grains_and_resumes_to_the_local_run(own_scheduler, runner,
                                                                                        tmp_path, monkeypatch):
    import grainforge.cli.batch as batch_cli

    address, scheduler = own_scheduler
    monkeypatch.setattr("grainforge.runtime.cluster.CONNECT_TIMEOUT", "2s")
    recipe = tmp_path / "pop.toml"
    recipe.write_text(RECIPE)
    real_bar = batch_cli.progress_bar
    monkeypatch.setattr(batch_cli, "progress_bar", _bar_that_kills(real_bar, scheduler))
    out = tmp_path / "dask"
    res = runner.invoke(cli, ["batch", str(recipe), "--out", str(out), "--scheduler", address])
    assert res.exit_code == 1, res.output
    assert f"lost the Dask scheduler at {address}" in res.stderr and "--resume" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert not (out / "manifest.csv").exists() and any(out.glob("*.stl"))
    monkeypatch.setattr(batch_cli, "progress_bar", real_bar)
    res = runner.invoke(cli, ["batch", str(recipe), "--out", str(out), "--resume", "--workers", "1"])
    assert res.exit_code == 0, res.output
    run_batch(parse_recipe(RECIPE, source=str(recipe)), tmp_path / "local", workers=1)
    assert tree(out) == tree(tmp_path / "local")
