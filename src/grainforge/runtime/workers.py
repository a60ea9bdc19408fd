"""Process pools for the local parallel jobs (batch, tray, analyse, dem, fit, calibration), and the kill path
of child processes.

Every pool (:func:`process_pool`, used as a context manager; :func:`ordered_map` on top of it) shares these
habits:

- workers fork from a *fork server* that has imported the heavy modules once
  (``spawn`` where there is no fork server), so starting a worker costs
  milliseconds instead of a fresh interpreter's imports, and no state of the
  parent (open files, threads) leaks into them;
- workers run NumPy's BLAS single-threaded (unless the user set the thread
  variables): OpenBLAS otherwise starts one thread per core in *every*
  worker, so N workers would run N × cores busy threads on the cores;
- workers exit when the process that made the pool dies, even by SIGKILL
  (a watcher thread in each worker; on Linux also ``PR_SET_PDEATHSIG``), so a
  killed command leaves no processes behind;
- leaving the pool's ``with`` block on an exception (an error, Ctrl-C, SIGTERM, a generator closed early)
  stops its workers at once, and nothing waits for a worker that was stopped in the middle of a result.

The pool is built on documented standard-library calls only (``multiprocessing`` processes and pipes,
``multiprocessing.connection.wait``, ``concurrent.futures.Future``): no private attribute of the standard
library is read. Linux's ``/proc`` (its documented interface to processes) is read where the standard library
has no way at all: to list a process's descendants and a session's members (:func:`kill_process_tree`, which
stops DEM engines and their ``mpirun`` ranks), and to find the fork server when a pool's start-up is cut short
(:func:`stop_forkserver`; ``multiprocessing`` neither gives its pid nor stops it). Elsewhere those two do
what the standard library can (the root process alone; nothing).
"""

from __future__ import annotations

import atexit
import functools
import os
import signal
import sys
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from typing import Any

__all__ = ["process_pool", "single_threaded_children", "THREAD_VARS", "ordered_map", "watch_parent", "pid_alive",
           "close_pool", "stop_forkserver", "kill_process_tree", "RemoteTraceback"]

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


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a pool worker, set as that exception's ``__cause__`` (as
    :class:`concurrent.futures.ProcessPoolExecutor` does), so that a report shows where the worker failed.

    Parameters
    ----------
    text : str
        The worker's formatted traceback.

    Examples
    --------
    >>> str(RemoteTraceback("Traceback ..."))
    'Traceback ...'
    """

    def __init__(self, text: str):
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return self.text


def _serve(conn, owner: int) -> None:
    """A pool worker's life: :func:`watch_parent`, then the tasks that come through ``conn``, one at a time.

    A task is the pickle of ``(fn, args, kwargs)``, or of ``None`` (leave); the answer is the pickle of
    ``(True, result)`` or ``(False, exception, traceback text)``. The worker also leaves when the pipe ends
    (the pool closed its end, or its process is gone).
    """
    import pickle
    import traceback

    watch_parent(owner)
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            task = pickle.loads(data)
            if task is None:
                return
            fn, args, kwargs = task
            reply = (True, fn(*args, **kwargs))
        except BaseException as exc:  # raised in the caller, for its item
            reply = (False, exc, traceback.format_exc())
        data = task = None
        try:
            out = pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # the result (or the exception) does not pickle: that is the task's error
            what = "result" if reply[0] else f"exception ({type(reply[1]).__name__}: {reply[1]})"
            out = pickle.dumps((False, pickle.PicklingError(f"the task's {what} cannot be sent back: {exc}"),
                                traceback.format_exc()))
        reply = None
        try:
            conn.send_bytes(out)
        except OSError:  # the pool is gone
            return


def _apply_chunk(fn: Callable, chunk: list) -> list:
    """``[fn(*args) for args in chunk]``: one task of a pool's ``map`` with ``chunksize`` > 1."""
    return [fn(*args) for args in chunk]


#: seconds a stopped worker has to exit after SIGTERM before it gets SIGKILL
TERMINATE_GRACE = 1.0

#: pools not closed yet: stopped at the interpreter's exit (their workers are not daemons, which
#: ``multiprocessing`` would otherwise wait for)
_LIVE_POOLS: weakref.WeakSet = weakref.WeakSet()


def _stop_processes(procs: Sequence) -> None:
    """SIGTERM each of ``procs`` (``multiprocessing.Process``), SIGKILL those still there after
    :data:`TERMINATE_GRACE`, and join them."""
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


def _stop_live_pools() -> None:
    """Exit hook: stop the workers of pools nobody closed."""
    for pool in list(_LIVE_POOLS):
        pool.terminate()


@functools.cache
def _pool_class():
    """The class of :func:`process_pool`'s pools (made lazily: it imports concurrent.futures)."""
    import itertools
    import pickle
    from concurrent.futures import Executor, Future
    from concurrent.futures.process import BrokenProcessPool
    from multiprocessing.connection import wait

    atexit.register(_stop_live_pools)  # after multiprocessing's own exit hook, so it runs before it

    class WorkerPool(Executor):
        """A :class:`concurrent.futures.Executor` on ``workers`` processes of ``mp_context``.

        Each worker has a pipe of its own (``Pipe()``); this process keeps only its own end, so a worker
        that dies, even in the middle of sending a result, ends its pipe: the read here gets ``EOFError``
        instead of waiting for the rest of the message for ever. A manager thread starts the workers (so
        the caller's thread never waits inside a process start, where a signal would cut it short), hands
        each idle worker the next task and sets the futures. ``with`` stops the workers at once when the
        block ends on an exception (:func:`close_pool`).

        The attributes are this module's, not API; none has a leading underscore, as
        ``tests/test_workers.py`` flags every private name used in this module (the standard library's
        included).
        """

        def __init__(self, workers: int, mp_context, owner: int):
            self.workers = int(workers)
            self.context = mp_context
            self.start_method = mp_context.get_start_method()
            self.owner = owner
            self.lock = threading.Lock()
            self.queue: deque = deque()  # (future, fn, args, kwargs) not handed out yet
            self.started: list = []  # the worker processes started so far
            self.starting = True  # the manager thread is starting workers
            self.closing = False  # shutdown asked: no new tasks
            self.stopped = False  # terminate(): the workers are stopped
            self.broken = ""  # why the pool broke (a worker died), "" while it works
            self.woken = False  # a wake-up message is on its way to the manager thread
            self.wake_r, self.wake_w = mp_context.Pipe(duplex=False)
            self.thread = threading.Thread(target=self.manage, name="grainforge-pool", daemon=True)
            _LIVE_POOLS.add(self)
            self.thread.start()

        def processes(self) -> list:
            """The worker processes started so far (``multiprocessing.Process`` objects)."""
            with self.lock:
                return list(self.started)

        # -- the caller's side -------------------------------------------------------------------

        def submit(self, fn, /, *args, **kwargs):
            """Schedule ``fn(*args, **kwargs)`` on a worker; a :class:`concurrent.futures.Future` of its result."""
            with self.lock:
                if self.broken:
                    raise BrokenProcessPool(self.broken)
                if self.closing:
                    raise RuntimeError("cannot schedule new futures after shutdown")
                future = Future()
                self.queue.append((future, fn, args, kwargs))
                wake, self.woken = not self.woken, True
            if wake:
                self.wake()
            return future

        def map(self, fn, *iterables, timeout=None, chunksize=1):
            """:meth:`concurrent.futures.Executor.map`, ``chunksize`` items a task (as
            :class:`concurrent.futures.ProcessPoolExecutor` groups them)."""
            if chunksize <= 1:
                return super().map(fn, *iterables, timeout=timeout)
            args = zip(*iterables)
            chunks = iter(lambda: list(itertools.islice(args, chunksize)), [])
            return itertools.chain.from_iterable(super().map(functools.partial(_apply_chunk, fn), chunks,
                                                             timeout=timeout))

        def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
            """Let the workers finish the tasks handed out (and the queued ones, unless ``cancel_futures``),
            then end them; with ``wait``, return when they have ended."""
            with self.lock:
                self.closing = True
                dropped = list(self.queue) if cancel_futures else []
                if cancel_futures:
                    self.queue.clear()
            for future, *_ in dropped:
                future.cancel()
            self.wake()
            if wait:
                self.thread.join()
                self.wake_w.close()

        def terminate(self) -> None:
            """Stop the workers now (SIGTERM; SIGKILL after :data:`TERMINATE_GRACE`): queued tasks are
            cancelled, running ones fail (``BrokenProcessPool``), the manager thread ends.

            When start-up was cut short, a worker may be on its way from the fork server (asked for, its pid
            not known here yet), typically while the fork server still imports its preload: left alone, it
            would finish those imports and fork the worker after this process is gone. The fork server and
            every process it forked are killed (:func:`stop_forkserver`), which also ends the manager
            thread's wait for the fork server's answer.
            """
            with self.lock:
                self.closing = self.stopped = True
                procs, starting = list(self.started), self.starting
                dropped = list(self.queue)
                self.queue.clear()
            for future, *_ in dropped:
                future.cancel()
            if starting and self.start_method == "forkserver":
                stop_forkserver()
            _stop_processes(procs)
            self.wake()
            self.thread.join(TERMINATE_GRACE)
            if not self.thread.is_alive():
                self.wake_w.close()
            _LIVE_POOLS.discard(self)

        def __exit__(self, exc_type, exc, tb):
            close_pool(self, abort=exc_type is not None)
            return False

        def wake(self) -> None:
            """Wake the manager thread (it waits on its workers' pipes and on this one)."""
            try:
                self.wake_w.send_bytes(b"")
            except OSError:  # the manager thread has ended
                pass

        # -- the manager thread ------------------------------------------------------------------

        def manage(self) -> None:
            idle: list = []  # (connection, process) of the workers waiting for a task
            busy: dict = {}  # connection -> (process, future) of the others
            try:
                self.start_workers(idle)
                while self.dispatch(idle, busy):
                    for conn in wait([self.wake_r, *busy]):
                        if conn is self.wake_r:
                            while self.wake_r.poll():
                                self.wake_r.recv_bytes()
                            with self.lock:
                                self.woken = False
                        else:
                            self.collect(conn, idle, busy)
                if not (self.stopped or self.broken):  # shut down: the queue done, every worker idle
                    for conn, _ in idle:
                        try:
                            conn.send_bytes(pickle.dumps(None))
                        except OSError:
                            pass
                    for _, p in idle:
                        p.join(TERMINATE_GRACE)
                    _stop_processes([p for _, p in idle])
            except BaseException as exc:  # a worker did not start (or terminate() killed the fork server)
                if not self.stopped:
                    self.fail(f"a worker process could not start: {type(exc).__name__}: {exc}", busy)
            finally:
                for _, future in busy.values():
                    if not future.done():
                        future.set_exception(BrokenProcessPool("the pool was stopped"))
                for conn in [*busy, *(c for c, _ in idle)]:
                    conn.close()
                self.wake_r.close()
                _LIVE_POOLS.discard(self)

        def start_workers(self, idle: list) -> None:
            try:
                # a fork server's workers have its environment (started by process_pool with these limits)
                with nullcontext() if self.start_method == "forkserver" else single_threaded_children():
                    for k in range(self.workers):
                        here, there = self.context.Pipe()
                        p = self.context.Process(target=_serve, args=(there, self.owner),
                                                 name=f"grainforge-worker-{k + 1}")
                        try:
                            p.start()
                        finally:
                            there.close()  # the worker's end is the worker's alone
                        with self.lock:
                            self.started.append(p)
                            stopped = self.stopped
                        if stopped:  # terminate() came while it started, and did not see it
                            here.close()
                            _stop_processes([p])
                            return
                        idle.append((here, p))
            finally:
                with self.lock:
                    self.starting = False

        def dispatch(self, idle: list, busy: dict) -> bool:
            """Hand queued tasks to idle workers; False when the manager thread is done."""
            while idle:
                with self.lock:
                    if self.stopped or not self.queue:
                        break
                    future, fn, args, kwargs = self.queue.popleft()
                if not future.set_running_or_notify_cancel():  # cancelled meanwhile
                    continue
                try:
                    data = pickle.dumps((fn, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
                except Exception as exc:  # the task does not pickle: its error, raised for its item
                    future.set_exception(exc)
                    continue
                conn, p = idle.pop()
                busy[conn] = (p, future)
                try:
                    conn.send_bytes(data)
                except OSError:  # the worker is gone: collect() reads the end of its pipe
                    pass
            with self.lock:
                if self.stopped or self.broken:
                    return False
                return not (self.closing and not self.queue and not busy)

        def collect(self, conn, idle: list, busy: dict) -> None:
            """The answer of the worker on ``conn``, set on its future."""
            p, future = busy.pop(conn)
            try:
                reply = pickle.loads(conn.recv_bytes())
            except (EOFError, OSError):  # the worker died (stopped by terminate(), or killed)
                conn.close()
                if self.stopped:
                    future.set_exception(BrokenProcessPool("the pool was stopped"))
                    return
                p.join(TERMINATE_GRACE)
                why = f"a worker process ended while it ran a task (exit code {p.exitcode})"
                future.set_exception(BrokenProcessPool(why))
                self.fail(why, busy)
                return
            except Exception as exc:  # the answer does not unpickle here: the task's error
                future.set_exception(exc)
            else:
                if reply[0]:
                    future.set_result(reply[1])
                else:
                    error = reply[1]
                    error.__cause__ = RemoteTraceback(f'\n"""\n{reply[2]}"""')
                    future.set_exception(error)
            idle.append((conn, p))

        def fail(self, why: str, busy: dict) -> None:
            """Break the pool: every future not done raises ``BrokenProcessPool(why)``, the workers stop."""
            with self.lock:
                self.broken = why
                self.closing = True
                dropped = list(self.queue)
                self.queue.clear()
                procs = list(self.started)
            error = BrokenProcessPool(why)
            for future, *_ in dropped:
                if future.set_running_or_notify_cancel():
                    future.set_exception(error)
            for _, future in busy.values():
                if not future.done():
                    future.set_exception(error)
            _stop_processes(procs)

    return WorkerPool


def process_pool(workers: int, preload: Sequence[str] = ()):
    """A pool of ``workers`` processes started from a fork server; use it as a context manager.

    Leaving the ``with`` block normally lets the workers finish the tasks handed out (queued ones are
    cancelled) and ends them; leaving it on an exception (an error, Ctrl-C, SIGTERM, a generator closed
    early) stops them at once (:func:`close_pool`). Workers exit by themselves when this process dies
    (:func:`watch_parent`), start with SIGINT blocked (the command decides what a Ctrl-C stops) and run
    BLAS single-threaded (:func:`single_threaded_children`). Tasks and results travel as pickles; a task's
    exception is raised by its future's ``result()``, with the worker's traceback as its ``__cause__``
    (:class:`RemoteTraceback`); a worker that dies breaks the pool (``BrokenProcessPool``).

    Parameters
    ----------
    workers : int
        Number of worker processes.
    preload : sequence of str
        Modules the fork server imports once, before forking the workers.

    Returns
    -------
    concurrent.futures.Executor
        ``submit``, ``map`` (with ``chunksize``), ``shutdown``, and ``terminate()``, ``processes()``,
        ``workers`` and ``start_method`` for :func:`close_pool` and the tests.

    Examples
    --------
    >>> with process_pool(2) as pool:
    ...     futures = [pool.submit(pow, 2, k) for k in range(4)]
    ...     [f.result() for f in futures]
    [1, 2, 4, 8]
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
            # the tracker outlives a killed owner; nothing it prints concerns the user
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
    the pool's workers are stopped (pending work cancelled).  With ``executor`` (a
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
    >>> list(ordered_map(abs, [-1, 2, -3], workers=2))
    [1, 2, 3]
    """
    if workers <= 1 and executor is None:
        for item in items:
            yield fn(item)
        return
    workers = max(1, workers)
    with process_pool(workers, preload) if executor is None else nullcontext(executor) as pool:
        pending: deque = deque()
        try:
            it = iter(items)
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
        except BaseException:  # an error, a signal, the generator closed: drop what was not started
            for f in pending:
                f.cancel()
            raise


def close_pool(pool, abort: bool = False) -> None:
    """Shut a pool of :func:`process_pool` down; with ``abort`` (an error, Ctrl-C, SIGTERM) stop its
    workers now instead of letting them finish the tasks they hold.

    ``abort``: ``pool.terminate()`` (SIGTERM to the workers, SIGKILL to any left after
    :data:`TERMINATE_GRACE`; the fork server too when start-up was cut short). Otherwise
    ``pool.shutdown(wait=True, cancel_futures=True)``; a signal while it waits stops the workers at once.
    The pool's ``with`` block calls this on leaving.

    Parameters
    ----------
    pool : concurrent.futures.Executor
        A pool of :func:`process_pool` (or another executor, which is just shut down, its tasks cancelled).
    abort : bool, default False
        Stop the workers now (after an error or a signal) instead of letting them finish.
    """
    own = isinstance(pool, _pool_class())
    if abort and own:
        pool.terminate()
        return
    try:
        pool.shutdown(wait=True, cancel_futures=True)
    except BaseException:
        if own:
            pool.terminate()
        raise


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
