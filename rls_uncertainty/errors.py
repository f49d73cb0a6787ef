"""Every error the package raises on purpose, in one module.

Each class derives from :class:`RlsUncertaintyError` and from the built-in exception that
matches its meaning, so callers may catch either: ``except RlsUncertaintyError`` catches the
package's own errors (bad input, bad configuration, a bad file) and nothing else, while a
programming error (a numpy shape ``ValueError``, a ``KeyError``) is not caught by it and
shows its traceback. The command line catches only these and :class:`OSError`.

Bad input that is counted rather than raised (a message or sample rejected with its reason)
is a :class:`Refused`: returned by the check instead of its result, so the caller tells the
two apart by type.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "RlsUncertaintyError",
    "ConfigError",
    "StateFileError",
    "BagError",
    "OutputPathError",
    "EstimatorNotReady",
    "NonFiniteInput",
    "UnknownName",
    "NotComparable",
    "LiveTimeout",
    "SchedulerUnreachable",
    "WorkerLost",
    "MissingExtra",
    "Refused",
]


class RlsUncertaintyError(Exception):
    """Base class of the package's errors: a problem with the user's input, not a bug."""


class ConfigError(RlsUncertaintyError, ValueError):
    """A configuration value is missing or invalid; the message says which and why.
    ``parameter``: the setting refused (``inputs.max_gap``), when one is, so that a caller
    can say where its value came from."""

    def __init__(self, message: str, *, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter


class StateFileError(RlsUncertaintyError, ValueError):
    """A saved estimator state cannot be loaded (missing, corrupt or another configuration)."""


class BagError(RlsUncertaintyError, RuntimeError):
    """A bag, schema or mapping problem; the message names the file, topic and problem."""


class OutputPathError(RlsUncertaintyError, ValueError):
    """An output path that a command refuses to write (it would delete or overwrite data the
    command did not create)."""


class EstimatorNotReady(RlsUncertaintyError, RuntimeError):
    """An estimate was asked of a model that is not initialized yet."""


class NonFiniteInput(RlsUncertaintyError, ValueError):
    """A regressor or measured output is NaN or infinite, or the update would make the
    estimator state non-finite (the state is unchanged)."""


class UnknownName(RlsUncertaintyError, LookupError):
    """A name (a parameter, a model) asked of a result that does not have it; the message
    lists the names it has."""


class NotComparable(RlsUncertaintyError, ValueError):
    """Two replays whose outputs cannot be compared sample by sample (another bag, another
    span, other models or sample times); the message says why."""


class LiveTimeout(RlsUncertaintyError, TimeoutError):
    """A live node under test (:mod:`.testing`) did not do what was waited for in time; the
    message says what was missing and where the node's log is."""


class SchedulerUnreachable(RlsUncertaintyError, ConnectionError):
    """The Dask scheduler given with ``--scheduler`` did not answer in time, or went away in the
    middle of a run; the message gives the address and what happened."""


class WorkerLost(RlsUncertaintyError, RuntimeError):
    """A job that no worker finished (its worker died in every attempt); the message names it."""


class MissingExtra(RlsUncertaintyError, ImportError):
    """An optional dependency is not installed (:mod:`.extras`); the message names what needs
    it and the pip extra that installs it. ``extra`` and ``module``: which."""

    def __init__(self, message: str, *, extra: str, module: str) -> None:
        super().__init__(message, name=module)
        self.extra = extra
        self.module = module


@dataclass(frozen=True, slots=True)
class Refused:
    """Not an exception: what a check returns instead of its result when the input cannot be
    used, and why. ``reason`` is the key the caller counts the rejection under
    (``rejected.<reason>``, ``samples_rejected.<reason>``)."""

    reason: str
