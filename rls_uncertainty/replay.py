"""Offline replay: a replay bag through the node's own pipeline, no DDS, as fast as the CPU
allows (``rls-uncertainty replay BAG --config CFG --out DIR``).

The messages go through :func:`.inputs.feed` into one :class:`.pipeline.Pipeline`, exactly
as in the live node, so the node and the replay give the same numbers. Outputs (written to a
temporary directory renamed to ``DIR`` only when complete):

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
  time = the sample's stamp; and ``/diagnostics`` once per ``diagnostics_period`` of data time
  from the node's own diagnostics policy (:class:`_DataClockDiagnostics`), which carries each
  model's lag count, convergence flags and identifiability, with ``/rls_estimator/M/fit`` and
  ``/rls_estimator/M/identifiability`` at the same times (:func:`.outputs.fit_records`);
* ``M_estimates.png``: each parameter's history with corrected and conventional 2-sigma
  envelopes, and ``M_autocorrelation.png``: each model's residual autocorrelation.
Two runs give bit-identical CSV and MCAP files. The progress bar is drawn only on a terminal.
"""

from __future__ import annotations

import gc
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .alerts import no_estimate, not_excited
from .bags import read_inputs, typestore, write_replay
from .config import NodeConfig, PipelineConfig, node_config, pipeline_config
from .diagnostics import DiagnosticsPolicy, Snapshot, Status
from .files import output_directory
from .inputs import Stamped, feed
from .outputs import NODE_NAME, OutputLayout, fit_records
from .pipeline import Pipeline, SampleOutput
from .report import results_table, rows_from_arrays

__all__ = ["ReplayResult", "run_pipeline", "replay", "output_records", "NODE_NAME"]


@dataclass
class ReplayResult:
    """The pipeline after the run, every published sample and timing. :attr:`estimates`
    counts the samples that published an estimate (0: the run estimated nothing, which the
    command line reports with exit status 1); :attr:`explanations` says, one line each, why a
    model never produced an estimate (:func:`unestimated`)."""

    pipeline: Pipeline
    outputs: list[SampleOutput] = field(default_factory=list)
    n_messages: int = 0
    wall_seconds: float = 0.0
    data_seconds: float = 0.0
    # (stamp_ns, statuses) of the /diagnostics the node would have published, one per
    # diagnostics period of data time (empty unless run_pipeline was given a NodeConfig).
    diagnostics: list[tuple[int, list[Status]]] = field(default_factory=list)
    # ~/M/fit and ~/M/identifiability at the same times (outputs.fit_records).
    fits: list[tuple[int, str, str, bytes]] = field(default_factory=list)
    explanations: list[str] = field(default_factory=list)

    @property
    def estimates(self) -> int:
        """Samples in which at least one model published its estimates."""
        return sum(1 for out in self.outputs if out.ready.any())

    @property
    def speed(self) -> float:
        """Multiples of real time."""
        return self.data_seconds / self.wall_seconds if self.wall_seconds > 0 else float("inf")


def _is_terminal(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _progress(done: int, total: int, width: int = 40) -> None:
    filled = int(width * done / total)
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {100 * done // total:3d}%")
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()


class _DataClockDiagnostics:
    """The node's ``/diagnostics`` in a replay: every ``diagnostics_period`` of data time (the
    newest message stamp), one :class:`.diagnostics.Snapshot` of the pipeline into the same
    :class:`.diagnostics.DiagnosticsPolicy` the node uses. Data time stands in for the node's
    clock and steady time; a stream counts one publisher once its first message is read (a
    bag has no DDS matching); latencies and the state file do not apply."""

    def __init__(self, pipe: Pipeline, config: PipelineConfig, node_cfg: NodeConfig) -> None:
        self.pipe, self.config, self.node_cfg = pipe, config, node_cfg
        self.policy = DiagnosticsPolicy(NODE_NAME, window_s=node_cfg.diagnostics_window)
        self.period_ns = max(1, round(node_cfg.diagnostics_period * 1e9))
        self.previous_ns: int | None = None
        self.newest_ns = 0
        self.seen: set[str] = set()
        self.records: list[tuple[int, list[Status]]] = []
        self.fits: list[tuple[int, str, str, bytes]] = []

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
        if not self.records or self.previous_ns is None or self.newest_ns > self.previous_ns:
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
        self.records.append((self.newest_ns, self.policy.update(snap)))
        self.fits += fit_records(pipe, self.newest_ns)
        self.previous_ns = self.newest_ns


def run_pipeline(messages: Sequence[tuple[str, int, Stamped]], config: PipelineConfig, *, record: bool = True,
                 progress: bool = False, diagnostics: NodeConfig | None = None) -> ReplayResult:
    """Feed ``(kind, stamp, msg)`` messages through a fresh pipeline; keep every output.
    ``progress`` draws a bar on stderr when stderr is a terminal (never carriage-return
    frames into a log file or a pipe). With ``diagnostics`` (the node's settings), also keep
    the node's ``/diagnostics`` statuses once per diagnostics period of data time, and once
    at the end (:attr:`ReplayResult.diagnostics`)."""
    progress = progress and _is_terminal(sys.stderr)
    pipe = Pipeline(config, record=record)
    result = ReplayResult(pipe, n_messages=len(messages))
    total = len(messages)
    step = max(1, total // 50)
    t0 = time.perf_counter()
    outs = result.outputs
    diag = _DataClockDiagnostics(pipe, config, diagnostics) if diagnostics is not None else None
    # The loop allocates many small objects and no reference cycles: pausing the cyclic
    # garbage collector saves its repeated passes over the messages already read (about 6%).
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for i, (kind, stamp, msg) in enumerate(messages):
            produced = feed(pipe, kind, msg)
            if produced:
                outs.extend(produced)
            if diag is not None:
                diag.after(kind, stamp)
            if progress and (i % step == 0):
                _progress(i, total)
        pipe.finish()
        if diag is not None and messages:
            diag.finish()
            result.diagnostics, result.fits = diag.records, diag.fits
    finally:
        if gc_was_enabled:
            gc.enable()
    result.wall_seconds = time.perf_counter() - t0
    if progress:
        _progress(total, total)
    if messages:
        result.data_seconds = (messages[-1][1] - messages[0][1]) * 1e-9
    result.explanations = unestimated(pipe, outs)
    return result


def unestimated(pipe: Pipeline, outputs: Sequence[SampleOutput]) -> list[str]:
    """Why models never produced an estimate over ``outputs``, in the terms of
    :mod:`.alerts`: one line ``no estimates: <why>`` when the data path used no sample (which
    stream was rejected and why, expected against received, the parameter to change), else
    one ``<model>: no estimate: <why>`` per model that never became ready."""
    ever = np.zeros(len(pipe.models), dtype=bool)
    for out in outputs:
        ever |= out.ready
        if ever.all():  # the usual case: every model ready early in the run
            return []
    why = no_estimate(pipe.counters(), pipe.required)
    if why is not None:
        return [f"no estimates: {why}"]
    lines = []
    for j, (m, n) in enumerate(zip(pipe.models, pipe.sizes, strict=True)):
        if not ever[j]:
            # With the regression recorded: the regressors that never moved (the bias aside).
            X = np.array([x[j, :n] for _t, x, _z in pipe.regression]).reshape(-1, n)
            constant = [r for i, r in enumerate(m.regressors) if r != "1" and len(X) and np.ptp(X[:, i]) == 0]
            lines.append(f"{m.output}: no estimate: {not_excited(n, pipe.bank.k, constant)}")
    return lines


def output_records(pipe: Pipeline, outputs: Iterable[SampleOutput], frame_id: str = "base_link",
                   node: str = NODE_NAME) -> list[tuple[int, str, str, bytes]]:
    """The node's output messages for every sample, as bag records of CDR bytes: exactly what
    the node publishes (:meth:`.outputs.OutputLayout.encode`)."""
    layout = OutputLayout.of(pipe)
    topics = [(f"/{node}/{topic}", msgtype) for topic, msgtype in layout.topics]
    return [(out.stamp_ns, *topics[index], data) for out in outputs for index, data in layout.encode(out, frame_id)]


DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"


def diagnostics_records(diagnostics: Iterable[tuple[int, list[Status]]], store: Any) -> list[tuple[int, str, str, Any]]:
    """``/diagnostics`` bag records (``rosbags`` messages of ``store``) of the statuses a
    replay kept (:attr:`ReplayResult.diagnostics`), stamped with the data time."""
    types = store.types
    header, stamp_t = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    array_t, status_t = types[DIAGNOSTIC_ARRAY], types["diagnostic_msgs/msg/DiagnosticStatus"]
    key_value = types["diagnostic_msgs/msg/KeyValue"]
    records = []
    for stamp_ns, statuses in diagnostics:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        msg = array_t(
            header=header(stamp=stamp_t(sec=sec, nanosec=nanosec), frame_id=""),
            status=[status_t(level=s.level, name=s.name, message=s.message, hardware_id=s.hardware_id,
                             values=[key_value(key=k, value=v) for k, v in s.values]) for s in statuses],
        )
        records.append((stamp_ns, "/diagnostics", DIAGNOSTIC_ARRAY, msg))
    return records


def _stamp_text(stamp_ns: int) -> str:
    return f"{stamp_ns // 10**9}.{stamp_ns % 10**9:09d}"


CSV_COLUMNS = ("time", "model", "parameter", "estimate", "std_error", "std_error_conventional", "converged", "lags")


def _write_csv(path: Path, pipe: Pipeline, outputs: Iterable[SampleOutput]) -> None:
    """``estimates.csv``: :data:`CSV_COLUMNS`, one row per sample and parameter of every ready
    model; ``converged`` is the parameter's flag (1/0), ``lags`` the model's lag count of Eq. 22
    behind ``std_error`` (chosen per sample under ``estimator.lag_selection: auto``)."""
    layout = OutputLayout.of(pipe)
    with open(path, "w") as fh:
        fh.write(",".join(CSV_COLUMNS) + "\n")
        for out in outputs:
            t = _stamp_text(out.stamp_ns)
            for j, name, names, theta, se, se_conv in layout.rows(out):
                lags = int(out.lags[j]) if out.lags is not None else ""
                flags = out.converged[j, : len(names)].tolist()
                # (Python floats from tolist: the same repr as float() of each numpy element.)
                for p, a, b, c, f in zip(names, theta.tolist(), se.tolist(), se_conv.tolist(), flags, strict=True):
                    fh.write(f"{t},{name},{p},{a!r},{b!r},{c!r},{int(f)},{lags}\n")


# Columns of the wide CSV per parameter P: P (estimate), P_se (corrected), P_se_conventional,
# P_converged (1.0/0.0); and per model M, after its parameters, M_lags.
WIDE_QUANTITIES = (("", "theta"), ("_se", "se"), ("_se_conventional", "se_conventional"), ("_converged", "converged"))


def wide_columns(pipe: Pipeline) -> list[str]:
    """The wide CSV's header: ``time`` then, per model, every quantity of each parameter and
    the model's lag count."""
    columns = ["time"]
    for m, names in zip(pipe.models, pipe.parameter_names, strict=True):
        columns += [f"{p}{suffix}" for p in names for suffix, _ in WIDE_QUANTITIES] + [f"{m.output}_lags"]
    return columns


def _write_wide_csv(path: Path, pipe: Pipeline, outputs: Iterable[SampleOutput]) -> None:
    """``estimates_wide.csv``: one row per sample, one column per parameter and quantity
    (:func:`wide_columns`), empty where the model is not ready yet. Comma separated, a header
    row and a numeric time column (s): what PlotJuggler's CSV loader reads as is."""
    sizes = pipe.sizes
    with open(path, "w") as fh:
        fh.write(",".join(wide_columns(pipe)) + "\n")
        for out in outputs:
            cells = [_stamp_text(out.stamp_ns)]
            arrays = [np.asarray(getattr(out, field), dtype=np.float64) for _, field in WIDE_QUANTITIES]
            for j, n in enumerate(sizes):
                if out.ready[j]:
                    rows = [a[j, :n].tolist() for a in arrays]  # Python floats: repr as float()
                    cells += [repr(row[i]) for i in range(n) for row in rows]
                    cells.append(str(int(out.lags[j])) if out.lags is not None else "")
                else:
                    cells += [""] * (n * len(arrays) + 1)
            fh.write(",".join(cells) + "\n")


def summary_table(pipe: Pipeline, outputs: Sequence[SampleOutput]) -> str:
    """The last sample's estimates of every ready model (:func:`.report.results_table`), then
    why any model has none (:func:`unestimated`)."""
    why = unestimated(pipe, outputs)
    rows = []
    for row in OutputLayout.of(pipe).rows(outputs[-1]) if outputs else ():
        rows += rows_from_arrays(row.names, row.estimates, row.standard_errors_conventional, row.standard_errors)
    return "\n".join(([results_table(rows)] if rows else []) + why)


def _plots(out_dir: Path, pipe: Pipeline, outputs: Sequence[SampleOutput]) -> list[Path]:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    written: list[Path] = []
    if not outputs:
        return written
    t0 = outputs[0].stamp_ns
    t = np.array([(o.stamp_ns - t0) * 1e-9 for o in outputs])
    for j, m in enumerate(pipe.models):
        names = pipe.parameter_names[j]
        th = np.array([o.theta[j, : len(names)] for o in outputs])
        se = np.array([o.se[j, : len(names)] for o in outputs])
        sc = np.array([o.se_conventional[j, : len(names)] for o in outputs])
        if np.all(np.isnan(th)):
            continue
        fig, axes = plt.subplots(len(names), 1, figsize=(7, 1.9 * len(names)), sharex=True, squeeze=False)
        for i, ax in enumerate(axes[:, 0]):
            ax.plot(t, th[:, i], "k", lw=1, label="estimate")
            ax.fill_between(t, th[:, i] - 2 * se[:, i], th[:, i] + 2 * se[:, i], color="tab:blue", alpha=0.25,
                            label="2 sigma corrected")
            ax.plot(t, th[:, i] - 2 * sc[:, i], "r--", lw=0.8, label="2 sigma conventional")
            ax.plot(t, th[:, i] + 2 * sc[:, i], "r--", lw=0.8)
            ax.set_ylabel(names[i])
            fin = np.isfinite(th[:, i])
            if fin.sum() > 10:  # ignore the first estimates right after initialization
                k0 = int(np.flatnonzero(fin)[0]) + (int(fin.sum()) // 10)
                lo = np.nanmin(th[k0:, i] - 3 * se[k0:, i])
                hi = np.nanmax(th[k0:, i] + 3 * se[k0:, i])
                if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
                    ax.set_ylim(lo, hi)
        axes[0, 0].legend(loc="upper right", fontsize=7)
        axes[-1, 0].set_xlabel("time from first estimate, s")
        fig.suptitle(f"{m.output}: estimates with 2-sigma bounds")
        fig.tight_layout()
        path = out_dir / f"{m.output}_estimates.png"
        fig.savefig(path, dpi=90, metadata={"Software": None})
        plt.close(fig)
        written.append(path)
        if pipe.bank.ready[j]:
            R = pipe.bank.autocorrelation(j)
            n = pipe.bank.k
            fig, ax = plt.subplots(figsize=(6, 3))
            ax.stem(np.arange(R.size), R / R[0], basefmt=" ")
            bound = 2 / np.sqrt(n)
            ax.axhline(bound, color="r", ls="--", lw=0.8)
            ax.axhline(-bound, color="r", ls="--", lw=0.8, label="2 sigma white-noise bound")
            ax.set_xlabel("lag, samples")
            ax.set_ylabel("R(i) / R(0)")
            ax.set_title(f"{m.output}: residual autocorrelation (Eq. 17) after {n} samples")
            ax.legend(fontsize=7)
            fig.tight_layout()
            path = out_dir / f"{m.output}_autocorrelation.png"
            fig.savefig(path, dpi=90, metadata={"Software": None})
            plt.close(fig)
            written.append(path)
    return written


def replay(bag: str | Path, params: dict[str, Any], out: str | Path, *, start: float | None = None,
           end: float | None = None, strict: bool = True, progress: bool = True, plots: bool = True,
           force: bool = False, inputs: Iterable[str | Path] = ()) -> ReplayResult:
    """Run a replay bag through the pipeline and write the outputs to ``out``
    (:func:`.files.output_directory`: complete or absent; an existing non-empty ``out`` only
    with ``force``; never over the input bag or the other ``inputs``, such as the parameter
    file)."""
    config = pipeline_config(params)
    topics = node_config(params).topics
    with output_directory(out, force=force, inputs=(bag, *inputs)) as tmp:
        messages, _t0 = read_inputs(bag, topics, strict=strict, start=start, end=end)
        result = run_pipeline(messages, config, progress=progress, diagnostics=node_config(params))
        _write_csv(tmp / "estimates.csv", result.pipeline, result.outputs)
        _write_wide_csv(tmp / "estimates_wide.csv", result.pipeline, result.outputs)
        store = typestore()
        records = output_records(result.pipeline, result.outputs, node_config(params).frame_id)
        records += diagnostics_records(result.diagnostics, store) + result.fits
        if records:
            write_replay(tmp / "estimates", records, store)
            (tmp / "estimates" / "estimates.mcap").rename(tmp / "estimates.mcap")
            (tmp / "estimates" / "metadata.yaml").unlink()
            (tmp / "estimates").rmdir()
        if plots:
            _plots(tmp, result.pipeline, result.outputs)
    return result
