"""What a bank keeps per lag: the recent samples and the lag-indexed sums (Eqs. 17 and 21).

:class:`LagStorage` owns these arrays; :meth:`LagStorage.add` takes one sample (its scaled
regressors and outputs, and the fits that give its residuals), :meth:`LagStorage.start` a
model just initialized; the evaluation reads the sums. For ``M`` models of at most ``n``
parameters and a lag capacity ``cap`` (``held + 1``, or growing by doubling when all lags are
kept):

* **History**, newest first: ``x`` (column-scaled regressors) and ``v`` (residuals of
  Eqs. 16-17) of the last ``min(k, cap)`` samples, and while a model waits for
  initialization ``y = (x, z)`` with the outputs. :meth:`LagStorage.window` of a buffer is
  ``[:, 0]`` = sample ``k``, ``[:, i]`` = sample ``k - i``. Each sample is written once, in
  front of the window, which stays contiguous, so one outer product updates every lag of
  Eq. 21. When the newest sample sits at slot 0, the next one first copies the window back
  to the end of the buffer (every ``3 cap`` samples; the buffer holds ``4 cap``). With all
  lags the buffer is exactly the capacity, and the next sample first doubles it.
* **Eq. 17 as sums**: ``lag_sums[m, i] = n_k R_k(i) = sum_j w_j v_j v_(j-i)``, so that one
  multiply-add per sample updates it; ``R_k(i) = lag_sums[:, i] / n_k``.
* **Eq. 21, one-sided**: ``lag_products[m, a, i, b] = Lambda+_k(i)[a, b]`` with
  ``Lambda+_k(i) = f^2 Lambda+_(k-1)(i) + f^i x_k x_(k-i)'``; the two-sided
  ``Lambda_k(i)`` is formed in :mod:`.covariance`. The lag axis sits between the matrix axes
  so that each model's row ``a`` is one contiguous block.
* **Lagged moments** for exact initialization (:mod:`.initialization`), weighted
  ``w_j = f^(k-j)``: the products of ``y = (x, z)``, ``products_y[m, a, i, b] = sum_j w_j
  y_j[a] y_(j-i)[b]``, kept only while a model waits: ``A_k = X'WX`` is the ``x x'``
  block of lag 0, ``X'Wz`` the ``x z`` block.

**With a noise model** (forgetting ``f < 1`` with ``noise_forgetting`` ``f_R != f``, see
:mod:`.bank`): a third history ``u`` holds the noise model's residuals, ``lag_sums`` are
those of ``u`` weighted ``f_R^(k-j)``, and the lagged moments are weighted ``f_R^(k-j)`` (the
noise model's exact initialization needs them at every lag), with the lag-0 moments
weighted ``f^(k-j)`` kept beside them as ``moment0`` for the estimator's own initialization.
The ``v`` history (the estimator's residuals) is kept for :meth:`.EstimatorBank.residuals`.

**While a model waits and f = 1**, the weights of Eq. 21 and of the moments coincide, so
``lag_products`` is the ``x`` block of ``products_y`` and one outer product of ``y`` per
sample updates both (a separate product of ``x`` plus the moments costs the six-model T-2
replay about 20%). When every model is initialized (:meth:`LagStorage.all_initialized`),
``lag_products`` moves to an array of its own and the moments are dropped.

**With instruments** (instrumental variables, :mod:`.iv_fit`): the ``x`` history and Eq. 21's
products are those of the instruments ``zeta`` (column-scaled by their own ``t``), so that
``Lambda_k(i)`` is the instruments'; the ``y = (x, z)`` history and lagged moments are kept as
above while a model waits, with the lag-0 cross moments ``cross0[m, a, b] = sum_j zeta_j[a]
y_j[b]`` beside them (``Z'X`` and ``Z'z`` of the batch estimate). Nothing is merged.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np
import numpy.typing as npt

from .counts import SampleCounts

__all__ = ["LagStorage", "Sample", "GROWTH_START", "assign_checked"]

GROWTH_START = 64  # initial lag capacity when all lags are kept (lags="all")

_HISTORY = ("x", "y", "v")

FloatArray = npt.NDArray[np.float64]
# (lag_sums, its scratch, products, their scratch): the views one sample's update writes.
LagViews = tuple[FloatArray, FloatArray, FloatArray, FloatArray]


class Sample(Protocol):
    """The sample being added, as the models see it: ``y = (x / s, z)`` ``(M, n+1)``, ``x``
    its regressor part, ``x_col`` and ``y_col`` their column views (:class:`.bank.ScaledSample`)."""

    y: FloatArray
    x: FloatArray
    x_col: FloatArray
    y_col: FloatArray


class Residuals(Protocol):
    """A fit that gives the residual ``v_k`` of the sample being added (:class:`.rls_fit.RlsFit`)."""

    def residual(self, out: FloatArray) -> None: ...


class Start(Protocol):
    """What an initialized model's storage takes (:class:`.initialization.Start`)."""

    @property
    def model(self) -> int: ...
    @property
    def inv(self) -> FloatArray: ...
    @property
    def lag_sums(self) -> FloatArray: ...
    @property
    def x_scaled(self) -> FloatArray: ...
    @property
    def residuals(self) -> FloatArray: ...
    @property
    def noise_residuals(self) -> FloatArray | None: ...
    @property
    def inv_instruments(self) -> FloatArray | None: ...
    @property
    def instruments_scaled(self) -> FloatArray | None: ...


class LagStorage:
    """The history buffers and lag-indexed sums of ``m`` models (see the module docstring):
    :meth:`add` takes one sample, :meth:`start` an initialized model."""

    # Arrays that exist only in some configurations hold None otherwise (assigned in
    # :meth:`_allocate`); they are read only where they exist: ``u`` and ``moment0`` with a
    # noise model, ``products_y`` while a model waits, ``_products_scratch`` when not merged.
    # Typed as arrays, since mypy cannot follow that invariant.
    x: FloatArray
    y: FloatArray
    v: FloatArray
    u: FloatArray
    lag_sums: FloatArray
    products_y: FloatArray
    moment0: FloatArray | None  # (checked where it may be None)
    cross0: FloatArray | None  # (with instruments, while waiting)
    lag_products: FloatArray
    lag0: FloatArray
    _sums_scratch: FloatArray
    _lag_powers: FloatArray
    _products_y_scratch: FloatArray
    _products_scratch: FloatArray
    _full: LagViews

    def __init__(
        self, m: int, n: int, cap: int, *, all_lags: bool, forgetting: float, waiting: bool,
        noise_forgetting: float | None = None, instruments: bool = False,
    ) -> None:
        self.m, self.n = m, n
        self.instruments = instruments
        self.all_lags = all_lags
        self.forgetting = forgetting
        # A noise model (f_R != f): the u history, lag sums of u, moments weighted f_R.
        self.noise = noise_forgetting is not None and noise_forgetting != forgetting
        # (self.noise implies noise_forgetting is a float, which mypy cannot see)
        self.moment_forgetting: float = noise_forgetting if self.noise else forgetting  # type: ignore[assignment]
        self._history = (*_HISTORY, "u") if self.noise else _HISTORY
        self.waiting = waiting
        self._allocate(cap)

    def _allocate(self, cap: int) -> None:
        """Fresh zero arrays for a lag capacity ``cap`` (an empty history)."""
        m, n = self.m, self.n
        n1 = n + 1
        self.cap = cap
        # lag_products is the x block of products_y (while a model waits, f = 1)
        self.merged = self.waiting and self.forgetting == 1.0 and not self.instruments
        length = cap if self.all_lags else 4 * cap
        self.x = np.zeros((m, length, n))
        self.y = np.zeros((m, length, n1))
        self.v = np.zeros((m, length))
        self.u = np.zeros((m, length)) if self.noise else None  # type: ignore[assignment]  # read only with noise
        self.ptr = length  # the window is [ptr, ptr + w)
        self.lag_sums = np.zeros((m, cap))
        self._sums_scratch = np.zeros((m, cap))
        self._lag_powers = self.forgetting ** np.arange(cap, dtype=float)  # f^i of Eq. 21
        self.products_y = self._products_y_scratch = None  # type: ignore[assignment]  # set below while waiting
        self.moment0 = None  # lag-0 moments weighted f (with a noise model, while waiting)
        if self.waiting and self.noise:
            self.moment0 = np.zeros((m, n1, n1))
        self.cross0 = np.zeros((m, n, n1)) if self.waiting and self.instruments else None
        if self.waiting:
            self.products_y = np.zeros((m, n1, cap, n1))
            self._products_y_scratch = np.zeros((m, n1, cap * n1))
        if self.merged:
            self.lag_products = self.products_y[:, :n, :, :n]
            self._products_scratch = None  # type: ignore[assignment]  # unused when merged
        else:
            self.lag_products = np.zeros((m, n, cap, n))
            self._products_scratch = np.zeros((m, n, cap * n))
        self._full = self._restricted(cap)
        self.lag0 = self.lag_products[:, :, 0, :]  # Lambda+_k(0)

    def _restricted(self, w: int) -> LagViews:
        """Views of the first ``w`` lags with the scratch their updates use: ``(lag_sums, .,
        products, .)``, the products flattened to ``(M, rows, w cols)``: ``lag_products``, or
        ``products_y`` when merged."""
        m, n = self.m, self.n
        if self.merged:
            products = self.products_y[:, :, :w].reshape(m, n + 1, w * (n + 1))
            scratch = self._products_y_scratch[:, :, : w * (n + 1)]
            return self.lag_sums[:, :w], self._sums_scratch[:, :w], products, scratch
        products = self.lag_products[:, :, :w].reshape(m, n, w * n)
        return self.lag_sums[:, :w], self._sums_scratch[:, :w], products, self._products_scratch[:, :, : w * n]

    def add(self, sample: Sample, fit: Residuals, noise: Residuals | None, counts: SampleCounts) -> None:
        """Sample ``k`` (``counts.k``): its ``x`` (and while a model waits its ``y``) and its
        residuals ``v_k`` (``u_k``) written in front of the window, then Eqs. 17 and 21."""
        k = counts.k
        if self.ptr == 0:  # no free slot in front of the window: move it back, or grow (all lags)
            self._make_room(k - 1 if k - 1 < self.cap else self.cap)
        cap = self.cap
        w = k if k < cap else cap  # lags held after this sample
        p = self.ptr = self.ptr - 1  # the slot in front of the window
        if self.waiting:
            self.y[:, p] = sample.y
        if not self.merged:  # (merged: the x history is kept in y)
            self.x[:, p] = sample.x
        fit.residual(self.v[:, p])  # v_k (Eqs. 16-17)
        if noise is not None:
            noise.residual(self.u[:, p])  # u_k, the noise model's
        sums, sums_tmp, products, products_tmp = self._full if w == cap else self._restricted(w)
        # Eq. 17 as sums: n_k R_k(i) = f n_(k-1) R_(k-1)(i) + v_k v_(k-i) (with a noise model
        # f_R and its residuals u_k).
        g = self.moment_forgetting
        if g != 1.0:
            sums *= g
        series = self.u if self.noise else self.v
        v_window = series[:, p : p + w]  # v_k, v_(k-1), ...
        lagged = np.multiply(v_window, v_window[:, :1], out=sums_tmp)  # v_k v_(k-i)
        if counts.masking:  # some model's window reaches into its burn-in
            starts, left_out = counts.burn_in(w, cap)
            sums[starts] = 0.0
            lagged[left_out] = 0.0
        sums += lagged
        self._add_products(products, products_tmp, p, w, sample)

    def _add_products(self, products: FloatArray, scratch: FloatArray, p: int, w: int, sample: Sample) -> None:
        """Eq. 21, one-sided: ``Lambda+_k(i) = f^2 Lambda+_(k-1)(i) + f^i x_k x_(k-i)'``, and
        while a model waits the lagged moments weighted ``f^(k-j)`` (``f_R^(k-j)`` with a
        noise model); ``products`` and ``scratch`` are :meth:`_restricted`'s."""
        m, n = self.m, self.n
        if self.merged:  # of y = (x, z): Lambda+ and the lagged moments at once
            y_window = self.y[:, p : p + w].reshape(m, 1, w * (n + 1))  # y_k, y_(k-1), ...
            products += np.multiply(sample.y_col, y_window, out=scratch)
            return
        f = self.forgetting
        x_window = self.x[:, p : p + w].reshape(m, 1, w * n)  # x_k, x_(k-1), ... (a view)
        if f == 1.0:
            products += np.multiply(sample.x_col, x_window, out=scratch)
        else:
            weighted = (x_window.reshape(m, w, n) * self._lag_powers[None, :w, None]).reshape(m, 1, w * n)
            self.lag_products *= f * f
            products += np.multiply(sample.x_col, weighted, out=scratch)
        if self.waiting:
            n1 = n + 1
            moments = self.products_y[:, :, :w].reshape(m, n1, w * n1)
            if self.cross0 is not None:  # sum zeta_j y_j' (instruments)
                self.cross0 += sample.x_col * sample.y[:, None, :]
            if self.moment0 is not None:  # the lag-0 moments weighted f^(k-j)
                self.moment0 *= f
                self.moment0 += sample.y_col * sample.y[:, None, :]
            self.products_y *= self.moment_forgetting
            y_window = self.y[:, p : p + w].reshape(m, 1, w * n1)
            moments += np.multiply(sample.y_col, y_window, out=self._products_y_scratch[:, :, : w * n1])

    def all_initialized(self) -> None:
        """Every model is initialized: ``lag_products`` gets an array of its own and the
        moments are dropped."""
        if not self.waiting:
            return
        if self.merged:
            self.x[...] = self.y[:, :, : self.n]  # the x history was kept in y
            lag_products = np.ascontiguousarray(self.lag_products)
        else:
            lag_products = self.lag_products
        self.waiting = False
        lag_sums, history = self.lag_sums, (self.x, self.y, self.v, self.u)
        ptr = self.ptr
        self._allocate(self.cap)
        self.lag_sums, self.lag_products = lag_sums, lag_products
        self.x, self.y, self.v, self.u = history
        self.ptr = ptr
        self._full = self._restricted(self.cap)
        self.lag0 = self.lag_products[:, :, 0, :]

    def start(self, start: Start, w: int) -> None:
        """Model ``start.model`` initialized (:mod:`.initialization`; ``w`` lags held): its
        lag sums of Eq. 10, its lag products and history in the column-scaled units ``x / s``
        (``start.inv`` is ``1/s``, 0 on padding), and its residual histories (Eq. 7)."""
        j = start.model
        self.lag_sums[j, :w] = start.lag_sums
        products = self.lag_products[j]
        inv = start.inv if start.inv_instruments is None else start.inv_instruments
        products *= inv[:, None, None]  # regressors (instruments) to scaled units
        products *= inv[None, None, :]
        self.y[j, :, : self.n] = start.x_scaled
        self.x[j] = start.x_scaled if start.instruments_scaled is None else start.instruments_scaled
        self.v[j] = start.residuals
        if start.noise_residuals is not None:
            self.u[j] = start.noise_residuals

    def window(self, buf: FloatArray, w: int) -> FloatArray:
        """The last ``w`` entries of a history buffer, newest first (a view)."""
        return buf[:, self.ptr : self.ptr + w]

    def _make_room(self, w: int) -> None:
        """A free slot in front of the ``w`` samples held, when the newest is at slot 0: the
        window moved back to the buffer's end, or with all lags the capacity doubled."""
        if self.all_lags:
            self._grow(w)
        else:
            self._relocate(w)

    def _relocate(self, w: int) -> None:
        """Move the history window from the buffer's front back to its end."""
        length = self.v.shape[1]
        for buf in (self.y, self.v) if self.merged else (self.x, self.y, self.v):
            buf[:, length - w :] = buf[:, :w]
        if self.noise:
            self.u[:, length - w :] = self.u[:, :w]
        self.ptr = length - w

    def _grow(self, w: int) -> None:
        """Double the lag capacity (all lags), keeping the ``w`` samples and lags held."""
        names = (*self._history, "lag_sums", "lag_products", "products_y", "moment0", "cross0")
        old = {name: getattr(self, name) for name in names}
        old_ptr, old_cap = self.ptr, self.cap
        self._allocate(2 * old_cap)
        self.ptr -= w
        if old["moment0"] is not None:
            self.moment0[...] = old["moment0"]  # type: ignore[index]  # allocated again (waiting, noise)
        if old["cross0"] is not None:
            self.cross0[...] = old["cross0"]  # type: ignore[index]  # allocated again (waiting, instruments)
        for name in self._history:
            getattr(self, name)[:, self.ptr :] = old[name][:, old_ptr : old_ptr + w]
        self.lag_sums[:, :old_cap] = old["lag_sums"]
        if old["products_y"] is not None:
            self.products_y[:, :, :old_cap] = old["products_y"]
        if not self.merged:
            self.lag_products[:, :, :old_cap] = old["lag_products"]

    # ------------------------------------------------------------------ state
    def arrays(self, w: int) -> dict[str, FloatArray]:
        """Copies of the history windows (newest first) and the lag-indexed sums (the moments
        only while a model waits)."""
        out = {name: self.window(getattr(self, name), w).copy() for name in self._history}
        out["lag_sums"] = self.lag_sums.copy()
        out["lag_products"] = self.lag_products.copy()  # (a contiguous copy, also of the view)
        if self.waiting:
            out["products_y"] = self.products_y.copy()
            if self.noise:
                out["moment0"] = self.moment0.copy()  # type: ignore[union-attr]  # set while waiting with noise
            if self.cross0 is not None:
                out["cross0"] = self.cross0.copy()
        return out

    def lay_out(self, cap: int, waiting: bool, w: int) -> None:
        """Fresh storage of capacity ``cap`` for a state with ``w`` lags held (``waiting``: some
        model waits for initialization), its history window placed as :meth:`load` fills it."""
        self.waiting = waiting
        self._allocate(cap)
        self.ptr -= w

    def load(self, arrays: Mapping[str, npt.ArrayLike], w: int) -> None:
        """Inverse of :meth:`arrays`, on storage laid out by :meth:`lay_out`."""
        for name in self._history:
            assign_checked(self.window(getattr(self, name), w), arrays[name], name)
        assign_checked(self.lag_sums, arrays["lag_sums"], "lag_sums")
        if self.waiting:
            assign_checked(self.products_y, arrays["products_y"], "products_y")
            if self.noise:
                assign_checked(self.moment0, arrays["moment0"], "moment0")  # type: ignore[arg-type]  # as in arrays()
            if self.cross0 is not None:
                assign_checked(self.cross0, arrays["cross0"], "cross0")
        if not self.merged:
            assign_checked(self.lag_products, arrays["lag_products"], "lag_products")


def assign_checked(target: np.ndarray, value: npt.ArrayLike, name: str) -> None:
    """``target[...] = value`` for a state field, refusing another shape by name."""
    value = np.asarray(value)
    if value.shape != target.shape:
        raise ValueError(f"estimator state field {name!r} has shape {value.shape}, expected {target.shape}")
    target[...] = value
