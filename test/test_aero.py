"""Eq. 1 coefficients, Eq. 2 regressors, frames and the flight state of a sample."""

import math

import numpy as np
import pytest

from rls_uncertainty.aero.coefficients import (
    SAMPLE_FIELDS,
    FlightState,
    aircraft_sample,
    coefficients,
    flight_state,
    physics_rejection,
    regressor_matrix,
    regressors,
    rep103_to_aircraft,
)
from rls_uncertainty.datapath.limits import PlausibilityLimits
from rls_uncertainty.errors import Refused
from rls_uncertainty.settings import DEFAULT_MODELS, load_aircraft

T2 = load_aircraft("t2")


def state(**kw):
    base = dict(ax=0.5, ay=-0.2, az=-9.7, p=0.1, q=-0.05, r=0.02, p_dot=0.3, q_dot=-0.4, r_dot=0.1,
                V=40.0, alpha=0.08, beta=0.01, qbar=980.0, delta_e=-0.02, delta_a=0.01, delta_r=0.005, thrust=20.0)
    base.update(kw)
    return FlightState(**base)


def test_eq1_against_rigid_body_moment_equations():
    """Rebuild the aerodynamic moments from Euler's equations with the inertia tensor
    (aircraft axes, Ixz product) and compare with the coefficients of Eq. 1d-f."""
    s = state()
    c = coefficients(s, T2)
    inertia = np.array([[T2.Ixx, 0, -T2.Ixz], [0, T2.Iyy, 0], [-T2.Ixz, 0, T2.Izz]])
    w = np.array([s.p, s.q, s.r])
    wd = np.array([s.p_dot, s.q_dot, s.r_dot])
    M = inertia @ wd + np.cross(w, inertia @ w)  # L, M, N
    qS = s.qbar * T2.S
    assert c["Cl"] == pytest.approx(M[0] / (qS * T2.b), rel=1e-12)
    assert c["Cm"] == pytest.approx(M[1] / (qS * T2.cbar), rel=1e-12)
    assert c["Cn"] == pytest.approx(M[2] / (qS * T2.b), rel=1e-12)
    assert c["CX"] == pytest.approx((T2.mass * s.ax - s.thrust) / qS)
    assert c["CZ"] == pytest.approx(T2.mass * s.az / qS)


def test_regressors_and_default_models_of_eq2():
    s = state()
    values = regressors(s, T2)
    assert values["q_hat"] == pytest.approx(s.q * T2.cbar / (2 * s.V))
    assert values["p_hat"] == pytest.approx(s.p * T2.b / (2 * s.V))
    sizes = [len(m.regressors) for m in DEFAULT_MODELS]
    assert sizes == [3, 4, 3, 6, 4, 4]
    cm = DEFAULT_MODELS[4]
    assert cm.parameter_names == ("Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e")
    np.testing.assert_allclose(regressor_matrix(cm, values), [1.0, s.alpha, values["q_hat"], s.delta_e])


def test_rep103_to_aircraft_axes():
    # Level flight: the IMU's specific force is +g on REP-103 z (up), -g on aircraft z (down);
    # a nose-up pitch rate is -wy in REP-103 (y left) and +q in aircraft axes.
    np.testing.assert_allclose(rep103_to_aircraft([0.1, 0.2, 9.81]), [0.1, -0.2, -9.81])
    np.testing.assert_allclose(rep103_to_aircraft(np.array([[0.0, -0.05, 0.0]])), [[0.0, 0.05, 0.0]])


@pytest.mark.parametrize("kw, reason", [
    (dict(qbar=0.0), "nonpositive_dynamic_pressure"),
    (dict(qbar=-5.0), "nonpositive_dynamic_pressure"),
    (dict(V=0.0), "nonpositive_airspeed"),
    (dict(alpha=np.nan), "non_finite_alpha"),
    (dict(q_dot=np.inf), "non_finite_q_dot"),
])
def test_bad_physics_input_is_a_rejection_reason(kw, reason):
    assert physics_rejection(state(**kw)) == reason
    assert physics_rejection(state()) is None


def test_a_rep103_sample_becomes_aircraft_axes_and_a_flight_state():
    """Level flight, nose up 0.1 rad/s, air from the right and from below: independent of the
    conversion code, REP-103 y (left) and z (up) flip sign in aircraft axes."""
    imu = (0.01, -0.1, 0.02, 0.3, 0.2, 9.8)  # wx wy wz (rad/s), fx fy fz (m/s^2), REP-103
    velocity = (40.0, -2.0, -3.0)  # REP-103: u, v to the left, w up
    sample = aircraft_sample(imu, velocity, 950.0, (0.01, -0.02, 0.03), 120.0)
    expected = dict(ax=0.3, ay=-0.2, az=-9.8, p=0.01, q=0.1, r=-0.02, u=40.0, v=2.0, w=3.0, qbar=950.0,
                    delta_e=0.01, delta_a=-0.02, delta_r=0.03, thrust=120.0)
    assert dict(zip(SAMPLE_FIELDS, sample, strict=True)) == expected
    s = flight_state(sample, np.array([0.5, -0.6, 0.7]), air_density=1.225)
    V = math.sqrt(40.0**2 + 2.0**2 + 3.0**2)
    assert s.V == pytest.approx(V, rel=1e-15)
    assert s.alpha == pytest.approx(math.atan(3.0 / 40.0), rel=1e-14)  # w down: nose above the flow
    assert s.beta == pytest.approx(math.asin(2.0 / V), rel=1e-14)  # v right: air from the right
    assert (s.q, s.q_dot, s.qbar, s.delta_a, s.thrust) == (0.1, -0.6, 950.0, -0.02, 120.0)
    # Without a measured dynamic pressure (NaN) it is rho V^2 / 2.
    s = flight_state(aircraft_sample(imu, velocity), np.zeros(3), air_density=1.1)
    assert s.qbar == pytest.approx(0.5 * 1.1 * V * V, rel=1e-15)
    assert (s.delta_e, s.delta_a, s.delta_r, s.thrust) == (0.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("velocity, qbar, reason", [
    ((0.0, 0.0, 0.0), 900.0, "nonpositive_airspeed"),
    ((40.0, 0.0, 0.0), 0.0, "nonpositive_dynamic_pressure"),
    ((40.0, 0.0, 0.0), math.inf, "non_finite_qbar"),
])
def test_a_sample_that_cannot_be_reduced_gives_its_reason(velocity, qbar, reason):
    sample = aircraft_sample((0.0,) * 6, velocity, qbar)
    assert flight_state(sample, np.zeros(3), 1.225) == Refused(reason)


# ----------------------------------------------------------------------------- plausibility
LIMITS = PlausibilityLimits()


def test_flight_state_judges_derived_quantities_with_the_limits():
    """qbar = rho V^2 / 2 from a thin-air density is below the minimum although every message
    was plausible; without limits the same sample reduces (the caller decides)."""
    imu = (0.0, -0.1, 0.0, 0.3, 0.0, 9.8)
    sample = aircraft_sample(imu, (25.0, 0.0, -1.0))
    assert flight_state(sample, np.zeros(3), 0.01, LIMITS) == Refused("implausible_dynamic_pressure")  # 3.1 Pa
    assert isinstance(flight_state(sample, np.zeros(3), 0.01), FlightState)
    assert isinstance(flight_state(sample, np.zeros(3), 1.225, LIMITS), FlightState)  # 383 Pa
    # Non-finite is reported as such before any limit.
    infinite_qbar = aircraft_sample(imu, (25.0, 0.0, -1.0), math.inf)
    assert flight_state(infinite_qbar, np.zeros(3), 1.2, LIMITS) == Refused("non_finite_qbar")
    # Interpolated air data: each message within |alpha| <= 1 rad, half way between them too,
    # but a low speed made of two just-plausible ones is not (V = 3 cos 0.9 = 1.9 m/s).
    a = 0.9
    mid = aircraft_sample(imu, (3.0 * math.cos(a), 0.0, 0.0))
    assert LIMITS.airspeed_rejection((3.0 * math.cos(a), 0.0, 3.0 * math.sin(a))) is None
    assert flight_state(mid, np.zeros(3), 1.225, LIMITS) == Refused("implausible_airspeed")


def test_a_measured_dynamic_pressure_is_judged_against_the_airspeed_a_computed_one_is_not():
    """At 25 m/s: 9.4 Pa measured implies 0.03 kg/m^3, below limits.air_density_min (0.05):
    inconsistent; the same 9.4 Pa computed from inputs.air_density = 0.03 is what the user
    said the air is, and is used. 383 Pa measured (1.225 kg/m^3) is consistent."""
    imu = (0.0, -0.1, 0.0, 0.3, 0.0, 9.8)
    velocity = (25.0, 0.0, 0.0)
    qbar = 0.5 * 0.03 * 25.0**2
    assert flight_state(aircraft_sample(imu, velocity, qbar), np.zeros(3), 1.225, LIMITS) == \
        Refused("inconsistent_dynamic_pressure")
    computed = flight_state(aircraft_sample(imu, velocity), np.zeros(3), 0.03, LIMITS)
    assert isinstance(computed, FlightState) and computed.qbar == pytest.approx(qbar, rel=1e-15)
    assert isinstance(flight_state(aircraft_sample(imu, velocity, 383.0), np.zeros(3), 0.03, LIMITS), FlightState)
