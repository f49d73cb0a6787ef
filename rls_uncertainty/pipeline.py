"""The single data path from stamped sensor messages to estimates (numpy only).

The ROS node, the offline replay and the tests all drive one :class:`Pipeline`:

1. ``add_imu``, ``add_airspeed``, ``add_dynamic_pressure``, ``add_surfaces``, ``add_thrust``
   take plain stamped numbers in the REP-103 body frame (x forward, y left, z up) and SI.
   Each message is accepted into its stream buffer or rejected with a reason
   (``non_finite``, ``duplicate``, ``out_of_order``, ``mismatched_arrays``, ``missing_joint``).
2. Samples are formed on a fixed grid ``t_k = k / rate`` (integer nanoseconds, so the grid
   does not depend on when the pipeline started) as soon as every needed stream has a
   message at or after ``t_k``: each stream is linearly interpolated between the two
   messages around ``t_k``, never extrapolated. A stream silent for longer than
   ``max_gap`` around ``t_k`` rejects the sample (``gap_<stream>``).
3. Rates go through the fixed-lag differentiator (:mod:`.differentiation`); every other
   signal waits in a delay line of the same lag, so a sample reaches the aerodynamics
   ``lag`` samples late but time-aligned.
4. :func:`.aero.rep103_to_aircraft` converts to aircraft body axes, then Eq. 1 coefficients
   and Eq. 2 regressors feed one :class:`.estimator.EstimatorBank` (Eqs. 15-22).

Every formed sample ends as used or as rejected with a reason, and every message as accepted
or rejected: :meth:`Pipeline.counters` holds the bookkeeping the node reports in
``/diagnostics``.
"""

from __future__ import annotations

import json
import math
from bisect import bisect_left, bisect_right
from collections import Counter, deque
from operator import attrgetter
from typing import NamedTuple
from pathlib import Path

import numpy as np

from .aero import FlightState, coefficients, physics_rejection, regressors, rep103_to_aircraft
from .config import PipelineConfig
from .differentiation import DifferentiatorConfig, FixedLagDifferentiator
from .errors import NonFiniteInput, StateFileError
from .files import atomic_file
from .estimator import EstimatorBank
from .messages import INPUTS

__all__ = ["Pipeline", "SampleOutput", "STREAMS", "StateFileError"]

STREAMS = INPUTS
_SURFACES = ("delta_e", "delta_a", "delta_r")


class SampleOutput(NamedTuple):
    """What one estimator sample produced.

    ``theta``, ``se`` (corrected, Eqs. 20/22) and ``se_conventional`` (Eq. 13) are
    ``(M, n_max)`` arrays in the order of ``config.models``; rows of models that are not
    ``ready`` yet (exact initialization still waiting) and the padding are NaN.
    """

    stamp_ns: int
    index: int
    theta: np.ndarray
    se: np.ndarray
    se_conventional: np.ndarray
    ready: np.ndarray

    @property
    def time(self) -> float:
        return self.stamp_ns * 1e-9


class _Stream:
    """Time-ordered buffer of one input: integer-nanosecond stamps and value vectors."""

    __slots__ = ("name", "stamps", "values", "received", "rejected", "expired", "last", "interval", "missing")

    def __init__(self, name: str) -> None:
        self.name = name
        self.stamps: list[int] = []
        self.values: list[tuple] = []
        self.received = 0
        self.rejected: Counter = Counter()
        self.expired = 0
        self.last = None
        self.interval = 0.0  # running estimate of the stream's stamp interval, ns
        self.missing = 0  # messages presumed lost in transport (stamp gaps), see _accept


# The sample vector, aircraft body axes: specific force, rates, air-relative velocity,
# dynamic pressure (NaN when computed from density), surfaces, thrust.
_AX, _AY, _AZ, _P, _Q, _R, _U, _V, _W, _QBAR, _DE, _DA, _DR, _T = range(14)
_NEWEST = attrgetter("last")


def _mean(values, index) -> float:
    """Mean of ``values`` at ``index`` (0 when there is none): Eq. 23's surface averages."""
    if len(index) == 1:
        return values[index[0]]
    return sum([values[i] for i in index]) / len(index) if index else 0.0


class Pipeline:
    """Sample formation, differentiation, aero reduction and estimation for one configuration.

    ``record=True`` keeps every regression row and output handed to the estimator
    (``self.regression``), for batch comparisons and the replay's plots.
    """

    def __init__(self, config: PipelineConfig, *, record: bool = False, enabled: bool = True) -> None:
        self.config = config
        self.models = config.models
        self.parameter_names = [m.parameter_names for m in config.models]
        self.labels = [",".join(names) for names in self.parameter_names]
        self.sizes = [len(m.regressors) for m in config.models]
        self.period_ns = config.period_ns
        self.max_gap_ns = int(round(config.max_gap * 1e9))
        self.buffer_ns = int(round(config.buffer_duration * 1e9))
        self.enabled = enabled
        self.record = record
        self.regression: list[tuple[int, np.ndarray, np.ndarray]] = []
        uses = {r for m in config.models for r in m.regressors}
        self.required = ["imu", "airspeed"]
        if uses & set(_SURFACES):
            self.required.append("control_surfaces")
        if config.use_dynamic_pressure:
            self.required.append("dynamic_pressure")
        if config.use_thrust and any(m.output == "CX" for m in config.models):
            self.required.append("thrust")
        self.streams = {name: _Stream(name) for name in STREAMS}
        self._needed = [self.streams[name] for name in self.required]
        self._stream_list = list(self.streams.values())
        self._imu = self.streams["imu"]
        self._surfaces = self.streams["control_surfaces"]
        self._joint_names: list | None = None  # the last JointState name list and its layout
        self._joint_layout_last = None
        self._joints = {s: config.mixing.names(s) for s in _SURFACES}
        self._joint_layouts: dict = {}
        self.samples_formed = 0
        self.samples_used = 0
        self._used_before = 0  # samples used before a reconfiguration (see reconfigured())
        self.samples_rejected: Counter = Counter()
        self.resets: Counter = Counter()
        self.unknown_joints: Counter = Counter()
        self._next_t: int | None = None
        self._frontier_stream: _Stream | None = None
        self._index = 0
        self._new_estimator()
        self._diff = FixedLagDifferentiator(
            DifferentiatorConfig(config.diff_window, config.diff_order, config.diff_lag),
            1.0 / config.rate,
            width=3,
        )
        self._pending: deque = deque()
        self._rows = [tuple(m.regressors) for m in config.models]
        self._outputs = [m.output for m in config.models]
        # Where each model's regressors go in the (M, n_max) regression matrix, flattened.
        n_max = self.bank.n_max
        self._x_names = [name for names in self._rows for name in names]
        self._x_index = np.array(
            [j * n_max + i for j, names in enumerate(self._rows) for i in range(len(names))], dtype=np.intp
        )

    # ------------------------------------------------------------------ estimator
    def _new_estimator(self) -> None:
        c = self.config
        self.bank = EstimatorBank(self.sizes, c.n_lags, c.window, c.forgetting, residual=c.residual)
        self._X = np.zeros((len(self.sizes), self.bank.n_max))
        self._z = np.zeros(len(self.sizes))
        self._zsum = np.zeros(len(self.sizes))
        self._zsq = np.zeros(len(self.sizes))

    @property
    def ready(self) -> np.ndarray:
        return self.bank.ready

    # ------------------------------------------------------------------ inputs
    def _accept(self, stream: _Stream, stamp: int, values: tuple, finite: bool) -> list[SampleOutput]:
        stream.received += 1
        if not finite:
            stream.rejected["non_finite"] += 1
            return []
        newest = stream.last  # the newest accepted stamp (stamps[-1] while any is buffered)
        if newest is not None:
            dt = stamp - newest
            if dt <= 0:
                stream.rejected["duplicate" if dt == 0 else "out_of_order"] += 1
                return []
            # Messages lost before they reached us (a best-effort DDS drop, a recorder gap)
            # leave a hole in the stamps: count the missing ones against the stream's usual
            # interval (exponential average) so that they show in diagnostics.
            interval = stream.interval
            if interval == 0.0:
                stream.interval = float(dt)
            elif dt > 1.5 * interval:
                stream.missing += int(round(dt / interval)) - 1
            else:
                stream.interval = interval + 0.05 * (dt - interval)
        stamps = stream.stamps
        stamps.append(stamp)
        stream.values.append(values)
        stream.last = stamp
        if stamp - stamps[0] > self.buffer_ns:
            self._expire(stream, stamp)
        frontier = self._frontier_stream
        if frontier is not None and frontier.last < self._next_t:
            return []  # the stream holding the grid back has still not reached it (see _advance)
        return self._advance()

    def add_imu(self, stamp_ns: int, angular_velocity, linear_acceleration) -> list[SampleOutput]:
        """``sensor_msgs/Imu`` in the REP-103 body frame: rad/s and specific force m/s^2."""
        wx, wy, wz = angular_velocity
        fx, fy, fz = linear_acceleration
        finite = math.isfinite(wx + wy + wz + fx + fy + fz)
        return self._accept(self._imu, int(stamp_ns), (wx, wy, wz, fx, fy, fz), finite)

    def add_airspeed(self, stamp_ns: int, velocity) -> list[SampleOutput]:
        """True-airspeed vector in the REP-103 body frame, m/s."""
        vx, vy, vz = velocity
        values = (vx, vy, vz)
        return self._accept(self.streams["airspeed"], int(stamp_ns), values, math.isfinite(vx + vy + vz))

    def add_dynamic_pressure(self, stamp_ns: int, pascal: float) -> list[SampleOutput]:
        return self._accept(self.streams["dynamic_pressure"], int(stamp_ns), (pascal,), math.isfinite(pascal))

    def add_thrust(self, stamp_ns: int, force_x: float) -> list[SampleOutput]:
        return self._accept(self.streams["thrust"], int(stamp_ns), (force_x,), math.isfinite(force_x))

    def add_surfaces(self, stamp_ns: int, names, positions) -> list[SampleOutput]:
        """``sensor_msgs/JointState`` names and positions (rad), mixed by Eq. 23."""
        stream = self._surfaces
        if names == self._joint_names:  # the usual case: every message has the same name list
            layout = self._joint_layout_last
        else:
            key = tuple(names)
            layout = self._joint_layouts.get(key)
            if layout is None:
                layout = self._joint_layout(key)
            self._joint_names, self._joint_layout_last = list(key), layout
        if len(positions) != len(names):
            layout = "mismatched_arrays"
        if isinstance(layout, str):
            stream.received += 1
            stream.rejected[layout] += 1
            return []
        elevator, right, left, combined, rudder, unknown = layout
        for n in unknown:
            self.unknown_joints[n] += 1
        de = _mean(positions, elevator)
        if combined is not None:
            da = positions[combined]
        elif right or left:
            da = 0.5 * (_mean(positions, right) - _mean(positions, left))  # Eq. 23
        else:
            da = 0.0
        dr = _mean(positions, rudder)
        return self._accept(stream, int(stamp_ns), (de, da, dr), math.isfinite(de + da + dr))

    def _joint_layout(self, names: tuple):
        """Where each mixed joint sits in a JointState's arrays (cached per name list), or the
        rejection reason of the name list."""
        if len(self._joint_layouts) >= 16:  # name lists normally never change; stay bounded
            self._joint_layouts.clear()
        if len(set(names)) != len(names):
            layout = "mismatched_arrays"
        elif any(n not in names for s in _SURFACES for n in self._joints[s]):
            layout = "missing_joint"
        else:
            mix = self.config.mixing
            where = {n: i for i, n in enumerate(names)}
            known = set(mix.elevator) | set(mix.rudder) | set(self._joints["delta_a"])
            split = bool(self._joints["delta_a"]) and not mix.aileron_combined
            layout = (
                [where[n] for n in mix.elevator],
                [where[n] for n in mix.aileron_right] if split else [],
                [where[n] for n in mix.aileron_left] if split else [],
                where[mix.aileron_combined] if mix.aileron_combined else None,
                [where[n] for n in mix.rudder],
                [n for n in names if n not in known],
            )
        self._joint_layouts[names] = layout
        return layout

    # ------------------------------------------------------------------ sample formation
    def _expire(self, stream: _Stream, newest: int) -> None:
        """Drop messages older than ``buffer_duration`` while another stream holds the grid
        back; they are counted as expired (never used)."""
        cut = bisect_left(stream.stamps, newest - self.buffer_ns)
        # Keep the message just before the cut: it may still bracket a later sample.
        cut -= 1
        if cut > 0:
            del stream.stamps[:cut]
            del stream.values[:cut]
            stream.expired += cut

    def _advance(self) -> list[SampleOutput]:
        out: list[SampleOutput] = []
        needed = self._needed
        P = self.period_ns
        t = self._next_t
        if t is not None and self._frontier_stream is not None:
            # Fast path: the stream that held the grid back has still not reached t.
            if self._frontier_stream.last < t:
                return out
        for s in needed:
            if not s.stamps:
                return out
        if t is None:
            start = max(s.stamps[0] for s in needed)
            t = -(-start // P) * P
        t_start = t
        while True:
            lagging = min(needed, key=_NEWEST)  # every needed stream holds a message here
            if lagging.last < t:
                self._frontier_stream = lagging
                break
            raw, reason, skip_to = self._interpolate(t)
            if raw is None:
                # Every grid point up to skip_to shares the problem: count them all at once.
                n_skip = max(1, -(-(skip_to - t) // P))
                self.samples_formed += n_skip
                self.samples_rejected[reason] += n_skip
                self._flush("discontinuity")
                t += n_skip * P
            else:
                self.samples_formed += 1
                result = self._process(t, raw)
                if result is not None:
                    out.append(result)
                t += P
        if t != t_start:
            self._trim(t)
        self._next_t = t
        return out

    def _interpolate(self, t: int):
        """Stream values at ``t`` (aircraft axes), or ``(None, reason, skip_to)``."""
        vals = {}
        max_gap = self.max_gap_ns
        for s in self._needed:
            stamps = s.stamps
            i = bisect_left(stamps, t)
            t1 = stamps[i]
            if t1 == t:
                vals[s.name] = s.values[i]
                continue
            if i == 0:
                return None, f"expired_{s.name}", stamps[0]
            t0 = stamps[i - 1]
            if t1 - t0 > max_gap:
                return None, f"gap_{s.name}", t1
            w = (t - t0) / (t1 - t0)
            vals[s.name] = [x + w * (y - x) for x, y in zip(s.values[i - 1], s.values[i])]
        imu = vals["imu"]
        # The conversion to aircraft body axes: specific force, rates, velocity.
        raw = [
            *rep103_to_aircraft(imu[3:]),
            *rep103_to_aircraft(imu[:3]),
            *rep103_to_aircraft(vals["airspeed"]),
            vals["dynamic_pressure"][0] if "dynamic_pressure" in vals else math.nan,
            *vals.get("control_surfaces", (0.0, 0.0, 0.0)),
            vals["thrust"][0] if "thrust" in vals else 0.0,
        ]
        return raw, None, None

    def _trim(self, t_next: int) -> None:
        """Drop messages no later sample can need (keep the last one at or before ``t_next``)."""
        for s in self._stream_list:
            stamps = s.stamps
            if len(stamps) > 1 and stamps[1] <= t_next:
                i = bisect_right(stamps, t_next) - 1
                del stamps[:i]
                del s.values[:i]

    # ------------------------------------------------------------------ per sample
    def _flush(self, reason: str) -> None:
        """Drop the samples waiting in the delay line and restart the differentiator."""
        if self._pending:
            self.samples_rejected[reason] += len(self._pending)
            self._pending.clear()
        self._diff.reset()

    def _process(self, t: int, raw: list) -> SampleOutput | None:
        self._pending.append((t, raw))
        rate_dot = self._diff.push(raw[_P:_R + 1])
        if rate_dot is None:
            if len(self._pending) > self.config.diff_lag:
                self._pending.popleft()
                self.samples_rejected["differentiator_warmup"] += 1
            return None
        t, raw = self._pending.popleft()  # the sample diff_lag samples back, aligned
        return self._estimate(t, raw, rate_dot)

    def flight_state(self, raw: list, rate_dot) -> FlightState | str:
        """The aligned sample as a :class:`FlightState`, or the reason it cannot be used."""
        u, v, w = raw[_U:_W + 1]
        V = math.sqrt(u * u + v * v + w * w)
        if not V > 0.0:
            return "nonpositive_airspeed"
        qbar = raw[_QBAR]
        if math.isnan(qbar):
            qbar = 0.5 * self.config.air_density * V * V
        ax, ay, az, p, q, r = raw[:6]
        de, da, dr, thrust = raw[_DE:]
        p_dot, q_dot, r_dot = rate_dot.tolist()
        state = FlightState(
            ax=ax, ay=ay, az=az, p=p, q=q, r=r, p_dot=p_dot, q_dot=q_dot, r_dot=r_dot,
            V=V, alpha=math.atan2(w, u), beta=math.asin(max(-1.0, min(1.0, v / V))), qbar=float(qbar),
            delta_e=de, delta_a=da, delta_r=dr, thrust=thrust,
        )
        return physics_rejection(state) or state

    def _estimate(self, t: int, raw: list, rate_dot) -> SampleOutput | None:
        state = self.flight_state(raw, rate_dot)
        if isinstance(state, str):
            self.samples_rejected[state] += 1
            return None
        if not self.enabled:
            self.samples_rejected["estimation_disabled"] += 1
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
            self.samples_rejected["non_finite_regression"] += 1
            return None
        self.samples_used += 1
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
        )

    def published(self, out: SampleOutput):
        """What the node publishes for a sample, per ready model: ``(output, label, estimates,
        corrected SEs, conventional SEs)``; models still initializing publish nothing, so no
        NaN ever leaves the pipeline."""
        for j, (name, label, n) in enumerate(zip(self._outputs, self.labels, self.sizes)):
            if out.ready[j]:
                yield name, label, out.theta[j, :n], out.se[j, :n], out.se_conventional[j, :n]

    # ------------------------------------------------------------------ control
    def reset(self, reason: str, *, clear_inputs: bool = False) -> None:
        """Start the estimator afresh (``~/reset``, a time jump). The sample stream goes on:
        samples in the differentiator's delay line reach the new estimator. With
        ``clear_inputs`` (time jumped) the buffered messages and the delay line are dropped
        too, counted as expired messages and ``reset_<reason>`` samples."""
        self.resets[reason] += 1
        self._new_estimator()
        self.regression.clear()
        if clear_inputs:
            self._flush(f"reset_{reason}")
            for s in self.streams.values():
                s.expired += len(s.stamps)
                s.stamps.clear()
                s.values.clear()
                s.last = None
            self._next_t = None
            self._frontier_stream = None

    def reconfigured(self, config: PipelineConfig, reason: str = "parameters_changed") -> "Pipeline":
        """A pipeline with a new configuration that keeps this one's bookkeeping: buffered
        messages are counted as expired, samples waiting in the delay line as
        ``reset_<reason>``, and every counter carries over, so nothing disappears from the
        diagnostics. The estimator starts afresh."""
        new = Pipeline(config, record=self.record, enabled=self.enabled)
        self._flush(f"reset_{reason}")
        for name, s in self.streams.items():
            t = new.streams[name]
            t.received, t.rejected, t.last = s.received, Counter(s.rejected), s.last
            t.interval, t.missing = s.interval, s.missing
            t.expired = s.expired + len(s.stamps)
        new.samples_formed = self.samples_formed
        new.samples_used = 0
        new._used_before = self.samples_used + self._used_before
        new.samples_rejected = Counter(self.samples_rejected)
        new.resets = Counter(self.resets)
        new.resets[reason] += 1
        new.unknown_joints = Counter(self.unknown_joints)
        return new

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
        }

    def counters(self) -> dict:
        """Bookkeeping for diagnostics: messages per stream and samples, with reasons."""
        streams = {}
        for name, s in self.streams.items():
            streams[name] = {
                "received": s.received,
                "accepted": s.received - sum(s.rejected.values()),
                "rejected": dict(s.rejected),
                "expired": s.expired,
                "missing": s.missing,
                "newest_stamp_ns": s.last,
            }
        return {
            "streams": streams,
            "samples_formed": self.samples_formed,
            "samples_used": self.samples_used + self._used_before,
            "samples_rejected": dict(self.samples_rejected),
            "samples_pending": len(self._pending),
            "resets": dict(self.resets),
            "unknown_joints": dict(self.unknown_joints),
        }

    # ------------------------------------------------------------------ persistence
    def save_state(self, path: str | Path) -> None:
        """Write the estimator state (atomically, no pickle) so a restarted node resumes."""
        path = Path(path)
        state = self.bank.state()
        meta = {
            "format": EstimatorBank.STATE_FORMAT,
            "fingerprint": self.config.fingerprint(),
            "bank_config": state["config"],
            "bank_counters": state["counters"],
            "samples_used": self.samples_used,
            "zsum": self._zsum.tolist(),
            "zsq": self._zsq.tolist(),
        }
        with atomic_file(path) as fh:
            np.savez(fh, meta=np.array(json.dumps(meta)), **state["arrays"])

    def load_state(self, path: str | Path) -> None:
        """Continue from :meth:`save_state`. Raises :class:`StateFileError` when the file is
        unreadable or was written with another configuration."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {k: data[k] for k in data.files if k != "meta"}
        except FileNotFoundError as exc:
            raise StateFileError(f"{path}: no such state file") from exc
        except Exception as exc:  # noqa: BLE001 - any corruption is reported the same way
            raise StateFileError(f"{path}: not a readable state file ({exc})") from exc
        if meta.get("format") != EstimatorBank.STATE_FORMAT:
            raise StateFileError(
                f"{path}: state format {meta.get('format')!r}, this version reads "
                f"{EstimatorBank.STATE_FORMAT} (saved by another version; delete it to start afresh)"
            )
        want = json.loads(json.dumps(self.config.fingerprint()))
        if meta["fingerprint"] != want:
            raise StateFileError(f"{path}: saved with another aircraft, model or estimator configuration")
        try:
            bank = EstimatorBank.from_state(
                {"format": EstimatorBank.STATE_FORMAT, "config": meta["bank_config"], "counters": meta["bank_counters"], "arrays": arrays}
            )
        except (KeyError, ValueError) as exc:
            raise StateFileError(f"{path}: inconsistent estimator state ({exc})") from exc
        self.bank = bank
        self.samples_used = int(meta["samples_used"])
        self._zsum = np.array(meta["zsum"], dtype=float)
        self._zsq = np.array(meta["zsq"], dtype=float)
