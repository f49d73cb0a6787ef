"""What a bank keeps per lag: the recent samples and the lag-indexed sums.

For ``M`` models of at most ``n`` parameters and a lag capacity ``cap`` (``n_lags + 1``,
or growing by doubling when all lags are kept):

* **History**, newest first: ``x`` (column-scaled regressors) and ``v`` (residuals of
  Eqs. 16-17) of the last ``min(k, cap)`` samples, and while a model waits for
  initialization ``y = (x, z)`` with the outputs. :meth:`LagStorage.window` of a buffer is
  ``[:, 0]`` = sample ``k``, ``[:, i]`` = sample ``k - i``. Each sample is
  written once, in front of the window; the window of ``x`` is contiguous, so one outer
  product updates every lag of Eq. 21. When a sample lands on slot 0 the window is copied
  back to the end of the buffer (every ``3 cap`` samples; the buffer holds ``4 cap``). With
  all lags the buffer is exactly the capacity and grows with it.
* **Eq. 17 as sums**: ``lag_sums[m, i] = n_k R_k(i) = sum_j w_j v_j v_(j-i)``, so that one
  multiply-add per sample updates it; ``R_k(i) = lag_sums[:, i] / n_k``.
* **Eq. 21, one-sided**: ``lag_products[m, a, i, b] = Lambda+_k(i)[a, b]`` with
  ``Lambda+_k(i) = f^2 Lambda+_(k-1)(i) + f^i x_k x_(k-i)'``; the two-sided
  ``Lambda_k(i)`` is formed in :mod:`.covariance`. The lag axis sits between the matrix axes
  so that each model's row ``a`` is one contiguous block.
* **Lagged moments** for exact initialization (:mod:`.initialization`), weighted
  ``w_j = f^(k-j)``: ``moment_xz[m, a, i] = sum w_j x_j[a] z_(j-i)``, ``moment_zy[m, i, b]
  = sum w_j z_j y_(j-i)[b]`` (``z x'`` and ``z z`` products) and, under
  forgetting, ``moment_xx[m, a, i, b] = sum w_j x_j[a] x_(j-i)[b]`` (with ``f = 1`` that is
  ``lag_products``). They are updated only while a model waits for initialization.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LagStorage", "GROWTH_START"]

GROWTH_START = 64  # initial lag capacity when all lags are kept (n_lags=None)

_HISTORY = ("x", "y", "v")
_BY_LAG = ("lag_sums", "lag_products", "moment_xz", "moment_zy", "moment_xx")
_LAG_AXIS = {"lag_sums": 1, "lag_products": 2, "moment_xz": 2, "moment_zy": 1, "moment_xx": 2}


class LagStorage:
    """The history buffers and lag-indexed sums of ``m`` models (see the module docstring)."""

    def __init__(self, m: int, n: int, cap: int, *, all_lags: bool, forgetting: float) -> None:
        self.m, self.n = m, n
        self.all_lags = all_lags
        self.forgetting = forgetting
        self.allocate(cap)

    def allocate(self, cap: int) -> None:
        """Fresh zero arrays for a lag capacity ``cap`` (an empty history)."""
        m, n = self.m, self.n
        self.cap = cap
        length = cap if self.all_lags else 4 * cap
        self.x = np.zeros((m, length, n))
        self.y = np.zeros((m, length, n + 1))
        self.v = np.zeros((m, length))
        self.ptr = length  # the window is [ptr, ptr + w)
        self.lag_sums = np.zeros((m, cap))
        self.lag_products = np.zeros((m, n, cap, n))
        self.moment_xz = np.zeros((m, n, cap))
        self.moment_zy = np.zeros((m, cap, n + 1))
        self.moment_xx = np.zeros((m, n, cap, n)) if self.forgetting != 1.0 else None
        self.lag_powers = self.forgetting ** np.arange(cap, dtype=float)  # f^i of Eq. 21
        self.products_flat = self.lag_products.reshape(m, n, cap * n)  # row a of every lag
        # The products of one sample, before they are added.
        self.products_scratch = np.zeros((m, n, cap * n))
        self.sums_scratch = np.zeros((m, cap))
        self.xz_scratch = np.zeros((m, n, cap))
        self.zy_scratch = np.zeros((m, cap, n + 1))
        self._full = self._restricted(cap)

    def _restricted(self, w: int) -> tuple:
        m, n = self.m, self.n
        return (
            self.lag_sums[:, :w], self.sums_scratch[:, :w],
            self.lag_products[:, :, :w].reshape(m, n, w * n), self.products_scratch[:, :, : w * n],
            self.moment_xz[:, :, :w], self.xz_scratch[:, :, :w],
            self.moment_zy[:, :w], self.zy_scratch[:, :w],
        )

    def by_lag(self, w: int) -> tuple:
        """Views of the first ``w`` lags, each with the scratch its update uses:
        ``(lag_sums, ., lag_products as (M, n, w n), ., moment_xz, ., moment_zy, .)``."""
        return self._full if w == self.cap else self._restricted(w)

    def window(self, buf: np.ndarray, w: int) -> np.ndarray:
        """The last ``w`` entries of a history buffer, newest first (a view)."""
        return buf[:, self.ptr : self.ptr + w]

    def relocate(self, w: int) -> None:
        """Move the history window from the buffer's front back to its end (called when the
        newest sample was written at slot 0)."""
        length = self.v.shape[1]
        for buf in (self.x, self.y, self.v):
            buf[:, length - w :] = buf[:, :w]
        self.ptr = length - w

    def grow(self, w: int) -> None:
        """Double the lag capacity (all lags), keeping the ``w`` samples and lags held."""
        old = {name: getattr(self, name) for name in _HISTORY + _BY_LAG}
        old_ptr, old_cap = self.ptr, self.cap
        self.allocate(2 * old_cap)
        self.ptr -= w
        for name in _HISTORY:
            getattr(self, name)[:, self.ptr :] = old[name][:, old_ptr : old_ptr + w]
        for name in _BY_LAG:
            if old[name] is not None:
                index = (slice(None),) * _LAG_AXIS[name] + (slice(0, old_cap),)
                getattr(self, name)[index] = old[name]

    def arrays(self, w: int) -> dict:
        """Copies of the history windows (newest first) and the lag-indexed sums."""
        out = {name: self.window(getattr(self, name), w).copy() for name in _HISTORY}
        for name in _BY_LAG:
            if getattr(self, name) is not None:
                out[name] = getattr(self, name).copy()
        return out

    def load(self, arrays: dict, w: int) -> None:
        """Inverse of :meth:`arrays` (on freshly allocated storage of the same capacity)."""
        self.ptr -= w
        for name in _HISTORY:
            target = self.window(getattr(self, name), w)
            _assign(target, arrays[name], name)
        for name in _BY_LAG:
            if getattr(self, name) is not None:
                _assign(getattr(self, name), arrays[name], name)


def _assign(target: np.ndarray, value, name: str) -> None:
    value = np.asarray(value, dtype=target.dtype)
    if value.shape != target.shape:
        raise ValueError(f"estimator state field {name!r} has shape {value.shape}, expected {target.shape}")
    target[...] = value
