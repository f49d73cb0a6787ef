"""Loud misconfiguration (rls_uncertainty.datapath.alerts): the texts name what was expected, what came
and the parameter to change, computed from real pipeline runs; the policy says them when a
needed stream is all rejected or no sample is used for a window, at most once per repeat
period, and never for a healthy or deliberately disabled pipeline. No ROS."""

from __future__ import annotations

import math

import pytest
from bag_samples import changed_messages

from rls_uncertainty.datapath.alerts import MAX_LINE, MIN_MESSAGES, SHOWN, AlertPolicy, explain, no_estimate
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from conftest import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"
T2 = load_parameters_file("t2")
MS = 1_000_000
SEC = 1_000_000_000


@pytest.fixture(scope="module")
def bag():
    return read_inputs(BUNDLED)[0]


def run(messages, params, *, upto=None):
    """A pipeline fed ``messages`` (until stamp ``upto``) with ``params``; its counters."""
    pipe = Pipeline(pipeline_config(params))
    for kind, stamp, msg in messages:
        if upto is not None and stamp > upto:
            break
        feed(pipe, kind, msg)
    return pipe, pipe.counters()


def test_the_default_surfaces_on_the_bundled_bag_name_the_joints_and_the_parameter(bag):
    """The bundled bag has split elevators; the default surfaces.elevator expects one joint."""
    pipe, c = run(bag, {})
    assert c["streams"]["control_surfaces"]["rejected"] == {"missing_joint": 1200}
    assert no_estimate(c, pipe.required) == (
        "control_surfaces: all 1200 messages rejected (missing_joint): surfaces.elevator expects [elevator], "
        "messages carry [elevator_left, elevator_right, aileron_left, aileron_right, rudder]; set surfaces.elevator")


def test_every_missing_field_is_named_with_its_joints(bag):
    params = {**T2, "surfaces.elevator": ["el_l", "el_r"], "surfaces.rudder": ["rud"]}
    _pipe, c = run(bag, params, upto=bag[0][1] + SEC)
    text = c["explanations"]["control_surfaces"]["missing_joint"]
    assert text.startswith("surfaces.elevator expects [el_l, el_r], surfaces.rudder expects [rud], messages carry")
    assert text.endswith("; set surfaces.elevator, surfaces.rudder")


def test_a_frame_mismatch_names_the_frame_expected_and_received_once_for_every_stream(bag):
    pipe, c = run(bag, {**T2, "inputs.frame_id": "imu_link"})
    why = no_estimate(c, pipe.required)
    assert why == ("imu, airspeed, control_surfaces, dynamic_pressure: all 2400/600/1200/600 messages rejected "
                   "(frame_mismatch): inputs.frame_id expects 'imu_link', messages carry 'base_link'; set "
                   "inputs.frame_id (empty: not checked)")


def test_an_implausible_value_names_the_limit_and_the_value_seen(bag):
    """The value seen is the newest refused message's alpha = atan2(w, u) in aircraft axes,
    computed here from the message itself."""
    _pipe, c = run(bag, {**T2, "limits.alpha": 0.05})
    last = [m for kind, _s, m in bag if kind == "airspeed"][-1]
    alpha = math.atan2(-last.vector.z, last.vector.x)
    assert abs(alpha) > 0.05
    assert c["explanations"]["airspeed"]["implausible_alpha"] == (
        f"seen alpha = {alpha:.4g} rad, limits.alpha allows |alpha| <= 0.05 rad; set limits.alpha if that is "
        "real, else check the sensor's units")
    _pipe, c = run(bag, {**T2, "limits.airspeed_max": 20.0}, upto=bag[0][1] + SEC)
    assert "limits.airspeed_max allows 3 <= airspeed <= 20 m/s; set limits.airspeed_max" in \
        c["explanations"]["airspeed"]["implausible_airspeed"]


def test_samples_refused_once_formed_are_explained_with_the_derived_value(bag):
    """Dynamic pressure from a thin air density: every message plausible, every sample not."""
    params = {**T2, "inputs.use_dynamic_pressure": False, "inputs.air_density": 0.01,
              "limits.dynamic_pressure_min": 100.0}
    pipe, c = run(bag, params)
    assert c["samples_used"] == 0 and c["samples_rejected"]["implausible_dynamic_pressure"] > 500
    why = no_estimate(c, pipe.required)
    assert why.startswith(f"samples: none of the {c['samples_formed']} samples of the run used "
                          "(implausible_dynamic_pressure ")
    seen = float(why.split("seen dynamic_pressure = ")[1].split(" Pa")[0])
    assert 0.5 * 0.01 * 30.0**2 < seen < 0.5 * 0.01 * 60.0**2  # rho V^2 / 2 at the T-2's 30-60 m/s
    assert "limits.dynamic_pressure_min allows 100 <= dynamic_pressure <= 100000 Pa" in why


def test_a_dynamic_pressure_that_disagrees_with_the_airspeed_names_both_and_the_density(bag):
    """5 Pa at the bag's airspeed: the text gives both, the density 2 qbar / V^2 they imply
    (computed here from the values shown) and the parameter that bounds it."""
    def five_pascal(k, msg):
        msg.fluid_pressure = 5.0

    pipe, c = run(changed_messages(bag, "dynamic_pressure", five_pascal), T2)
    text = c["explanations"]["samples"]["inconsistent_dynamic_pressure"]
    V = float(text.split("at true airspeed ")[1].split(" m/s")[0])
    rho = float(text.split("2 qbar/V^2 = ")[1].split(" kg/m^3")[0])
    speeds = [math.hypot(m.vector.x, m.vector.y, m.vector.z) for kind, _s, m in bag if kind == "airspeed"]
    assert min(speeds) * (1 - 1e-3) <= V <= max(speeds) * (1 + 1e-3)  # shown to 4 digits
    assert rho == pytest.approx(2 * 5.0 / V**2, rel=1e-3)
    assert text == (f"dynamic pressure 5 Pa at true airspeed {V:.4g} m/s implies an air density 2 qbar/V^2 = "
                    f"{rho:.4g} kg/m^3, limits.air_density_min allows 0.05 <= air_density <= 2 kg/m^3: the "
                    "dynamic_pressure and airspeed streams disagree (a unit? a blocked pitot?); set "
                    "limits.air_density_min if that is real, or inputs.use_dynamic_pressure false to use rho V^2 / 2 "
                    "with inputs.air_density")
    assert no_estimate(c, pipe.required).startswith(
        f"samples: none of the {c['samples_formed']} samples of the run used (inconsistent_dynamic_pressure ")


def test_a_gyro_spike_names_the_angular_acceleration_it_implies(bag):
    """One pitch-rate message of 19.999 rad/s: the value seen is its change from the message
    before it over their interval, computed here from the bag."""
    imu = [(s, m) for kind, s, m in bag if kind == "imu"]
    k = 1200

    def spike(i, msg):
        if i != k:
            return False
        msg.angular_velocity.y = 19.999

    _pipe, c = run(changed_messages(bag, "imu", spike), T2)
    (t0, before), (t1, _m) = imu[k - 1], imu[k]
    seen = (19.999 - before.angular_velocity.y) / ((t1 - t0) * 1e-9)
    assert c["explanations"]["imu"]["implausible_angular_acceleration"] == (
        f"seen angular_acceleration = {seen:.4g} rad/s^2, limits.angular_acceleration allows "
        "|angular_acceleration| <= 500 rad/s^2; set limits.angular_acceleration if that is real, else look for "
        "gyro spikes (a body rate jumped between two consecutive imu messages)")


def test_a_healthy_run_says_nothing(bag):
    pipe, c = run(bag, T2)
    assert no_estimate(c, pipe.required) is None
    policy = AlertPolicy()
    assert policy.update(12.0, c, pipe.required, True, 10.0) == []


def test_texts_stay_bounded_whatever_the_joint_names():
    pipe = Pipeline(pipeline_config(T2))
    names = [f"{'x' * 500}{i}" for i in range(1000)]
    for k in range(5):
        pipe.add_surfaces(k * 10 * MS, names, [0.0] * 1000)
    c = pipe.counters()
    text = c["explanations"]["control_surfaces"]["missing_joint"]
    # At most SHOWN names, each cut to 40 characters, then "...".
    assert len(text) < 700 and "x" * 41 not in text and text.count("x" * 37 + "...") == SHOWN
    policy = AlertPolicy()
    (alert,) = policy.update(1.0, c, pipe.required, True, 10.0)
    assert len(alert.text) <= MAX_LINE


# ----------------------------------------------------------------------------- when
def counters(received=0, accepted=None, rejected=None, formed=0, used=0, samples_rejected=None, explanations=None):
    """Counters of a pipeline whose needed streams are ``imu`` and ``airspeed``."""
    rejected = dict(rejected or {})
    accepted = received - sum(rejected.values()) if accepted is None else accepted
    streams = {"imu": {"received": 10 * received, "accepted": 10 * received, "rejected": {}, "missing": 0,
                       "expired": 0},
               "airspeed": {"received": received, "accepted": accepted, "rejected": rejected, "missing": 0,
                            "expired": 0}}
    return {"streams": streams, "samples_formed": formed, "samples_used": used,
            "samples_rejected": dict(samples_rejected or {}), "explanations": explanations or {}}


REQUIRED = ("imu", "airspeed")


def test_all_rejected_is_said_at_once_and_logged_once_per_repeat_period():
    policy = AlertPolicy(repeat_s=30.0)
    logged = []
    for second in range(1, 71):
        c = counters(received=50 * second, rejected={"frame_mismatch": 50 * second},
                     explanations={"airspeed": {"frame_mismatch": "WHY"}})
        alerts = policy.update(1.0, c, REQUIRED, True, 10.0)
        assert [a.text for a in alerts] == [f"airspeed: all {50 * second} messages rejected (frame_mismatch): WHY"]
        logged += [(second, line) for line in policy.due()]
    assert [s for s, _ in logged] == [1, 31, 61]


def test_a_stream_that_recovers_is_said_for_its_window_only_then_clears():
    policy = AlertPolicy()
    seq = [counters(received=50, rejected={"missing_joint": 50})]
    seq += [counters(received=50 + 50 * k, rejected={"missing_joint": 50}, formed=40 * k, used=40 * k)
            for k in range(1, 15)]
    said = [bool(policy.update(1.0, c, REQUIRED, True, 10.0)) for c in seq]
    assert said == [True] + [False] * 14  # the second second accepts messages: not all rejected


def test_a_few_rejected_messages_are_not_a_misconfiguration():
    policy = AlertPolicy()
    c = counters(received=MIN_MESSAGES - 1, rejected={"non_finite": MIN_MESSAGES - 1})
    assert policy.update(1.0, c, REQUIRED, True, 10.0) == []


def test_no_sample_used_is_said_after_a_whole_window_and_never_when_disabled():
    """Messages arrive and are accepted, samples are formed and all refused: said once the
    window has passed with no sample used, not before; not at all when estimation is disabled."""
    def seq(k):
        return counters(received=50 * k, formed=50 * k, samples_rejected={"implausible_alpha": 50 * k},
                        explanations={"samples": {"implausible_alpha": "WHY"}})
    policy, disabled = AlertPolicy(), AlertPolicy()
    said = []
    for k in range(1, 15):
        said.append([a.text for a in policy.update(1.0, seq(k), REQUIRED, True, 10.0)])
        assert disabled.update(1.0, seq(k), REQUIRED, False, 10.0) == []
    assert said[:9] == [[]] * 9
    assert said[9] == ["samples: none of the 500 samples of the last 10 s used (implausible_alpha): WHY"]
    assert said[13] == ["samples: none of the 500 samples of the last 10 s used (implausible_alpha): WHY"]


def test_no_sample_formed_names_the_silent_stream():
    policy = AlertPolicy()
    for k in range(1, 12):
        c = counters(received=0)
        c["streams"]["imu"].update(received=100 * k, accepted=100 * k)
        alerts = policy.update(1.0, c, REQUIRED, True, 10.0)
    assert [a.text for a in alerts] == ["samples: none formed in the last 10 s although messages arrive: waiting for "
                                        "airspeed (no message in the last 10 s; topics.airspeed)"]


def test_the_explanation_of_a_reason_without_evidence_is_still_a_sentence():
    config = pipeline_config(T2)
    assert explain(config, "imu", "far_from_clock").startswith("stamps more than inputs.max_clock_offset = 0 s")
    assert "inputs.max_gap = 0.25 s" in explain(config, "samples", "gap_airspeed")
    assert explain(config, "imu", "implausible_angular_rate").startswith("limits.angular_rate allows |angular_rate|")


# ------------------------------------------------------------------ identifiability
def test_identifiability_lines_name_the_regressors_the_figure_and_the_parameter():
    from rls_uncertainty.datapath.alerts import identifiability
    from rls_uncertainty.datapath.identifiability import Problem

    collinear = Problem("collinear", ("delta_e", "delta_r"), (-0.99999995,), (0.999,), samples=600)
    assert identifiability("CZ", [collinear]) == (
        "CZ: delta_e and delta_r correlated -1 - 5.0e-08 (their estimates; identifiability.max_correlation 0.999): "
        "not identifiable; excite delta_e and delta_r independently or leave one out of models.CZ")
    no_fit = Problem("no_fit", (), (0.0031,), (0.5,), samples=600)
    assert identifiability("Cm", [no_fit]) == (
        "Cm: no regressor explains the output (R^2 0.003, identifiability.min_r_squared 0.5): not identifiable; "
        "excite the model or check its output")
    flat = Problem("constant", ("beta",), (0.0,), (1e-4,), ("rad",), samples=141)
    assert identifiability("CZ", [flat]) == (
        "CZ: regressor beta not excited (std 0 rad in 141 samples since start; identifiability.angle_resolution "
        "0.0001 rad): the model cannot initialize; move beta or leave it out of models.CZ")
    several = Problem("not_excited", ("beta", "r_hat"), (2e-5, 3e-7), (1e-4, 1e-6), ("rad", ""), samples=90)
    assert identifiability("Cn", [no_fit, several]) == (
        "Cn: no regressor explains the output (R^2 0.003, identifiability.min_r_squared 0.5): not identifiable; "
        "excite the model or check its output; regressors beta, r_hat not excited (std beta 2e-05 rad, r_hat 3e-07 "
        "in 90 samples since start; identifiability.angle_resolution 0.0001 rad, identifiability.rate_resolution "
        "1e-06): not identifiable; move beta, r_hat or leave them out of models.Cn")
    assert identifiability("CZ", []) == ""
    # An ordinary correlation keeps its digits; a constant output says so.
    assert "correlated +0.999512 (their" in identifiability("CZ", [Problem("collinear", ("a", "b"), (0.9995123,),
                                                                             (0.999,))])
    assert "the output does not vary (R^2 undefined)" in identifiability("CX", [Problem("no_fit", (), (math.nan,),
                                                                                        (0.5,))])


def test_a_model_alert_is_raised_while_a_flag_is_held_back_and_logged_once_per_repeat_period():
    text = "CZ: delta_e and delta_r correlated -1 - 5.0e-08 (...): not identifiable"
    held = {"ready": True, "held_back": "CZ_delta_e,CZ_delta_r", "identifiability": text}
    transient = {"ready": True, "held_back": "", "identifiability": text}  # not identifiable yet, nothing withheld
    waiting = {"ready": False, "samples": 200, "identifiability": "CY: regressor beta not excited (...)"}
    policy = AlertPolicy(repeat_s=30.0)
    counters = run([], T2)[1]
    lines = []
    for second in range(70):
        policy.update(1.0, counters, (), True, 10.0)
        models = [("CZ", held if second < 65 else transient), ("Cm", {"ready": True}), ("CY", waiting)]
        assert [a.key for a in policy.models(models)] == [("model CZ", "identifiability"),
                                                          ("model CY", "identifiability")][0 if second < 65 else 1:]
        lines += [(second, line) for line in policy.due()]
    assert lines == [(0, text), (0, waiting["identifiability"]), (30, text), (30, waiting["identifiability"]),
                     (60, text), (60, waiting["identifiability"])]
