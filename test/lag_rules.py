"""Lag rules the estimator does not use, kept as the tests' points of comparison.

``docs/studies/automatic_lags/REPORT.md`` compares Politis' flat-top rule (the estimator's,
:mod:`rls_uncertainty.estimator.lag_selection`) with the AR(1) plug-in rules of Andrews (1991)
and Newey & West (1994), and with the flat-top rule applied to each parameter's score instead
of the residual. Those alternatives live here, for the tests that show why the flat-top rule
on the residual was chosen. Same conventions as the package's rule: ``R`` ``(..., W)`` holds
``R(0..W-1)``, ``n`` the sample count, ``L`` the largest retained lag in ``[min_lags, min(cap,
W - 1, n - 1)]``, and ``min_lags`` for fewer than two samples or an unusable ``R``.

``"andrews"`` -- Andrews (1991), "Heteroskedasticity and autocorrelation consistent
covariance matrix estimation", Econometrica 59(3), 817-858, Eqs. 6.2-6.4 and Table I, with
the AR(1) approximation ``rho_hat = rho(1)`` (the Yule-Walker estimate):
``alpha(1) = 4 rho^2 / ((1-rho)^2 (1+rho)^2)``, ``alpha(2) = 4 rho^2 / (1-rho)^4``;
bandwidth ``S = 1.1447 (alpha(1) n)^(1/3)`` for the Bartlett window (``L = floor(S)``,
weights ``1 - i/(L+1)`` as in R sandwich's ``NeweyWest``) or ``S = 0.6611 (alpha(2)
n)^(1/5)`` for the truncated window (``L = floor(S)``). ``|rho|`` is limited to 0.97, the
bound Andrews & Monahan (1992, Econometrica 60(4), 953-966) put on the prewhitening AR
coefficient, so that ``rho -> 1`` gives a large finite bandwidth (then the cap).

``"newey_west"`` -- Newey & West (1994), "Automatic lag selection in covariance matrix
estimation", Rev. Economic Studies 61(4), 631-653, Bartlett kernel without prewhitening:
``n0 = floor(4 (n/100)^(2/9))`` autocorrelations, ``s0 = 1 + 2 sum_{i=1}^{n0} rho(i)``,
``s1 = 2 sum_{i=1}^{n0} i rho(i)``, ``gamma = 1.1447 ((s1/s0)^2)^(1/3)``,
``m = gamma n^(1/3)``, ``L = floor(m)``, Bartlett window. A non-positive ``s0`` (the
estimated long-run variance cancels, as for differentiated noise) makes ``gamma`` unbounded:
``L = cap``.

**Scores** (``lambda_diag``): under the factorisation behind Eq. 11 (the residual
autocorrelation does not depend on the regressors) the lag-``i`` autocorrelation of the score
of parameter ``a`` is ``rho_a(i) = rho(i) g_a(i)`` with the regressor autocorrelation ``g_a(i)
= Lambda_aa(i) / (2 Lambda_aa(0))`` for ``i >= 1`` (paper's convention: ``Lambda(0) = sum x
x'``, ``Lambda(i) = sum x_j x_(j-i)' + x_(j-i) x_j'``). Each parameter gets its own ``L_a``; the
model's ``L`` is ``max_a L_a``. Parameters whose ``Lambda_aa(0)`` is not positive and finite
(padding, a regressor that never moved) are ignored.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple, get_args

import numpy as np
import numpy.typing as npt

from rls_uncertainty.estimator.lag_selection import _limits, flat_top_lags

Rule = Literal["flat_top", "andrews", "andrews_bartlett", "newey_west"]
RULES: tuple[Rule, ...] = get_args(Rule)
# The window each rule's bandwidth is derived for (the estimator's window names).
RULE_WINDOWS: dict[str, str] = {
    "flat_top": "truncated",
    "andrews": "truncated",
    "andrews_bartlett": "bartlett",
    "newey_west": "bartlett",
}

RHO_LIMIT = 0.97  # Andrews & Monahan (1992)


class LagChoice(NamedTuple):
    """Largest retained lag per model and the window the rule's bandwidth belongs to."""

    lags: np.ndarray
    window: str


def correlations(R: npt.ArrayLike, lambda_diag: npt.ArrayLike | None = None) -> np.ndarray:
    """Autocorrelations of the series a rule looks at, ``(..., P, W)``: ``P = 1``, the
    residual's ``R(i)/R(0)``, without ``lambda_diag``; with ``lambda_diag`` ``(..., W, n)``
    (the diagonals ``Lambda_aa(i)``) ``P = n``, the scores'. Entries of ignored parameters and
    of models with unusable ``R`` are NaN."""
    R = np.asarray(R, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        r0 = R[..., :1]
        rho = np.where((r0 > 0.0) & np.isfinite(r0), R / r0, np.nan)
        if lambda_diag is None:
            return rho[..., None, :]
        lam = np.swapaxes(np.asarray(lambda_diag, dtype=float), -1, -2)  # (..., n, W)
        if lam.shape[-1] != R.shape[-1]:
            raise ValueError(f"lambda_diag has {lam.shape[-1]} lags, R has {R.shape[-1]}")
        l0 = lam[..., :1]
        g = np.where((l0 > 0.0) & np.isfinite(l0), lam / (2.0 * l0), np.nan)
        g[..., :1] = np.where(np.isfinite(g[..., :1]), 1.0, np.nan)
        return rho[..., None, :] * g


def score_flat_top_lags(R: npt.ArrayLike, n: float, lambda_diag: npt.ArrayLike, *, cap: int | None = None,
                        min_lags: int = 0) -> np.ndarray:
    """The flat-top rule on each parameter's score; the model takes the largest ``L_a``."""
    return flat_top_lags(correlations(R, lambda_diag), n, cap=cap, min_lags=min_lags).max(axis=-1)


def _finish(per_series: np.ndarray, usable: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Model lag = max over its usable series, clipped to ``[lo, hi]``; ``lo`` where none."""
    L = np.where(usable, per_series, -1).max(axis=-1)
    L = np.where(L < 0, lo, np.minimum(L, hi))
    return np.maximum(L, lo).astype(np.int64)


def _usable(rho: np.ndarray) -> npt.NDArray[np.bool_]:
    usable: npt.NDArray[np.bool_] = np.isfinite(rho).all(axis=-1)
    return usable


def andrews_lags(R: npt.ArrayLike, n_samples: float, *, cap: int | None = None, window: str = "truncated",
                 min_lags: int = 0) -> np.ndarray:
    """Andrews (1991) AR(1) plug-in bandwidth, ``L = floor(S)``; see the module docstring."""
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    n = float(n_samples)
    hi, lo = _limits(W, n, cap, min_lags)
    rho = correlations(R)
    usable = _usable(rho[..., : min(W, 2)])
    if n < 2 or W < 2:
        return np.full(R.shape[:-1], lo, dtype=np.int64)
    r = np.clip(np.nan_to_num(rho[..., 1], nan=0.0), -RHO_LIMIT, RHO_LIMIT)
    if window == "bartlett":
        alpha = 4.0 * r**2 / ((1.0 - r) ** 2 * (1.0 + r) ** 2)
        S = 1.1447 * np.cbrt(alpha * n)
    elif window == "truncated":
        alpha = 4.0 * r**2 / (1.0 - r) ** 4
        S = 0.6611 * (alpha * n) ** 0.2
    else:
        raise ValueError(f"window must be 'truncated' or 'bartlett', got {window!r}")
    L = np.floor(np.minimum(S, hi)).astype(np.int64)
    return _finish(L, usable, lo, hi)


def newey_west_lags(R: npt.ArrayLike, n_samples: float, *, cap: int | None = None, min_lags: int = 0) -> np.ndarray:
    """Newey & West (1994) plug-in for the Bartlett window, ``L = floor(m)``; see the module
    docstring."""
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    n = float(n_samples)
    hi, lo = _limits(W, n, cap, min_lags)
    if n < 2 or W < 2:
        return np.full(R.shape[:-1], lo, dtype=np.int64)
    n0 = min(math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)), W - 1)
    rho = correlations(R)[..., : n0 + 1]
    usable = _usable(rho)
    if n0 < 1:
        return _finish(np.zeros(rho.shape[:-1], dtype=np.int64), usable, lo, hi)
    r = np.nan_to_num(rho[..., 1:], nan=0.0)
    i = np.arange(1, n0 + 1, dtype=float)
    s0 = 1.0 + 2.0 * r.sum(axis=-1)
    s1 = 2.0 * (r * i).sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma = 1.1447 * np.cbrt((s1 / s0) ** 2)
        m = np.where(s0 > 0.0, gamma * np.cbrt(n), np.inf)
    L = np.floor(np.minimum(m, hi)).astype(np.int64)
    return _finish(L, usable, lo, hi)


def select_lags(R: npt.ArrayLike, n_samples: float, rule: str = "flat_top", *, cap: int | None = None,
                min_lags: int = 0) -> LagChoice:
    """The largest retained lag of every model by ``rule``, with the window that rule's
    bandwidth is meant for."""
    if rule == "flat_top":
        L = flat_top_lags(R, n_samples, cap=cap, min_lags=min_lags)
    elif rule == "andrews":
        L = andrews_lags(R, n_samples, cap=cap, min_lags=min_lags)
    elif rule == "andrews_bartlett":
        L = andrews_lags(R, n_samples, cap=cap, window="bartlett", min_lags=min_lags)
    elif rule == "newey_west":
        L = newey_west_lags(R, n_samples, cap=cap, min_lags=min_lags)
    else:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    return LagChoice(L, RULE_WINDOWS[rule])
