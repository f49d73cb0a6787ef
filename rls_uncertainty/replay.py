"""Offline replay: a replay bag through the node's own pipeline, no DDS, as fast as the CPU
allows (``rls-uncertainty replay BAG --config CFG --out DIR``).

The messages go through :func:`.messages.feed` into one :class:`.pipeline.Pipeline`, exactly
as in the live node, so the node and the replay give the same numbers. Outputs (written to a
temporary directory renamed to ``DIR`` only when complete):

* ``estimates.csv``: ``time,model,parameter,estimate,std_error,std_error_conventional``, one
  row per sample and parameter of every ready model (time in s, the sample's stamp);
* ``estimates_wide.csv``: ``time`` and, per parameter P of every model, ``P``, ``P_se`` and
  ``P_se_conventional``: one row per sample, cells empty while a model is not ready (for
  PlotJuggler's CSV loader and spreadsheets);
* ``estimates.mcap``: every topic the node publishes per sample, byte for byte
  (:func:`.outputs.sample_messages`: ``/rls_estimator/sample_stamp``,
  ``/rls_estimator/M/estimates``, ``.../standard_errors``, ``.../standard_errors_conventional``),
  log time = the sample's stamp;
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

from .bags import read_inputs, typestore, write_replay
from .config import PipelineConfig, node_config, pipeline_config
from .files import output_directory
from .messages import NODE_NAME, Stamped, feed
from .outputs import sample_messages
from .pipeline import Pipeline, SampleOutput
from .report import results_table, rows_from_arrays

__all__ = ["ReplayResult", "run_pipeline", "replay", "output_records", "NODE_NAME"]


@dataclass
class ReplayResult:
    """The pipeline after the run, every published sample and timing."""

    pipeline: Pipeline
    outputs: list[SampleOutput] = field(default_factory=list)
    n_messages: int = 0
    wall_seconds: float = 0.0
    data_seconds: float = 0.0

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


def run_pipeline(messages: Sequence[tuple[str, int, Stamped]], config: PipelineConfig, *, record: bool = True,
                 progress: bool = False) -> ReplayResult:
    """Feed ``(kind, stamp, msg)`` messages through a fresh pipeline; keep every output.
    ``progress`` draws a bar on stderr when stderr is a terminal (never carriage-return
    frames into a log file or a pipe)."""
    progress = progress and _is_terminal(sys.stderr)
    pipe = Pipeline(config, record=record)
    result = ReplayResult(pipe, n_messages=len(messages))
    total = len(messages)
    step = max(1, total // 50)
    t0 = time.perf_counter()
    outs = result.outputs
    # The loop allocates many small objects and no reference cycles: pausing the cyclic
    # garbage collector saves its repeated passes over the messages already read (about 6%).
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for i, (kind, _stamp, msg) in enumerate(messages):
            produced = feed(pipe, kind, msg)
            if produced:
                outs.extend(produced)
            if progress and (i % step == 0):
                _progress(i, total)
        pipe.finish()
    finally:
        if gc_was_enabled:
            gc.enable()
    result.wall_seconds = time.perf_counter() - t0
    if progress:
        _progress(total, total)
    if messages:
        result.data_seconds = (messages[-1][1] - messages[0][1]) * 1e-9
    return result


def output_records(pipe: Pipeline, outputs: Iterable[SampleOutput], frame_id: str = "base_link",
                   node: str = NODE_NAME) -> list[tuple[int, str, str, bytes]]:
    """The node's output messages for every sample, as bag records of CDR bytes: exactly what
    the node publishes (:func:`.outputs.sample_messages`)."""
    return [(out.stamp_ns, f"/{node}/{topic}", msgtype, data)
            for out in outputs for topic, msgtype, data in sample_messages(pipe, out, frame_id)]


def _write_csv(path: Path, pipe: Pipeline, outputs: Iterable[SampleOutput]) -> None:
    with open(path, "w") as fh:
        fh.write("time,model,parameter,estimate,std_error,std_error_conventional\n")
        for out in outputs:
            t = f"{out.stamp_ns // 10**9}.{out.stamp_ns % 10**9:09d}"
            published = zip(pipe.published(out), _names_of(pipe, out), strict=True)
            for (name, _label, theta, se, se_conv), names in published:
                for p, a, b, c in zip(names, theta, se, se_conv, strict=True):
                    fh.write(f"{t},{name},{p},{float(a)!r},{float(b)!r},{float(c)!r}\n")


# Columns of the wide CSV per parameter P: P (estimate), P_se (corrected), P_se_conventional.
WIDE_QUANTITIES = (("", "theta"), ("_se", "se"), ("_se_conventional", "se_conventional"))


def wide_columns(pipe: Pipeline) -> list[str]:
    """The wide CSV's header: ``time`` then, per model and parameter, every quantity."""
    return ["time"] + [f"{p}{suffix}" for names in pipe.parameter_names for p in names for suffix, _ in WIDE_QUANTITIES]


def _write_wide_csv(path: Path, pipe: Pipeline, outputs: Iterable[SampleOutput]) -> None:
    """``estimates_wide.csv``: one row per sample, one column per parameter and quantity
    (:func:`wide_columns`), empty where the model is not ready yet. Comma separated, a header
    row and a numeric time column (s): what PlotJuggler's CSV loader reads as is."""
    sizes = pipe.sizes
    with open(path, "w") as fh:
        fh.write(",".join(wide_columns(pipe)) + "\n")
        for out in outputs:
            cells = [f"{out.stamp_ns // 10**9}.{out.stamp_ns % 10**9:09d}"]
            arrays = [getattr(out, field) for _, field in WIDE_QUANTITIES]
            for j, n in enumerate(sizes):
                if out.ready[j]:
                    cells += [repr(float(a[j, i])) for i in range(n) for a in arrays]
                else:
                    cells += [""] * (n * len(arrays))
            fh.write(",".join(cells) + "\n")


def _names_of(pipe: Pipeline, out: SampleOutput) -> list[tuple[str, ...]]:
    return [pipe.parameter_names[j] for j in range(len(pipe.sizes)) if out.ready[j]]


def summary_table(pipe: Pipeline, outputs: Sequence[SampleOutput]) -> str:
    """The last sample's estimates of every ready model (:func:`.report.results_table`)."""
    if not outputs:
        return "no estimates: no model became ready (check the excitation and the configuration)"
    last = outputs[-1]
    rows = []
    for (_name, _l, theta, se, sc), names in zip(pipe.published(last), _names_of(pipe, last), strict=True):
        rows += rows_from_arrays(names, theta, sc, se)
    return results_table(rows)


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
        result = run_pipeline(messages, config, progress=progress)
        _write_csv(tmp / "estimates.csv", result.pipeline, result.outputs)
        _write_wide_csv(tmp / "estimates_wide.csv", result.pipeline, result.outputs)
        store = typestore()
        records = output_records(result.pipeline, result.outputs, node_config(params).frame_id)
        if records:
            write_replay(tmp / "estimates", records, store)
            (tmp / "estimates" / "estimates.mcap").rename(tmp / "estimates.mcap")
            (tmp / "estimates" / "metadata.yaml").unlink()
            (tmp / "estimates").rmdir()
        if plots:
            _plots(tmp, result.pipeline, result.outputs)
    return result
