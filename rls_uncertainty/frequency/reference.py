"""The frequency-domain estimator of one model on a whole record, written out literally
(docs/frequency.md): the executable specification that :class:`.bank.FrequencyBank` must
equal at every sample, and the batch estimate of a finished maneuver.

One statement per equation, explicit ``N x N`` and ``N x p`` matrices, no recursion, no
closed forms: the transform is a sum over the samples (F1), the corrected covariance the
sandwich ``A^-1 h' T(R) h A^-1`` over the samples with the Toeplitz matrix ``T(R)`` of the
residual autocovariance (F6), the residuals those of an explicit least-squares fit (F9) --
memory and time grow with ``N^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .options import FrequencyOptions
from .transform import phasors

__all__ = ["FrequencyFit", "frequency_reference"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]


@dataclass(frozen=True)
class FrequencyFit:
    """One model's frequency-domain fit of ``N`` samples (no repair: the raw formulas)."""

    theta: FloatArray  # (p,) Eq. F4
    cov_conventional: FloatArray  # (p, p) Eq. F5
    cov_corrected: FloatArray  # (p, p) Eq. F6 with R (fit-corrected if asked)
    R: FloatArray  # (L+1,) the residual autocovariance used (F9-F10), lags 0..min(L, N-1)
    Z: ComplexArray  # (K,) transform of z - z_0
    X: ComplexArray  # (K, p) transform of x - x_0
    h: FloatArray  # (N, p) the estimate's error is A^-1 sum_n h_n e_n


def _toeplitz(r: FloatArray, N: int) -> FloatArray:
    """``T[n, m] = r[|n - m|]`` (zero beyond ``len(r) - 1``)."""
    full = np.zeros(N)
    full[: min(r.size, N)] = r[:N]
    gap = np.abs(np.subtract.outer(np.arange(N), np.arange(N)))
    out: FloatArray = full[gap]
    return out


def frequency_reference(
    x: npt.ArrayLike, z: npt.ArrayLike, options: FrequencyOptions, instruments: npt.ArrayLike | None = None,
) -> FrequencyFit:
    """The fit of ``z_n = x_n' theta + b + e_n`` (``x`` ``(N, p)`` without the bias column,
    ``z`` ``(N,)``, sampled at ``options.rate_hz``) on ``options``' grid; with ``instruments``
    ``(N, p)`` (one per regressor) the instrumental-variable fit (F11-F12), whose ``h`` and
    covariances are built from the instruments' transform ``W``."""
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    zeta = x if instruments is None else np.asarray(instruments, dtype=np.float64).reshape(x.shape)
    N, p = int(x.shape[0]), int(x.shape[1])
    dt, f = options.dt, options.frequencies()
    # The trim, the mean of the first m samples (1: the first sample), subtracted from every signal.
    m = min(options.trim_samples, N)
    xt, zt, wt = x - x[:m].mean(axis=0), z - z[:m].mean(), zeta - zeta[:m].mean(axis=0)
    # F1: c[k, n] = exp(-j w_k t_n); X = dt sum_n x_n c_n.
    c = phasors(f, np.arange(N), options.rate_hz)
    X = dt * c @ xt
    Z = dt * c @ zt
    W = dt * c @ wt
    # F4 (F11 with instruments): theta = Re(W^H X)^-1 Re(W^H Z), W = X without instruments.
    A = (W.conj().T @ X).real
    A_inv = np.linalg.inv(A)
    theta = A_inv @ (W.conj().T @ Z).real
    # F5 (F12): s^2 = sum_k |Z_k - X_k theta|^2 / (K - p); cov = s^2 A^-1 Re(W^H W) A^-T.
    E = Z - X @ theta
    s2 = float((E.conj() @ E).real) / (f.size - p)
    cov_conventional = s2 * A_inv if instruments is None else s2 * A_inv @ (W.conj().T @ W).real @ A_inv.T
    # F6: theta - theta_true = A^-1 sum_n h_n (e_n - e_bar), e_bar the mean of e over the first m
    # samples; h_n = g_n - (1/m) sum_j g_j for n < m (the -e_bar of every sample moved onto them),
    # g_n otherwise; g_n = dt Re(W^H c_n).
    g = dt * (W.conj().T @ c).real.T
    h = g.copy()
    h[:m] -= g.sum(axis=0) / m
    R = _residual_autocovariance(xt, zt, None if instruments is None else wt, options)
    cov_corrected = A_inv @ h.T @ _toeplitz(R, N) @ h @ (A_inv if instruments is None else A_inv.T)
    return FrequencyFit(theta=theta, cov_conventional=cov_conventional, cov_corrected=cov_corrected, R=R, Z=Z, X=X, h=h)


def _residual_autocovariance(
    xt: FloatArray, zt: FloatArray, wt: FloatArray | None, options: FrequencyOptions,
) -> FloatArray:
    """F9: the residuals of the time-domain fit of the record with a bias -- least squares, or
    with instruments ``wt`` the instrumental-variable fit ``(W'X)^-1 W'z`` of the centered
    signals -- their autocovariance (Eq. 10), lags 0..L (L <= N - 1), and F10's correction
    (that of the least-squares fit in both cases)."""
    N = int(xt.shape[0])
    lags = min(options.n_lags, N - 1)
    xc = xt - xt.mean(axis=0)
    zc = zt - zt.mean()
    B_inv = np.linalg.pinv(xc.T @ xc)
    if wt is None:
        v = zc - xc @ (B_inv @ xc.T @ zc)
    else:
        wc = wt - wt.mean(axis=0)
        v = zc - xc @ np.linalg.solve(wc.T @ xc, wc.T @ zc)
    R: FloatArray = np.array([v[i:] @ v[: N - i] for i in range(lags + 1)]) / N
    if options.dof_correction:
        # F10: R + D R + D^2 R, D as in lags.dof_correction, written over the samples.
        Cx = [xc[j:].T @ xc[: N - j] for j in range(lags + 1)]  # C^x_j = sum_n x_n x_(n-j)'

        def T(j: int) -> float:
            return float(np.trace(B_inv @ Cx[abs(j)])) if abs(j) <= lags else 0.0

        def T1(j: int) -> float:  # the same for the bias: a regressor of ones
            return float(max(N - abs(j), 0)) / N

        def D(r: FloatArray) -> FloatArray:
            middle = r[0] * Cx[0] + sum(r[j] * (Cx[j] + Cx[j].T) for j in range(1, lags + 1))
            cov_fit = B_inv @ middle @ B_inv
            var_mean = sum((N - abs(j)) * r[abs(j)] for j in range(-lags, lags + 1)) / N**2
            out = np.zeros(lags + 1)
            for i in range(lags + 1):
                cross = sum(r[abs(j)] * (T(j - i) + T(j + i) + T1(j - i) + T1(j + i)) for j in range(-lags, lags + 1))
                out[i] = (cross - np.trace(Cx[i] @ cov_fit) - (N - i) * var_mean) / N
            return out

        R = R + D(R + D(R))
    return R
