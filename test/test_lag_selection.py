"""Automatic lag selection against hand-computed values of the published formulas,
literal implementations on raw series, edge cases and monotonic behaviour; beside it the rules
the estimator does not use (``lag_rules.py``), which show why it uses the flat-top rule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from lag_rules import RULES, andrews_lags, correlations, newey_west_lags, score_flat_top_lags, select_lags
from statsmodels.tsa.stattools import acf

from rls_uncertainty.aero.differentiation import DifferentiatorConfig, derivative_weights
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
from rls_uncertainty.estimator.lag_selection import flat_top_lags, politis_threshold


def geometric(rho: float, W: int) -> np.ndarray:
    """Theoretical AR(1) autocorrelation rho^i, i = 0..W-1 (R(0) = 1)."""
    return rho ** np.arange(W, dtype=float)


def ma_acf(c: np.ndarray, W: int) -> np.ndarray:
    """Theoretical autocorrelation of the moving average sum_j c_j e_(k-j), white e."""
    r = np.array([np.dot(c[i:], c[: len(c) - i]) if i < len(c) else 0.0 for i in range(W)])
    return r / r[0]


# ------------------------------------------------------------------ hand-computed values
def test_politis_threshold_hand_values():
    assert politis_threshold(100) == pytest.approx(2 * math.sqrt(2 / 100))  # 0.28284
    assert politis_threshold(1000) == pytest.approx(0.109545, abs=1e-6)  # 2 sqrt(3/1000)
    assert politis_threshold(1) == math.inf


def test_flat_top_is_twice_the_lag_before_the_first_run_of_five_insignificant_lags():
    # n = 1000: threshold 0.1095. Lags 1-3 significant, 4.. insignificant: m_hat = 3, L = 6.
    R = np.zeros(51)
    R[:5] = [1.0, 0.5, 0.3, 0.2, 0.05]
    assert flat_top_lags(R, 1000) == 6
    # A significant lag after a run of five insignificant ones does not count.
    R = np.zeros(51)
    R[[0, 1, 7]] = [2.0, 1.0, 1.0]  # rho(1) = rho(7) = 0.5
    assert flat_top_lags(R, 1000) == 2
    # Scale does not matter (R(0) normalises) and the rule reads |rho|.
    assert flat_top_lags(-3.0 * np.r_[-1.0, R[1:] / 2.0], 1000) == 2


def test_flat_top_uses_the_politis_white_number_of_lags_K():
    # K = max(5, ceil(sqrt(log10 n))): 5 up to n = 1e25, 6 above. A lag significant 6 lags
    # after the last one breaks the run only when K = 6.
    W = 40
    R = np.zeros(W)
    R[[0, 1, 7]] = [1.0, 0.9, 0.9]
    assert flat_top_lags(R, 1e25) == 2  # K = 5: lags 2-6 insignificant
    assert flat_top_lags(R, 1e26) == 14  # K = 6: lags 2-7 contain lag 7; lags 8-13 do not
    R = np.zeros(W)
    R[[0, 1, 6]] = [1.0, 0.9, 0.9]
    assert flat_top_lags(R, 1000) == 12  # K = 5: lags 2-6 contain lag 6


def test_andrews_ar1_hand_values():
    # rho = 0.5, n = 500. Bartlett: alpha(1) = 4 .25 / (.25 * 2.25) = 1.7778,
    # S = 1.1447 (888.89)^(1/3) = 11.006 -> L = 11.
    R = geometric(0.5, 60)
    assert andrews_lags(R, 500, window="bartlett") == 11
    # Truncated: alpha(2) = 4 .25 / .5^4 = 16, S = 0.6611 * 8000^(1/5) = 3.989 -> L = 3.
    assert andrews_lags(R, 500, window="truncated") == 3
    assert select_lags(R, 500, "andrews_bartlett") == (11, "bartlett")


def test_newey_west_1994_hand_values():
    # n = 100: n0 = floor(4 (100/100)^(2/9)) = 4. rho = .5^i: s0 = 1 + 2 (.9375) = 2.875,
    # s1 = 2 (.5 + .5 + .375 + .25) = 3.25, gamma = 1.1447 (1.1304^2)^(1/3) = 1.24213,
    # m = gamma 100^(1/3) = 5.765 -> L = 5.
    R = geometric(0.5, 30)
    assert newey_west_lags(R, 100) == 5
    # Only lags 1..n0 enter: changing lag 5 does nothing, changing lag 4 does.
    R2 = R.copy()
    R2[5] = 0.9
    assert newey_west_lags(R2, 100) == 5
    R2[4] = 0.9
    assert newey_west_lags(R2, 100) != 5
    assert select_lags(R, 100, "newey_west") == (5, "bartlett")
    # n = 2000: n0 = floor(4 * 20^(2/9)) = floor(7.78) = 7, so lag 8 is not read but lag 7 is.
    R = geometric(0.5, 30)
    R8, R7 = R.copy(), R.copy()
    R8[8] = R7[7] = 0.9
    assert newey_west_lags(R8, 2000) == newey_west_lags(R, 2000)
    assert newey_west_lags(R7, 2000) != newey_west_lags(R, 2000)


# ------------------------------------------------------------------ literal implementations on raw series
def _literal_newey_west(h: np.ndarray) -> int:
    """Newey & West (1994), Bartlett, no prewhitening, on the raw series (as R sandwich's
    bwNeweyWest(prewhite = 0) followed by NeweyWest's floor)."""
    n = len(h)
    m = math.floor(4 * (n / 100) ** (2 / 9))
    sigma = [sum(h[j] * h[j - i] for j in range(i, n)) / n for i in range(m + 1)]
    s0 = sigma[0] + 2 * sum(sigma[1:])
    s1 = 2 * sum(i * sigma[i] for i in range(1, m + 1))
    return math.floor(1.1447 * ((s1 / s0) ** 2) ** (1 / 3) * n ** (1 / 3))


def _literal_flat_top(h: np.ndarray, max_lag: int) -> int:
    """Politis & White (2004): the first m with K insignificant |rho(m+1..m+K)|, M = 2m."""
    n = len(h)
    rho = acf(h, nlags=max_lag, adjusted=False, fft=False)  # demeans: pass a zero-mean h
    crit = 2 * math.sqrt(math.log10(n) / n)
    K = max(5, math.ceil(math.sqrt(math.log10(n))))
    for m in range(max_lag - K + 1):
        if all(abs(rho[m + j]) < crit for j in range(1, K + 1)):
            return min(2 * m, max_lag)
    return max_lag


@pytest.mark.parametrize("seed,rho", [(1, 0.0), (2, 0.4), (3, 0.8), (4, -0.6)])
def test_rules_on_R_equal_literal_implementations_on_the_series(seed, rho):
    rng = np.random.default_rng(seed)
    n, W = 700, 61
    e = rng.standard_normal(n + 200)
    h = np.empty_like(e)
    h[0] = e[0]
    for k in range(1, len(e)):
        h[k] = rho * h[k - 1] + e[k]
    h = h[200:] - h[200:].mean()
    R = np.array([h[i:] @ h[: n - i] for i in range(W)]) / n  # Eq. 10 / Eq. 17 with f = 1
    assert flat_top_lags(R, n) == _literal_flat_top(h, W - 1)
    assert newey_west_lags(R, n, cap=10_000) == min(_literal_newey_west(h), W - 1)


def test_flat_top_with_one_count_per_model_is_each_models_own_call():
    """n_samples as an array (the bank's counts after a residual burn-in) gives every model
    what the scalar call with its count gives: threshold, run length (K = 6 above 1e25) and the
    limits n - 1 and min_lags."""
    rng = np.random.default_rng(0)
    for _ in range(300):
        M, W = int(rng.integers(1, 8)), int(rng.integers(1, 60))
        R = 0.3 * rng.standard_normal((M, W)) + rng.uniform(0.3, 0.99, (M, 1)) ** np.arange(W)
        R[:, 0] = np.abs(R[:, 0]) + 0.5
        if rng.random() < 0.2:
            R[0, 0] = 0.0
        n = rng.choice([1.0, 1.5, 2.0, 7.0, 60.0, 500.0, 1e4, 1e26], M)
        cap = int(rng.integers(1, 70))
        lo = min(int(rng.integers(0, 5)), cap)
        per_model = flat_top_lags(R, n, cap=cap, min_lags=lo)
        alone = [flat_top_lags(R[j], n[j], cap=cap, min_lags=lo) for j in range(M)]
        assert per_model.dtype == np.int64 and list(per_model) == [int(L) for L in alone]
    R = geometric(0.7, 51)[None, :] * np.array([[1.0], [0.9], [1.1]])
    R[1, 20:] += 0.05
    n = np.array([120.0, 5000.0, 60.0])  # every count above the lags held, then one below
    for counts in (n[:2], n):
        assert list(flat_top_lags(R[: len(counts)], counts, cap=50)) == [
            int(flat_top_lags(R[j], counts[j], cap=50)) for j in range(len(counts))]
    with pytest.raises(ValueError, match="n_samples has shape"):
        flat_top_lags(np.ones((3, 10)), np.full(2, 100.0))


def _literal_flat_top_on_R(R: np.ndarray, n: float, cap: int) -> int:
    """The rule on one model's ``R(0..W-1)`` as written: the first m whose next K lags are
    all insignificant, L = 2m within [0, cap]; cap when no such run fits."""
    crit = 2 * math.sqrt(math.log10(n) / n)
    K = max(5, math.ceil(math.sqrt(math.log10(n))))
    for m in range(len(R) - K):
        if all(abs(R[m + j]) < crit * R[0] for j in range(1, K + 1)):
            return min(2 * m, cap)
    return cap


def test_few_and_many_models_agree_with_the_rule_written_out():
    """A few models (a node's) and hundreds (a Monte Carlo bank's) take different searches
    for the run of insignificant lags; both give each model the literal rule's lag."""
    rng = np.random.default_rng(11)
    W, cap = 51, 50
    R = 0.2 * rng.standard_normal((300, W)) + rng.uniform(0.2, 0.98, (300, 1)) ** np.arange(W)
    R[:, 0] = np.abs(R[:, 0]) + 0.5
    n = rng.uniform(60.0, 5000.0, 300)
    expected = [_literal_flat_top_on_R(R[j], n[j], cap) for j in range(300)]
    assert flat_top_lags(R, n, cap=cap).tolist() == expected  # hundreds at once
    few = [flat_top_lags(R[j : j + 6], n[j : j + 6], cap=cap).tolist() for j in range(0, 300, 6)]
    assert [L for block in few for L in block] == expected
    for j in range(0, 300, 6):  # one count for the few
        block = flat_top_lags(R[j : j + 6], float(n[j]), cap=cap).tolist()
        assert block == [_literal_flat_top_on_R(R[i], n[j], cap) for i in range(j, j + 6)]


def test_score_correlations_follow_the_factorisation_of_eq_11():
    # One regressor column x, residual v: sum_j x_j x_(j-i) v_j v_(j-i) over sum x^2 v^2 is
    # rho(i) g(i) when v is independent of x; check the algebra on the defining sums.
    rng = np.random.default_rng(7)
    x = np.sin(np.arange(400) * 0.05) + 0.1 * rng.standard_normal(400)
    R = np.array([1.0, 0.6, 0.3, 0.1])
    lam = np.array([[x @ x], [2 * x[1:] @ x[:-1]], [2 * x[2:] @ x[:-2]], [2 * x[3:] @ x[:-3]]])
    rho = correlations(R, lam)[0]
    g = [1.0] + [x[i:] @ x[:-i] / (x @ x) for i in (1, 2, 3)]
    np.testing.assert_allclose(rho, R * np.array(g), rtol=1e-12)


# ------------------------------------------------------------------ the case the rule is chosen for
def test_flat_top_keeps_the_whole_moving_average_of_the_papers_differentiator():
    # White noise through the 5-point cubic differentiator (montecarlo.PAPER_DIFFERENTIATOR):
    # rho = (1, -.123, -.492, .123, -.008), summing to a zero long-run variance. At n = 600
    # (threshold .136) lag 3 is "insignificant", m_hat = 2, and M = 2 m_hat = 4 keeps all four
    # lags; m_hat alone would stop at lag 2, where the truncated sum is negative.
    c = derivative_weights(DifferentiatorConfig(window=5, order=3, lag=2), 1.0)
    R = ma_acf(c, 51)
    assert R[1:5] == pytest.approx([-0.1231, -0.4923, 0.1231, -0.0077], abs=1e-4)
    assert flat_top_lags(R, 600) == 4  # M = 2 m_hat
    assert flat_top_lags(R, 600) // 2 == 2  # m_hat
    assert 1 + 2 * R[1:3].sum() < 0
    assert abs(1 + 2 * R[1:5].sum()) < 1e-12
    # The AR(1) plug-ins read only rho(1) = -.123: a short bandwidth (Andrews, truncated:
    # 0.6611 (alpha(2) 600)^(1/5) = 1.24), or NW's s0 = 0 sends its bandwidth to the cap.
    assert andrews_lags(R, 600) == 1
    assert newey_west_lags(R, 600, cap=50) == 50


# ------------------------------------------------------------------ monotonic behaviour
@pytest.mark.parametrize("rule", RULES)
def test_more_correlation_gives_no_fewer_lags(rule):
    n, W = 2000, 201
    lags = [int(select_lags(geometric(r, W), n, rule).lags) for r in (0.0, 0.2, 0.5, 0.8, 0.9, 0.95)]
    assert lags == sorted(lags), lags
    assert lags[0] == 0  # white noise: no lags
    assert lags[-1] > lags[1] > 0, lags


# Median chosen L on white noise over 20 seeded series of 1000 samples: the flat-top rule's
# threshold (3.5 sigma at n = 1000) leaves white noise at L = 0; NW94's ratio s1/s0 of noisy
# sums is itself noisy on white noise (a known property of the plug-in), hence its looser bound.
WHITE_MEDIAN = {"flat_top": 0, "andrews": 0, "andrews_bartlett": 1, "newey_west": 8}


@pytest.mark.parametrize("rule", RULES)
def test_white_noise_series_get_few_lags_and_ar_series_many(rule):
    n, W = 1000, 51
    white, ar = [], []
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        e = rng.standard_normal(n)
        v = np.empty(n)
        v[0] = e[0]
        for k in range(1, n):
            v[k] = 0.9 * v[k - 1] + e[k]
        for series, out in ((e, white), (v, ar)):
            R = np.array([series[i:] @ series[: n - i] for i in range(W)]) / n
            out.append(int(select_lags(R, n, rule).lags))
    assert np.median(white) <= WHITE_MEDIAN[rule], white
    assert min(ar) >= 15, ar  # AR(1) 0.9: correlation time about 10 samples
    assert min(ar) > np.percentile(white, 90), (white, ar)


def test_score_lags_are_no_more_than_residual_lags_when_regressors_decorrelate():
    # |g_a(i)| <= 1 shrinks every score correlation, so the flat-top L can only fall; a
    # regressor whose lag products vanish (g = 0) contributes L = 0, and the model takes the max.
    R = geometric(0.8, 51)
    n = 1000
    lam = np.zeros((51, 2))
    lam[0] = 1.0
    lam[1:, 0] = 2.0  # g = 1: the score is the residual
    assert score_flat_top_lags(R, n, lam) == flat_top_lags(R, n)
    lam[1:, 0] = 2.0 * 0.5 ** np.arange(1, 51)  # fast-decorrelating regressor
    assert score_flat_top_lags(R, n, lam) < flat_top_lags(R, n)
    lam[:, 1] = np.nan  # padding of a smaller model: ignored
    assert score_flat_top_lags(R, n, lam) == score_flat_top_lags(R, n, lam[:, :1])


# ------------------------------------------------------------------ edge cases
@pytest.mark.parametrize("rule", RULES)
def test_degenerate_inputs_give_min_lags(rule):
    R = geometric(0.9, 51)
    assert select_lags(np.zeros(51), 1000, rule, min_lags=3).lags == 3  # R(0) = 0: exact fit
    bad = R.copy()
    bad[5] = np.nan
    if rule.startswith("andrews"):
        assert select_lags(bad, 1000, rule).lags > 0  # only rho(1) is read
    else:
        assert select_lags(bad, 1000, rule, min_lags=2).lags == 2
    assert select_lags(np.full(51, np.nan), 1000, rule, min_lags=2).lags == 2  # not ready
    assert select_lags(R[:1], 1000, rule, min_lags=2).lags == 0  # one lag held: L <= W - 1
    assert select_lags(R, 1, rule, min_lags=2).lags == 0  # one sample: L <= n - 1
    assert select_lags(R, 4, rule, cap=50).lags <= 3


@pytest.mark.parametrize("rule", RULES)
def test_cap_and_min_lags_bound_every_rule(rule):
    R = geometric(0.99, 201)
    assert select_lags(R, 10_000, rule, cap=30).lags == 30
    assert select_lags(geometric(0.0, 201), 10_000, rule, min_lags=4).lags == 4
    with pytest.raises(ValueError):
        select_lags(R, 1000, rule, cap=-1)
    with pytest.raises(ValueError):
        select_lags(R, 1000, rule, min_lags=1.5)


def test_andrews_limits_rho_near_one():
    # |rho| is limited to 0.97 (Andrews & Monahan 1992): rho = 1 and rho = 0.97 give the same
    # finite bandwidth, rho = -1 that of -0.97.
    n = 500
    for window in ("bartlett", "truncated"):
        at_one = andrews_lags(np.ones(400), n, window=window)
        assert at_one == andrews_lags(geometric(0.97, 400), n, window=window)
        assert 0 < at_one < 399
        assert andrews_lags(geometric(-1.0, 400), n, window=window) == andrews_lags(
            geometric(-0.97, 400), n, window=window
        )
    # Hand value: rho = .97, Bartlett: alpha(1) = 4 .9409 / (.0009 * 3.8809) = 1077.5,
    # S = 1.1447 (538770)^(1/3) = 93.4 -> L = 93.
    assert andrews_lags(np.ones(400), n, window="bartlett") == 93


def test_vectorised_over_models_matches_one_by_one():
    rng = np.random.default_rng(3)
    Rs = np.stack([geometric(r, 41) for r in (0.0, 0.3, 0.7, 0.9, -0.5, 0.95)]).reshape(2, 3, 41)
    Rs = Rs + 0.01 * rng.standard_normal(Rs.shape) * (np.arange(41) > 0)
    for rule in RULES:
        together = select_lags(Rs, 800, rule, cap=40).lags
        assert together.shape == (2, 3)
        one = [[int(select_lags(Rs[a, b], 800, rule, cap=40).lags) for b in range(3)] for a in range(2)]
        assert together.tolist() == one


def test_unknown_rule_is_refused():
    with pytest.raises(ValueError):
        select_lags(geometric(0.5, 10), 100, "bandwidth")
    with pytest.raises(ValueError):
        andrews_lags(geometric(0.5, 10), 100, window="parzen")


# ------------------------------------------------------------------ on the estimator's own autocorrelation
def test_rule_on_a_bank_residual_autocorrelation():
    # Equation error AR(1) rho = 0.9 against white, one model each, 50 lags held (Eq. 17).
    rng = np.random.default_rng(11)
    n = 1000
    t = np.arange(n) / 50.0
    X = np.column_stack([np.ones(n), np.sin(2 * np.pi * 0.4 * t), np.cos(2 * np.pi * 1.1 * t)])
    e = rng.standard_normal(n)
    ar = np.empty(n)
    ar[0] = e[0]
    for k in range(1, n):
        ar[k] = 0.9 * ar[k - 1] + e[k]
    bank = EstimatorBank((3, 3), EstimatorOptions(lags=50))
    z = np.column_stack([X @ [1.0, 2.0, 3.0] + 0.1 * e, X @ [1.0, 2.0, 3.0] + 0.1 * ar])
    for k in range(n):
        bank.update(np.stack([X[k], X[k]]), z[k])
    R = np.stack([bank.autocorrelation(0), bank.autocorrelation(1)])
    L = select_lags(R, bank.n_samples, "flat_top", cap=bank.options.held).lags
    assert L[0] <= 4
    assert L[1] >= 20
