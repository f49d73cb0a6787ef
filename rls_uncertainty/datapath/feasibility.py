"""What cannot work, said before the data is run: refusals and warnings of one line each.

:func:`configuration_warnings` judges a configuration alone (the node at start and on parameter
changes, the command line before it reads a bag); :func:`record_checks` a configuration against
the record it is about to run over (``replay`` and ``campaign``: the span after ``--start`` /
``--end`` is known from the bag's index before a message is read). A refusal is a
:class:`.errors.ConfigError` naming the parameter; a warning a line the caller prints or logs.
The configuration refuses the rest itself (:class:`.config.PipelineConfig`: a grid above the
Nyquist frequency, a differentiator whose pass band lies below the models' band).
"""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import ConfigError
from .config import PipelineConfig

__all__ = ["configuration_warnings", "record_checks"]


def configuration_warnings(config: PipelineConfig, topics: Mapping[str, str] | None = None) -> list[str]:
    """Warnings about a configuration: forgetting that remembers fewer samples than the
    publication rule's (``1 / (1 - f)`` against ``n + publish_lag_windows x L`` of the largest
    model): the corrected standard errors then stay too small; and with the input ``topics``
    (``topics.*``), instrumental variables whose excitation is the measured surfaces; and
    instrumental variables from the surfaces and the delayed regressors, which hold in open loop only."""
    o = config.estimator
    out = []
    source = config.instruments.resolved_source(config.models) if o.algorithm == "iv" else ""
    if source == "delayed":
        out.append("estimator.algorithm iv with instruments.source delayed: the measured surfaces instrument "
                   "themselves and the other regressors their values instruments.delay_span earlier; this removes "
                   "the bias only in open loop (no pilot or feedback answering the gusts) and with surface sensors "
                   "far less noisy than the motion's")
    elif source and topics is not None and topics.get("excitation") == topics.get("control_surfaces"):
        out.append("estimator.algorithm iv takes its instruments from the measured surfaces (topics.excitation is "
                   "topics.control_surfaces): they carry the surfaces' sensor noise and, in closed loop (a pilot or a "
                   "feedback answering the gusts), the gusts, so the estimates stay biased; point topics.excitation "
                   "at the injected excitation if the flight-control computer publishes it")
    if o.forgetting < 1.0 and config.publishes_time:
        memory = 1.0 / (1.0 - o.forgetting)
        sizes = {m.output: len(m.regressors) for m in config.models}
        model, n = max(sizes.items(), key=lambda item: item[1])
        needed = o.publish_samples(n)
        if memory < needed:
            out.append(f"estimator.forgetting {o.forgetting:g} remembers about {memory:.0f} samples (1/(1 - f)), "
                       f"fewer than the {needed} the corrected standard errors need (estimator.publish_lag_windows "
                       f"{o.publish_lag_windows:g} x {o.publish_lags} lags + {n} parameters of {model}): they stay "
                       "too small; raise estimator.forgetting or shorten estimator.lag_span")
    return out


def record_checks(config: PipelineConfig, seconds: float) -> list[str]:
    """Refuse (:class:`.errors.ConfigError`) what a record of ``seconds`` cannot carry and
    return the warnings: the frequency grid entirely below ``1/T`` (refused; partly below:
    a warning: those frequencies carry no independent information), ``frequency.trim_span``
    longer than the record (refused: the trim would be the mean of the whole maneuver)."""
    f = config.frequency
    if f is None or seconds <= 0.0:
        return []
    lowest, grid = 1.0 / seconds, f.frequencies()
    if grid[-1] < lowest:
        raise ConfigError(
            f"frequency grid {grid[0]:g}-{grid[-1]:g} Hz lies below the lowest frequency the {seconds:.1f} s record "
            f"resolves (1/T = {lowest:.2g} Hz): set frequency.f_min and f_max within {lowest:.2g}-{f.rate_hz / 2:g} "
            "Hz", parameter="frequency.f_min")
    trim = f.trim_samples / f.rate_hz
    if f.trim_samples > 1 and trim > seconds:
        raise ConfigError(
            f"frequency.trim_span {trim:g} s is longer than the record ({seconds:.1f} s after --start/--end): the trim "
            "would be the mean of the whole maneuver; set it to the steady part before the input (config/t2.yaml: "
            "0.5 s)", parameter="frequency.trim_span")
    below = int((grid < lowest).sum())
    if below:
        return [f"frequency grid starts at {grid[0]:g} Hz, below the lowest frequency the {seconds:.1f} s record "
                f"resolves (1/T = {lowest:.2g} Hz): {below} of {grid.size} frequencies carry no independent "
                "information"]
    return []
