"""Offline replay: a replay bag through the node's own pipeline, no DDS, as fast as the CPU
allows (``rls-uncertainty replay BAG --config CFG --out DIR``).

The messages go through :func:`.inputs.feed` into one :class:`.pipeline.Pipeline`, exactly
as in the live node, so the node and the replay give the same numbers. The bag is read as a
stream (:class:`.bags.InputStream`) and the outputs are written sample by sample
(:class:`.replay_files.ReplayFiles`): memory does not grow with the recording. Outputs
(written to a temporary directory renamed to ``DIR`` only when complete):

* ``estimates.csv``: ``time,model,parameter,estimate,std_error,std_error_conventional,
  converged,lags``, one row per sample and parameter of every ready model (time in s, the
  sample's stamp; ``converged`` the parameter's flag 1/0; ``lags`` the model's lag count of
  Eq. 22, chosen per sample under ``estimator.lag_selection: auto``);
* ``estimates_wide.csv``: ``time`` and, per parameter P of every model, ``P``, ``P_se``,
  ``P_se_conventional`` and ``P_converged``, and per model M ``M_lags``: one row per sample,
  cells empty while a model is not ready (for PlotJuggler's CSV loader and spreadsheets);
* ``estimates.mcap``: every topic the node publishes. Per sample, byte for byte what the node
  sends (:meth:`.outputs.OutputLayout.encode`: ``/rls_estimator/sample_stamp``, and per model
  ``/rls_estimator/M/estimates``, ``.../standard_errors``, ``.../standard_errors_conventional``,
  ``.../converged``, decimated ``.../covariance`` and ``.../covariance_conventional``), log
  time = the sample's stamp; and ``/diagnostics`` once per ``diagnostics_period`` of data
  time from the node's own diagnostics policy (:class:`_DataClockDiagnostics`), which carries
  each model's lag count, convergence flags and identifiability, with ``/rls_estimator/M/fit``
  and ``/rls_estimator/M/identifiability`` at the same times (:func:`.outputs.fit_records`);
* ``run.json``: the bag's input digest, the span, the parameters and the configuration
  (:func:`.replay_files.run_record`), for ``replay --compare`` (:mod:`.compare`);
* ``summary.txt``: the summary the command prints (:func:`run_summary`);
* ``parameters.csv``: every parameter's state and percent error at the end, both methods
  (:func:`parameters_csv`);
* ``models.json``: each model's final estimates with their corrected and conventional
  covariances and residual variance (:mod:`.model_file`), for ``rls-uncertainty predict``; with
  ``maneuvers.source`` on, one entry per maneuver recorded (as ``campaign RECORDING`` writes);
* per model ``M``, the figures of :func:`.figures.replay_figures` (``M_estimates``, ``M_fit``,
  ``M_autocorrelation``, ``M_lags``, in the requested formats), drawn from at most twice
  :data:`PLOT_POINTS` evenly spaced samples per run and from sums kept as the run goes
  (:class:`.figure_data.FigureData`), so a long recording plots in bounded memory.
Two runs give bit-identical CSV and MCAP files. The progress bars (reading, then drawing) go to stderr,
by default only on a terminal (:mod:`..progress`).
"""

from __future__ import annotations

import csv
import gc
import io
import json
import math
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sized
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..datapath.alerts import no_estimate, not_excited, too_few_samples
from ..datapath.config import PipelineConfig
from ..datapath.diagnostics import DiagnosticsPolicy, Snapshot, Status
from ..datapath.feasibility import configuration_warnings, record_checks
from ..datapath.inputs import Stamped, feed
from ..datapath.maneuvers import (
    EVENT,
    MIN_SPAN,
    ManeuverTracker,
    history_json,
    history_key,
    maneuvers_csv,
    tracker_for,
)
from ..datapath.outputs import NODE_NAME, OutputLayout, fit_records
from ..datapath.pipeline import Pipeline, SampleOutput
from ..datapath.states import parameter_states
from ..files import output_directory
from ..progress import Progress
from ..settings.config import NodeConfig
from ..settings.parameters import node_config, parameter_defaults, pipeline_config
from .bags import InputStream, check_bag
from .figure_data import FigureData
from .model_file import MODELS_FILE, models_json, run_models
from .replay_files import ReplayFiles, run_record
from .report import results_table, rows_from_arrays
from .results import History, ReplayResult, accounting

if TYPE_CHECKING:  # annotations only: the figures are drawn on demand
    from .figures import FigureOptions

__all__ = ["ReplayResult", "run_pipeline", "replay", "planned_run", "summary_table", "run_summary", "unestimated",
           "parameters_csv",
           "NODE_NAME", "PLOT_POINTS"]

# Samples kept for the plots: at most twice this many, evenly spaced (results.History).
PLOT_POINTS = 2048


class Sink(Protocol):
    """What :func:`run_pipeline` hands each output to as the run goes (the replay's files)."""

    def sample(self, out: SampleOutput) -> None: ...

    def diagnostics(self, stamp_ns: int, statuses: list[Status], fits: list[tuple[int, str, str, bytes]]) -> None: ...

    def after(self, newest_ns: int) -> None: ...

    def maneuvers(self, stamp_ns: int, text: str) -> None: ...


class _DataClockDiagnostics:
    """The node's ``/diagnostics`` in a replay: every ``diagnostics_period`` of data time (the
    newest message stamp), one :class:`.diagnostics.Snapshot` of the pipeline into the same
    :class:`.diagnostics.DiagnosticsPolicy` the node uses. Data time stands in for the node's
    clock and steady time; a stream counts one publisher once its first message is read (a
    bag has no DDS matching); latencies and the state file do not apply. Each report goes to
    ``emit(stamp_ns, statuses)`` as it is made."""

    def __init__(self, pipe: Pipeline, config: PipelineConfig, node_cfg: NodeConfig,
                 emit: Callable[[int, list[Status]], None]) -> None:
        self.pipe, self.config, self.node_cfg, self.emit = pipe, config, node_cfg, emit
        self.policy = DiagnosticsPolicy(NODE_NAME, window_s=node_cfg.diagnostics_window)
        self.period_ns = max(1, round(node_cfg.diagnostics_period * 1e9))
        self.previous_ns: int | None = None
        self.newest_ns = 0
        self.seen: set[str] = set()
        self.reports = 0

    def after(self, kind: str, stamp_ns: int) -> None:
        """Called after each message: a snapshot when a period of data time has passed."""
        self.seen.add(kind)
        self.newest_ns = max(self.newest_ns, stamp_ns)
        if self.previous_ns is None:
            self.previous_ns = stamp_ns
        elif self.newest_ns - self.previous_ns >= self.period_ns:
            self.snapshot()

    def finish(self) -> None:
        """The end of the data: one more snapshot, unless data time has not moved since the
        last one (a snapshot over zero elapsed time would divide message counts by zero)."""
        if not self.reports or self.previous_ns is None or self.newest_ns > self.previous_ns:
            self.snapshot()

    def snapshot(self) -> None:
        pipe, node_cfg = self.pipe, self.node_cfg
        elapsed = (self.newest_ns - (self.previous_ns or self.newest_ns)) * 1e-9
        snap = Snapshot(
            counters=pipe.counters(),
            models=[(m.output, pipe.model_report(j)) for j, m in enumerate(self.config.models)],
            required=tuple(pipe.required),
            max_gap=self.config.inputs.max_gap,
            now_ns=self.newest_ns,
            elapsed_s=elapsed,
            publishers={kind: int(kind in self.seen) for kind in node_cfg.topics},
            topics=dict(node_cfg.topics),
            reliable=node_cfg.reliable,
            enabled=pipe.enabled,
            state_file="replay: no state file",
        )
        self.emit(self.newest_ns, self.policy.update(snap))
        self.reports += 1
        self.previous_ns = self.newest_ns


class _Rows:
    """The pipeline's regression rows (``pipe.regression``), taken after each message by
    whoever reads them (the excitation watch, the figures' data); dropped once taken unless
    the caller keeps them (``keep``)."""

    def __init__(self, pipe: Pipeline, keep: bool) -> None:
        self.pipe, self.keep = pipe, keep
        self.seen = 0
        pipe.record = True

    def take(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        rows = self.pipe.regression
        if len(rows) < self.seen:  # the pipeline restarted and dropped its rows
            self.seen = 0
        new = rows[self.seen:]
        if self.keep:
            self.seen = len(rows)
        else:
            rows.clear()
            self.pipe.instruments.clear()  # (estimator.algorithm iv: each row's, beside them)
        return new

    @property
    def pending(self) -> bool:
        """Whether :meth:`take` has anything to do (rows came, or the pipeline dropped them)."""
        return len(self.pipe.regression) != self.seen

    def stop(self) -> None:
        """No reader needs rows any longer: the pipeline records them only if kept."""
        self.pipe.record = self.keep


class _Excitation:
    """Which regressors of each model moved over the run, for :func:`unestimated`: the
    extremes of every regression row. Watching stops once every model has published: then
    nothing needs explaining."""

    def __init__(self, pipe: Pipeline) -> None:
        self.pipe = pipe
        self.low = np.full((len(pipe.sizes), pipe.bank.n_max), np.inf)
        self.high = -self.low
        self.watching = True

    def update(self, rows: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        for _t, X, _z in rows:
            np.minimum(self.low, X, out=self.low)
            np.maximum(self.high, X, out=self.high)

    def constant(self, j: int) -> list[str]:
        """Model ``j``'s regressors (the bias aside) that never moved over the samples used."""
        m, n = self.pipe.models[j], self.pipe.sizes[j]
        lo, hi = self.low[j, :n], self.high[j, :n]
        return [r for i, r in enumerate(m.regressors) if r != "1" and np.isfinite(lo[i]) and lo[i] == hi[i]]


class _Run:
    """One run's bookkeeping of outputs: what the :class:`.results.ReplayResult` keeps, what
    each model published last (per method), and the sink that writes them. ``ever``: per
    model, whether it published (its time-domain estimates, or with ``estimator.method:
    frequency`` its frequency-domain ones)."""

    def __init__(self, pipe: Pipeline, result: ReplayResult, keep_outputs: bool, sink: Sink | None) -> None:
        self.pipe, self.result, self.keep_outputs, self.sink = pipe, result, keep_outputs, sink
        self.time = pipe.config.publishes_time
        self.ever = np.zeros(len(pipe.sizes), dtype=bool)
        self.last: list[SampleOutput | None] = [None] * len(pipe.sizes)
        self.last_frequency: list[SampleOutput | None] = [None] * len(pipe.sizes)
        self.newest_frequency: SampleOutput | None = None  # the newest output with frequency-domain results
        self.real = np.arange(pipe.bank.n_max) < np.array(pipe.sizes)[:, None]
        self.tracker: ManeuverTracker | None = None  # with maneuvers.source not off
        self._history_sent: object = None

    def sample(self, out: SampleOutput) -> None:
        result = self.result
        ready = out.ready if self.time else np.zeros_like(out.ready)
        if ready.any():
            self.ever |= ready
            for j in np.flatnonzero(ready).tolist():
                self.last[j] = out
        if result.history is not None and self.time:
            result.history.add(out, self.real)
        f = out.frequency
        if f is not None:
            self.newest_frequency = out
            if f.ready.any():
                for j in np.flatnonzero(f.ready).tolist():
                    self.last_frequency[j] = out
                if not self.time:
                    self.ever |= f.ready
            if result.frequency_history is not None:
                real = self.pipe.frequency.real  # type: ignore[union-attr]  # out.frequency: the path exists
                result.frequency_history.append(out.stamp_ns, f.theta[real], f.se[real], f.se_conventional[real],
                                                f.converged[real], f.ready, f.lags)
        if ready.any() or (f is not None and f.ready.any()):
            result.estimates += 1
        if self.keep_outputs:
            result.outputs.append(out)
        result.last_output = out
        if self.tracker is not None:
            self.tracker.sample(out)
        if self.sink is not None:
            self.sink.sample(out)

    def history(self, stamp_ns: int) -> None:
        """The maneuver history to the sink when it changed (as the node publishes ``~/maneuvers``)."""
        tracker = self.tracker
        if tracker is not None and self.sink is not None and history_key(tracker) != self._history_sent:
            self._history_sent = history_key(tracker)
            self.sink.maneuvers(stamp_ns, history_json(tracker))

    def diagnostics(self, stamp_ns: int, statuses: list[Status]) -> None:
        if self.keep_outputs:
            self.result.diagnostics.append((stamp_ns, statuses))
        if self.sink is not None:  # with the node's per-period ~/M/fit and ~/M/identifiability
            self.sink.diagnostics(stamp_ns, statuses, fit_records(self.pipe, stamp_ns))

    def finals(self) -> None:
        """Each model's last published values into the result, and every parameter's state at
        the end (:mod:`.datapath.states`)."""
        pipe, result = self.pipe, self.result
        if pipe.config.publishes_time:
            result.states = parameter_states(pipe, result.last_output)
        if pipe.frequency is not None:
            result.states += parameter_states(pipe, self.newest_frequency, "frequency")
        for j, out in enumerate(self.last):
            if out is not None:
                n = self.pipe.sizes[j]
                self.result.published(out.stamp_ns, j, out.theta[j, :n], out.se[j, :n], out.se_conventional[j, :n],
                                      out.converged[j, :n])
        for j, out in enumerate(self.last_frequency):
            if out is not None and out.frequency is not None:
                f, n = out.frequency, len(self.result.frequency_parameter_names[j])
                self.result.published(out.stamp_ns, j, f.theta[j, :n], f.se[j, :n], f.se_conventional[j, :n],
                                      f.converged[j, :n], method="frequency")


def _new_result(pipe: Pipeline, history: History | None) -> ReplayResult:
    """The result of a run of ``pipe``: its models and parameters, the methods it publishes and,
    with the frequency domain, its parameters and a history like ``history``."""
    config = pipe.config
    result = ReplayResult(tuple(m.output for m in config.models), tuple(map(tuple, pipe.parameter_names)),
                          history=history, pipeline=pipe, methods=config.published_methods)
    if config.frequency is not None:
        result.frequency_parameter_names = names = tuple(m.frequency_parameter_names for m in config.models)
        if history is not None:
            result.frequency_history = History(names, history.capacity)
    return result


def routed(messages: Iterable[tuple[str, int, Stamped]],
           tracker: ManeuverTracker | None) -> Iterator[tuple[str, int, Stamped]]:
    """The input messages of ``messages``; the event messages go to ``tracker`` in their place
    (ignored without one), and with ``maneuvers.source: detect`` it sees every surface message."""
    for kind, stamp, msg in messages:
        if kind == EVENT:
            if tracker is not None:
                m: Any = msg
                tracker.event(stamp, getattr(m, "key", None), getattr(m, "value", None))
            continue
        if tracker is not None and kind == "control_surfaces" and tracker.detector is not None:
            tracker.surfaces(stamp, list(getattr(msg, "position", ())))
        yield kind, stamp, msg


def run_pipeline(messages: Iterable[tuple[str, int, Stamped]], config: PipelineConfig, *, record: bool = True,
                 progress: bool | None = False, diagnostics: NodeConfig | None = None, keep_outputs: bool = True,
                 history: History | None = None, sink: Sink | None = None,
                 figure_data: FigureData | None = None, min_span: float = MIN_SPAN) -> ReplayResult:
    """Feed ``(kind, stamp, msg)`` messages (a list, or a :class:`.bags.InputStream` read as it
    goes) through a fresh pipeline. ``record`` keeps every regression row
    (``pipeline.regression``); ``keep_outputs`` every :class:`.pipeline.SampleOutput` (and
    report) in the result; ``history`` collects the time histories (:class:`.results.History`);
    ``sink`` receives each output and report as it is made; ``figure_data`` collects what the
    figures draw besides the histories (:class:`.figure_data.FigureData`, bounded). With
    ``maneuvers.source`` not ``off``, the stream is cut into maneuvers
    (:class:`.maneuvers.ManeuverTracker` in ``result.maneuvers``, every maneuver kept; ``min_span``
    its too-short rule) and event messages go to it in their place in the stream. Without
    the first two, memory does not grow with the run. With ``estimator.method`` ``frequency``
    or ``both`` the result keeps the frequency-domain estimates too (in a history like
    ``history``, when given). ``progress``: a bar on stderr with the rate and the time left
    (:mod:`..progress`: None on a terminal only, True always, False never). With ``diagnostics`` (the node's
    settings), the node's ``/diagnostics`` statuses once per diagnostics period of data time,
    and once at the end."""
    total = len(messages) if isinstance(messages, Sized) else int(getattr(messages, "total", 0))
    bar = Progress(total or None, "replay", " messages", progress)
    pipe = Pipeline(config, record=record)
    result = _new_result(pipe, history)
    run = _Run(pipe, result, keep_outputs, sink)
    result.maneuvers = run.tracker = tracker_for(pipe, min_span=min_span, keep_all=True)
    rows = _Rows(pipe, keep=record)
    excitation = _Excitation(pipe)
    diag = _DataClockDiagnostics(pipe, config, diagnostics, run.diagnostics) if diagnostics is not None else None
    step = max(1, total // 50)
    first: int | None = None
    newest = 0
    n = 0
    t0 = time.perf_counter()
    # The loop allocates many small objects and no reference cycles: pausing the cyclic
    # garbage collector saves its repeated passes over the objects it keeps (about 6%).
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for kind, stamp, msg in routed(messages, run.tracker):
            if first is None:
                first = newest = stamp
            elif stamp > newest:
                newest = stamp
            outs = feed(pipe, kind, msg)
            for out in outs:
                run.sample(out)
            if figure_data is not None or excitation.watching:
                _take_rows(run, outs, rows, excitation, figure_data)
            if diag is not None:
                diag.after(kind, stamp)
            run.history(newest)
            if sink is not None:
                sink.after(newest)
            n += 1
            if n % step == 0:
                bar.update(step)
        pipe.finish()
        if run.tracker is not None:
            run.tracker.finish(newest)
        if diag is not None and n:
            diag.finish()
    finally:
        if gc_was_enabled:
            gc.enable()
        bar.set_to(n)
        bar.close()
    result.wall_seconds = time.perf_counter() - t0
    result.n_messages = n
    if first is not None:
        result.data_seconds = (newest - first) * 1e-9
    return _finished(run, excitation, figure_data, str(getattr(messages, "digest", "")))


def _take_rows(run: _Run, outs: list[SampleOutput], rows: _Rows, excitation: _Excitation,
               figure_data: FigureData | None) -> None:
    """After a message: the new regression rows to the figures' data, and to the excitation
    watch while some model has never published (taken only when new ones came)."""
    if figure_data is not None:
        new = rows.take()
        figure_data.add(run.pipe, outs, new)
        if excitation.watching:
            excitation.update(new)
            excitation.watching = not run.ever.all()
    elif excitation.watching:
        if rows.pending:
            excitation.update(rows.take())
        if outs and run.ever.all():  # (only an output changes run.ever)
            excitation.watching = False
            rows.stop()


def _finished(run: _Run, excitation: _Excitation, figure_data: FigureData | None, digest: str) -> ReplayResult:
    """The run's result completed at the end of the data: the final values, the figures' sums,
    why a model never published, the counters and the input digest."""
    pipe, result = run.pipe, run.result
    run.finals()
    if figure_data is not None:
        figure_data.finish(pipe)
    result.explanations = unestimated(pipe, run.ever, excitation,
                                      np.array([f is not None for f in run.last_frequency]))
    result.counter_values = accounting(pipe.counters())
    result.bag_digest = digest
    return result


def unestimated(pipe: Pipeline, ever: np.ndarray, excitation: _Excitation | None = None,
                frequency_ever: np.ndarray | None = None) -> list[str]:
    """Why models never produced an estimate (``ever``: per model, whether it published), in
    the terms of :mod:`.alerts`: one line ``no estimates: <why>`` when the data path used no
    sample (which stream was rejected and why, expected against received, the parameter to
    change), else one ``<model>: no estimate: <why>`` per model that never became ready, with
    the regressors that never moved when ``excitation`` watched them; with ``estimator.method:
    frequency`` the frequency-domain estimator's reason. With ``both``, ``frequency_ever`` (per
    model, whether its frequency-domain estimates were published) adds one
    ``<model> (frequency domain): no estimate: <why>`` per model that has none."""
    lines: list[str] = []
    if not ever.all():
        why = no_estimate(pipe.counters(), pipe.required)
        if why is not None:
            return [f"no estimates: {why}"]
        if pipe.config.publishes_time:
            constant = excitation.constant if excitation else (lambda j: [])
            lines = [f"{m.output}: no estimate: {_time_unready(pipe, j, constant)}"
                     for j, m in enumerate(pipe.models) if not ever[j]]
        else:
            lines = [f"{m.output}: no estimate: {_frequency_unready(pipe, j)}"
                     for j, m in enumerate(pipe.models) if not ever[j]]
    if pipe.config.publishes_time and frequency_ever is not None and pipe.frequency is not None:
        lines += [f"{m.output} (frequency domain): no estimate: {_frequency_unready(pipe, j)}"
                  for j, m in enumerate(pipe.models) if not frequency_ever[j]]
    return lines


def _time_unready(pipe: Pipeline, j: int, constant: Callable[[int], list[str]]) -> str:
    """Why model ``j``'s time-domain estimator never published: too few samples for the
    publication rule once initialized, else its regressors never spanned their space."""
    bank, o = pipe.bank, pipe.config.estimator
    if bank.initialized[j] and bank.publish_count[j] >= bank.publish_at[j]:
        withheld = pipe.bookkeeping.outputs_withheld.get(pipe.models[j].output, 0)
        return (f"withheld at all {withheld} samples past the publication rule: its standard errors were not above "
                "rounding of its estimates (an exact fit: the output is a noise-free combination of the regressors) "
                "or not finite")
    if bank.initialized[j]:
        return too_few_samples(int(bank.publish_count[j]), int(bank.publish_at[j]), o.publish_lag_windows,
                               o.publish_lags, pipe.sizes[j], "estimator.lag_span")
    return not_excited(pipe.sizes[j], bank.k, constant(j))


def _frequency_unready(pipe: Pipeline, j: int) -> str:
    """Why model ``j``'s frequency-domain estimator never published: never evaluated (fewer
    samples than ``frequency.every``), or its regressors not independent on the grid."""
    path = pipe.frequency
    assert path is not None  # estimator.method frequency or both
    bank = path.bank
    if bank.solved[j] and bank.n_samples < bank.publish_at[j]:
        o = bank.options
        return too_few_samples(bank.n_samples, int(bank.publish_at[j]), o.publish_lag_windows, o.publish_lags,
                               path.sizes[j] + 1, "frequency.lag_span")
    if bank.evaluated_at == 0:
        return (f"the frequency-domain estimator is evaluated every frequency.every = {path.every} samples and "
                f"took {bank.n_samples} (lower frequency.every)")
    return (f"its {path.sizes[j]} frequency-domain regressors were not excited independently on the grid "
            f"(frequency.f_min .. f_max) in {bank.n_samples} samples (the maneuver must excite that band)")


def summary_table(result: ReplayResult) -> str:
    """The last sample's estimates of every model ready in it (:func:`.report.results_table`),
    then the frequency-domain ones last published, when the run published them, then why any
    model has none (:attr:`.results.ReplayResult.explanations`)."""
    rows = []
    last, pipe = result.last_output, result.pipeline
    states = {m: {s.parameter: s.text for s in result.states if s.method == m} for m in ("time", "frequency")}
    if last is not None and pipe is not None:
        for row in OutputLayout.of(pipe).rows(last):
            rows += rows_from_arrays(row.names, row.estimates, row.standard_errors_conventional, row.standard_errors,
                                     states=states["time"] if result.states else None)
    tables = [results_table(rows)] if rows else []
    finals = result.finals("frequency") if "frequency" in result.methods else {}
    if finals:
        names, values = list(finals), list(finals.values())
        frequency = rows_from_arrays(names, [f.estimate for f in values], [f.std_error_conventional for f in values],
                                     [f.std_error for f in values],
                                     states=states["frequency"] if result.states else None)
        tables.append("frequency domain (docs/frequency.md):\n" + results_table(frequency))
    return "\n".join(tables + result.explanations)


def parameters_csv(result: ReplayResult) -> str:
    """``parameters.csv``: every parameter's state at the end of the run, one row per method
    and parameter: ``method,model,parameter,estimate,std_error,se_percent,state,reason``
    (the corrected standard error; empty numbers where nothing was published)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["method", "model", "parameter", "estimate", "std_error", "se_percent", "state", "reason"])
    for s in result.states:
        numbers = [repr(x) if math.isfinite(x) else "" for x in (s.estimate, s.std_error, s.se_percent)]
        w.writerow([s.method, s.model, s.parameter, *numbers, s.state, s.reason])
    return out.getvalue()


def run_summary(result: ReplayResult) -> str:
    """What the command prints and writes to ``summary.txt``: :func:`summary_table`, then the
    sample accounting, the streams that lost messages, and the messages and data seconds
    read (the wall-clock speed, which varies between runs, is printed only)."""
    c = result.counters()
    rejected = ", ".join(f"{k} {v}" for k, v in sorted(c["samples_rejected"].items())) or "none"
    lines = [summary_table(result), "", f"{c['samples_formed']} samples formed, {c['samples_used']} used; "
             f"rejected: {rejected}"]
    for name, s in c["streams"].items():
        if s["rejected"] or s["expired"] or s["missing"]:
            lines.append(f"  {name}: {s['received']} received, rejected {s['rejected']}, expired {s['expired']}, "
                         f"missing (stamp gaps) {s['missing']}")
    lines.append(f"{result.n_messages} messages, {result.data_seconds:.1f} s of data")
    return "\n".join(lines)


def replay(bag: str | Path, params: dict[str, Any], out: str | Path, *, start: float | None = None,
           end: float | None = None, strict: bool = True, progress: bool | None = None, plots: bool = True,
           figures: FigureOptions | None = None, force: bool = False,
           inputs: Iterable[str | Path] = ()) -> ReplayResult:
    """Run a replay bag through the pipeline, reading it and writing the outputs to ``out``
    as it goes (:func:`.files.output_directory`: complete or absent; an existing non-empty
    ``out`` only with ``force``; never over the input bag or the other ``inputs``, such as the
    parameter file), then ``summary.txt`` (:func:`run_summary`) and, with ``plots``, the
    figures (:func:`.figures.replay_figures`, in the formats and resolution of ``figures``).
    The result keeps no per-sample outputs, and the time histories only decimated for the
    plots (:data:`PLOT_POINTS`)."""
    check_bag(bag)  # before the output directory is made
    config = pipeline_config(params)
    node_cfg = node_config(params)
    names = [m.parameter_names for m in config.models]
    data = FigureData([m.output for m in config.models], [m.regressors for m in config.models], names, config.rate,
                      PLOT_POINTS) if plots else None
    split = config.maneuvers.source != "off"  # (then the all-lags rows are kept: record)
    events = config.maneuvers.topic if config.maneuvers.source == "events" else None
    with output_directory(out, force=force, inputs=(bag, *inputs)) as tmp, \
            InputStream(bag, node_cfg.topics, strict=strict, start=start, end=end, events=events) as stream:
        for line in configuration_warnings(config, node_cfg.topics) + record_checks(config, stream.span_seconds):
            print(f"warning: {line}", file=sys.stderr)
        files = ReplayFiles(tmp, config, node_cfg.frame_id, NODE_NAME, stream.store)
        with files:
            result = run_pipeline(stream, config, record=split, progress=progress, diagnostics=node_cfg,
                                  keep_outputs=False, history=History(names, PLOT_POINTS), sink=files, figure_data=data)
        record = planned_run(params, start=start, end=end, strict=strict)
        record["bag"] |= {"path": str(bag), "input_sha256": stream.digest, "messages_read": stream.read,
                          "messages_used": result.n_messages}
        (tmp / "run.json").write_text(json.dumps(record, indent=1, sort_keys=True, default=repr) + "\n")
        (tmp / "summary.txt").write_text(run_summary(result) + "\n")
        (tmp / "parameters.csv").write_text(parameters_csv(result))
        if result.maneuvers is not None:  # each maneuver's models, as a campaign of the recording
            (tmp / MODELS_FILE).write_text(models_json([(m.name, m.models) for m in result.maneuvers.history]))
        elif result.pipeline is not None:
            (tmp / MODELS_FILE).write_text(models_json([(Path(bag).name, run_models(result.pipeline))]))
        if result.maneuvers is not None:
            (tmp / "maneuvers.csv").write_text(maneuvers_csv(list(result.maneuvers.history), stream.t0))
        if data is not None and result.history is not None:
            from .figures import replay_figures  # noqa: PLC0415 - drawing (matplotlib) only when asked

            replay_figures(tmp, Path(bag).name, result.history, data, figures, progress=progress)
    return result


def planned_run(params: dict[str, Any], *, start: float | None = None, end: float | None = None,
                strict: bool = True) -> dict[str, Any]:
    """The ``run.json`` of a replay with ``params`` over the span, before the bag is read
    (:func:`.replay_files.run_record`; the replay adds the bag's path and input digest)."""
    return run_record({"start": start, "end": end, "strict": strict}, {**parameter_defaults(), **params},
                      pipeline_config(params))
