"""Lag-product sums of the transformed signals, from which the residual autocovariance of any
estimate is formed exactly (docs/frequency.md, "The residual autocovariance").

For the signals ``u_n = (z_n, x_n)`` of a model with their first sample subtracted, the sums

    S_i = sum_(n=i..N-1) u_n u_(n-i)',   s = sum_n u_n,   H_i = sum_(n<i) u_n,
    T_i = sum_(n=N-i..N-1) u_n,          i = 0 .. L

give the centered lag sums ``C_i = sum_(n=i..N-1) (u_n - m)(u_(n-i) - m)'``, ``m = s / N``:

    C_i = S_i - (s - H_i) m' - m (s - T_i)' + (N - i) m m'                   (F9)

so the residual ``v_n = w' u_n`` of any weight ``w = (1, -theta)`` has the mean-removed sample
autocovariance (the paper's Eq. 10 about the mean) ``R(i) = w' C_i w / N`` over the whole
record -- the residuals of an estimate of *now*, not the stale ones of a recursion. Memory is
bounded: ``S`` and ``H`` hold ``L + 1`` lags, ``T`` comes from the last ``L + 1`` samples.

:func:`residual_autocovariance` takes the weight of the time-domain least-squares fit of the
record (with a bias) and corrects ``R`` for the degrees of freedom that fit takes (Eq. F10).
numpy only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["LagSums", "pseudo_inverse", "dof_correction", "residual_autocovariance"]

FloatArray = npt.NDArray[np.float64]


class LagSums:
    """Eq. F9 for ``M`` models of ``q`` signals each, lags ``0 .. n_lags``, one sample at a time."""

    def __init__(self, models: int, signals: int, n_lags: int) -> None:
        self.width = w = int(n_lags) + 1
        self.n = 0
        self.sums: FloatArray = np.zeros((models, w, signals, signals))  # S_i
        self.total: FloatArray = np.zeros((models, signals))  # s
        self.head: FloatArray = np.zeros((models, w, signals))  # H_i
        # The last w samples, each written twice so that a contiguous slice is the window.
        self._buffer: FloatArray = np.zeros((models, 2 * w, signals))

    def window(self) -> FloatArray:
        """The last ``n_lags + 1`` samples, newest first (zeros before the first), a view."""
        pos = (self.n - 1) % self.width
        view: FloatArray = self._buffer[:, pos + 1 : pos + 1 + self.width][:, ::-1]
        return view

    def update(self, u: FloatArray) -> None:
        """Add sample ``n`` (``(M, q)``, first sample already subtracted)."""
        w, n = self.width, self.n
        pos = n % w
        self._buffer[:, pos] = u
        self._buffer[:, pos + w] = u
        self.n += 1
        # S_i += u_n u_(n-i)' for every lag at once (the window is newest first).
        self.sums += u[:, None, :, None] * self.window()[:, :, None, :]
        self.total += u
        if n + 1 < w:
            self.head[:, n + 1 :] += u[:, None, :]

    def centered(self) -> FloatArray:
        """``C_i`` of Eq. F9 for ``i = 0 .. min(n_lags, N - 1)``, shape ``(M, lags, q, q)``."""
        N = self.n
        lags = min(self.width, N)
        mean = self.total / N
        tail = np.zeros_like(self.head[:, :lags])
        np.cumsum(self.window()[:, : lags - 1], axis=1, out=tail[:, 1:])
        after_head = self.total[:, None] - self.head[:, :lags]  # sum_(n >= i) u_n
        before_tail = self.total[:, None] - tail  # sum_(n <= N-1-i) u_n
        count = (N - np.arange(lags, dtype=np.float64))[None, :, None, None]
        centered: FloatArray = (
            self.sums[:, :lags]
            - after_head[..., :, None] * mean[:, None, None, :]
            - mean[:, None, :, None] * before_tail[..., None, :]
            + count * (mean[:, :, None] * mean[:, None, :])[:, None]
        )
        return centered

    def reset(self) -> None:
        self.n = 0
        for a in (self.sums, self.total, self.head, self._buffer):
            a[...] = 0.0


def pseudo_inverse(B: FloatArray, columns: npt.NDArray[np.bool_]) -> FloatArray:
    """``B^+`` of symmetric ``(M, p, p)`` matrices after scaling to a unit diagonal (relative
    cutoff 1e-12); rows and columns that are padding (``columns`` false) or zero on the
    diagonal are left out (0 in ``B^+``). Where ``B`` is singular the fit's residual is still
    the unique least-squares projection."""
    d = np.diagonal(B, axis1=1, axis2=2)
    used = columns & (d > 0)
    s = np.where(used, 1.0 / np.sqrt(np.where(used, d, 1.0)), 0.0)
    scaled = B * s[:, :, None] * s[:, None, :]
    inv = np.linalg.pinv(scaled, rcond=1e-12, hermitian=True) * s[:, :, None] * s[:, None, :]
    out: FloatArray = np.asarray(inv, dtype=np.float64)
    return out


def dof_correction(Cx: FloatArray, B_inv: FloatArray, N: int) -> Callable[[FloatArray], FloatArray]:
    """The linear map ``D`` of Eq. F10 (what the least-squares fit of the same record, the
    regressors and the bias, takes out of ``R(i)`` on average), for ``R`` ``(M, L+1)``:

        (D R)(i) = [2 sum_(|l|<=L) R(l) T(l-i) - tr(C^x_i cov(R))
                    + 2 sum_(|l|<=L) R(l) T1(l-i) - (N - i) var(R)] / N,

    ``T(j) = tr(B^+ C^x_j)`` (0 beyond ``L``; even in ``j``), ``C^x`` the centered regressor lag
    sums, ``cov(R) = B^+ [R(0) C^x_0 + sum_(l>=1) R(l) (C^x_l + C^x_l')] B^+`` the fit's
    covariance; the bias (the mean, orthogonal to the centered regressors) is the same with
    ``T1(j) = max(N - |j|, 0) / N`` and ``var(R) = sum_(|l|<=L) (N - |l|) R(l) / N^2``."""
    M, lags = Cx.shape[:2]
    L = lags - 1
    T = np.zeros((M, 4 * L + 1))  # T(j) at index j + 2L, j = -2L..2L
    T[:, 2 * L : 3 * L + 1] = np.einsum("mab,miba->mi", B_inv, Cx)
    T[:, L : 2 * L + 1] = T[:, 2 * L : 3 * L + 1][:, ::-1]
    # Row i holds T(l - i) for l = -L..L: the window starting at index L - i.
    shifted = sliding_window_view(T, 2 * L + 1, axis=1)[:, L::-1]  # (M, L+1, 2L+1), a view
    gap = np.arange(-2 * L, 2 * L + 1)
    shifted_mean = sliding_window_view(np.maximum(N - np.abs(gap), 0) / N, 2 * L + 1)[L::-1]  # T1(l - i)
    weight = (N - np.abs(np.arange(-L, L + 1))) / N**2
    both = Cx[:, 1:] + np.swapaxes(Cx[:, 1:], 2, 3)
    count = N - np.arange(lags, dtype=np.float64)

    def apply(R: FloatArray) -> FloatArray:
        two_sided = np.concatenate([R[:, :0:-1], R], axis=1)  # R(|l|), l = -L..L
        cross = 2.0 * (np.einsum("mil,ml->mi", shifted, two_sided) + two_sided @ shifted_mean.T)
        middle = R[:, 0, None, None] * Cx[:, 0] + np.einsum("mi,miab->mab", R[:, 1:], both)
        quad = np.einsum("miab,mba->mi", Cx, B_inv @ middle @ B_inv)
        quad_mean = count[None, :] * (two_sided @ weight)[:, None]
        out: FloatArray = (cross - quad - quad_mean) / N
        return out

    return apply


def residual_autocovariance(C: FloatArray, columns: npt.NDArray[np.bool_], N: int, correct: bool) -> FloatArray:
    """Eqs. F9-F10: ``R(0..L)`` (``(M, L+1)``) of the residuals of the least-squares fit of ``z``
    on the regressors and a bias over the record (``theta = B^+ b``, ``B = C_0[x, x]``,
    ``b = C_0[x, z]``), plus ``D R + D^2 R`` when ``correct`` (the fit's degrees of freedom)."""
    B_inv = pseudo_inverse(C[:, 0, 1:, 1:], columns[:, 1:])
    theta = np.einsum("mab,mb->ma", B_inv, C[:, 0, 1:, 0])
    w = np.concatenate([np.ones((C.shape[0], 1)), -theta], axis=1)
    R0: FloatArray = np.einsum("ma,miab,mb->mi", w, C, w) / N
    if not correct:
        return R0
    D = dof_correction(C[:, :, 1:, 1:], B_inv, N)
    R1 = R0 + D(R0)
    R: FloatArray = R0 + D(R1)
    return R
