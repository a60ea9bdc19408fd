"""Engine processes of the virtual tests: started in a session of their own, their output logged and their
progress lines read, killed with everything below them (an mpirun's ranks) on an interrupt."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from ..errors import EngineMissing, InputError
from ..runtime.children import owned_command

__all__ = ["run_engine_process", "EngineFailed", "kill_running", "find_executable", "mpi_session_folder",
           "mpi_slots", "check_mpi_ranks"]


def find_executable(variable: str, name: str, missing: str, setting: str | None = None) -> str:
    """Path of command ``name``, or of the command the environment variable ``variable`` names.

    Parameters
    ----------
    variable : str
        Environment variable that may name the command (a name on ``PATH`` or a path), e.g. ``GRAINFORGE_YADE``.
    name : str
        The command looked up on ``PATH`` when ``variable`` is not set.
    missing : str
        The message of the error raised when the command is not found.
    setting : str, optional
        The setting that asks for the command, named in ``missing`` as ``{setting}`` (``mpi``).

    Returns
    -------
    str
        The command's absolute path.

    Raises
    ------
    grainforge.errors.EngineMissing
        With the message ``missing`` when there is none (a ``FileNotFoundError``).
    """
    import shutil

    exe = shutil.which(os.environ.get(variable, name))
    if exe is None:
        raise EngineMissing(missing, setting=setting)
    return exe


#: the line by which an engine names a temporary folder of its own, ``grainforge-tempdir PATH``
#: (:func:`run_engine_process` removes it when the engine has ended)
TEMPDIR_LINE = "grainforge-tempdir"


def run_engine_process(cmd: Sequence[str], cwd: Path, *, log_path: Path, env: dict,
                       progress: Callable[[float, str], None] | None, timeout: float | None = None,
                       temp_prefix: str | None = None) -> int:
    """Run an engine command in ``cwd`` (its own session), its output to ``log_path``; its exit status.

    ``grainforge-progress <fraction> <phase>`` lines go to ``progress``.  On any exception
    (an interrupt) the process and everything below it (an mpirun's ranks) are killed.  A folder the
    engine names by a ``grainforge-tempdir PATH`` line (:data:`TEMPDIR_LINE`; Yade's ``/tmp/yade-*``,
    which Yade leaves behind) is removed once the engine has ended, however it ended, if its name begins
    with ``temp_prefix``.

    Parameters
    ----------
    cmd : sequence of str
        The command and its arguments.
    cwd : path
        The folder it runs in (the deck's).
    log_path : path
        File that receives the engine's standard output and error (overwritten).
    env : dict
        Environment variables added to this process's (``OMP_NUM_THREADS`` is set to 1 first).
    progress : callable or None
        ``progress(fraction, phase)`` for each ``grainforge-progress`` line; None ignores them.
    timeout : float, optional
        Seconds to wait for the process after its output has ended; None waits for ever.
    temp_prefix : str, optional
        The name's beginning of the temporary folders the engine may name (``"yade-"``): those are removed
        after it; None removes none.

    Returns
    -------
    int
        The process's exit status.
    """
    env = dict(os.environ, OMP_NUM_THREADS="1", **env)
    with open(log_path, "w", buffering=1) as log:
        # in a session of its own, through a launcher that ignores Ctrl-C and kills the engine when this
        # process is gone (no pre-exec hook: unsafe with threads, and this may run in a pool thread)
        proc = _track(subprocess.Popen(owned_command(cmd), cwd=cwd, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
                                       errors="replace", env=env, start_new_session=True))
        named = []  # the engine's own temporary folders
        try:
            for line in proc.stdout:
                log.write(line)
                if line.startswith("grainforge-progress") and progress is not None:
                    _, frac, *phase = line.split()
                    progress(float(frac), " ".join(phase))
                elif line.startswith(TEMPDIR_LINE) and temp_prefix:
                    named.append(line[len(TEMPDIR_LINE):].strip())
            rc = proc.wait(timeout=timeout)
        except BaseException:
            _kill(proc)
            if temp_prefix:  # a folder named in output not yet read when the interrupt came
                rest = _unread(proc.stdout)
                log.write(rest)
                named += [ln[len(TEMPDIR_LINE):].strip() for ln in rest.splitlines() if ln.startswith(TEMPDIR_LINE)]
            raise
        finally:
            proc.stdout.close()
            _RUNNING.discard(proc)
            for folder in named:  # the engine has ended (or was killed and reaped): its folder is no one's now
                _remove_engine_folder(folder, temp_prefix)
    return rc


def _unread(stream) -> str:
    """What a killed engine wrote that was not read yet (without waiting: nothing if its pipe is still open)."""
    try:
        os.set_blocking(stream.fileno(), False)
        return stream.read() or ""
    except (OSError, TypeError, ValueError):  # no data without waiting, or the stream already closed
        return ""


def _remove_engine_folder(folder: str, prefix: str) -> None:
    """Remove a temporary folder an engine named, if it is one: an absolute path to a directory (not a link)
    whose name begins with ``prefix``."""
    path = Path(folder)
    if path.is_absolute() and path.name.startswith(prefix) and path.is_dir() and not path.is_symlink():
        _remove_folder(str(path))


class EngineFailed(RuntimeError):
    """An engine run ended with an error (not an interrupt); ``deck`` is its folder (deck and log)."""

    def __init__(self, message: str, deck: str | os.PathLike):
        super().__init__(message)
        self.deck = Path(deck)


#: engine processes started by this process and not yet finished (killed on an interrupt)
_RUNNING: set = set()


def _track(proc):
    _RUNNING.add(proc)
    return proc


def kill_running() -> None:
    """Kill every engine process this process started and that has not finished (with its children)."""
    for proc in list(_RUNNING):
        _kill(proc)


def _kill(proc: subprocess.Popen) -> None:
    from ..runtime.children import kill_process_tree

    kill_process_tree(proc.pid)
    proc.wait()


#: the name of a run's own temporary folder for mpirun, followed by the pid of the process that made it
MPI_TMP_PREFIX = "grainforge-mpi-"


@contextmanager
def mpi_session_folder() -> Iterator[dict]:
    """A temporary folder of one ``mpirun`` run for Open MPI's session folder; yields the environment that puts
    it there, and removes the folder after the run, whatever happened.

    ``mpirun`` keeps its session folder (Open MPI 4: ``ompi.HOST.UID/pid.N``, with the PMIx segments; 5:
    ``prte.*``) under ``$TMPDIR`` or ``/tmp`` and removes it as it ends, but not when it is killed (an
    interrupted run); here the folder lies in one of this run's own, removed after the kill.  The folders of a
    run whose owner was killed (SIGKILL: nothing could clean up) are removed by the next run.

    Yields
    ------
    dict
        ``TMPDIR`` and Open MPI's MCA variables naming the temporary folder, to add to ``mpirun``'s environment.

    Examples
    --------
    >>> with mpi_session_folder() as env:
    ...     folder = env["TMPDIR"]
    ...     os.path.isdir(folder)
    True
    >>> os.path.exists(folder)
    False
    """
    import tempfile

    _remove_stale_mpi_folders()
    folder = tempfile.mkdtemp(prefix=f"{MPI_TMP_PREFIX}{os.getpid()}-")
    try:
        # TMPDIR: Open MPI's and PMIx's default; the MCA settings name it for Open MPI 4 (ORTE) and 5 (PRRTE)
        yield {"TMPDIR": folder, "OMPI_MCA_orte_tmpdir_base": folder, "PRTE_MCA_prte_tmpdir_base": folder}
    finally:
        _remove_folder(folder)


def _remove_folder(folder: str) -> None:
    import shutil

    try:
        shutil.rmtree(folder, ignore_errors=True)
    finally:  # again if a signal stopped the first pass (the command ignores a second signal while cleaning up)
        if os.path.lexists(folder):
            shutil.rmtree(folder, ignore_errors=True)


def _remove_stale_mpi_folders() -> None:
    """Remove the mpirun folders (:func:`mpi_session_folder`) of processes that no longer run."""
    import tempfile

    from ..runtime.children import remove_leftovers

    remove_leftovers(tempfile.gettempdir(), MPI_TMP_PREFIX)


#: environment variables through which batch systems give a job its number of MPI slots
ALLOCATION_VARIABLES = ("SLURM_NTASKS", "SLURM_NPROCS", "PBS_NP", "NSLOTS", "LSB_DJOB_NUMPROC")
#: environment variables naming a file with one host per line (Open MPI hostfile syntax: ``host slots=N``)
HOSTFILE_VARIABLES = ("PBS_NODEFILE", "OMPI_MCA_orte_default_hostfile", "OMPI_MCA_rmaps_default_hostfile",
                      "PRTE_MCA_prte_default_hostfile")


def mpi_slots(environ: dict | None = None) -> tuple[int, str]:
    """How many MPI ranks this run may start, and where that number comes from.

    The cores this process may use (its CPU affinity), or more when a batch allocation
    (:data:`ALLOCATION_VARIABLES`) or a hostfile (:data:`HOSTFILE_VARIABLES`: a line per host, ``slots=N``
    counted, else one slot a line) provides them.

    Parameters
    ----------
    environ : dict, optional
        The environment read for allocations and hostfiles; None reads ``os.environ``.

    Returns
    -------
    slots : int
        The ranks available (at least 1).
    source : str
        Where that number comes from, as said in the error of :func:`check_mpi_ranks`.

    Examples
    --------
    >>> mpi_slots({"SLURM_NTASKS": "4096"})
    (4096, 'SLURM_NTASKS=4096')
    >>> mpi_slots({})[0] >= 1
    True
    """
    import re

    env = os.environ if environ is None else environ
    from ..runtime.workers import default_workers

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else default_workers()
    best = (cores, f"{cores} core(s) here")
    for name in ALLOCATION_VARIABLES:
        value = env.get(name, "").strip()
        if value.isdigit() and int(value) > best[0]:
            best = (int(value), f"{name}={value}")
    for name in HOSTFILE_VARIABLES:
        path = env.get(name)
        if not path:
            continue
        try:
            lines = Path(path).read_text(errors="replace").splitlines()
        except OSError:
            continue
        slots = 0
        for line in lines:
            line = line.split("#", 1)[0].strip()
            if line:
                m = re.search(r"\bslots\s*=\s*(\d+)", line)
                slots += int(m.group(1)) if m else 1
        if slots > best[0]:
            best = (slots, f"{slots} slot(s) in {name}")
    return best


def check_mpi_ranks(mpi: int | None, workers: int | None = None, environ: dict | None = None,
                    usable=None) -> None:
    """Refuse ``mpi`` ranks per run (× ``workers`` runs at once) beyond :func:`mpi_slots`.

    Parameters
    ----------
    mpi : int or None
        MPI ranks of each run (``--mpi``); None (no ``mpirun``) is accepted as it is.
    workers : int, optional
        Runs at once (``--workers``); None counts one.
    environ : dict, optional
        As :func:`mpi_slots`.
    usable : callable, optional
        ``usable(n)``: the most ranks, ``n`` at most, the run itself can be cut among (a LIGGGHTS triaxial
        specimen's, :func:`grainforge.simulate.liggghts_triaxial.largest_ranks`), so that the ``--mpi`` the line
        suggests passes that check too; default any ``n``.

    Raises
    ------
    ValueError
        Naming the cores (or the allocation) and the largest ``--mpi`` that fits.

    Examples
    --------
    >>> check_mpi_ranks(100000, environ={})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: mpi 100000: only ... rank(s) available (... core(s) here); use mpi ... or fewer, or run ...
    >>> check_mpi_ranks(64, environ={"SLURM_NTASKS": "100000"})  # a batch allocation provides them
    """
    if mpi is None:
        return
    slots, source = mpi_slots(environ)
    runs = workers or 1
    if mpi * runs > slots:
        what = f"{{mpi}} {mpi}" + (f" × {{workers}} {runs}" if runs > 1 else "")
        largest = max(1, slots // runs)
        if usable is not None:
            largest = max(1, usable(largest))
        raise InputError(f"{what}: only {slots} rank(s) available ({source}); use {{mpi}} {largest} or fewer"
                         + (" (or fewer {workers})" if runs > 1 else "")
                         + ", or run inside a batch allocation or with a hostfile that provides more",
                         setting=("mpi", "workers"))
