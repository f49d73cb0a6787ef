"""The corrected covariance of the frequency-domain estimate in closed form (docs/frequency.md,
Eqs. F6-F8 and F10).

The estimate's error is ``A^-1 Re(X^H E)`` with ``E`` the transformed equation error. For a
stationary equation error with autocovariance ``R(i)``, truncated after ``L`` lags, its
covariance is

    cov = A^-1 (1/2) Re(X^H M X + X^H P conj(X)) A^-1,                       (F7)

``M = E[E E^H]``, ``P = E[E E^T]`` (``K x K``), and both are closed forms in the one-sided
sums ``S+(w) = sum_(i=1..L) R(i) exp(-j w i dt)``, ``S1(w) = sum_(i=1..L) i R(i) exp(-j w i dt)``
at the grid frequencies and geometric sums over the record (Eq. F8): no sum over samples,
``O(K L + K^2)`` per model, the same for a record of 3 s or 3 h. :class:`PairGeometry` holds
what depends only on the grid and the sample count and is shared by all models.
numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["PairGeometry", "spectral_sums", "trim_terms", "pair_matrices", "sandwich", "middle"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]


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
        # [-(cot- + cot+)/2, -I/2]] [Re a; Im a]: the two cot blocks are K x K products, the
        # rest column sums and halves.
        cot_minus = np.zeros((K, K))
        cot_minus[~self.diagonal] = 1.0 / np.tan(minus[~self.diagonal] / 2)
        cot_plus = 1.0 / np.tan((a[:, None] + a[None, :]) / 2)
        self.cot_imag: FloatArray = 0.5 * (cot_minus - cot_plus)  # Im a -> Re L
        self.cot_real: FloatArray = -0.5 * (cot_minus + cot_plus)  # Re a -> Im L
        # The tables of the last lag count asked for, one each: the count grows with the record
        # up to frequency.n_lags + 1 and then stays, so one entry serves every evaluation after
        # the first n_lags samples and memory stays that of one table (one per count would add
        # up to O(n_lags^2 K) while the record grows).
        self._tables: dict[int, FloatArray] = {}
        self._spectral: dict[int, FloatArray] = {}
        self._weights: dict[int, FloatArray] = {}
        self.at(1)

    def lag_weights(self, lags: int) -> FloatArray:
        """``1.0 .. lags`` (kept for the last ``lags``)."""
        out = self._weights.get(lags)
        if out is None:
            out = np.arange(1, lags + 1, dtype=np.float64)
            self._weights = {lags: out}
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
        (kept for the last ``lags``)."""
        table = self._tables.get(lags)
        if table is None:
            phase = np.mod(np.multiply.outer(np.arange(1, lags + 1, dtype=np.float64), self.angles), 2 * np.pi)
            table = np.empty((lags, 2 * self.angles.size))
            table[:, 0::2], table[:, 1::2] = np.cos(phase), -np.sin(phase)
            self._tables = {lags: table}
        return table

    def spectral_table(self, lags: int) -> FloatArray:
        """``(lags, 3K)``: :meth:`lag_table` and ``i cos(a_k i)``, so that ``r @ table`` gives
        ``S+`` (the first ``2K`` columns, viewed as complex) and ``Re S1`` (kept for the last ``lags``)."""
        table = self._spectral.get(lags)
        if table is None:
            cosines = self.lag_table(lags)[:, 0::2]
            table = np.hstack([self.lag_table(lags), self.lag_weights(lags)[:, None] * cosines])
            self._spectral = {lags: table}
        return table

    def at(self, N: int) -> PairGeometry:
        """Set the sample count ``N`` (the record so far); returns ``self``."""
        if getattr(self, "N", None) == int(N):
            return self
        self.N = int(N)
        self.rho = rho = np.exp(-1j * np.mod(self.angles * N, 2 * np.pi))
        self.rho_conj: ComplexArray = rho.conj()
        self.gamma = (1.0 - rho) * self.inv_single
        return self

    # The N-dependent K x K matrices, formed only by :func:`pair_matrices` (tests, the explicit form).
    @property
    def rot_minus(self) -> ComplexArray:
        """``exp(-j (a_k - a_l) N)``."""
        out: ComplexArray = self.rho[:, None] * self.rho.conj()[None, :]
        return out

    @property
    def rot_plus(self) -> ComplexArray:
        """``exp(-j (a_k + a_l) N)``."""
        out: ComplexArray = self.rho[:, None] * self.rho[None, :]
        return out

    @property
    def g_minus(self) -> ComplexArray:
        """``G_N(a_k - a_l)`` (``N`` on the diagonal)."""
        out: ComplexArray = (1.0 - self.rot_minus) * self.inv_minus
        out[self.diagonal] = float(self.N)
        return out

    @property
    def g_plus(self) -> ComplexArray:
        """``G_N(a_k + a_l)``."""
        out: ComplexArray = (1.0 - self.rot_plus) * self.inv_plus
        return out


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


def pair_matrices(R: FloatArray, geometry: PairGeometry, trim: int = 1) -> tuple[ComplexArray, ComplexArray]:
    """``M / dt^2`` and ``P / dt^2`` of Eq. F8, ``(M, K, K)``, for the transform of
    ``e_n - e_bar`` (``e_bar`` the mean of the first ``trim`` samples' ``e``) where ``e`` has the
    autocovariance ``R(0..L)`` (``(M, L+1)``, ``L <= N - 1``)."""
    g = geometry
    plus, first = spectral_sums(R, g)
    r0 = R[:, :1]
    spectrum = r0 + 2.0 * plus.real  # two-sided S(w_l) = R(0) + 2 Re S+(w_l)
    Sk, Sl = plus[:, :, None], plus[:, None, :]
    cSk, cSl = Sk.conj(), Sl.conj()
    # Q(w_k, w_l): e^{-j w_k t_n} e^{+j w_l t_m} R(n - m) summed over the record.
    M = g.g_minus * spectrum[:, None, :] - g.inv_minus * ((Sl - Sk) + g.rot_minus * (cSk - cSl))
    M[:, g.diagonal] = g.N * spectrum - 2.0 * first.real  # Q(w_k, w_k): the sums' limit at 0
    # Q(w_k, -w_l): the pseudo-covariance E[E_k E_l].
    P = g.g_plus * spectrum[:, None, :] - g.inv_plus * ((cSl - Sk) + g.rot_plus * (cSk - Sl))
    # The trim subtracted from every sample: E_k = dt (sum e_n c_kn - e_bar Gamma_k).
    V, var = trim_terms(R, g, trim)
    var3 = var[:, None, None]
    gam = g.gamma[None, :]
    M += (var3 * gam[:, :, None] * gam.conj()[:, None, :]
          - V[:, :, None] * gam.conj()[:, None, :] - gam[:, :, None] * V.conj()[:, None, :])
    P += (var3 * gam[:, :, None] * gam[:, None, :]
          - V[:, :, None] * gam[:, None, :] - gam[:, :, None] * V[:, None, :])
    return M, P


def sandwich(X: ComplexArray, M: ComplexArray, P: ComplexArray) -> FloatArray:
    """``(1/2) Re(X^H M X + X^H P conj(X))`` (Eq. F7's middle), ``X`` ``(M, K, p)``."""
    XH = np.swapaxes(X.conj(), 1, 2)
    mid = 0.5 * (XH @ (M @ X) + XH @ (P @ X.conj())).real
    out: FloatArray = 0.5 * (mid + np.swapaxes(mid, 1, 2))
    return out


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
    ``P = (cot- + cot+) Re(a)``, ``Q = (cot- - cot+) Im(a)``: one product of each of the two
    fixed real ``K x K`` matrices with the ``2 M p`` columns of ``X`` and ``Y`` (``O(K^2 M p)``),
    then one contraction over ``3K`` rows per model. The ``-a/2`` of ``L`` is left out: it adds
    ``-Re(X^H bX)/2 + Re(Y^H bY)/2 = -Im(X^H diag(Im(R(0) + 2 S)) X)``, antisymmetric
    (``|rho_k| = 1``), nothing to the symmetric part. The trim's ``Re(X^H Gamma)`` and
    ``Re(X^H V)`` are two more columns of the same contraction."""
    g = geometry
    m, K, p = X.shape
    sums = R[:, 1:] @ g.spectral_table(R.shape[1] - 1)  # S+ and Re S1
    plus: ComplexArray = sums[:, : 2 * K].view(np.complex128)
    r0 = R[:, :1]
    XY = np.empty((m, 2, K, p), complex)  # X and Y per model
    XY[:, 0] = X
    np.multiply(g.rho_conj[:, None], X, out=XY[:, 1])
    # [Re; Im] of every column of X and Y, (2K, M 2 p), through the fixed (2K, 2K) map.
    columns = XY.view(np.float64).reshape(m, 2, K, p, 2).transpose(4, 2, 0, 1, 3).reshape(2 * K, 2 * m * p)
    re, im = columns[:K], columns[K:]
    mapped = np.empty((2 * K, 2 * m * p))
    np.matmul(g.cot_imag, im, out=mapped[:K])
    mapped[:K] += re.sum(axis=0)
    np.matmul(g.cot_real, re, out=mapped[K:])
    mapped = mapped.reshape(2, K, m, 2, p).transpose(0, 2, 3, 1, 4)  # (re/im, M, X/Y, K, p)
    left = np.empty((m, 3 * K, p), complex)  # L(X), L(Y), X (the diagonal of M)
    left.real[:, : 2 * K].reshape(m, 2, K, p)[...] = mapped[0]
    left.imag[:, : 2 * K].reshape(m, 2, K, p)[...] = mapped[1]
    left[:, 2 * K :] = X
    base = r0 + 2.0 * plus  # R(0) + 2 S
    # bX, -bY, (N s - 2 Re S1) X; and, against X only, Gamma and V (the trim's terms).
    right = np.zeros((m, 3 * K, p + 2), complex)
    np.multiply(base.conj()[:, :, None], X, out=right[:, :K, :p])
    np.multiply(-base[:, :, None], XY[:, 1], out=right[:, K : 2 * K, :p])
    np.multiply((g.N * base.real - 2.0 * sums[:, 2 * K :])[:, :, None], X, out=right[:, 2 * K :, :p])
    if trim == 1:
        np.add(r0, plus, out=right[:, 2 * K :, p + 1])
        var = R[:, 0]
    else:
        right[:, 2 * K :, p + 1], var = trim_terms(R, g, trim)
    right[:, 2 * K :, p] = g.gamma
    # Re(left^H right) = Re' Re + Im' Im: one real product of the interleaved views.
    both = left.view(np.float64).swapaxes(1, 2) @ right.view(np.float64)  # (M, 2p, 2p + 4)
    contracted = both[:, 0::2, 0::2] + both[:, 1::2, 1::2]
    mid = contracted[:, :, :p]
    mid *= 0.5
    # The trim subtracted: var Gamma Gamma^H - V Gamma^H - Gamma V^H (and ^T for P), whose real
    # parts reduce to var g g' - v g' - g v' with g = Re(X^H Gamma), v = Re(X^H V).
    gam = contracted[:, :, p]
    mid += (var[:, None] * gam - 2.0 * contracted[:, :, p + 1])[:, :, None] * gam[:, None, :]
    out: FloatArray = mid + mid.swapaxes(1, 2)
    out *= 0.5
    return out
