"""Exact initialization of the instrumental-variables models of a bank (the IV form of Eqs. 6,
7 and 10 at the first usable sample).

While a model waits, the lag storage keeps the lag-0 cross moments ``Z'X`` and ``Z'z`` of the
instruments with ``y = (x, z)`` beside the lagged moments of ``y`` (:mod:`.lag_storage`). At
the first sample ``k0`` (at least ``iv_init_samples``) at which the column-scaled
``T^-1 Z'X S^-1`` is better conditioned than ``init_condition`` (``s = sqrt(diag(X'X))``,
``t = sqrt(diag(Z'Z))``) the model takes the batch
estimate ``theta = (Z'X)^-1 Z'z`` (:func:`.reference.batch_iv`), the residuals of samples
``1..k0`` with it (Eq. 7) and their lag sums ``n_k R_k(i)`` (Eq. 10) from the lagged moments,
and continues with :mod:`.iv_fit`. From then on its regressors are divided by ``s`` and its
instruments by ``t``: ``P`` and ``theta`` are kept as ``S P T`` and ``S theta``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from .initialization import ExactInitialization, Start
from .lag_storage import LagStorage, assign_checked

__all__ = ["IvInitialization"]


class IvInitialization(ExactInitialization):
    """:class:`.initialization.ExactInitialization` for instrumental variables, with the
    instruments' column scales :attr:`inv_t` (``1/t`` on each model's parameters, 0 on
    padding) beside :attr:`inv_s`; a model waits for at least ``min_samples`` samples."""

    def __init__(self, sizes: Sequence[int], n: int, init_condition: float, min_samples: int = 0) -> None:
        super().__init__(sizes, n, init_condition, prior=False)
        self.min_samples = min_samples
        self.inv_t = self.inv_s.copy()

    def check(self, k: int, w: int, lags: LagStorage) -> list[Start]:
        started = super().check(k, w, lags)
        for start in started:
            s_n = self.sizes[start.model]
            assert start.inv_instruments is not None  # (made by _solve below)
            self.inv_t[start.model, :s_n] = start.inv_instruments[:s_n]
        return started

    def _solve(self, j: int, k: int, w: int, lags: LagStorage) -> Start | None:
        """The batch IV estimate of model ``j`` at sample ``k`` if ``Z'X`` allows it and it is
        finite, else None."""
        s_n, n = self.sizes[j], self.n
        if k < max(s_n, self.min_samples) or lags.cross0 is None:
            return None
        P = lags.products_y[j]
        cross = lags.cross0[j]
        s = np.sqrt(np.diag(P[:s_n, 0, :s_n]))
        t = np.sqrt(np.diag(lags.lag_products[j, :s_n, 0, :s_n]))  # Z'Z (unscaled while waiting)
        if not (np.all(s > 0) and np.all(t > 0)):
            return None
        C = cross[:s_n, :s_n] / np.outer(t, s)
        if not np.linalg.cond(C) < self.init_condition:
            return None
        P_scaled = np.linalg.inv(C)  # S P T
        theta_scaled = P_scaled @ (cross[:s_n, n] / t)  # S theta
        ta = np.zeros(n + 1)
        ta[:s_n] = -theta_scaled / s
        ta[n] = 1.0
        lag_sums = np.einsum("a,aib,b->i", ta, P[:, :w, :], ta)  # Eq. 10 of v_j = ta' y_j
        inv, inv_t = np.zeros(n), np.zeros(n)
        inv[:s_n], inv_t[:s_n] = 1.0 / s, 1.0 / t
        history = lags.y[j]
        x_scaled = history[:, :n] * inv[None, :]
        residuals = history[:, n] - x_scaled @ np.concatenate([theta_scaled, np.zeros(n - s_n)])  # Eq. 7
        zeta_scaled = lags.x[j] * inv_t[None, :]
        held = slice(lags.ptr, lags.ptr + w)
        if not (np.isfinite(theta_scaled).all() and np.isfinite(lag_sums).all()
                and np.isfinite(residuals[held]).all()):
            return None
        return Start(j, inv, P_scaled, theta_scaled, None, None, lag_sums, x_scaled, residuals, None,
                     inv_t, zeta_scaled)

    # ------------------------------------------------------------------ state
    def arrays(self) -> dict[str, np.ndarray]:
        """:meth:`.ExactInitialization.arrays` and a copy of ``inv_t``."""
        return {**super().arrays(), "inv_t": self.inv_t.copy()}

    def load(self, arrays: Mapping[str, npt.ArrayLike]) -> None:
        super().load(arrays)
        assign_checked(self.inv_t, arrays["inv_t"], "inv_t")


