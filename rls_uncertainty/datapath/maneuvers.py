"""Maneuvers within one data stream: where each starts and ends, and what it ended with (numpy only).

A flight-test day is a card of test points flown one after another in one recording. With
``maneuvers.source`` other than ``off``, a :class:`ManeuverTracker` fed by the caller of the
:class:`.pipeline.Pipeline` (the node, the replay, the campaign of one recording) cuts the
stream into maneuvers:

* ``events``: from messages on ``maneuvers.topic`` (``diagnostic_msgs/msg/KeyValue``: ``key``
  the test point's name, ``value`` ``start`` or ``stop``), read by
  :func:`.maneuver_detector.event_boundary`: a key or value that is not text
  (``event_type``), an empty or unprintable name or one over 64 characters (``event_key``), a
  value other than start or stop (``event_value``), a stop without a start
  (``stop_without_start``) or of another test point (``stop_other_name``) and a start while a
  maneuver runs (``start_twice``) are rejected with their reason and counted, never acted on;
* ``detect``: from the excitation itself, by :class:`.maneuver_detector.ManeuverDetector`
  (its rule and thresholds, ``maneuvers.f_max``, ``.window``, ``.threshold``, ``.rise``,
  ``.hold``, are there), fed the control-surface positions before the pipeline sees them;
* ``off`` (the default): no tracker; one estimate runs across everything, as without maneuvers.

A boundary is acted on when it is declared: an event when it arrives, a detected start
``maneuvers.rise`` after the crossing, a detected end ``maneuvers.hold`` after the power fell
back. At a maneuver's start the estimator starts afresh (:meth:`.pipeline.Pipeline.reset` with
``clear_inputs=False``: the buffered inputs, the differentiator and its delay line are kept, so
the samples waiting there reach the new estimator). At its end the tracker records, per
parameter, the final estimate (each model's last published sample stamped at or before the
end's stamp: a detected end is stamped about a window before it is declared, and the samples
between are trim), the
conventional (Eq. 13) and corrected (Eq. 22) standard errors, with the pipeline's regression
rows kept (``record``) the corrected one with all lags (Eq. 20), the state and its reason
(:mod:`.states`), the model's R^2 and samples and, with ``targets.percent`` set, the test
point's verdict (:mod:`.targets`; all three at the end's declaration), the fitted models with
their covariances for ``models.json`` (:mod:`.fitted`, the estimator's state at the end's
declaration: under ``detect`` it has taken the trim samples up to the declaration too), and
the maneuver's start, end and duration (the boundaries' stamps). With the frequency domain
published (``estimator.method`` ``frequency`` or ``both``) each parameter's frequency-domain row
follows its time-domain one: the newest frequency-domain results ready before the end. The
rows have the campaign's columns (:data:`MANEUVER_COLUMNS`); a maneuver shorter than
``min_span`` has every row ``too_short`` as in a campaign. The history keeps the newest
``maneuvers.history`` maneuvers (a ring: the oldest is dropped, and counted), so memory is
bounded whatever the length of the flight. (The regression rows behind the all-lags standard
errors are the pipeline's, kept only with ``record``, as in a replay or campaign: they restart at
each maneuver's start.)
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import Refused
from .config import SOURCES, ManeuverSettings
from .fitted import FittedModel, run_models
from .maneuver_detector import Boundary, ManeuverDetector, event_boundary
from .pipeline import all_lags_bank
from .states import parameter_states, se_percent

if TYPE_CHECKING:  # annotations only
    from .pipeline import Pipeline, SampleOutput

__all__ = ["ManeuverSettings", "ParameterResult", "OK", "ManeuverRecord", "ManeuverTracker", "Boundary",
           "MANEUVER_COLUMNS", "MIN_SPAN", "SOURCES", "EVENT_TYPE", "EVENT",
           "tracker_for", "maneuvers_csv", "verdict_of", "history_json", "history_key", "HISTORY_TOPIC"]

HISTORY_TOPIC = "maneuvers"  # the node's ~/maneuvers: the history as JSON (:func:`history_json`)

EVENT_TYPE = "diagnostic_msgs/msg/KeyValue"
EVENT = "event"  # the kind of an event message in a stream of (kind, stamp, message)
START, END = "start", "end"
OK = "ok"  # a row's status when the maneuver gave its values

# The shortest maneuver whose parameters can be flagged converged at the defaults: the T-2 models'
# publication span (2.1 s: 2 x 50 lags + 4 parameters at 50 Hz) plus convergence.window (2 s).
MIN_SPAN = 4.0

# A maneuver's row: the campaign's maneuvers.csv columns (every field of ParameterResult, the percent
# error, the method beside the parameter).
MANEUVER_COLUMNS = ("maneuver", "model", "parameter", "method", "estimate", "se_conventional", "se_corrected",
                    "se_corrected_all", "samples", "r_squared", "status", "se_percent", "state", "reason", "verdict")


@dataclass(frozen=True)
class ParameterResult:
    """A row of ``maneuvers.csv``: one parameter's end-of-maneuver values of one ``method``.
    Time domain (``"time"``): ``se_corrected`` is the corrected standard error with the
    configured lags (Eq. 22), ``se_corrected_all`` with all lags (Eq. 20), ``se_conventional``
    Eq. 13; ``samples`` those the model's estimator used, ``r_squared`` its fit. Frequency
    domain (``"frequency"``): ``se_corrected`` the corrected standard error the node publishes
    (docs/frequency.md F7-F10, ``frequency.lag_span``), ``se_conventional`` F5,
    ``se_corrected_all`` NaN (all lags is a time-domain variant), ``samples`` those behind the
    frequency-domain record's last evaluation, ``r_squared`` NaN (the frequency-domain
    estimator has no R^2 of its own). NaN where the maneuver gave none."""

    maneuver: str
    model: str
    parameter: str
    estimate: float
    se_conventional: float
    se_corrected: float
    se_corrected_all: float
    samples: int
    r_squared: float
    status: str
    method: str = "time"
    state: str = ""
    reason: str = ""
    verdict: str = ""  # the maneuver's verdict against its targets (:mod:`.targets`), empty without targets

    @property
    def ok(self) -> bool:
        return self.status == OK

    @property
    def se_percent(self) -> float:
        """``100 se_corrected / |estimate|`` (NaN when undefined)."""
        return se_percent(self.estimate, self.se_corrected)


@dataclass(frozen=True)
class ManeuverRecord:
    """A maneuver: its ``name``, ``start_ns`` and ``end_ns`` (the boundaries' stamps), its rows
    and its fitted ``models`` (module docstring)."""

    name: str
    start_ns: int
    end_ns: int
    rows: tuple[ParameterResult, ...]
    models: tuple[FittedModel, ...] = field(default=(), compare=False)  # (numpy arrays: not compared)

    @property
    def duration(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    def as_dict(self, origin_ns: int = 0) -> dict[str, Any]:
        """The record as plain values (JSON): start and end in s from ``origin_ns``; NaN as None."""
        def cell(x: object) -> object:
            return None if isinstance(x, float) and not math.isfinite(x) else x
        return {"name": self.name, "start": (self.start_ns - origin_ns) * 1e-9, "end": (self.end_ns - origin_ns) * 1e-9,
                "duration": self.duration,
                "rows": [{c: cell(getattr(r, c)) for c in MANEUVER_COLUMNS if c != "maneuver"} for r in self.rows]}


@dataclass
class _Open:
    name: str
    start_ns: int
    last: list[Any] = field(default_factory=list)  # per model: its newest ready SampleOutput
    # per model: its newest SampleOutput whose frequency-domain results are ready
    last_frequency: list[Any] = field(default_factory=list)


class ManeuverTracker:
    """Cuts one pipeline's stream into maneuvers (module docstring). The caller hands it the
    event messages (:meth:`event`), or the boundaries of a detector (:meth:`boundary`), and every
    :class:`.pipeline.SampleOutput` (:meth:`sample`); :attr:`pipe` follows a reconfigured
    pipeline. ``detector``: for ``detect``, a callable ``(stamp_ns, positions) -> boundaries``
    fed by :meth:`surfaces`."""

    def __init__(self, pipe: Pipeline, options: ManeuverSettings, *, min_span: float = MIN_SPAN,
                 detector: ManeuverDetector | None = None, keep_all: bool = False) -> None:
        self.pipe = pipe
        self.options = options
        self.min_span = min_span
        self.detector = detector
        # The newest maneuvers.history maneuvers; every one with keep_all (an offline run's outputs).
        self.history: deque[ManeuverRecord] = deque(maxlen=None if keep_all else options.history)
        self.recorded = 0  # maneuvers recorded (dropped from the history ones too)
        self.rejected: dict[str, int] = {}  # event rejections by reason
        self.active: _Open | None = None
        # The newest outputs, for an end stamped before it is declared (detect: window + hold).
        span = pipe.config.detection.window + pipe.config.detection.hold + 1.0 if detector is not None else 0.0
        self._recent: deque[SampleOutput] = deque(maxlen=1 + math.ceil(span * pipe.config.rate))

    # ------------------------------------------------------------------ boundaries in
    def event(self, stamp_ns: int, key: object, value: object) -> str | None:
        """One event message (``key``, ``value``): acted on, or rejected with its reason
        (returned, and counted in :attr:`rejected`). It is placed in data time: at the stamp of
        the newest sample the estimator used when it arrives (the samples after it are the new
        maneuver's; at an end, the stamp of the final estimates), ``stamp_ns`` (the caller's
        clock) before any sample. So the node, the replay and a campaign of the same messages in
        the same order place it alike, whatever clock or playback speed."""
        newest = self.pipe.last_stamp_ns
        judged = event_boundary(int(stamp_ns) if newest is None else newest, key, value)
        if isinstance(judged, Refused):
            return self.reject(judged.reason)
        return self.boundary(judged)

    def surfaces(self, stamp_ns: int, positions: Sequence[float]) -> None:
        """Control-surface positions for the detector (``detect``), whose boundaries are acted on."""
        if self.detector is not None:
            for b in self.detector.update(stamp_ns, positions):
                self.boundary(b)

    def boundary(self, b: Boundary) -> str | None:
        """Start or end a maneuver; a start while one runs (``start_twice``), an end with none
        running (``stop_without_start``) or of another test point (``stop_other_name``) is
        rejected: its reason is returned and counted."""
        active = self.active
        if b.kind == START:
            if active is not None:
                return self.reject("start_twice")
            self.pipe.reset("maneuver_start", clear_inputs=False)
            self._recent.clear()
            self.active = _Open(b.name, b.stamp_ns, [None] * len(self.pipe.sizes), [None] * len(self.pipe.sizes))
            return None
        if active is None:
            return self.reject("stop_without_start")
        if b.name != active.name:
            return self.reject("stop_other_name")
        self._record(max(b.stamp_ns, active.start_ns))
        return None

    def finish(self, stamp_ns: int) -> None:
        """End of data: a maneuver still running ends at ``stamp_ns`` (the detector's end, with
        ``detect``) and is recorded."""
        if self.detector is not None:
            for b in self.detector.finish(int(stamp_ns)):
                self.boundary(b)
        if self.active is not None:
            self._record(max(int(stamp_ns), self.active.start_ns))

    def reject(self, reason: str) -> str:
        """Count an event rejected for ``reason`` (also one the caller could not decode)."""
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return reason

    def follow(self, pipe: Pipeline) -> None:
        """Go on with ``pipe`` (a reconfigured pipeline); a running maneuver keeps its start
        and name, its final outputs are the new pipeline's."""
        self.pipe = pipe
        if self.active is not None:
            self.active.last = [None] * len(pipe.sizes)
            self.active.last_frequency = [None] * len(pipe.sizes)

    # ------------------------------------------------------------------ samples in
    def sample(self, out: SampleOutput) -> None:
        """A sample of the pipeline: each ready model's newest output within the maneuver."""
        active = self.active
        if active is None:
            return
        for j in np.flatnonzero(out.ready).tolist():
            active.last[j] = out
        if out.frequency is not None:
            for j in np.flatnonzero(out.frequency.ready).tolist():
                active.last_frequency[j] = out
        self._recent.append(out)

    # ------------------------------------------------------------------ the record
    def _record(self, end_ns: int) -> None:
        active = self.active
        assert active is not None
        self.active = None
        self._settle(active, end_ns)
        rows = tuple(self._rows(active, end_ns))
        verdict = verdict_of(self.pipe)
        if verdict:
            rows = tuple(replace(r, verdict=verdict) for r in rows)
        duration = (end_ns - active.start_ns) * 1e-9
        models = tuple(run_models(self.pipe))
        if duration < self.min_span:
            short = (f"too_short: {duration:.2f} s of data, fewer than --min-span {self.min_span:g} s")
            rows, models = tuple(replace(r, status=short) for r in rows), ()
        self.history.append(ManeuverRecord(active.name, active.start_ns, end_ns, rows, models))
        self.recorded += 1

    def _settle(self, active: _Open, end_ns: int) -> None:
        """Each model's final output: its newest ready one stamped at or before ``end_ns``
        (among the outputs kept; none: no estimate)."""
        recent = self._recent
        if not recent or recent[-1].stamp_ns <= end_ns:
            return
        for j in range(len(active.last)):
            active.last[j] = next((o for o in reversed(recent) if o.stamp_ns <= end_ns and o.ready[j]), None)
            active.last_frequency[j] = next((o for o in reversed(recent) if o.stamp_ns <= end_ns
                                             and o.frequency is not None and o.frequency.ready[j]), None)
        recent.clear()

    def _all_lags(self, end_ns: int) -> tuple[np.ndarray | None, int | None]:
        """The corrected standard errors with all lags (Eq. 20) over the maneuver's regression
        rows up to ``end_ns`` and the stamp of the last (None without rows: ``record`` off)."""
        pipe = self.pipe
        rows = [r for r in pipe.regression if r[0] <= end_ns] if pipe.record else []
        if not rows or not pipe.config.publishes_time:
            return None, None
        bank = all_lags_bank(pipe, end_ns)
        se = bank.standard_errors_all("corrected") if bank.ready.any() else None
        return se, rows[-1][0]

    def _rows(self, active: _Open, end_ns: int) -> list[ParameterResult]:
        """Per model and parameter its time-domain row, then its frequency-domain one (the
        methods ``estimator.method`` publishes, :meth:`.config.PipelineConfig.row_methods`)."""
        pipe = self.pipe
        states = {s.parameter: s for s in parameter_states(pipe, pipe.last)}
        frequency = pipe.config.frequency is not None
        f_states = {s.parameter: s for s in parameter_states(pipe, pipe.last, "frequency")} if frequency else {}
        f_samples = pipe.frequency.bank.evaluated_at if pipe.frequency is not None else 0
        se_all, last_row = self._all_lags(end_ns)
        nan = math.nan
        rows = []
        for j, m in enumerate(pipe.models):
            fit = pipe.model_fit(j)
            samples, r2 = int(fit.get("samples", 0)), float(fit.get("r_squared", nan))
            out = active.last[j]
            for i, p in enumerate(pipe.parameter_names[j]):
                for method in pipe.config.row_methods(m, p):
                    if method == "frequency":
                        rows.append(self._frequency_row(active, j, p, f_samples, f_states.get(p)))
                        continue
                    s = states.get(p)
                    st, why = ("", "") if s is None else (s.state, s.reason)
                    if out is None:
                        rows.append(ParameterResult(active.name, m.output, p, nan, nan, nan, nan, samples, r2,
                                                    "no estimate: its model never became ready", "time", st, why))
                        continue
                    s_all = float(se_all[j, i]) if se_all is not None and out.stamp_ns == last_row else nan
                    rows.append(ParameterResult(active.name, m.output, p, float(out.theta[j, i]),
                                                float(out.se_conventional[j, i]), float(out.se[j, i]), s_all, samples,
                                                r2, OK, "time", st, why))
        return rows

    def _frequency_row(self, active: _Open, j: int, parameter: str, samples: int,
                       state: Any) -> ParameterResult:
        """Model ``j``'s ``parameter`` from its newest frequency-domain results in the maneuver
        (``samples``: those behind the last evaluation; ``se_corrected_all`` and ``r_squared``
        NaN, as in a campaign's frequency-domain rows)."""
        m, nan = self.pipe.models[j], math.nan
        st, why = ("", "") if state is None else (state.state, state.reason)
        out = active.last_frequency[j]
        if out is None:
            return ParameterResult(active.name, m.output, parameter, nan, nan, nan, nan, samples, nan,
                                   "no estimate: its frequency-domain estimator never became ready", "frequency",
                                   st, why)
        f, k = out.frequency, m.frequency_parameter_names.index(parameter)
        return ParameterResult(active.name, m.output, parameter, float(f.theta[j, k]), float(f.se_conventional[j, k]),
                               float(f.se[j, k]), nan, samples, nan, OK, "frequency", st, why)

    # ------------------------------------------------------------------ reporting
    def summary(self) -> dict[str, Any]:
        """For ``/diagnostics``: the source, the maneuver running (name, ``-`` none), those
        recorded and kept, the rejected events by reason, and the newest maneuver's name,
        duration and parameters converged."""
        newest = self.history[-1] if self.history else None
        out: dict[str, Any] = {
            "maneuvers.source": self.options.source,
            "maneuvers.active": self.active.name if self.active is not None else "-",
            "maneuvers.recorded": self.recorded,
            "maneuvers.kept": len(self.history),
            "maneuvers.events_rejected": sum(self.rejected.values()),
        }
        for reason, n in sorted(self.rejected.items()):
            out[f"maneuvers.events_rejected.{reason}"] = n
        if newest is not None:
            ok = [r for r in newest.rows if r.status == OK]
            out["maneuvers.last"] = newest.name
            out["maneuvers.last.duration"] = round(newest.duration, 3)
            out["maneuvers.last.converged"] = f"{sum(r.state == 'converged' for r in ok)} of {len(newest.rows)}"
        return out


def verdict_of(pipe: Pipeline) -> str:
    """The test point's verdict against its targets at ``pipe``'s newest sample
    (:meth:`.targets.TargetTracker.verdict`: ``done``, ``needs more (...)``, ``not identifiable
    (...)``); empty without targets or before any sample."""
    targets = pipe.targets
    return targets.verdict().text if targets is not None and targets.progress else ""


def tracker_for(pipe: Pipeline, *, min_span: float = MIN_SPAN, keep_all: bool = False) -> ManeuverTracker | None:
    """The tracker of ``pipe``'s ``maneuvers.*`` settings (None with ``source: off``); with
    ``detect``, fed by the maneuver detector (:mod:`.maneuver_detector`)."""
    options = pipe.config.maneuvers
    if options.source == "off":
        return None
    detector = ManeuverDetector(pipe.config.detection) if options.source == "detect" else None
    return ManeuverTracker(pipe, options, min_span=min_span, detector=detector, keep_all=keep_all)


def _cell(x: object) -> str:
    if isinstance(x, float):
        return "" if math.isnan(x) else repr(float(x))
    return str(x)


def maneuvers_csv(records: Sequence[ManeuverRecord], origin_ns: int) -> str:
    """``maneuvers.csv`` of a run cut into maneuvers: :data:`MANEUVER_COLUMNS` plus ``start``
    and ``end`` (s from ``origin_ns``, the recording's start), one row per maneuver and
    parameter, full precision, empty cells where a maneuver gave no value."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow((*MANEUVER_COLUMNS, "start", "end"))
    for rec in records:
        span = (_cell((rec.start_ns - origin_ns) * 1e-9), _cell((rec.end_ns - origin_ns) * 1e-9))
        for row in rec.rows:
            w.writerow([_cell(getattr(row, c)) for c in MANEUVER_COLUMNS] + list(span))
    return buf.getvalue()


def history_json(tracker: ManeuverTracker) -> str:
    """The history message (``~/maneuvers``): ``{"source", "recorded", "rejected": {reason: n},
    "active": name or null, "maneuvers": [...]}``, each maneuver ``{"name", "start", "end",
    "duration", "rows"}`` (start and end in s, data time: the inputs' header stamps; ``rows``
    one per parameter with the campaign's columns, ``null`` where there is no value:
    :meth:`ManeuverRecord.as_dict`)."""
    return json.dumps({
        "source": tracker.options.source,
        "recorded": tracker.recorded,
        "rejected": dict(sorted(tracker.rejected.items())),
        "active": tracker.active.name if tracker.active is not None else None,
        "maneuvers": [rec.as_dict() for rec in tracker.history],
    }, allow_nan=False)


def history_key(tracker: ManeuverTracker) -> tuple:
    """What changes the history message: the maneuvers recorded, the one running, the rejections."""
    return (tracker.recorded, tracker.active.name if tracker.active else None, tuple(sorted(tracker.rejected.items())))
