"""Independent tasks on a Dask distributed cluster (``--scheduler ADDRESS`` of batch, analyse and fit).

The commands run their per-grain or per-file work through a
:class:`concurrent.futures.Executor`: a local process pool
(:func:`grainforge.runtime.workers.process_pool`) or, with ``--scheduler``, a
:class:`DaskExecutor` on a cluster that is already running.  The code that
submits the tasks and puts their results in order is the same for both, so
the outputs are byte-identical; this process keeps the progress bar, the
estimate, the refusals and the writing of the outputs.

Dask is an optional extra (``pip install 'grainforge[dask]'``), imported here
only when a scheduler is given.  :func:`dask_executor` refuses, in one line
(a ``ValueError``), an address that is not one, an address where nothing
listens (at once: :func:`probe` tries a TCP connection first), a scheduler that
does not answer within :data:`CONNECT_TIMEOUT` and workers that run another grainforge
version; a scheduler lost during the run raises :class:`SchedulerLost`.
"""

from __future__ import annotations

import concurrent.futures as cf
import errno
import logging
import re
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from .._version import __version__
from ..errors import InputError

__all__ = ["CONNECT_TIMEOUT", "INSTALL", "DaskExecutor", "SchedulerLost", "VersionMismatch", "check_address",
           "connect", "dask_executor", "probe"]

#: how long ``--scheduler`` waits for the scheduler to answer
CONNECT_TIMEOUT = "20s"

#: how to install what ``--scheduler`` needs
INSTALL = "pip install 'grainforge[dask]'"

#: the communication protocols a Dask scheduler listens on
SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
#: the protocols carried over a TCP connection (:func:`probe` tries it before Dask does)
TCP_SCHEMES = ("tcp", "tls", "ws", "wss")


class SchedulerLost(RuntimeError):
    """The connection to the Dask scheduler was lost during a run.

    Attributes
    ----------
    address : str
    done, total : int
        Tasks finished before the loss, tasks submitted.
    """

    def __init__(self, address: str, done: int, total: int, reason: str = ""):
        self.address, self.done, self.total = address, int(done), int(total)
        super().__init__(f"lost the Dask scheduler at {address} after {done} of {total} task(s) had finished"
                         + (f" ({reason})" if reason else ""))


class VersionMismatch(InputError):
    """A Dask worker runs another grainforge version than this process (its results could differ)."""


def check_address(address: str) -> str:
    """``address`` if it can name a Dask scheduler (``tcp://HOST:PORT``, ``HOST:PORT``, ``tls://…``), else refuse.

    Parameters
    ----------
    address : str
        What the user gave for ``--scheduler``.

    Returns
    -------
    str
        The address, stripped of surrounding blanks.

    Raises
    ------
    ValueError
        One line saying what an address looks like.

    Examples
    --------
    >>> check_address("tcp://10.0.0.5:8786"), check_address("node12:8786")
    ('tcp://10.0.0.5:8786', 'node12:8786')
    >>> check_address("http://node12")
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: scheduler 'http://node12': not a Dask scheduler address; give tcp://HOST:PORT, the address the scheduler prints (e.g. tcp://10.0.0.5:8786)
    """
    text = str(address).strip()
    scheme, sep, rest = text.rpartition("://")
    if not sep:
        scheme, rest = "tcp", text
    ok = scheme in SCHEMES and bool(rest) and not re.search(r"[\s/]", rest)
    if ok and scheme != "inproc":
        host, colon, port = rest.rpartition(":")
        host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        ok = bool(colon and host and port.isdigit() and 0 < int(port) < 65536)
    if not ok:
        raise InputError(f"{{scheduler}} {address!r}: not a Dask scheduler address; give tcp://HOST:PORT, the address "
                         "the scheduler prints (e.g. tcp://10.0.0.5:8786)", setting="scheduler")
    return text


def _seconds(timeout: str) -> float:
    """Seconds of a Dask timeout string (``"20s"``, ``"1.5s"``, ``"2m"``, ``"500ms"``) or a number."""
    m = re.fullmatch(r"\s*([0-9.]+)\s*(ms|s|m|)\s*", str(timeout))
    if not m:
        return 20.0
    return float(m.group(1)) * {"ms": 1e-3, "s": 1.0, "": 1.0, "m": 60.0}[m.group(2)]


def probe(address: str, timeout: float) -> None:
    """Refuse at once a scheduler address where nothing listens: a TCP connection to its host and port, refused or
    unroutable in milliseconds, instead of Dask's retries until its timeout (20 s for ``tcp://127.0.0.1:1``).

    An address whose protocol is not carried over TCP (``ucx``, ``inproc``) is left to Dask.

    Parameters
    ----------
    address : str
        The scheduler's address (:func:`check_address`).
    timeout : float
        Seconds to wait for a host that neither answers nor refuses.

    Raises
    ------
    ValueError
        One line naming the address and why: connection refused, host not found, no route, no answer.

    Examples
    --------
    >>> with socket.socket() as s:
    ...     s.bind(("127.0.0.1", 0)); port = s.getsockname()[1]   # a port nothing listens on
    >>> probe(f"tcp://127.0.0.1:{port}", 5)
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: cannot connect to the Dask scheduler at tcp://127.0.0.1:...: connection refused (nothing listens ...
    """
    scheme, sep, rest = address.rpartition("://")
    if (scheme if sep else "tcp") not in TCP_SCHEMES:
        return
    host, _, port = rest.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    where = f"cannot connect to the Dask scheduler at {address}"
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            return
    except socket.gaierror:
        raise InputError(f"{where}: host {host!r} not found; check {{scheduler}}", setting="scheduler") from None
    except TimeoutError:
        raise InputError(f"{where}: no answer within {timeout:g} s; check {{scheduler}}, and that the scheduler "
                         "runs and its port is open", setting="scheduler") from None
    except ConnectionRefusedError:
        raise InputError(f"{where}: connection refused (nothing listens on port {port} of {host}); start the "
                         "scheduler (dask scheduler) or give the address it prints") from None
    except OSError as exc:
        reason = {errno.EHOSTUNREACH: "no route to the host", errno.ENETUNREACH: "network unreachable"}.get(
            exc.errno, exc.strerror or type(exc).__name__)
        raise InputError(f"{where}: {reason}; check {{scheduler}}", setting="scheduler") from None


def _distributed():
    try:
        import distributed
    except ImportError:
        raise InputError(f"{{scheduler}} needs Dask distributed: {INSTALL}", setting="scheduler") from None
    return distributed


@contextmanager
def _quiet_dask_logs() -> Iterator[None]:
    """Dask's own log lines off meanwhile (a lost scheduler is logged with tracebacks; the command says it in
    one line)."""
    names = ["distributed"] + [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
    loggers = [logging.getLogger(n) for n in names]
    saved = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, saved):
            lg.setLevel(level)


def _worker_versions(client) -> dict[str, str]:
    def version() -> str:  # a local function, sent by value: it runs whatever grainforge the worker has
        try:
            import grainforge
        except ImportError:
            return "none (not installed)"
        return str(getattr(grainforge, "__version__", "unknown"))

    return client.run(version)


def check_versions(client, address: str) -> None:
    """Refuse workers that run another grainforge version than this process.

    Raises
    ------
    VersionMismatch
        Naming both versions and one worker.
    """
    try:
        versions = _worker_versions(client)
    except Exception as exc:  # noqa: BLE001 - whatever a worker that cannot run the check says
        raise VersionMismatch(f"the Dask workers at {address} cannot run grainforge's check of their version "
                              f"({type(exc).__name__}: {exc}); install grainforge {__version__} on them") from None
    other = {w: v for w, v in versions.items() if v != __version__}
    if other:
        worker, version = sorted(other.items())[0]
        raise VersionMismatch(f"the Dask worker {worker} (and {len(other) - 1} more) runs grainforge {version}, "
                              f"this process grainforge {__version__}; install the same version on the workers"
                              if len(other) > 1 else
                              f"the Dask worker {worker} runs grainforge {version}, this process grainforge "
                              f"{__version__}; install the same version on the workers")


@contextmanager
def connect(address: str, *, timeout: str | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` of the scheduler at ``address`` whose workers run this grainforge version.

    Dask's log lines are off while it is open; the client is closed on leaving.

    Parameters
    ----------
    address : str
        The scheduler's address (:func:`check_address`).
    timeout : str, optional
        Dask's timeout string (``"10s"``); default :data:`CONNECT_TIMEOUT`.

    Yields
    ------
    distributed.Client
        Open while the block runs.

    Raises
    ------
    ValueError
        Dask not installed, a bad address, nothing listening there (at once,
        :func:`probe`), no answer within ``timeout`` (default
        :data:`CONNECT_TIMEOUT`), workers of another version.
    """
    address = check_address(address)
    distributed = _distributed()
    probe(address, _seconds(timeout or CONNECT_TIMEOUT))
    with _quiet_dask_logs():
        try:
            client = distributed.Client(address, timeout=timeout or CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"cannot connect to the Dask scheduler at {address}: {reason}") from None
        except MemoryError:  # something else answers there: its first bytes read as a huge Dask message
            raise InputError(f"cannot connect to the Dask scheduler at {address}: what answers there does not speak "
                             "Dask's protocol; give the address the scheduler prints") from None
        try:
            check_versions(client, address)
            yield client
        finally:
            try:
                client.close(timeout=5)
            except Exception:  # noqa: BLE001 - a lost scheduler: nothing left to close cleanly
                pass


def _call(version: str, fn: Callable, args: tuple, kwargs: dict) -> Any:
    """Run ``fn(*args, **kwargs)`` on a Dask worker, first checking it runs grainforge ``version`` (a worker that
    joined after :func:`check_versions`)."""
    if __version__ != version:
        raise VersionMismatch(f"a Dask worker runs grainforge {__version__}, this process grainforge {version}; "
                              "install the same version on the workers")
    return fn(*args, **kwargs)


class DaskExecutor(cf.Executor):
    """A :class:`concurrent.futures.Executor` whose tasks run on a Dask cluster.

    Its futures are ordinary :class:`concurrent.futures.Future` objects (so
    ``wait``, ``as_completed`` and the code written for a process pool work
    unchanged).  Every task is submitted with ``pure=False`` and checks that
    its worker runs this grainforge version.  A task's own error is raised by
    its future's ``result()``; a task the scheduler lost (the connection
    gone) raises :class:`SchedulerLost`.  A task whose worker dies is rerun
    by Dask elsewhere.

    Parameters
    ----------
    client : distributed.Client
    address : str
        The scheduler's address, for messages.
    """

    def __init__(self, client, address: str = ""):
        self.client = client
        self.address = address
        self._pending: set = set()
        self._lock = threading.Lock()
        self._closing = False
        self.submitted = 0
        self.finished = 0

    @property
    def workers(self) -> int:
        """Worker threads of the cluster now (at least 1): what the callers size their windows and estimates by."""
        try:
            info = self.client.scheduler_info(n_workers=-1)
        except TypeError:  # an older distributed
            info = self.client.scheduler_info()
        except Exception:  # noqa: BLE001 - a scheduler that does not answer: one
            return 1
        return max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        """Run ``fn(*args, **kwargs)`` on the cluster.

        Parameters
        ----------
        fn : callable
            Picklable by Dask (cloudpickle).
        *args, **kwargs
            Its arguments.

        Returns
        -------
        concurrent.futures.Future
            Cancelling it cancels the Dask task.

        Raises
        ------
        RuntimeError
            After :meth:`shutdown`.
        SchedulerLost
            If the scheduler refuses the task (the connection is gone).
        """
        if self._closing:
            raise RuntimeError("cannot schedule new tasks after shutdown")
        out: cf.Future = cf.Future()
        try:
            fut = self.client.submit(_call, __version__, fn, args, kwargs, pure=False)
        except Exception as exc:  # noqa: BLE001 - a client whose scheduler is gone refuses new tasks
            raise SchedulerLost(self.address, self.finished, self.submitted, f"{type(exc).__name__}: {exc}") from None
        with self._lock:
            self._pending.add(fut)
            self.submitted += 1

        def cancelled(f: cf.Future) -> None:
            if not f.cancelled() or self._closing:
                return  # a shutdown cancels its pending tasks in one call, and may close the client after
            try:
                fut.cancel()
            except Exception:  # noqa: BLE001 - a client already closed (its loop gone) holds nothing to cancel
                pass

        out.add_done_callback(cancelled)
        fut.add_done_callback(lambda f: self._settle(f, out))
        return out

    def _settle(self, fut, out: cf.Future) -> None:
        """Pass the Dask future's outcome to ``out`` (in Dask's callback thread)."""
        with self._lock:
            self._pending.discard(fut)
        if out.done():
            return
        status = fut.status
        try:
            if status == "finished":
                result = fut.result()
                with self._lock:
                    self.finished += 1
                out.set_result(result)
                return
            if status == "error":
                out.set_exception(fut.exception())
                return
        except Exception as exc:  # noqa: BLE001 - the result could not be fetched: the scheduler is gone
            reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        else:
            reason = f"task {status}"
        try:
            if self._closing:
                out.cancel()
                out.set_running_or_notify_cancel()
            else:
                out.set_exception(SchedulerLost(self.address, self.finished, self.submitted, reason))
        except cf.InvalidStateError:
            pass

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop: with ``cancel_futures`` (or without ``wait``) cancel the tasks not done, else wait for them.

        Parameters
        ----------
        wait : bool, default True
            Wait for the tasks not done (unless ``cancel_futures``).
        cancel_futures : bool, default False
            Cancel the tasks not done.
        """
        with self._lock:
            pending = list(self._pending)
        if cancel_futures or not wait:
            self._closing = True
            if pending:
                try:
                    self.client.cancel(pending)
                except Exception:  # noqa: BLE001 - a lost scheduler holds nothing to cancel
                    pass
        elif pending:
            _distributed().wait(pending)
        self._closing = True


@contextmanager
def dask_executor(address: str) -> Iterator[DaskExecutor]:
    """:func:`connect`, then a :class:`DaskExecutor` on that client; tasks not done on leaving are cancelled.

    Parameters
    ----------
    address : str
        The scheduler's address.

    Yields
    ------
    DaskExecutor

    Raises
    ------
    ValueError
        As :func:`connect`: Dask missing, a bad or silent address, workers of another version.
    """
    with connect(address) as client:
        ex = DaskExecutor(client, check_address(address))
        try:
            yield ex
        finally:
            ex.shutdown(wait=False, cancel_futures=True)
