"""What a measurement of an aircraft in flight can be: the ``limits.*`` parameters.

:class:`PlausibilityLimits` bounds each measured quantity. Its ``*_rejection`` methods judge
one input message (the pipeline calls them before a message reaches the sampler) and
:meth:`PlausibilityLimits.sample_rejection` one formed sample, which also covers what only a
sample has: the flow angles of interpolated air data and ``rho V^2 / 2`` when the dynamic
pressure is not measured. A value out of bounds is rejected as ``implausible_<quantity>``
instead of reaching Eqs. 1 and 2; :meth:`PlausibilityLimits.bound` and :func:`message_value` /
:func:`sample_value` say, for a misconfiguration report, which parameter bounds the quantity
and what value was seen. Pure Python.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, fields
from typing import Any

from .errors import ConfigError

__all__ = ["PlausibilityLimits", "BOUNDS", "message_value", "sample_value"]

# implausible_<quantity> -> (the limits.* fields that bound it, unit). A bound given as one
# field is symmetric (|x| <= limit); as two, a range (min <= x <= max).
BOUNDS: dict[str, tuple[tuple[str, ...], str]] = {
    "implausible_airspeed": (("airspeed_min", "airspeed_max"), "m/s"),
    "implausible_alpha": (("alpha",), "rad"),
    "implausible_beta": (("beta",), "rad"),
    "implausible_angular_rate": (("angular_rate",), "rad/s"),
    "implausible_specific_force": (("specific_force",), "m/s^2"),
    "implausible_surface": (("surface",), "rad"),
    "implausible_dynamic_pressure": (("dynamic_pressure_min", "dynamic_pressure_max"), "Pa"),
    "implausible_thrust": (("thrust",), "N"),
}


@dataclass(frozen=True)
class PlausibilityLimits:
    """What no aircraft this package targets (fixed-wing, subsonic: subscale research models
    to transports) can measure in flight, SI; the ``limits.*`` parameters. Each default lies
    well beyond any such aircraft yet many orders of magnitude below the overflow of Eqs. 1, 2
    and the estimator, so an absurd value (a flipped bit, a wrong unit, a crafted message) is
    rejected with the reason ``implausible_<field>`` instead of reaching the regression.

    ``airspeed_min``/``airspeed_max`` bound the true airspeed ``V`` (m/s); ``alpha`` and
    ``beta`` bound ``|alpha|`` and ``|beta|`` (rad, below pi/2: ``|alpha|`` near pi is flying
    backwards); ``angular_rate`` (rad/s) and ``specific_force`` (m/s^2) bound each IMU axis;
    ``surface`` bounds each mixed control-surface joint and deflection (rad);
    ``dynamic_pressure_min``/``_max`` bound the dynamic pressure (Pa, measured or
    ``rho V^2 / 2``); ``thrust`` bounds ``|thrust|`` (N, reverse thrust is negative).
    """

    airspeed_min: float = 3.0
    airspeed_max: float = 400.0
    alpha: float = 1.0
    beta: float = 0.6
    angular_rate: float = 20.0
    specific_force: float = 200.0
    surface: float = 1.0
    dynamic_pressure_min: float = 5.0
    dynamic_pressure_max: float = 1.0e5
    thrust: float = 2.0e6

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise ConfigError(f"limits.{f.name} must be a positive number, got {value!r}")
        for name in ("alpha", "beta"):
            if getattr(self, name) >= 0.5 * math.pi:
                raise ConfigError(f"limits.{name} must be below pi/2 rad, got {getattr(self, name)!r}")
        for name in ("airspeed", "dynamic_pressure"):
            low, high = getattr(self, f"{name}_min"), getattr(self, f"{name}_max")
            if not low < high:
                raise ConfigError(f"limits.{name}_min ({low!r}) must be below limits.{name}_max ({high!r})")

    # One message each. ``non_finite`` when a value is NaN or infinite (checked first, as the
    # sampler does), else ``implausible_<field>`` for the first value out of its bounds, else
    # None. Written as chained comparisons, which NaN fails: the usual case costs one test.
    def imu_rejection(self, angular_velocity: Sequence[float], specific_force: Sequence[float]) -> str | None:
        """A ``sensor_msgs/Imu``: each body rate (rad/s) and specific force (m/s^2) component."""
        w, f = self.angular_rate, self.specific_force
        wx, wy, wz = angular_velocity
        fx, fy, fz = specific_force
        if -w <= wx <= w and -w <= wy <= w and -w <= wz <= w and -f <= fx <= f and -f <= fy <= f and -f <= fz <= f:
            return None
        if not _all_finite((wx, wy, wz, fx, fy, fz)):
            return "non_finite"
        return "implausible_angular_rate" if not (-w <= wx <= w and -w <= wy <= w and -w <= wz <= w) \
            else "implausible_specific_force"

    def airspeed_rejection(self, velocity: Sequence[float]) -> str | None:
        """A true-airspeed vector (REP-103, m/s): its magnitude and flow angles."""
        vx, vy, vz = velocity
        if not _all_finite((vx, vy, vz)):
            return "non_finite"
        V, alpha, beta = _air_data(vx, vy, vz)
        if not self.airspeed_min <= V <= self.airspeed_max:
            return "implausible_airspeed"
        if not abs(alpha) <= self.alpha:
            return "implausible_alpha"
        if not abs(beta) <= self.beta:
            return "implausible_beta"
        return None

    def dynamic_pressure_rejection(self, pascal: float) -> str | None:
        if self.dynamic_pressure_min <= pascal <= self.dynamic_pressure_max:
            return None
        return "non_finite" if not math.isfinite(pascal) else "implausible_dynamic_pressure"

    def thrust_rejection(self, newton: float) -> str | None:
        if -self.thrust <= newton <= self.thrust:
            return None
        return "non_finite" if not math.isfinite(newton) else "implausible_thrust"

    def surface_rejection(self, positions: Sequence[float]) -> str | None:
        """The control-surface joints a deflection is mixed from (rad)."""
        s = self.surface
        for x in positions:
            if not -s <= x <= s:
                return "non_finite" if not _all_finite(positions) else "implausible_surface"
        return None

    def sample_rejection(self, state: Any) -> str | None:
        """Reason one formed sample (a scalar :class:`.aero.FlightState` whose values are all
        finite) is implausible, ``implausible_<field>``, or ``None``. Messages were judged one
        by one already; this also covers what only a sample has: flow angles and airspeed of
        interpolated air data, and ``rho V^2 / 2`` when the dynamic pressure is not measured."""
        s = state
        if not self.airspeed_min <= s.V <= self.airspeed_max:
            return "implausible_airspeed"
        if not abs(s.alpha) <= self.alpha:
            return "implausible_alpha"
        if not abs(s.beta) <= self.beta:
            return "implausible_beta"
        if not self.dynamic_pressure_min <= s.qbar <= self.dynamic_pressure_max:
            return "implausible_dynamic_pressure"
        if not max(abs(s.p), abs(s.q), abs(s.r)) <= self.angular_rate:
            return "implausible_angular_rate"
        if not max(abs(s.ax), abs(s.ay), abs(s.az)) <= self.specific_force:
            return "implausible_specific_force"
        if not max(abs(s.delta_e), abs(s.delta_a), abs(s.delta_r)) <= self.surface:
            return "implausible_surface"
        if not abs(s.thrust) <= self.thrust:
            return "implausible_thrust"
        return None

    def bound(self, reason: str, seen: float = math.nan) -> tuple[str, str]:
        """``(parameter, bound)`` of an ``implausible_<quantity>`` reason, e.g.
        ``("limits.alpha", "|alpha| <= 1 rad")``; of a range, the side that ``seen`` is beyond
        (``limits.airspeed_max`` for a value above it; both when unknown). ``("", "")`` for any
        other reason."""
        if reason not in BOUNDS:
            return "", ""
        names, unit = BOUNDS[reason]
        quantity = reason.removeprefix("implausible_")
        if len(names) == 1:
            return f"limits.{names[0]}", f"|{quantity}| <= {getattr(self, names[0]):g} {unit}"
        low, high = (getattr(self, n) for n in names)
        side = names[1] if seen > high else names[0] if seen < low else f"{names[0]}/{names[1].rsplit('_', 1)[1]}"
        return f"limits.{side}", f"{low:g} <= {quantity} <= {high:g} {unit}"


def _all_finite(values: Iterable[float]) -> bool:
    return all(math.isfinite(x) for x in values)


def _air_data(vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """``(V, alpha, beta)`` of a REP-103 airspeed vector (aircraft axes ``u, v, w = vx, -vy,
    -vz``, as :func:`.aero.rep103_to_aircraft`); ``hypot`` cannot overflow (1e200 stays 1e200)."""
    u, v, w = vx, -vy, -vz
    V = math.hypot(u, v, w)
    return V, math.atan2(w, u), math.asin(max(-1.0, min(1.0, v / V))) if V > 0 else 0.0


def _largest(values: Iterable[float]) -> float:
    return max((abs(x) for x in values), default=math.nan)


def message_value(reason: str, values: Sequence[float]) -> float:
    """The value of an ``implausible_<quantity>`` message that its bound refused: the
    message's values as the pipeline judged them (IMU ``(wx, wy, wz, fx, fy, fz)``, the
    airspeed vector, the dynamic pressure, the thrust, or the mixed joints' positions); the
    largest magnitude for a per-axis bound. NaN when the reason is not a bound's."""
    if reason in ("implausible_airspeed", "implausible_alpha", "implausible_beta") and len(values) == 3:
        V, alpha, beta = _air_data(*values)
        return {"implausible_airspeed": V, "implausible_alpha": alpha, "implausible_beta": beta}[reason]
    if reason == "implausible_angular_rate":
        return _largest(values[:3])
    if reason == "implausible_specific_force":
        return _largest(values[3:6])
    if reason == "implausible_surface":
        return _largest(values)
    if reason in ("implausible_dynamic_pressure", "implausible_thrust") and values:
        return values[0]
    return math.nan


def sample_value(reason: str, state: Any) -> float:
    """The value of an ``implausible_<quantity>`` sample (a scalar :class:`.aero.FlightState`)
    that its bound refused; the largest magnitude for a per-axis bound. NaN for other reasons."""
    s = state
    quantities = {
        "implausible_airspeed": lambda: s.V,
        "implausible_alpha": lambda: s.alpha,
        "implausible_beta": lambda: s.beta,
        "implausible_dynamic_pressure": lambda: s.qbar,
        "implausible_angular_rate": lambda: _largest((s.p, s.q, s.r)),
        "implausible_specific_force": lambda: _largest((s.ax, s.ay, s.az)),
        "implausible_surface": lambda: _largest((s.delta_e, s.delta_a, s.delta_r)),
        "implausible_thrust": lambda: s.thrust,
    }
    get = quantities.get(reason)
    return float(get()) if get is not None else math.nan
