"""Every ``--quick`` command shown in README.md and the guides runs as written and passes its own checks.

A new user's first ``simulate`` run is the quick one the docs show as the check of the set-up: it must end
with exit 0 (a run that fails its own check exits 3), print its result line and write its outputs.  The
commands are read from the pages' shell blocks with the doc-path test's reader; only the output folder is
moved into the test's temporary folder (``--out``), so a command is run exactly as a user would copy it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import require_engine
from test_doc_paths import PAGES, SHELL_LANGS, fenced_blocks, shell_commands

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow


def quick_commands() -> list[tuple[str, list[str]]]:
    """(page, tokens) of every ``grainforge ... --quick`` command in a shell block of the README and the guides."""
    found = []
    for page in PAGES:
        for lang, body in fenced_blocks(page.read_text()):
            if lang not in SHELL_LANGS:
                continue
            for tokens in shell_commands(body):
                if tokens[0] == "grainforge" and "--quick" in tokens:
                    found.append((page.relative_to(ROOT).as_posix(), tokens))
    return found


def _distinct(found):
    """One of each command, its output folder aside (the README and a guide may show the same check)."""
    seen, out = set(), []
    for page, tokens in found:
        key = tuple(t for k, t in enumerate(tokens) if not (k and tokens[k - 1] == "--out") and t != "--out")
        if key not in seen:
            seen.add(key)
            out.append((page, tokens))
    return out


COMMANDS = _distinct(quick_commands())


def test_the_docs_show_a_quick_command_for_every_simulate_test():
    """The quick checks a user is shown cover every test and the tilt calibration, the triaxial test in both
    engines (the triaxial calibration's wiring is tested on a stand-in engine, and in Yade on the long lane)."""
    shown = {" ".join(t[1:3]) if t[1:3] != ["simulate", "calibrate"] else " ".join(t[1:4]) for _, t in COMMANDS}
    assert {"simulate repose", "simulate tilt", "simulate triaxial", "simulate calibrate tilt"} <= shown, shown
    engines = {("liggghts" if "liggghts" in t else "yade") for _, t in COMMANDS if t[2] == "triaxial"}
    assert engines == {"yade", "liggghts"}


def _with_out(tokens: list[str], out: Path) -> list[str]:
    args = list(tokens[1:])
    assert "--out" in args, f"a documented quick command without --out: {' '.join(tokens)}"
    args[args.index("--out") + 1] = str(out)
    return args


@pytest.mark.parametrize("page, tokens", COMMANDS, ids=[f"{p}: {' '.join(t[1:])}" for p, t in COMMANDS])
def test_a_documented_quick_command_passes_its_own_checks(page, tokens, tmp_path):
    require_engine("liggghts" if "liggghts" in tokens else "yade")
    if "--mpi" in tokens:
        require_engine("mpirun")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-c", "from grainforge.cli.main import main; main()",
                        *_with_out(tokens, out)], cwd=ROOT, stdin=subprocess.DEVNULL, capture_output=True,
                       text=True, env=dict(os.environ, COLUMNS="120"), timeout=1200)
    assert r.returncode == 0, f"{page}: {' '.join(tokens)} exited {r.returncode}:\n{r.stderr[-2000:]}"
    assert "check failed" not in r.stderr and "Traceback" not in r.stderr
    assert str(out) in r.stdout  # the result line names where the outputs are
    csvs = sorted(p.name for p in out.glob("*.csv"))
    assert csvs and any(p.suffix == ".png" for p in out.iterdir()), sorted(p.name for p in out.iterdir())
