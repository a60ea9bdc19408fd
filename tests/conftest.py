"""Shared test settings.

Hypothesis runs a bounded number of examples with no per-example deadline
(the machine has 2 cores; timing belongs in benchmarks/, never in tests).
"""

import os
import signal

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "default", max_examples=25, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("thorough", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("GRAINFORGE_HYPOTHESIS", "default"))

# The signal tests interrupt commands as a terminal's Ctrl-C does. A suite started in the background of a
# non-interactive shell (`nohup make test &`) inherits SIGINT ignored, and so would every command it starts:
# a command rightly leaves an inherited ignored SIGINT alone, and six signal tests then fail. The suite runs
# as a foreground job would: SIGINT at Python's default in the test processes (and the commands they start).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(config, items):
    """The tests marked slow first, each group in its collected order.

    ``make test`` hands the tests to two processes one at a time, in this order, to whichever is
    free (pytest-xdist's ``--dist load --maxschedchunk 1``). Starting with the long tests leaves
    short ones for the end, so that no process is left running one long test alone while the
    other idles. (Work stealing, ``--dist worksteal``, did leave one: it splits the queue in two
    halves up front and steals from the tail, so the long tests at the head stay on one process.)"""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture
def runner():
    from click.testing import CliRunner

    return CliRunner()


@pytest.fixture(scope="session")
def angular_grains(tmp_path_factory):
    """A folder of three small angular grains (2 mm, subdivisions 3) with their manifest."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    out = tmp_path_factory.mktemp("angular") / "grains"
    res = CliRunner().invoke(cli, ["generate", "angular", "--count", "3", "--size", "2", "--subdivisions", "3",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def require_long_lane(why: str) -> None:
    """Skip a test of the opt-in long lane unless ``GRAINFORGE_LONG=1`` (``GRAINFORGE_LONG=1 make test``); ``why``
    says what it costs and what checks the same in the suite meanwhile."""
    if os.environ.get("GRAINFORGE_LONG") != "1":
        pytest.skip(f"{why}: set GRAINFORGE_LONG=1")


def require_engine(executable: str, package: str = "yade python3-yade liggghts lammps openmpi-bin") -> str:
    """The path of a DEM engine (or mpirun) the test needs: skipped with the reason where it is not
    installed, a failure where GRAINFORGE_REQUIRE_ENGINES=1 (CI: a missing engine is a failure)."""
    import shutil

    path = shutil.which(executable)
    if path is None:
        reason = f"{executable} not installed (apt-get install {package})"
        if os.environ.get("GRAINFORGE_REQUIRE_ENGINES") == "1":
            pytest.fail(reason + " but GRAINFORGE_REQUIRE_ENGINES=1")
        pytest.skip(reason)
    return path


@pytest.fixture
def three_cri_grains(tmp_path):
    """A `generate` folder of three 2 mm rough-angular CRI grains at subdivisions 3 (the simulate tests' inputs)."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    out = tmp_path / "g"
    r = CliRunner().invoke(cli, ["generate", "cri", "--out", str(out), "--count", "3", "--size", "2",
                                 "--subdivisions", "3", "--preset", "rough-angular"])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="session")
def grain_files(tmp_path_factory):
    """A folder of three grains of 4 mm-ish scale: an FSO, a CRI and a DPA grain (seeds 0, 1, 2)."""
    import grainforge
    import grainforge.io

    d = tmp_path_factory.mktemp("grains")
    for i, method in enumerate(["fso", "cri", "dpa"]):
        g = getattr(grainforge, method)(rng=i).scaled(4.0)
        grainforge.io.write_mesh(g, d / f"{method}-{i:04d}.stl")
    return d


@pytest.fixture(scope="module")
def cluster():
    """A ``dask.distributed`` LocalCluster of 2 single-threaded worker processes, one per test module (what
    ``--scheduler`` runs on; the dashboard on a random port, so clusters of two test processes never collide).
    Skipped where Dask distributed is not installed."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=40) as c:
        yield c


def refused_in_one_line(result, *words: str) -> str:
    """The CLI's refusal of a user's mistake, as every command makes it: exit 2, one line on stderr (each of
    ``words`` in it), no traceback.  ``result`` is a click ``Result`` (``runner.invoke``) or a
    ``subprocess.CompletedProcess`` run with ``text=True``; returns the line."""
    code = getattr(result, "exit_code", getattr(result, "returncode", None))
    err = result.stderr or ""
    assert code == 2, f"exit {code}:\n{err}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err + (getattr(result, "output", None) or getattr(result, "stdout", "") or "")
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]
