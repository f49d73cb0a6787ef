"""Batch least squares with the conventional and the colored-residual covariance (Eqs. 6-14).

The batch formulas the recursive estimator is compared with (Table 3, the Twin Otter and
Monte Carlo figures). :func:`batch_estimate` evaluates Eq. 11 in row blocks of the Toeplitz
matrix of Eq. 9, which bounds memory for long records; :func:`.reference.batch_reference`
is the same quantity written out as the paper's matrices.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .lag_window import lag_weights
from .options import check_window

__all__ = ["batch_estimate"]


def batch_estimate(
    X: np.ndarray,
    z: np.ndarray,
    lags: int | Literal["all"] = "all",
    window: str = "truncated",
    residuals: np.ndarray | None = None,
    *,
    forgetting: float = 1.0,
    noise_forgetting: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch least squares with conventional and colored-residual covariances.

    Returns ``(theta, cov_conventional, cov_corrected)``: Eq. 6 for ``theta``, Eq. 13-14 for
    the conventional covariance and Eq. 8-11 (the Toeplitz form of Eq. 9 with the sample
    autocorrelation of Eq. 10, lags beyond ``lags`` dropped or Bartlett-weighted) for the
    corrected one (``lags`` an integer, or ``"all"``). ``residuals`` replaces ``z - X theta``
    in Eq. 10 (for instance the residual history of a recursive estimator). ``forgetting < 1``
    gives the exponentially weighted formulas that :class:`~.bank.EstimatorBank` implements
    recursively (sample ``j`` of ``N`` weighted by ``f^(N-j)``). ``noise_forgetting`` ``f_R`` (default ``forgetting``)
    weights the autocorrelation of Eq. 10 by ``f_R^(N-j)`` instead; without given
    ``residuals`` they are then those of the ``f_R``-weighted fit (the batch counterpart of the
    bank's noise model; pass the bank's :meth:`~.bank.EstimatorBank.noise_residuals` history
    to reproduce its recursive covariance).
    """
    X = np.asarray(X, dtype=float)
    z = np.asarray(z, dtype=float).reshape(-1)
    if X.ndim != 2 or X.shape[0] != z.shape[0]:
        raise ValueError(f"X must be (N, n) with N = len(z); got {X.shape} and {z.shape}")
    check_window(window)
    N, n = X.shape
    wts = forgetting ** np.arange(N - 1, -1, -1, dtype=float)
    sw = np.sqrt(wts)
    theta = np.linalg.lstsq(X * sw[:, None], z * sw, rcond=None)[0]  # Eq. 6
    A = X.T @ (X * wts[:, None])
    D = np.linalg.inv(A)  # Eq. 6: the dispersion matrix
    g = forgetting if noise_forgetting is None else float(noise_forgetting)
    g_wts = wts if g == forgetting else g ** np.arange(N - 1, -1, -1, dtype=float)
    if residuals is not None:
        v = np.asarray(residuals, dtype=float).reshape(-1)
    elif g == forgetting:
        v = z - X @ theta  # Eq. 7
    else:  # Eq. 7 of the f_R-weighted fit (the noise model)
        sg = np.sqrt(g_wts)
        v = z - X @ np.linalg.lstsq(X * sg[:, None], z * sg, rcond=None)[0]
    if v.shape != (N,):
        raise ValueError(f"residuals must have {N} entries, got {v.shape}")
    L = N - 1 if lags == "all" else min(int(lags), N - 1)
    # Eq. 10 (weighted): R(i) = sum_{j>i} w_j v_j v_{j-i} / sum_j w_j (w = f_R^(N-j))
    R = np.array([np.dot(g_wts[i:] * v[i:], v[: N - i]) for i in range(L + 1)]) / g_wts.sum()
    kernel = R * lag_weights(L if lags == "all" else int(lags), window, L + 1)
    Xw = X * wts[:, None]
    if forgetting == 1.0:
        cov_conv = R[0] * D  # Eq. 13 with Eq. 14
    else:
        cov_conv = R[0] * D @ (Xw.T @ Xw) @ D
    # Eq. 11: D [sum_j sum_l x_j R(j-l) x_l'] D, in row blocks to bound memory.
    middle = np.zeros((n, n))
    cols = np.arange(N)
    block = max(1, min(N, 2_000_000 // max(N, 1)))
    for start in range(0, N, block):
        rows = np.arange(start, min(N, start + block))
        lag = np.abs(rows[:, None] - cols[None, :])
        T = np.where(lag <= L, kernel[np.minimum(lag, L)], 0.0)
        middle += Xw[rows].T @ (T @ Xw)
    cov_corr = D @ middle @ D
    return theta, cov_conv, cov_corr
