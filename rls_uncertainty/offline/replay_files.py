"""The offline replay's output files, written sample by sample as the replay runs.

:class:`ReplayFiles` receives every :class:`.pipeline.SampleOutput` and every ``/diagnostics``
report of a replay (:func:`.replay.run_pipeline`'s sink) and writes, into the replay's output
directory:

* ``estimates.csv`` (:data:`CSV_COLUMNS`): one row per sample and parameter of every ready
  model;
* ``estimates_wide.csv`` (:func:`wide_columns`): one row per sample, one column per parameter
  and quantity, cells empty while a model is not ready (these two only when the time-domain
  estimates are published: ``estimator.method`` ``time`` or ``both``);
* ``estimates_frequency.csv`` (with ``estimator.method`` ``frequency`` or ``both``): the
  columns of ``estimates.csv``, one row per parameter of every model ready in the frequency
  domain on each sample where it publishes (:mod:`.frequency_path`), over the parameters
  without the bias; ``lags`` are those of its residual autocovariance;
* ``estimates.mcap``: every topic the node publishes, byte for byte what the node sends
  (:meth:`.outputs.OutputLayout.encode`), log time = the sample's stamp, and the
  ``/diagnostics`` reports at their data time, and with ``maneuvers.source`` not ``off`` the
  node's ``~/maneuvers`` history (``std_msgs/msg/String``, JSON:
  :func:`..datapath.maneuvers.history_json`) at the newest message's stamp whenever it
  changes, as the node publishes it (a maneuver still running at the end of the data is in
  ``maneuvers.csv``, not in this history: the node does not end it either); ordered by log
  time, then topic (:class:`.bags.BagWriter`: with CRCs), holding back only the records a
  later one could precede: those after the newest sample or the newest message;
* ``run.json`` (:func:`run_record`): what a later ``replay --compare`` checks before
  comparing (:mod:`.compare`): the bag's input content digest, the span, the parameters and
  the configuration with its digest, the models and their parameters.

Nothing is kept per sample: memory does not grow with the recording.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from itertools import chain
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from ..datapath.cdr import encode_diagnostic_array, encode_string
from ..datapath.maneuvers import HISTORY_TOPIC
from ..datapath.outputs import OutputLayout
from ..files import OutputWriter
from .bags import BagWriter

if TYPE_CHECKING:  # annotations only
    from rosbags.typesys.store import Typestore

    from ..datapath.config import PipelineConfig
    from ..datapath.diagnostics import Status
    from ..datapath.pipeline import SampleOutput

__all__ = ["ReplayFiles", "CSV_COLUMNS", "WIDE_QUANTITIES", "wide_columns", "stamp_text", "run_record",
           "RUN_FORMAT", "configuration_digest", "DIAGNOSTIC_ARRAY"]

CSV_COLUMNS = ("time", "model", "parameter", "estimate", "std_error", "std_error_conventional", "converged", "lags")
# Columns of the wide CSV per parameter P: P (estimate), P_se (corrected), P_se_conventional,
# P_converged (1.0/0.0); and per model M, after its parameters, M_lags.
WIDE_QUANTITIES = (("", "theta"), ("_se", "se"), ("_se_conventional", "se_conventional"), ("_converged", "converged"))
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
STRING = "std_msgs/msg/String"
RUN_FORMAT = "rls_uncertainty replay run 1"


def stamp_text(stamp_ns: int) -> str:
    """A stamp as the CSV files write it: ``SEC.NANOSEC``, exact."""
    return f"{stamp_ns // 10**9}.{stamp_ns % 10**9:09d}"


def wide_columns(config: PipelineConfig) -> list[str]:
    """The wide CSV's header: ``time`` then, per model, every quantity of each parameter and
    the model's lag count."""
    columns = ["time"]
    for m in config.models:
        columns += [f"{p}{suffix}" for p in m.parameter_names for suffix, _ in WIDE_QUANTITIES] + [f"{m.output}_lags"]
    return columns


def configuration_digest(config: PipelineConfig) -> tuple[dict[str, Any], str]:
    """The configuration as plain JSON values and the SHA-256 of its canonical text."""
    values = json.loads(json.dumps(asdict(config), default=repr))
    text = json.dumps(values, sort_keys=True, separators=(",", ":"))
    return values, hashlib.sha256(text.encode()).hexdigest()


def run_record(bag: dict[str, Any], parameters: dict[str, Any], config: PipelineConfig) -> dict[str, Any]:
    """``run.json``: the bag (``bag``: path, input digest, messages, span, strictness), every
    parameter as resolved (defaults filled in), the configuration and its digest, and the
    outputs' models, parameter names and sample period."""
    values, digest = configuration_digest(config)
    return {
        "format": RUN_FORMAT,
        "bag": bag,
        "parameters": parameters,
        "configuration": values,
        "configuration_sha256": digest,
        "models": [m.output for m in config.models],
        "parameter_names": [list(m.parameter_names) for m in config.models],
        "period_ns": config.period_ns,
    }


class _Csv:
    """``estimates.csv``: :data:`CSV_COLUMNS`, one row per sample and parameter of every ready
    model; ``converged`` is the parameter's flag (1/0), ``lags`` the model's lag count of Eq. 22
    behind ``std_error`` (chosen per sample under ``estimator.lag_selection: auto``). With
    ``frequency``, ``estimates_frequency.csv``: the same of the frequency-domain results."""

    def __init__(self, path: Path, layout: OutputLayout, frequency: bool = False) -> None:
        self.layout, self.frequency = layout, frequency
        self.fh: IO[str] = open(path, "w")  # noqa: SIM115 - closed by ReplayFiles.close
        self.fh.write(",".join(CSV_COLUMNS) + "\n")

    def sample(self, out: SampleOutput) -> dict[int, list[tuple[str, str, str]]]:
        """Write the sample's rows; per model written, its parameters' estimate and standard
        errors as written (for the wide CSV: each float's text made once)."""
        t = stamp_text(out.stamp_ns)
        write = self.fh.write
        f = out.frequency
        lag_counts: np.ndarray | None
        texts: dict[int, list[tuple[str, str, str]]] = {}
        if self.frequency:
            if f is None:
                return texts
            rows, converged, lag_counts = self.layout.frequency_rows(out), f.converged, f.lags
        else:
            rows, converged, lag_counts = self.layout.rows(out), out.converged, out.lags
        lines = []
        for j, name, names, theta, se, se_conv in rows:
            lags = int(lag_counts[j]) if lag_counts is not None else ""
            flags = converged[j, : len(names)].tolist()
            # (Python floats from tolist: the same repr as float() of each numpy element.)
            texts[j] = values = [(repr(a), repr(b), repr(c))
                                 for a, b, c in zip(theta.tolist(), se.tolist(), se_conv.tolist(), strict=True)]
            lines += [f"{t},{name},{p},{a},{b},{c},{int(f)},{lags}\n"
                      for p, (a, b, c), f in zip(names, values, flags, strict=True)]
        write("".join(lines))
        return texts


class _WideCsv:
    """``estimates_wide.csv``: one row per sample, one column per parameter and quantity
    (:func:`wide_columns`), empty where the model is not ready yet. Comma separated, a header
    row and a numeric time column (s): what PlotJuggler's CSV loader reads as is."""

    def __init__(self, path: Path, config: PipelineConfig) -> None:
        self.sizes = [len(m.regressors) for m in config.models]
        self.empty = [[""] * (n * len(WIDE_QUANTITIES) + 1) for n in self.sizes]  # a model not ready
        self.fh: IO[str] = open(path, "w")  # noqa: SIM115 - closed by ReplayFiles.close
        self.fh.write(",".join(wide_columns(config)) + "\n")

    def sample(self, out: SampleOutput, texts: dict[int, list[tuple[str, str, str]]]) -> None:
        """One row; ``texts``: the estimates and standard errors of the models that
        ``estimates.csv`` wrote for this sample, as it wrote them (:meth:`_Csv.sample`)."""
        cells = [stamp_text(out.stamp_ns)]
        arrays: list[list[list[float]]] | None = None
        ready = out.ready.tolist()
        for j, n in enumerate(self.sizes):
            if ready[j]:
                # parameter by parameter, each one's quantities in the order of WIDE_QUANTITIES;
                # Python floats (tolist): repr as float() of each element; the flags as 1.0/0.0.
                if j in texts:
                    flags = np.asarray(out.converged[j, :n], dtype=np.float64).tolist()
                    cells += chain.from_iterable((*v, repr(f)) for v, f in zip(texts[j], flags, strict=True))
                else:  # (a row with a value not finite: written here only)
                    if arrays is None:
                        arrays = [np.asarray(getattr(out, field), dtype=np.float64).tolist()
                                  for _, field in WIDE_QUANTITIES]
                    cells += map(repr, chain.from_iterable(zip(*(a[j][:n] for a in arrays), strict=True)))
                cells.append(str(int(out.lags[j])) if out.lags is not None else "")
            else:
                cells += self.empty[j]
        self.fh.write(",".join(cells) + "\n")


def _diagnostic_array(stamp_ns: int, statuses: list[Status]) -> bytes:
    """The CDR of a ``diagnostic_msgs/DiagnosticArray`` of ``statuses`` stamped with the data
    time: the bytes ``rosbags`` serializes (``test_replay_files`` compares them), without
    building its message objects and its serializer for each replay."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return encode_diagnostic_array(sec, nanosec, [(s.level, s.name, s.message, s.hardware_id, s.values)
                                                  for s in statuses])


class _Mcap:
    """``estimates.mcap`` (module docstring), opened at its first record: a replay that
    publishes nothing and reports nothing writes no bag. Every topic of the configuration's
    outputs and ``/diagnostics`` get a connection, whether or not a message follows."""

    def __init__(self, directory: Path, layout: OutputLayout, frame_id: str, node: str, store: Typestore,
                 maneuvers: bool = False) -> None:
        self.directory, self.layout, self.frame_id, self.store = directory, layout, frame_id, store
        self.topics = [(f"/{node}/{topic}", msgtype) for topic, msgtype in layout.topics]
        self.fit_topics = [(f"/{node}/{topic}", msgtype) for topic, msgtype in layout.fit_topics]
        self.history_topic = f"/{node}/{HISTORY_TOPIC}"
        if maneuvers:
            self.fit_topics.append((self.history_topic, STRING))
        self.writer: BagWriter | None = None
        self.newest_sample: int | None = None  # stamp of the newest sample written

    def _open(self) -> BagWriter:
        if self.writer is None:
            self.writer = BagWriter(self.directory / "estimates.mcap",
                                    [*self.topics, *self.fit_topics, ("/diagnostics", DIAGNOSTIC_ARRAY)],
                                    self.store)
        return self.writer

    def sample(self, out: SampleOutput) -> None:
        writer, topics, stamp = self._open(), self.topics, out.stamp_ns
        for index, data in self.layout.encode(out, self.frame_id):
            writer.add(stamp, *topics[index], data)
        self.newest_sample = stamp

    def diagnostics(self, stamp_ns: int, statuses: list[Status], fits: list[tuple[int, str, str, bytes]]) -> None:
        writer = self._open()
        writer.add(stamp_ns, "/diagnostics", DIAGNOSTIC_ARRAY, _diagnostic_array(stamp_ns, statuses))
        for log_ns, topic, msgtype, raw in fits:
            writer.add(log_ns, topic, msgtype, raw)

    def maneuvers(self, stamp_ns: int, text: str) -> None:
        self._open().add(stamp_ns, self.history_topic, STRING, encode_string(text))

    def after(self, newest_ns: int) -> None:
        """Write what no later record can precede: a later sample comes after the newest one,
        a later report at the newest message's stamp or after."""
        if self.writer is not None:
            bound = newest_ns if self.newest_sample is None else min(newest_ns, self.newest_sample + 1)
            self.writer.release(bound)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


class ReplayFiles(OutputWriter):
    """Every output file of a replay into ``directory`` (module docstring), as the samples
    come; :meth:`close` completes them (a failure leaves them to the caller's
    :func:`.files.output_directory`, which discards the directory)."""

    def __init__(self, directory: Path, config: PipelineConfig, frame_id: str, node: str, store: Typestore) -> None:
        layout = OutputLayout.for_config(config)
        self.time: tuple[_Csv, _WideCsv] | None = None
        self.frequency: _Csv | None = None
        self.csvs: list[_Csv | _WideCsv] = []
        if config.publishes_time:
            self.time = (_Csv(directory / "estimates.csv", layout), _WideCsv(directory / "estimates_wide.csv", config))
            self.csvs += self.time
        if config.frequency is not None:
            self.frequency = _Csv(directory / "estimates_frequency.csv", layout, frequency=True)
            self.csvs.append(self.frequency)
        self.mcap = _Mcap(directory, layout, frame_id, node, store, maneuvers=config.maneuvers.source != "off")

    def sample(self, out: SampleOutput) -> None:
        if self.time is not None:
            long, wide = self.time
            wide.sample(out, long.sample(out))
        if self.frequency is not None:
            self.frequency.sample(out)
        self.mcap.sample(out)

    def diagnostics(self, stamp_ns: int, statuses: list[Status], fits: list[tuple[int, str, str, bytes]]) -> None:
        self.mcap.diagnostics(stamp_ns, statuses, fits)

    def maneuvers(self, stamp_ns: int, text: str) -> None:
        """The maneuver history changed: its ``~/maneuvers`` message at ``stamp_ns``."""
        self.mcap.maneuvers(stamp_ns, text)

    def after(self, newest_ns: int) -> None:
        self.mcap.after(newest_ns)

    def close(self) -> None:
        for csv in self.csvs:
            csv.fh.close()
        self.mcap.close()

    def abort(self) -> None:
        """Close the CSV files and remove the unfinished bag (the caller discards the directory)."""
        for csv in self.csvs:
            csv.fh.close()
        if self.mcap.writer is not None:
            self.mcap.writer.abort()
