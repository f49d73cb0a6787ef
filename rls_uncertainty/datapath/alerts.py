"""Loud misconfiguration in the data path: what to say, and when (pure Python, no ROS).

**What.** :func:`explain` turns a rejection reason into the user's terms, from the
configuration and the evidence the pipeline kept of the newest refused input
(:attr:`.bookkeeping.Bookkeeping.evidence`): what was expected against what came, and the
parameter to change. For example ``missing_joint``: ``surfaces.elevator expects [elevator],
messages carry [elevator_left, elevator_right, ...]; set surfaces.elevator``; ``frame_mismatch``
names ``inputs.frame_id`` and the frame received; ``implausible_<quantity>`` the value seen and
the ``limits.*`` parameter that bounds it (:mod:`.limits`). :func:`explanations` gives the text
of every reason a pipeline counted (:meth:`.pipeline.Pipeline.counters` carries them).

**When.** :class:`AlertPolicy` looks at the counters once per diagnostics period, over the
last ``window_s`` seconds (as the ``/diagnostics`` levels do), and raises an :class:`Alert`

* per needed stream whose messages of the window were all rejected (at least
  :data:`MIN_MESSAGES`): ``control_surfaces: all 1200 messages rejected (missing_joint): ...``;
* when no sample was used for the whole window although messages of the needed streams
  arrived and estimation is enabled: the main reason samples were rejected, or why none was
  formed.

**Identifiability.** :func:`identifiability` says why a model's parameters are not identifiable
(:mod:`.identifiability`: the fit, the excitation of each regressor, the correlation of the
estimates), naming the regressors and the figure, e.g. ``CZ: delta_e and delta_r correlated
-0.999998 (their estimates; limit 0.999): not identifiable ...``; :func:`model_alerts` raises it
when it withholds a convergence flag, or keeps a model from initializing.

The node logs each alert as a WARN at most once per ``repeat_s`` seconds per stream and reason
(:meth:`AlertPolicy.due`) and puts the texts first in the ``inputs`` status of
``/diagnostics`` (level ERROR); the replay reports the same texts for a run in which a model
never produced an estimate (:func:`no_estimate`). Texts are bounded: a few names, each cut,
a line at most :data:`MAX_LINE` characters.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..aero.coefficients import FlightState, flight_state
from ..errors import Refused
from .bookkeeping import NO_TOTALS, SAMPLES, Bookkeeping, Totals, Window, growth
from .limits import BOUNDS, message_value, sample_value

if TYPE_CHECKING:  # annotations only
    from .config import PipelineConfig
    from .identifiability import Problem

__all__ = ["Alert", "AlertPolicy", "explain", "explanations", "no_estimate", "not_excited", "identifiability",
           "model_alerts", "MIN_MESSAGES", "MAX_LINE", "SHOWN"]

MIN_MESSAGES = 3  # rejected messages of a stream in the window before "all rejected" is said
MAX_LINE = 400  # characters of an alert line
SHOWN = 6  # names shown of a list (joint names), the rest as "..."
_CUT = 40  # characters of a name or frame shown

# Reasons the sampler gives without evidence: what they mean and what to look at.
_STAMP_REASONS = {
    "duplicate": "stamps repeat (two publishers on one topic, or a coarse sensor clock)",
    "out_of_order": "stamps go backwards (two publishers on one topic, or transport that reorders)",
    "stamp_jump": "stamps jump away from the stream's and do not continue there (inputs.max_stamp_jump, "
                  "inputs.jump_confirmation)",
    "previous_timeline": "stragglers of a timeline the data has left (a restarted replay)",
    "non_finite": "messages carry NaN or infinite values (check the publisher)",
    "expired": "buffered messages expired unused",
}


@dataclass(frozen=True)
class Alert:
    """One misconfiguration: ``key`` ``(stream or "samples", reason)`` and its one-line text."""

    key: tuple[str, str]
    text: str


def _cut(text: object, n: int = _CUT) -> str:
    t = "".join(c if c.isprintable() else "?" for c in str(text))
    return t if len(t) <= n else t[: n - 3] + "..."


def _list(names: Sequence[str], total: int | None = None) -> str:
    """``[a, b, ...]``: at most :data:`SHOWN` names, each cut."""
    total = len(names) if total is None else total
    shown = [_cut(n) for n in names[:SHOWN]]
    more = ", ..." if total > len(shown) else ""
    return f"[{', '.join(shown)}{more}]"


def _g(x: float) -> str:
    return f"{x:.4g}"


# What else than a real value a refused one may be, where it is not a unit.
_SUSPECTS = {
    "implausible_angular_acceleration": "else look for gyro spikes (a body rate jumped between two consecutive imu "
                                        "messages)",
}


def _limit(config: PipelineConfig, reason: str, seen: float) -> str:
    """``seen alpha = 1.31 rad, limits.alpha allows |alpha| <= 1 rad; set limits.alpha ...``"""
    parameter, bound = config.limits.bound(reason, seen)
    quantity = reason.removeprefix("implausible_")
    unit = BOUNDS[reason][1] if reason in BOUNDS else ""
    seen_text = f"seen {quantity} = {_g(seen)} {unit}, " if not math.isnan(seen) else ""
    suspect = _SUSPECTS.get(reason, "else check the sensor's units")
    return f"{seen_text}{parameter} allows {bound}; set {parameter} if that is real, {suspect}"


def _inconsistent_dynamic_pressure(config: PipelineConfig, state: Any) -> str:
    """The dynamic pressure and the airspeed of a refused sample (a FlightState, or None), the
    density they imply and the bound it is beyond."""
    seen = math.nan if state is None else sample_value("inconsistent_dynamic_pressure", state)
    parameter, bound = config.limits.bound("inconsistent_dynamic_pressure", seen)
    implies = "" if state is None else (f"dynamic pressure {_g(state.qbar)} Pa at true airspeed {_g(state.V)} m/s "
                                        f"implies an air density 2 qbar/V^2 = {_g(seen)} kg/m^3, ")
    return (f"{implies}{parameter} allows {bound}: the dynamic_pressure and airspeed streams disagree (a unit? a "
            f"blocked pitot?); set {parameter} if that is real, or inputs.use_dynamic_pressure false to use "
            "rho V^2 / 2 with inputs.air_density")


def _explain_joints(config: PipelineConfig, reason: str, evidence: Any) -> str:
    names, total, positions, missing = evidence
    carry = f"messages carry {_list(names, total)}"
    if reason == "mismatched_arrays":
        return f"a JointState needs one position per name and no name twice; {carry} with {positions} positions"
    if not missing:
        return carry
    expects = ", ".join(f"{field} expects {_list(joints)}" for field, joints in missing)
    return f"{expects}, {carry}; set {', '.join(field for field, _ in missing)}"


def _explain_stream(config: PipelineConfig, stream: str, reason: str, evidence: Any) -> str:
    inputs = config.inputs
    if reason in ("missing_joint", "mismatched_arrays") and evidence is not None:
        return _explain_joints(config, reason, evidence)
    if reason == "frame_mismatch":
        got = f"messages carry {_cut(evidence)!r}" if evidence is not None else "messages carry another frame"
        return f"inputs.frame_id expects {inputs.frame_id!r}, {got}; set inputs.frame_id (empty: not checked)"
    if reason.startswith("implausible_"):
        seen = message_value(reason, evidence) if evidence is not None else math.nan
        return _limit(config, reason, seen)
    if reason == "far_from_clock":
        return (f"stamps more than inputs.max_clock_offset = {inputs.max_clock_offset:g} s from the node's clock; "
                "set use_sim_time when a bag plays /clock, or inputs.max_clock_offset (0: off)")
    if reason.startswith("malformed"):
        detail = f" ({_cut(evidence, 120)})" if evidence else ""
        return f"messages could not be decoded{detail}: check the topic's message type (topics.{stream})"
    return _STAMP_REASONS.get(reason, reason)


def _explain_sample(config: PipelineConfig, reason: str, evidence: Any) -> str:
    inputs = config.inputs
    stream = reason.split("_", 1)[1] if "_" in reason else ""
    if reason.startswith("gap_"):
        return (f"{stream} messages more than inputs.max_gap = {inputs.max_gap:g} s apart; set inputs.max_gap or "
                f"check the {stream} rate")
    if reason.startswith("expired_"):
        return (f"{stream} messages expired before every needed stream reached their time (stamps of the streams "
                f"more than inputs.buffer_duration = {inputs.buffer_duration:g} s apart: different clocks?)")
    if reason.startswith("invalid_"):
        return f"holes left by rejected {stream} messages"
    if reason.startswith("implausible_") or reason == "inconsistent_dynamic_pressure":
        state: FlightState | Refused | None = None
        if evidence is not None:
            sample, rate_dot = evidence
            state = flight_state(sample, np.asarray(rate_dot), inputs.air_density)
        if isinstance(state, Refused):
            state = None
        if reason == "inconsistent_dynamic_pressure":
            return _inconsistent_dynamic_pressure(config, state)
        return _limit(config, reason, math.nan if state is None else sample_value(reason, state))
    if reason.startswith(("nonpositive_", "non_finite")):
        return f"{reason.replace('_', ' ')} in the formed samples (Eq. 1 divides by dynamic pressure and airspeed)"
    if reason == "differentiator_warmup":
        return "every run of samples is shorter than the differentiator's (differentiator.window): gaps restart it"
    return reason.replace("_", " ")


def explain(config: PipelineConfig, stream: str, reason: str, evidence: Any = None) -> str:
    """What rejection ``reason`` of ``stream`` (or of :data:`.bookkeeping.SAMPLES`) means in
    the user's terms, with ``evidence`` (what the newest such input carried, or None)."""
    if stream == SAMPLES:
        return _explain_sample(config, reason, evidence)
    return _explain_stream(config, stream, reason, evidence)


def explanations(config: PipelineConfig, book: Bookkeeping) -> dict[str, dict[str, str]]:
    """The :func:`explain` text of every reason ``book`` counted, by stream (and
    :data:`.bookkeeping.SAMPLES`) and reason (the tables are bounded, so is this)."""
    out: dict[str, dict[str, str]] = {}
    for name, counts in book.streams.items():
        if counts.rejected:
            out[name] = {r: explain(config, name, r, book.evidence.get((name, r))) for r in counts.rejected}
    if book.samples_rejected:
        out[SAMPLES] = {r: explain(config, SAMPLES, r, book.evidence.get((SAMPLES, r)))
                        for r in book.samples_rejected}
    return out


def _reasons(grown: list[tuple[str, int]]) -> str:
    return grown[0][0] if len(grown) == 1 else ", ".join(f"{k} {n}" for k, n in grown[:3])


def _line(text: str) -> str:
    return text if len(text) <= MAX_LINE else text[: MAX_LINE - 3] + "..."


def _problems(now: Totals, before: Totals, counters: Mapping, required: Sequence[str], window: str) -> list[Alert]:
    """The alerts of the counts between ``before`` and ``now`` (``window``: how the span is
    named in the texts, e.g. ``"the last 10 s"``)."""
    why = counters.get("explanations", {})
    # Streams whose messages of the window were all rejected, grouped by what to say (one
    # frame_id mismatch rejects every stream for the same reason).
    groups: dict[tuple[str, str, str, bool], list[tuple[str, int]]] = {}
    for kind in required:
        received = now.received.get(kind, 0) - before.received.get(kind, 0)
        accepted = now.accepted.get(kind, 0) - before.accepted.get(kind, 0)
        grown = growth(now.rejected.get(kind, {}), before.rejected.get(kind, {}))
        if received >= MIN_MESSAGES and accepted <= 0 and grown:
            reason = grown[0][0]
            ever = now.accepted.get(kind, 0) <= 0  # never one accepted: count them all
            key = (reason, _reasons(grown), why.get(kind, {}).get(reason, reason), ever)
            groups.setdefault(key, []).append((kind, now.received[kind] if ever else received))
    alerts = []
    for (reason, reasons, text, ever), streams in groups.items():
        names = ", ".join(kind for kind, _ in streams)
        counts = "/".join(str(n) for _, n in streams)
        span = f"all {counts} messages" + ("" if ever else f" of {window}")
        alerts.append(Alert((names, reason), _line(f"{names}: {span} rejected ({reasons}): {text}")))
    if alerts:
        return alerts  # the streams say why no sample can be formed
    arriving = any(now.received.get(k, 0) > before.received.get(k, 0) for k in required)
    if not arriving or now.used > before.used:
        return []
    formed = now.formed - before.formed
    grown = growth(now.samples_rejected, before.samples_rejected)
    grown = [(k, n) for k, n in grown if k not in ("estimation_disabled", "end_of_data")]
    if formed > 0 and grown:
        reason = grown[0][0]
        text = (f"samples: none of the {formed} samples of {window} used ({_reasons(grown)}): "
                f"{why.get(SAMPLES, {}).get(reason, reason)}")
        return [Alert((SAMPLES, reason), _line(text))]
    if formed <= 0:
        silent = [k for k in required if now.received.get(k, 0) <= before.received.get(k, 0)]
        what = (f"waiting for {', '.join(silent)} (no message in {window}; topics.{silent[0]})" if silent else
                "the needed streams' stamps never overlap within inputs.buffer_duration (different clocks?)")
        return [Alert((SAMPLES, "none_formed"), _line(f"samples: none formed in {window} although messages "
                                                      f"arrive: {what}"))]
    return []


class AlertPolicy:
    """The alerts of one node (or replay): :meth:`update` once per diagnostics period with
    the pipeline's counters, the streams the samples need and whether estimation is enabled;
    :meth:`due` the lines to log now, each alert at most once per ``repeat_s`` seconds."""

    def __init__(self, repeat_s: float = 30.0) -> None:
        if not repeat_s > 0:
            raise ValueError(f"repeat_s must be positive, got {repeat_s!r}")
        self.repeat_s = float(repeat_s)
        self.current: list[Alert] = []
        self.model: list[Alert] = []  # identifiability (model_alerts), logged beside the inputs'
        self._window = Window(NO_TOTALS)
        self._logged: dict[tuple[str, str], float] = {}

    def update(self, elapsed_s: float, counters: Mapping, required: Sequence[str], enabled: bool,
               window_s: float) -> list[Alert]:
        """The alerts over the last ``window_s`` seconds (``elapsed_s``: steady time since the
        previous update). "No sample used" needs a whole window of history."""
        now = Totals.of(counters)
        before, whole = self._window.advance(elapsed_s, now, window_s)
        alerts = _problems(now, before, counters, required, f"the last {window_s:g} s")
        if alerts and alerts[0].key[0] == SAMPLES and (not enabled or not whole):
            alerts = []  # disabled on purpose, or less than a window since the start
        self.current = alerts
        return alerts

    def models(self, models: Sequence[tuple[str, Mapping]]) -> list[Alert]:
        """The identifiability alerts of the models' reports (:func:`model_alerts`), logged by
        :meth:`due` with the others."""
        self.model = model_alerts(models)
        return self.model

    def due(self) -> list[str]:
        """The current alerts not logged in the last ``repeat_s`` seconds (then marked logged)."""
        lines = []
        for alert in self.current + self.model:
            last = self._logged.get(alert.key)
            if last is None or self._window.time - last >= self.repeat_s:
                self._logged[alert.key] = self._window.time
                lines.append(alert.text)
        if len(self._logged) > 256:  # keys come from bounded tables; stay bounded anyway
            self._logged = {a.key: self._logged[a.key] for a in self.current + self.model if a.key in self._logged}
        return lines


def no_estimate(counters: Mapping, required: Sequence[str]) -> str | None:
    """Why no model can have produced an estimate in a whole run (the alerts of the run's
    counters), or None when samples were used."""
    alerts = _problems(Totals.of(counters), NO_TOTALS, counters, required, "the run")
    if alerts:
        return "; ".join(a.text for a in alerts)
    if counters["samples_used"] == 0:
        silent = [k for k in required if counters["streams"][k]["received"] == 0]
        return f"no message of {', '.join(silent)} (topics.{silent[0]})" if silent else "no sample was used"
    return None


def not_excited(n_regressors: int, samples: int, constant: Sequence[str] = ()) -> str:
    """Why a model that received samples never produced an estimate: its regressors never
    spanned their space (exact initialization waits for that); ``constant``: those that never
    moved, when known."""
    which = f" ({', '.join(constant)} never moved)" if constant else ""
    return (f"its {n_regressors} regressors were not excited independently in {samples} samples{which}, so the "
            "estimator never initialized (a maneuver must move each of them; or leave the model out of "
            "models.enabled)")


def too_few_samples(count: int, needed: int, windows: float, lags: int, parameters: int, option: str) -> str:
    """Why an initialized model never published: its fit had ``count`` of the ``needed``
    samples the publication rule asks (``windows`` lag windows of ``lags`` plus its
    ``parameters``); ``option``: the lag span to shorten."""
    return (f"{count} samples, fewer than the {needed} its corrected standard errors need "
            f"(estimator.publish_lag_windows {windows:g} x {lags} lags + {parameters} parameters); use a longer span "
            f"or shorten {option}")


def _correlation_text(r: float) -> str:
    """A correlation with the digits that tell it from +-1: ``-0.999998``, ``+1 - 2.0e-09``."""
    if 1.0 - abs(r) >= 5e-7:
        return f"{r:+.6f}"
    return f"{'-' if r < 0 else '+'}1 - {1.0 - abs(r):.1e}"


def _figure(x: float, unit: str) -> str:
    return f"{x:.3g} {unit}".rstrip()


_RESOLUTION = {"rad": "identifiability.angle_resolution", "": "identifiability.rate_resolution"}


def _flat_text(model: str, p: Problem) -> str:
    """Regressors that did not move, each with its standard deviation, and the floors."""
    regs = ", ".join(p.regressors)
    one = len(p.regressors) == 1
    floors = dict.fromkeys(zip(p.units, p.limits, strict=True))  # in order, once each
    limits = ", ".join(f"{_RESOLUTION.get(u, 'resolution')} {_figure(x, u)}" for u, x in floors)
    where = f"in {p.samples} samples since start; {limits}"
    if one:
        what = f"regressor {regs} not excited (std {_figure(p.figures[0], p.units[0])} {where})"
    else:
        stds = ", ".join(f"{r} {_figure(x, u)}" for r, x, u in zip(p.regressors, p.figures, p.units, strict=True))
        what = f"regressors {regs} not excited (std {stds} {where})"
    effect = "the model cannot initialize" if p.kind == "constant" else "not identifiable"
    return f"{what}: {effect}; move {regs} or leave {'it' if one else 'them'} out of models.{model}"


def _problem_text(model: str, p: Problem) -> str:
    if p.kind == "no_fit":
        r2, limit = p.figures[0], p.limits[0]
        if not math.isfinite(r2):
            return "the output does not vary (R^2 undefined): not identifiable; check the model's output"
        return (f"no regressor explains the output (R^2 {r2:.3f}, identifiability.min_r_squared {limit:g}): "
                "not identifiable; excite the model or check its output")
    if p.kind in ("not_excited", "constant"):
        return _flat_text(model, p)
    if p.kind == "noise":
        (reg,), (std, noise), (limit,), (unit,) = p.regressors, p.figures, p.limits, p.units
        ratio = (std / noise) ** 2 if noise > 0 else math.inf
        return (f"regressor {reg} does not move beyond its sensor noise (std {_figure(std, unit)}, noise "
                f"{_figure(noise, unit)} from its second differences: variance ratio {ratio:.3g}, "
                f"identifiability.min_noise_ratio {limit:g}): not identifiable; move {reg} or leave it out of "
                f"models.{model}")
    a, b = p.regressors
    r = _correlation_text(p.figures[0])
    if p.kind == "collinear":
        return (f"{a} and {b} correlated {r} (their estimates; identifiability.max_correlation {p.limits[0]:g}): "
                f"not identifiable; excite {a} and {b} independently or leave one out of models.{model}")
    return (f"regressors {a} and {b} correlated {r} in {p.samples} samples: the model cannot initialize; excite "
            f"them independently or leave one out of models.{model}")


def identifiability(model: str, problems: Sequence[Problem]) -> str:
    """One line: why model ``model``'s parameters are not identifiable (or, for a model not
    ready, why it cannot initialize), each problem of :meth:`.identifiability.
    IdentifiabilityMonitor.problems` with its regressors and figure; empty without problems."""
    if not problems:
        return ""
    return _line(f"{model}: " + "; ".join(_problem_text(model, p) for p in problems))


def model_alerts(models: Sequence[tuple[str, Mapping]]) -> list[Alert]:
    """An alert per model whose report (:meth:`.pipeline.Pipeline.model_report`) has a
    convergence flag held back as not identifiable, or that names why the model cannot
    initialize: its ``identifiability`` text, one key per model (logged at most once per
    ``repeat_s`` whatever the figure)."""
    alerts = []
    for name, fit in models:
        text = fit.get("identifiability", "")
        if text and (fit.get("held_back") or not fit.get("ready")):
            alerts.append(Alert((f"model {name}", "identifiability"), text))
    return alerts
