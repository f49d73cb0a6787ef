"""A flight-control team's bag-replay tests, as docs/testing.md writes them: the estimator
node under test on a private ROS domain, a recorded maneuver played to it, and assertions on
what it published (the fixtures of rls_uncertainty.testing.plugin, enabled in pytest.ini).

The accepted values: the T-2's C_m_alpha is the simulation's truth (Table 1 of the paper);
the Twin Otter's comes from its accepted earlier analysis (docs/validation.md)."""

import numpy as np

from rls_uncertainty.testing import bundled_bag, replay_bag

T2_CM_ALPHA = -1.481
TWIN_OTTER_CM_ALPHA = -1.3832


def test_t2_cm_alpha_is_within_two_corrected_standard_errors(rls_live_replay):
    result = rls_live_replay(bundled_bag(), "t2")
    final = result.final("Cm_alpha")
    assert abs(final.estimate - T2_CM_ALPHA) <= 2 * final.std_error


def test_twin_otter_cm_alpha_is_within_two_corrected_standard_errors(rls_live_replay, twin_otter_longitudinal):
    result = rls_live_replay(twin_otter_longitudinal, "twin_otter_longitudinal")
    final = result.final("Cm_alpha")
    assert abs(final.estimate - TWIN_OTTER_CM_ALPHA) <= 2 * final.std_error


def test_the_same_check_in_process_without_ros():
    final = replay_bag(bundled_bag(), "t2").final("Cm_alpha")
    assert abs(final.estimate - T2_CM_ALPHA) <= 2 * final.std_error


def test_every_message_is_used_and_the_flags_hold_once_converged(rls_estimator, rls_play):
    node = rls_estimator("t2", estimator__lag_span=0.8)
    result = rls_play(bundled_bag(), node)
    counters = result.counters()
    streams = counters["streams"]
    assert all(s["received"] == s["accepted"] for s in streams.values())
    assert all(streams[k]["received"] > 0 for k in ("imu", "airspeed", "dynamic_pressure", "control_surfaces"))
    flags = result.series("Cm_q").converged
    assert flags[-1] and np.all(flags[np.argmax(flags):])  # once set, it stays set
