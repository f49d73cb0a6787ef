"""What a run of the estimator produced, in the user's terms (numpy only).

A :class:`ReplayResult` is what :func:`.replay.run_pipeline` returns (the offline replay, and
:func:`.testing.replay_bag`) and what :mod:`.testing` collects from a live node's outputs:

* :attr:`ReplayResult.parameters`: every parameter's name (``CZ_alpha``, ``Cm_q``, ...), in the
  order of the configuration's models;
* :meth:`ReplayResult.final`: a parameter's last published estimate with its corrected
  (Eqs. 20/22) and conventional (Eq. 13) standard errors, its convergence flag and stamp;
* :meth:`ReplayResult.series`: a parameter's time history as numpy arrays, one element per
  sample in which its model published (kept when the run was asked to keep a
  :class:`History`);
* both for the frequency-domain estimates too (``method="frequency"``; with
  ``estimator.method`` ``frequency`` or ``both``, :attr:`ReplayResult.methods`): over the
  parameters without the bias (:attr:`ReplayResult.frequency_parameter_names`), their
  corrected (docs/frequency.md F7-F10) and conventional (F5) standard errors;
* :meth:`ReplayResult.counters`: the message and sample accounting (:func:`accounting`).

Memory: :class:`History` keeps every sample, or with a ``capacity`` at most twice that many
evenly spaced ones (every ``stride``-th sample, the stride doubling whenever the history is
full), which is what a plot needs whatever the recording's length.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..errors import EstimatorNotReady, UnknownName

if TYPE_CHECKING:  # annotations only: this module does not need the pipeline to work
    from ..datapath.diagnostics import Status
    from ..datapath.maneuvers import ManeuverTracker
    from ..datapath.pipeline import Pipeline, SampleOutput
    from ..datapath.states import ParameterState

__all__ = ["Final", "Series", "History", "ReplayResult", "accounting", "METHODS"]

# The estimates a run can hold: the time-domain (recursive least squares) and the frequency-domain ones.
METHODS = ("time", "frequency")


class Final(NamedTuple):
    """A parameter's last published estimate: ``std_error`` is the corrected standard error
    (Eqs. 20/22, colored residuals), ``std_error_conventional`` the conventional one (Eq. 13);
    ``converged`` its flag; ``stamp_ns`` the sample's time."""

    estimate: float
    std_error: float
    std_error_conventional: float
    converged: bool
    stamp_ns: int


class Series(NamedTuple):
    """A parameter's time history: one element per kept sample in which its model published.
    ``stamps_ns`` (int64, the sample times), ``estimates``, ``std_errors`` (corrected),
    ``std_errors_conventional``, ``converged`` (bool)."""

    stamps_ns: np.ndarray
    estimates: np.ndarray
    std_errors: np.ndarray
    std_errors_conventional: np.ndarray
    converged: np.ndarray

    @property
    def time(self) -> np.ndarray:
        """The sample times in seconds (float64: microsecond resolution at today's epoch)."""
        return self.stamps_ns * 1e-9


# The per-parameter quantities a History keeps, in the order of History.append's arguments.
_COLUMNS = ("theta", "se", "se_conventional")


class History:
    """Per sample: its stamp, per parameter the estimate, both standard errors (NaN while the
    model is not ready) and the convergence flag, and per model ``ready`` and the lag count
    (-1: not known, as for a live node's outputs). ``parameter_names``: per model, its
    parameters' names. Every sample is kept, or with ``capacity`` at most ``2 * capacity``:
    when full, every other kept sample is dropped and from then on only every ``stride``-th
    sample is kept (the stride doubles), so the samples kept stay evenly spaced."""

    def __init__(self, parameter_names: Sequence[Sequence[str]], capacity: int | None = None) -> None:
        if capacity is not None and capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity!r}")
        self.sizes = [len(names) for names in parameter_names]
        self.capacity = capacity
        self.stride = 1
        self.offered = 0  # samples offered to append (kept or not)
        self.n = 0
        width = sum(self.sizes)
        rows = 64 if capacity is None else 2 * capacity
        self._stamps = np.zeros(rows, dtype=np.int64)
        self._values = np.full((len(_COLUMNS), rows, width), np.nan)
        self._converged = np.zeros((rows, width), dtype=bool)
        self._ready = np.zeros((rows, len(self.sizes)), dtype=bool)
        self._lags = np.full((rows, len(self.sizes)), -1, dtype=np.int64)

    def append(self, stamp_ns: int, theta: np.ndarray, se: np.ndarray, se_conventional: np.ndarray,
               converged: np.ndarray, ready: np.ndarray, lags: np.ndarray | None = None) -> None:
        """One sample: flat per-parameter arrays (models in order) and per-model ``ready`` and
        ``lags``."""
        offered = self.offered
        self.offered += 1
        if offered % self.stride:
            return
        if self.n == self._stamps.size:
            self._make_room()
        i = self.n
        self._stamps[i] = stamp_ns
        values = self._values
        values[0, i], values[1, i], values[2, i] = theta, se, se_conventional
        self._converged[i] = converged
        self._ready[i] = ready
        if lags is not None:
            self._lags[i] = lags
        self.n = i + 1

    def _make_room(self) -> None:
        if self.capacity is None:  # keep everything: grow geometrically
            rows = 2 * self._stamps.size
            self._stamps = np.resize(self._stamps, rows)
            self._values = np.concatenate([self._values, np.full_like(self._values, np.nan)], axis=1)
            self._converged = np.concatenate([self._converged, np.zeros_like(self._converged)])
            self._ready = np.concatenate([self._ready, np.zeros_like(self._ready)])
            self._lags = np.concatenate([self._lags, np.full_like(self._lags, -1)])
            return
        # Full: keep every other sample (those at multiples of the doubled stride).
        half = self.n // 2 + self.n % 2
        for a in (self._stamps, self._converged, self._ready, self._lags):
            a[:half] = a[: self.n : 2]
        self._values[:, :half] = self._values[:, : self.n : 2]
        self.n = half
        self.stride *= 2

    def add(self, out: SampleOutput, real: np.ndarray) -> None:
        """One :class:`.pipeline.SampleOutput`; ``real`` ``(M, n_max)`` marks the parameters
        among its padded rows."""
        if self.offered % self.stride:
            self.offered += 1
            return
        self.append(out.stamp_ns, out.theta[real], out.se[real], out.se_conventional[real], out.converged[real],
                    out.ready, out.lags)

    @property
    def stamps_ns(self) -> np.ndarray:
        return self._stamps[: self.n]

    def column(self, k: int) -> tuple[np.ndarray, ...]:
        """Parameter ``k``'s kept values: estimates, SEs, conventional SEs, flags."""
        n = self.n
        return (self._values[0, :n, k], self._values[1, :n, k], self._values[2, :n, k], self._converged[:n, k])

    def ready(self, j: int) -> np.ndarray:
        """Per kept sample: whether model ``j`` published."""
        return self._ready[: self.n, j]

    def lags(self, j: int) -> np.ndarray:
        """Per kept sample: model ``j``'s lag count of Eq. 22 (-1 when not known)."""
        return self._lags[: self.n, j]


def accounting(counters: Mapping[str, Any]) -> dict[str, Any]:
    """The message and sample accounting of :meth:`.pipeline.Pipeline.counters`: per input
    stream ``received``, ``accepted``, ``rejected`` (by reason), ``expired`` and ``missing``;
    ``samples_formed``, ``samples_used``, ``samples_rejected`` (by reason),
    ``samples_pending`` (waiting in the differentiator's delay line: a live node's last
    samples; a replay counts them as rejected ``end_of_data``) and ``resets`` (by reason)."""
    streams = {kind: {key: (dict(s[key]) if key == "rejected" else s[key])
                      for key in ("received", "accepted", "rejected", "expired", "missing")}
               for kind, s in counters["streams"].items()}
    return {"streams": streams, "samples_formed": counters["samples_formed"],
            "samples_used": counters["samples_used"], "samples_rejected": dict(counters["samples_rejected"]),
            "samples_pending": counters["samples_pending"], "resets": dict(counters["resets"])}


@dataclass
class ReplayResult:
    """What a run produced (module docstring). ``models`` and ``parameter_names`` name the
    outputs; :attr:`estimates` counts the samples in which some model published (0: nothing
    was estimated, which the command line reports with exit status 1); :attr:`explanations`
    says, one line each, why a model never produced an estimate. An in-process run also keeps
    its :attr:`pipeline` and, when asked, every :class:`.pipeline.SampleOutput` in
    :attr:`outputs`; :attr:`last_output` is the newest sample's."""

    models: tuple[str, ...]
    parameter_names: tuple[tuple[str, ...], ...]
    history: History | None = None
    pipeline: Pipeline | None = None
    outputs: list[SampleOutput] = field(default_factory=list)
    last_output: SampleOutput | None = None
    estimates: int = 0
    n_messages: int = 0
    wall_seconds: float = 0.0
    data_seconds: float = 0.0
    # (stamp_ns, statuses) of the /diagnostics the node would have published, one per
    # diagnostics period of data time (empty unless the run was given a NodeConfig).
    diagnostics: list[tuple[int, list[Status]]] = field(default_factory=list)
    explanations: list[str] = field(default_factory=list)
    counter_values: dict[str, Any] = field(default_factory=dict)
    bag_digest: str = ""
    # The methods whose estimates the run published (estimator.method), and the frequency
    # domain's parameters (without the bias) and history.
    methods: tuple[str, ...] = ("time",)
    frequency_parameter_names: tuple[tuple[str, ...], ...] = ()
    frequency_history: History | None = None
    # Each parameter's state at the end, both methods (:mod:`rls_uncertainty.datapath.states`).
    states: list[ParameterState] = field(default_factory=list)
    # With maneuvers.source not off: the maneuvers cut from the stream and their history.
    maneuvers: ManeuverTracker | None = None
    _last: dict[str, Final] = field(default_factory=dict, repr=False)
    _last_frequency: dict[str, Final] = field(default_factory=dict, repr=False)

    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter's name, models in order."""
        return tuple(p for names in self.parameter_names for p in names)

    @property
    def speed(self) -> float:
        """Multiples of real time."""
        return self.data_seconds / self.wall_seconds if self.wall_seconds > 0 else float("inf")

    def _where(self, parameter: str, method: str = "time") -> tuple[int, int]:
        """(model index, column in the flat parameter order) of ``parameter`` among the
        ``method``'s parameters; the method must be one the run published."""
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self._where_in(self.parameter_names, parameter)  # an unknown name is said as such
        if method not in self.methods:
            raise EstimatorNotReady(f"this run published no {method}-domain estimates (estimator.method: "
                                    f"{'both' if len(self.methods) > 1 else self.methods[0]})")
        if method == "time":
            return self._where_in(self.parameter_names, parameter)
        if not any(parameter in names for names in self.frequency_parameter_names):
            raise UnknownName(f"{parameter} is a bias, which the frequency-domain method does not estimate; its "
                              f"parameters: {', '.join(p for names in self.frequency_parameter_names for p in names)}")
        return self._where_in(self.frequency_parameter_names, parameter)

    def _where_in(self, parameter_names: tuple[tuple[str, ...], ...], parameter: str) -> tuple[int, int]:
        k = 0
        for j, names in enumerate(parameter_names):
            if parameter in names:
                return j, k + names.index(parameter)
            k += len(names)
        raise UnknownName(f"no parameter {parameter!r} in this run; its parameters: {', '.join(self.parameters)}")

    def published(self, stamp_ns: int, j: int, theta: Sequence[float] | np.ndarray, se: Sequence[float] | np.ndarray,
                  se_conventional: Sequence[float] | np.ndarray, converged: Sequence[bool] | np.ndarray,
                  method: str = "time") -> None:
        """Model ``j`` published at ``stamp_ns`` (its ``method``-domain estimates): its
        parameters' final values so far."""
        names, last = (self.parameter_names, self._last) if method == "time" else \
            (self.frequency_parameter_names, self._last_frequency)
        for i, p in enumerate(names[j]):
            last[p] = Final(float(theta[i]), float(se[i]), float(se_conventional[i]), bool(converged[i]), int(stamp_ns))

    def final(self, parameter: str, method: str = "time") -> Final:
        """The last published estimate of ``parameter`` with both standard errors, of the
        time-domain estimator or (``method="frequency"``) the frequency-domain one.
        :class:`.errors.UnknownName` for a name not in :attr:`parameters` (or, in the frequency
        domain, a bias), :class:`.errors.EstimatorNotReady` when its model never published or
        the run did not publish that method's estimates."""
        self._where(parameter, method)
        last = self._last if method == "time" else self._last_frequency
        if parameter not in last:
            why = "; ".join(self.explanations) or "its model never produced an estimate"
            what = "estimate" if method == "time" else "frequency-domain estimate"
            raise EstimatorNotReady(f"{parameter}: no {what} in this run ({why})")
        return last[parameter]

    def finals(self, method: str = "time") -> dict[str, Final]:
        """:meth:`final` of every parameter whose model published (``method``'s estimates), in
        the order of the models."""
        names = self.parameter_names if method == "time" else self.frequency_parameter_names
        last = self._last if method == "time" else self._last_frequency
        return {p: last[p] for row in names for p in row if p in last}

    def series(self, parameter: str, method: str = "time") -> Series:
        """``parameter``'s history over the kept samples in which its model published, of the
        time-domain estimates or (``method="frequency"``) the frequency-domain ones (those
        samples where they were published: every ``frequency.every``-th)."""
        j, k = self._where(parameter, method)
        h = self.history if method == "time" else self.frequency_history
        if h is None:
            raise EstimatorNotReady("this run kept no time histories (testing.replay_bag keeps them; so does "
                                    "run_pipeline given a History)")
        ready = h.ready(j)
        theta, se, sc, flags = h.column(k)
        return Series(h.stamps_ns[ready].copy(), theta[ready].copy(), se[ready].copy(), sc[ready].copy(),
                      flags[ready].copy())

    def counters(self) -> dict[str, Any]:
        """The message and sample accounting (:func:`accounting`)."""
        return copy.deepcopy(self.counter_values)
