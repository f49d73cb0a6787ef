"""When can a recursive estimate be trusted? Per-parameter convergence flags.

Grauer and Morelli judge convergence by eye: in Fig. 6 of the paper, "by 6 s ... the
corrected parameter uncertainty envelope enclosed the observed scatter". Across-run scatter
is not available in flight, so the flag uses what one run has: the estimate and its corrected
standard error (Eq. 22) over the last ``T`` seconds. With ``t`` the current stamp and ``a``
the *anchor* -- the newest retained sample stamped at or before ``t - T`` -- a parameter is
flagged *converged* when every sample ``s`` from the anchor to now (inclusive) satisfies

1. **the estimate has settled** -- it lies strictly within ``k`` corrected standard errors
   of the current estimate: ``|theta_s - theta_t| < k se_t``;
2. **its uncertainty has settled** -- the standard error lies strictly within a factor
   ``g = exp(r (t - t_a))`` of the current one, either way: ``se_t / g < se_s < g se_t``
   (a relative rate of change below ``r`` per second);
3. **the history is whole** -- the entry was valid: model ready, not padding, finite
   estimate, finite positive standard error.

A model is flagged when all its parameters are. Nothing is flagged without an anchor: less
than ``T`` seconds since the start or a :meth:`~ConvergenceMonitor.reset`, a stamp that did
not increase (the history restarts), or more samples in ``T`` seconds than the buffer holds.

Exactly as computed (what the brute-force test checks): with ``s_x = max(se_x, 0)`` (NaN when
the model is not ready), ``c = min(s_t, 1e300) * k`` and ``g = exp(min(r (t - t_a), 30))``,
every sample of the window satisfies ``theta_x < theta_t + c``, ``-theta_x < -theta_t + c``,
``s_x < s_t * g`` and ``-s_x < -s_t * (1 / g)``. The strict inequalities fail on NaN, on an
infinite estimate, and on a standard error that is zero, negative or infinite, so no
separate validity test is needed; a standard error below the floating-point resolution of
its estimate (``theta + k se == theta``) is never flagged.

Why these tests. For least squares with white residuals the estimates at ``t - T`` and ``t``
differ by an error of variance ``se_{t-T}^2 - se_t^2``, and a standard error falling like
``1/sqrt(time)`` falls at ``1/(2 time)`` per second, so test 2 passes once the data since
the start of the excitation span more than ``T / (1 - exp(-2 r T))`` (3.2 s with the
defaults) and test 1 once the last ``T`` seconds no longer move the estimate by ``k``
standard errors; test 1 also drops the flag at once when a parameter moves (a failure, a new
flight condition), and test 2, two-sided, holds it down while the corrected standard error
is still *growing* early in a maneuver, when the residual autocorrelation (Eq. 17) has not
yet seen the coloring and the corrected error is too small (at 20% band-limited noise the
mean corrected SE is 0.5 to 0.65 of the observed scatter at 1 s, 0.85 to 1 at 3 s).
Stabilisation of the estimates and of their error bounds is how real-time aircraft
parameter estimation judges convergence (E. A. Morelli, "Real-Time Parameter Estimation in
the Frequency Domain", AIAA-99-4043, 1999: "Parameter estimates converged in less than 1
cycle of the dominant dynamic mode natural frequencies"), but no published quantitative rule
was found: the rule and the thresholds here are ours. Defaults (T = 2 s, about two periods
of the T-2 short-period mode; k = 1; r = 0.25/s) were chosen on a Table 3 Monte Carlo with
another seed (7) than the reported one (2016); ``rls_uncertainty.simulation.montecarlo`` tabulates
flag times against the time the corrected envelope covers the observed scatter, and the
false-convergence rates.

Cost and memory: :meth:`ConvergenceMonitor.update` is a fixed sequence of about twenty small
numpy calls whatever the number of models and parameters (the window maxima come from a
two-stack queue, amortised O(1) per sample, with a rebuild of the front stack once per
window); for 6 models x 6 parameters that is about 15 us on the development machine, where
one call of ``np.add`` on 6 x 6 arrays costs 0.5 us (``validation/convergence/bench.py``).
The history is a buffer of ``2 * capacity`` samples, ``capacity = min(ceil(T * rate_hz) + 2,
max_samples)``, whatever arrives (with its suffix maxima, ``2 * capacity * 4 * M * 8 *
ceil(n_max / 8) * 16`` bytes): samples faster than ``rate_hz`` shorten the span it holds,
and when that no longer reaches back ``T`` seconds nothing is flagged (fail safe).

numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..schema import check, option

__all__ = ["ConvergenceConfig", "ConvergenceMonitor"]

_STAMP_LIMIT = 2**62  # |stamp_ns| below this (146 years): stamp - T stays inside int64
_BIG = 1e300  # cap of the standard error in the band k se (no overflow)
_F64, _BOOL = np.dtype(np.float64), np.dtype(np.bool_)
_MAX_LOG_GAIN = 30.0  # cap of r (t - t_a) (no overflow in g se)


@dataclass(frozen=True)
class ConvergenceConfig:
    """Parameters of the convergence criterion (see the module docstring).

    window:
        ``T``, seconds of history the criterion looks back over.
    band:
        ``k``: every estimate in the window within ``k`` corrected standard errors of the
        current estimate.
    max_se_rate:
        ``r``, 1/s: every standard error in the window within a factor ``exp(r (t - t_a))``
        of the current one (``|ln se_s - ln se_t| < r (t - t_a)``).
    rate_hz:
        Highest sample rate the buffer is sized for: it holds ``ceil(window * rate_hz) + 2``
        samples (the window plus its anchor and one sample of jitter), at most
        ``max_samples``.
    max_samples:
        Hard cap of the buffer, samples.
    """

    window: float = option(2.0, "convergence flags (~/M/converged): seconds of history that must be settled; "
                           "window x rate may not exceed 4094 samples", unit="s", low=0.05, high=60.0,
                           ros="convergence.window")
    band: float = option(1.0, "convergence flags: every estimate of the window within this many current corrected "
                         "standard errors of the current estimate", low=0.01, high=1e6, ros="convergence.band")
    max_se_rate: float = option(0.25, "convergence flags: every standard error of the window within a factor "
                                "exp(max_se_rate x age) of the current one", unit="1/s", low=0.001, high=100.0,
                                ros="convergence.max_se_rate")
    rate_hz: float = option(200.0, "highest sample rate the buffer is sized for", unit="Hz", low=0.0, low_open=True)
    max_samples: int = option(4096, "hard cap of the buffer", unit="samples", low=2)

    def __post_init__(self) -> None:
        check(self, "convergence")

    @property
    def capacity(self) -> int:
        """Samples the buffer holds: ``min(ceil(window * rate_hz) + 2, max_samples)``."""
        return int(min(math.ceil(self.window * self.rate_hz) + 2, self.max_samples))


class ConvergenceMonitor:
    """Per-parameter and per-model convergence flags of ``M`` models, updated once per sample.

    ``sizes`` are the models' parameter counts (as for
    :class:`~rls_uncertainty.estimator.EstimatorBank`); arrays are ``(M, n_max)`` with padding
    after each model's parameters. Padding is never flagged and does not count for the model
    flag. ``update(stamp_ns, theta, se, ready)`` returns ``(flags, model_flags)``.
    """

    def __init__(self, sizes: Sequence[int], config: ConvergenceConfig = ConvergenceConfig()) -> None:
        sizes = tuple(int(s) for s in sizes)
        if not sizes or min(sizes) < 1:
            raise ValueError(f"every model needs at least one parameter, got sizes={sizes}")
        if not isinstance(config, ConvergenceConfig):
            raise TypeError(f"config must be a ConvergenceConfig, got {type(config).__name__}")
        self.config = config
        self.sizes = sizes
        m, n = len(sizes), max(sizes)
        self.shape = (m, n)
        # Internally the parameter axis is padded to whole 64-bit words of flags (8 per word):
        # the four tests of a model combine as words, and a model's flag is one comparison of
        # its words with those of its real parameters.
        self._words = w = -(-n // 8)
        self._npad = npad = 8 * w
        self._mask = np.zeros((m, npad), dtype=bool)
        for j, s in enumerate(sizes):
            self._mask[j, :s] = True
        self._pattern = self._mask.view(np.uint64)  # (m, w)
        self.capacity = cap = config.capacity
        self._window_ns = int(round(config.window * 1e9))
        self._band = np.array(float(config.band))  # 0-d arrays: cheaper ufunc operands
        self._big = np.array(_BIG)
        self._rate = float(config.max_se_rate) * 1e-9  # per nanosecond
        # History rows [theta, se, -theta, -se] in a sliding buffer of 2 * capacity rows:
        # rows [lo, hi) are held (at most capacity); when hi reaches the end, the rows from
        # the anchor on (the only ones still needed) move to the front (amortised O(1)).
        # se is floored at 0, and NaN off the ready models' parameters and in the padding.
        self._stamps = [0] * (2 * cap)  # Python ints: the anchor search reads them one by one
        self._rows = np.full((2 * cap, 4, m, npad), np.nan)
        # Window maxima by a two-stack queue: rows [anchor, front) are the front stack, with
        # suffix maxima in _suffix; rows [front, hi) the back stack, with running maximum
        # _back; the maximum over the window is max(_suffix[anchor], _back).
        self._suffix = np.zeros((2 * cap, 4, m, npad))
        self._back = np.full((4, m, npad), -np.inf)
        self._wmax = np.zeros((4, m, npad))
        # rhs = cur * gain + lim with gain rows [1, g, 1, 1/g] and lim rows [c, 0, c, 0]
        self._gain = np.ones((4, m, npad))
        self._lim = np.zeros((4, m, npad))
        self._rhs = np.zeros((4, m, npad))
        self._ok = np.zeros((4, m, npad), dtype=bool)
        self._ok_words = tuple(self._ok.view(np.uint64))  # 4 x (m, w)
        # The current sample is assembled in _cur (views made once: a view costs as much as
        # a small numpy operation), then copied into the buffer.
        self._cur = np.full((4, m, npad), np.nan)
        c = self._cur
        self._cur_views = (c[0, :, :n], c[1, :, :n], c[:2], c[2:], c[1])
        self._lim_views = (self._lim[0], self._lim[2])
        self._lower = np.full((m, n), np.nan)  # 0 on the ready models' parameters, else NaN
        self._ready_key: bytes | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the history: nothing is flagged until ``window`` seconds have arrived again."""
        self._lo = self._hi = self._front = 0
        self._anchor = -1
        self._last: int | None = None
        self._dt: int | None = None  # t - t_a of the gains g, 1/g
        self._back.fill(-np.inf)

    @property
    def n_held(self) -> int:
        """Samples currently in the buffer (at most :attr:`capacity`)."""
        return self._hi - self._lo

    def no_flags(self) -> tuple[np.ndarray, np.ndarray]:
        """``(flags, model_flags)`` with nothing flagged: what :meth:`update` returns without
        an anchor, and the flags of an estimator that has no sample yet."""
        return np.zeros(self.shape, dtype=bool), np.zeros(self.shape[0], dtype=bool)

    def update(
        self, stamp_ns: int, theta: npt.ArrayLike, se: npt.ArrayLike, ready: npt.ArrayLike
    ) -> tuple[np.ndarray, np.ndarray]:
        """Add one sample; return ``(flags (M, n_max) bool, model_flags (M,) bool)``.

        ``stamp_ns``: sample time, integer nanoseconds (any epoch, ``|stamp| < 2**62``;
        irregular spacing is fine). A stamp that is not after the previous one restarts the
        history (time went backwards: the old samples no longer belong to this window); one
        that is not an integer, or out of range, also returns no flags. ``theta`` and ``se``:
        estimates and corrected standard errors, ``(M, n_max)``, NaN where not available;
        ``ready``: ``(M,)`` bool. A parameter is not flagged while its model was not ready, its
        estimate was not finite or its standard error not finite and positive at any sample
        of the window. The returned arrays are new on every call.
        """
        theta, se, ready = self._arrays(theta, se, ready)
        try:
            stamp = int(stamp_ns)
        except (TypeError, ValueError, OverflowError):
            stamp = None
        if stamp is None or not -_STAMP_LIMIT < stamp < _STAMP_LIMIT:
            self.reset()
            return self.no_flags()
        if self._last is not None and stamp <= self._last:
            self.reset()
        self._last = stamp
        key = ready.tobytes()
        if key != self._ready_key:
            self._ready_key = key
            self._lower = np.where(self._mask[:, : self.shape[1]] & ready[:, None], 0.0, np.nan)
        self._append(stamp, theta, se)
        a = self._advance_anchor(stamp)
        if a < self._lo:
            return self.no_flags()
        return self._flags(stamp, a)

    def _arrays(self, theta: npt.ArrayLike, se: npt.ArrayLike,
                ready: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``theta``, ``se`` as float64 ``(M, n_max)`` and ``ready`` as bool ``(M,)`` arrays
        (as given when they already are), or a ValueError naming the shapes."""
        if type(theta) is not np.ndarray or theta.dtype is not _F64:
            theta = np.asarray(theta, dtype=float)
        if type(se) is not np.ndarray or se.dtype is not _F64:
            se = np.asarray(se, dtype=float)
        if type(ready) is not np.ndarray or ready.dtype is not _BOOL:
            ready = np.asarray(ready, dtype=bool)
        m = self.shape[0]
        if theta.shape != self.shape or se.shape != self.shape or ready.shape != (m,):
            raise ValueError(
                f"expected theta and se of shape {self.shape} and ready of shape {(m,)}, "
                f"got {theta.shape}, {se.shape}, {ready.shape}"
            )
        return theta, se, ready

    def _append(self, stamp: int, theta: np.ndarray, se: np.ndarray) -> None:
        """Append the row ``[theta, se, -theta, -se]`` (se floored at 0, so the arithmetic of
        :meth:`_flags` cannot warn; NaN off the ready models' parameters) to the history and to
        the back stack's running maximum; the oldest rows beyond the capacity leave it."""
        cap = self.capacity
        if self._hi == 2 * cap:  # move the rows still needed (from the anchor on) to the front
            shift = max(self._anchor, self._lo)
            keep = self._hi - shift
            self._stamps[:keep] = self._stamps[shift : self._hi]  # list: same length
            self._rows[:keep] = self._rows[shift : self._hi]
            self._suffix[:keep] = self._suffix[shift : self._hi]
            self._anchor -= shift
            self._front = max(self._front - shift, 0)
            self._lo, self._hi = 0, keep
        i = self._hi
        cur = self._cur
        th_n, s_n, pos, neg, _s = self._cur_views
        th_n[...] = theta
        np.maximum(se, self._lower, out=s_n)
        np.negative(pos, out=neg)
        self._rows[i] = cur
        self._stamps[i] = stamp
        np.maximum(self._back, cur, out=self._back)
        self._hi = hi = i + 1
        if hi - self._lo > cap:
            self._lo = hi - cap

    def _advance_anchor(self, stamp: int) -> int:
        """The anchor: the newest held sample stamped at or before ``stamp - T`` (below
        ``_lo`` when there is none)."""
        cut = stamp - self._window_ns
        a = max(self._anchor, self._lo - 1)
        stamps, hi = self._stamps, self._hi
        while a + 1 < hi and stamps[a + 1] <= cut:
            a += 1
        self._anchor = a
        return a

    def _flags(self, stamp: int, a: int) -> tuple[np.ndarray, np.ndarray]:
        """The four tests of the module docstring over the window from anchor ``a`` to the
        newest row, as ``(flags, model_flags)``."""
        hi = self._hi
        if a >= self._front:  # front stack empty: rebuild it from rows [a, hi)
            np.maximum.accumulate(self._rows[a:hi][::-1], axis=0, out=self._suffix[a:hi][::-1])
            self._front = hi
            self._back.fill(-np.inf)
        wmax = np.maximum(self._suffix[a], self._back, out=self._wmax)

        # Every sample x of the window strictly inside the band around the current one:
        #   theta_x < theta_t + c,   -theta_x < -theta_t + c,   c = k min(se_t, 1e300),
        #   se_x < g se_t,           -se_x < -se_t (1 / g),     g = exp(r (t - t_a)).
        # NaN, an infinite estimate and a zero, negative or infinite se all fail.
        dt = stamp - self._stamps[a]
        if dt != self._dt:
            self._dt = dt
            g = math.exp(min(self._rate * dt, _MAX_LOG_GAIN))
            self._gain[1] = g
            self._gain[3] = 1.0 / g
        s = self._cur_views[4]
        c, c2 = self._lim_views
        np.minimum(s, self._big, out=c)
        np.multiply(c, self._band, out=c)
        c2[...] = c
        rhs = np.multiply(self._cur, self._gain, out=self._rhs)
        np.add(rhs, self._lim, out=rhs)
        np.less(wmax, rhs, out=self._ok)
        # AND of the four tests, eight parameters per 64-bit word.
        ok0, ok1, ok2, ok3 = self._ok_words
        words = ok0 & ok1
        words &= ok2
        words &= ok3
        model = words == self._pattern
        model = model[:, 0] if self._words == 1 else model.all(axis=1)
        return words.view(np.bool_)[:, : self.shape[1]], model
