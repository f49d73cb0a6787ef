"""The single data path from stamped sensor messages to estimates (numpy only).

The ROS node, the offline replay and the tests all drive one :class:`Pipeline`, which
coordinates the modules that do the work:

1. ``add_imu``, ``add_airspeed``, ``add_dynamic_pressure``, ``add_surfaces``, ``add_thrust``
   take plain stamped numbers in the REP-103 body frame (x forward, y left, z up) and SI, one
   per input stream of :data:`STREAMS`. :class:`.intake.Intake` judges each message
   (``limits.*``, ``inputs.frame_id``), mixes JointState surfaces into Eq. 23's deflections
   (:mod:`.surface_mixing`) and hands it to the sampler.
2. :mod:`.sampling` buffers the streams, counts every message (accepted, or rejected with a
   reason), and forms samples on the grid ``t_k = k / rate`` by linear interpolation, never
   extrapolating; the pipeline names the streams a sample needs. When the stamps move to a new
   timeline (a looped replay, a confirmed jump) the sampler says so between the samples of the
   two timelines, and the pipeline restarts its data path there (:meth:`Pipeline._restart`).
3. Rates go through the fixed-lag differentiator (:mod:`.differentiation`); every other
   signal waits in a delay line of the same lag, so a sample reaches the aerodynamics
   ``lag`` samples late but time-aligned.
4. :mod:`.aero` converts the sample to aircraft body axes (:func:`.aero.aircraft_sample`),
   then Eq. 1 coefficients and Eq. 2 regressors feed one :class:`.estimator.EstimatorBank`
   (Eqs. 15-22), and each used sample yields a :class:`SampleOutput`: estimates, standard
   errors, per-parameter convergence flags (:mod:`.convergence`, one monitor reset with the
   estimator) and, every ``outputs.covariance_decimation`` grid points, the full covariances.
   What leaves for ROS is made of it at the edge (:mod:`.outputs`). With ``estimator.method``
   ``frequency`` or ``both`` the same rows also feed the frequency-domain estimator
   (:mod:`.frequency_path`), whose results ride in :attr:`SampleOutput.frequency`.

Every formed sample ends as used or as rejected with a reason, and every message as accepted
or rejected: :class:`.bookkeeping.Bookkeeping` holds every counter and what the refused inputs
carried, :meth:`Pipeline.counters` reports them (the node's ``/diagnostics``), and a
reconfigured pipeline takes over the same object.

Nothing non-finite leaves: a message in another frame than ``inputs.frame_id``, or with a value
that is non-finite or beyond ``limits.*`` (:class:`.limits.PlausibilityLimits`), is rejected
with its reason; so is a sample that is implausible once formed, or that the estimator refuses
(``non_finite_regression``); and a model whose outputs are not all finite is marked not
``ready`` in its :class:`SampleOutput` and counted.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..aero.coefficients import (
    RATES,
    FloatArray,
    aircraft_sample,
    coefficients,
    flight_state,
    regressors,
)
from ..aero.differentiation import FixedLagDifferentiator
from ..aero.models import REGRESSOR_UNITS
from ..aero.surface_mixing import SURFACES
from ..errors import NonFiniteInput, Refused, StateFileError
from ..estimator import EstimatorBank
from ..state_file import EstimatorState, load_state, save_state
from .alerts import explanations
from .bookkeeping import Bookkeeping, model_fit
from .config import PipelineConfig
from .convergence import ConvergenceMonitor
from .frequency_path import FrequencyPath
from .guard import withheld as unpublishable
from .identifiability import IdentifiabilityMonitor
from .instrument_path import InstrumentPath
from .intake import Intake
from .pipeline_inputs import PipelineInputs
from .sample_output import SampleOutput
from .sampling import Sample, Sampler, Skipped
from .states import model_report
from .targets import TargetTracker

__all__ = ["Pipeline", "SampleOutput", "STREAMS", "StateFileError", "required_streams", "sampler_for",
           "uses_excitation", "uses_instruments", "all_lags_bank"]

# The input streams, one per ``add_*`` method: inertial data, air data and the optional ones.
STREAMS = ("imu", "airspeed", "dynamic_pressure", "control_surfaces", "thrust", "excitation")


def required_streams(config: PipelineConfig) -> tuple[str, ...]:
    """The streams every sample needs: IMU and air data always, the others when the
    configuration uses them (the order is the order of the rejection checks)."""
    uses = {r for m in config.models for r in m.regressors}
    required = ["imu", "airspeed"]
    if uses & set(SURFACES):
        required.append("control_surfaces")
    if config.inputs.use_dynamic_pressure:
        required.append("dynamic_pressure")
    if config.inputs.use_thrust and any(m.output == "CX" for m in config.models):
        required.append("thrust")
    if uses_excitation(config):
        required.append("excitation")
    return tuple(required)


def uses_excitation(config: PipelineConfig) -> bool:
    """Whether the estimator needs the injected excitation (``estimator.algorithm iv`` with
    ``instruments.source`` resolved to ``excitation``: its instruments are built from it)."""
    return uses_instruments(config) and config.instruments.resolved_source(config.models) == "excitation"


def uses_instruments(config: PipelineConfig) -> bool:
    """Whether the estimator takes instruments with its rows (``estimator.algorithm iv``)."""
    return getattr(config.estimator, "algorithm", "rls") == "iv"


def symmetric_covariances(c: np.ndarray, real: np.ndarray, real_square: np.ndarray, ready: np.ndarray) -> np.ndarray:
    """``(2, M, n_max, n_max)`` from :meth:`.estimator.EstimatorBank.covariance_all` ``c``
    (changed in place): made exactly symmetric (``(C + C')/2``: the products leave
    rounding-level asymmetry), NaN off the ready models' parameters (``real`` ``(M, n_max)``
    marks the parameters, ``real_square`` their blocks)."""
    # A negative variance only at an exact fit (the initialization sample), whose R(0)
    # comes out as a tiny negative number: zero, as its standard errors are.
    smallest = np.minimum.reduce(c.diagonal(0, 2, 3), axis=2, where=real, initial=np.inf)
    c[smallest < 0.0] = 0.0
    cov = c + c.swapaxes(2, 3)
    cov *= 0.5
    # NaN off the ready models' blocks (padding, models not ready or withheld).
    np.copyto(cov, np.nan, where=~(real_square & ready[:, None, None]))
    return cov


def sampler_for(config: PipelineConfig, required: Sequence[str], book: Bookkeeping) -> Sampler:
    """The :class:`.sampling.Sampler` of a configuration: its grid, gap, buffer and timeline
    settings (``inputs.*``), the streams every sample needs, and the bookkeeping's counters."""
    inputs = config.inputs
    return Sampler(
        STREAMS,
        tuple(required),
        period_ns=config.period_ns,
        max_gap_ns=inputs.max_gap_ns,
        buffer_ns=inputs.buffer_ns,
        max_jump_ns=inputs.max_stamp_jump_ns,
        confirm=inputs.jump_confirmation,
        max_buffered=inputs.max_buffered,
        max_clock_ns=inputs.max_clock_offset_ns,
        counts=book.streams,
    )


def all_lags_bank(pipe: Pipeline, upto_ns: int | None = None) -> EstimatorBank:
    """A bank with every lag (Eq. 20) fed the regression rows ``pipe`` kept (``record``), in
    order, up to ``upto_ns`` (with ``estimator.algorithm iv``, with their instruments); the other
    options are the run's (the residual burn-in resolved as configured)."""
    o = pipe.config.estimator
    bank = EstimatorBank(pipe.sizes, replace(o, lags="all", residual_burn_in=o.burn_in, noise_forgetting=None))
    zetas = pipe.instruments if o.algorithm == "iv" else None
    for i, (t, X, z) in enumerate(pipe.regression):
        if upto_ns is not None and t > upto_ns:
            break
        if zetas is None:
            bank.update(X, z)
        else:
            bank.update(X, z, instruments=zetas[i])
    return bank


class Pipeline(PipelineInputs):
    """Sample formation, differentiation, aero reduction and estimation for one configuration.

    ``record=True`` keeps every regression row and output handed to the estimator
    (``self.regression``), for batch comparisons and the replay's plots. ``bookkeeping``
    continues the counters of an earlier pipeline (:meth:`reconfigured`).
    """

    def __init__(
        self,
        config: PipelineConfig,
        *,
        record: bool = False,
        enabled: bool = True,
        bookkeeping: Bookkeeping | None = None,
    ) -> None:
        self.config = config
        self.models = config.models
        self.parameter_names = [m.parameter_names for m in config.models]
        self.labels = [",".join(names) for names in self.parameter_names]
        self.sizes = [len(m.regressors) for m in config.models]
        self.enabled = enabled
        self.record = record
        self.regression: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.instruments: list[np.ndarray] = []  # with estimator.algorithm iv, each row's (record)
        self.bookkeeping = book = bookkeeping if bookkeeping is not None else Bookkeeping.for_streams(STREAMS)
        self.required = required_streams(config)
        inputs = config.inputs
        self.sampler = sampler_for(config, self.required, book)
        self.intake = Intake(self.sampler, config.limits, config.surfaces, book)
        # The caller's clock is compared with the stamps only when inputs.max_clock_offset > 0
        # (the node then sets clock_ns before each message; the offline replay has no clock).
        self.needs_clock = inputs.max_clock_offset_ns > 0
        # Where the optional streams sit in a sample's values (None: not required).
        where = {name: i for i, name in enumerate(self.required)}
        self._i_qbar = where.get("dynamic_pressure")
        self._i_surfaces = where.get("control_surfaces")
        self._i_thrust = where.get("thrust")
        self._i_excitation = where.get("excitation")
        self.limits = config.limits
        self.frame_id = inputs.frame_id  # checked by inputs.feed
        self._index = 0
        self._monitor = ConvergenceMonitor(self.sizes, replace(config.convergence, rate_hz=config.rate))
        # targets.percent: each named parameter's time left and the test point's verdict.
        self.targets = TargetTracker([p for names in self.parameter_names for p in names], config.targets) \
            if config.targets.percent() else None
        self._flat = np.flatnonzero(np.arange(max(self.sizes)) < np.array(self.sizes)[:, None])  # (the parameters)
        # Identifiability (the fit, excitation, collinearity) takes its flags out of the monitor's.
        rows = [m.regressors for m in config.models]
        self._x_names = [name for names in rows for name in names]
        self._quality = IdentifiabilityMonitor(rows, [[REGRESSOR_UNITS[r] for r in row] for row in rows],
                                               config.identifiability, config.estimator.forgetting)
        self.named_after = math.ceil(config.convergence.window * config.rate)  # samples before a cause is named
        self.last_stamp_ns: int | None = None  # the newest sample the estimator used
        # outputs.covariance_decimation; the node raises it while it cannot keep up (.load_policy)
        self.covariance_every = config.outputs.covariance_decimation
        self._period_ns = config.period_ns
        self._new_estimator()
        self._diff = FixedLagDifferentiator(config.differentiator, 1.0 / config.rate, width=3)
        self._lag = config.differentiator.lag
        self._pending: deque = deque()  # the delay line: (stamp, sample, excitation) awaiting rate_dot
        self._outputs = [m.output for m in config.models]
        # Where each model's regressors go in the (M, n_max) regression matrix, flattened.
        n_max = self.bank.n_max
        self._x_index = np.array([j * n_max + i for j, names in enumerate(rows) for i in range(len(names))],
                                 dtype=np.intp)
        self._real = np.arange(n_max) < np.array(self.sizes)[:, None]  # (M, n_max): not padding
        self._real_square = self._real[:, :, None] & self._real[:, None, :]  # (M, n_max, n_max)

    def _new_estimator(self) -> None:
        self.bank = EstimatorBank(self.sizes, self.config.estimator)
        self._X = np.zeros((len(self.sizes), self.bank.n_max))
        self._z = np.zeros(len(self.sizes))
        self._quality.reset()  # its output sums (R^2) and regressor statistics restart too
        self._withheld = np.zeros(len(self.sizes), dtype=bool)  # the last output's, per model
        self._monitor.reset()
        if self.targets is not None:
            self.targets.reset()
        self._converged = self._monitor.no_flags()  # the newest sample's flags
        self._last: SampleOutput | None = None  # the newest sample's output
        # estimator.method frequency or both: the frequency-domain estimator on the same rows.
        self.frequency = FrequencyPath(self.config) if self.config.frequency is not None else None
        # estimator.algorithm iv: the rows' instruments (rows waiting for them end as rejected).
        iv = getattr(self, "_iv", None)
        if iv is not None and iv.waiting:
            self.bookkeeping.reject_samples("instruments_not_ready", iv.waiting)
        self._iv = InstrumentPath(self.config) if uses_instruments(self.config) else None

    @property
    def identifiability(self) -> IdentifiabilityMonitor:
        """The identifiability figures of the newest sample (:mod:`.identifiability`)."""
        return self._quality

    @property
    def samples_used(self) -> int:
        """Samples that reached an estimator, over the pipeline's life (reconfigurations too)."""
        return self.bookkeeping.samples_used

    # ------------------------------------------------------------------ per sample
    def _advance(self) -> list[SampleOutput]:
        out: list[SampleOutput] = []
        book = self.bookkeeping
        for item in self.sampler.due():
            if isinstance(item, Sample):
                book.samples_formed += 1
                values = item.values
                i_u = self._i_excitation
                result = self._process(item.stamp_ns, self._sample_vector(values),
                                       None if i_u is None else values[i_u])
                if result is not None:
                    out.append(result)
            elif isinstance(item, Skipped):  # grid points not formed: the differentiator restarts after them
                book.samples_formed += item.count
                book.reject_samples(item.reason, item.count)
                self._flush("discontinuity")
            else:  # Restart: the stamps moved to a new timeline
                self._restart(item.reason)
        return out

    def _restart(self, reason: str) -> None:
        """The data moved to a new timeline (every sample of the previous one was formed): the
        delay line is dropped (``reset_<reason>``) and the differentiator restarts. After a
        backward jump (a looped replay, ``/clock`` went back) the estimator restarts too; after a
        forward jump it goes on, as after a dropout: the later data is the same flight."""
        self.bookkeeping.resets.count(reason)
        self._flush(f"reset_{reason}")
        if reason != "stamps_jumped_forward":
            self._new_estimator()
            self.regression.clear()
            self.instruments.clear()

    def _sample_vector(self, values: list) -> list:
        """The sampled streams (in ``required`` order) as one :data:`.aero.SAMPLE_FIELDS`
        vector in aircraft body axes; streams not used take their stand-ins."""
        i_qbar, i_surfaces, i_thrust = self._i_qbar, self._i_surfaces, self._i_thrust
        return aircraft_sample(
            values[0],
            values[1],
            math.nan if i_qbar is None else values[i_qbar][0],
            (0.0, 0.0, 0.0) if i_surfaces is None else values[i_surfaces],
            0.0 if i_thrust is None else values[i_thrust][0],
        )

    def _flush(self, reason: str) -> None:
        """Drop the samples waiting in the delay line and restart the differentiator."""
        if self._pending:
            self.bookkeeping.reject_samples(reason, len(self._pending))
            self._pending.clear()
        self._diff.reset()
        self._quality.restart_chain()  # the sensor-noise estimate's second differences too

    def _process(self, t: int, sample: list, u: Sequence[float] | None = None) -> SampleOutput | None:
        """The delay line: the rates enter the differentiator now, the sample leaves ``lag``
        samples later together with its angular accelerations (and ``u``, the injected
        excitation's deflections, when the estimator uses them)."""
        self._pending.append((t, sample, u))
        rate_dot = self._diff.push(sample[RATES])
        if rate_dot is None:
            if len(self._pending) > self._lag:
                self._pending.popleft()
                self.bookkeeping.reject_samples("differentiator_warmup")
            return None
        t, sample, u = self._pending.popleft()  # the sample `lag` samples back, aligned
        return self._estimate(t, sample, rate_dot, u)

    def _estimate(self, t: int, sample: list[float], rate_dot: FloatArray,
                  u: Sequence[float] | None = None) -> SampleOutput | None:
        book = self.bookkeeping
        state = flight_state(sample, rate_dot, self.config.inputs.air_density, self.limits)
        if isinstance(state, Refused):
            book.reject_samples(state.reason, evidence=(sample, rate_dot.tolist()))  # (a rejected sample's values)
            return None
        if not self.enabled:
            book.reject_samples("estimation_disabled")
            return None
        ac = self.config.aircraft
        coef = coefficients(state, ac)
        reg = regressors(state, ac)
        X, z = self._X, self._z
        X.flat[self._x_index] = [reg[name] for name in self._x_names]
        z[:] = [coef[name] for name in self._outputs]
        freq = self.frequency
        if self._iv is not None:  # estimator.algorithm iv: the rows with their instruments
            last = self._last
            if not self._iv.feed(t, X, z, u, state, None if last is None else last.theta, self.bank, book, self._used,
                                 freq):
                return None
        else:
            try:
                if freq is not None:
                    freq.check(X, z)  # a row either estimator refuses is used by neither
                self.bank.update(X, z)
            except NonFiniteInput:  # the row, or the state it would make, is not finite: unchanged
                book.reject_samples("non_finite_regression")
                return None
            self._used(t, X, z)
        bank = self.bank
        self._index += 1
        theta = bank.theta_all()
        se, se_conv = bank.standard_errors_both()
        ready = bank.ready
        # The last guard: a ready model with a non-finite estimate or SE, or an SE not above
        # rounding of its estimate (:mod:`.guard`), is withheld, counted.
        self._withheld = bad = unpublishable(ready, self._real, theta, se, se_conv)
        if bad.any():
            for j in np.flatnonzero(bad):
                book.outputs_withheld.count(self._outputs[j])
            ready &= ~bad
        flags, model_flags = self._monitor.update(t, theta, se, ready)
        # A parameter that is not identifiable from the data so far is never flagged converged.
        flags, model_flags = self._quality.restrict(flags, model_flags, bank, ready)
        if self._iv is not None and self._iv.weak.any():  # nor one whose instruments are weak
            flags, model_flags = flags & ~self._iv.weak[:, None], model_flags & ~self._iv.weak
        self._converged = flags, model_flags
        if self.targets is not None:  # (the parameters of models not ready are NaN: no forecast)
            self.targets.update(t * 1e-9, theta.flat[self._flat], se.flat[self._flat], flags.flat[self._flat])
        frequency = None if freq is None else freq.add(t, book.outputs_withheld, self._quality)
        self._last = SampleOutput(stamp_ns=t, index=self._index, theta=theta, se=se, se_conventional=se_conv,
                                  ready=ready, converged=flags, model_converged=model_flags,
                                  covariance=self._covariances(t, ready), lags=np.where(ready, bank.lags_used, 0),
                                  frequency=frequency)
        return self._last

    def _used(self, t: int, X: np.ndarray, z: np.ndarray, zeta: np.ndarray | None = None) -> None:
        """Row ``t`` (instruments ``zeta`` with iv) reached the estimator."""
        self.bookkeeping.samples_used += 1
        self._quality.add(X, z)
        self.last_stamp_ns = t
        if self.record:
            self.regression.append((t, X.copy(), z.copy()))
            if zeta is not None:
                self.instruments.append(zeta.copy())

    def weak_instruments(self, j: int) -> str:
        """Why model ``j``'s parameters are held back for weak instruments ('' if not)."""
        return "" if self._iv is None else self._iv.weak_reason(j)

    @property
    def instrument_strength(self) -> np.ndarray | None:
        """Each model's ``rho_min`` at the last weak-instrument judgement (NaN before one;
        :mod:`..instruments.strength`), or None without instruments."""
        return None if self._iv is None else self._iv.rho_min.copy()

    def _covariances(self, t: int, ready: np.ndarray) -> np.ndarray | None:
        """The corrected and conventional covariances of the ready models
        (:func:`symmetric_covariances`) on the grid points that publish them (every
        ``outputs.covariance_decimation``-th), else None."""
        every = self.covariance_every
        if not every or (t // self._period_ns) % every:
            return None
        return symmetric_covariances(self.bank.covariance_all(), self._real, self._real_square, ready)

    # ------------------------------------------------------------------ lifecycle
    def reset(self, reason: str, *, clear_inputs: bool = True) -> None:
        """Start afresh (``~/reset``): the estimator, and with ``clear_inputs`` all input
        state too: buffered and held messages (counted as expired), the streams' newest stamps
        (older stamps are accepted again), jump candidates, timelines, the grid and the delay
        line (``reset_<reason>`` samples). ``clear_inputs=False`` restarts the estimator only:
        samples in the delay line then reach the new estimator."""
        self.bookkeeping.resets.count(reason)
        self._new_estimator()
        self.regression.clear()
        self.instruments.clear()
        if clear_inputs:
            self._flush(f"reset_{reason}")
            self.sampler.clear(forget_newest=True)

    def time_jumped(self, now_ns: int, before_ns: int) -> bool:
        """The caller's clock went back from ``before_ns`` to ``now_ns`` (``/clock`` restarted):
        streams whose stamps step back near ``now_ns`` start the new timeline without
        confirmation, and the restart (``resets.time_jumped_backwards``) happens when they do,
        after the samples of the messages sent before the jump. False when there is nothing
        to restart (no data yet, or the stamps already moved near ``now_ns``)."""
        return self.sampler.time_jumped(int(now_ns), int(before_ns))

    def reconfigured(self, config: PipelineConfig, reason: str = "parameters_changed") -> Pipeline:
        """A pipeline with a new configuration that takes over this one's bookkeeping:
        buffered messages are counted as expired, samples waiting in the delay line as
        ``reset_<reason>``, so nothing disappears from the diagnostics. The estimator starts
        afresh; this pipeline must not be used afterwards."""
        self._flush(f"reset_{reason}")
        self.sampler.clear(forget_newest=False)
        self.bookkeeping.resets.count(reason)
        return Pipeline(config, record=self.record, enabled=self.enabled, bookkeeping=self.bookkeeping)

    def finish(self) -> None:
        """End of data: the last ``lag`` samples never get a centred derivative (and with
        ``estimator.algorithm iv``, rows still waiting for instruments never get them)."""
        self._flush("end_of_data")
        if self._iv is not None and self._iv.waiting:
            self.bookkeeping.reject_samples("instruments_not_ready", self._iv.waiting)
            self._iv = InstrumentPath(self.config)

    # ------------------------------------------------------------------ reporting
    def model_fit(self, j: int) -> dict:
        """Model ``j``'s fit (:func:`.bookkeeping.model_fit`)."""
        withheld = self.bookkeeping.outputs_withheld.get(self._outputs[j], 0)
        r2 = float(self._quality.fit(self.bank)[j])
        return model_fit(self.bank, j, r2, bool(self._withheld[j]), withheld)

    def model_report(self, j: int) -> dict:
        """What ``/diagnostics`` reports of model ``j``, node and replay alike (:func:`.states.model_report`)."""
        return model_report(self, j)

    @property
    def last(self) -> SampleOutput | None:
        """The newest sample's output (None before any)."""
        return self._last

    def convergence(self, j: int) -> dict:
        """The newest sample's convergence flags of model ``j`` for diagnostics: ``converged``
        (the model flag) and ``converged_parameters`` (the names, comma-separated)."""
        flags, model_flags = self._converged
        names = [p for p, f in zip(self.parameter_names[j], flags[j], strict=False) if f]
        return {"converged": bool(model_flags[j]), "converged_parameters": ",".join(names)}

    def counters(self) -> dict:
        """Bookkeeping for diagnostics: messages per stream and samples, with reasons, and
        ``explanations``: each reason in the user's terms (:func:`.alerts.explanations`)."""
        waiting = 0 if self._iv is None else self._iv.waiting
        report = self.bookkeeping.report(len(self._pending) + waiting)
        report["explanations"] = explanations(self.config, self.bookkeeping)
        return report

    # ------------------------------------------------------------------ persistence
    def save_state(self, path: str | Path) -> None:
        """Write the estimator state (:mod:`.state_file`; with ``estimator.algorithm iv`` the
        instruments' too, with ``estimator.method`` frequency or both the frequency-domain
        record's) so a restarted node resumes."""
        quality, iv, freq = self._quality, self._iv, self.frequency
        state = EstimatorState(self.bank, self.bookkeeping.samples_used, quality.output_sum, quality.output_sum_squares,
                               None if iv is None else iv.snapshot(), None if freq is None else freq.snapshot())
        save_state(path, state, self.config.fingerprint())

    def load_state(self, path: str | Path) -> None:
        """Continue from :meth:`save_state`. Raises :class:`StateFileError` when the file is
        unreadable, not a valid state or was written with another configuration (every field is
        checked against this pipeline's configuration before anything is allocated)."""
        expect, iv, freq = (tuple(self.sizes), self.config.estimator), self._iv, self.frequency
        state = load_state(path, self.config.fingerprint(), expect=expect, instruments=iv, frequency=freq)
        for part, saved in ((iv, state.instruments), (freq, state.frequency)):
            if part is not None and saved is not None:
                part.restore(saved)
        self.bank = state.bank
        self.bookkeeping.samples_used = state.samples_used
        self._quality.resume(state.output_sum, state.output_sum_squares)
        # The convergence history restarts: flags need window seconds of the resumed estimates.
        self._monitor.reset()
        self._converged = self._monitor.no_flags()
