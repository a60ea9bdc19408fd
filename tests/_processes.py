"""Process helpers shared by the tests that run real ``grainforge`` processes."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path


def _live_processes() -> dict[int, list[str]]:
    """The fields of /proc/PID/stat after the command name (state, parent, group, session, ...) of every
    process that is not a zombie."""
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] not in ("Z", "X"):
            out[int(entry.name)] = fields
    return out


def session_processes(sid: int) -> list[int]:
    """Processes (not zombies) whose session is ``sid``."""
    return [pid for pid, fields in _live_processes().items() if int(fields[3]) == sid]  # fields[3]: session id


def kill_sessions(started: list[subprocess.Popen]) -> None:
    """Kill every process of the sessions ``started`` made (each started with ``start_new_session``),
    and reap them; empties the list."""
    while started:
        proc = started.pop()
        for pid in session_processes(proc.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def child_processes(pid: int) -> list[int]:
    """Processes (not zombies) descended from ``pid``, at any depth."""
    parent = {p: int(fields[1]) for p, fields in _live_processes().items()}  # fields[1]: parent pid
    found, frontier = [], {pid}
    while frontier:
        frontier = {p for p, pp in parent.items() if pp in frontier}
        found += sorted(frontier)
    return found


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] not in "ZX"
    except OSError:
        return False


def assert_gone(pids, wait: float = 5.0) -> None:
    """Every process of ``pids`` ends within ``wait`` seconds (those left are killed, then it fails)."""
    import time

    deadline = time.monotonic() + wait
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in pids if alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"engine processes left behind: {left}"


def interrupt_simulate_run(args: list[str], tmp_path: Path) -> None:
    """``grainforge simulate ARGS --out o --quick`` with a stand-in Yade that starts a child and waits; SIGINT to
    the command while the engine runs: exit 130 with ``Interrupted.`` last, the engine and its child gone (the
    engine's whole process group: an mpirun's ranks are its children), and nothing in the working folder."""
    import sys
    import time

    work = tmp_path / "work"
    work.mkdir()
    fake = tmp_path / "yade"
    fake.write_text(f'#!/bin/sh\nsleep 60 &\necho $! > "{tmp_path}/child.pid"\necho $$ > "{tmp_path}/engine.pid"\n'
                    "wait\n")
    fake.chmod(0o755)
    proc = subprocess.Popen([sys.executable, "-c", "from grainforge.cli.main import main; main()", "simulate",
                             *args, "--out", "o", "--quick"], cwd=work, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                            env=dict(os.environ, GRAINFORGE_YADE=str(fake)))
    try:
        deadline = time.monotonic() + 120  # a hang guard
        while not (tmp_path / "child.pid").exists() or not (tmp_path / "engine.pid").exists():
            assert proc.poll() is None, proc.communicate()[1].decode()
            assert time.monotonic() < deadline, "the stand-in engine never started"
            time.sleep(0.05)
        time.sleep(0.3)
        pids = [int((tmp_path / f).read_text()) for f in ("child.pid", "engine.pid")]
        os.kill(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err.decode()
        assert err.decode().strip().splitlines()[-1] == "Interrupted."
        assert_gone(pids)
        assert list(work.iterdir()) == []
    finally:
        kill_sessions([proc])
