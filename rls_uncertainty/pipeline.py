"""The single data path from stamped sensor messages to estimates (numpy only).

The ROS node, the offline replay and the tests all drive one :class:`Pipeline`, which
coordinates the modules that do the work:

1. ``add_imu``, ``add_airspeed``, ``add_dynamic_pressure``, ``add_surfaces``, ``add_thrust``
   take plain stamped numbers in the REP-103 body frame (x forward, y left, z up) and SI.
   JointState surfaces are mixed into Eq. 23's deflections first (:mod:`.surface_mixing`).
2. :mod:`.sampling` buffers the streams, counts every message (accepted, or rejected with a
   reason), and forms samples on the grid ``t_k = k / rate`` by linear interpolation, never
   extrapolating; the pipeline names the streams a sample needs.
3. Rates go through the fixed-lag differentiator (:mod:`.differentiation`); every other
   signal waits in a delay line of the same lag, so a sample reaches the aerodynamics
   ``lag`` samples late but time-aligned.
4. :mod:`.aero` converts the sample to aircraft body axes (:func:`.aero.aircraft_sample`),
   then Eq. 1 coefficients and Eq. 2 regressors feed one :class:`.estimator.EstimatorBank`
   (Eqs. 15-22), and each used sample yields a :class:`SampleOutput`.

Every formed sample ends as used or as rejected with a reason, and every message as accepted
or rejected: :class:`Bookkeeping` holds every counter, :meth:`Pipeline.counters` reports them
(the node's ``/diagnostics``), and a reconfigured pipeline takes over the same object.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .aero import RATES, aircraft_sample, coefficients, flight_state, regressors
from .config import PipelineConfig
from .differentiation import FixedLagDifferentiator
from .errors import NonFiniteInput, StateFileError
from .estimator import EstimatorBank
from .messages import INPUTS
from .sampling import Sample, Sampler, StreamCounts
from .estimator.state_file import EstimatorState, load_state, save_state
from .surface_mixing import SURFACES, SurfaceMixer

__all__ = ["Pipeline", "SampleOutput", "Bookkeeping", "STREAMS", "StateFileError"]

STREAMS = INPUTS


class SampleOutput(NamedTuple):
    """What one estimator sample produced.

    ``theta``, ``se`` (corrected, Eqs. 20/22) and ``se_conventional`` (Eq. 13) are
    ``(M, n_max)`` arrays in the order of ``config.models``; rows of models that are not
    ``ready`` yet (exact initialization still waiting) and the padding are NaN. ``lags``
    ``(M,)`` ints: the largest lag of Eq. 22 behind each corrected SE (chosen per sample with
    ``estimator.lag_selection: auto``), 0 for models not ready.
    """

    stamp_ns: int
    index: int
    theta: np.ndarray
    se: np.ndarray
    se_conventional: np.ndarray
    ready: np.ndarray
    lags: np.ndarray | None = None

    @property
    def time(self) -> float:
        return self.stamp_ns * 1e-9


def _new_stream_counts() -> dict[str, StreamCounts]:
    return {name: StreamCounts() for name in STREAMS}


@dataclass
class Bookkeeping:
    """Every counter of a pipeline, kept across reconfigurations: the messages of each input
    stream, samples formed, used and rejected (by reason), estimator resets (by reason) and
    JointState joints that no surface uses (by name)."""

    streams: dict[str, StreamCounts] = field(default_factory=_new_stream_counts)
    samples_formed: int = 0
    samples_used: int = 0
    samples_rejected: Counter = field(default_factory=Counter)
    resets: Counter = field(default_factory=Counter)
    unknown_joints: Counter = field(default_factory=Counter)


class Pipeline:
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
        self.bookkeeping = book = bookkeeping if bookkeeping is not None else Bookkeeping()
        self.required = self._required_streams(config)
        self.sampler = Sampler(
            STREAMS,
            self.required,
            period_ns=config.period_ns,
            max_gap_ns=config.inputs.max_gap_ns,
            buffer_ns=config.inputs.buffer_ns,
            counts=book.streams,
        )
        streams = self.sampler.streams
        self._imu, self._airspeed, self._surfaces = streams["imu"], streams["airspeed"], streams["control_surfaces"]
        self._qbar, self._thrust = streams["dynamic_pressure"], streams["thrust"]
        # Where the optional streams sit in a sample's values (None: not required).
        where = {name: i for i, name in enumerate(self.required)}
        self._i_qbar = where.get("dynamic_pressure")
        self._i_surfaces = where.get("control_surfaces")
        self._i_thrust = where.get("thrust")
        self._mixer = SurfaceMixer(config.surfaces)
        self._index = 0
        self._new_estimator()
        self._diff = FixedLagDifferentiator(config.differentiator, 1.0 / config.rate, width=3)
        self._lag = config.differentiator.lag
        self._pending: deque = deque()  # the delay line: (stamp, sample) awaiting rate_dot
        self._outputs = [m.output for m in config.models]
        # Where each model's regressors go in the (M, n_max) regression matrix, flattened.
        n_max = self.bank.n_max
        rows = [m.regressors for m in config.models]
        self._x_names = [name for names in rows for name in names]
        self._x_index = np.array([j * n_max + i for j, names in enumerate(rows) for i in range(len(names))], dtype=np.intp)

    @staticmethod
    def _required_streams(config: PipelineConfig) -> tuple[str, ...]:
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
        return tuple(required)

    def _new_estimator(self) -> None:
        c = self.config.estimator
        self.bank = EstimatorBank(
            self.sizes, c.bank_lags, c.window, c.forgetting, residual=c.residual, max_lags=c.max_lags
        )
        self._X = np.zeros((len(self.sizes), self.bank.n_max))
        self._z = np.zeros(len(self.sizes))
        self._zsum = np.zeros(len(self.sizes))  # sums of z and z^2 since the estimator started
        self._zsq = np.zeros(len(self.sizes))

    @property
    def samples_used(self) -> int:
        """Samples that reached an estimator, over the pipeline's life (reconfigurations too)."""
        return self.bookkeeping.samples_used

    # ------------------------------------------------------------------ inputs
    def add_imu(self, stamp_ns: int, angular_velocity, linear_acceleration) -> list[SampleOutput]:
        """``sensor_msgs/Imu`` in the REP-103 body frame: rad/s and specific force m/s^2."""
        wx, wy, wz = angular_velocity
        fx, fy, fz = linear_acceleration
        finite = math.isfinite(wx + wy + wz + fx + fy + fz)
        if self.sampler.add(self._imu, int(stamp_ns), (wx, wy, wz, fx, fy, fz), finite):
            return self._advance()
        return []

    def add_airspeed(self, stamp_ns: int, velocity) -> list[SampleOutput]:
        """True-airspeed vector in the REP-103 body frame, m/s."""
        vx, vy, vz = velocity
        if self.sampler.add(self._airspeed, int(stamp_ns), (vx, vy, vz), math.isfinite(vx + vy + vz)):
            return self._advance()
        return []

    def add_dynamic_pressure(self, stamp_ns: int, pascal: float) -> list[SampleOutput]:
        if self.sampler.add(self._qbar, int(stamp_ns), (pascal,), math.isfinite(pascal)):
            return self._advance()
        return []

    def add_thrust(self, stamp_ns: int, force_x: float) -> list[SampleOutput]:
        if self.sampler.add(self._thrust, int(stamp_ns), (force_x,), math.isfinite(force_x)):
            return self._advance()
        return []

    def add_surfaces(self, stamp_ns: int, names, positions) -> list[SampleOutput]:
        """``sensor_msgs/JointState`` names and positions (rad), mixed by Eq. 23."""
        layout = self._mixer.layout(names)
        if len(positions) != len(names):
            layout = "mismatched_arrays"
        if type(layout) is str:
            self.sampler.reject(self._surfaces, layout)
            return []
        for n in layout.unknown:
            self.bookkeeping.unknown_joints[n] += 1
        de, da, dr = layout.deflections(positions)
        if self.sampler.add(self._surfaces, int(stamp_ns), (de, da, dr), math.isfinite(de + da + dr)):
            return self._advance()
        return []

    def reject(self, stream: str, reason: str) -> None:
        """Count a message of input ``stream`` that never reached the pipeline's ``add_*``
        (the node could not decode it)."""
        self.sampler.reject(self.sampler.streams[stream], reason)

    # ------------------------------------------------------------------ per sample
    def _advance(self) -> list[SampleOutput]:
        out: list[SampleOutput] = []
        book = self.bookkeeping
        for item in self.sampler.due():
            if type(item) is Sample:
                book.samples_formed += 1
                result = self._process(item.stamp_ns, self._sample_vector(item.values))
                if result is not None:
                    out.append(result)
            else:  # Skipped grid points: the differentiator restarts after them
                book.samples_formed += item.count
                book.samples_rejected[item.reason] += item.count
                self._flush("discontinuity")
        return out

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
            self.bookkeeping.samples_rejected[reason] += len(self._pending)
            self._pending.clear()
        self._diff.reset()

    def _process(self, t: int, sample: list) -> SampleOutput | None:
        """The delay line: the rates enter the differentiator now, the sample leaves ``lag``
        samples later together with its angular accelerations."""
        self._pending.append((t, sample))
        rate_dot = self._diff.push(sample[RATES])
        if rate_dot is None:
            if len(self._pending) > self._lag:
                self._pending.popleft()
                self.bookkeeping.samples_rejected["differentiator_warmup"] += 1
            return None
        t, sample = self._pending.popleft()  # the sample `lag` samples back, aligned
        return self._estimate(t, sample, rate_dot)

    def _estimate(self, t: int, sample: list, rate_dot) -> SampleOutput | None:
        book = self.bookkeeping
        state = flight_state(sample, rate_dot, self.config.inputs.air_density)
        if type(state) is str:
            book.samples_rejected[state] += 1
            return None
        if not self.enabled:
            book.samples_rejected["estimation_disabled"] += 1
            return None
        ac = self.config.aircraft
        coef = coefficients(state, ac)
        reg = regressors(state, ac)
        X, z = self._X, self._z
        X.flat[self._x_index] = [reg[name] for name in self._x_names]
        z[:] = [coef[name] for name in self._outputs]
        try:
            self.bank.update(X, z)
        except NonFiniteInput:  # pragma: no cover - inputs are checked above
            book.samples_rejected["non_finite_regression"] += 1
            return None
        book.samples_used += 1
        self._zsum += z
        self._zsq += z * z
        if self.record:
            self.regression.append((t, X.copy(), z.copy()))
        bank = self.bank
        self._index += 1
        return SampleOutput(
            stamp_ns=t,
            index=self._index,
            theta=bank.theta_all(),
            se=bank.standard_errors_all("corrected"),
            se_conventional=bank.standard_errors_all("conventional"),
            ready=bank.ready,
            lags=np.where(bank.ready, bank.lags_used, 0),
        )

    def published(self, out: SampleOutput):
        """What the node publishes for a sample, per ready model: ``(output, label, estimates,
        corrected SEs, conventional SEs)``; models still initializing publish nothing, so no
        NaN ever leaves the pipeline."""
        for j, (name, label, n) in enumerate(zip(self._outputs, self.labels, self.sizes)):
            if out.ready[j]:
                yield name, label, out.theta[j, :n], out.se[j, :n], out.se_conventional[j, :n]

    # ------------------------------------------------------------------ lifecycle
    def reset(self, reason: str, *, clear_inputs: bool = False) -> None:
        """Start the estimator afresh (``~/reset``, a time jump). The sample stream goes on:
        samples in the differentiator's delay line reach the new estimator. With
        ``clear_inputs`` (time jumped) the buffered messages and the delay line are dropped
        too, counted as expired messages and ``reset_<reason>`` samples."""
        self.bookkeeping.resets[reason] += 1
        self._new_estimator()
        self.regression.clear()
        if clear_inputs:
            self._flush(f"reset_{reason}")
            self.sampler.clear(forget_newest=True)

    def reconfigured(self, config: PipelineConfig, reason: str = "parameters_changed") -> Pipeline:
        """A pipeline with a new configuration that takes over this one's bookkeeping:
        buffered messages are counted as expired, samples waiting in the delay line as
        ``reset_<reason>``, so nothing disappears from the diagnostics. The estimator starts
        afresh; this pipeline must not be used afterwards."""
        self._flush(f"reset_{reason}")
        self.sampler.clear(forget_newest=False)
        self.bookkeeping.resets[reason] += 1
        return Pipeline(config, record=self.record, enabled=self.enabled, bookkeeping=self.bookkeeping)

    def finish(self) -> None:
        """End of data: the last ``lag`` samples never get a centred derivative."""
        self._flush("end_of_data")

    # ------------------------------------------------------------------ reporting
    def model_fit(self, j: int) -> dict:
        """R^2 of model ``j`` (1 - residual variance / output variance) and residual
        whiteness: the lag-1 autocorrelation coefficient and the fraction of lags whose
        coefficient lies outside the 2-sigma white-noise bound 2/sqrt(n)."""
        bank = self.bank
        if not bank.ready[j]:
            return {"ready": False, "samples": bank.k}
        n = bank.k  # samples since the estimator (re)started
        mean = self._zsum[j] / n
        var_z = self._zsq[j] / n - mean * mean
        R = bank.autocorrelation(j)
        r2 = 1.0 - R[0] / var_z if var_z > 0 else float("nan")
        rho = R[1:] / R[0] if R[0] > 0 else np.zeros(0)
        bound = 2.0 / math.sqrt(max(n, 1))
        return {
            "ready": True,
            "samples": bank.k,
            "r_squared": float(r2),
            "residual_rho1": float(rho[0]) if rho.size else float("nan"),
            "lags_outside_2sigma": float(np.mean(np.abs(rho) > bound)) if rho.size else float("nan"),
            "repairs": int(bank.repairs[j]),
            "lags": int(bank.lags_used[j]),  # the largest lag of Eq. 22 (chosen with lag_selection auto)
        }

    def counters(self) -> dict:
        """Bookkeeping for diagnostics: messages per stream and samples, with reasons."""
        book = self.bookkeeping
        return {
            "streams": {name: counts.report() for name, counts in book.streams.items()},
            "samples_formed": book.samples_formed,
            "samples_used": book.samples_used,
            "samples_rejected": dict(book.samples_rejected),
            "samples_pending": len(self._pending),
            "resets": dict(book.resets),
            "unknown_joints": dict(book.unknown_joints),
        }

    # ------------------------------------------------------------------ persistence
    def save_state(self, path: str | Path) -> None:
        """Write the estimator state (:mod:`.state_file`) so a restarted node resumes."""
        state = EstimatorState(self.bank, self.bookkeeping.samples_used, self._zsum, self._zsq)
        save_state(path, state, self.config.fingerprint())

    def load_state(self, path: str | Path) -> None:
        """Continue from :meth:`save_state`. Raises :class:`StateFileError` when the file is
        unreadable or was written with another configuration."""
        state = load_state(path, self.config.fingerprint())
        self.bank = state.bank
        self.bookkeeping.samples_used = state.samples_used
        self._zsum = state.output_sum
        self._zsq = state.output_sum_squares
