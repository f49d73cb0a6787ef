"""The ``limits.*`` parameters (rls_uncertainty.datapath.limits): each message and each sample beyond
them is refused with its reason, and a misconfiguration report can name the parameter that
bounds a quantity and the value seen."""

import math

import pytest

from rls_uncertainty.aero.coefficients import FlightState
from rls_uncertainty.datapath.limits import BOUNDS, PlausibilityLimits, message_value, sample_value
from rls_uncertainty.errors import ConfigError


def state(**kw):
    base = dict(ax=0.5, ay=-0.2, az=-9.7, p=0.1, q=-0.05, r=0.02, p_dot=0.3, q_dot=-0.4, r_dot=0.1,
                V=40.0, alpha=0.08, beta=0.01, qbar=980.0, delta_e=-0.02, delta_a=0.01, delta_r=0.005, thrust=20.0)
    base.update(kw)
    return FlightState(**base)


LIMITS = PlausibilityLimits()  # 3..400 m/s, |alpha| 1, |beta| 0.6 rad, 20 rad/s, 200 m/s^2, 1 rad, 5..1e5 Pa, 2 MN
TINY = 5e-324  # the smallest subnormal


@pytest.mark.parametrize("gyro, accel, reason", [
    ((0.1, -0.2, 0.05), (0.5, 0.0, 9.8), None),
    ((20.0, -20.0, 0.0), (200.0, -200.0, 0.0), None),  # the bounds themselves are plausible
    ((0.0, 1e100, 0.0), (0.0, 0.0, 9.8), "implausible_angular_rate"),  # a gyro of 1e100 rad/s
    ((0.0, 20.000001, 0.0), (0.0, 0.0, 9.8), "implausible_angular_rate"),
    ((0.0, 0.0, 0.0), (0.0, 0.0, 1e150), "implausible_specific_force"),  # 1e150 m/s^2
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
    ((-40.0, 0.0, 0.0), "implausible_alpha"),  # "negative airspeed" is flying backwards
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
    ("dynamic_pressure_rejection", 1e-300, "implausible_dynamic_pressure"),  # below the smallest normal double
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
    ([1e150, 0.0], "implausible_surface"),  # a deflection of 1e150
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
    (dict(p_dot=1e3), None),  # derived accelerations: the messages' rate changes are bounded (Intake)
    (dict(qbar=5.0), None),  # 0.006 kg/m^3 at 40 m/s, but qbar is not measured: rho V^2 / 2 agrees by construction
])
def test_a_sample_beyond_the_limits_gives_its_reason(kw, reason):
    assert LIMITS.sample_rejection(state(**kw)) == reason


@pytest.mark.parametrize("kw, reason", [
    ({}, None),  # 980 Pa at 40 m/s: 1.225 kg/m^3
    (dict(qbar=5.0), "inconsistent_dynamic_pressure"),  # 0.006 kg/m^3: the air at 37 km
    (dict(qbar=0.5 * 0.05 * 1600.0), None),  # the bounds themselves are consistent
    (dict(qbar=0.5 * 2.0 * 1600.0), None),
    (dict(qbar=0.5 * 0.0499 * 1600.0), "inconsistent_dynamic_pressure"),
    (dict(qbar=0.5 * 2.01 * 1600.0), "inconsistent_dynamic_pressure"),
    (dict(qbar=980.0 / 100.0), "inconsistent_dynamic_pressure"),  # hPa given for Pa
    (dict(qbar=4.0), "implausible_dynamic_pressure"),  # beyond its own bound: named first
])
def test_a_measured_dynamic_pressure_must_agree_with_the_airspeed(kw, reason):
    assert LIMITS.sample_rejection(state(**kw), qbar_measured=True) == reason


@pytest.mark.parametrize("dt, change, reason", [
    (0.02, (0.1, -0.2, 0.05), None),
    (0.02, (0.0, 10.0, 0.0), None),  # 500 rad/s^2: the bound itself is plausible
    (0.02, (0.0, 10.001, 0.0), "implausible_angular_acceleration"),
    (0.02, (0.0, 0.0, -19.999), "implausible_angular_acceleration"),  # a spike at 50 Hz: 1000 rad/s^2
    (0.005, (2.6, 0.0, 0.0), "implausible_angular_acceleration"),  # 520 rad/s^2 at 200 Hz
    (0.25, (0.0, 40.0, 0.0), None),  # from -20 to +20 rad/s over 0.25 s: 160 rad/s^2
])
def test_a_rate_change_between_imu_messages_beyond_the_limit_is_implausible(dt, change, reason):
    assert LIMITS.rate_change_rejection(dt, change) == reason


def test_the_density_range_and_the_angular_acceleration_are_checked_once_here():
    with pytest.raises(ConfigError, match=r"limits\.air_density_min"):
        PlausibilityLimits(air_density_min=2.5)
    with pytest.raises(ConfigError, match=r"limits\.angular_acceleration"):
        PlausibilityLimits(angular_acceleration=0.0)


@pytest.mark.parametrize("reason, parameter, bound", [
    ("implausible_alpha", "limits.alpha", "|alpha| <= 1 rad"),
    ("implausible_airspeed", "limits.airspeed_min/max", "3 <= airspeed <= 400 m/s"),
    ("implausible_dynamic_pressure", "limits.dynamic_pressure_min/max", "5 <= dynamic_pressure <= 100000 Pa"),
    ("implausible_thrust", "limits.thrust", "|thrust| <= 2e+06 N"),
    ("implausible_angular_acceleration", "limits.angular_acceleration", "|angular_acceleration| <= 500 rad/s^2"),
    ("inconsistent_dynamic_pressure", "limits.air_density_min/max", "0.05 <= air_density <= 2 kg/m^3"),
    ("missing_joint", "", ""),
])
def test_each_implausible_reason_names_the_parameter_that_bounds_it(reason, parameter, bound):
    assert LIMITS.bound(reason) == (parameter, bound)


def test_every_bound_names_fields_that_exist_and_every_refusal_has_a_bound():
    """BOUNDS covers each implausible_<quantity> (and inconsistent_dynamic_pressure) the limits
    can return, with real fields."""
    names = {f for f, _ in BOUNDS.values() for f in f}
    assert names <= set(PlausibilityLimits.__dataclass_fields__)
    refusals = {LIMITS.imu_rejection((99.0, 0, 0), (0, 0, 0)), LIMITS.imu_rejection((0, 0, 0), (999.0, 0, 0)),
                LIMITS.airspeed_rejection((1.0, 0, 0)), LIMITS.airspeed_rejection((-40.0, 0, 0)),
                LIMITS.airspeed_rejection((30.0, 30.0, 0.0)), LIMITS.dynamic_pressure_rejection(1.0),
                LIMITS.thrust_rejection(1e9), LIMITS.surface_rejection([2.0]),
                LIMITS.rate_change_rejection(0.01, (0.0, 19.0, 0.0)),
                LIMITS.sample_rejection(state(qbar=5.0), qbar_measured=True)}
    assert refusals == set(BOUNDS)


@pytest.mark.parametrize("reason, values, seen", [
    ("implausible_angular_rate", (0.1, -25.0, 3.0, 0.0, 0.0, 9.8), 25.0),
    ("implausible_specific_force", (0.0, 0.0, 0.0, 0.0, -300.0, 9.8), 300.0),
    ("implausible_airspeed", (3.0, 0.0, -4.0), 5.0),
    ("implausible_alpha", (10.0, 0.0, -10.0), math.pi / 4),  # REP-103 z up: w = +10 m/s down
    ("implausible_beta", (10.0, -10.0, 0.0), math.asin(10.0 / math.hypot(10.0, 10.0))),
    ("implausible_dynamic_pressure", (2.0,), 2.0),
    ("implausible_thrust", (-3e6,), -3e6),
    ("implausible_surface", (0.1, -1.5), 1.5),
    ("implausible_angular_acceleration", (0.02, 0.0, 19.9, -0.5), 995.0),  # (interval, changes)
])
def test_the_value_seen_in_a_refused_message_is_the_bounded_quantity(reason, values, seen):
    assert message_value(reason, values) == pytest.approx(seen, rel=1e-15)


def test_the_value_seen_in_a_refused_sample_is_the_bounded_quantity():
    assert sample_value("implausible_alpha", state(alpha=1.3)) == 1.3
    assert sample_value("implausible_angular_rate", state(q=-30.0)) == 30.0
    assert sample_value("inconsistent_dynamic_pressure", state(qbar=5.0, V=40.0)) == 2.0 * 5.0 / 1600.0
    assert math.isnan(sample_value("gap_imu", state()))
