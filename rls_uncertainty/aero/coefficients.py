"""Aerodynamic data reduction: Eq. 1 coefficients and Eq. 2 regressors. numpy only.

Inside this module everything is in aircraft body axes (x forward, y right, z down) and SI.
ROS interfaces use the REP-103 body frame (x forward, y left, z up); the conversion happens
in one place, :func:`rep103_to_aircraft`, which :func:`aircraft_sample` applies to the
interpolated measurements of one sample. :func:`flight_state` derives airspeed, flow angles
and dynamic pressure from such a sample and judges it (:func:`physics_rejection`, and the
``limits.*`` parameters of :class:`.limits.PlausibilityLimits`); :func:`coefficients` and
:func:`regressors` reduce it. The control-surface mixing of Eq. 23 is in :mod:`.surface_mixing`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

from ..errors import Refused

if TYPE_CHECKING:  # annotations only: this module imports numpy alone
    from .models import AircraftConfig, ModelConfig

__all__ = [
    "FloatArray",
    "Signal",
    "rep103_to_aircraft",
    "SAMPLE_FIELDS",
    "RATES",
    "aircraft_sample",
    "flight_state",
    "FlightState",
    "coefficients",
    "regressors",
    "regressor_matrix",
    "physics_rejection",
]

FloatArray = NDArray[np.float64]
# A quantity of one sample (a float, the per-sample path) or of many (an array, batch reduction).
Signal = float | FloatArray


def rep103_to_aircraft(vec: Sequence[float] | FloatArray) -> tuple[float, float, float] | FloatArray:
    """REP-103 body frame (x fwd, y left, z up) to aircraft body axes (x fwd, y right, z down).

    A rotation of pi about x: ``(x, y, z) -> (x, -y, -z)``. Applies to vectors (specific
    force, angular rate, airspeed) given as ``(..., 3)`` arrays; one vector given as a tuple
    or list of three numbers (the per-sample path) comes back as a tuple of floats.
    """
    if (type(vec) is tuple or type(vec) is list) and len(vec) == 3:
        x, y, z = vec
        return (float(x), -float(y), -float(z))
    v = np.asarray(vec, dtype=np.float64)
    out: FloatArray = v * np.array([1.0, -1.0, -1.0])
    return out


@dataclass
class FlightState:
    """Measured motion of one sample (or arrays of samples), aircraft body axes, SI.

    ``ax, ay, az``: specific force (m/s^2, about -9.81 on z in level flight);
    ``p, q, r``: body rates (rad/s); ``p_dot, q_dot, r_dot``: angular accelerations (rad/s^2);
    ``V`` true airspeed (m/s); ``alpha, beta`` (rad); ``qbar`` dynamic pressure (Pa);
    ``delta_e, delta_a, delta_r`` (rad, Eq. 23 conventions); ``thrust`` along body x (N).
    """

    ax: Signal
    ay: Signal
    az: Signal
    p: Signal
    q: Signal
    r: Signal
    p_dot: Signal
    q_dot: Signal
    r_dot: Signal
    V: Signal
    alpha: Signal
    beta: Signal
    qbar: Signal
    delta_e: Signal = 0.0
    delta_a: Signal = 0.0
    delta_r: Signal = 0.0
    thrust: Signal = 0.0


# One measured sample, aircraft body axes: specific force (m/s^2), rates (rad/s), air-relative
# velocity (m/s), dynamic pressure (Pa; NaN when it is computed from the air density), the
# Eq. 23 deflections (rad) and thrust (N).
SAMPLE_FIELDS = ("ax", "ay", "az", "p", "q", "r", "u", "v", "w", "qbar", "delta_e", "delta_a", "delta_r", "thrust")
_U, _W, _QBAR, _DE = 6, 8, 9, 10
RATES = slice(3, 6)  # p, q, r: the signals the differentiator turns into p_dot, q_dot, r_dot
_NO_SURFACES = (0.0, 0.0, 0.0)


def aircraft_sample(imu: Sequence[float], velocity: Sequence[float], qbar: float = math.nan,
                    surfaces: Sequence[float] = _NO_SURFACES, thrust: float = 0.0) -> list[float]:
    """The :data:`SAMPLE_FIELDS` vector of one sample from REP-103 measurements: ``imu`` is
    ``(wx, wy, wz, fx, fy, fz)`` (rates, then specific force), ``velocity`` the air-relative
    velocity; ``qbar`` NaN means "compute it from the air density" (:func:`flight_state`)."""
    return [
        *rep103_to_aircraft(imu[3:]),
        *rep103_to_aircraft(imu[:3]),
        *rep103_to_aircraft(velocity),
        qbar,
        *surfaces,
        thrust,
    ]


class SampleLimits(Protocol):
    """What judges a reduced sample's plausibility (the data path's ``limits.*`` parameters,
    :class:`rls_uncertainty.datapath.limits.PlausibilityLimits`)."""

    def sample_rejection(self, state: FlightState, qbar_measured: bool = False) -> str | None: ...


def flight_state(sample: Sequence[float], rate_dot: FloatArray, air_density: float,
                 limits: SampleLimits | None = None) -> FlightState | Refused:
    """A :data:`SAMPLE_FIELDS` vector and its angular accelerations as a :class:`FlightState`
    (``V``, ``alpha = atan2(w, u)``, ``beta = asin(v / V)``; ``qbar = rho V^2 / 2`` when not
    measured), or :class:`.errors.Refused` with the reason it cannot be reduced
    (:func:`physics_rejection`) or is not plausible
    (:meth:`.limits.PlausibilityLimits.sample_rejection`, when ``limits`` are given; a measured
    dynamic pressure is also checked against ``V``)."""
    u, v, w = sample[_U:_W + 1]
    V = math.sqrt(u * u + v * v + w * w)
    if not V > 0.0:
        return Refused("nonpositive_airspeed")
    qbar = sample[_QBAR]
    measured = not math.isnan(qbar)
    if not measured:
        qbar = 0.5 * air_density * V * V
    ax, ay, az, p, q, r = sample[:6]
    de, da, dr, thrust = sample[_DE:]
    p_dot, q_dot, r_dot = rate_dot.tolist()
    state = FlightState(
        ax=ax, ay=ay, az=az, p=p, q=q, r=r, p_dot=p_dot, q_dot=q_dot, r_dot=r_dot,
        V=V, alpha=math.atan2(w, u), beta=math.asin(max(-1.0, min(1.0, v / V))), qbar=float(qbar),
        delta_e=de, delta_a=da, delta_r=dr, thrust=thrust,
    )
    reason = physics_rejection(state)
    if reason is None and limits is not None:
        reason = limits.sample_rejection(state, measured)
    return state if reason is None else Refused(reason)


def physics_rejection(state: FlightState) -> str | None:
    """Reason a (scalar) sample cannot be reduced, or ``None``: non-finite values, or zero or
    negative dynamic pressure or airspeed (Eq. 1 and the rate normalisations divide by them)."""
    values = vars(state)
    try:  # the per-sample path: plain floats, one check when all are finite
        all_finite = math.isfinite(sum(values.values()))
    except (TypeError, ValueError):
        all_finite = False
    if not all_finite:
        for name, value in values.items():
            if not np.all(np.isfinite(value)):
                return f"non_finite_{name}"
    qbar, V = state.qbar, state.V
    if not (qbar > 0 if isinstance(qbar, float) else np.all(np.asarray(qbar) > 0)):
        return "nonpositive_dynamic_pressure"
    if not (V > 0 if isinstance(V, float) else np.all(np.asarray(V) > 0)):
        return "nonpositive_airspeed"
    return None


def coefficients(s: FlightState, ac: AircraftConfig) -> dict[str, Signal]:
    """Body-axis force and moment coefficients, Eq. 1a-f."""
    qS = s.qbar * ac.S if isinstance(s.qbar, float) else np.asarray(s.qbar, dtype=float) * ac.S
    return {
        "CX": (ac.mass * s.ax - s.thrust) / qS,  # Eq. 1a
        "CY": ac.mass * s.ay / qS,  # Eq. 1b
        "CZ": ac.mass * s.az / qS,  # Eq. 1c
        "Cl": (ac.Ixx * s.p_dot - ac.Ixz * (s.r_dot + s.p * s.q) + (ac.Izz - ac.Iyy) * s.q * s.r)
        / (qS * ac.b),  # Eq. 1d
        "Cm": (ac.Iyy * s.q_dot + (ac.Ixx - ac.Izz) * s.p * s.r + ac.Ixz * (s.p**2 - s.r**2))
        / (qS * ac.cbar),  # Eq. 1e
        "Cn": (ac.Izz * s.r_dot - ac.Ixz * (s.p_dot - s.q * s.r) + (ac.Iyy - ac.Ixx) * s.p * s.q)
        / (qS * ac.b),  # Eq. 1f
    }


def regressors(s: FlightState, ac: AircraftConfig) -> dict[str, Signal]:
    """Every regressor of Eq. 2 by name: bias, flow angles, controls and the nondimensional
    rates ``p b/2V``, ``q cbar/2V``, ``r b/2V``. Absolute angles are used; the bias terms
    absorb the trim values (Eq. 2's perturbations differ from them by constants)."""
    V2: Signal
    one: Signal
    if isinstance(s.V, float):  # one sample
        V2, one = 2.0 * s.V, 1.0
    else:
        V2 = 2.0 * np.asarray(s.V, dtype=float)
        one = np.ones_like(V2)
    return {
        "1": one,
        "alpha": s.alpha * one,
        "beta": s.beta * one,
        "delta_e": s.delta_e * one,
        "delta_a": s.delta_a * one,
        "delta_r": s.delta_r * one,
        "p_hat": s.p * ac.b / V2,
        "q_hat": s.q * ac.cbar / V2,
        "r_hat": s.r * ac.b / V2,
    }


def regressor_matrix(model: ModelConfig, values: Mapping[str, Signal]) -> FloatArray:
    """Columns of ``model.regressors`` stacked: ``(N, n)`` for arrays, ``(n,)`` for a sample."""
    return np.stack([np.asarray(values[r], dtype=float) for r in model.regressors], axis=-1)
