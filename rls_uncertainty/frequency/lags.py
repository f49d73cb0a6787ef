"""Lag-product sums of the transformed signals, from which the residual autocovariance of any
estimate is formed exactly (docs/frequency.md, "The residual autocovariance").

For the signals ``u_n = (z_n, x_n)`` of a model with their first sample subtracted, the sums

    S_i = sum_(n=i..N-1) u_n u_(n-i)',   s = sum_n u_n,   H_i = sum_(n<i) u_n,
    T_i = sum_(n=N-i..N-1) u_n,          i = 0 .. L

give the centered lag sums ``C_i = sum_(n=i..N-1) (u_n - m)(u_(n-i) - m)'``, ``m = s / N``:

    C_i = S_i - (s - H_i) m' - m (s - T_i)' + (N - i) m m'                   (F9)

or, with the augmented sums ``Sa_i = sum_(n=i..N-1) (u_n, 1)(u_(n-i), 1)'``, which hold
``s - H_i``, ``s - T_i`` and ``N - i`` in their last column and row, ``C_i = E Sa_i E'`` with
``E = [I, -m]``: any contraction of ``C_i`` with a matrix ``K``, ``sum K . C_i``, is the
contraction of ``Sa_i`` with ``E' K E``. The residual ``v_n = w' u_n`` of any weight
``w = (1, -theta)`` has the mean-removed sample autocovariance (the paper's Eq. 10 about the
mean) ``R(i) = w' C_i w / N`` over the whole record -- the residuals of an estimate of *now*,
not the stale ones of a recursion. Memory is bounded: ``S`` and ``H`` hold ``L + 1`` lags,
``T`` comes from the last ``L + 1`` samples.

:func:`residual_autocovariance` takes the weight of the time-domain least-squares fit of the
record (with a bias) and corrects ``R`` for the degrees of freedom that fit takes (Eq. F10).
numpy only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from .instrumental import instrumental_fit

__all__ = ["LagSums", "pseudo_inverse", "dof_correction", "residual_autocovariance", "centering"]

FloatArray = npt.NDArray[np.float64]


class LagSums:
    """Eq. F9 for ``M`` models of ``q`` signals each, lags ``0 .. n_lags``, one sample at a time,
    kept as the augmented sums ``Sa_i`` (module docstring): the sums, the partial totals and the
    counts are one product per sample.

    Kept as ``(M, q+1, lags, q+1)`` (:attr:`sums` gives the ``(M, lags, q+1, q+1)`` of the
    equations): sample ``n``'s products with the window of the last samples are then one
    product of a column ``(u_n, 1)`` with a row of ``lags (q+1)`` contiguous numbers, the window,
    which the buffer holds newest first (each sample written twice, at ``w - 1 - n % w`` and
    ``w`` further, so that a contiguous slice is the window)."""

    def __init__(self, models: int, signals: int, n_lags: int) -> None:
        self.width = w = int(n_lags) + 1
        self.n = 0
        self._sums: FloatArray = np.zeros((models, signals + 1, w, signals + 1))
        self._buffer: FloatArray = np.zeros((models, 2 * w, signals + 1))
        self._product: FloatArray = np.empty((models, signals + 1, w * (signals + 1)))
        # The sums' rows Sa_i[a, :] as single items (the void of q+1 doubles, a view): reordered to
        # the equations' (M, lags, q+1, q+1) they are copied whole, not one number at a time.
        self._row = np.dtype((np.void, 8 * (signals + 1)))
        self._rows = self._sums.view(self._row)[..., 0]  # (M, q+1, lags)
        self._reused: FloatArray = np.empty((models, 0, signals + 1, signals + 1))  # augmented(reuse=True)

    def window(self) -> FloatArray:
        """The last ``n_lags + 1`` samples ``(u_n, 1)``, newest first (zeros before the first), a view."""
        start = self.width - 1 - (self.n - 1) % self.width
        view: FloatArray = self._buffer[:, start : start + self.width]
        return view

    def update(self, u: FloatArray) -> None:
        """Add sample ``n`` (``(M, q)``, first sample already subtracted)."""
        w, n = self.width, self.n
        pos = w - 1 - n % w
        sample = self._buffer[:, pos]
        sample[:, :-1] = u
        if n < w:  # the constant 1 stays once every position has held a sample
            sample[:, -1] = 1.0
        self._buffer[:, pos + w] = sample
        self.n += 1
        # Sa_i += (u_n, 1) (u_(n-i), 1)' for every lag at once (the window is newest first).
        M, q1 = sample.shape
        window = self._buffer[:, pos : pos + w].reshape(M, 1, w * q1)
        np.multiply(sample[:, :, None], window, out=self._product)
        flat = self._sums.reshape(self._product.shape)  # a view
        np.add(flat, self._product, out=flat)

    @property
    def sums(self) -> FloatArray:
        """``Sa_i`` for ``i = 0 .. n_lags`` ``(M, n_lags + 1, q+1, q+1)``, a new array; assigned,
        it sets them."""
        return self._reordered(self.width)

    @sums.setter
    def sums(self, values: FloatArray) -> None:
        self._sums[...] = np.asarray(values, dtype=np.float64).transpose(0, 2, 1, 3)

    @property
    def buffer(self) -> FloatArray:
        """The window's buffer as oldest-first positions ``n % w`` (and ``w`` further), a new
        array; assigned, it sets it."""
        half = self._buffer[:, : self.width][:, ::-1]
        out: FloatArray = np.concatenate([half, half], axis=1)
        return out

    @buffer.setter
    def buffer(self, values: FloatArray) -> None:
        half = np.asarray(values, dtype=np.float64)[:, : self.width][:, ::-1]
        self._buffer[:, : self.width] = half
        self._buffer[:, self.width :] = half

    def augmented(self, reuse: bool = False) -> FloatArray:
        """``Sa_i`` for ``i = 0 .. min(n_lags, N - 1)``, ``(M, lags, q+1, q+1)``: a new array, or
        with ``reuse`` one this object keeps and overwrites at the next such call."""
        lags = min(self.width, self.n)
        if not reuse:
            return self._reordered(lags)
        if self._reused.shape[1] != lags:
            self._reused = np.empty((self._sums.shape[0], lags, *self._sums.shape[1::2]))
        return self._reordered(lags, self._reused)

    def _reordered(self, lags: int, out: FloatArray | None = None) -> FloatArray:
        """The sums of lags ``0 .. lags-1`` in the equations' order ``(M, lags, q+1, q+1)``,
        written to ``out`` (C-contiguous, that shape) or a new array."""
        if out is None:
            out = np.empty((self._sums.shape[0], lags, *self._sums.shape[1::2]))
        out.view(self._row)[..., 0] = self._rows[:, :, :lags].transpose(0, 2, 1)
        return out

    def centered(self) -> FloatArray:
        """``C_i = E Sa_i E'`` of Eq. F9 for ``i = 0 .. min(n_lags, N - 1)``, ``(M, lags, q, q)``."""
        augmented = self.augmented()
        E = centering(augmented)[:, None]
        out: FloatArray = E @ augmented @ E.swapaxes(2, 3)
        return out

    def reset(self) -> None:
        self.n = 0
        self._sums[...] = 0.0
        self._buffer[...] = 0.0


def pseudo_inverse(B: FloatArray, columns: npt.NDArray[np.bool_]) -> FloatArray:
    """``B^+`` of symmetric ``(M, p, p)`` matrices after scaling to a unit diagonal (relative
    cutoff 1e-12 on the eigenvalues' magnitudes); rows and columns that are padding
    (``columns`` false) or zero on the diagonal are left out (0 in ``B^+``). Where ``B`` is
    singular the fit's residual is still the unique least-squares projection."""
    d = np.diagonal(B, axis1=1, axis2=2)
    s = 1.0 / np.sqrt(np.where(columns & (d > 0), d, np.inf))  # left out: 0
    scale = s[:, :, None] * s[:, None, :]
    w, u = np.linalg.eigh(B * scale)
    magnitude = np.abs(w)
    cut = magnitude <= 1e-12 * magnitude.max(axis=1, keepdims=True)
    if cut.any():
        w = np.where(cut, np.inf, w)  # 1 / w: 0
    out: FloatArray = (u * (1.0 / w)[:, None, :]) @ u.swapaxes(1, 2)
    out *= scale
    return out


def centering(augmented: FloatArray) -> FloatArray:
    """``E = [I, -m]`` ``(M, q, q+1)`` of augmented sums ``(M, lags, q+1, q+1)``:
    ``C_i = E Sa_i E'`` (``m = (s - H_0) / N`` from ``Sa_0``)."""
    M, q = augmented.shape[0], augmented.shape[2] - 1
    E = _identities(M, q)
    np.divide(augmented[:, 0, :q, q], -augmented[:, 0, q, q, None], out=E[:, :, q])
    return E


_IDENTITIES: dict[tuple[int, int], FloatArray] = {}


def _identities(M: int, q: int) -> FloatArray:
    """A new ``(M, q, q+1)`` array ``[I, 0]`` (a copy of one kept per shape)."""
    template = _IDENTITIES.get((M, q))
    if template is None:
        template = _IDENTITIES[(M, q)] = np.zeros((M, q, q + 1))
        template[:, :, :q] = np.eye(q)
    return template.copy()


def dof_correction(
    augmented: FloatArray, E: FloatArray, B_inv: FloatArray, N: int
) -> Callable[[FloatArray], FloatArray]:
    """The linear map ``D`` of Eq. F10 (what the least-squares fit of the same record, the
    regressors and the bias, takes out of ``R(i)`` on average), for ``R`` ``(M, L+1)``:

        (D R)(i) = [2 sum_(|l|<=L) R(l) T(l-i) - tr(C^x_i cov(R))
                    + 2 sum_(|l|<=L) R(l) T1(l-i) - (N - i) var(R)] / N,

    ``T(j) = tr(B^+ C^x_j)`` (0 beyond ``L``; even in ``j``), ``C^x`` the centered regressor lag
    sums, ``cov(R) = B^+ [R(0) C^x_0 + sum_(l>=1) R(l) (C^x_l + C^x_l')] B^+`` the fit's
    covariance; the bias (the mean, orthogonal to the centered regressors) is the same with
    ``T1(j) = max(N - |j|, 0) / N`` and ``var(R) = sum_(|l|<=L) (N - |l|) R(l) / N^2``.
    The centered sums are never formed: ``C^x_j = E_x Sa_j E_x'`` (``E_x`` the regressor rows of
    :func:`centering`), so ``T``, the traces and ``sum_l R(l) Sa_l`` are each one product with
    the augmented sums (the fit's covariance enters as ``E_x' B^+ E_x``, formed once); the cross
    terms and the bias's variance are one ``(L+1) x (L+1)`` matrix of ``R(0..L)`` per model,
    formed once (``T``'s Toeplitz and Hankel parts as strided views, :func:`_bias_terms`)."""
    M, lags, q1 = augmented.shape[:3]
    L = lags - 1
    flat = augmented.reshape(M, lags, q1 * q1)
    Ex = E[:, 1:]
    # tr(K C^x_j) = Sa_j . (Ex' K' Ex); for K = B^+ (Ex Y Ex') B^+ with Y symmetric in the
    # augmented coordinates that is Sa_j . (Bt Y Bt), Bt = Ex' B^+' Ex, formed once.
    Bt = Ex.swapaxes(1, 2) @ B_inv.swapaxes(1, 2) @ Ex

    def traces(Y: FloatArray) -> FloatArray:
        """``Sa_j . Y`` for every lag ``j``, ``(M, lags)``."""
        out: FloatArray = (flat @ Y.reshape(M, q1 * q1, 1))[:, :, 0]
        return out

    # The cross terms and (N - i) var(R), var(R) = sum_(|l|<=L) (N - |l|) R(l) / N^2, are
    # matrices of R(0..L) (the sums over l = -L..L folded onto |l|): T's Toeplitz part
    # 2 T(|j - i|) and Hankel part 2 T(j + i) (j >= 1; 0 beyond L), (M, lags, lags), strided
    # views of 2 T laid out at index 2L + k, k = -2L..2L; the rest, shared by the models,
    # depends only on N and L.
    shifted = np.zeros((M, 4 * L + 1))
    T2 = 2.0 * traces(Bt)  # 2 tr(B^+ C^x_j)
    shifted[:, 2 * L : 3 * L + 1] = T2
    shifted[:, L : 2 * L + 1] = T2[:, ::-1]
    step = shifted.strides
    toeplitz = np.ndarray((M, lags, lags), np.float64, shifted, 2 * L * step[1], (step[0], -step[1], step[1]))
    hankel = np.ndarray((M, lags, lags), np.float64, shifted, 2 * L * step[1], (step[0], step[1], step[1]))
    lagged = toeplitz + hankel
    lagged[:, :, 0] -= T2  # the Hankel part starts at j = 1
    shared = _bias_terms(N, L).T
    first = augmented[:, 0]

    def apply(R: FloatArray) -> FloatArray:
        summed = (R[:, None, :] @ flat).reshape(M, q1, q1)  # sum_l R(l) Sa_l
        middle = summed + summed.swapaxes(1, 2) - R[:, :1, None] * first  # Ex middle Ex' is cov(R)'s middle
        out: FloatArray = (lagged @ R[:, :, None])[:, :, 0] + R @ shared - traces(Bt @ middle @ Bt)
        out /= N
        return out

    return apply


# The fixed matrices of the last L asked for (L grows with the record up to frequency.n_lags
# and then stays; one entry keeps memory at five (L+1) x (L+1) matrices).
_FOLDS: dict[int, tuple[FloatArray, ...]] = {}


def _bias_terms(N: int, L: int) -> FloatArray:
    """The part of :func:`dof_correction`'s lag matrix that depends only on ``N`` and ``L``,
    ``(L+1, L+1)``: ``2 [T1(j - i) + T1(-j - i)] - (N - i)(N - j) c_j / N^2`` with
    ``T1(k) = max(N - |k|, 0) / N`` (the ``-j`` term only for ``j >= 1``) and ``c_j`` the lags
    ``+-j`` folded onto ``j``: 1 for ``j = 0``, 2 beyond. From ``N = 2L`` on no ``T1`` is
    clipped and it is ``c_j + (P1 + P2 / N) / N`` with fixed ``P1 = (i + j) c_j - 2 (|j - i| +
    (i + j) [j >= 1])`` and ``P2 = -i j c_j`` (kept for the last ``L``)."""
    folds = _FOLDS.get(L)
    if folds is None:
        i, j = np.arange(L + 1.0)[:, None], np.arange(L + 1.0)[None, :]
        c = np.where(j >= 1, 2.0, 1.0)
        mirrored = np.where(j >= 1, i + j, np.inf)  # |-j - i|, none for j = 0
        P1 = (i + j) * c - 2.0 * (np.abs(j - i) + np.where(j >= 1, i + j, 0.0))
        folds = (np.abs(j - i), mirrored, c, P1, -i * j * c)
        _FOLDS.clear()
        _FOLDS[L] = folds
    direct, mirrored, c, P1, P2 = folds
    if N >= 2 * L:
        out: FloatArray = P2 / N
        out += P1
        out /= N
        out += c
        return out
    out = (N - direct) + np.maximum(N - mirrored, 0.0)  # |j - i| <= L < N
    out *= 2.0 / N
    count = N - np.arange(L + 1.0)
    out -= np.multiply.outer(count, count * c[0]) / N**2
    return out


def residual_autocovariance(
    augmented: FloatArray, columns: npt.NDArray[np.bool_], N: int, correct: bool, cross: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Eqs. F9-F10: ``R(0..L)`` (``(M, L+1)``) of the residuals of the least-squares fit of ``z``
    on the regressors and a bias over the record (``theta = B^+ b``, ``B = C_0[x, x]``,
    ``b = C_0[x, z]``), plus ``D R + D^2 R`` when ``correct`` (the fit's degrees of freedom),
    and ``C_0`` ``(M, q, q)``. ``augmented``: :meth:`LagSums.augmented` ``(M, L+1, q+1, q+1)``
    (the centered sums ``C_i`` with a zero last row and column and ``N - i`` in the corner are
    the same). With ``cross`` (:func:`.instrumental.instrumental_fit`'s sums of the
    instruments), the residuals are those of the instrumental-variable fit of the record and
    ``D`` is still the least-squares fit's."""
    M, lags, q1 = augmented.shape[:3]
    E = centering(augmented)
    C0 = E @ augmented[:, 0] @ E.swapaxes(1, 2)
    B_inv = pseudo_inverse(C0[:, 1:, 1:], columns[:, 1:])
    if cross is None:
        theta = np.einsum("mab,mb->ma", B_inv, C0[:, 1:, 0])
    else:
        theta = instrumental_fit(cross, E, C0, columns[:, 1:])
    w = np.empty((M, q1 - 1))  # (1, -theta)
    w[:, 0] = 1.0
    np.negative(theta, out=w[:, 1:])
    weight = (w[:, None, :] @ E)[:, 0]  # R(i) = w' C_i w / N = (E'w)' Sa_i (E'w) / N
    outer = (weight[:, :, None] * weight[:, None, :]).reshape(M, q1 * q1, 1)
    R0: FloatArray = (augmented.reshape(M, lags, q1 * q1) @ outer)[:, :, 0] / N
    if not correct:
        return R0, C0
    D = dof_correction(augmented, E, B_inv, N)
    R1 = R0 + D(R0)
    R: FloatArray = R0 + D(R1)
    return R, C0
