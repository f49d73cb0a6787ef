"""Each parameter's state in words, and its percent error: what every human-facing output says.

One state per parameter and method, from what the pipeline published and judged at a sample:

* ``converged``: published and flagged converged (:mod:`.convergence`);
* ``settling``: published, not flagged (yet);
* ``held back: not identifiable: <reason>``: published, but the data cannot identify it
  (:mod:`.identifiability`: the fit, the excitation against the floor and against the sensor's
  own noise, collinearity), so its flag is never raised; the reason in a few words
  (``correlated -1.000 with CZ_delta_r``, ``delta_e moves no more than its sensor noise (ratio
  0.99 < 10)``);
* ``initializing (37 of 104 samples)``: nothing published yet: the model's fit has not the
  degrees of freedom its corrected standard errors need (``estimator.publish_lag_windows``), or
  it has not initialized; ``withheld`` when it is past that but its last values were not
  finite or not above rounding (:mod:`.guard`).

and the percent error ``100 SE / |estimate|`` (corrected standard error) that flight-test
engineers read first. ``replay``, ``campaign``, ``montecarlo``, ``/diagnostics`` (and so
``status`` and the page) all take them from here. numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..aero.models import BIAS_REGRESSOR
from .alerts import identifiability

if TYPE_CHECKING:  # annotations only
    from ..aero.models import ModelConfig
    from ..estimator import EstimatorBank
    from .config import PipelineConfig
    from .frequency_path import FrequencyOutput, FrequencyPath
    from .identifiability import IdentifiabilityMonitor
    from .targets import TargetTracker


class Published(Protocol):
    """What a sample's output (:class:`.pipeline.SampleOutput`) holds that the states read."""

    @property
    def ready(self) -> np.ndarray: ...
    @property
    def theta(self) -> np.ndarray: ...
    @property
    def se(self) -> np.ndarray: ...
    @property
    def converged(self) -> np.ndarray: ...
    @property
    def frequency(self) -> FrequencyOutput | None: ...


class Publisher(Protocol):
    """What a pipeline (:class:`.pipeline.Pipeline`) holds that the states read."""

    bank: EstimatorBank
    frequency: FrequencyPath | None

    @property
    def models(self) -> Sequence[ModelConfig]: ...
    @property
    def parameter_names(self) -> Sequence[Sequence[str]]: ...
    @property
    def identifiability(self) -> IdentifiabilityMonitor: ...
    def weak_instruments(self, j: int) -> str: ...


class Reporter(Publisher, Protocol):
    """What :func:`model_report` reads of a pipeline besides :class:`Publisher`."""

    config: PipelineConfig
    named_after: int  # samples before a cause of non-identifiability is named
    targets: TargetTracker | None  # targets.percent: the test point judged

    @property
    def last(self) -> Published | None: ...
    def model_fit(self, j: int) -> dict: ...
    def convergence(self, j: int) -> dict: ...

__all__ = ["ParameterState", "STATES", "se_percent", "se_percent_text", "model_reasons", "initializing",
           "parameter_states", "state_fields", "Published", "Publisher",
           "Reporter", "model_report"]

STATES = ("converged", "settling", "held back", "initializing", "withheld")


def se_percent(estimate: float, std_error: float) -> float:
    """``100 SE / |estimate|``; NaN when the estimate is 0 or either is not finite."""
    if not (math.isfinite(estimate) and math.isfinite(std_error)) or estimate == 0.0:
        return math.nan
    return 100.0 * std_error / abs(estimate)


def se_percent_text(value: float) -> str:
    """One decimal (``11.3``), ``-`` when undefined."""
    return f"{value:.1f}" if math.isfinite(value) else "-"


@dataclass(frozen=True)
class ParameterState:
    """One parameter's ``state`` (one of :data:`STATES`), its ``reason`` (the words after
    ``held back: `` or inside ``initializing (...)``, empty otherwise) and the published
    ``estimate`` and corrected ``std_error`` (NaN when nothing is published)."""

    method: str
    model: str
    parameter: str
    estimate: float
    std_error: float
    state: str
    reason: str = ""

    @property
    def se_percent(self) -> float:
        return se_percent(self.estimate, self.std_error)

    @property
    def text(self) -> str:
        """``converged``, ``settling``, ``held back: <reason>``, ``initializing (<reason>)``."""
        if self.state == "held back":
            return f"held back: {self.reason}"
        if self.state in ("initializing", "withheld") and self.reason:
            return f"{self.state} ({self.reason})"
        return self.state


def _regressor_reason(quality: IdentifiabilityMonitor, j: int, i: int, parameters: list[str]) -> str:
    cfg, regs = quality.config, quality.regressors[j]
    name = regs[i]
    if quality.noisy[j, i]:
        noise = float(np.sqrt(quality.stats.noise_variance[j, i]))
        ratio = (float(quality.stats.std[j, i]) / noise) ** 2 if noise > 0 else math.inf
        return f"{name} moves no more than its sensor noise (ratio {ratio:.2g} < {cfg.min_noise_ratio:g})"
    if quality.not_excited[j, i]:
        if quality.bias[j, i]:
            return "the bias is confounded with a regressor that does not move"
        unit = str(quality.units[j, i])
        return f"{name} not excited (std {float(quality.stats.std[j, i]):.3g}{' ' + unit if unit else ''})"
    if quality.collinear[j, i]:
        rho = quality.correlation[j, i].copy()
        rho[i] = 0.0
        rho[quality.bias[j]] = 0.0
        k = int(np.argmax(np.abs(rho[: len(regs)])))
        return f"correlated {rho[k]:.3f} with {parameters[k]}"
    return ""


def model_reasons(quality: IdentifiabilityMonitor, j: int, parameters: list[str]) -> list[str]:
    """Why each parameter of model ``j`` (``parameters``: its names, one per regressor) is not
    identifiable at the last judgement, ``not identifiable: <why>``; empty for an identifiable
    one."""
    ok = quality.identifiable[j]  # (judges the pending sample)
    no_fit = ""
    if quality.no_fit[j] and not ok[: len(parameters)].all():
        r2 = float(quality.r_squared[j])
        no_fit = (f"no fit (R^2 {r2:.3f} < {quality.config.min_r_squared:g})" if math.isfinite(r2)
                  else "no fit (the output does not vary)")
    out = []
    for i in range(len(parameters)):
        if ok[i]:
            out.append("")
            continue
        why = no_fit or _regressor_reason(quality, j, i, parameters)
        out.append(f"not identifiable: {why}" if why else "")
    return out


def initializing(count: int, needed: int) -> str:
    """``37 of 104 samples``."""
    return f"{max(count, 0)} of {needed} samples"


def _time_states(pipe: Publisher, out: Published, models: Sequence[int]) -> list[ParameterState]:
    bank, quality = pipe.bank, pipe.identifiability
    counts, needed, initialized = bank.publish_count, bank.publish_at, bank.initialized
    states = []
    for j in models:
        model = pipe.models[j]
        names = list(pipe.parameter_names[j])
        published = bool(out.ready[j])
        reasons = model_reasons(quality, j, names) if published else [""] * len(names)
        weak = pipe.weak_instruments(j) if published else ""
        reasons = [r or weak for r in reasons]
        for i, name in enumerate(names):
            theta, se = float(out.theta[j, i]), float(out.se[j, i])
            if published:
                state = "held back" if reasons[i] else ("converged" if out.converged[j, i] else "settling")
                states.append(ParameterState("time", model.output, name, theta, se, state, reasons[i]))
            else:
                late = initialized[j] and counts[j] >= needed[j]
                states.append(ParameterState("time", model.output, name, math.nan, math.nan,
                                             "withheld" if late else "initializing",
                                             "" if late else initializing(int(counts[j]), int(needed[j]))))
    return states


def _frequency_states(pipe: Publisher, out: Published | None, models: Sequence[int]) -> list[ParameterState]:
    path = pipe.frequency
    assert path is not None
    bank, quality = path.bank, pipe.identifiability
    f = path.last if out is None or out.frequency is None else out.frequency
    states = []
    for j in models:
        model = pipe.models[j]
        regs = [r for r in model.regressors if r != BIAS_REGRESSOR]
        index = [model.regressors.index(r) for r in regs]
        names = list(path.parameter_names[j])
        published = f is not None and bool(f.ready[j])
        reasons = model_reasons(quality, j, list(pipe.parameter_names[j])) if published else []
        for k, name in enumerate(names):
            if f is not None and published:
                reason = reasons[index[k]]
                state = "held back" if reason else ("converged" if f.converged[j, k] else "settling")
                states.append(ParameterState("frequency", model.output, name, float(f.theta[j, k]),
                                             float(f.se[j, k]), state, reason))
            else:
                late = bank.n_samples >= bank.publish_at[j]
                states.append(ParameterState("frequency", model.output, name, math.nan, math.nan,
                                             "withheld" if late else "initializing",
                                             "" if late else initializing(bank.n_samples, int(bank.publish_at[j]))))
    return states


def parameter_states(pipe: Publisher, out: Published | None, method: str = "time",
                     models: Sequence[int] | None = None) -> list[ParameterState]:
    """Every parameter's state by ``method`` (``time`` or ``frequency``) at the pipeline's
    newest sample, whose output is ``out`` (None before any: every model initializing);
    ``models``: only those models' (indices, in order; default all)."""
    index = range(len(pipe.models)) if models is None else models
    if method == "frequency":
        return _frequency_states(pipe, out, index)
    if out is None:
        bank = pipe.bank
        return [ParameterState("time", pipe.models[j].output, name, math.nan, math.nan, "initializing",
                               initializing(int(bank.publish_count[j]), int(bank.publish_at[j])))
                for j in index for name in pipe.parameter_names[j]]
    return _time_states(pipe, out, index)


def state_fields(pipe: Publisher, out: Published | None, output: str, methods: Sequence[str]) -> dict[str, str | float]:
    """``/diagnostics`` fields of the model of ``output``, per parameter and method published
    (``methods``): ``state.<parameter>`` (:attr:`ParameterState.text`) and
    ``se_percent.<parameter>`` (two decimals, ``-`` when undefined); ``frequency.`` before
    both for the frequency domain."""
    fields: dict[str, str | float] = {}
    models = [j for j, m in enumerate(pipe.models) if m.output == output]
    for method in methods:
        prefix = "frequency." if method == "frequency" else ""
        for s in parameter_states(pipe, out, method, models):
            if s.model == output:
                fields[f"{prefix}state.{s.parameter}"] = s.text
                fields[f"{prefix}se_percent.{s.parameter}"] = round(s.se_percent, 2) \
                    if math.isfinite(s.se_percent) else "-"
    return fields


def model_report(pipe: Reporter, j: int) -> dict:
    """What ``/diagnostics`` reports of model ``j`` (node and replay alike): its fit
    (:meth:`.pipeline.Pipeline.model_fit`), once it is published its newest convergence flags
    (:meth:`.pipeline.Pipeline.convergence`) and identifiability figures, and
    ``identifiability``: why parameters are not identifiable, or why the model cannot
    initialize (:func:`.alerts.identifiability`), when that is so; ``initializing``: ``37 of
    104 samples (...)`` while the publication rule holds it back; :func:`state_fields` of each
    method published, and with the frequency domain its fit (:meth:`.frequency_path.
    FrequencyPath.report`). ``time_domain``: whether the time domain's estimates are published."""
    fit, quality = pipe.model_fit(j), pipe.identifiability
    why = identifiability(pipe.models[j].output, quality.problems(j, pipe.named_after))
    if fit["ready"]:
        fit = {**fit, **pipe.convergence(j), **quality.report(j, pipe.parameter_names[j])}
    elif "publish_at_samples" in fit and pipe.bank.initialized[j]:
        o = pipe.config.estimator
        fit["initializing"] = (f"{initializing(fit['publish_count'], fit['publish_at_samples'])} (the corrected "
                               f"standard errors need estimator.publish_lag_windows {o.publish_lag_windows:g} x "
                               f"{o.publish_lags} lags + {len(pipe.parameter_names[j])} parameters)")
    fit["time_domain"] = pipe.config.publishes_time
    methods = ["time"] if pipe.config.publishes_time else []
    if pipe.frequency is not None:
        fit.update(pipe.frequency.report(j))
        methods.append("frequency")
    fit.update(state_fields(pipe, pipe.last, pipe.models[j].output, methods))
    if pipe.targets is not None:
        fit.update(target_fields(pipe.targets, pipe.parameter_names[j]))
    return {**fit, "identifiability": why} if why else fit


def target_fields(tracker: TargetTracker, names: Sequence[str]) -> dict[str, str]:
    """``target.<parameter>`` of the parameters ``names`` that have a target (:mod:`.targets`:
    met, or the time left at the present rate of information, or why there is none) and
    ``verdict``, the test point's (``done``, ``needs more (about 3.1 s: ...)``, ``not
    identifiable (...)``)."""
    out = {}
    for p in tracker.progress:
        if p.name not in names or math.isnan(p.target):
            continue
        pe = f"{p.percent_error:.1f} %" if math.isfinite(p.percent_error) else "-"
        if p.met:
            text = f"met: {pe} <= {p.target:g} %" + ("" if p.converged else ", not converged yet")
        elif math.isfinite(p.time_left):
            text = f"{pe} -> {p.target:g} % in about {p.time_left:.1f} s"
        else:
            text = f"{pe} > {p.target:g} %: {p.reason}"
        out[f"target.{p.name}"] = text
    if tracker.progress:
        out["verdict"] = tracker.verdict().text
    return out

