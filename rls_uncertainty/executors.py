"""Where independent jobs run: local worker processes, or an existing Dask distributed cluster.

A campaign's maneuvers (:mod:`.campaign`) and a Monte Carlo's noise levels (:mod:`.montecarlo`)
are independent jobs: one function applied to each of a list of arguments. An :class:`Executor`
runs them (:meth:`Executor.run`) and returns the results in the order of the arguments,
whichever process finished first, so every sum the caller forms over them is the same
whatever ran them.

* :class:`LocalProcesses` - ``workers`` processes of this machine (``concurrent.futures``;
  every core by default). A worker process that dies (killed, out of memory) breaks the pool:
  the jobs it had not finished are run again in a new pool, at most :data:`ATTEMPTS` times
  in all.
* :class:`DaskCluster` - the cluster whose scheduler listens at ``address``
  (``tcp://host:8786``). Dask runs a job again on another worker when its worker dies,
  until the scheduler's ``allowed-failures`` is reached; the job is then lost. The function
  and its arguments are pickled to the workers, which must have this package installed and
  read the same file paths (docs/campaign.md). An unreachable scheduler is a
  :class:`.errors.SchedulerUnreachable` within ``timeout`` seconds.

A lost job comes back as a :class:`Lost` (why, in one line) in its place: the caller names it
in its outputs. The executor's own errors are the only ones turned into :class:`Lost`: an
exception raised by the job itself is re-raised (jobs catch their own input errors).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from .errors import ConfigError, SchedulerUnreachable

__all__ = ["ATTEMPTS", "Lost", "Executor", "LocalProcesses", "DaskCluster", "executor_for"]

T = TypeVar("T")
A = TypeVar("A")
# Runs of a job in local processes before it is given up as lost (a pool broken by a dead
# worker makes every unfinished job of the pool try again).
ATTEMPTS = 3
DEFAULT_TIMEOUT = 10.0  # s, to reach a scheduler


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


class LocalProcesses:
    """``workers`` processes of this machine (default: every core); one job runs in this
    process when there is a single job or a single worker."""

    def __init__(self, workers: int | None = None) -> None:
        if workers is not None and not (type(workers) is int and workers >= 1):
            raise ConfigError(f"workers must be an integer >= 1, got {workers!r} (--workers)")
        self.workers = workers or os.cpu_count() or 1
        self.description = f"{self.workers} local process{'es' if self.workers > 1 else ''}"

    def run(self, fn: Callable[[A], T], args: Sequence[A], done: Done | None = None) -> list[T | Lost]:
        results: list[T | Lost | None] = [None] * len(args)
        if self.workers == 1 or len(args) <= 1:
            for i, a in enumerate(args):
                results[i] = fn(a)
                if done is not None:
                    done(i + 1, len(args))
            return results  # type: ignore[return-value]  # every slot filled
        pending = list(range(len(args)))
        finished = 0
        for attempt in range(1, ATTEMPTS + 1):
            broken: list[int] = []
            with ProcessPoolExecutor(max_workers=min(self.workers, len(pending))) as pool:
                futures: dict[Future[T], int] = {pool.submit(fn, args[i]): i for i in pending}
                waiting = set(futures)
                while waiting:
                    ready, waiting = wait(waiting, return_when=FIRST_COMPLETED)
                    for fut in ready:
                        i = futures[fut]
                        try:
                            results[i] = fut.result()
                        except BrokenProcessPool:
                            broken.append(i)
                            continue
                        finished += 1
                        if done is not None:
                            done(finished, len(args))
            if not broken:
                break
            pending = sorted(broken)
            if attempt == ATTEMPTS:
                for i in pending:
                    results[i] = Lost(f"its worker process died in each of {ATTEMPTS} attempts")
                    finished += 1
                    if done is not None:
                        done(finished, len(args))
        return results  # type: ignore[return-value]  # every slot filled


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

    def _client(self) -> Any:
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
        from distributed import as_completed  # noqa: PLC0415 - only when a cluster is asked for

        client = self._client()
        try:
            futures = client.map(fn, list(args), pure=False, retries=self.retries)
            index = {f.key: i for i, f in enumerate(futures)}
            results: list[T | Lost | None] = [None] * len(args)
            for finished, fut in enumerate(as_completed(futures, loop=client.loop), 1):
                i = index[fut.key]
                if fut.status == "error":
                    exc = fut.exception()
                    if not _lost_worker(exc):
                        raise exc
                    results[i] = Lost(f"its worker died ({type(exc).__name__}: {' '.join(str(exc).split())[:160]})")
                else:
                    results[i] = fut.result()
                if done is not None:
                    done(finished, len(args))
            return results  # type: ignore[return-value]  # every slot filled
        finally:
            client.close()


def _lost_worker(exc: BaseException) -> bool:
    """Whether Dask gave up on a job because of its workers (not an error of the job)."""
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
