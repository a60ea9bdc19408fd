"""Child processes: started with SIGINT blocked and single-threaded BLAS, watching the process that made them,
and stopped with everything below them.

The pools of :mod:`grainforge.runtime.workers` and the DEM engines of :mod:`grainforge.simulate.process` start
their children with these habits and stop them through :func:`kill_process_tree` (the one kill path). Linux's
``/proc`` (its documented interface to processes) is read where the standard library has no way at all: to
list a process's descendants and a session's members (:func:`kill_process_tree`, which stops DEM engines and
their ``mpirun`` ranks), and to find the fork server when a pool's start-up is cut short
(:func:`stop_forkserver`; ``multiprocessing`` neither gives its pid nor stops it). Elsewhere those two do what
the standard library can (the root process alone; nothing).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

__all__ = ["single_threaded_children", "sigint_blocked", "THREAD_VARS", "WATCH_INTERVAL", "watch_parent",
           "die_with_parent", "owned_command", "run_owned", "pid_alive", "stop_forkserver", "kill_process_tree", "TERMINATE_GRACE",
           "stop_processes", "quiet_stderr", "remove_leftovers"]

#: seconds between a worker's checks that the process that made its pool is alive
WATCH_INTERVAL = 0.25

#: BLAS/OpenMP thread limits given to pool workers (unless the user set them): one worker = one core.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def single_threaded_children() -> Iterator[None]:
    """Set the BLAS thread limits to 1 while worker processes start, then restore them.

    :func:`process_pool` starts the fork server (whose environment its
    workers inherit) and, without a fork server, the workers inside it.

    Yields
    ------
    None

    Examples
    --------
    >>> import os
    >>> before = os.environ.get("OMP_NUM_THREADS")
    >>> with single_threaded_children():
    ...     inside = os.environ["OMP_NUM_THREADS"]
    >>> inside if before is None else "1"
    '1'
    >>> os.environ.get("OMP_NUM_THREADS") == before
    True
    """
    saved = {k: os.environ.get(k) for k in THREAD_VARS}
    for k, v in saved.items():
        if v is None:
            os.environ[k] = "1"
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)


@contextmanager
def sigint_blocked() -> Iterator[None]:
    """Block SIGINT in this thread (POSIX), so processes started meanwhile inherit it blocked; a Ctrl-C
    that arrives meanwhile is delivered when the block ends.

    Yields
    ------
    None
        Inside the block SIGINT is blocked (nothing is blocked where there is no ``pthread_sigmask``).

    Examples
    --------
    >>> with sigint_blocked():
    ...     pass
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet reaped, counts as dead).

    Parameters
    ----------
    pid : int
        Process id.

    Returns
    -------
    bool

    Examples
    --------
    >>> pid_alive(os.getpid())
    True
    """
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            state = fh.read().rsplit(b")", 1)[1].split()[0]
        return state not in (b"Z", b"X")
    except (OSError, IndexError):
        return True


def die_with_parent() -> None:
    """Ask the kernel to SIGKILL this process when its parent dies (Linux ``PR_SET_PDEATHSIG``; elsewhere nothing).

    Used by pool workers (:func:`watch_parent`); engine processes are owned through :func:`run_owned`.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the owner decides
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass


def owned_command(cmd: Sequence[str]) -> list[str]:
    """``cmd`` run under :func:`run_owned` on behalf of this process: the command line to start instead.

    The engine processes are started this way, not with a pre-exec hook of ``subprocess`` (which Python documents as unsafe
    once threads exist, and whose ``PR_SET_PDEATHSIG`` follows the *thread* that forked, so an engine started
    from a pool thread would be killed when that thread ends, and kept when the process dies otherwise).

    Parameters
    ----------
    cmd : sequence of str
        The command and its arguments.

    Returns
    -------
    list of str
        This Python running :func:`run_owned` with this process as the owner, then ``cmd``.

    Examples
    --------
    >>> owned_command(["yade", "-x", "run.py"])[-3:]
    ['yade', '-x', 'run.py']
    """
    return [sys.executable, "-c", "from grainforge.runtime.children import run_owned; run_owned()",
            str(os.getpid()), *map(str, cmd)]


def run_owned(argv: Sequence[str] | None = None, *, poll: float = 0.2) -> None:
    """Run a command for an owner process and end with it: ``python -c ... OWNER CMD...`` (:func:`owned_command`).

    This launcher, single-threaded and started in a session of its own, ignores SIGINT (Ctrl-C reaches the
    owner, which decides), takes SIGTERM at its default, starts ``CMD`` (which inherits both), and waits for it,
    polling the owner every ``poll`` seconds: when the owner is gone (killed, even by SIGKILL), it kills its
    whole process group, the command and what the command started. It ends as the command ended: the same
    exit status, or the same signal.

    Parameters
    ----------
    argv : sequence of str, optional
        The owner's pid, then the command; ``sys.argv[1:]`` when None.
    poll : float
        Seconds between two looks at the owner.
    """
    import subprocess

    args = list(sys.argv[1:] if argv is None else argv)
    owner, cmd = int(args[0]), args[1:]
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    proc = subprocess.Popen(cmd)
    while True:
        try:
            status = proc.wait(timeout=poll)
            break
        except subprocess.TimeoutExpired:
            if not pid_alive(owner) or os.getppid() != owner:
                os.killpg(0, signal.SIGKILL)  # the command, its children and this launcher
    if status < 0:  # ended by a signal: end by it too
        signal.signal(-status, signal.SIG_DFL)
        os.kill(os.getpid(), -status)
    sys.exit(status)


def watch_parent(owner: int) -> None:
    """Pool-worker initializer: exit as soon as process ``owner`` (the pool's maker) is gone.

    On Linux the kernel also sends SIGKILL when the worker's parent dies
    (``PR_SET_PDEATHSIG``); the parent of a fork-server worker is the fork
    server, not the owner, so a daemon thread polls the owner as well.

    Parameters
    ----------
    owner : int
        Process id of the pool's maker.
    """
    die_with_parent()

    def watch():
        while pid_alive(owner):
            time.sleep(WATCH_INTERVAL)
        os._exit(1)

    if not pid_alive(owner):
        os._exit(1)
    threading.Thread(target=watch, name="grainforge-watch-parent", daemon=True).start()


@contextmanager
def quiet_stderr() -> Iterator[None]:
    """File descriptor 2 on /dev/null meanwhile (for a child process started inside: it keeps it).

    Yields
    ------
    None
        Inside the block this process's standard error goes to ``/dev/null``; it is restored after.
    """

    try:
        sys.stderr.flush()
    except (AttributeError, ValueError, OSError):
        pass
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


#: seconds a stopped worker has to exit after SIGTERM before it gets SIGKILL
TERMINATE_GRACE = 1.0


def stop_processes(procs: Sequence) -> None:
    """SIGTERM each of ``procs``, SIGKILL those still there after :data:`TERMINATE_GRACE`, and join them.

    Parameters
    ----------
    procs : sequence of multiprocessing.Process
        Started processes (those already ended are only joined).
    """
    for p in procs:
        if p.exitcode is None:
            p.terminate()
    deadline = time.monotonic() + TERMINATE_GRACE
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs:
        if p.exitcode is None:
            p.kill()
            p.join(TERMINATE_GRACE)


def _proc_stats():
    """``(pid, fields)`` of every process, ``fields`` its ``/proc/PID/stat`` after the command name (state,
    parent, group, session, ...); nothing where there is no ``/proc``."""
    try:
        entries = os.listdir("/proc")
    except OSError:
        return
    for name in entries:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                fields = fh.read().rsplit(b")", 1)[1].split()
        except (OSError, IndexError):
            continue
        yield int(name), fields


def _children_of(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux ``/proc``; empty elsewhere)."""
    return [p for p, fields in _proc_stats() if int(fields[1]) == pid]


def _descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (children first, then theirs; Linux ``/proc``, empty elsewhere)."""
    found, todo = [], [pid]
    while todo:
        kids = _children_of(todo.pop())
        found += kids
        todo += kids
    return found


def _session_members(sid: int) -> list[int]:
    """Live processes (zombies aside) of session ``sid`` (Linux ``/proc``; empty elsewhere)."""
    return [p for p, fields in _proc_stats() if int(fields[3]) == sid and fields[0] not in (b"Z", b"X")]


#: passes over a killed session's members (each a few ms): a process forked while the previous pass ran
SESSION_PASSES = 20


def kill_process_tree(pid: int) -> None:
    """SIGKILL process ``pid``, every process below it and, when it leads a process group of its own
    (``start_new_session=True``), that group and every process of its session: the one kill path of
    grainforge's child processes.

    ``pid`` is stopped (SIGSTOP) first, so it cannot start new children while they are listed. Its
    descendants can still fork while they are killed one by one, and a launcher may put them in process
    groups of their own (Open MPI's ``mpirun`` puts each rank in one): an orphan forked at that moment
    escapes the tree and the group. No process leaves a session but by ``setsid``, so when ``pid`` leads
    a session of its own, its members are killed pass after pass until none is left. The caller still
    reaps ``pid`` if it is its child (``Popen.wait``). A process already gone is no error. Never signals
    this process's own group or session.

    Parameters
    ----------
    pid : int
        The root process (a child of this process, typically started with ``start_new_session=True``).

    Examples
    --------
    >>> import subprocess, sys
    >>> proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    >>> kill_process_tree(proc.pid)
    >>> proc.wait()
    -9
    """
    try:
        group = os.getpgid(pid)
    except ProcessLookupError:
        return
    own_group = group == pid and group != os.getpgrp()
    try:
        os.kill(pid, signal.SIGSTOP)
    except ProcessLookupError:
        return
    for child in _descendants(pid):
        try:
            os.kill(child, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        if own_group:
            os.killpg(pid, signal.SIGKILL)
        else:
            os.kill(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        own_session = os.getsid(0) == pid
    except OSError:
        own_session = True
    if own_group and not own_session:
        for _ in range(SESSION_PASSES):
            members = [m for m in _session_members(pid) if m != os.getpid()]
            if not members:
                break
            for m in members:
                try:
                    os.kill(m, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass


def _forkserver_pids() -> list[int]:
    """Children of this process that are multiprocessing fork servers (found by their command line
    in Linux ``/proc``; empty elsewhere)."""
    found = []
    for pid in _children_of(os.getpid()):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmdline = fh.read()
        except OSError:
            continue
        if b"multiprocessing.forkserver" in cmdline:
            found.append(pid)
    return found


def stop_forkserver() -> None:
    """Kill this process's multiprocessing fork server and every process it forked (workers, also
    half-started ones) with :func:`kill_process_tree`.

    The fork server is found as the child of this process running ``multiprocessing.forkserver``.
    The next pool starts a new one: ``multiprocessing.forkserver.ensure_running()`` reaps a dead fork
    server and starts another.
    """
    for pid in _forkserver_pids():
        if pid_alive(pid):
            kill_process_tree(pid)


def remove_leftovers(folder, prefix: str, *, suffix: str = "") -> list:
    """Remove what killed processes left in ``folder``: files and folders named ``prefix`` + PID + a non-digit
    + anything + ``suffix``, whose process PID no longer runs (:func:`pid_alive`).

    The one clean-up of the three kinds of leftovers a killed grainforge leaves: staging folders
    (``.grainforge-staging-PID-…``), a tray's temporary print files (``.NAME.pidPID.….tmp``) and the
    ``mpirun`` session folders in the temporary directory. What a running process owns is kept.

    Parameters
    ----------
    folder : path-like
        Where to look (nothing happens when it is not a folder).
    prefix : str
        The names' beginning, before the PID.
    suffix : str
        The names' end.

    Returns
    -------
    list of Path
        What was removed.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> dead = 2 ** 22 + 7  # above Linux's largest pid: no such process
    >>> _ = (d / f".x.pid{dead}.ab.tmp").write_text(""); _ = (d / f".x.pid{os.getpid()}.cd.tmp").write_text("")
    >>> [p.name for p in remove_leftovers(d, ".x.pid", suffix=".tmp")] == [f".x.pid{dead}.ab.tmp"]
    True
    """
    import re
    import shutil
    from pathlib import Path

    folder = Path(folder)
    removed: list = []
    if not folder.is_dir():
        return removed
    pattern = re.compile(re.escape(prefix) + r"(\d+)\D.*" + re.escape(suffix), flags=re.S)
    for p in sorted(folder.iterdir()):
        m = pattern.fullmatch(p.name)
        if m is None or pid_alive(int(m.group(1))):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    return removed
