"""The automatic choice of the largest lag ``L`` kept in Eq. 22 (``lags="auto"``).

Grauer & Morelli (2016) truncate the colored-residual covariance

    cov(theta_k) = D_k [ sum_{i=0}^{L} c_i R_k(i) Lambda_k(i) ] D_k          (Eq. 22)

at a hand-picked ``L`` ("a safe number ... would be about 50"; "there is no procedure for
selecting how many lags to maintain"). The middle term is a kernel (lag-window) estimate of the
long-run variance of the score ``x_k v_k``, so the bandwidth rules of the HAC literature apply.
The estimator uses Politis' flat-top rule on the residual autocorrelation ``R_k(0..W-1)`` (Eq.
17) it holds at every sample; why this rule and not the AR(1) plug-ins of Andrews (1991) or
Newey & West (1994): ``docs/studies/automatic_lags/REPORT.md``. numpy only, vectorised over
models (leading axes), ``O(W)`` per model.

**The flat-top rule** -- Politis (2003), "Adaptive bandwidth choice", J. Time Series Analysis
24(5), 517-533, Remark 2.3; Politis & White (2004), Econometric Reviews 23(1), 53-70, Section
3.2 and footnote c. With ``rho(i) = R(i) / R(0)`` and ``n`` samples, ``m_hat`` is the smallest
``m >= 0`` such that ``|rho(m+j)| < 2 sqrt(log10(n) / n)`` for ``j = 1..K``, ``K = max(5,
ceil(sqrt(log10 n)))``; the flat-top lag window then has bandwidth ``M = 2 m_hat``. Here ``L =
2 m_hat`` with the **truncated** window of Eq. 22 (weight 1 on lags ``0..L``): the rectangular
window is the flat-top family's limit, has no bias from the lags it keeps, and, unlike the
Bartlett window, lets the anti-correlated lags of differentiated noise cancel the lag-0 term
(``docs/estimator.md``). When no run of ``K`` insignificant lags fits inside the ``W`` lags
held, ``L = cap``.

Edge cases: fewer than two samples, ``R(0) <= 0`` (an exact fit: the covariance is zero
whatever ``L``) or non-finite ``R`` give ``L = min_lags`` (a model that is not ready has NaN
``R``); ``L`` is never above ``cap``, ``W - 1`` or ``n - 1``, and never below ``min_lags``
where those allow it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["flat_top_lags", "politis_threshold"]

# Up to this many models the run search is a byte search per model (:func:`_first_runs`).
_FEW_MODELS = 32


def politis_threshold(n: float) -> float:
    """``2 sqrt(log10(n) / n)``: the flat-top rule's bound on an insignificant correlation."""
    return 2.0 * math.sqrt(math.log10(n) / n) if n > 1 else math.inf


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


# _limits_held's results (a few per configuration)
_HELD_LIMITS: dict[tuple[int, type, int | None, type, int], tuple[int, int]] = {}


def _limits_held(W: int, cap: int | None, min_lags: int) -> tuple[int, int]:
    """:func:`_limits` with more samples than lags held (``n = W + 1``), kept per arguments
    (their types too: a bool ``cap`` or ``min_lags`` is refused, not taken as 1)."""
    key = (W, type(cap), cap, type(min_lags), min_lags)
    limits = _HELD_LIMITS.get(key)
    if limits is None:
        limits = _limits(W, W + 1.0, cap, min_lags)
        if len(_HELD_LIMITS) >= 256:
            _HELD_LIMITS.clear()
        _HELD_LIMITS[key] = limits
    return limits


def flat_top_lags(R: npt.ArrayLike, n_samples: float | npt.ArrayLike, *, cap: int | None = None,
                  min_lags: int = 0) -> np.ndarray:
    """Politis (2003) / Politis & White (2004) flat-top rule, ``L = 2 m_hat`` (module
    docstring), for ``R`` ``(..., W)``: ``R(0..W-1)`` of each model (lag sums ``n R(i)`` give
    the same ratios).

    Written for a per-sample call (about 15 numpy operations on ``(M, W)`` arrays whatever
    ``M``): a lag ``i`` is significant where ``|R(i)| >= threshold R(0)``. ``n_samples`` is
    one count for every model, or an array of ``R``'s leading shape with each model's own
    count (each model then gets exactly what a call with its count alone gives).
    """
    R = np.asarray(R, dtype=float)
    W = R.shape[-1]
    if np.ndim(n_samples) > 0:
        return _flat_top_per_model(R, np.asarray(n_samples, dtype=float), cap, min_lags)
    n = float(n_samples)  # type: ignore[arg-type]  # (a scalar here)
    hi, lo = _limits(W, n, cap, min_lags)
    if n < 2 or W < 2:
        return np.full(R.shape[:-1], lo, dtype=np.int64)
    K = max(5, math.ceil(math.sqrt(math.log10(n))))
    return _flat_top(R, politis_threshold(n), K, hi, lo)


def _flat_top(R: np.ndarray, thr: float | np.ndarray, K: int, hi: int | np.ndarray, lo: int | np.ndarray) -> np.ndarray:
    """The rule with the threshold ``thr``, run length ``K`` and limits ``[lo, hi]``, each a
    scalar or one value per model (``R``'s leading shape)."""
    W = R.shape[-1]
    # Usable models: R(0) > 0 and every R finite (a sum is NaN or Inf otherwise).
    ok = (R[..., 0] > 0.0) & np.isfinite(R.sum(axis=-1))
    threshold = thr[..., None] if isinstance(thr, np.ndarray) else thr
    sig = np.abs(R[..., 1:]) >= threshold * R[..., :1]  # lags 1..W-1
    if W - 1 < K:  # no room for a run of K lags: the correlation may go on
        L = np.broadcast_to(np.asarray(hi, dtype=np.int64), sig.shape[:-1])
    elif sig.ndim == 2 and sig.shape[0] <= _FEW_MODELS:
        m_hat = _first_runs(sig, K)
        L = np.where(m_hat >= 0, 2 * m_hat, hi)  # M = 2 m_hat
    else:
        # counts[m] = significant lags among m+1..m+K, m = 0..W-1-K
        csum = np.cumsum(sig, axis=-1)
        counts = csum[..., K - 1 :].copy()
        counts[..., 1:] -= csum[..., : W - 1 - K]
        run = counts == 0
        L = np.where(run.any(axis=-1), 2 * run.argmax(axis=-1), hi)  # M = 2 m_hat
    L = np.where(ok, np.minimum(L, hi), lo)
    return np.maximum(L, lo).astype(np.int64)


def _first_runs(sig: np.ndarray, K: int) -> np.ndarray:
    """Per row of ``sig`` ``(M, W-1)``: the first ``m`` with ``sig[m:m+K]`` all False (lags
    ``m+1..m+K`` insignificant), -1 where there is none. A byte search per row: for the few
    models of a node or a replay, cheaper than the cumulative sums of :func:`_flat_top`'s
    general case, with the same result."""
    rows, width = sig.shape
    data = np.ascontiguousarray(sig).tobytes()  # one byte (0 or 1) per lag
    pattern = bytes(K)
    found = [data.find(pattern, j * width, (j + 1) * width) for j in range(rows)]
    return np.array([f - j * width if f >= 0 else -1 for j, f in enumerate(found)], dtype=np.int64)


def _flat_top_per_model(R: np.ndarray, n: np.ndarray, cap: int | None, min_lags: int) -> np.ndarray:
    """:func:`flat_top_lags` with one count per model: the threshold and limits of the scalar
    call, evaluated elementwise (numpy's log10 and sqrt, as ``math``'s correctly rounded here),
    then one pass per distinct run length (``K = 5`` for every count up to 1e25)."""
    lead, W = R.shape[:-1], R.shape[-1]
    if n.shape != lead:
        raise ValueError(f"n_samples has shape {n.shape}, R has {lead} models")
    top, top_lo = _limits_held(W, cap, min_lags)  # checks cap and min_lags; the limits without n
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
    thr = 2.0 * np.sqrt(log_count / count)
    if count.max() <= 1e25:  # K = max(5, ceil(sqrt(log10 n))) is 5 up to 1e25
        L = _flat_top(R, thr, 5, hi, lo)
        return L if small is None else np.where(small, lo, L)
    run_length = np.maximum(5, np.ceil(np.sqrt(log_count))).astype(np.int64)
    out = np.empty(lead, dtype=np.int64)
    for length in np.unique(run_length).tolist():
        chosen = run_length == length
        out[chosen] = _flat_top(R, thr, length, hi, lo)[chosen]
    return out if small is None else np.where(small, lo, out)
