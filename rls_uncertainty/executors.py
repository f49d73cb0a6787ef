"""Where independent jobs run: local worker processes, or an existing Dask distributed cluster.

A campaign's maneuvers (:mod:`.campaign`) and a Monte Carlo's noise levels (:mod:`.montecarlo`)
are independent jobs: one function applied to each of a list of arguments. An :class:`Executor`
runs them (:meth:`Executor.run`) and returns the results in the order of the arguments,
whichever process finished first, so every sum the caller forms over them is the same
whatever ran them.

* :class:`LocalProcesses` - ``workers`` processes of this machine (every core by default;
  never more than its cores, nor than the jobs), each fed through a pipe of its own. A worker
  process that dies (killed, out of memory) is replaced and its job runs again, at most
  :data:`ATTEMPTS` times in all. The workers never outlive the process that started them: an
  interrupted :meth:`LocalProcesses.run` (Ctrl-C, a signal turned into an exception) kills
  them before it returns, they ignore SIGINT (a Ctrl-C reaches the whole process group: their
  parent ends them), and one whose parent dies, however (SIGKILL), is killed by the kernel
  (``PR_SET_PDEATHSIG`` on Linux) or ends at the end of its pipe (it holds no other copy of
  it).
* :class:`DaskCluster` - the cluster whose scheduler listens at ``address``
  (``tcp://host:8786``). Dask runs a job again on another worker when its worker dies,
  until the scheduler's ``allowed-failures`` is reached; the job is then lost. The function
  and its arguments are pickled to the workers, which must have this package installed and
  read the same file paths (docs/campaign.md). An unreachable scheduler is a
  :class:`.errors.SchedulerUnreachable` within ``timeout`` seconds, and so is one lost in the
  middle of a run; the client is closed whatever ends the run.

A lost job comes back as a :class:`Lost` (why, in one line) in its place: the caller names it
in its outputs. The executor's own errors are the only ones turned into :class:`Lost`: an
exception raised by the job itself is re-raised (jobs catch their own input errors).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import connection
from typing import Any, ClassVar, Protocol, TypeVar

from .errors import ConfigError, SchedulerUnreachable
from .extras import optional, require

__all__ = ["ATTEMPTS", "Lost", "Executor", "LocalProcesses", "DaskCluster", "executor_for", "usable_cores"]

T = TypeVar("T")
A = TypeVar("A")
# Runs of a job in local processes before it is given up as lost (its worker process died in
# each; the other workers' jobs are not affected).
ATTEMPTS = 3
DEFAULT_TIMEOUT = 10.0  # s, to reach a scheduler
_PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent dies (Linux)


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells, else every
    core of the machine)."""
    with contextlib.suppress(AttributeError, OSError):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


@dataclass(frozen=True)
class Lost:
    """A job no worker finished: ``why`` in one line."""

    why: str


Done = Callable[[int, int], object]  # (jobs finished, jobs in all)


class Executor(Protocol):
    """Runs ``fn(arg)`` for every argument; results in the arguments' order; ``done`` is told
    each time a job ends."""

    description: str

    def run(self, fn: Callable[[A], T], args: Sequence[A], done: Done | None = None) -> list[T | Lost]: ...


class _Worker:
    """One local worker process with its own pipe: no queue or lock is shared between
    workers, so one that dies (killed, out of memory) cannot leave the others blocked (a
    killed :class:`concurrent.futures.ProcessPoolExecutor` worker can die holding its
    shared call queue's lock)."""

    # The parent's ends of every live worker's pipe: a new worker closes its copies of them, so
    # that its own pipe ends (EOF) when the parent is gone, whichever worker started last.
    parent_ends: ClassVar[set[Any]] = set()

    def __init__(self, fn: Callable[[Any], Any]) -> None:
        # fork: the worker is this process's child (PR_SET_PDEATHSIG follows the parent) and
        # inherits the job's function without pickling it.
        ctx = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods() else None)
        self.conn, child = ctx.Pipe()
        _Worker.parent_ends.add(self.conn)
        self.proc = ctx.Process(target=_serve, args=(child, fn, os.getpid()), daemon=True)
        self.proc.start()
        child.close()
        self.job: int | None = None  # the index of the job it runs, None while idle

    def give(self, i: int, arg: Any) -> None:
        self.job = i
        self.conn.send((i, arg))

    def stop(self, *, wait: bool = True) -> None:
        """Ask it to end and wait for it (``wait``), then make sure it has: a worker of a failed
        or interrupted run is killed at once."""
        if wait:
            with contextlib.suppress(OSError):  # it is gone already
                self.conn.send(None)
            self.proc.join(timeout=5.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        _Worker.parent_ends.discard(self.conn)
        self.conn.close()


def _die_with(parent: int) -> None:
    """In a new worker: end when ``parent`` ends. Ctrl-C and a hang-up reach the whole process
    group: they are its parent's to handle (ignored here); SIGTERM ends it (not the parent's
    handler it inherited); the kernel kills it when its parent dies (Linux); and it holds no
    parent's end of any worker's pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for end in list(_Worker.parent_ends):
        with contextlib.suppress(OSError):
            end.close()
    _Worker.parent_ends.clear()
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != parent:  # it died before the request took effect
        os._exit(1)


def _serve(conn: Any, fn: Callable[[Any], Any], parent: int) -> None:
    """A worker's loop: ``(index, argument)`` in, ``(index, ok, result or exception)`` out,
    until ``None`` or the end of the pipe (its parent is gone)."""
    _die_with(parent)
    with contextlib.suppress(EOFError, OSError):
        _loop(conn, fn)


def _loop(conn: Any, fn: Callable[[Any], Any]) -> None:
    while (item := conn.recv()) is not None:
        i, arg = item
        try:
            conn.send((i, True, fn(arg)))
        except Exception as exc:  # noqa: BLE001 - the job's own error, re-raised by the caller
            conn.send((i, False, exc))


class LocalProcesses:
    """``workers`` processes of this machine (default: every core; at most its cores, and at
    most one per job); one job runs in this process when there is a single job or a single
    worker. A job whose worker process dies runs again in a new worker, at most
    :data:`ATTEMPTS` times in all, then comes back as :class:`Lost`."""

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and not (type(workers) is int and workers >= 1):
            raise ConfigError(f"workers must be an integer >= 1, got {workers!r} (--workers)")
        self.requested, self.cores = workers, usable_cores()
        self.workers = min(workers or self.cores, self.cores)
        self.description = f"{self.workers} local process{'es' if self.workers > 1 else ''}"

    def capped(self, jobs: int, what: str = "job") -> str | None:
        """One line saying that fewer processes than asked will run ``jobs`` jobs (``what`` one
        is), and why; None when as many as asked will."""
        used = min(self.workers, max(jobs, 1))
        if self.requested is None or used >= self.requested:
            return None
        processes = f"{used} local process{'es' if used > 1 else ''}"
        return (f"--workers {self.requested}: using {processes} instead: at most one per core ({self.cores} here) and "
                f"one per {what} ({jobs} here)")

    def run(self, fn: Callable[[A], T], args: Sequence[A], done: Done | None = None) -> list[T | Lost]:
        results: list[Any] = [None] * len(args)
        if self.workers == 1 or len(args) <= 1:
            for i, a in enumerate(args):
                results[i] = fn(a)
                if done is not None:
                    done(i + 1, len(args))
            return results
        pending, runs, finished = list(range(len(args))), [0] * len(args), 0
        workers = [_Worker(fn) for _ in range(min(self.workers, len(args)))]
        try:
            while pending or any(w.job is not None for w in workers):
                for w in workers:
                    if w.job is None and pending:
                        i = pending.pop(0)
                        runs[i] += 1
                        w.give(i, args[i])
                busy = [w for w in workers if w.job is not None]
                ready = set(connection.wait([w.conn for w in busy] + [w.proc.sentinel for w in busy]))
                for k, w in enumerate(workers):
                    if w.job is None or not (w.conn in ready or w.proc.sentinel in ready):
                        continue
                    i = w.job
                    try:
                        _j, ok, value = w.conn.recv()
                    except (EOFError, OSError):  # the worker died with the job
                        w.job = None
                        w.stop()
                        workers[k] = _Worker(fn)
                        if runs[i] < ATTEMPTS:
                            pending.insert(0, i)
                            continue
                        ok, value = True, Lost(f"its worker process died in each of {ATTEMPTS} attempts")
                    w.job = None
                    if not ok:
                        raise value
                    results[i] = value
                    finished += 1
                    if done is not None:
                        done(finished, len(args))
        except BaseException:
            for w in workers:  # interrupted (Ctrl-C, a signal) or failed: no worker outlives the run
                w.stop(wait=False)
            raise
        for w in workers:
            w.stop()
        return results


class DaskCluster:
    """The Dask distributed cluster whose scheduler listens at ``address``; connecting waits
    at most ``timeout`` seconds. ``retries``: extra runs of a job that raised (a job's own
    errors are caught by the job; this covers a worker lost in the middle of it)."""

    def __init__(self, address: str, *, timeout: float = DEFAULT_TIMEOUT, retries: int = 2) -> None:
        given: object = address  # (whatever a script passed: checked here)
        if not isinstance(given, str) or not given.strip():
            raise ConfigError(f"scheduler address must be host:port or tcp://host:port, got {address!r} (--scheduler)")
        self.address = address.strip()
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.description = f"Dask cluster at {self.address}"
        require("campaign", what="a Dask scheduler (--scheduler)")

    def _client(self) -> Any:
        with optional("campaign"):
            from distributed import Client  # noqa: PLC0415 - only when a cluster is asked for

        try:
            return Client(self.address, timeout=self.timeout, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            why = " ".join(str(exc).split()) or type(exc).__name__
            raise SchedulerUnreachable(
                f"cannot reach the Dask scheduler at {self.address} within {self.timeout:g} s ({why[:200]}); "
                "check --scheduler (tcp://host:port of a running dask scheduler)"
            ) from exc

    def run(self, fn: Callable[[A], T], args: Sequence[A], done: Done | None = None) -> list[T | Lost]:
        client = self._client()
        with _quiet_client():
            return self._run(client, fn, args, done)

    def _run(self, client: Any, fn: Callable[[A], T], args: Sequence[A], done: Done | None) -> list[T | Lost]:
        from distributed import as_completed  # noqa: PLC0415 - only when a cluster is asked for

        finished = 0
        try:
            futures = client.map(fn, list(args), pure=False, retries=self.retries)
            index = {f.key: i for i, f in enumerate(futures)}
            results: list[T | Lost | None] = [None] * len(args)
            for fut in as_completed(futures, loop=client.loop):
                i = index[fut.key]
                if fut.status == "error":
                    exc = fut.exception()
                    if not _lost_worker(exc):
                        raise exc
                    results[i] = Lost(f"its worker died ({type(exc).__name__}: {' '.join(str(exc).split())[:160]})")
                else:
                    results[i] = fut.result()
                finished += 1
                if done is not None:
                    done(finished, len(args))
            return results  # type: ignore[return-value]  # every slot filled
        except _scheduler_lost() as exc:
            why = getattr(exc, "reason", None) or " ".join(str(exc).split())[:160] or type(exc).__name__
            raise SchedulerUnreachable(f"lost the Dask scheduler at {self.address} after {finished} of {len(args)} "
                                       f"jobs ({why}); check that it runs and rerun") from None
        finally:
            client.close(timeout=self.timeout)


@contextlib.contextmanager
def _quiet_client() -> Iterator[None]:
    """The Dask client's own log records are not printed while it runs the jobs: when its
    scheduler goes away, it logs the traceback of each reconnection attempt; what went wrong
    is the one error :meth:`DaskCluster.run` raises."""
    logger = logging.getLogger("distributed.client")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


def _scheduler_lost() -> tuple[type[BaseException], ...]:
    """What the client raises when its scheduler goes away during a run: its futures cancelled
    (``scheduler-connection-lost``), its connection closed."""
    try:
        from distributed.client import FutureCancelledError  # noqa: PLC0415
        from distributed.comm.core import CommClosedError  # noqa: PLC0415
    except ImportError:  # no Dask: no cluster to lose
        return ()
    return (FutureCancelledError, CommClosedError)


def _lost_worker(exc: BaseException) -> bool:
    """Whether Dask gave up on a job because of its workers (not an error of the job)."""
    with optional("campaign"):
        from distributed.scheduler import KilledWorker  # noqa: PLC0415

    return isinstance(exc, (KilledWorker, OSError))


def executor_for(scheduler: str | None, workers: int | None, option: str = "--workers") -> Executor:
    """The executor of the command line: ``--scheduler`` (a Dask cluster) or ``workers``
    local processes (the command's ``option``); both at once is a :class:`.errors.ConfigError`."""
    if scheduler is not None:
        if workers is not None:
            raise ConfigError(f"{option} sets the local processes; with --scheduler the cluster's workers run the "
                              f"jobs (drop {option})")
        return DaskCluster(scheduler)
    return LocalProcesses(workers)
