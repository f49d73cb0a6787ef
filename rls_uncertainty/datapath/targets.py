"""Test points judged against their targets: percent errors, time left, a verdict (numpy only).

A flight-test engineer gives some parameters a target percent error ``100 SE / |estimate|``
(the corrected standard error, Eqs. 20/22). Per sample, :class:`TargetTracker` reports for
each parameter its current percent error ``pe`` and, when a target ``g`` is set and not yet
met, a forecast of the time left to reach it at the present rate of information; per
maneuver, :meth:`TargetTracker.verdict` says ``done``, ``needs more`` (with the time left) or
``not identifiable`` (with the reason).

The forecast. Least squares standard errors fall as the square root of the information:
``SE = c / sqrt(I)`` (Eq. 13: the covariance is ``s^2 (X'X)^-1``; the corrected covariance of
Eqs. 20/22 scales the same way while the residual autocorrelation is stationary). The
information is therefore measured by ``I = 1 / SE^2`` (up to the constant ``c^2``, which
cancels). Over the last window of ``w`` seconds it grew from ``I_0`` to ``I``, at the rate
``(I - I_0) / w``, which is taken to hold on. With the estimate steady, ``pe`` is proportional
to ``SE``, so the target needs the information ``I (pe / g)^2``, and the time left is

    t_left = (I (pe/g)^2 - I) / ((I - I_0) / w) = w ((pe/g)^2 - 1) I / (I - I_0).

When the information grows in proportion to time (``I = a t``, steady excitation without
forgetting) ``I / (I - I_0) = t / w`` and the forecast is exact: ``t_left = t ((pe/g)^2 - 1)``,
which is the time at which ``c / sqrt(a t)`` reaches the target minus the present time. With a
forgetting factor the information levels off and the forecast, which extrapolates the last
window's rate, is optimistic; when the information does not grow over the window
(``I <= I_0``) no forecast is made and the parameter is ``not identifiable`` at the present
excitation.

The verdict is judged over the parameters with a target: ``done`` when every one of them meets
its target and is flagged converged (:mod:`.convergence`); ``not identifiable`` when one of
them is above its target with no forecast (its information not growing, its estimate zero, its
standard error not finite), with that parameter's reason; else ``needs more`` with the longest
time left (NaN when a parameter meets its target but is not converged yet, or when there is no
window of history yet). Parameters
without a target are not judged.

Settings (:class:`TargetOptions`, the one schema): ``targets.percent`` (comma-separated
``NAME=PERCENT`` entries) and ``targets.window`` (seconds). The pipeline drives a tracker with
each sample's time, estimates, standard errors and flags when targets are set, and
:func:`.states.target_fields` puts its progress and verdict in the models' ``/diagnostics``.
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ..schema import check, option

__all__ = ["TargetOptions", "ParameterProgress", "Verdict", "TargetTracker", "time_left", "percent_errors",
           "judge", "targets_of",
           "DONE", "NEEDS_MORE", "NOT_IDENTIFIABLE"]

DONE, NEEDS_MORE, NOT_IDENTIFIABLE = "done", "needs more", "not identifiable"
NO_HISTORY = "no history yet to measure the rate of information"

_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", re.ASCII)


@dataclass(frozen=True)
class TargetOptions:
    """The targets and the forecast's window (module docstring).

    targets:
        ``NAME=PERCENT`` entries: parameter ``NAME``'s target percent error ``100 SE /
        |estimate|`` (a number > 0). Parameters not named have no target.
    window:
        Seconds of history behind the rate of information of the forecast.
    """

    targets: str = option("", "target percent errors 100 SE/|estimate| of a test point: comma-separated "
                          "NAME=PERCENT entries (e.g. Cm_q=10,Cm_alpha=5); /diagnostics then gives each named "
                          "parameter's time left and the test point's verdict; parameters not named have none",
                          own_check=True, ros="targets.percent")
    window: float = option(2.0, "targets: seconds of history behind the rate of information the time left is "
                           "forecast from", unit="s", low=0.0, low_open=True, high=600.0, ros="targets.window")

    def __post_init__(self) -> None:
        check(self, "targets")
        entries: object = self.targets
        if isinstance(entries, (tuple, list)) and all(isinstance(t, str) for t in entries):
            object.__setattr__(self, "targets", ",".join(entries))
        elif not isinstance(entries, str):
            raise ConfigError(f"targets.percent must be comma-separated NAME=PERCENT entries, got {self.targets!r}",
                              parameter="targets.percent")
        self.percent()  # each entry checked

    def percent(self) -> dict[str, float]:
        """The targets as ``{name: percent}``; a malformed entry, a percent that is not a
        positive number or a name given twice is a :class:`.errors.ConfigError`."""
        out: dict[str, float] = {}
        for entry in (e for e in self.targets.split(",") if e.strip()):
            name, sep, value = entry.partition("=")
            name = name.strip()
            # A plain decimal number only: Python's float() would also take "1_0" and other
            # scripts' digits, which a flight-test card never means.
            percent = float(value) if _DECIMAL.fullmatch(value.strip()) else math.nan
            if not sep or not name or not (math.isfinite(percent) and percent > 0):
                raise ConfigError(f"targets.percent {entry!r}: give NAME=PERCENT with a percent > 0 (e.g. Cm_q=10)",
                                  parameter="targets.percent")
            if name in out:
                raise ConfigError(f"targets.percent: {name} is given twice", parameter="targets.percent")
            out[name] = percent
        return out


@dataclass(frozen=True)
class ParameterProgress:
    """One parameter at one sample: its percent error ``pe`` (NaN when undefined), its
    ``target`` (NaN: none), ``met`` (``pe <= target``), ``converged`` (its flag), the forecast
    ``time_left`` in seconds (0 when met, NaN when no forecast) and ``reason`` why there is no
    forecast (empty otherwise)."""

    name: str
    percent_error: float
    target: float
    met: bool
    converged: bool
    time_left: float
    reason: str = ""


@dataclass(frozen=True)
class Verdict:
    """A maneuver's verdict: ``state`` (:data:`DONE`, :data:`NEEDS_MORE`,
    :data:`NOT_IDENTIFIABLE`), ``time_left`` (s; the longest of the parameters, NaN when not
    known or not needed) and ``reason`` (the parameter and why, for ``not identifiable``; what
    is missing for ``needs more``)."""

    state: str
    time_left: float = math.nan
    reason: str = ""

    @property
    def text(self) -> str:
        if self.state == NEEDS_MORE and math.isfinite(self.time_left):
            return f"{NEEDS_MORE} (about {self.time_left:.1f} s: {self.reason})"
        return f"{self.state} ({self.reason})" if self.reason else self.state


def percent_errors(estimates: np.ndarray, std_errors: np.ndarray) -> np.ndarray:
    """``100 SE / |estimate|`` elementwise, NaN where the estimate is zero or either is not finite."""
    est, se = np.asarray(estimates, dtype=float), np.asarray(std_errors, dtype=float)
    ok = np.isfinite(est) & np.isfinite(se) & (est != 0.0)
    out = np.full(np.broadcast(est, se).shape, np.nan)
    np.divide(100.0 * se, np.abs(est), out=out, where=ok)
    return out


def time_left(percent_error: float, target: float, information: float, information_before: float,
              elapsed: float) -> float:
    """Seconds until ``percent_error`` falls to ``target`` when the information, which grew from
    ``information_before`` to ``information`` over the last ``elapsed`` seconds, grows on at
    that rate: ``elapsed ((pe/g)^2 - 1) I / (I - I_0)`` (module docstring). 0 when the target is
    met; NaN when it cannot be forecast (undefined percent error, no growth, no elapsed time, or a
    target so far below the percent error that the forecast is beyond floating point)."""
    if not (math.isfinite(percent_error) and math.isfinite(target)):
        return math.nan
    if percent_error <= target:
        return 0.0
    gained = information - information_before
    if not (elapsed > 0 and math.isfinite(gained) and gained > 0 and math.isfinite(information)):
        return math.nan
    ratio = percent_error / target
    left = elapsed * (ratio * ratio - 1.0) * information / gained  # (``**`` would raise on overflow)
    return left if math.isfinite(left) else math.nan


class TargetTracker:
    """Per-parameter progress towards the targets of ``options`` for the parameters ``names``
    (in the order the caller's arrays hold them), fed one sample at a time by :meth:`update`;
    :meth:`reset` at a new maneuver. Memory: the samples of the last window."""

    def __init__(self, names: Sequence[str], options: TargetOptions = TargetOptions()) -> None:
        self.names = tuple(names)
        targets = options.percent()
        unknown = sorted(set(targets) - set(self.names))
        if unknown:
            raise ConfigError(f"targets.percent names {', '.join(unknown)}, not a parameter of the models; they "
                              f"are {', '.join(self.names)}", parameter="targets.percent")
        self.window = options.window
        self.targets = np.array([targets.get(n, math.nan) for n in self.names])
        self._history: deque[tuple[float, np.ndarray]] = deque()
        self.progress: list[ParameterProgress] = []

    def reset(self) -> None:
        """A new maneuver: the history and the progress start afresh."""
        self._history.clear()
        self.progress = []

    def _anchor(self, t: float) -> tuple[float, np.ndarray] | None:
        """The newest kept sample at least a window old (else the oldest), dropping older ones."""
        h = self._history
        while len(h) > 1 and h[1][0] <= t - self.window:
            h.popleft()
        return h[0] if h else None

    def update(self, t: float, estimates: Sequence[float] | np.ndarray, std_errors: Sequence[float] | np.ndarray,
               converged: Sequence[bool] | np.ndarray) -> list[ParameterProgress]:
        """One sample at time ``t`` (s): the parameters' estimates, corrected standard errors
        and convergence flags. Returns (and keeps in :attr:`progress`) each parameter's
        :class:`ParameterProgress`."""
        se = np.asarray(std_errors, dtype=float)
        pe = percent_errors(np.asarray(estimates, dtype=float), se)
        with np.errstate(divide="ignore", invalid="ignore"):
            info = np.where(np.isfinite(se) & (se > 0), 1.0 / se**2, np.nan)
        anchor = self._anchor(t)
        self._history.append((t, info))
        flags = np.asarray(converged, dtype=bool)
        out = []
        for i, name in enumerate(self.names):
            out.append(self._one(i, name, t, pe[i], info[i], anchor, bool(flags[i])))
        self.progress = out
        return out

    def _one(self, i: int, name: str, t: float, pe: float, info: float, anchor: tuple[float, np.ndarray] | None,
             converged: bool) -> ParameterProgress:
        target = float(self.targets[i])
        if math.isnan(target):
            return ParameterProgress(name, float(pe), target, False, converged, math.nan)
        met = bool(math.isfinite(pe) and pe <= target)
        if met:
            return ParameterProgress(name, float(pe), target, True, converged, 0.0)
        if not math.isfinite(pe):
            return ParameterProgress(name, float(pe), target, False, converged, math.nan,
                                     "no percent error (estimate zero or standard error not finite)")
        if anchor is None or anchor[0] >= t:
            return ParameterProgress(name, float(pe), target, False, converged, math.nan,
                                     NO_HISTORY)
        elapsed, before = t - anchor[0], float(anchor[1][i])
        left = time_left(float(pe), target, float(info), before, elapsed)
        if math.isfinite(left):
            reason = ""
        elif math.isfinite(info - before) and info > before:
            reason = f"the target is too far below the percent error to forecast ({pe:.3g} % against {target:g} %)"
        else:
            reason = f"information not growing over the last {elapsed:.1f} s"
        return ParameterProgress(name, float(pe), target, False, converged, left, reason)

    def verdict(self) -> Verdict:
        """The maneuver's verdict at the newest sample (module docstring)."""
        return judge(self.progress)


def judge(progress: Sequence[ParameterProgress]) -> Verdict:
    """The verdict over the parameters of ``progress`` that have a target (module docstring)."""
    judged = [p for p in progress if not math.isnan(p.target)]
    if not judged:
        return Verdict(NEEDS_MORE, math.nan, "no parameter has a target")
    if all(p.met and p.converged for p in judged):
        return Verdict(DONE)
    stuck = [p for p in judged if not p.met and not math.isfinite(p.time_left) and p.reason != NO_HISTORY]
    if stuck:
        p = stuck[0]
        return Verdict(NOT_IDENTIFIABLE, math.nan, f"{p.name} at {p.percent_error:.1f} % > {p.target:g} %: {p.reason}")
    short = [p for p in judged if not p.met]
    if short:  # (NaN time left: no history yet, the slowest unknown)
        slowest = max(short, key=lambda p: p.time_left if math.isfinite(p.time_left) else math.inf)
        return Verdict(NEEDS_MORE, slowest.time_left,
                       f"{slowest.name} at {slowest.percent_error:.1f} %, target {slowest.target:g} %")
    waiting = ", ".join(p.name for p in judged if not p.converged)
    return Verdict(NEEDS_MORE, math.nan, f"targets met, not converged yet: {waiting}")


def targets_of(values: Mapping[str, float]) -> TargetOptions:
    """:class:`TargetOptions` of a ``{name: percent}`` mapping (the default window)."""
    return TargetOptions(targets=",".join(f"{k}={float(v)!r}" for k, v in values.items()))
