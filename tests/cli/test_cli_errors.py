"""What a command says when it stops on an exception (docs/cli-contract.md, *Exit codes*).

- what the user can fix (a ``grainforge.errors.GrainforgeError``, an ``OSError`` on the user's own path): one
  line, exit code 2, the library's setting named by its option (``overwrite`` -> ``--overwrite``);
- anything else is a bug in grainforge: one line naming the exception and the file its traceback was written
  to, exit code 1; the file holds the whole traceback.

Run: ``.venv/bin/python -m pytest tests/cli/test_cli_errors.py -q -n 0``
"""

from __future__ import annotations

import os
import pickle
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from grainforge.cli.main import cli
from grainforge.errors import FileFormatError, GrainforgeError, InputError, OutputExistsError

#: the one line of a bug, and the traceback's file it names
BUG_LINE = re.compile(r"^Error: a bug in grainforge \((\w+)(?:: (.*))?\); the traceback is in (\S+): please report it "
                      r"with that file$")


def _boom(*args, **kwargs):
    raise TypeError("unsupported operand type(s) for +: 'int' and 'str'")


@pytest.fixture
def temp_dir(tmp_path, monkeypatch):
    """The system's temporary folder, for the command, is ``tmp_path/temp``."""
    folder = tmp_path / "temp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def test_a_bug_is_one_line_exit_1_and_its_traceback_in_a_file(runner, tmp_path, temp_dir, monkeypatch):
    """A TypeError raised inside the library (a bug, not the user's input): exit 1, one line naming the
    exception and the file, which holds the whole traceback down to the function that raised it."""
    import grainforge.population.generate as generate

    monkeypatch.setattr(generate, "write_run", _boom)
    r = runner.invoke(cli, ["generate", "fso", "--subdivisions", "2", "--out", str(tmp_path / "g")])
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 1 and len(lines) == 1, r.stderr
    m = BUG_LINE.match(lines[0])
    assert m and m.group(1) == "TypeError" and "'int' and 'str'" in m.group(2), lines[0]
    report = Path(m.group(3))
    assert report == temp_dir / f"grainforge-crash-{os.getpid()}.txt"
    text = report.read_text()
    assert "Traceback (most recent call last)" in text and "in _boom" in text, text
    assert text.rstrip().endswith("TypeError: unsupported operand type(s) for +: 'int' and 'str'")
    assert [p.name for p in temp_dir.iterdir()] == [report.name]  # written whole: no temporary file left
    assert not (tmp_path / "g").exists()


@pytest.mark.slow  # a real process
def test_a_bug_in_the_console_script_is_one_line_exit_1(tmp_path):
    """The same, as the console script runs: no traceback on stderr, exit 1, the traceback's file."""
    temp = tmp_path / "temp"
    temp.mkdir()
    code = ("import grainforge.population.generate as g\n"
            "def boom(*a, **k):\n    raise TypeError('boom')\n"
            "g.write_run = boom\n"
            "from grainforge.cli.main import main\nmain()\n")
    env = {**os.environ, "TMPDIR": str(temp)}
    r = subprocess.run([sys.executable, "-c", code, "generate", "fso", "--subdivisions", "2", "--out", "g"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    m = BUG_LINE.match(lines[0])
    assert m and m.group(1) == "TypeError" and m.group(2) == "boom", lines[0]
    text = Path(m.group(3)).read_text()
    assert Path(m.group(3)).parent == temp and "in boom" in text and text.rstrip().endswith("TypeError: boom"), text
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize("exc, line", [
    (InputError("count must be positive"), "Error: count must be positive"),
    (OutputExistsError("out/a.stl exists; use {overwrite}", setting="overwrite"),
     "Error: out/a.stl exists; use --overwrite"),
    (FileFormatError.wrap("scan.tif", ValueError("not a TIFF file")), "Error: scan.tif: cannot read it (not a TIFF file)"),
    (InputError("check {raw_shape} and {voxel_size}", setting=("raw_shape", "voxel_size")),
     "Error: check --raw-shape and --voxel-size-um"),
    (PermissionError(13, "Permission denied", "out/a.stl"), "Error: out/a.stl: permission denied"),
    (OSError(28, "No space left on device", "out/a.stl"), "Error: out/a.stl: no space left on device"),
    (FileNotFoundError("Yade is not installed"), "Error: Yade is not installed"),
])
def test_what_the_user_can_fix_is_one_line_exit_2(runner, tmp_path, temp_dir, monkeypatch, exc, line):
    """A GrainforgeError or an OSError about the user's path: exit 2, one line (the setting named by its
    option), no traceback file."""
    import grainforge.population.generate as generate

    def refuse(*args, **kwargs):
        raise exc

    monkeypatch.setattr(generate, "write_run", refuse)
    r = runner.invoke(cli, ["generate", "fso", "--subdivisions", "2", "--out", str(tmp_path / "g")])
    assert r.exit_code == 2 and r.stderr.strip() == line, r.stderr
    assert list(temp_dir.iterdir()) == []


@pytest.mark.parametrize("exc", [ValueError("could not convert string to float: 'x'"), OSError(9, "Bad file descriptor"),
                                 KeyError("volume"), AssertionError()])
def test_an_error_grainforge_did_not_refuse_is_a_bug(runner, tmp_path, temp_dir, monkeypatch, exc):
    """A bare ValueError (a third-party library's, not a refusal), an OSError that is no user's path, a
    KeyError: a bug, exit 1."""
    import grainforge.population.generate as generate

    def fail(*args, **kwargs):
        raise exc

    monkeypatch.setattr(generate, "write_run", fail)
    r = runner.invoke(cli, ["generate", "fso", "--subdivisions", "2", "--out", str(tmp_path / "g")])
    lines = r.stderr.strip().splitlines()
    assert r.exit_code == 1 and len(lines) == 1 and BUG_LINE.match(lines[0]), r.stderr
    assert type(exc).__name__ in lines[0]


def test_the_library_names_settings_as_python_does():
    """Outside a command, a message names the setting (``overwrite``), not the option."""
    e = OutputExistsError("out/a.stl exists; use {overwrite}", setting="overwrite")
    assert str(e) == "out/a.stl exists; use overwrite" and isinstance(e, FileExistsError)
    assert isinstance(InputError("x"), ValueError) and isinstance(FileFormatError("x"), InputError)
    assert issubclass(InputError, GrainforgeError)


def test_the_refusals_are_grainforge_errors_and_cross_a_process_pool():
    """The library's own refusals are InputErrors (still ValueErrors), and pickle with their settings."""
    from grainforge.params import ParameterError
    from grainforge.population.recipe import RecipeError
    from grainforge.runtime.estimate import TooLargeError
    from grainforge.simulate.sweep import JournalMismatch

    for cls in (ParameterError, RecipeError, TooLargeError, JournalMismatch):
        assert issubclass(cls, InputError) and issubclass(cls, ValueError), cls
    e = pickle.loads(pickle.dumps(InputError("use {resume}", setting="resume")))
    assert str(e) == "use resume" and e.setting == "resume"
    e = pickle.loads(pickle.dumps(OutputExistsError("a exists; use {overwrite}", setting="overwrite")))
    assert str(e) == "a exists; use overwrite" and isinstance(e, FileExistsError)
    p = pickle.loads(pickle.dumps(ParameterError("amplitude", "must be <= 0.3")))
    assert p.setting == "amplitude" and str(p) == "amplitude must be <= 0.3"


def test_importing_the_command_line_changes_no_signal_handler():
    """Another program (a notebook, a test) imports the command line: its signal handlers are its own."""
    code = ("import signal\nbefore = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]\n"
            "import grainforge.cli.main as m\nm.cli\n"
            "assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == before\n"
            "assert before == [signal.default_int_handler, signal.SIG_DFL]\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert r.returncode == 0, r.stderr
