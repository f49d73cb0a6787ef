"""Exact initialization of the models of a bank (Eqs. 6, 7 and 10 at the first usable sample).

Until its weighted ``A_k = X'WX`` is well conditioned after column scaling, a model only
accumulates its lag products and lagged moments (:mod:`.lag_storage`). At that sample
``k0`` it takes the batch solution ``theta = A^-1 X'Wz`` (Eq. 6), defines the residuals of
samples ``1..k0`` with it (Eq. 7) and their lag sums ``n_k R_k(i)`` (Eq. 10) from the
lagged moments, and continues with Eq. 15. From then on the model works in column-scaled
units: its regressors are divided by ``s = sqrt(diag(A_k0))``, which keeps ``D`` well
conditioned when the regressors span orders of magnitude.

With a noise model (forgetting ``f_R``, ``docs/estimator.md``) the lagged moments are weighted
``f_R^(k-j)`` and the lag-0 moments weighted ``f^(k-j)`` are kept beside them: at ``k0`` the
estimator takes its batch solution from the latter, the noise model the ``f_R``-weighted
batch solution (in the same scaled units), and ``R_k0(i)`` is formed from the noise model's
residuals of samples ``1..k0``. ``A_k`` weighted ``f_R`` is at least ``A_k`` weighted ``f``
(``f_R >= f``), so it is invertible whenever the estimator's is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from .lag_storage import FloatArray, LagStorage, assign_checked

__all__ = ["ExactInitialization", "Start"]


class Start(NamedTuple):
    """A model initialized at sample ``k0``, in its column-scaled units (``inv`` = ``1/s`` on
    its parameters, 0 on padding): its batch solution ``D``, ``theta`` (Eq. 6; the noise
    model's ``D_noise``, ``theta_noise`` with a noise model), the lag sums ``n R_k0(i)`` of
    Eq. 10, the scaled regressors ``x_scaled`` of its history buffer and its residuals (Eq. 7;
    ``noise_residuals`` the noise model's)."""

    model: int
    inv: FloatArray
    D: FloatArray
    theta: FloatArray
    D_noise: FloatArray | None
    theta_noise: FloatArray | None
    lag_sums: FloatArray
    x_scaled: FloatArray
    residuals: FloatArray
    noise_residuals: FloatArray | None
    inv_instruments: FloatArray | None = None
    instruments_scaled: FloatArray | None = None


class _Waiting:
    """A waiting model: its index, the flat indices of its ``diag(A_k)`` in ``products_y``
    and its blocker (the flat index of a zero diagonal entry, or None)."""

    __slots__ = ("model", "diagonal", "blocker")

    def __init__(self, model: int, diagonal: npt.NDArray[np.intp], blocker: int | None) -> None:
        self.model, self.diagonal, self.blocker = model, diagonal, blocker


class ExactInitialization:
    """Which models are :attr:`ready`, since when (:attr:`ready_at`) and their column scales
    (:attr:`inv_s`: ``1/s`` on each model's parameters, 0 on padding); :meth:`check` finds the
    waiting models whose data allow an initialization and solves them (:class:`Start`), which
    the bank hands to its fits and lag storage. With a ``prior`` every model is ready from the
    start, with ``s = 1``.

    Only a model whose ``A_k`` has a positive diagonal can be well conditioned. A zero
    diagonal entry (a regressor that has been exactly zero so far, such as a surface that
    never moved) is remembered as the model's blocker, and only that one number is looked
    at until it becomes positive.
    """

    def __init__(self, sizes: Sequence[int], n: int, init_condition: float, *, prior: bool) -> None:
        self.sizes, self.n, self.init_condition = tuple(sizes), n, init_condition
        m = len(self.sizes)
        self.inv_s = (np.arange(n) < np.array(self.sizes)[:, None]).astype(float)
        self.ready = np.full(m, prior, dtype=bool)
        self.ready_at = np.zeros(m, dtype=np.int64)
        self._waiting: list[_Waiting] | None = None  # one per waiting model
        self._cap = 0  # the lag capacity _waiting's flat indices are for

    def check(self, k: int, w: int, lags: LagStorage) -> list[Start]:
        """The waiting models whose ``A_k`` allows an initialization at sample ``k`` (``w``
        lags held), solved from ``lags``' moments and history; each is :attr:`ready` from now."""
        waiting = self._waiting
        if waiting is None or self._cap != lags.cap:
            # Flat indices of each waiting model's diag(A_k) in products_y, and its blocker.
            n1, cap = self.n + 1, lags.cap
            self._cap = cap
            waiting = self._waiting = [
                _Waiting(j, np.array([((j * n1 + a) * cap) * n1 + a for a in range(s)], dtype=np.intp), None)
                for j, s in enumerate(self.sizes) if not self.ready[j]
            ]
        flat = lags.products_y.reshape(-1)
        started = []
        for entry in waiting:
            blocker = entry.blocker
            if blocker is not None and not flat[blocker] > 0.0:
                continue
            diag = flat.take(entry.diagonal)
            zero = np.flatnonzero(~(diag > 0.0))
            if zero.size:
                entry.blocker = int(entry.diagonal[zero[0]])
                continue
            entry.blocker = None
            start = self._solve(entry.model, k, w, lags)
            if start is not None:
                j = entry.model
                self.inv_s[j, : self.sizes[j]] = start.inv[: self.sizes[j]]
                self.ready[j], self.ready_at[j] = True, k
                started.append(start)
        if started:
            self._waiting = None
        return started

    def _solve(self, j: int, k: int, w: int, lags: LagStorage) -> Start | None:
        """Exact initialization of model ``j`` at sample ``k``, if ``A_k`` allows it and the
        batch solution is finite, else None. Before it, the model's units are the
        regressors'."""
        s_n, n = self.sizes[j], self.n
        if k < s_n:
            return None
        # P(i) = sum_j f^(k-j) y_j y_(j-i)' of y = (x, z): A_k = X'WX is its lag-0 x block.
        P = lags.products_y[j]
        P0 = P[:, 0, :] if lags.moment0 is None else lags.moment0[j]  # weighted f
        A = P0[:s_n, :s_n]
        s = np.sqrt(np.diag(A))
        if not np.all(s > 0):
            return None
        C = A / np.outer(s, s)
        if not np.linalg.cond(C) < self.init_condition:
            return None
        D_scaled = np.linalg.inv(C)
        D_scaled = 0.5 * (D_scaled + D_scaled.T)  # S D S with S = diag(s)
        theta_scaled = D_scaled @ (P0[:s_n, n] / s)  # Eq. 6 (S theta), X'Wz the lag-0 x z moment
        D_noise = theta_noise = noise_residuals = None
        if lags.noise:  # the noise model's batch solution, weighted f_R, in the same units
            D_noise = np.linalg.inv(P[:s_n, 0, :s_n] / np.outer(s, s))
            D_noise = 0.5 * (D_noise + D_noise.T)
            theta_noise = D_noise @ (P[:s_n, 0, n] / s)
        # Eq. 10 from the lagged moments: v_j = ta' y_j with ta = (-theta, 1), so
        # sum_j w_j v_j v_(j-i) = ta' P(i) ta (the noise model's theta and weights with one).
        ta = np.zeros(n + 1)
        ta[:s_n] = -(theta_scaled if theta_noise is None else theta_noise) / s
        ta[n] = 1.0
        lag_sums = np.einsum("a,aib,b->i", ta, P[:, :w, :], ta)
        inv = np.zeros(n)
        inv[:s_n] = 1.0 / s
        history = lags.y[j]
        x_scaled = history[:, :n] * inv[None, :]
        residuals = history[:, n] - x_scaled @ np.concatenate([theta_scaled, np.zeros(n - s_n)])  # Eq. 7
        held = slice(lags.ptr, lags.ptr + w)
        finite = np.isfinite(theta_scaled).all() and np.isfinite(lag_sums).all()
        if theta_noise is not None:
            noise_residuals = history[:, n] - x_scaled @ np.concatenate([theta_noise, np.zeros(n - s_n)])
            finite = finite and np.isfinite(theta_noise).all() and np.isfinite(noise_residuals[held]).all()
        if not (finite and np.isfinite(residuals[held]).all()):
            return None  # absurd (finite) data so far: the state would not stay finite
        return Start(j, inv, D_scaled, theta_scaled, D_noise, theta_noise, lag_sums, x_scaled, residuals,
                     noise_residuals)

    # ------------------------------------------------------------------ state
    def arrays(self) -> dict[str, np.ndarray]:
        """Copies of ``inv_s``, ``ready`` and ``ready_at``."""
        return {"inv_s": self.inv_s.copy(), "ready": self.ready.copy(), "ready_at": self.ready_at.copy()}

    def load(self, arrays: Mapping[str, npt.ArrayLike]) -> None:
        """Inverse of :meth:`arrays`; another shape is refused by name."""
        for name, target in (("inv_s", self.inv_s), ("ready", self.ready), ("ready_at", self.ready_at)):
            assign_checked(target, arrays[name], name)
        self._waiting = None
