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
        self._tables: dict[int, tuple[FloatArray, FloatArray]] = {}
        self.at(1)

    def head_phasors(self, count: int) -> ComplexArray:
        """``exp(-j a_k n)`` for ``n = 0 .. count-1``, ``(K, count)`` (kept for the largest count)."""
        if getattr(self, "_head", np.zeros((0, 0))).shape[1] < count:
            self._head: ComplexArray = np.exp(-1j * np.mod(np.multiply.outer(self.angles, np.arange(count)), 2 * np.pi))
        out: ComplexArray = self._head[:, :count]
        return out

    def lag_table(self, lags: int) -> tuple[FloatArray, FloatArray]:
        """``cos(a_k i)`` and ``sin(a_k i)`` for ``i = 1..lags``, ``(lags, K)`` (kept per ``lags``)."""
        if lags not in self._tables:
            phase = np.mod(np.multiply.outer(np.arange(1, lags + 1, dtype=np.float64), self.angles), 2 * np.pi)
            self._tables[lags] = (np.cos(phase), np.sin(phase))
        return self._tables[lags]

    def at(self, N: int) -> PairGeometry:
        """Set the sample count ``N`` (the record so far); returns ``self``."""
        self.N = int(N)
        rho = np.exp(-1j * np.mod(self.angles * N, 2 * np.pi))
        self.rot_minus: ComplexArray = rho[:, None] * rho.conj()[None, :]
        self.rot_plus: ComplexArray = rho[:, None] * rho[None, :]
        self.g_minus: ComplexArray = (1.0 - self.rot_minus) * self.inv_minus
        self.g_minus[self.diagonal] = float(N)
        self.g_plus: ComplexArray = (1.0 - self.rot_plus) * self.inv_plus
        self.gamma: ComplexArray = (1.0 - rho) * self.inv_single
        return self


def spectral_sums(R: FloatArray, geometry: PairGeometry) -> tuple[ComplexArray, ComplexArray]:
    """``S+`` and ``S1`` (``(M, K)``) of ``R`` (``(M, L+1)``, lags 0..L) at the grid's angles."""
    cos, sin = geometry.lag_table(R.shape[1] - 1)
    lags = np.arange(1, R.shape[1], dtype=np.float64)
    r, ir = R[:, 1:], R[:, 1:] * lags
    plus: ComplexArray = r @ cos - 1j * (r @ sin)
    first: ComplexArray = ir @ cos - 1j * (ir @ sin)
    return plus, first


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


def _shared(G: ComplexArray, Y: ComplexArray) -> ComplexArray:
    """``G @ Y_m`` for every model at once: one ``(K, K) @ (K, M p)`` product."""
    m, K, p = Y.shape
    out: ComplexArray = (G @ Y.transpose(1, 0, 2).reshape(K, m * p)).reshape(K, m, p).transpose(1, 0, 2)
    return out


def _inner(left: ComplexArray, right: ComplexArray) -> ComplexArray:
    """``sum_k left_k right_k'`` per model: ``(M, K, p) x (M, K, p) -> (M, p, p)``."""
    out: ComplexArray = np.swapaxes(left, 1, 2) @ right
    return out


def middle(R: FloatArray, X: ComplexArray, geometry: PairGeometry, trim: int = 1) -> FloatArray:
    """:func:`sandwich` of :func:`pair_matrices` without forming them. Every term of Eq. F8 is
    ``G o (a b')`` with ``G`` a geometry matrix shared by all models and ``a``, ``b`` per model,
    and ``X^H (G o a b') Y = sum_k a_k conj(X_k) (G (b o Y))_k``: ten products of a shared
    ``K x K`` matrix with every model's columns at once, plus the diagonal and rank-one terms.
    Returns ``(M, p, p)`` (divided by ``dt^2`` like :func:`pair_matrices`)."""
    g = geometry
    plus, first = spectral_sums(R, g)
    r0 = R[:, :1]
    spectrum = (r0 + 2.0 * plus.real)[:, :, None]
    Sp, Sc = plus[:, :, None], plus.conj()[:, :, None]
    Xc = X.conj()
    rot_minus, rot_plus = g.inv_minus * g.rot_minus, g.inv_plus * g.rot_plus
    # X^H M X: g_minus o 1 S' - inv_minus o (1 S+' - S+ 1') - rot_minus o (conj(S+) 1' - 1 conj(S+)').
    xmx = (_inner(Xc, _shared(g.g_minus, spectrum * X) - _shared(g.inv_minus, Sp * X) + _shared(rot_minus, Sc * X))
           + _inner(Sp * Xc, _shared(g.inv_minus, X)) - _inner(Sc * Xc, _shared(rot_minus, X))
           + _inner(Xc, (-2.0 * first.real)[:, :, None] * X))  # diagonal: N S(w_k) - 2 Re S1(w_k)
    # X^H P conj(X): g_plus o 1 S' - inv_plus o (1 conj(S+)' - S+ 1') - rot_plus o (conj(S+) 1' - 1 S+').
    xpx = (_inner(Xc, _shared(g.g_plus, spectrum * Xc) - _shared(g.inv_plus, Sc * Xc) + _shared(rot_plus, Sp * Xc))
           + _inner(Sp * Xc, _shared(g.inv_plus, Xc)) - _inner(Sc * Xc, _shared(rot_plus, Xc)))
    # The trim subtracted: var Gamma Gamma^H - V Gamma^H - Gamma V^H (and ^T for P).
    V, var = trim_terms(R, g, trim)
    var3 = var[:, None, None]
    xg = np.einsum("mka,k->ma", Xc, g.gamma)  # X^H Gamma
    xv = np.einsum("mka,mk->ma", Xc, V)  # X^H V
    outer = np.einsum
    xmx += (var3 * outer("ma,mb->mab", xg, xg.conj())
            - outer("ma,mb->mab", xv, xg.conj()) - outer("ma,mb->mab", xg, xv.conj()))
    xpx += var3 * outer("ma,mb->mab", xg, xg) - outer("ma,mb->mab", xv, xg) - outer("ma,mb->mab", xg, xv)
    mid = 0.5 * (xmx + xpx).real
    out: FloatArray = 0.5 * (mid + np.swapaxes(mid, 1, 2))
    return out
