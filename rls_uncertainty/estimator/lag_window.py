"""The lag window ``c_i`` applied to the residual autocorrelation in Eqs. 9, 20 and 22.

``truncated`` is Eq. 22: lags ``0..n_tau`` with weight 1, the others dropped. ``bartlett``
weights lag ``i`` by ``1 - i/(n_tau + 1)``; its Toeplitz kernel is positive semi-definite,
so by the Schur product theorem so is the covariance, whereas the uniform truncation can
make the covariance indefinite. With all lags kept (Eq. 20), ``n_tau = k - 1``.
"""

from __future__ import annotations

import numpy as np

from .options import check_window

__all__ = ["lag_weights"]


def lag_weights(n_tau: int, window: str, count: int | None = None) -> np.ndarray:
    """Weights ``c_i`` of lags ``i = 0..count-1`` (default ``count = n_tau + 1``).

    ``n_tau`` is the largest retained lag of Eq. 22; lags beyond it get 0.
    """
    check_window(window)
    count = n_tau + 1 if count is None else count
    i = np.arange(count, dtype=float)
    if window == "truncated":
        w = np.ones(count)
    else:
        w = 1.0 - i / (n_tau + 1.0)
    w[i > n_tau] = 0.0
    return w
