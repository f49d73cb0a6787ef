"""Where a maneuver starts and ends: detected from the control surfaces, or read from events.

**Detected** (:class:`ManeuverDetector`). A maneuver is a stretch of deliberate input: the
control surfaces move in the estimated band well above what they do in trim. Per message of
the surface positions (rad, any number of surfaces):

1. each surface is low-passed at ``f_max`` (a first-order filter, exact for uneven stamps:
   ``y += (1 - exp(-2 pi f_max dt)) (x - y)``), which drops the sensor noise above the band;
2. the *input power* ``P`` is the variance of the low-passed positions over the last
   ``window`` seconds, summed over the surfaces (rad^2): the window's mean removes the trim
   and everything slower than about ``1 / window``;
3. the *noise floor* ``F`` is the geometric mean of ``P`` over about ``floor_span`` seconds of
   trim (an exponential average of ``ln P``, updated only while no maneuver is flown and ``P``
   is below ``threshold F``), never below ``min_rms^2``; it is first set from the first full
   window, so a recording is taken to begin in trim;
4. a maneuver **starts** when ``P > threshold F`` has held for ``rise`` seconds: the start is
   declared then, stamped at the first message above (the crossing);
5. it **ends** when ``P <= threshold F`` has held for ``hold`` seconds: declared then, stamped
   at the first quiet message minus ``window`` (the power stays above the threshold until the
   last input leaves the window, so the input stopped about one window earlier), never before
   the start.

At the defaults (``threshold`` 10, i.e. 10 dB, ``window`` 2 s, ``rise`` 0.3 s, ``hold`` 1 s)
on the simulated flight (``make-bag --flight``, docs/maneuvers.md) every maneuver is found,
its start and end within 0.3 s of the input's when the elevator's trim floor is its wide-band
sensor noise, within 1.2 s when band-limited noise 16 dB below the maneuver's power is on the
elevator too, and no trim leg in gusts gives a maneuver: the gusts move the aircraft, not the
surfaces. A pilot's trim corrections in the band would count as input; raise
``threshold`` when the trim floor is not sensor noise.

Garbage is counted, never raised: a message with a NaN or infinite position (``non_finite``),
a stamp not after the previous one (``out_of_order``) or another number of surfaces than the
first message's (``shape``) is skipped and counted in :attr:`ManeuverDetector.rejected`.

**From events** (:func:`event_boundary`): a ``diagnostic_msgs/KeyValue`` on the event topic,
``key`` the test-point name (``TP-02a``) and ``value`` ``start`` or ``stop``, is the same
:class:`Boundary`; anything else is refused with the reason (:class:`.errors.Refused`).

Numpy only; no ROS.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import Refused
from ..schema import check, option

__all__ = ["Boundary", "ManeuverOptions", "ManeuverDetector", "event_boundary", "refusal_text", "KINDS",
           "EVENT_TOPIC", "EVENT_TYPE", "EVENT_VALUES", "EVENT_REASONS", "MAX_NAME"]

KINDS = ("start", "end")
EVENT_TOPIC = "test_point"  # the event topic a simulated flight records (relative, as the input topics)
EVENT_TYPE = "diagnostic_msgs/msg/KeyValue"
# The event topic's values and the boundary each one is.
EVENT_VALUES = {"start": "start", "stop": "end"}
# Why an event is refused, by the reason it is counted under.
EVENT_REASONS = {
    "event_type": "key and value must be text",
    "event_key": "the key must be a test-point name of 1 to 64 printable characters",
    "event_value": "the value must be start or stop",
}
MAX_NAME = 64  # characters of a test-point name
_RESUM = 4096  # messages between exact sums of the window


@dataclass(frozen=True)
class Boundary:
    """A maneuver's start or end: ``kind`` (``"start"`` or ``"end"``), ``stamp_ns`` (the time it
    happened, ns, on the stamps' clock) and ``name`` (the test point, or ``m001``, ``m002``, ...
    for a detected maneuver; a start and its end carry the same name)."""

    kind: str
    stamp_ns: int
    name: str


@dataclass(frozen=True)
class ManeuverOptions:
    """The detection rule's settings (module docstring)."""

    f_max: float = option(1.5, "maneuver detection: the surfaces are low-passed at the band's upper edge before "
                          "their power is measured", unit="Hz", low=0.0, low_open=True, high=1000.0,
                          ros="maneuvers.f_max")
    window: float = option(2.0, "maneuver detection: seconds over which the input power (variance of the "
                           "low-passed surfaces) is measured", unit="s", low=0.1, high=60.0, ros="maneuvers.window")
    threshold: float = option(10.0, "maneuver detection: input power over its trim noise floor that is a maneuver "
                              "(10 = 10 dB)", low=1.0, low_open=True, high=1e6, ros="maneuvers.threshold")
    rise: float = option(0.3, "maneuver detection: seconds the power must stay above the threshold before a start "
                         "is declared (stamped at the crossing)", unit="s", low=0.0, high=60.0, ros="maneuvers.rise")
    hold: float = option(1.0, "maneuver detection: seconds the power must stay back below the threshold before an "
                         "end is declared", unit="s", low=0.0, high=600.0, ros="maneuvers.hold")
    floor_span: float = option(20.0, "maneuver detection: seconds of trim the noise floor averages over",
                               unit="s", low=0.1, high=3600.0, ros="maneuvers.floor_span")
    min_rms: float = option(1e-5, "maneuver detection: the noise floor's least RMS (a noiseless recording)",
                            unit="rad", low=0.0, low_open=True, high=1.0, ros="maneuvers.min_rms")

    def __post_init__(self) -> None:
        check(self, "maneuvers")


class _Window:
    """The low-passed positions of the last ``span_ns`` and their running sums (about
    ``reference``, exact again every :data:`_RESUM` messages), for the variance."""

    def __init__(self, first: npt.NDArray[np.float64], span_ns: int) -> None:
        self.filtered = first.copy()
        self.span_ns = span_ns
        self.reference = first.copy()
        self.stamps: deque[int] = deque()
        self.values: deque[npt.NDArray[np.float64]] = deque()
        self.sum = np.zeros_like(first)
        self.sum2 = np.zeros_like(first)
        self._added = 0

    def add(self, stamp_ns: int) -> None:
        v = self.filtered - self.reference
        self.stamps.append(stamp_ns)
        self.values.append(v)
        self.sum += v
        self.sum2 += v * v
        while self.stamps[0] < stamp_ns - self.span_ns:
            self.stamps.popleft()
            old = self.values.popleft()
            self.sum -= old
            self.sum2 -= old * old
        self._added += 1
        if self._added % _RESUM == 0:  # rounding of the running sums stays bounded
            held = np.array(self.values) + self.reference
            self.reference = held.mean(axis=0)
            self.values = deque(held - self.reference)
            self.sum = np.sum(self.values, axis=0)
            self.sum2 = np.sum(np.square(self.values), axis=0)

    def variance(self) -> float:
        """The summed variance of the held positions (rad^2)."""
        n = len(self.values)
        return float(np.maximum(self.sum2 / n - (self.sum / n) ** 2, 0.0).sum())


class ManeuverDetector:
    """The detection rule of the module docstring over a stream of surface positions.

    ``update(stamp_ns, positions)`` takes one message and returns the boundaries it declares
    (none, one, or an end and a start); ``finish(stamp_ns)`` ends a maneuver still flown when
    the data stop. :attr:`rejected` counts skipped messages by reason; :attr:`power` and
    :attr:`floor` are the last input power and noise floor (rad^2, NaN before the first full
    window)."""

    def __init__(self, options: ManeuverOptions = ManeuverOptions()) -> None:
        if not isinstance(options, ManeuverOptions):
            raise TypeError(f"options must be ManeuverOptions, got {type(options).__name__}")
        self.options = options
        self.rejected: dict[str, int] = {"non_finite": 0, "out_of_order": 0, "shape": 0}
        self.power = math.nan
        self.floor = math.nan
        self.count = 0  # maneuvers started
        self._surfaces: _Window | None = None
        self._first_ns: int | None = None
        self._last_ns: int | None = None
        self._log_floor = math.nan
        self._active: str | None = None  # the name of the maneuver flown
        self._since: int | None = None  # first message of the present crossing (above, or back below)
        self._started = 0  # the stamp of the maneuver's start

    @property
    def active(self) -> str | None:
        """The name of the maneuver being flown, or None in trim."""
        return self._active

    def _accept(self, stamp_ns: int, positions: Sequence[float] | npt.ArrayLike) -> npt.NDArray[np.float64] | None:
        x = np.asarray(positions, dtype=np.float64).reshape(-1)
        if x.size == 0 or (self._surfaces is not None and x.size != self._surfaces.filtered.size):
            self.rejected["shape"] += 1
            return None
        if not np.isfinite(x).all():
            self.rejected["non_finite"] += 1
            return None
        if self._last_ns is not None and stamp_ns <= self._last_ns:
            self.rejected["out_of_order"] += 1
            return None
        return x

    def _measure(self, stamp_ns: int, x: npt.NDArray[np.float64]) -> bool:
        """Filter, window and measure ``P``; False until the window is first full."""
        o = self.options
        if self._surfaces is None:
            self._surfaces = _Window(x, round(o.window * 1e9))
            self._first_ns = stamp_ns
        else:
            assert self._last_ns is not None
            dt = (stamp_ns - self._last_ns) * 1e-9
            self._surfaces.filtered += -math.expm1(-2.0 * math.pi * o.f_max * dt) * (x - self._surfaces.filtered)
        self._last_ns = stamp_ns
        w = self._surfaces
        w.add(stamp_ns)
        assert self._first_ns is not None
        if stamp_ns - self._first_ns < w.span_ns or len(w.values) < 2:
            return False
        self.power = w.variance()
        return True

    def _track_floor(self, stamp_ns: int, dt: float) -> None:
        o = self.options
        least = math.log(o.min_rms**2)
        log_p = math.log(max(self.power, o.min_rms**2))
        if math.isnan(self._log_floor):
            self._log_floor = log_p
        elif self._active is None and log_p <= self._log_floor + math.log(o.threshold):
            self._log_floor += -math.expm1(-dt / o.floor_span) * (log_p - self._log_floor)
        self._log_floor = max(self._log_floor, least)
        self.floor = math.exp(self._log_floor)

    def update(self, stamp_ns: int, positions: Sequence[float] | npt.ArrayLike) -> list[Boundary]:
        """One message of surface positions (rad) stamped ``stamp_ns``: the boundaries it declares."""
        stamp_ns = int(stamp_ns)
        x = self._accept(stamp_ns, positions)
        if x is None:
            return []
        last = self._last_ns
        if not self._measure(stamp_ns, x):
            return []
        self._track_floor(stamp_ns, 0.0 if last is None else (stamp_ns - last) * 1e-9)
        o = self.options
        above = self.power > o.threshold * self.floor
        if above == (self._active is not None):  # nothing is changing
            self._since = None
            return []
        if self._since is None:
            self._since = stamp_ns
        if self._active is None:
            if stamp_ns - self._since < round(o.rise * 1e9):
                return []
            self.count += 1
            self._active = f"m{self.count:03d}"
            self._started, self._since = self._since, None
            return [Boundary("start", self._started, self._active)]
        if stamp_ns - self._since < round(o.hold * 1e9):
            return []
        return [self._end(self._since)]

    def _end(self, quiet_ns: int) -> Boundary:
        assert self._active is not None
        end = Boundary("end", max(quiet_ns - round(self.options.window * 1e9), self._started), self._active)
        self._active, self._since = None, None
        return end

    def finish(self, stamp_ns: int) -> list[Boundary]:
        """The data stop at ``stamp_ns``: the end of a maneuver still flown (stamped at the
        quiet stretch's beginning, as :meth:`update` would, or at ``stamp_ns``), else nothing."""
        if self._active is None:
            return []
        if self._since is not None:
            return [self._end(self._since)]
        end = Boundary("end", max(int(stamp_ns), self._started), self._active)
        self._active = None
        return [end]


def event_boundary(stamp_ns: int, key: object, value: object) -> Boundary | Refused:
    """A ``diagnostic_msgs/KeyValue`` event (``key`` the test-point name, ``value`` ``start``
    or ``stop``, case and surrounding blanks ignored) received at ``stamp_ns`` as a
    :class:`Boundary`, or :class:`.errors.Refused` whose reason is a key of
    :data:`EVENT_REASONS` (:func:`refusal_text` says it with the event)."""
    if not isinstance(key, str) or not isinstance(value, str):
        return Refused("event_type")
    name = key.strip()
    if not name or len(name) > MAX_NAME or not name.isprintable():
        return Refused("event_key")
    kind = EVENT_VALUES.get(value.strip().lower())
    if kind is None:
        return Refused("event_value")
    return Boundary(kind, int(stamp_ns), name)


def refusal_text(refused: Refused, key: object, value: object) -> str:
    """One line: why the event ``(key, value)`` was refused, showing it (cut)."""
    shown = [repr(x)[:MAX_NAME] for x in (key, value)]
    return f"event key={shown[0]} value={shown[1]} refused: {EVENT_REASONS.get(refused.reason, refused.reason)}"
