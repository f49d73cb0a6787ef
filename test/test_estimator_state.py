"""Estimator state (state() / from_state()): bit-identical continuation, copies, the format."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimator_cases import run, wide_scale_problem

from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions, RecursiveEstimator


def test_snapshot_restore_continues_bit_identically():
    X, z = wide_scale_problem()
    for lags in ("all", 50):
        a = run(RecursiveEstimator(4, EstimatorOptions(lags=lags, forgetting=0.995)), X, z, stop=300)
        b = RecursiveEstimator.from_state(a.state())
        for k in range(300, len(z)):
            a.update(X[k], z[k])
            b.update(X[k], z[k])
        np.testing.assert_array_equal(a.theta, b.theta)
        np.testing.assert_array_equal(a.covariance(), b.covariance())
        np.testing.assert_array_equal(a.standard_errors("conventional"), b.standard_errors("conventional"))

@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_snapshot_while_a_model_waits_for_initialization_continues_bit_identically(forgetting):
    """Restore while one model still accumulates its lagged moments (its third regressor is
    not excited until sample 200): it initializes at the same sample with the same numbers."""
    rng = np.random.default_rng(5)
    n = 500
    X = np.zeros((n, 2, 3))
    X[:, 0, :2] = np.column_stack([np.ones(n), rng.standard_normal(n)])
    X[:, 1] = np.column_stack(
        [np.ones(n), rng.standard_normal(n), np.where(np.arange(n) < 200, 0.0, rng.standard_normal(n))]
    )
    Z = np.einsum("kmi,mi->km", X, [[1.0, 2.0, 0.0], [0.5, -1.0, 3.0]]) + 0.1 * rng.standard_normal((n, 2))
    for lags in ("all", 20):
        a = EstimatorBank((2, 3), EstimatorOptions(lags=lags, forgetting=forgetting))
        for k in range(100):
            a.update(X[k], Z[k])
        assert list(a.initialized) == [True, False]
        b = EstimatorBank.from_state(a.state())
        for k in range(100, n):
            a.update(X[k], Z[k])
            b.update(X[k], Z[k])
        assert list(b.ready_at) == list(a.ready_at) and a.ready_at[1] > 200
        np.testing.assert_array_equal(a.theta_all(), b.theta_all())
        np.testing.assert_array_equal(a.standard_errors_all(), b.standard_errors_all())
        np.testing.assert_array_equal(a.standard_errors_all("conventional"), b.standard_errors_all("conventional"))

@pytest.mark.parametrize("forgetting", [1.0, 0.99])
@pytest.mark.parametrize("lags", ["all", 20, "auto"])
def test_snapshot_during_and_after_the_residual_burn_in_continues_bit_identically(lags, forgetting):
    """The burn-in is not stored: its end follows from ready_at, the weight totals from k. A
    state taken while a model waits, during its burn-in, at its last sample, while the lag
    window still reaches into it and long after continues bit for bit; the configuration
    keeps the resolved burn-in."""
    rng = np.random.default_rng(6)
    n = 360
    X = np.zeros((n, 2, 3))
    X[:, 0, :2] = np.column_stack([np.ones(n), rng.standard_normal(n)])
    X[:, 1] = np.column_stack([np.ones(n), rng.standard_normal(n), np.where(np.arange(n) < 60, 0.0, 1.0)])
    Z = np.einsum("kmi,mi->km", X, [[1.0, 2.0, 0.0], [0.5, -1.0, 3.0]]) + 0.1 * rng.standard_normal((n, 2))
    options = EstimatorOptions(lags=lags, forgetting=forgetting, residual_burn_in=None if lags == "auto" else 30,
                               max_lags=20)
    B = options.burn_in
    assert B == (50 if lags == "auto" else 30)
    for stop in (40, 80, 61 + B, 62 + B, 70 + B, 300):  # model 1 initializes at 61
        a = EstimatorBank((2, 3), options)
        for k in range(stop):
            a.update(X[k], Z[k])
        b = EstimatorBank.from_state(a.state())
        assert b.options == options and list(a.initialized) == [True, stop > 60]
        for k in range(stop, n):
            a.update(X[k], Z[k])
            b.update(X[k], Z[k])
            np.testing.assert_array_equal(a.standard_errors_all(), b.standard_errors_all())
            np.testing.assert_array_equal(a.lags_used, b.lags_used)
        np.testing.assert_array_equal(a.autocorrelation(1), b.autocorrelation(1))
        np.testing.assert_array_equal(a.standard_errors_all("conventional"), b.standard_errors_all("conventional"))
        assert list(a.ready_at) == [2, 61]


@pytest.mark.parametrize("lags", [5, "all"])
def test_snapshot_is_a_copy(lags):
    X, z = wide_scale_problem()
    a = run(RecursiveEstimator(4, EstimatorOptions(lags=lags)), X, z, stop=100)
    snap = a.state()
    theta = a.theta.copy()
    frozen = {name: arr.tobytes() for name, arr in snap["arrays"].items()}
    run(a, X[100:], z[100:])
    assert np.array_equal(RecursiveEstimator.from_state(snap).theta, theta)
    # No array of the state is a view of the estimator's: continuing changed none of them.
    assert {name: arr.tobytes() for name, arr in snap["arrays"].items()} == frozen


def test_a_state_of_another_format_or_shape_is_refused_by_name():
    X, z = wide_scale_problem()
    saved = run(RecursiveEstimator(4, EstimatorOptions(lags=5)), X, z, stop=50).state()
    assert saved["format"] == EstimatorBank.STATE_FORMAT == 9
    old = dict(saved, format=8)  # before the frequency-domain record
    with pytest.raises(ValueError, match="state format 8"):
        EstimatorBank.from_state(old)
    bad = dict(saved, arrays=dict(saved["arrays"], lag_sums=np.zeros((1, 5))))
    with pytest.raises(ValueError, match="lag_sums"):
        EstimatorBank.from_state(bad)


def test_state_holds_plain_arrays_with_the_residuals_and_history_newest_first():
    """The saved history windows are lag-indexed (entry i is sample k - i) and the residuals
    carry their sign: a restore does not depend on where they sat in the buffers."""
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=5)), X, z, stop=50)
    arrays = est.state()["arrays"]
    assert all(isinstance(a, np.ndarray) for a in arrays.values())
    np.testing.assert_array_equal(arrays["v"][0], est.residuals()[::-1])
    np.testing.assert_allclose(arrays["x"][0, 0] / arrays["inv_s"][0], X[49], rtol=1e-15)
    np.testing.assert_allclose(arrays["lag_sums"][0] / 50, est.autocorrelation(), rtol=1e-15)


@pytest.mark.parametrize("kw,n", [
    (dict(lags=10), 5), (dict(lags=10), 300), (dict(lags=0), 50), (dict(lags="all"), 40),
    (dict(lags="all"), 200), (dict(lags=7, forgetting=0.98), 100), (dict(lags=5, window="bartlett"), 1),
    (dict(lags="auto", max_lags=8), 120), (dict(lags="all", residual_burn_in=30), 100),
    (dict(lags=5, forgetting=0.98), 2), (dict(lags=5, p0=10.0), 7),
])
def test_the_layout_table_is_the_estimators_state(kw, n):
    """EstimatorBank.state_layout() describes exactly what EstimatorBank.state() writes (also
    while a model waits, with and without a noise model, with a prior): what a state file must
    hold."""
    rng = np.random.default_rng(1)
    bank = EstimatorBank((3, 2, 4), EstimatorOptions(**kw))
    for _ in range(n):
        bank.update(rng.standard_normal((3, 4)), rng.standard_normal(3))
    s = bank.state()
    options = EstimatorOptions.from_dict(s["options"])
    waiting = not s["arrays"]["ready"].all()
    layout = EstimatorBank.state_layout(tuple(s["sizes"]), options, s["counters"], waiting=waiting)
    assert {k: (v.shape, v.dtype) for k, v in s["arrays"].items()} == {
        k: (shape, dtype.newbyteorder("=")) for k, (shape, dtype) in layout.items()}
