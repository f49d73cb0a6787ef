"""Automatic choice of the number of residual-autocorrelation lags kept in Eq. 22.

Grauer & Morelli (2016) truncate the colored-residual covariance

    cov(theta_k) = D_k [ sum_{i=0}^{L} c_i R_k(i) Lambda_k(i) ] D_k          (Eq. 22)

at a hand-picked ``L`` ("a safe number ... would be about 50"; "there is no procedure for
selecting how many lags to maintain"). The middle term is a kernel (lag-window) estimate of the
long-run variance of the score ``h_k = x_k v_k``, so the bandwidth rules of the HAC literature
apply. This module computes three published rules from what the recursive estimator holds at
every sample: the residual autocorrelation ``R_k(0..W-1)`` (Eq. 17), the sample count, and
optionally the diagonals of the lag products ``Lambda_k(i)`` (Eqs. 18-19, 21). numpy only;
every function is vectorised over models (leading axes) and costs ``O(W n)`` per model.

The series whose correlation is measured
----------------------------------------
*Residual* (``lambda_diag=None``): ``rho(i) = R(i) / R(0)``.

*Score* (``lambda_diag`` given): under the factorisation behind Eq. 11 (the residual
autocorrelation does not depend on the regressors) the lag-``i`` autocorrelation of the score
of parameter ``a`` is ``rho_a(i) = rho(i) g_a(i)`` with the regressor autocorrelation
``g_a(i) = Lambda_aa(i) / (2 Lambda_aa(0))`` for ``i >= 1`` (paper's convention: ``Lambda(0) =
sum x x'``, ``Lambda(i) = sum x_j x_(j-i)' + x_(j-i) x_j'``). Each parameter gets its own
``L_a``; the model's ``L`` is ``max_a L_a`` (one ``L`` per model keeps its covariance one
matrix; the largest protects every parameter). Parameters whose ``Lambda_aa(0)`` is not
positive and finite (padding, a regressor that never moved) are ignored.

Rules (``n`` the sample count ``k``; ``L`` the largest retained lag, ``0 <= L <= cap``)
------------------------------------------------------------------------------------------
``"flat_top"`` -- Politis (2003), "Adaptive bandwidth choice", J. Time Series Analysis
24(5), 517-533, Remark 2.3; Politis & White (2004), Econometric Reviews 23(1), 53-70,
Section 3.2 and footnote c. ``m_hat`` is the smallest ``m >= 0`` such that
``|rho(m+j)| < c sqrt(log10(n) / n)`` for ``j = 1..K``, with ``c = 2`` and
``K = max(5, ceil(sqrt(log10 n)))``; the flat-top lag window then has bandwidth
``M = 2 m_hat``. Here ``L = min(2 m_hat, cap)`` with the **truncated** window of Eq. 22
(weight 1 on lags ``0..L``): the rectangular window is the flat-top family's limit, has no
bias from the lags it keeps, and, unlike the Bartlett window, lets the anti-correlated lags
of differentiated noise cancel the lag-0 term (docs/estimator.md). When no
run of ``K`` insignificant lags fits inside the ``W`` lags held, ``L = cap``.

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

Edge cases, for every rule: fewer than two samples, ``R(0) <= 0`` (an exact fit: the
covariance is zero whatever ``L``) or non-finite ``R`` give ``L = min_lags`` (a model that is
not ready has NaN ``R``); ``L`` is never above ``cap``, ``W - 1`` or ``n - 1``, and never below
``min_lags`` where those allow it.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple, get_args

import numpy as np
import numpy.typing as npt

__all__ = [
    "RULES",
    "RULE_WINDOWS",
    "LagChoice",
    "Rule",
    "andrews_lags",
    "correlations",
    "flat_top_lags",
    "newey_west_lags",
    "politis_threshold",
    "select_lags",
]

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
    """Largest retained lag per model (``int`` array, the leading shape of ``R``) and the
    window the rule's bandwidth belongs to (``"truncated"`` or ``"bartlett"``)."""

    lags: np.ndarray
    window: str


def correlations(R: npt.ArrayLike, lambda_diag: npt.ArrayLike | None = None) -> np.ndarray:
    """Autocorrelations of the series each rule looks at, ``(..., P, W)``.

    ``R``: ``(..., W)`` residual autocorrelation ``R(0..W-1)`` (Eq. 17; lag sums ``S(i)``
    give the same ratios). ``lambda_diag``: ``None`` (``P = 1``, the residual: ``R(i)/R(0)``)
    or ``(..., W, n)`` diagonals ``Lambda_aa(i)`` in the paper's convention (``P = n``, the
    scores: ``R(i)/R(0) * Lambda_aa(i) / (2 Lambda_aa(0))`` for ``i >= 1``). Entries of
    ignored parameters and of models with unusable ``R`` are NaN.
    """
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


def politis_threshold(n: float, c: float = 2.0) -> float:
    """``c sqrt(log10(n) / n)``: the flat-top rule's bound on an insignificant correlation."""
    return c * math.sqrt(math.log10(n) / n) if n > 1 else math.inf


def _limits(W: int, n: float, cap: int | None, min_lags: int) -> tuple[int, int]:
    hi = W - 1
    if cap is not None:
        if isinstance(cap, bool) or int(cap) != cap or cap < 0:
            raise ValueError(f"cap must be an integer >= 0, got {cap!r}")
        hi = min(hi, int(cap))
    hi = min(hi, max(math.floor(n) - 1, 0))
    if isinstance(min_lags, bool) or int(min_lags) != min_lags or min_lags < 0:
        raise ValueError(f"min_lags must be an integer >= 0, got {min_lags!r}")
    return max(hi, 0), min(int(min_lags), max(hi, 0))


def _finish(per_series: np.ndarray, usable: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Model lag = max over its usable series, clipped to ``[lo, hi]``; ``lo`` where none."""
    L = np.where(usable, per_series, -1).max(axis=-1)
    L = np.where(L < 0, lo, np.minimum(L, hi))
    return np.maximum(L, lo).astype(np.int64)


def _usable(rho: np.ndarray) -> npt.NDArray[np.bool_]:
    usable: npt.NDArray[np.bool_] = np.isfinite(rho).all(axis=-1)
    return usable


def flat_top_lags(R: npt.ArrayLike, n_samples: float | npt.ArrayLike, *, cap: int | None = None,
                  lambda_diag: npt.ArrayLike | None = None, c: float = 2.0, K: int | None = None,
                  min_lags: int = 0, factor: int = 2) -> np.ndarray:
    """Politis (2003) / Politis & White (2004) flat-top rule: ``L = factor * m_hat``
    (``factor = 2`` is their ``M = 2 m_hat``); see the module docstring.

    Written for a per-sample call (about 15 numpy operations on ``(M, W)`` arrays whatever
    ``M``): a lag ``i`` is significant where ``|R(i)| >= threshold R(0)``. ``n_samples`` is
    one count for every model, or an array of ``R``'s leading shape with each model's own
    count (each model then gets exactly what a call with its count alone gives).
    """
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    if np.ndim(n_samples) > 0:
        return _flat_top_per_model(R, np.asarray(n_samples, dtype=float), cap, lambda_diag, c, K, min_lags, factor)
    n = float(n_samples)  # type: ignore[arg-type]  # (a scalar here)
    hi, lo = _limits(W, n, cap, min_lags)
    if n < 2 or W < 2:
        return np.full(R.shape[:-1], lo, dtype=np.int64)
    if K is None:
        K = max(5, math.ceil(math.sqrt(math.log10(n))))
    return _flat_top(R, politis_threshold(n, c), K, hi, lo, lambda_diag, factor)


def _flat_top(R: np.ndarray, thr: float | np.ndarray, K: int, hi: int | np.ndarray, lo: int | np.ndarray,
              lambda_diag: npt.ArrayLike | None, factor: int) -> np.ndarray:
    """The rule with the threshold ``thr``, run length ``K`` and limits ``[lo, hi]``, each a
    scalar or one value per model (``R``'s leading shape)."""
    W = R.shape[-1]
    per_model = np.ndim(thr) > 0
    # Usable models: R(0) > 0 and every R finite (a sum is NaN or Inf otherwise).
    ok = (R[..., 0] > 0.0) & np.isfinite(R.sum(axis=-1))
    if lambda_diag is None:
        sig = np.abs(R[..., 1:]) >= (thr[..., None] if per_model else thr) * R[..., :1]  # type: ignore[index]  # lags 1..W-1
        hi_series = hi
    else:
        rho = correlations(R, lambda_diag)  # (..., P, W); NaN compares False (ignored)
        sig = np.abs(rho[..., 1:]) >= (thr[..., None, None] if per_model else thr)  # type: ignore[index]
        hi_series = np.asarray(hi)[..., None] if per_model else hi  # per series (..., P)
    if W - 1 < K:  # no room for a run of K lags: the correlation may go on
        L = np.broadcast_to(np.asarray(hi_series, dtype=np.int64), sig.shape[:-1])
    else:
        # counts[m] = significant lags among m+1..m+K, m = 0..W-1-K
        csum = np.cumsum(sig, axis=-1)
        counts = csum[..., K - 1 :].copy()
        counts[..., 1:] -= csum[..., : W - 1 - K]
        run = counts == 0
        L = np.where(run.any(axis=-1), factor * run.argmax(axis=-1), hi_series)
    if lambda_diag is not None:
        L = L.max(axis=-1)  # the model's L protects each of its parameters
    L = np.where(ok, np.minimum(L, hi), lo)
    return np.maximum(L, lo).astype(np.int64)


def _flat_top_per_model(R: np.ndarray, n: np.ndarray, cap: int | None, lambda_diag: npt.ArrayLike | None,
                        c: float, K: int | None, min_lags: int, factor: int) -> np.ndarray:
    """:func:`flat_top_lags` with one count per model: the threshold and limits of the scalar
    call, evaluated elementwise (numpy's log10 and sqrt, as ``math``'s correctly rounded here),
    then one pass per distinct run length (``K = 5`` for every count up to 1e25)."""
    lead, W = R.shape[:-1], R.shape[-1]
    if n.shape != lead:
        raise ValueError(f"n_samples has shape {n.shape}, R has {lead} models")
    top, top_lo = _limits(W, W + 1.0, cap, min_lags)  # checks cap and min_lags; the limits without n
    hi: int | np.ndarray
    lo: int | np.ndarray
    if W >= 2 and n.min() >= W + 1.0:  # (the usual case) more samples than lags held: the limits of W
        small, hi, lo, count = None, top, top_lo, n
    else:
        small = n < 2.0 if W >= 2 else np.ones(lead, dtype=bool)
        hi = np.maximum(np.minimum(np.floor(n) - 1.0, top), 0.0).astype(np.int64)
        lo = np.minimum(int(min_lags), hi)
        count = np.where(small, 2.0, n)  # (small: replaced by lo below)
    log_count = np.log10(count)
    thr = c * np.sqrt(log_count / count)
    if K is not None or count.max() <= 1e25:  # K = max(5, ceil(sqrt(log10 n))) is 5 up to 1e25
        L = _flat_top(R, thr, 5 if K is None else K, hi, lo, lambda_diag, factor)
        return L if small is None else np.where(small, lo, L)
    run_length = np.maximum(5, np.ceil(np.sqrt(log_count))).astype(np.int64)
    lengths = np.unique(run_length)
    if lengths.size == 1:
        out = _flat_top(R, thr, int(lengths[0]), hi, lo, lambda_diag, factor)
    else:
        out = np.empty(lead, dtype=np.int64)
        for length in lengths.tolist():
            chosen = run_length == length
            out[chosen] = _flat_top(R, thr, length, hi, lo, lambda_diag, factor)[chosen]
    return out if small is None else np.where(small, lo, out)


def andrews_lags(R: npt.ArrayLike, n_samples: float, *, cap: int | None = None,
                 lambda_diag: npt.ArrayLike | None = None, window: str = "truncated",
                 min_lags: int = 0) -> np.ndarray:
    """Andrews (1991) AR(1) plug-in bandwidth, ``L = floor(S)``; see the module docstring."""
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    n = float(n_samples)
    hi, lo = _limits(W, n, cap, min_lags)
    rho = correlations(R, lambda_diag)
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


def newey_west_lags(R: npt.ArrayLike, n_samples: float, *, cap: int | None = None,
                    lambda_diag: npt.ArrayLike | None = None, min_lags: int = 0) -> np.ndarray:
    """Newey & West (1994) plug-in for the Bartlett window, ``L = floor(m)``; see the module
    docstring."""
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    n = float(n_samples)
    hi, lo = _limits(W, n, cap, min_lags)
    if n < 2 or W < 2:
        return np.full(R.shape[:-1], lo, dtype=np.int64)
    n0 = min(math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)), W - 1)
    rho = correlations(R, lambda_diag)[..., : n0 + 1]
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
                lambda_diag: npt.ArrayLike | None = None, min_lags: int = 0) -> LagChoice:
    """The largest retained lag of every model by ``rule`` (see the module docstring), with
    the window that rule's bandwidth is meant for."""
    if rule == "flat_top":
        L = flat_top_lags(R, n_samples, cap=cap, lambda_diag=lambda_diag, min_lags=min_lags)
    elif rule == "andrews":
        L = andrews_lags(R, n_samples, cap=cap, lambda_diag=lambda_diag, min_lags=min_lags)
    elif rule == "andrews_bartlett":
        L = andrews_lags(R, n_samples, cap=cap, lambda_diag=lambda_diag, window="bartlett",
                         min_lags=min_lags)
    elif rule == "newey_west":
        L = newey_west_lags(R, n_samples, cap=cap, lambda_diag=lambda_diag, min_lags=min_lags)
    else:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    return LagChoice(L, RULE_WINDOWS[rule])
