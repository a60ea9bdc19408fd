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
