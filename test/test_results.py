"""What a run produced (rls_uncertainty/offline/results.py): the bounded, evenly spaced history, a
parameter's final values and series, and the errors that name what is missing. No ROS."""

import numpy as np
import pytest

from rls_uncertainty.errors import EstimatorNotReady, UnknownName
from rls_uncertainty.offline.results import History, ReplayResult, accounting

NAMES = (("CZ_0", "CZ_alpha"), ("Cm_0", "Cm_alpha", "Cm_q"))


def _fill(history, n, ready=lambda i: (True, True)):
    for i in range(n):
        values = np.arange(5, dtype=float) + 10 * i
        history.append(1000 + i, values, values / 10, values / 20, values > 20, np.array(ready(i)), np.array([i, -i]))


def test_an_unbounded_history_keeps_every_sample_in_order():
    h = History(NAMES)
    _fill(h, 1000)
    assert h.n == 1000 and h.stride == 1
    assert np.array_equal(h.stamps_ns, 1000 + np.arange(1000))
    theta, se, sc, flags = h.column(3)  # Cm_alpha: the fourth parameter
    assert np.array_equal(theta, 3 + 10 * np.arange(1000)) and np.array_equal(se, theta / 10)
    assert np.array_equal(sc, theta / 20) and np.array_equal(flags, theta > 20)
    assert np.array_equal(h.lags(1), -np.arange(1000))


@pytest.mark.parametrize("capacity,n", [(8, 7), (8, 16), (8, 17), (8, 1000), (3, 100_000)])
def test_a_bounded_history_keeps_at_most_twice_its_capacity_evenly_spaced(capacity, n):
    h = History(NAMES, capacity)
    _fill(h, n)
    kept = h.stamps_ns - 1000
    # Every stride-th sample from the first: evenly spaced, the newest no more than a stride old.
    assert h.n <= 2 * capacity and np.array_equal(kept, np.arange(0, n, h.stride))
    assert n - 1 - kept[-1] < h.stride
    assert h.stride == 1 or h.n > capacity  # thinned only as far as needed
    assert np.array_equal(h.column(0)[0], 10 * kept)  # the values travel with their stamps


def test_a_sample_is_copied_when_appended():
    h = History(NAMES)
    values = np.zeros(5)
    h.append(1, values, values, values, values > 0, np.array([True, True]))
    values[:] = 7
    assert h.column(0)[0][0] == 0.0


def _result(history=None):
    r = ReplayResult(("CZ", "Cm"), NAMES, history=history, explanations=["Cm: no estimate: its 3 regressors ..."])
    r.published(5, 0, [1.0, 2.0], [0.1, 0.2], [0.05, 0.1], [False, True])
    return r


def test_final_gives_the_last_published_values_and_names_what_is_missing():
    r = _result()
    assert r.parameters == ("CZ_0", "CZ_alpha", "Cm_0", "Cm_alpha", "Cm_q")
    f = r.final("CZ_alpha")
    assert (f.estimate, f.std_error, f.std_error_conventional, f.converged, f.stamp_ns) == (2.0, 0.2, 0.1, True, 5)
    with pytest.raises(UnknownName, match=r"C_m_alpha.*CZ_0, CZ_alpha, Cm_0, Cm_alpha, Cm_q"):
        r.final("C_m_alpha")
    with pytest.raises(EstimatorNotReady, match=r"Cm_alpha: no estimate in this run.*its 3 regressors"):
        r.final("Cm_alpha")
    with pytest.raises(EstimatorNotReady, match="kept no time histories"):
        r.series("CZ_0")


def test_a_series_holds_the_samples_in_which_its_model_published():
    h = History(NAMES)
    _fill(h, 10, ready=lambda i: (i >= 3, i % 2 == 0))
    r = _result(h)
    cz, cm = r.series("CZ_alpha"), r.series("Cm_q")
    assert np.array_equal(cz.stamps_ns, 1000 + np.arange(3, 10))
    assert np.array_equal(cz.estimates, 1 + 10 * np.arange(3, 10))
    assert np.array_equal(cm.stamps_ns, 1000 + np.arange(0, 10, 2)) and np.array_equal(cm.time, cm.stamps_ns * 1e-9)
    assert np.array_equal(cm.std_errors, (4 + 10 * np.arange(0, 10, 2)) / 10)
    cz.estimates[:] = 0  # the caller's copy
    assert r.series("CZ_alpha").estimates[0] == 31


def test_the_accounting_keeps_the_counts_and_drops_the_rest():
    counters = {"streams": {"imu": {"received": 3, "accepted": 2, "rejected": {"frame_mismatch": 1}, "expired": 0,
                                    "missing": 0, "newest_stamp_ns": 9}},
                "samples_formed": 2, "samples_used": 1, "samples_rejected": {"end_of_data": 1}, "samples_pending": 0,
                "resets": {}, "unknown_joints": {}, "explanations": ["..."]}
    got = accounting(counters)
    assert got == {"streams": {"imu": {"received": 3, "accepted": 2, "rejected": {"frame_mismatch": 1}, "expired": 0,
                                       "missing": 0}},
                   "samples_formed": 2, "samples_used": 1, "samples_rejected": {"end_of_data": 1},
                   "samples_pending": 0, "resets": {}}
    r = ReplayResult(("CZ",), NAMES[:1], counter_values=got)
    r.counters()["streams"]["imu"]["received"] = 0  # a copy
    assert r.counters()["streams"]["imu"]["received"] == 3


FREQUENCY_NAMES = (("CZ_alpha",), ("Cm_alpha", "Cm_q"))


def test_the_frequency_domain_estimates_are_asked_for_by_method_and_kept_apart():
    h, hf = History(NAMES), History(FREQUENCY_NAMES)
    _fill(h, 4)
    for i in range(2):  # published every other sample
        values = np.array([100.0, 200.0, 300.0]) + i
        hf.append(1000 + 2 * i, values, values / 10, values / 20, values > 250, np.array([True, i == 1]))
    r = ReplayResult(("CZ", "Cm"), NAMES, history=h, methods=("time", "frequency"),
                     frequency_parameter_names=FREQUENCY_NAMES, frequency_history=hf)
    r.published(5, 0, [1.0, 2.0], [0.1, 0.2], [0.05, 0.1], [False, True])
    r.published(6, 0, [9.0], [0.9], [0.8], [True], method="frequency")
    assert r.final("CZ_alpha") == (2.0, 0.2, 0.1, True, 5)
    assert r.final("CZ_alpha", method="frequency") == (9.0, 0.9, 0.8, True, 6)
    assert r.finals("frequency") == {"CZ_alpha": r.final("CZ_alpha", "frequency")}
    assert list(r.finals()) == ["CZ_0", "CZ_alpha"]
    with pytest.raises(EstimatorNotReady, match="Cm_q: no frequency-domain estimate in this run"):
        r.final("Cm_q", method="frequency")
    with pytest.raises(UnknownName, match="CZ_0 is a bias, which the frequency-domain method does not estimate"):
        r.final("CZ_0", method="frequency")
    with pytest.raises(UnknownName, match="no parameter 'Cm_r'"):
        r.series("Cm_r", method="frequency")
    with pytest.raises(ValueError, match="method must be one of"):
        r.final("CZ_alpha", method="fourier")
    s = r.series("Cm_q", method="frequency")
    assert s.stamps_ns.tolist() == [1002] and s.estimates.tolist() == [301.0]
    assert r.series("CZ_alpha", method="frequency").estimates.tolist() == [100.0, 101.0]
    assert r.series("CZ_alpha").estimates.tolist() == [1.0, 11.0, 21.0, 31.0]


def test_a_method_the_run_did_not_publish_is_named():
    time_only = _result()
    with pytest.raises(EstimatorNotReady, match=r"no frequency-domain estimates \(estimator.method: time\)"):
        time_only.final("CZ_alpha", method="frequency")
    frequency_only = ReplayResult(("CZ", "Cm"), NAMES, methods=("frequency",),
                                  frequency_parameter_names=FREQUENCY_NAMES)
    with pytest.raises(EstimatorNotReady, match=r"no time-domain estimates \(estimator.method: frequency\)"):
        frequency_only.series("CZ_alpha")
    with pytest.raises(UnknownName, match="no parameter 'Cx'"):  # an unknown name first
        frequency_only.final("Cx")
