"""Process pools for the local parallel jobs (batch, tray, calibration).

Two habits every pool shares:

- workers fork from a *fork server* that has imported the heavy modules once
  (``spawn`` where there is no fork server), so starting a worker costs
  milliseconds instead of a fresh interpreter's imports, and no state of the
  parent (open files, threads) leaks into them;
- workers run NumPy's BLAS single-threaded (unless the user set the thread
  variables): OpenBLAS otherwise starts one thread per core in *every*
  worker, so N workers would run N × cores busy threads on the cores;
- workers exit when the process that made the pool dies, even by SIGKILL
  (a watcher thread in each worker; on Linux also ``PR_SET_PDEATHSIG``), so a
  killed command leaves no processes behind.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

__all__ = ["process_pool", "single_threaded_children", "THREAD_VARS", "ordered_map", "watch_parent", "pid_alive",
           "close_pool", "stop_forkserver", "kill_process_tree"]

#: seconds between a worker's checks that the process that made its pool is alive
WATCH_INTERVAL = 0.25

#: BLAS/OpenMP thread limits given to pool workers (unless the user set them): one worker = one core.
THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def single_threaded_children() -> Iterator[None]:
    """Set the BLAS thread limits to 1 while worker processes start, then restore them.

    Workers (and the fork server) start when the first tasks are submitted,
    so wrap those submissions.

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

    Also used as ``preexec_fn`` of engine subprocesses (Yade), so a killed
    ``grainforge`` leaves no engine running.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the owner decides
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass


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
def _quiet_stderr() -> Iterator[None]:
    """File descriptor 2 on /dev/null meanwhile (for a child process started inside: it keeps it)."""

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


@functools.cache
def _pool_class():
    """:class:`concurrent.futures.ProcessPoolExecutor` with what :func:`close_pool` needs to know,
    recorded through public API only (made lazily: the class imports concurrent.futures).

    Its workers are the children this process started after the pool was made, so one process
    runs one pool at a time (as every grainforge command does)."""
    from concurrent.futures import ProcessPoolExecutor

    class Pool(ProcessPoolExecutor):
        """A ``ProcessPoolExecutor`` that remembers its size, its start method and the child processes
        this process had before it (so that its own workers are the children started since)."""

        def __init__(self, workers: int, mp_context, owner: int):
            import multiprocessing

            self.workers = int(workers)
            self.start_method = mp_context.get_start_method()
            self.children_before = {p.pid for p in multiprocessing.active_children()}
            super().__init__(max_workers=self.workers, mp_context=mp_context, initializer=watch_parent,
                             initargs=(owner,))

        def worker_processes(self) -> list:
            """The pool's live worker processes (``multiprocessing.Process`` objects)."""
            import multiprocessing

            return [p for p in multiprocessing.active_children() if p.pid not in self.children_before]

    return Pool


def process_pool(workers: int, preload: Sequence[str] = ()):
    """A ``ProcessPoolExecutor`` of ``workers`` processes started from a fork server.

    Workers exit by themselves when this process dies (see :func:`watch_parent`).
    Shut it down with :func:`close_pool`.

    Parameters
    ----------
    workers : int
        Number of worker processes.
    preload : sequence of str
        Modules the fork server imports once, before forking the workers.

    Returns
    -------
    concurrent.futures.ProcessPoolExecutor
        With ``workers``, ``start_method`` and ``worker_processes()`` for :func:`close_pool`.
    """
    import multiprocessing

    if "forkserver" in multiprocessing.get_all_start_methods():
        from multiprocessing import forkserver, resource_tracker

        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))
        # Ctrl-C reaches the whole process group: the fork server (its imports take seconds) and the
        # workers it forks must not die of it with a traceback. Started with SIGINT blocked, it and
        # they never see it (they inherit the mask); the owner decides and stops them. (The resource
        # tracker first: starting it unblocks SIGINT in this thread.)
        # The fork server imports NumPy (preload) once for all workers: it must start with the
        # BLAS thread limits of one worker = one core, or every worker inherits multithreaded BLAS.
        with _quiet_stderr():
            # the tracker outlives a killed owner and then unlinks the pool's semaphores; its report
            # of them ("leaked semaphore objects") is no news after a SIGKILL, and nothing else it
            # prints concerns the user
            resource_tracker.ensure_running()
        with sigint_blocked(), single_threaded_children():
            forkserver.ensure_running()
    else:
        ctx = multiprocessing.get_context("spawn")
    return _pool_class()(workers, ctx, os.getpid())


def ordered_map(fn: Callable[[Any], Any], items: Iterable[Any], *, workers: int, preload: Sequence[str] = (),
                inflight: int = 3, executor=None) -> Iterator[Any]:
    """``map(fn, items)`` on ``workers`` processes, results in input order, memory bounded.

    At most ``inflight × workers`` items are submitted ahead of the one being
    yielded, so ``items`` may be a long generator.  ``workers <= 1`` runs in
    this process.  An exception in ``fn`` is raised here, for its item, and
    the pool is shut down (pending work cancelled).  With ``executor`` (a
    :class:`grainforge.runtime.cluster.DaskExecutor`, say) the items run there
    instead, ``workers`` of them at a time; the executor stays open (its
    owner closes it), and an error or interrupt cancels the items submitted.

    Parameters
    ----------
    fn : callable
        A picklable function of one item (module level, for a process pool).
    items : iterable
        The items, consumed lazily.
    workers : int
        Processes (``<= 1``: in this process, no pool); with ``executor``, items in flight at once.
    preload : sequence of str, default ()
        Modules the fork server imports once (:func:`process_pool`).
    inflight : int, default 3
        Items submitted ahead per worker.
    executor : concurrent.futures.Executor, optional
        Run there instead of a new pool (left open).

    Yields
    ------
    object
        ``fn(item)`` for each item, in the order of ``items``.

    Examples
    --------
    >>> list(ordered_map(abs, [-1, 2, -3], workers=1))
    [1, 2, 3]
    """
    if workers <= 1 and executor is None:
        for item in items:
            yield fn(item)
        return
    pool = process_pool(workers, preload) if executor is None else executor
    workers = max(1, workers)
    ok = False
    pending: deque = deque()
    try:
        it = iter(items)
        with single_threaded_children():  # the workers start with the first submissions
            for item in it:
                pending.append(pool.submit(fn, item))
                if len(pending) >= inflight * workers:
                    break
        while pending:
            result = pending.popleft().result()
            nxt = next(it, _END)
            if nxt is not _END:
                pending.append(pool.submit(fn, nxt))
            yield result
        ok = True
    finally:
        if executor is None:
            close_pool(pool, abort=not ok)
        elif not ok:
            for f in pending:
                f.cancel()


def close_pool(pool, abort: bool = False) -> None:
    """Shut a pool of :func:`process_pool` down; with ``abort`` (an error, Ctrl-C, SIGTERM) stop its
    workers now instead of letting them finish the tasks they hold.

    The documented shutdown: the workers (``multiprocessing.active_children()`` started since the pool
    was made) are terminated and joined; when fewer workers than asked for had started, one may still
    be on its way from the fork server, so the fork server and everything it forked are killed
    (:func:`stop_forkserver`); the pool's result pipe is unblocked (:func:`_unblock_result_reader`,
    the one use of a private attribute, for the reason given there); then
    ``pool.shutdown(wait=True, cancel_futures=True)`` drops the queued tasks and joins the pool's
    manager thread.

    Parameters
    ----------
    pool : concurrent.futures.Executor
        A pool of :func:`process_pool` (or another executor, which is just shut down).
    abort : bool, default False
        Stop the workers now (after an error or a signal) instead of letting them finish.
    """
    if not abort or not hasattr(pool, "worker_processes"):
        # another executor (a :class:`grainforge.runtime.cluster.DaskExecutor`): its own shutdown cancels what is left
        pool.shutdown(wait=True, cancel_futures=True)
        return
    processes = pool.worker_processes()
    unblock = _unblock_result_reader(pool)  # before shutdown, which forgets the pipe
    for p in processes:
        try:
            p.terminate()
        except (OSError, AttributeError, ValueError):
            pass
    if len(processes) < pool.workers and pool.start_method == "forkserver":
        # start-up was cut short: a worker may be on its way from the fork server (the request sent,
        # its pid not yet known here); it would start after this process is gone and print a
        # traceback. Stop the fork server and every process it forked.
        stop_forkserver()
    for p in processes:
        p.join(timeout=5)
    unblock()
    # the pool's manager thread, unblocked, sees its workers gone and ends: joined here, so that it is not
    # still closing its wake-up pipe when the interpreter's exit hook writes to that pipe (Python 3.11
    # takes no lock there: "OSError: Bad file descriptor", printed after "Terminated.")
    pool.shutdown(wait=True, cancel_futures=True)


def _unblock_result_reader(pool) -> Callable[[], None]:
    """What unblocks the pool's result reader once its workers are stopped: closing this process's
    write end of the result pipe.

    A worker stopped while it was sending a result leaves the pool's manager thread reading the rest
    of that message for ever (this process holds the pipe's write end as well, so the read never
    sees the end of the pipe), and the interpreter waits for that thread at exit: the command
    printed "Interrupted." and hung. Closing our write end lets the read end (the workers' ends died
    with them). Neither ``concurrent.futures`` (up to Python 3.14's ``terminate_workers``) nor
    ``multiprocessing`` has a public way to reach that pipe, so this is the one place grainforge
    touches a private attribute of the standard library: ``pool._result_queue._writer``. Where it
    is missing (another Python), the returned function does nothing and an interrupted pool may
    again wait for its manager thread.
    """
    writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)

    def close() -> None:
        if writer is not None:
            try:
                writer.close()
            except OSError:
                pass

    return close


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


_END = object()
