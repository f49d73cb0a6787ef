"""The finite Fourier transform of sampled signals, batch and recursive (docs/frequency.md, F1-F2).

For samples ``u_n`` at ``t_n = n dt`` (``n = 0 .. N-1``) and angular frequencies ``w_k``:

    U_N(w_k) = dt sum_n u_n exp(-j w_k t_n)                                  (F1)
    U_N(w_k) = U_(N-1)(w_k) + dt u_(N-1) exp(-j w_k t_(N-1))                 (F2)

Morelli (JGCD 23(5), 2000): each sample costs one complex multiply-add per frequency and
signal. The phasor ``exp(-j w_k t_n)`` is computed from the sample index at every sample, with
the number of cycles ``f_k n / rate`` reduced modulo 1 first: no rotation is accumulated in the
state, and the phase of sample ``n`` is exact to the rounding of that cycle count (about
``1e-16 f_k n / rate`` cycles). numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["phasors", "finite_fourier_transform", "RecursiveFourierTransform"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]


def phasors(frequencies: npt.ArrayLike, n: npt.ArrayLike, rate_hz: float) -> ComplexArray:
    """``exp(-j 2 pi f t_n)`` with ``t_n = n / rate_hz``, shape ``frequencies.shape + n.shape``.
    The number of cycles ``f n / rate_hz`` is reduced modulo 1 before the exponential."""
    f = np.asarray(frequencies, dtype=np.float64)
    idx = np.asarray(n, dtype=np.float64)
    cycles = np.multiply.outer(f, idx) / float(rate_hz)
    out: ComplexArray = np.exp(-2j * np.pi * np.mod(cycles, 1.0))
    return out


def finite_fourier_transform(signals: npt.ArrayLike, frequencies: npt.ArrayLike, rate_hz: float) -> ComplexArray:
    """Eq. F1 for a whole record: ``signals`` ``(N, ...)`` sampled at ``rate_hz`` from ``t_0 = 0``;
    returns ``(K, ...)``, ``K`` frequencies in Hz."""
    u = np.asarray(signals, dtype=np.float64)
    c = phasors(frequencies, np.arange(u.shape[0]), rate_hz)  # (K, N)
    out: ComplexArray = np.tensordot(c, u, axes=(1, 0)) / float(rate_hz)
    return out


class RecursiveFourierTransform:
    """Eq. F2: the finite Fourier transform of signals of shape ``shape`` on a frequency grid,
    one sample at a time. :attr:`values` ``(*shape[:-1], K, shape[-1])`` equals
    :func:`finite_fourier_transform` of the samples so far (to rounding).

    The sums are kept frequency-last, ``(*shape, K)``, so that a sample is one real product of
    its values with the phasors' real and imaginary parts (``2K`` contiguous numbers) and one
    addition; the phasors of the next :data:`BLOCK` samples are computed at once, by the same
    elementwise operations as :meth:`phasor`'s."""

    BLOCK = 16

    def __init__(self, frequencies: npt.ArrayLike, rate_hz: float, shape: tuple[int, ...]) -> None:
        self.frequencies: FloatArray = np.asarray(frequencies, dtype=np.float64).reshape(-1)
        self.rate_hz = float(rate_hz)
        self.shape = tuple(int(s) for s in shape)
        self.n = 0
        K = self.frequencies.size
        self._sums: ComplexArray = np.zeros((*self.shape, K), complex)
        self._product: FloatArray = np.empty((int(np.prod(self.shape)), 2 * K))
        self._block_start = -2 * self.BLOCK  # no block yet
        self._block: FloatArray = np.empty((self.BLOCK, 2 * K))

    @property
    def values(self) -> ComplexArray:
        """The transforms ``(*shape[:-1], K, shape[-1])``, a new array."""
        out: ComplexArray = np.ascontiguousarray(np.swapaxes(self._sums, -1, -2))
        return out

    @values.setter
    def values(self, values: npt.ArrayLike) -> None:
        self._sums[...] = np.swapaxes(np.asarray(values, dtype=np.complex128), -1, -2)

    @property
    def frequency_last(self) -> ComplexArray:
        """The transforms as kept, ``(*shape, K)``: the state itself (read, never written)."""
        return self._sums

    def phasor(self) -> ComplexArray:
        """``dt exp(-j w_k t_n)`` of the next sample ``n``, shape ``(K,)``."""
        out: ComplexArray = phasors(self.frequencies, self.n, self.rate_hz) / self.rate_hz
        return out

    def _phasors(self, n: int) -> FloatArray:
        """:meth:`phasor` of sample ``n`` as ``2K`` reals (real and imaginary parts interleaved),
        from the block of ``n``'s :data:`BLOCK` samples, computed when ``n`` leaves the last."""
        row = n - self._block_start
        if not 0 <= row < self.BLOCK:
            count = np.arange(n, n + self.BLOCK, dtype=np.float64)[:, None]
            block = np.exp(-2j * np.pi * np.mod(self.frequencies * count / self.rate_hz, 1.0)) / self.rate_hz
            self._block = block.view(np.float64)
            self._block_start, row = n, 0
        out: FloatArray = self._block[row]
        return out

    def update(self, sample: npt.ArrayLike) -> None:
        """Add sample ``n`` (Eq. F2) and advance ``n``: every signal's sum gains the signal
        times the phasor's real and imaginary parts (the complex product with a real number)."""
        u = np.asarray(sample, dtype=np.float64).reshape(-1, 1)
        np.multiply(u, self._phasors(self.n), out=self._product)
        flat = self._sums.view(np.float64).reshape(self._product.shape)  # a view: (signals, 2K)
        np.add(flat, self._product, out=flat)
        self.n += 1

    def reset(self) -> None:
        self.n = 0
        self._sums[...] = 0.0
