"""Convergence flags: the monitor against a brute-force implementation of the
criterion, its behaviour on converging and jumping estimates, bounded memory, bad input."""

import math
import warnings

import numpy as np
import pytest

from rls_uncertainty.datapath.convergence import ConvergenceConfig, ConvergenceMonitor
from rls_uncertainty.errors import ConfigError, RlsUncertaintyError


class ReferenceMonitor:
    """The criterion written out sample by sample and parameter by parameter: keep every
    sample since the last reset, look at the newest ``capacity`` of them, take as anchor the
    newest stamped at or before ``t - T``, and test every sample from the anchor to now."""

    def __init__(self, sizes, config):
        self.sizes, self.config = list(sizes), config
        self.reset()

    def reset(self):
        self.history, self.last = [], None

    def _nothing(self):
        m, n = len(self.sizes), max(self.sizes)
        return np.zeros((m, n), bool), np.zeros(m, bool)

    def update(self, stamp, theta, se, ready):
        try:
            stamp = int(stamp)
        except (TypeError, ValueError, OverflowError):
            self.reset()
            return self._nothing()
        if not -(2**62) < stamp < 2**62:
            self.reset()
            return self._nothing()
        if self.last is not None and stamp <= self.last:
            self.reset()
        self.last = stamp
        self.history.append((stamp, np.array(theta, float), np.array(se, float), np.array(ready, bool)))
        held = self.history[-self.config.capacity :]
        cut = stamp - int(round(self.config.window * 1e9))
        anchors = [i for i, h in enumerate(held) if h[0] <= cut]
        flags, model = self._nothing()
        if not anchors:
            return flags, model
        window = held[anchors[-1] :]
        rate = float(self.config.max_se_rate) * 1e-9
        g = math.exp(min(rate * (stamp - window[0][0]), 30.0))
        k = float(self.config.band)

        def s_of(h, j, p):  # se floored at 0; NaN when the model is not ready
            return float(np.maximum(h[2][j, p], 0.0)) if h[3][j] else math.nan

        now = window[-1]
        for j, size in enumerate(self.sizes):
            for p in range(size):
                th_t, s_t = now[1][j, p], s_of(now, j, p)
                band = float(np.minimum(s_t, 1e300)) * k
                flags[j, p] = all(
                    h[1][j, p] < th_t + band
                    and -h[1][j, p] < -th_t + band
                    and s_of(h, j, p) < s_t * g
                    and -s_of(h, j, p) < -s_t * (1.0 / g)
                    for h in window
                )
            model[j] = flags[j, :size].all()
        return flags, model


def _random_sequence(rng, sizes, n_samples):
    """Converging-looking estimates with every kind of trouble mixed in: irregular stamps,
    gaps, repeated and backward stamps, NaN/inf/zero/negative standard errors, models
    switching between ready and not ready."""
    m, n = len(sizes), max(sizes)
    truth = rng.normal(size=(m, n))
    stamp = int(rng.integers(-(10**12), 10**12))
    for k in range(n_samples):
        u = rng.random()
        if u < 0.01:
            stamp -= int(rng.integers(0, 10**9))  # backwards or repeated: reset
        elif u < 0.03:
            stamp += int(rng.integers(1, 3 * 10**9))  # gap
        elif u < 0.05:
            stamp += 1
        else:
            stamp += int(rng.integers(5 * 10**6, 30 * 10**6))  # 20 ms +- jitter
        scale = 1.0 / math.sqrt(1.0 + (k % 300))
        theta = truth + 0.1 * scale * rng.normal(size=(m, n))
        se = 0.5 * scale * np.exp(0.02 * rng.normal(size=(m, n)))
        if rng.random() < 0.02:
            theta = theta + rng.normal(size=(m, n))  # jump
        ready = rng.random(m) > 0.02
        for j, s in enumerate(sizes):
            theta[j, s:] = np.nan
            se[j, s:] = np.nan
            if not ready[j]:
                theta[j], se[j] = np.nan, np.nan
        bad = rng.random((m, n))
        se[bad < 0.003] = np.nan
        se[(bad > 0.003) & (bad < 0.005)] = 0.0
        se[(bad > 0.005) & (bad < 0.006)] = -0.1
        se[(bad > 0.006) & (bad < 0.007)] = np.inf
        theta[(bad > 0.007) & (bad < 0.008)] = np.inf
        theta[(bad > 0.008) & (bad < 0.009)] = -np.inf
        theta[(bad > 0.009) & (bad < 0.010)] = np.nan
        if rng.random() < 0.003:
            ready[int(rng.integers(m))] = True  # ready with NaN estimates
        yield (np.nan if rng.random() < 0.003 else stamp), theta, se, ready, rng.random() < 0.003


@pytest.mark.parametrize(
    "seed, config",
    [
        (1, ConvergenceConfig(window=0.3, band=1.0, max_se_rate=0.3, rate_hz=100.0)),
        (2, ConvergenceConfig(window=0.2, band=2.0, max_se_rate=1.0, rate_hz=50.0)),
        (3, ConvergenceConfig(window=0.5, band=0.5, max_se_rate=2.0, rate_hz=20.0)),  # buffer too short at times
        (4, ConvergenceConfig(window=0.06, band=3.0, max_se_rate=0.5, rate_hz=500.0, max_samples=4)),  # hard cap
    ],
)
def test_monitor_equals_brute_force(seed, config):
    rng = np.random.default_rng(seed)
    sizes = [int(s) for s in rng.integers(1, 10, size=int(rng.integers(1, 5)))]
    mon, ref = ConvergenceMonitor(sizes, config), ReferenceMonitor(sizes, config)
    n_flags = n_model = 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning whatever arrives
        for stamp, theta, se, ready, reset in _random_sequence(rng, sizes, 2500):
            if reset:
                mon.reset()
                ref.reset()
            flags, model = mon.update(stamp, theta, se, ready)
            want, want_model = ref.update(stamp, theta, se, ready)
            np.testing.assert_array_equal(flags, want)
            np.testing.assert_array_equal(model, want_model)
            assert flags.dtype == bool and model.dtype == bool
            n_flags += int(flags.sum())
            n_model += int(model.sum())
    # The sequences exercise both outcomes (else the comparison above proves little).
    total = 2500 * sum(sizes)
    assert 0.05 * total < n_flags < 0.95 * total
    assert n_model > 50


def _converging(n, rate_hz=50.0, seed=0, jump_at=None, jump=0.0):
    """An estimate converging like a running mean: se_k = 1 / sqrt(k + 20), and theta_k = 1
    plus a running mean of unit noise scaled to an error of about se_k / 2."""
    rng = np.random.default_rng(seed)
    e = np.cumsum(rng.normal(size=n)) / np.arange(1, n + 1)
    k = np.arange(n)
    theta = 1.0 + 0.5 * e * np.sqrt((k + 1) / (k + 20.0))
    se = 1.0 / np.sqrt(k + 20.0)
    if jump_at is not None:
        theta[jump_at:] += jump
    stamps = (np.round(k / rate_hz * 1e9)).astype(np.int64)
    return stamps, theta, se


def test_flag_comes_up_on_a_converging_estimate_and_goes_down_on_a_jump():
    cfg = ConvergenceConfig(window=2.0, band=1.0, max_se_rate=0.2, rate_hz=50.0)
    n, jump_at = 1500, 1000  # 30 s at 50 Hz; the estimate jumps by 2 SE at 20 s
    stamps, _, se = _converging(n)
    _, theta_j, _ = _converging(n, jump_at=jump_at, jump=2.0 * se[jump_at])
    mon = ConvergenceMonitor([2], cfg)
    flags = []
    for k in range(n):
        th = np.array([[theta_j[k], 5.0]])  # second parameter: constant, same se
        s = np.array([[se[k], se[k]]])
        f, model = mon.update(int(stamps[k]), th, s, np.array([True]))
        flags.append((f[0, 0], f[0, 1], model[0]))
    flags = np.array(flags)
    t = stamps / 1e9
    # The constant parameter passes the estimate test at once; the SE test
    # se_{k-100} < e^{0.2 * 2} se_k holds from 0.5 ln((k + 20) / (k - 80)) < 0.4 on.
    k = np.arange(n)
    predicted = np.flatnonzero((k >= 100) & (0.5 * np.log((k + 20.0) / np.maximum(k - 80.0, 1e-9)) < 0.4))[0]
    assert 3.0 < t[predicted] < 3.5
    np.testing.assert_array_equal(flags[:, 1], k >= predicted)
    # The noisy parameter converges too, and the model flag is the AND of both.
    assert flags[(t > 10) & (t < 20), 0].mean() > 0.9
    np.testing.assert_array_equal(flags[:, 2], flags[:, 0] & flags[:, 1])
    # A jump of two standard errors drops the flag at once and for the whole window.
    after = (t >= 20.0) & (t < 22.0)
    assert not flags[after, 0].any()
    assert flags[(t > 23) & (t < 30), 0].mean() > 0.9
    assert flags[k >= predicted, 1].all()  # the other parameter is not disturbed


def test_flag_waits_for_the_window_and_restarts_after_a_reset():
    cfg = ConvergenceConfig(window=1.0, band=1.0, max_se_rate=1.0, rate_hz=10.0)
    mon = ConvergenceMonitor([1], cfg)
    th, se, ready = np.array([[1.0]]), np.array([[0.1]]), np.array([True])
    got = [mon.update(k * 100_000_000, th, se, ready)[0][0, 0] for k in range(15)]
    assert got == [False] * 10 + [True] * 5  # anchor t - 1 s exists from the 11th sample on
    mon.reset()
    assert not mon.update(2_000_000_000, th, se, ready)[0].any()
    assert not mon.update(1_000_000_000, th, se, ready)[0].any()  # backwards: history restarts
    got = [mon.update(1_000_000_000 + k * 100_000_000, th, se, ready)[0][0, 0] for k in range(1, 12)]
    assert got == [False] * 9 + [True] * 2


def test_irregular_stamps_use_time_not_sample_counts():
    cfg = ConvergenceConfig(window=1.0, band=1.0, max_se_rate=1.0, rate_hz=100.0)
    mon = ConvergenceMonitor([1], cfg)
    th, se, ready = np.array([[1.0]]), np.array([[0.1]]), np.array([True])
    # three samples 10 ms apart, then one 1.5 s later: the first three are all before t - T,
    # the anchor is the third, and the flag is up with a window of two samples.
    for s in (0, 10_000_000, 20_000_000):
        assert not mon.update(s, th, se, ready)[0].any()
    assert mon.update(1_520_000_000, th, se, ready)[0].all()
    # a burst of 50 samples within 0.1 s: the anchor stays the sample of 0.02 s
    flags = [mon.update(1_520_000_000 + (k + 1) * 2_000_000, th, se, ready)[0][0, 0] for k in range(50)]
    assert all(flags)


def test_memory_stays_bounded_under_a_flood():
    cfg = ConvergenceConfig(window=2.0, rate_hz=50.0, max_samples=64)
    assert cfg.capacity == 64  # min(ceil(2 * 50) + 2, 64)
    mon = ConvergenceMonitor([3, 4], cfg)
    arrays = {k: v.nbytes for k, v in vars(mon).items() if isinstance(v, np.ndarray)}
    th = np.array([[1.0, 2.0, 3.0, np.nan], [1.0, 2.0, 3.0, 4.0]])
    se = np.where(np.isnan(th), np.nan, 0.1)
    ready = np.array([True, True])
    for k in range(100_000):  # 1 MHz for 0.1 s: far more samples than the buffer holds
        flags, model = mon.update(k * 1000, th, se, ready)
        assert mon.n_held <= mon.capacity
        assert not flags.any() and not model.any()  # the buffer never reaches back 2 s: fail safe
    assert {k: v.nbytes for k, v in vars(mon).items() if isinstance(v, np.ndarray)} == arrays
    assert len(mon._stamps) == 2 * mon.capacity
    # at a rate the buffer can hold, the flags come up once 2 s have passed
    t0 = 100_000 * 1000
    got = [mon.update(t0 + (k + 1) * 40_000_000, th, se, ready)[1].all() for k in range(60)]
    assert not any(got[:49]) and all(got[50:])


def test_non_finite_input_never_flags_never_warns():
    cfg = ConvergenceConfig(window=0.2, rate_hz=50.0)
    mon = ConvergenceMonitor([2, 2], cfg)
    ready = np.array([True, True])
    good_th, good_se = np.array([[1.0, 2.0], [3.0, 4.0]]), np.full((2, 2), 0.1)
    cases = [
        (np.array([[np.inf, 2.0], [-np.inf, 4.0]]), np.array([[np.inf, 0.1], [np.inf, 0.1]])),
        (np.array([[np.nan, 2.0], [3.0, np.inf]]), np.array([[0.1, -np.inf], [np.nan, np.inf]])),
        (good_th, np.array([[0.0, -1.0], [np.nan, np.inf]])),
        (np.array([[1e300, -1e300], [np.inf, np.nan]]), np.array([[1e299, 1e299], [0.0, 0.1]])),
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for th, se in cases:
            mon.reset()
            bad = ~(np.isfinite(th) & np.isfinite(se) & (se > 0))
            for k in range(30):
                flags, model = mon.update(k * 20_000_000, th, se, ready)
                assert not flags[bad].any()
            assert flags[~bad].all()  # the valid entries of the same models converge
            # a bad sample in the middle of good ones holds the flag down for one window
            mon.reset()
            for k in range(30):
                bad_now = k == 15
                flags, _ = mon.update(k * 20_000_000, th if bad_now else good_th, se if bad_now else good_se, ready)
                if 15 <= k <= 15 + 10:
                    assert not flags[bad].any()
            assert flags.all()
        for stamp in (np.nan, np.inf, "x", None, 2**63, -(2**62)):
            flags, model = mon.update(stamp, good_th, good_se, ready)
            assert not flags.any() and not model.any() and mon.n_held == 0


def test_not_ready_models_and_padding_are_never_flagged():
    cfg = ConvergenceConfig(window=0.2, rate_hz=50.0)
    mon = ConvergenceMonitor([1, 3], cfg)
    th = np.array([[1.0, 7.0, 7.0], [1.0, 2.0, 3.0]])  # finite padding on purpose
    se = np.full((2, 3), 0.1)
    for k in range(30):
        flags, model = mon.update(k * 20_000_000, th, se, np.array([True, False]))
    np.testing.assert_array_equal(flags, [[True, False, False], [False, False, False]])
    np.testing.assert_array_equal(model, [True, False])


def test_bad_shapes_raise():
    mon = ConvergenceMonitor([2, 3])
    with pytest.raises(ValueError, match="shape"):
        mon.update(0, np.zeros((2, 2)), np.zeros((2, 3)), np.ones(2, bool))
    with pytest.raises(ValueError, match="shape"):
        mon.update(0, np.zeros((2, 3)), np.zeros((2, 3)), np.ones(3, bool))
    with pytest.raises(ValueError):
        ConvergenceMonitor([])
    with pytest.raises(TypeError):
        ConvergenceMonitor([2], config={"window": 2.0})


@pytest.mark.parametrize(
    "kwargs",
    [
        {"window": 0.0}, {"window": -1.0}, {"window": math.inf}, {"window": math.nan}, {"window": "2"},
        {"window": 1e10}, {"band": 0.0}, {"band": 2e6}, {"band": True}, {"max_se_rate": -0.1},
        {"max_se_rate": math.nan}, {"rate_hz": 0.0}, {"max_samples": 1}, {"max_samples": 2.5},
        {"max_samples": True},
    ],
)
def test_config_rejects_bad_values(kwargs):
    with pytest.raises(ConfigError) as info:
        ConvergenceConfig(**kwargs)
    assert isinstance(info.value, RlsUncertaintyError) and isinstance(info.value, ValueError)
    assert next(iter(kwargs)) in str(info.value)


def test_capacity_is_window_times_rate_with_a_hard_cap():
    assert ConvergenceConfig(window=2.0, rate_hz=50.0).capacity == 102
    assert ConvergenceConfig(window=2.0, rate_hz=200.0).capacity == 402
    assert ConvergenceConfig(window=60.0, rate_hz=1000.0).capacity == 4096
    assert ConvergenceConfig(window=0.05, rate_hz=1.0).capacity == 3
