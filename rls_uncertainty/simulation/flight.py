"""A simulated flight-test day: trim legs in turbulence and repeated T-2 maneuvers at several
flight conditions, as one continuous set of sensor streams.

The card: at each flight condition (:data:`CONDITIONS`, the same altitude at three airspeeds),
``repeats`` test points ``TP-01a``, ``TP-01b``, ... are flown, each the Table 2 elevator
multisine (10 s of input, Section IV.A), each after a trim leg of 10 to 30 s (uniform, whole
tenths of a second, drawn from the seed) with the elevator held at trim; a last trim leg ends
the flight. The Dryden vertical gust (:mod:`.turbulence`) blows throughout, trim legs and
maneuvers alike; it moves the aircraft, not the surfaces.

Each condition is one continuous simulation of Eq. 25 (:func:`.t2.fine_response`, the gust one
more input) at its airspeed and dynamic pressure; the conditions follow one another without a
transition (the state restarts at trim at the first sample of a condition, which is in a trim
leg). The streams are those of :func:`.t2.simulate_sensor_streams` (same topics, rates and
noise model); the sensor noise keeps the scale of the nominal maneuver at condition A (the
paper's), since it belongs to the sensors.

**True values.** The nondimensional derivatives are Table 3's at every condition
(:data:`.t2.T2_TRUE`): the model is quasi-steady and linear, and the simulation holds them
constant over this speed range (no Mach or aeroelastic effect), so a repeat at another
condition estimates the same derivatives. The dimensional dynamics change with the condition:
the short-period frequency and damping grow with the dynamic pressure. The trim is the same at
every condition (4.8 deg angle of attack, the elevator at 0, level flight), so the intercepts
change with the dynamic pressure:

    CZ_0 = -m g cos(alpha_0) / (qbar S) - CZ_alpha alpha_0 - CZ_delta_e delta_e0
    Cm_0 = -Cm_alpha alpha_0 - Cm_delta_e delta_e0

(the coefficients of Eq. 1c and 1e at trim, level flight: the regressors are the absolute
angles). Seeded and deterministic.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import signal

from ..aero.models import AircraftConfig
from ..errors import ConfigError
from ..settings.models import load_aircraft
from .multisine import T2_TABLE2, Multisine
from .t2 import (
    BAND_LIMITED_ON,
    FT,
    G0,
    T2_MODELS,
    FineResponse,
    SensorStreams,
    SimulationConfig,
    fine_response,
    gust_input,
    sensor_streams,
    state_space,
)
from .turbulence import LOW_ALTITUDE_SIGMA_W, DrydenVertical, scale_length

__all__ = ["FlightCondition", "CONDITIONS", "TRIM_LEG", "FlownManeuver", "Flight", "PARAMETERS", "true_values",
           "simulate_flight"]

TRIM_LEG = (10.0, 30.0)  # s, the shortest and longest trim leg
# After its input a maneuver's slot holds this much more trim before the next trim leg begins
# (the T-2 record: 0.5 s before the input and 1.5 s after it, 12 s in all).
_SETTLE = 2.0
PARAMETERS = tuple(p for m in T2_MODELS for p in m.parameter_names)


@dataclass(frozen=True)
class FlightCondition:
    """A flight condition of the card: its ``name`` and true ``airspeed`` (m/s); the altitude
    and trim are :class:`.t2.SimulationConfig`'s."""

    name: str
    airspeed: float

    def config(self, duration: float) -> SimulationConfig:
        return replace(SimulationConfig(), airspeed=self.airspeed, duration=duration)


CONDITIONS = (
    FlightCondition("A", 134.0 * FT),  # the paper's
    FlightCondition("B", 160.0 * FT),
    FlightCondition("C", 115.0 * FT),
)


@dataclass(frozen=True)
class FlownManeuver:
    """One maneuver flown: test point ``name``, ``condition``, ``start`` and ``end`` of its
    input (s from the flight's start) and the ``true`` value of each parameter."""

    name: str
    condition: str
    start: float
    end: float
    true: dict[str, float]


@dataclass(frozen=True)
class Flight:
    """The flight's sensor streams, its maneuvers in the order flown and its ``duration`` (s)."""

    streams: SensorStreams
    maneuvers: tuple[FlownManeuver, ...]
    duration: float


def true_values(cfg: SimulationConfig, aircraft: AircraftConfig) -> dict[str, float]:
    """The true value of each of :data:`PARAMETERS` at ``cfg``'s condition (module docstring)."""
    t = cfg.true
    a0, d0 = cfg.alpha_trim, cfg.delta_e_trim
    cz0 = -aircraft.mass * G0 * np.cos(a0) / (cfg.qbar * aircraft.S) - t["CZ_alpha"] * a0 - t["CZ_delta_e"] * d0
    values = {"CZ_0": float(cz0), "Cm_0": float(-t["Cm_alpha"] * a0 - t["Cm_delta_e"] * d0),
              **{k: float(v) for k, v in t.items()}}
    return {p: values[p] for p in PARAMETERS}


def _lsim(system: tuple[np.ndarray, ...], u: np.ndarray, dt: float) -> np.ndarray:
    """The outputs of the continuous ``system`` (A, B, C, D, one input) driven by ``u`` on a
    grid of step ``dt``, the input linear between samples and the state at rest at first:
    :func:`scipy.signal.lsim`'s response, through the exact first-order-hold discretization
    and :func:`scipy.signal.lfilter` (fast on long records). (The discrete state starts at
    zero, so a record whose input does not start at zero begins with a short transient that
    :func:`~scipy.signal.lsim` has not: the gust's, in a trim leg.)"""
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete(system, dt, method="foh")
    num, den = signal.ss2tf(Ad, Bd, Cd, Dd)
    return np.column_stack([signal.lfilter(row, den, u) for row in num])


def _response(cfg: SimulationConfig, ac: AircraftConfig, elevator: Multisine, starts: Sequence[float],
              gust: np.ndarray | None) -> FineResponse:
    """:func:`.t2.fine_response` over a long record with the multisine flown from each of
    ``starts``."""
    n_fine = int(round(cfg.duration * cfg.fine_rate))
    t = np.arange(n_fine) / cfg.fine_rate
    u = np.zeros(n_fine)
    for start in starts:
        on = slice(int(round(start * cfg.fine_rate)), int(round((start + elevator.period) * cfg.fine_rate)) + 1)
        u[on] = elevator(t[on] - start)
    dt = 1.0 / cfg.fine_rate
    y = _lsim(state_space(cfg, ac), u, dt)
    if gust is None:
        return FineResponse(t, u, y, None, None)
    A, _, C, _ = state_space(cfg, ac)
    Bg, Dg = gust_input(cfg, ac)
    return FineResponse(t, u, y, gust, _lsim((A, Bg, C, Dg), gust / cfg.airspeed, dt))


def _legs(rng: np.random.Generator, n: int) -> list[float]:
    """``n`` trim legs (s), uniform in :data:`TRIM_LEG`, whole tenths of a second."""
    low, high = (round(x * 10) for x in TRIM_LEG)
    return [int(k) / 10.0 for k in rng.integers(low, high + 1, size=n)]


def _concatenate(parts: Sequence[SensorStreams], start_ns: int) -> SensorStreams:
    def joined(kind: str) -> tuple[np.ndarray, np.ndarray]:
        stamps = np.concatenate([getattr(p, kind)[0] for p in parts])
        if np.any(np.diff(stamps) <= 0):
            raise AssertionError(f"{kind}: the conditions' stamps overlap")  # (a bug, not an input)
        return stamps, np.concatenate([getattr(p, kind)[1] for p in parts])

    kinds = ("imu", "airspeed", "dynamic_pressure", "control_surfaces", "thrust")
    return SensorStreams(start_ns, **{k: joined(k) for k in kinds})  # type: ignore[arg-type]


def simulate_flight(
    seed: int = 2010,
    *,
    conditions: Sequence[FlightCondition] = CONDITIONS,
    repeats: int = 4,
    gust_sigma: float = LOW_ALTITUDE_SIGMA_W["light"],
    band_level: float = 0.2,
    band_limited_on: Collection[str] = BAND_LIMITED_ON,
    start_ns: int = 1_767_225_600 * 10**9,
) -> Flight:
    """The flight of the module docstring: ``repeats`` maneuvers at each of ``conditions``, the
    gust at ``gust_sigma`` (m/s RMS, 0: calm air; default light turbulence), the noise of
    :func:`.t2.add_noise` (``band_level``, ``band_limited_on``). From ``SeedSequence(seed)``: the
    trim legs, then per condition its noise and its gust, each its own stream."""
    if not (type(repeats) is int and repeats >= 1) or not conditions:
        raise ConfigError(f"a flight needs conditions and repeats >= 1, got {len(conditions)} and {repeats!r}")
    root = np.random.SeedSequence(seed)
    legs_ss, *condition_ss = root.spawn(1 + len(conditions))
    legs = _legs(np.random.default_rng(legs_ss), repeats * len(conditions) + 1)
    ac = load_aircraft("t2")
    elevator = T2_TABLE2["elevator"]
    nominal = fine_response(SimulationConfig(), ac, elevator, None)  # the sensors' noise scale
    parts, maneuvers, t0 = [], [], 0.0
    for c, (condition, ss) in enumerate(zip(conditions, condition_ss, strict=True)):
        mine = legs[c * repeats:(c + 1) * repeats]
        starts, clock = [], 0.0
        for leg in mine:
            starts.append(round(clock + leg, 3))
            clock += leg + elevator.period + _SETTLE
        if c == len(conditions) - 1:
            clock += legs[-1]
        cfg = condition.config(round(clock, 3))
        noise_ss, gust_ss = ss.spawn(2)
        gust = DrydenVertical(gust_sigma, scale_length(cfg.altitude))
        n_fine = int(round(cfg.duration * cfg.fine_rate))
        w = gust.sample(n_fine, cfg.airspeed, 1.0 / cfg.fine_rate, np.random.default_rng(gust_ss))
        response = _response(cfg, ac, elevator, starts, w if gust_sigma > 0 else None)
        parts.append(sensor_streams(response, nominal, cfg, ac, np.random.default_rng(noise_ss),
                                    band_level=band_level, band_limited_on=band_limited_on,
                                    start_ns=start_ns + round(t0 * 1e9)))
        truth = true_values(cfg, ac)
        for k, s in enumerate(starts):
            name = f"TP-{c + 1:02d}{chr(ord('a') + k)}"
            maneuvers.append(FlownManeuver(name, condition.name, round(t0 + s, 3),
                                           round(t0 + s + elevator.period, 3), dict(truth)))
        t0 = round(t0 + cfg.duration, 3)
    return Flight(_concatenate(parts, start_ns), tuple(maneuvers), t0)
