"""The fast estimator: ``M`` recursive least-squares models updated together (Eqs. 15-22).

:class:`EstimatorBank` runs the six coefficient models of Eq. 2 (3-6 parameters each), or
the hundreds of a Monte Carlo study, with one set of vectorised numpy operations per sample.
Its numbers are those of :class:`.reference.RecursiveReference`, which defines every option
(:class:`.options.EstimatorOptions`); the tests hold the two together. The bank composes one
object per part of the paper, each owning its arrays: :class:`.rls_fit.RlsFit` (Eqs. 15-16;
a second one is the noise model under forgetting), :class:`.counts.SampleCounts` (``k``,
``n_k`` and the residual burn-in), :class:`.lag_storage.LagStorage` (the histories, Eq. 17's
lag sums and Eq. 21's lag products), :class:`.initialization.ExactInitialization` (Eqs. 6, 7,
10) and :class:`.evaluation.Evaluation` (the lag choice and Eqs. 13, 20, 22); the bank hands
each sample from one to the next (:meth:`EstimatorBank._apply`); its snapshot is :mod:`.snapshot`.

With the option ``algorithm="iv"`` the models are recursive instrumental variables: the
instruments come with every sample (:meth:`EstimatorBank.update`), :class:`.iv_fit.IvFit`
takes the place of the least-squares fit, :class:`.iv_initialization.IvInitialization` that of
the exact initialization, the lag storage keeps the instruments' history for Eq. 21, and every
covariance is the sandwich ``P N P'`` (:mod:`.covariance`); :func:`.reference.batch_iv` is its
batch form.

How the hot path differs from the reference, and why (each measured in
``benchmarks/estimator_benchmark.py``):

* Each model works on column-scaled regressors once initialized (``x / s``, the
  :class:`ScaledSample`); results are scaled back on output.
* ``D`` and ``theta`` are the rows of one array ``[D; theta']``, updated by one rank-one
  product (:mod:`.rls_fit`), which also keeps ``D`` exactly symmetric.
* Eq. 17 is kept as the lag sums ``n_k R_k(i)`` and Eq. 21 one-sided (see
  :mod:`.lag_storage`); the sample histories are written once into a newest-first buffer.
* The residual burn-in is not stored (:mod:`.counts`): its ends follow from ``ready_at``,
  its counts are closed forms, and its products are left out only while a window reaches back.
* An update whose every quantity (scaled regressors, output, ``D x``, innovation) is at most
  ``1e100`` in magnitude cannot make a finite state non-finite (its products with anything
  already in the state stay below ``1e254``, which rounding absorbs even next to the largest
  double), so it is applied directly. Any other sample is applied after a copy of the state
  is taken, and rolled back and refused with :class:`NonFiniteInput` if the state is not
  finite after it. (What the guard does not cover: ``D`` growing without bound under
  forgetting when a regressor stays zero for a very long time.)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import EstimatorNotReady, NonFiniteInput
from .counts import SampleCounts
from .evaluation import Evaluation, kind_index
from .initialization import ExactInitialization
from .iv_fit import InstrumentSample, IvFit
from .iv_initialization import IvInitialization
from .lag_storage import GROWTH_START, FloatArray, LagStorage
from .options import EstimatorOptions, check_kind
from .publication import PublicationRule
from .rls_fit import RlsFit
from .snapshot import BankSnapshot
from .state import STATE_FORMAT

__all__ = ["EstimatorBank", "ScaledSample"]

_F64 = np.dtype(np.float64)

# A sample whose quantities are all at most this in magnitude is applied without checks.
_SAFE = 1e100
_SAFE_SQUARED = _SAFE * _SAFE


def as_regressors(
    X: npt.NDArray[Any] | Sequence[npt.ArrayLike], sizes: tuple[int, ...], what: str = "regressors",
) -> FloatArray:
    """``X`` as the ``(M, n_max)`` array of regressors (or instruments: ``what``) of models of
    ``sizes`` parameters, from such an array or a sequence of ``M`` vectors; another shape is
    refused."""
    m, n = len(sizes), max(sizes)
    if isinstance(X, np.ndarray) and X.shape == (m, n):
        return X if X.dtype == float else X.astype(float)
    rows = [X] if isinstance(X, np.ndarray) and X.ndim == 1 else list(X)
    if len(rows) != m:
        raise ValueError(f"expected {what} for {m} models, got {len(rows)}")
    x = np.zeros((m, n))
    for j, (row, s) in enumerate(zip(rows, sizes, strict=True)):  # (lengths checked above)
        values = np.asarray(row, dtype=float).reshape(-1)
        if values.shape != (s,):
            raise ValueError(f"model {j} has {s} parameters, got {values.shape[0]} {what}")
        x[j, :s] = values
    return x


def given_instruments(
    instruments: npt.NDArray[Any] | Sequence[npt.ArrayLike] | None, iv: bool, sizes: tuple[int, ...],
) -> FloatArray:
    """A sample's instruments as :func:`as_regressors` makes the regressors, for a bank whose
    algorithm is ``"iv"`` (``iv``); otherwise, or without them, one clear error."""
    if not iv:
        raise ValueError("instruments are taken only with estimator algorithm 'iv'")
    if instruments is None:
        raise ValueError("estimator algorithm 'iv' needs the instruments of every sample: update(X, z, instruments)")
    return as_regressors(instruments, sizes, "instruments")


class ScaledSample:
    """The sample being added, as the models see it: ``y = (x / s, z)`` ``(M, n+1)``, the
    column-scaled regressors ``x`` and the outputs ``z`` side by side, with the views the
    fits and the lag storage read (``x_col``, ``y_col``: columns)."""

    def __init__(self, m: int, n: int) -> None:
        self.y = np.zeros((m, n + 1))
        self.x = self.y[:, :n]
        self.z = self.y[:, n]
        self.x_col = self.x[:, :, None]
        self.y_col = self.y[:, :, None]
        self._flat = self.y.reshape(-1)
        self._magnitude = np.zeros_like(self._flat)

    def set(self, x: FloatArray, inv_s: FloatArray, z: FloatArray) -> bool:
        """``y = (x / s, z)`` (``inv_s`` = ``1/s``); True when every entry is at most 1e100 in
        magnitude (NaN, infinity or a larger number: False)."""
        np.multiply(x, inv_s, out=self.x)
        self.z[...] = z
        small: bool = np.maximum.reduce(np.absolute(self._flat, out=self._magnitude)) <= _SAFE
        return small


class EstimatorBank(BankSnapshot):
    """``M`` independent recursive least-squares models updated together (Eqs. 15-22).

    ``sizes``: the number of parameters of each model, e.g. ``(3, 4, 3, 6, 4, 4)`` for Eq.
    2a-f. ``options``: :class:`.options.EstimatorOptions` (lags, window, forgetting, residual,
    residual burn-in, noise model, initialization), shared by every model; defined in
    :mod:`.reference`, tabulated in ``docs/estimator.md``.
    """

    STATE_FORMAT = STATE_FORMAT

    def __init__(self, sizes: Sequence[int], options: EstimatorOptions | None = None) -> None:
        sizes = tuple(int(s) for s in sizes)
        if not sizes or min(sizes) < 1:
            raise ValueError(f"every model needs at least one parameter, got sizes={sizes}")
        o = EstimatorOptions() if options is None else options
        if not isinstance(o, EstimatorOptions):
            raise TypeError(f"options must be an EstimatorOptions, got {type(o).__name__}")
        self.options = o
        self.sizes = sizes
        self.n_models = m = len(sizes)
        self.n_max = n = max(sizes)
        self.forgetting = f = o.forgetting
        g = o.noise_forgetting_used  # f_R
        self._mask = np.arange(n) < np.array(sizes)[:, None]  # each model's parameters, not the padding
        self._sample = ScaledSample(m, n)
        self._iv = o.algorithm == "iv"
        self._instruments = InstrumentSample(self._sample, m, n)  # (read with algorithm iv)
        self._zeta: FloatArray = np.zeros((m, n))  # this sample's instruments, as given
        self._noise = RlsFit(m, n, g, o.residual) if o.noise_model else None  # gives R_k(i) (f < 1)
        self._counts = SampleCounts(m, f, g, o.noise_model, o.burn_in)
        held = o.held
        self._lags = LagStorage(
            m, n, GROWTH_START if held is None else held + 1, all_lags=held is None, forgetting=f,
            waiting=o.p0 is None, noise_forgetting=g, instruments=self._iv,
        )
        # [D; theta'] in column-scaled units, S D S and S theta (iv: [P'; theta'], S P T and S theta)
        self._fit = IvFit(m, n, o.residual, self._instruments, self._lags) if self._iv else RlsFit(m, n, f, o.residual)
        self._init = (IvInitialization(sizes, n, o.init_condition, o.iv_init_samples) if self._iv
                      else ExactInitialization(sizes, n, o.init_condition, prior=o.p0 is not None))
        self._eval = Evaluation(o, sizes, self._fit, self._lags, self._counts)
        self._rule = PublicationRule(sizes, o)
        prior = o.prior(n)
        if prior is not None:
            D0 = np.eye(n) * prior * self._mask[:, :, None] * self._mask[:, None, :]
            self._fit.set_prior(D0)  # type: ignore[union-attr]  # (rls: the options refuse p0 with iv)
            if self._noise is not None:
                self._noise.set_prior(D0)
        self._readiness_changed()

    def _readiness_changed(self) -> None:
        """Recompute what depends on which models are ready (after an initialization or a
        restored state)."""
        ready = self._init.ready
        self._rule.restart()
        if ready.all():
            self._lags.all_initialized()
        self._counts.restart(ready, self._init.ready_at, self._lags.cap)
        self._eval.readiness_changed(ready, self._init.inv_s)

    @property
    def k(self) -> int:
        """The number of samples processed."""
        return self._counts.k

    @property
    def n_eff(self) -> float:
        """``n_k = sum_j f^(k-j)``, the estimator's weight total (``k`` when ``f = 1``)."""
        return self._counts.n

    @property
    def n_noise(self) -> float:
        """``n^N_k = sum_j f_R^(k-j)``, the noise model's weight total (0 without one)."""
        return self._counts.n_noise

    @property
    def n_window(self) -> int:
        """Number of lags currently held: ``min(k, lags + 1)``, or ``k`` for all lags."""
        return min(self._counts.k, self._lags.cap)

    # ------------------------------------------------------------------ update
    def update(
        self, X: npt.NDArray[Any] | Sequence[npt.ArrayLike], z: npt.ArrayLike,
        instruments: npt.NDArray[Any] | Sequence[npt.ArrayLike] | None = None,
    ) -> None:
        """Process one sample for every model (Eqs. 15-17, 21).

        ``X`` is ``(M, n_max)`` (row ``j`` holds model ``j``'s regressors first; the padding
        is ignored) or a sequence of ``M`` regressor vectors; ``z`` holds the ``M`` measured
        outputs; ``instruments`` (algorithm ``"iv"`` only, and then required) are shaped as
        ``X``, one instrument per parameter. A NaN or infinite input, or one that would make
        the state non-finite, raises :class:`NonFiniteInput` and leaves the state unchanged.
        """
        if self._iv or instruments is not None:
            self._zeta = given_instruments(instruments, self._iv, self.sizes)
        if type(X) is np.ndarray and X.shape == self._mask.shape and X.dtype == _F64:
            x = X
        else:
            x = as_regressors(X, self.sizes)
        if not (type(z) is np.ndarray and z.shape == (self.n_models,) and z.dtype == _F64):
            z = np.asarray(z, dtype=float).reshape(-1)
            if z.shape != (self.n_models,):
                raise ValueError(f"expected {self.n_models} measured outputs, got shape {z.shape}")
        if self._prepare(x, z):
            self._apply()
        else:
            self._apply_checked(x, z)

    def _prepare(self, x: FloatArray, z: FloatArray, check: bool = True) -> bool:
        """The sample ``y = (x / s, z)`` and the fits' ``(D x, theta' x - z)`` and ``d_k``:
        the state is not touched. True when every entry of ``y`` and of ``(D x, theta' x -
        z)`` is at most 1e100 in magnitude (then the update keeps a finite state finite); with
        ``check``, NaN, infinity or a larger number in ``y`` stops it early and returns False."""
        sample = self._sample
        small = sample.set(x, self._init.inv_s, z)
        if self._iv:
            small = self._instruments.set(self._zeta, self._init.inv_t) and small  # type: ignore[attr-defined]
        if check and not small:
            return False
        magnitude = self._fit.prepare(sample.x, sample.x_col, sample.z)
        small = small and magnitude <= _SAFE_SQUARED
        if self._noise is not None:  # the same for the noise model (forgetting f_R)
            magnitude = self._noise.prepare(sample.x, sample.x_col, sample.z)
            small = small and magnitude <= _SAFE_SQUARED
        return small

    def _apply(self) -> None:
        """Add the prepared sample to the state."""
        self._fit.update()  # Eqs. 15a-c
        if self._noise is not None:
            self._noise.update()  # the noise model: Eq. 15 with f_R
        self._counts.add()  # k, n_k, n^N_k
        sample = self._instruments if self._iv else self._sample
        self._lags.add(sample, self._fit, self._noise, self._counts)  # v_k (u_k), Eqs. 17, 21
        if self._lags.waiting:
            self._initialize()  # Eqs. 6, 7, 10 for the models that allow it

    def _initialize(self) -> None:
        """Initialize the waiting models whose data allow it (:mod:`.initialization`): the
        batch solution (Eq. 6) to the fits, the residuals (Eq. 7) and their lag sums (Eq. 10)
        to the lag storage."""
        w = self.n_window
        started = self._init.check(self._counts.k, w, self._lags)
        for start in started:
            self._fit.start(start.model, start.D, start.theta)
            if self._noise is not None and start.D_noise is not None and start.theta_noise is not None:
                self._noise.start(start.model, start.D_noise, start.theta_noise)
            self._lags.start(start, w)
        if started:
            self._readiness_changed()

    def _apply_checked(self, x: FloatArray, z: FloatArray) -> None:
        """Apply a sample on which :meth:`_prepare` found NaN, infinity or a large number:
        refuse a non-finite input, or one that would make the state non-finite."""
        zeta = self._zeta if self._iv else x
        bad = [
            j for j in range(self.n_models)
            if not (np.isfinite(x[j, : self.sizes[j]]).all() and np.isfinite(z[j])
                    and np.isfinite(zeta[j, : self.sizes[j]]).all())
        ]
        if bad:
            raise NonFiniteInput(f"non-finite regressor, instrument or output for model(s) {bad}; sample ignored")
        if self._iv:
            self._zeta = np.where(self._mask, zeta, 0.0)
        x = np.where(self._mask, x, 0.0)  # the padding is ignored
        before = self.state()
        with np.errstate(all="ignore"):  # overflow is what is being checked
            self._prepare(x, z, check=False)
            self._apply()
        finite = all(np.isfinite(a).all() for a in self.state()["arrays"].values())
        if not finite:  # back to the state before it (the evaluation's results of it stay valid)
            self._restore(before["counters"], before["arrays"])
            raise NonFiniteInput(
                "sample ignored: its magnitude would make the estimator state non-finite "
                f"(largest |regressor| {np.max(np.abs(x)):.3g}, largest |output| {np.max(np.abs(z)):.3g})"
            )

    # ------------------------------------------------------------------ results
    @property
    def ready(self) -> np.ndarray:
        """Boolean per model: published, i.e. :attr:`initialized` and past the publication
        rule (:mod:`.publication`): nothing of a model is published before."""
        return self._published().copy()

    @property
    def initialized(self) -> np.ndarray:
        """Boolean per model: exactly initialized (Eqs. 6, 7, 10), so estimates and
        covariances exist (:meth:`theta`, :meth:`covariance`), published or not."""
        return self._init.ready.copy()

    def _published(self) -> np.ndarray:
        return self._rule.published(self._counts.k, self._init.ready, self._init.ready_at)

    @property
    def publish_count(self) -> np.ndarray:
        """What the publication rule counts for each model, ``(M,)``: the samples ``k``, or
        after a residual burn-in those after it (``k - k0 - B``; negative before it)."""
        return self._rule.count(self._counts.k, self._init.ready, self._init.ready_at)

    @property
    def publish_at(self) -> np.ndarray:
        """The :attr:`publish_count` at which each model publishes, ``(M,)``: ``n +
        ceil(publish_lag_windows x L)``."""
        return self._rule.at.copy()

    @property
    def ready_at(self) -> np.ndarray:
        """Sample count at which each model was initialized (0 while not ready)."""
        return np.where(self._init.ready, self._init.ready_at, 0)

    @property
    def n_samples(self) -> int:
        return self._counts.k

    @property
    def repairs(self) -> np.ndarray:
        """How many evaluated corrected covariances of each model needed a positive
        semi-definite repair, ``(M,)``."""
        return self._eval.repairs.copy()

    def _require(self, j: int) -> None:
        if not self._init.ready[j]:
            raise EstimatorNotReady(
                f"model {j} is not initialized after {self.k} samples: its regressors "
                "have not yet made X'X well conditioned"
            )

    def theta(self, j: int) -> np.ndarray:
        """Parameter estimate ``theta_k`` of model ``j`` (Eq. 15c)."""
        self._require(j)
        s_n = self.sizes[j]
        theta: FloatArray = self._fit.theta[j, :s_n] * self._init.inv_s[j, :s_n]
        return theta

    def theta_all(self) -> np.ndarray:
        """Estimates of every model as an ``(M, n_max)`` array; padding and models that are
        not :attr:`ready` (published) are NaN."""
        theta = self._eval.theta_all()
        rule = self._rule
        if not rule.all_published:
            self._published()  # (judged once per sample: rule.hidden)
            np.copyto(theta, np.nan, where=rule.hidden)
        return theta

    @property
    def n_R(self) -> np.ndarray:
        """The weight total of each model's ``R_k(i)``, ``(M,)``: ``n^N_k = sum_j f_R^(k-j)``
        with a noise model, otherwise ``n_k = sum_j f^(k-j)``; after a model's residual
        burn-in the sum runs over ``j > k0 + B`` only."""
        return np.broadcast_to(self._counts.weight_totals(), (self.n_models,)).copy()

    def residual_variance(self, j: int) -> float:
        """Fit-error variance (Eq. 16), i.e. ``R_k(0)`` (the noise model's under forgetting)."""
        self._require(j)
        return float(self._lags.lag_sums[j, 0] / self.n_R[j])

    def residual_variances(self) -> np.ndarray:
        """:meth:`residual_variance` of every model at once, a new ``(M,)`` array, NaN for the
        models that are not :attr:`ready` (one vectorised step: the per-sample fit test of
        :mod:`rls_uncertainty.datapath.identifiability`)."""
        totals = self._counts.weight_totals()
        if isinstance(totals, float) and totals > 0.0:
            R0: FloatArray = self._lags.lag_sums[:, 0] / totals
        else:  # per model after a burn-in; none yet right after it (0 / 0: NaN)
            with np.errstate(divide="ignore", invalid="ignore"):
                R0 = self._lags.lag_sums[:, 0] / totals
        return np.where(self._init.ready, R0, np.nan)

    def autocorrelation(self, j: int) -> np.ndarray:
        """Residual autocorrelation ``R_k(i)``, ``i = 0..n_window-1`` (Eq. 17; under
        forgetting that of the noise model's residuals, weighted ``f_R^(k-j)``; after the
        residual burn-in from the samples after it)."""
        self._require(j)
        R: FloatArray = self._lags.lag_sums[j, : self.n_window] / self.n_R[j]
        return R

    def residuals(self, j: int) -> np.ndarray:
        """Stored residuals of the estimator, oldest first: the whole history with all lags,
        otherwise the last ``held + 1``."""
        self._require(j)
        return self._lags.window(self._lags.v, self.n_window)[j, ::-1].copy()

    def noise_residuals(self, j: int) -> np.ndarray:
        """The residuals behind ``R_k(i)``, stored as :meth:`residuals`: the noise model's
        ``u_k`` under forgetting, otherwise the estimator's own residuals."""
        self._require(j)
        buf = self._lags.v if self._noise is None else self._lags.u
        return self._lags.window(buf, self.n_window)[j, ::-1].copy()

    @property
    def lags_used(self) -> np.ndarray:
        """The largest lag ``L`` of Eq. 22 each model uses at this sample, ``(M,)`` ints: with
        ``lags="auto"`` chosen by the flat-top rule (:mod:`.evaluation`), otherwise
        ``min(lags, k - 1)`` (``k - 1`` with all lags)."""
        return self._eval.lags_chosen().copy()

    @property
    def rule_samples(self) -> np.ndarray:
        """The sample count the lag rule uses for each model, ``(M,)``: ``k``, or under
        forgetting Kish's effective size of the weights ``f_R^(k-j)`` of ``R_k(i)``; after a
        model's residual burn-in the same with ``k - k0 - B`` samples (:mod:`.counts`)."""
        return np.broadcast_to(self._counts.rule_samples(), (self.n_models,)).copy()

    def standard_errors_all(self, kind: str = "corrected") -> np.ndarray:
        """Standard errors of every model as an ``(M, n_max)`` array: the square roots of the
        diagonals of :meth:`covariance`. Padding and models that are not :attr:`ready`
        (published) are NaN."""
        return self.standard_errors_both()[kind_index(kind)]

    def standard_errors_both(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`standard_errors_all` of both kinds at once: ``(corrected, conventional)``."""
        se = self._eval.evaluate().standard_errors  # (2, M, n_max)
        rule = self._rule
        if not rule.all_published:
            self._published()  # (judged once per sample: rule.hidden)
            se = np.where(rule.hidden, np.nan, se)
        return se[0], se[1]

    def covariance(self, j: int, kind: str = "corrected", *, repair: bool = True) -> np.ndarray:
        """Parameter covariance of model ``j``.

        ``kind="corrected"``: Eq. 20 (all lags) or Eq. 22 with the chosen window.
        ``kind="conventional"``: Eq. 13 with the fit-error variance of Eq. 16.
        With ``repair`` (default) a corrected covariance with a negative diagonal is replaced
        by the nearest positive semi-definite matrix and counted in :attr:`repairs` (once per
        sample), or by zero where the model fits exactly.
        """
        index = kind_index(kind)
        self._require(j)
        return self._eval.evaluate().matrix(index, j, self.sizes[j], repair=repair)

    def covariance_all(self, kind: str | None = None) -> np.ndarray:
        """:meth:`covariance` (repaired) of every model and both kinds at once, a new
        ``(2, M, n_max, n_max)`` array: ``[0]`` corrected, ``[1]`` conventional; NaN outside
        the :attr:`ready` (published) models' blocks. With ``kind``, that kind's alone ``(M,
        n_max, n_max)`` (the other kind not formed for it)."""
        published, evaluated = self._published(), self._eval.evaluate()
        cov = (evaluated.published(self.sizes, published) if kind is None
               else evaluated.published_kind(kind_index(kind), self.sizes, published))
        rule = self._rule
        if not rule.all_published:
            np.copyto(cov, np.nan, where=rule.hidden[:, :, None])
        return cov

    def standard_errors(self, j: int, kind: str = "corrected") -> np.ndarray:
        """Square roots of the covariance diagonal (never NaN: see :meth:`covariance`)."""
        check_kind(kind)
        self._require(j)
        return self._eval.standard_errors(kind)[j, : self.sizes[j]].copy()
