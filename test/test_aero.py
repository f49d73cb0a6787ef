"""Eq. 1 coefficients, Eq. 2 regressors, frames, the flight state of a sample and the Eq. 23
surface mixing."""

import math

import numpy as np
import pytest

from rls_uncertainty.aero import (
    SAMPLE_FIELDS,
    FlightState,
    PlausibilityLimits,
    aircraft_sample,
    coefficients,
    flight_state,
    physics_rejection,
    plausibility_rejection,
    regressor_matrix,
    regressors,
    rep103_to_aircraft,
)
from rls_uncertainty.config import DEFAULT_MODELS, load_aircraft
from rls_uncertainty.surface_mixing import JointLayout, SurfaceMixer, SurfaceMixing

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
    assert flight_state(sample, np.zeros(3), 1.225) == reason


def test_aileron_mixing_is_eq_23():
    mixer = SurfaceMixer(SurfaceMixing(aileron_right=("ar1", "ar2"), aileron_left=("al",), rudder=("r1", "r2")))
    names = ["ar1", "ar2", "al", "r1", "r2", "elevator"]
    de, da, dr = mixer.layout(names).deflections([0.1, 0.3, -0.2, 0.01, 0.03, 0.0])
    assert da == pytest.approx(0.5 * (0.2 - (-0.2)))  # (mean right - mean left) / 2
    assert dr == pytest.approx(0.02)
    # The joint order may change from message to message: the mixing follows the names.
    reordered = ["elevator", "r2", "r1", "al", "ar2", "ar1"]
    assert mixer.layout(reordered).deflections([0.0, 0.03, 0.01, -0.2, 0.3, 0.1]) == (de, da, dr)
    assert mixer.layout(names).deflections([0.1, 0.5, -0.2, 0.01, 0.03, 0.0])[1] == pytest.approx(0.5 * (0.3 - (-0.2)))
    combined = SurfaceMixer(SurfaceMixing(aileron_combined="ail"))
    assert combined.layout(["ail", "rudder", "elevator"]).deflections([0.07, 0.0, 0.0])[1] == 0.07
    # Only one aileron side configured: no aileron deflection is formed (and none required).
    one_side = SurfaceMixer(SurfaceMixing(aileron_left=()))
    assert one_side.layout(["aileron_right", "rudder", "elevator"]).deflections([0.07, 0.0, 0.01])[1] == 0.0
    assert one_side.layout(["rudder", "elevator"]).deflections([0.0, 0.01]) == (0.01, 0.0, 0.0)


def test_elevator_and_rudder_are_averages_and_other_joints_are_reported():
    mixing = SurfaceMixing(elevator=("el", "er"), rudder=("ru", "rl"))
    names = ("flap", "el", "aileron_left", "er", "ru", "aileron_right", "rl", "gear")
    layout = mixing.layout(names)
    assert isinstance(layout, JointLayout)
    assert layout.unknown == ("flap", "gear")
    positions = [9.0, 0.02, -0.1, 0.04, 0.3, 0.1, 0.1, 9.0]
    assert layout.deflections(positions) == pytest.approx((0.03, 0.1, 0.2), rel=1e-15)


def test_joint_lists_that_cannot_be_mixed_give_their_reason():
    mixing = SurfaceMixing()
    assert mixing.layout(("elevator", "rudder", "aileron_left")) == "missing_joint"
    assert mixing.layout(("elevator", "rudder", "aileron_left", "aileron_right", "rudder")) == "mismatched_arrays"
    # A deflection that no model needs may be unmapped: nothing is missing then.
    assert isinstance(SurfaceMixing(rudder=()).layout(("elevator", "aileron_left", "aileron_right")), JointLayout)


def test_the_mixer_follows_name_lists_that_change_or_are_reused():
    mixer = SurfaceMixer(SurfaceMixing())
    names = ["elevator", "aileron_left", "aileron_right", "rudder"]
    assert mixer.layout(names).deflections([0.1, 0.2, 0.4, 0.3]) == (0.1, pytest.approx(0.1), 0.3)
    names.reverse()  # the caller reuses its list object with other contents
    assert mixer.layout(names).deflections([0.3, 0.4, 0.2, 0.1]) == (0.1, pytest.approx(0.1), 0.3)
    for k in range(40):  # many different lists: the cache stays bounded and right
        extra = [f"j{k}", "rudder", "elevator", "aileron_right", "aileron_left"]
        assert mixer.layout(extra).deflections([5.0, 0.3, 0.1, 0.4, 0.2]) == (0.1, pytest.approx(0.1), 0.3)
        assert mixer.layout(extra).unknown == (f"j{k}",)
    assert len(mixer._layouts) <= SurfaceMixer._CACHE_SIZE


# ----------------------------------------------------------------------------- plausibility
LIMITS = PlausibilityLimits()  # 3..400 m/s, |alpha| 1, |beta| 0.6 rad, 20 rad/s, 200 m/s^2, 1 rad, 5..1e5 Pa, 2 MN
TINY = 5e-324  # the smallest subnormal


@pytest.mark.parametrize("gyro, accel, reason", [
    ((0.1, -0.2, 0.05), (0.5, 0.0, 9.8), None),
    ((20.0, -20.0, 0.0), (200.0, -200.0, 0.0), None),  # the bounds themselves are plausible
    ((0.0, 1e100, 0.0), (0.0, 0.0, 9.8), "implausible_angular_rate"),  # issue 12: a gyro of 1e100 rad/s
    ((0.0, 20.000001, 0.0), (0.0, 0.0, 9.8), "implausible_angular_rate"),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 1e150), "implausible_specific_force"),  # issue 12: 1e150 m/s^2
    ((0.0, 0.0, 0.0), (-1.7e308, 0.0, 9.8), "implausible_specific_force"),  # near the largest double
    ((1e100, 0.0, 0.0), (1e150, 0.0, 0.0), "implausible_angular_rate"),  # the rate is named first
    ((math.nan, 0.0, 0.0), (0.0, 0.0, 9.8), "non_finite"),
    ((1e100, 0.0, 0.0), (0.0, -math.inf, 9.8), "non_finite"),  # non-finite before implausible
    ((-0.0, TINY, -TINY), (0.0, 0.0, 9.8), None),
])
def test_imu_messages_beyond_the_limits_are_implausible(gyro, accel, reason):
    assert LIMITS.imu_rejection(gyro, accel) == reason


@pytest.mark.parametrize("velocity, reason", [
    ((40.0, 0.0, -3.0), None),  # REP-103: w = 3 m/s down in aircraft axes, alpha 0.075 rad
    ((-40.0, 0.0, 0.0), "implausible_alpha"),  # issue 12: "negative airspeed" is flying backwards
    ((-40.0, 0.0, -0.1), "implausible_alpha"),  # alpha = 179.9 deg
    ((0.0, 0.0, 0.0), "implausible_airspeed"),
    ((2.9, 0.0, 0.0), "implausible_airspeed"),
    ((400.1, 0.0, 0.0), "implausible_airspeed"),
    ((1e200, 1e200, 1e200), "implausible_airspeed"),  # |v| would overflow: still a clean reason
    ((30.0, 0.0, -30.0 * math.tan(1.01)), "implausible_alpha"),  # just beyond 1 rad
    ((30.0, 0.0, -30.0 * math.tan(0.99)), None),
    ((30.0, 30.0 * math.tan(0.61), 0.0), "implausible_beta"),  # sideslip 0.61 rad (v = -y: from the left)
    ((30.0, -30.0 * math.tan(0.59), 0.0), None),
    ((TINY, 0.0, 0.0), "implausible_airspeed"),
    ((40.0, math.nan, 0.0), "non_finite"),
])
def test_airspeed_messages_with_impossible_speed_or_flow_angles_are_implausible(velocity, reason):
    assert LIMITS.airspeed_rejection(velocity) == reason


@pytest.mark.parametrize("method, value, reason", [
    ("dynamic_pressure_rejection", 980.0, None),
    ("dynamic_pressure_rejection", 1e-300, "implausible_dynamic_pressure"),  # issue 12
    ("dynamic_pressure_rejection", TINY, "implausible_dynamic_pressure"),
    ("dynamic_pressure_rejection", -0.0, "implausible_dynamic_pressure"),
    ("dynamic_pressure_rejection", 4.99, "implausible_dynamic_pressure"),
    ("dynamic_pressure_rejection", 1.01e5, "implausible_dynamic_pressure"),
    ("dynamic_pressure_rejection", math.inf, "non_finite"),
    ("thrust_rejection", -3000.0, None),  # reverse thrust
    ("thrust_rejection", -0.0, None),
    ("thrust_rejection", 2.1e6, "implausible_thrust"),
    ("thrust_rejection", -1e150, "implausible_thrust"),
    ("thrust_rejection", math.nan, "non_finite"),
])
def test_scalar_messages_beyond_the_limits_are_implausible(method, value, reason):
    assert getattr(LIMITS, method)(value) == reason


@pytest.mark.parametrize("positions, reason", [
    ([0.1, -0.3, 0.0], None),
    ([1e150, 0.0], "implausible_surface"),  # issue 12: a deflection of 1e150
    ([1e150, -1e150], "implausible_surface"),  # whose Eq. 23 average would be a plausible 0
    ([0.0, -1.0000001], "implausible_surface"),
    ([math.nan, 1e150], "non_finite"),
    ([], None),
])
def test_control_surface_joints_beyond_the_limit_are_implausible(positions, reason):
    assert LIMITS.surface_rejection(positions) == reason


@pytest.mark.parametrize("kw, reason", [
    ({}, None),
    (dict(V=2.0), "implausible_airspeed"),
    (dict(V=401.0), "implausible_airspeed"),
    (dict(alpha=-1.1), "implausible_alpha"),
    (dict(alpha=math.pi - 0.01), "implausible_alpha"),
    (dict(beta=0.7), "implausible_beta"),
    (dict(qbar=1e-300), "implausible_dynamic_pressure"),
    (dict(qbar=2e5), "implausible_dynamic_pressure"),
    (dict(r=-21.0), "implausible_angular_rate"),
    (dict(ay=250.0), "implausible_specific_force"),
    (dict(delta_r=-1.2), "implausible_surface"),
    (dict(thrust=3e6), "implausible_thrust"),
    (dict(V=2.0, thrust=3e6), "implausible_airspeed"),  # the first problem is named
    (dict(p_dot=1e3), None),  # angular accelerations have no limit (derived, bounded by the rates)
])
def test_a_sample_beyond_the_limits_gives_its_reason(kw, reason):
    assert plausibility_rejection(state(**kw), LIMITS) == reason


def test_flight_state_judges_derived_quantities_with_the_limits():
    """qbar = rho V^2 / 2 from a thin-air density is below the minimum although every message
    was plausible; without limits the same sample reduces (the caller decides)."""
    imu = (0.0, -0.1, 0.0, 0.3, 0.0, 9.8)
    sample = aircraft_sample(imu, (25.0, 0.0, -1.0))
    assert flight_state(sample, np.zeros(3), 0.01, LIMITS) == "implausible_dynamic_pressure"  # 3.1 Pa
    assert isinstance(flight_state(sample, np.zeros(3), 0.01), FlightState)
    assert isinstance(flight_state(sample, np.zeros(3), 1.225, LIMITS), FlightState)  # 383 Pa
    # Non-finite is reported as such before any limit.
    infinite_qbar = aircraft_sample(imu, (25.0, 0.0, -1.0), math.inf)
    assert flight_state(infinite_qbar, np.zeros(3), 1.2, LIMITS) == "non_finite_qbar"
    # Interpolated air data: each message within |alpha| <= 1 rad, half way between them too,
    # but a low speed made of two just-plausible ones is not (V = 3 cos 0.9 = 1.9 m/s).
    a = 0.9
    mid = aircraft_sample(imu, (3.0 * math.cos(a), 0.0, 0.0))
    assert LIMITS.airspeed_rejection((3.0 * math.cos(a), 0.0, 3.0 * math.sin(a))) is None
    assert flight_state(mid, np.zeros(3), 1.225, LIMITS) == "implausible_airspeed"


def test_the_used_joints_are_the_mixed_ones():
    layout = SurfaceMixing(elevator=("el", "er"), rudder=("ru",)).layout(
        ("flap", "el", "aileron_left", "er", "ru", "aileron_right", "gear"))
    assert layout.used == (1, 2, 3, 4, 5)
    combined = SurfaceMixing(aileron_combined="ail").layout(("aileron_left", "ail", "rudder", "elevator"))
    assert combined.used == (1, 2, 3) and combined.unknown == ("aileron_left",)


def test_the_mixer_never_caches_long_name_lists():
    """A JointState with thousands of names is laid out (and its unknown joints listed) but
    not kept: the cache holds at most _CACHE_SIZE lists of at most _CACHE_MAX_NAMES names."""
    mixer = SurfaceMixer(SurfaceMixing())
    base = ["elevator", "aileron_left", "aileron_right", "rudder"]
    for k in range(40):
        names = base + [f"junk{k}_{i}" for i in range(5000)]
        layout = mixer.layout(names)
        assert layout.deflections([0.1, 0.2, 0.4, 0.3] + [0.0] * 5000) == (0.1, pytest.approx(0.1), 0.3)
        assert len(layout.unknown) == 5000
        assert mixer.layout(names) is layout  # the last list is still recognised
    assert all(len(key) <= SurfaceMixer._CACHE_MAX_NAMES for key in mixer._layouts)
    assert len(mixer._layouts) <= SurfaceMixer._CACHE_SIZE
