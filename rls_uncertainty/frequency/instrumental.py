"""The pieces of the instrumental-variable frequency-domain estimate (docs/frequency.md,
"Instrumental variables", Eqs. F11-F12) that the least-squares one does not have: the
time-domain instrumental-variable fit of the record whose residuals give the autocovariance
(F9 with the fit's weight), and the conditioning test of the non-symmetric ``Re(W^H X)``.
numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["instrumental_fit", "instrumental_system", "well_conditioned"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def _scaled_pinv(A: FloatArray, rows: FloatArray, cols: FloatArray) -> FloatArray:
    """``A^+`` of ``(M, p, p)`` after scaling its rows and columns by ``rows`` and ``cols``
    (relative cutoff 1e-12 on the singular values)."""
    scaled = A * rows[:, :, None] * cols[:, None, :]
    out: FloatArray = np.linalg.pinv(scaled, rcond=1e-12) * cols[:, :, None] * rows[:, None, :]
    return out


def _unit(d: FloatArray, used: BoolArray) -> FloatArray:
    out: FloatArray = np.where(used, 1.0 / np.sqrt(np.where(used, d, 1.0)), 0.0)
    return out


def instrumental_fit(cross: FloatArray, E: FloatArray, C0: FloatArray, real: BoolArray) -> FloatArray:
    """``theta = C0[w, x]^+ C0[w, z]`` ``(M, p)``: the instrumental-variable fit of ``z`` on the
    regressors and a bias over the record, centered. ``cross`` ``(M, p, q+1)`` holds
    ``sum_n w_n (u_n, 1)'`` (``u = (z, x)``, first sample subtracted), ``E`` ``(M, q, q+1)`` the
    centering of :func:`.lags.centering` (``sum_n (w_n - m_w)(u_n - m_u)' = cross E'``), ``C0``
    the regressors' centered sums (for the column scale), ``real`` ``(M, p)`` the parameters
    that are not padding."""
    C = cross @ E.swapaxes(1, 2)  # (M, p, q): [C(w, z), C(w, x)]
    Cwx = C[:, :, 1:]
    dw = np.einsum("mab,mab->ma", Cwx, Cwx)  # rows to unit length
    dx = np.diagonal(C0[:, 1:, 1:], axis1=1, axis2=2)
    used = real & (dx > 0) & (dw > 0)
    theta: FloatArray = np.einsum("mab,mb->ma", _scaled_pinv(Cwx, _unit(dw, used), _unit(dx, used)), C[:, :, 0])
    return theta


def well_conditioned(A: FloatArray, w_diag: FloatArray, x_diag: FloatArray, init_condition: float) -> BoolArray:
    """``Re(W^H X)`` ``(M, p, p)`` (padding: unit diagonal) with rows scaled by
    ``Re(W^H W)``'s diagonal and columns by ``Re(X^H X)``'s (padding: 1) whose singular values
    are within ``init_condition`` of each other: for ``W = X`` the least-squares test."""
    positive: BoolArray = np.all(w_diag > 0, axis=1) & np.all(x_diag > 0, axis=1) & np.all(np.isfinite(A), axis=(1, 2))
    rows = 1.0 / np.sqrt(np.where(positive[:, None], w_diag, 1.0))
    cols = 1.0 / np.sqrt(np.where(positive[:, None], x_diag, 1.0))
    scaled = A * rows[:, :, None] * cols[:, None, :]
    if not positive.all():
        scaled[~positive] = np.eye(A.shape[1])
    sv = np.linalg.svd(scaled, compute_uv=False)
    ok: BoolArray = positive & (sv[:, -1] * init_condition > sv[:, 0])
    return ok


def instrumental_system(
    S: npt.NDArray[np.complex128], Uc: npt.NDArray[np.complex128], q: int, pad_diagonal: BoolArray,
    init_condition: float, N: int,
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """``A = Re(W^H X)``, ``b = Re(W^H Z)`` (Eq. F11), ``Re(W^H W)`` (F12) and the well
    conditioned models, from the transforms frequency-last ``S`` ``(M, q + p, K)``: ``Z``, ``X``
    (``q - 1`` rows) and ``W``, and their conjugates ``Uc`` ``(M, K, q + p)`` (C-contiguous).
    Padding: a unit diagonal in ``A`` and in both Gram diagonals."""
    U = S.swapaxes(1, 2)
    WH = Uc[..., q:].swapaxes(1, 2)
    A = (WH @ U[..., 1:q]).real
    b = (WH @ U[..., :1]).real[:, :, 0]
    WW = (WH @ U[..., q:]).real
    A[pad_diagonal] = 1.0
    if N < 2:
        return A, b, WW, np.zeros(A.shape[0], dtype=bool)
    w_diag = np.where(pad_diagonal.any(axis=2), 1.0, np.diagonal(WW, axis1=1, axis2=2))
    Xc = Uc[..., 1:q]  # |conj(X)|^2 = |X|^2, summed over the frequencies row by row
    x_diag = np.where(pad_diagonal.any(axis=2), 1.0, (Xc.real**2 + Xc.imag**2).sum(axis=1))
    return A, b, WW, well_conditioned(A, w_diag, x_diag, init_condition)
