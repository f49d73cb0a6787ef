"""What a measurement of an aircraft in flight can be: the ``limits.*`` parameters.

:class:`PlausibilityLimits` bounds each measured quantity. Its ``*_rejection`` methods judge
one input message (the pipeline calls them before a message reaches the sampler) and
:meth:`PlausibilityLimits.sample_rejection` one formed sample, which also covers what only a
sample has: the flow angles of interpolated air data and ``rho V^2 / 2`` when the dynamic
pressure is not measured. A value out of bounds is rejected as ``implausible_<quantity>``
instead of reaching Eqs. 1 and 2; :meth:`PlausibilityLimits.bound` and :func:`message_value` /
:func:`sample_value` say, for a misconfiguration report, which parameter bounds the quantity
and what value was seen. Pure Python.

Two checks compare streams or messages rather than one value with its bound, because each
value can be plausible on its own while the data are not:

* **the air density implied by the measured dynamic pressure and the true airspeed**,
  ``2 qbar / V^2``, must lie in ``[air_density_min, air_density_max]`` (a sample outside is
  ``inconsistent_dynamic_pressure``): a dynamic pressure of 5 Pa at 40 m/s implies 0.006
  kg/m^3, the air at 37 km. It catches a dynamic pressure in another unit (hPa, kPa, psi for
  Pa), a blocked or disconnected pitot, a stream that does not belong with the airspeed. (It
  cannot tell an equivalent airspeed from the true one: both agree with sea-level density.
  Without a dynamic-pressure stream, ``qbar = rho V^2 / 2`` agrees by construction.)
* **the angular acceleration implied by two consecutive IMU messages**, each body rate's
  change over their interval, must stay within ``angular_acceleration``
  (:meth:`PlausibilityLimits.rate_change_rejection`, called by :class:`.intake.Intake`; a
  message beyond it is ``implausible_angular_acceleration``): a gyro spike of 19.999 rad/s
  passes ``angular_rate`` but implies 1000 rad/s^2 for one 50 Hz interval, which no airframe
  can do. The check is on the messages, before the differentiator: a spike refused there
  leaves a hole (no sample is interpolated across it), where a bound on the differentiated
  rates would miss the spike's own sample (the centred differentiator's middle weight is 0)
  and reject only its neighbours, after the spike had entered the regression.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from ..errors import ConfigError
from ..schema import check, option, settings

__all__ = ["PlausibilityLimits", "BOUNDS", "message_value", "sample_value"]

# The quantity a reason's bound is on, where it is not the reason's own ``implausible_<quantity>``.
_QUANTITY = {"inconsistent_dynamic_pressure": "air_density"}


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

    ``air_density_min``/``_max`` (kg/m^3) bound the density ``2 qbar / V^2`` that a measured
    dynamic pressure and the true airspeed imply. 0.05 lies below the air at 21 km (0.07 at
    70,000 ft, ISA), the ceiling of the highest-flying subsonic aircraft (U-2, ER-2; transports
    and business jets stop near 15.5 km, 0.18); 2.0 lies above the densest air at any airfield
    (-60 C at 1085 hPa: 1.77) with room for a pitot's impact pressure read as the dynamic
    pressure (up to 9 % more at Mach 0.6). A sensor's calibration error is well inside;
    a unit or a stream that does not belong is not.

    ``angular_acceleration`` (rad/s^2) bounds each body rate's change between consecutive IMU
    messages divided by their interval. 500 is about 10 times what a subscale research model
    reaches with full controls (the NASA T-2 at 45 m/s: 20 rad/s^2 in pitch with
    ``C_m_delta_e`` = -1.83, about 45 in roll; transports reach a few) and leaves room for
    gyro noise at 1 kHz (the change of two samples of 0.005 rad/s noise: 7 rad/s^2 rms); it
    refuses any jump above 10 rad/s between 50 Hz messages, above 2.5 rad/s at 200 Hz.
    """

    airspeed_min: float = option(
        3.0, "lowest plausible true airspeed (flow angles and p b/2V are noise below it); rejected as "
        "implausible_airspeed",
        unit="m/s", low=0.1, high=100.0, ros="limits.airspeed_min")
    airspeed_max: float = option(
        400.0, "highest plausible true airspeed (supersonic at any altitude); rejected as implausible_airspeed",
        unit="m/s", low=1.0, high=3000.0, ros="limits.airspeed_max")
    alpha: float = option(
        1.0, "largest plausible angle of attack, either sign (57 deg; flying backwards is near 3.14); rejected as "
        "implausible_alpha",
        unit="rad", low=0.05, high=1.5, ros="limits.alpha")
    beta: float = option(
        0.6, "largest plausible sideslip angle, either sign (34 deg); rejected as implausible_beta",
        unit="rad", low=0.05, high=1.5, ros="limits.beta")
    angular_rate: float = option(
        20.0, "largest plausible body rate about any axis (1150 deg/s); rejected as implausible_angular_rate",
        unit="rad/s", low=0.1, high=100.0, ros="limits.angular_rate")
    specific_force: float = option(
        200.0, "largest plausible specific force along any axis (20 g); rejected as implausible_specific_force",
        unit="m/s^2", low=1.0, high=2000.0, ros="limits.specific_force")
    surface: float = option(
        1.0, "largest plausible deflection of a mixed control-surface joint, either sign (57 deg); rejected as "
        "implausible_surface",
        unit="rad", low=0.01, high=1.5, ros="limits.surface")
    dynamic_pressure_min: float = option(
        5.0, "lowest plausible dynamic pressure (3 m/s at sea level; Eq. 1 divides by it); rejected as "
        "implausible_dynamic_pressure",
        unit="Pa", low=0.01, high=10000.0, ros="limits.dynamic_pressure_min")
    dynamic_pressure_max: float = option(
        1.0e5, "highest plausible dynamic pressure (400 m/s at sea level); rejected as implausible_dynamic_pressure",
        unit="Pa", low=1.0, high=1.0e7, ros="limits.dynamic_pressure_max")
    thrust: float = option(
        2.0e6, "largest plausible thrust, either sign (reverse thrust; above the largest aircraft's total thrust); "
        "rejected as implausible_thrust",
        unit="N", low=1.0, high=1.0e8, ros="limits.thrust")
    air_density_min: float = option(
        0.05, "lowest plausible air density 2 qbar/V^2 implied by the measured dynamic pressure and the true "
        "airspeed (the air at 21 km is 0.07); a sample below is rejected as inconsistent_dynamic_pressure",
        unit="kg/m^3", low=0.005, high=10.0, ros="limits.air_density_min")
    air_density_max: float = option(
        2.0, "highest plausible air density 2 qbar/V^2 implied by the measured dynamic pressure and the true "
        "airspeed (-60 C at 1085 hPa is 1.77); a sample above is rejected as inconsistent_dynamic_pressure",
        unit="kg/m^3", low=0.01, high=100.0, ros="limits.air_density_max")
    angular_acceleration: float = option(
        500.0, "largest plausible change of a body rate between consecutive imu messages over their interval (a "
        "gyro spike of 10 rad/s in one 50 Hz message is 500); rejected as implausible_angular_acceleration",
        unit="rad/s^2", low=1.0, high=1.0e6, ros="limits.angular_acceleration")

    def __post_init__(self) -> None:
        check(self, "limits")
        for name in ("airspeed", "dynamic_pressure", "air_density"):
            low, high = getattr(self, f"{name}_min"), getattr(self, f"{name}_max")
            if not low < high:
                raise ConfigError(f"limits.{name}_min ({low!r}) must be below limits.{name}_max ({high!r})",
                                  parameter=f"limits.{name}_min")

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

    def rate_change_rejection(self, dt_s: float, change: Sequence[float]) -> str | None:
        """Two consecutive IMU messages ``dt_s`` seconds apart whose body rates differ by
        ``change`` (rad/s, per axis): ``implausible_angular_acceleration`` when a change
        exceeds ``angular_acceleration * dt_s``. (The rates themselves were judged finite and
        within ``angular_rate`` first.)"""
        a = self.angular_acceleration * dt_s
        for d in change:
            if not -a <= d <= a:
                return "implausible_angular_acceleration"
        return None

    def surface_rejection(self, positions: Sequence[float]) -> str | None:
        """The control-surface joints a deflection is mixed from (rad)."""
        s = self.surface
        for x in positions:
            if not -s <= x <= s:
                return "non_finite" if not _all_finite(positions) else "implausible_surface"
        return None

    def sample_rejection(self, state: Any, qbar_measured: bool = False) -> str | None:
        """Reason one formed sample (a scalar :class:`.aero.FlightState` whose values are all
        finite) is implausible, ``implausible_<field>``, or ``None``. Messages were judged one
        by one already; this also covers what only a sample has: flow angles and airspeed of
        interpolated air data, ``rho V^2 / 2`` when the dynamic pressure is not measured, and
        when it is (``qbar_measured``), its agreement with the airspeed:
        ``inconsistent_dynamic_pressure`` when ``2 qbar / V^2`` is not a plausible air density."""
        s = state
        if not self.airspeed_min <= s.V <= self.airspeed_max:
            return "implausible_airspeed"
        if not abs(s.alpha) <= self.alpha:
            return "implausible_alpha"
        if not abs(s.beta) <= self.beta:
            return "implausible_beta"
        if not self.dynamic_pressure_min <= s.qbar <= self.dynamic_pressure_max:
            return "implausible_dynamic_pressure"
        if qbar_measured and not self.air_density_min * s.V * s.V <= 2.0 * s.qbar <= self.air_density_max * s.V * s.V:
            return "inconsistent_dynamic_pressure"
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
        quantity = _QUANTITY.get(reason, reason.removeprefix("implausible_"))
        if len(names) == 1:
            return f"limits.{names[0]}", f"|{quantity}| <= {getattr(self, names[0]):g} {unit}"
        low, high = (getattr(self, n) for n in names)
        side = names[1] if seen > high else names[0] if seen < low else f"{names[0]}/{names[1].rsplit('_', 1)[1]}"
        return f"limits.{side}", f"{low:g} <= {quantity} <= {high:g} {unit}"


# implausible_<quantity> -> (the limits.* fields that bound it, their unit). A bound given as one
# field is symmetric (|x| <= limit); as two, a range (min <= x <= max).
_BOUNDED_BY = {
    "implausible_airspeed": ("airspeed_min", "airspeed_max"),
    "implausible_alpha": ("alpha",),
    "implausible_beta": ("beta",),
    "implausible_angular_rate": ("angular_rate",),
    "implausible_specific_force": ("specific_force",),
    "implausible_surface": ("surface",),
    "implausible_dynamic_pressure": ("dynamic_pressure_min", "dynamic_pressure_max"),
    "implausible_thrust": ("thrust",),
    "implausible_angular_acceleration": ("angular_acceleration",),
    "inconsistent_dynamic_pressure": ("air_density_min", "air_density_max"),
}
_UNITS = {f.name: s.unit for f, s in settings(PlausibilityLimits)}
BOUNDS: dict[str, tuple[tuple[str, ...], str]] = {r: (names, _UNITS[names[0]]) for r, names in _BOUNDED_BY.items()}


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
    largest magnitude for a per-axis bound; of ``implausible_angular_acceleration`` the values
    are ``(dt_s, dwx, dwy, dwz)`` (:meth:`PlausibilityLimits.rate_change_rejection`'s). NaN when
    the reason is not a bound's."""
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
    if reason == "implausible_angular_acceleration" and len(values) == 4:
        return _largest(values[1:]) / values[0] if values[0] > 0 else math.nan
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
        "inconsistent_dynamic_pressure": lambda: 2.0 * s.qbar / (s.V * s.V),
    }
    get = quantities.get(reason)
    return float(get()) if get is not None else math.nan
