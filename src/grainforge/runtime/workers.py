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
import itertools
import os
import pickle
import threading
import weakref
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, Future
from concurrent.futures.process import BrokenProcessPool
from contextlib import nullcontext
from multiprocessing.connection import wait
from typing import Any

from .children import (
    TERMINATE_GRACE,
    quiet_stderr,
    sigint_blocked,
    single_threaded_children,
    stop_forkserver,
    stop_processes,
    watch_parent,
)

__all__ = ["default_workers", "process_pool", "ordered_map", "close_pool", "RemoteTraceback"]

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



#: pools not closed yet: stopped at the interpreter's exit (their workers are not daemons, which
#: ``multiprocessing`` would otherwise wait for)
_LIVE_POOLS: weakref.WeakSet = weakref.WeakSet()


def _stop_live_pools() -> None:
    """Exit hook: stop the workers of pools nobody closed."""
    for pool in list(_LIVE_POOLS):
        pool.terminate()


@functools.cache
def _pool_class():
    """:class:`WorkerPool`, with the exit hook that stops the pools nobody closed registered on first use: after
    ``multiprocessing``'s own exit hook, so that it runs before it."""
    atexit.register(_stop_live_pools)
    return WorkerPool


class WorkerPool(Executor):
    """A :class:`concurrent.futures.Executor` on ``workers`` processes of ``mp_context``.

    Each worker has a pipe of its own (``Pipe()``); this process keeps only its own end, so a worker
    that dies, even in the middle of sending a result, ends its pipe: the read here gets ``EOFError``
    instead of waiting for the rest of the message for ever. A manager thread starts the workers (so
    the caller's thread never waits inside a process start, where a signal would cut it short), hands
    each idle worker the next task and sets the futures. ``with`` stops the workers at once when the
    block ends on an exception (:func:`close_pool`).

    The attributes are this module's, not API; none has a leading underscore, as
    ``tests/runtime/test_workers.py`` flags every private name used in this module (the standard library's
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
        stop_processes(procs)
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
                stop_processes([p for _, p in idle])
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
                        stop_processes([p])
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
        stop_processes(procs)


def default_workers(workers: int | None = None) -> int:
    """The number of worker processes: ``workers`` when given, else one per CPU of this machine.

    The one default of every ``--workers`` option and ``workers=`` argument.

    Parameters
    ----------
    workers : int, optional
        The workers asked for; None (or 0) asks for the default.

    Returns
    -------
    int
        ``workers``, or ``os.cpu_count()`` (1 when the CPU count is unknown).

    Examples
    --------
    >>> default_workers(3)
    3
    >>> default_workers() == (os.cpu_count() or 1)
    True
    """
    return workers or os.cpu_count() or 1


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
        with quiet_stderr():
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


_END = object()
