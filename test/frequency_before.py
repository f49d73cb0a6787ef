"""The frequency-domain evaluation as it was written before it was restructured for speed, kept
literally: the oracle that test_frequency_evaluation.py holds FrequencyBank's evaluation to
(1e-12 relative). :func:`evaluate_before` reads a bank's transforms and lag sums and returns
what its evaluation gives (estimates, both covariances, ``R``, output variance, flags)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]
BoolArray = npt.NDArray[np.bool_]
EXACT_FIT = 1e-12


def pseudo_inverse(B: FloatArray, columns: npt.NDArray[np.bool_]) -> FloatArray:
    """``B^+`` of symmetric ``(M, p, p)`` matrices after scaling to a unit diagonal (relative
    cutoff 1e-12 on the eigenvalues' magnitudes); rows and columns that are padding
    (``columns`` false) or zero on the diagonal are left out (0 in ``B^+``). Where ``B`` is
    singular the fit's residual is still the unique least-squares projection."""
    d = np.diagonal(B, axis1=1, axis2=2)
    used = columns & (d > 0)
    s = np.where(used, 1.0 / np.sqrt(np.where(used, d, 1.0)), 0.0)
    scale = s[:, :, None] * s[:, None, :]
    w, u = np.linalg.eigh(B * scale)
    magnitude = np.abs(w)
    inverse = np.divide(1.0, w, where=magnitude > 1e-12 * magnitude.max(axis=1, keepdims=True), out=np.zeros_like(w))
    out: FloatArray = (u * inverse[:, None, :]) @ u.swapaxes(1, 2)
    out *= scale
    return out


def centering(augmented: FloatArray) -> FloatArray:
    """``E = [I, -m]`` ``(M, q, q+1)`` of augmented sums ``(M, lags, q+1, q+1)``:
    ``C_i = E Sa_i E'`` (``m = (s - H_0) / N`` from ``Sa_0``)."""
    M, q = augmented.shape[0], augmented.shape[2] - 1
    E = np.zeros((M, q, q + 1))
    E[:, :, :q] = np.eye(q)
    np.divide(augmented[:, 0, :q, q], -augmented[:, 0, q, q, None], out=E[:, :, q])
    return E


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
    :func:`centering`), so ``T``, the traces and ``sum_l R(l) C^x_l`` are each one product with
    the augmented sums; the cross terms are one contraction with strided windows of ``T + T1``."""
    M, lags, q1 = augmented.shape[:3]
    L = lags - 1
    flat = augmented.reshape(M, lags, q1 * q1)
    Ex = E[:, 1:]
    ExT = Ex.swapaxes(1, 2)

    def traces(K: FloatArray) -> FloatArray:
        """``tr(K C^x_j)`` for every lag ``j``, ``(M, lags)``."""
        out: FloatArray = (flat @ (ExT @ K.swapaxes(1, 2) @ Ex).reshape(M, q1 * q1, 1))[:, :, 0]
        return out

    # T(j) + T1(j) at index j + 2L, j = -2L..2L: row i of the cross term's matrix, f(l - i) for
    # l = -L..L, is the window starting at L - i (a strided view, never formed: O(M L) memory).
    shifted = np.zeros((M, 4 * L + 1))
    T = traces(B_inv)
    shifted[:, 2 * L : 3 * L + 1] = T
    shifted[:, L : 2 * L + 1] = T[:, ::-1]
    shifted += np.maximum(N - np.abs(np.arange(-2 * L, 2 * L + 1)), 0) / N
    step = shifted.strides
    windows = np.lib.stride_tricks.as_strided(shifted[:, L:], (M, lags, 2 * L + 1), (step[0], -step[1], step[1]))
    # (N - i) var(R), var(R) = sum_(|l|<=L) (N - |l|) R(l) / N^2.
    count = N - np.arange(lags, dtype=np.float64)
    weight = (N - np.abs(np.arange(-L, L + 1))) / N**2
    first = Ex @ augmented[:, 0] @ ExT  # C^x_0

    def apply(R: FloatArray) -> FloatArray:
        summed = Ex @ (R[:, None, :] @ flat).reshape(M, q1, q1) @ ExT  # sum_l R(l) C^x_l
        middle = summed + summed.swapaxes(1, 2) - R[:, :1, None] * first
        two_sided = np.concatenate([R[:, :0:-1], R], axis=1)  # R(|l|), l = -L..L
        out: FloatArray = 2.0 * np.einsum("mil,ml->mi", windows, two_sided)
        out -= count * (two_sided @ weight)[:, None]
        out -= traces(B_inv @ middle @ B_inv)
        out /= N
        return out

    return apply


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
    w = np.concatenate([np.ones((M, 1)), -theta], axis=1)
    weight = (w[:, None, :] @ E)[:, 0]  # R(i) = w' C_i w / N = (E'w)' Sa_i (E'w) / N
    outer = (weight[:, :, None] * weight[:, None, :]).reshape(M, q1 * q1, 1)
    R0: FloatArray = (augmented.reshape(M, lags, q1 * q1) @ outer)[:, :, 0] / N
    if not correct:
        return R0, C0
    D = dof_correction(augmented, E, B_inv, N)
    R1 = R0 + D(R0)
    R: FloatArray = R0 + D(R1)
    return R, C0


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
    U: npt.NDArray[np.complex128], q: int, pad_diagonal: BoolArray, init_condition: float, N: int,
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """``A = Re(W^H X)``, ``b = Re(W^H Z)`` (Eq. F11), ``Re(W^H W)`` (F12) and the well
    conditioned models, from the transforms ``U`` ``(M, K, q + p)``: ``Z``, ``X`` (``q - 1``
    columns) and ``W``. Padding: a unit diagonal in ``A`` and in both Gram diagonals."""
    W, X = U[..., q:], U[..., 1:q]
    WH = W.conj().swapaxes(1, 2)
    A = (WH @ X).real
    b = (WH @ U[..., :1]).real[:, :, 0]
    WW = (WH @ W).real
    A[pad_diagonal] = 1.0
    if N < 2:
        return A, b, WW, np.zeros(A.shape[0], dtype=bool)
    w_diag = np.where(pad_diagonal.any(axis=2), 1.0, np.diagonal(WW, axis1=1, axis2=2))
    x_diag = np.where(pad_diagonal.any(axis=2), 1.0, (X.real**2 + X.imag**2).sum(axis=1))
    return A, b, WW, well_conditioned(A, w_diag, x_diag, init_condition)


def _one_minus_exp(delta: FloatArray) -> ComplexArray:
    """``1 - exp(-j delta)`` without cancellation: ``2j sin(delta/2) exp(-j delta/2)``."""
    out: ComplexArray = 2j * np.sin(delta / 2) * np.exp(-0.5j * delta)
    return out


class PairGeometry:
    """Factors of Eq. F8 that depend only on the grid (angles ``a_k = w_k dt`` per sample) and
    the sample count ``N``, shared by all models: ``1 / (1 - exp(-j (a_k -+ a_l)))`` (fixed),
    ``exp(-j (a_k -+ a_l) N)`` (outer products of ``rho_k = exp(-j a_k N)``), the Dirichlet
    sums ``G_N(a_k -+ a_l) = (1 - exp(-j (a_k -+ a_l) N)) / (1 - exp(-j (a_k -+ a_l)))``
    (``N`` where ``a_k = a_l``) and ``Gamma_k = G_N(a_k)``, the transform of a constant.
    :meth:`at` sets the sample count."""

    def __init__(self, angles: FloatArray) -> None:
        a = np.asarray(angles, dtype=np.float64)
        K = a.size
        self.angles = a
        self.diagonal = np.eye(K, dtype=bool)
        minus = a[:, None] - a[None, :]
        inv_minus = np.zeros((K, K), complex)
        inv_minus[~self.diagonal] = 1.0 / _one_minus_exp(minus[~self.diagonal])
        self.inv_minus: ComplexArray = inv_minus
        self.inv_plus: ComplexArray = 1.0 / _one_minus_exp(a[:, None] + a[None, :])
        self.inv_single: ComplexArray = 1.0 / _one_minus_exp(a)
        # 1 / (1 - exp(-j d)) = (1 - j cot(d / 2)) / 2: inv_minus = (J - I)/2 - (j/2) cot-,
        # inv_plus = J/2 - (j/2) cot+ (J all ones), cot-+ = cot((a_k -+ a_l) / 2) (cot- zero on
        # the diagonal). :func:`middle` takes [Re L; Im L] = [[J - I/2, (cot- - cot+)/2],
        # [-(cot- + cot+)/2, -I/2]] [Re a; Im a].
        cot_minus = np.zeros((K, K))
        cot_minus[~self.diagonal] = 1.0 / np.tan(minus[~self.diagonal] / 2)
        cot_plus = 1.0 / np.tan((a[:, None] + a[None, :]) / 2)
        self.left_map: FloatArray = np.block([[np.ones((K, K)) - 0.5 * np.eye(K), 0.5 * (cot_minus - cot_plus)],
                                              [-0.5 * (cot_minus + cot_plus), -0.5 * np.eye(K)]])
        self._tables: dict[int, FloatArray] = {}
        self._weights: dict[int, FloatArray] = {}
        self.at(1)

    def lag_weights(self, lags: int) -> FloatArray:
        """``1.0 .. lags`` (kept per ``lags``)."""
        out = self._weights.get(lags)
        if out is None:
            out = self._weights[lags] = np.arange(1, lags + 1, dtype=np.float64)
        return out

    def head_phasors(self, count: int) -> ComplexArray:
        """``exp(-j a_k n)`` for ``n = 0 .. count-1``, ``(K, count)`` (kept for the largest count)."""
        if getattr(self, "_head", np.zeros((0, 0))).shape[1] < count:
            self._head: ComplexArray = np.exp(-1j * np.mod(np.multiply.outer(self.angles, np.arange(count)), 2 * np.pi))
        out: ComplexArray = self._head[:, :count]
        return out

    def lag_table(self, lags: int) -> FloatArray:
        """``(lags, 2K)``: ``cos(a_k i)`` and ``-sin(a_k i)`` interleaved (columns ``2k``, ``2k+1``)
        for ``i = 1..lags``, so that ``r @ table`` viewed as complex is ``sum_i r_i exp(-j a_k i)``
        (kept per ``lags``)."""
        table = self._tables.get(lags)
        if table is None:
            phase = np.mod(np.multiply.outer(np.arange(1, lags + 1, dtype=np.float64), self.angles), 2 * np.pi)
            table = np.empty((lags, 2 * self.angles.size))
            table[:, 0::2], table[:, 1::2] = np.cos(phase), -np.sin(phase)
            self._tables[lags] = table
        return table

    def at(self, N: int) -> PairGeometry:
        """Set the sample count ``N`` (the record so far); returns ``self``."""
        self.N = int(N)
        self.rho = rho = np.exp(-1j * np.mod(self.angles * N, 2 * np.pi))
        self.gamma = (1.0 - rho) * self.inv_single
        return self



def spectral_sums(R: FloatArray, geometry: PairGeometry) -> tuple[ComplexArray, ComplexArray]:
    """``S+`` and ``S1`` (``(M, K)``) of ``R`` (``(M, L+1)``, lags 0..L) at the grid's angles:
    one product of ``R(1..L)`` and ``i R(i)`` with :meth:`PairGeometry.lag_table`."""
    M, lags = R.shape[0], R.shape[1] - 1
    weighted = np.empty((2 * M, lags))
    weighted[:M] = R[:, 1:]
    np.multiply(R[:, 1:], geometry.lag_weights(lags), out=weighted[M:])
    sums: ComplexArray = (weighted @ geometry.lag_table(lags)).view(np.complex128)
    return sums[:M], sums[M:]


def trim_terms(R: FloatArray, geometry: PairGeometry, trim: int) -> tuple[ComplexArray, FloatArray]:
    """The terms of the trim ``e_bar``, the mean of the first ``trim`` samples' ``e``, subtracted
    from every sample: ``V_k = E[e_bar sum_n e_n exp(-j a_k n)] = sum_n w_n exp(-j a_k n)`` with
    ``w_n = (1/trim) sum_(j<trim) R(n - j)`` (``(M, K)``), and ``var(e_bar) = (1/trim) sum_(j<trim) w_j``
    (``(M,)``). ``trim = 1``, the first sample: ``V_k = R(0) + S+(w_k)``, ``var = R(0)``."""
    M, lags = R.shape
    L, N = lags - 1, geometry.N
    two_sided = np.concatenate([R[:, :0:-1], R], axis=1)  # R(i), i = -L..L
    # w_n, n = 0 .. trim + L - 1: a box of trim ones against R (n - j from -trim+1 to n).
    w = np.zeros((M, trim + L))
    for j in range(trim):
        w[:, max(0, j - L) : j + L + 1] += two_sided[:, max(0, L - j) :]
    w /= trim
    count = min(N, trim + L)
    V: ComplexArray = w[:, :count] @ geometry.head_phasors(count).T
    var: FloatArray = w[:, :trim].mean(axis=1)
    return V, var




def middle(R: FloatArray, X: ComplexArray, geometry: PairGeometry, trim: int = 1) -> FloatArray:
    """:func:`sandwich` of :func:`pair_matrices` without forming them, ``(M, p, p)`` (divided by
    ``dt^2`` like :func:`pair_matrices`), for ``X`` ``(M, K, p)``.

    With ``rho_k = exp(-j a_k N)``, ``Y = conj(rho) X``, ``S = S+``, the two-sided spectrum
    ``s = R(0) + 2 Re S`` and the fixed matrices ``W = 1 / (1 - exp(-j (a_k - a_l)))`` (zero
    diagonal) and ``V = 1 / (1 - exp(-j (a_k + a_l)))``, Eq. F8 regroups as
    ``M_kl = W_kl [R(0) + conj(S_l) + S_k - rho_k conj(rho_l) (R(0) + S_l + conj(S_k))]`` off the
    diagonal and ``P_kl = V_kl [R(0) + S_l + S_k - rho_k rho_l (R(0) + conj(S_l) + conj(S_k))]``,
    so that the symmetric part of ``Re(X^H M X + X^H P conj(X))`` is that of

        F(X, bX) - F(Y, bY) + Re(X^H diag(N s - 2 Re S1) X) + (trim),
        bX = (R(0) + 2 conj(S)) X,   bY = (R(0) + 2 S) Y,   F(a, b) = Re(a^H W b + a^H V conj(b)).

    ``W = (J - I)/2 - (j/2) cot((a_k - a_l)/2)`` and ``V = J/2 - (j/2) cot((a_k + a_l)/2)``
    (``J`` all ones) give ``F(a, b) = Re(L(a)^H b)`` with ``L(a) = (Q - j P - a)/2 + Re(1' a)``,
    ``P = (cot- + cot+) Re(a)``, ``Q = (cot- - cot+) Im(a)``: one product of the two fixed real
    ``K x K`` matrices with the ``2 M p`` columns of ``X`` and ``Y`` (``O(K^2 M p)``), then one
    contraction over ``3K`` rows per model."""
    g = geometry
    m, K, p = X.shape
    plus, first = spectral_sums(R, g)
    r0 = R[:, :1]
    XY = np.empty((m, 2, K, p), complex)  # X and Y per model
    XY[:, 0] = X
    np.multiply(g.rho.conj()[:, None], X, out=XY[:, 1])
    # [Re; Im] of every column of X and Y, (2K, M 2 p), through the fixed (2K, 2K) map.
    columns = XY.view(np.float64).reshape(m, 2, K, p, 2).transpose(4, 2, 0, 1, 3).reshape(2 * K, 2 * m * p)
    mapped = (g.left_map @ columns).reshape(2, K, m, 2, p).transpose(0, 2, 3, 1, 4)  # (re/im, M, X/Y, K, p)
    left = np.empty((m, 3 * K, p), complex)  # L(X), L(Y), X (the diagonal of M)
    left.real[:, : 2 * K].reshape(m, 2, K, p)[...] = mapped[0]
    left.imag[:, : 2 * K].reshape(m, 2, K, p)[...] = mapped[1]
    left[:, 2 * K :] = X
    base = r0 + 2.0 * plus  # R(0) + 2 S
    right = np.empty((m, 3 * K, p), complex)  # bX, -bY, (N s - 2 Re S1) X
    np.multiply(base.conj()[:, :, None], X, out=right[:, :K])
    np.multiply(base[:, :, None], XY[:, 1], out=right[:, K : 2 * K])
    np.negative(right[:, K : 2 * K], out=right[:, K : 2 * K])
    np.multiply((g.N * base.real - 2.0 * first.real)[:, :, None], X, out=right[:, 2 * K :])
    mid = 0.5 * (left.conj().swapaxes(1, 2) @ right).real
    # The trim subtracted: var Gamma Gamma^H - V Gamma^H - Gamma V^H (and ^T for P), whose real
    # parts reduce to var g g' - v g' - g v' with g = Re(X^H Gamma), v = Re(X^H V).
    if trim == 1:
        V, var = r0 + plus, R[:, 0]
    else:
        V, var = trim_terms(R, g, trim)
    targets = np.empty((m, K, 2), complex)
    targets[:, :, 0], targets[:, :, 1] = g.gamma, V
    gv = (X.conj().swapaxes(1, 2) @ targets).real
    gam = gv[:, :, 0]
    mid += (var[:, None] * gam - 2.0 * gv[:, :, 1])[:, :, None] * gam[:, None, :]
    out: FloatArray = mid + mid.swapaxes(1, 2)
    out *= 0.5
    return out


def _well_conditioned_ls(A: FloatArray, init_condition: float) -> BoolArray:
    d = np.diagonal(A, axis1=1, axis2=2)
    positive: BoolArray = np.all(d > 0, axis=1) & np.all(np.isfinite(A), axis=(1, 2))
    s = 1.0 / np.sqrt(np.where(positive[:, None], d, 1.0))
    scaled = A * s[:, :, None] * s[:, None, :]
    if not positive.all():
        scaled[~positive] = np.eye(A.shape[1])
    eig = np.linalg.eigvalsh(scaled)
    ok: BoolArray = positive & (eig[:, 0] * init_condition > eig[:, -1])
    return ok


def _trimmed(bank: Any, geometry: PairGeometry) -> ComplexArray:
    U: ComplexArray = bank._transform.values
    if bank.options.trim_samples == 1:
        return U
    trim = min(bank._lags.n, bank.options.trim_samples)
    shift = bank._trim_sum / max(trim, 1)
    out: ComplexArray = U - bank.options.dt * shift[:, None, :] * geometry.gamma[None, :, None]
    return out


def evaluate_before(bank: Any) -> dict[str, Any]:
    """The evaluation of ``bank`` at its current sample as it was computed before (the bank's
    ``_evaluate`` and ``_corrected``), without touching the bank."""
    N = bank._lags.n
    options, columns, cross = bank.options, bank._columns, bank._cross
    M, q = columns.shape
    real = columns[:, 1:]
    p_max = q - 1
    pad_diagonal = ~real[:, :, None] & np.eye(p_max, dtype=bool)
    pad_square = ~(real[:, :, None] & real[:, None, :])
    geometry = PairGeometry(2.0 * np.pi * bank.frequencies / float(options.rate_hz)).at(N)
    trim = min(N, options.trim_samples)
    U = _trimmed(bank, geometry)
    Z, X, W = U[..., 0], U[..., 1:q], U[..., q:]
    if cross is None:
        G = np.einsum("mka,mkb->mab", U.conj(), U).real
        A, b = G[:, 1:, 1:].copy(), G[:, 1:, 0]
        A[pad_diagonal] = 1.0
        solved = _well_conditioned_ls(A, options.init_condition) if N >= 2 else np.zeros(M, dtype=bool)
    else:
        A, b, WW, solved = instrumental_system(U, q, pad_diagonal, options.init_condition, N)
    all_solved = bool(solved.all())
    if not all_solved:
        A[~solved] = np.eye(A.shape[1])
    A_inv = np.linalg.inv(A)
    A_inv[pad_square] = 0.0
    theta = np.einsum("mab,mb->ma", A_inv, b)
    E = Z - np.einsum("mka,ma->mk", X, theta)
    s2 = (E.real**2 + E.imag**2).sum(axis=1) / (X.shape[1] - np.array(bank.sizes, dtype=np.float64))
    if cross is None:
        conventional = s2[:, None, None] * A_inv
        X_mid, right = X, A_inv
    else:
        right = A_inv.swapaxes(1, 2)
        conventional = s2[:, None, None] * (A_inv @ WW @ right)
        X_mid = W
    augmented = bank._lags.augmented()
    R, C0 = residual_autocovariance(augmented, columns, N, options.dof_correction, cross)
    mid = middle(R, X_mid, geometry, trim)
    mid *= options.dt**2
    corrected = A_inv @ mid @ right
    output_variance = np.einsum("ma,mab,mb->m", theta, C0[:, 1:, 1:], theta) / N
    exact = R[:, 0] <= EXACT_FIT * output_variance
    negative = (np.diagonal(corrected, axis1=1, axis2=2) < 0.0).any(axis=1) & ~exact
    unusable = exact | negative
    theta = np.where(solved[:, None] & real, theta, np.nan)
    cov = np.stack([corrected, conventional])
    cov[:, ~solved] = np.nan
    rule = solved & (N >= bank.publish_at)
    return {"theta": theta, "corrected": cov[0], "conventional": cov[1], "R": R, "z_variance": C0[:, 0, 0] / N,
            "solved": solved, "ready": rule & ~unusable, "withheld": rule & unusable, "negative": negative,
            "exact": exact}
