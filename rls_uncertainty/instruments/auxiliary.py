"""Instruments from an auxiliary short-period model driven by the injected excitation.

Young's refined instrumental variables: the states among the regressors (``alpha``, ``q_hat``)
are instrumented by the response of an auxiliary model of the aircraft (Eq. 25a with the
current estimates, :mod:`.discrete`) to the injected elevator excitation ``u``, the elevator
regressor by ``u`` itself, the bias by 1 (:mod:`.layout`, I1). ``u`` is external to the sensor
noise, the gusts and any feedback, so these instruments carry none of them.

Per sample (:meth:`ShortPeriodAuxiliary.update`):

1. until the estimator has estimates of its own, a bare RLS (:mod:`.bootstrap`) takes the
   sample;
2. until the auxiliary model exists, the sample waits; when there first are estimates (the
   estimator's, else the bare RLS's) whose model is stable, the model is run from rest over the
   excitation of the waiting samples (the replay) and they are handed over, each with its
   instruments;
3. every ``refresh_span`` the model is rebuilt from the current estimates (the estimator's when
   given, else the bare RLS's) and the current ``qbar`` and ``V``; a candidate whose poles do not
   both have a real part below ``-min_decay`` (or that is not finite) is refused and the last
   model kept;
4. the sample's instruments from the model's state and ``u``; then the state advances (I2).

Only the span of the instruments matters to a just-identified instrumental-variables estimate:
for C_m, ``(1, alpha_o, q_o, u)`` spans the input through the model's two modes, so the
auxiliary model needs its poles roughly right, not its gains.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from ..aero.models import AircraftConfig, ModelConfig
from ..errors import ConfigError, NonFiniteInput
from ..estimator.bank import as_regressors
from .bootstrap import BareRls, saved_array
from .discrete import MIN_DECAY, discretize, is_stable, short_period_matrices
from .layout import InstrumentLayout

__all__ = ["InstrumentedSample", "ShortPeriodAuxiliary"]

FloatArray = npt.NDArray[np.float64]
Regressors = npt.NDArray[Any] | Sequence[npt.ArrayLike]


class InstrumentedSample(NamedTuple):
    """A sample ready for the estimator: regressors ``X`` ``(M, n_max)``, outputs ``z``
    ``(M,)``, ``instruments`` ``(M, n_max)`` laid out like ``X``, and the ``tag`` it was given
    (its stamp, say: a waiting sample is handed over later)."""

    X: FloatArray
    z: FloatArray
    instruments: FloatArray
    tag: object = None


class _Waiting(NamedTuple):
    X: FloatArray
    z: FloatArray
    u: float
    V: float
    tag: object


class ShortPeriodAuxiliary:
    """The instruments of ``models`` (:class:`.layout.InstrumentLayout`: refused with a
    :class:`ConfigError` if it cannot serve them) for ``aircraft`` sampled at ``rate`` Hz.

    ``refresh_span``: seconds between rebuilds of the auxiliary model; ``min_decay``: the
    stability guard (1/s); ``max_backlog_span``: seconds of samples held while the model does
    not exist yet (older ones are dropped and counted in :attr:`dropped`); ``min_samples``:
    the bare RLS's smallest sample count before it starts.
    """

    def __init__(self, models: Sequence[ModelConfig], aircraft: AircraftConfig, rate: float, *,
                 refresh_span: float = 0.5, min_decay: float = MIN_DECAY, max_backlog_span: float = 30.0,
                 min_samples: int = 25) -> None:
        if not rate > 0 or not refresh_span > 0 or not max_backlog_span > 0:
            raise ConfigError(f"rate, refresh_span and max_backlog_span must be positive, got "
                              f"{rate!r}, {refresh_span!r}, {max_backlog_span!r}")
        self.layout = InstrumentLayout(models)
        self.aircraft = aircraft
        self.dt = 1.0 / rate
        self.refresh = max(1, round(refresh_span * rate))
        self.min_decay = min_decay
        self.min_samples = min_samples
        self.max_backlog = max(1, round(max_backlog_span * rate))  # samples that may wait
        self._backlog: deque[_Waiting] = deque(maxlen=self.max_backlog)
        self.reset()

    def reset(self) -> None:
        """Back to the start: no model, no estimates, nothing waiting, counters at 0."""
        self.bare = BareRls(self.layout.sizes, min_samples=self.min_samples)
        self.state = np.zeros(2)
        self.Phi = np.zeros((2, 2))
        self.Gamma = np.zeros(2)
        self._phi, self._gamma = self.Phi.tolist(), self.Gamma.tolist()  # Phi, Gamma as floats, for advance
        self.has_model = False
        self.refused = 0  # candidate models refused by the stability guard
        self.dropped = 0  # waiting samples dropped from a full backlog
        self._since_refresh = 0
        self._backlog.clear()

    @property
    def waiting(self) -> int:
        """Samples held until the auxiliary model exists."""
        return len(self._backlog)

    def set_model(self, theta: npt.ArrayLike, qbar: float, V: float) -> bool:
        """Rebuild the auxiliary model from the estimates ``theta`` ``(M, n_max)`` at ``qbar``,
        ``V``, unless it fails the stability guard; returns whether it was taken."""
        A, B = short_period_matrices(self.layout.derivatives(theta), qbar, V, self.aircraft)
        if not (is_stable(A, self.min_decay) and np.isfinite(B).all()):
            self.refused += 1
            return False
        Phi, Gamma = discretize(A, B, self.dt)
        if not (np.isfinite(Phi).all() and np.isfinite(Gamma).all()):
            self.refused += 1
            return False
        self.Phi, self.Gamma, self.has_model = Phi, Gamma, True
        self._phi, self._gamma = Phi.tolist(), Gamma.tolist()
        return True

    def instruments(self, u: float, V: float) -> FloatArray:
        """The ``(M, n_max)`` instruments of the current sample (I1), from the model's state."""
        return self.layout.assemble(self.state[0], self.state[1], u, V, self.aircraft.cbar)

    def advance(self, u: float) -> None:
        """The state at the next sample (I2) with this sample's excitation ``u``."""
        (p00, p01), (p10, p11) = self._phi
        g0, g1 = self._gamma
        a, q = float(self.state[0]), float(self.state[1])
        self.state = np.array([p00 * a + p01 * q + g0 * u, p10 * a + p11 * q + g1 * u])

    def step(self, u: float, V: float) -> FloatArray:
        """:meth:`instruments` of this sample, then :meth:`advance`."""
        zeta = self.instruments(u, V)
        self.advance(u)
        return zeta

    def replay(self, u: npt.ArrayLike, V: npt.ArrayLike) -> FloatArray:
        """The instruments ``(k, M, n_max)`` of an excitation history ``u`` ``(k,)`` (airspeeds
        ``V``) with the current model from rest; the state is left at the end of it."""
        self.state = np.zeros(2)
        return np.stack([self.step(float(a), float(b)) for a, b in zip(np.ravel(u), np.ravel(V), strict=True)])

    def update(self, X: Regressors, z: npt.ArrayLike, u: float, qbar: float, V: float,
               estimates: npt.ArrayLike | None = None, tag: object = None) -> list[InstrumentedSample]:
        """One sample: regressors ``X`` ``(M, n_max)`` (or ``M`` regressor vectors), outputs
        ``z`` ``(M,)``, the injected excitation ``u`` (rad, from trim), ``qbar`` (Pa), ``V``
        (m/s) and the estimator's ``estimates`` ``(M, n_max)`` (``None`` or NaN while it has
        none); ``tag`` comes back with the sample.

        Returns the samples to give the estimator now, in order: none while the auxiliary model
        does not exist, every waiting one at the hand-over, then this one. A non-finite input
        (or ``V <= 0``) raises :class:`NonFiniteInput` and changes nothing.
        """
        x, zz = self._checked(X, z, u, qbar, V)
        own = None if estimates is None else np.asarray(estimates, dtype=float)
        if own is not None and not np.isfinite(self.layout.derivatives(own)).all():
            own = None
        if own is None:
            self.bare.update(x, zz)
        if not self.has_model:
            if len(self._backlog) == self._backlog.maxlen:
                self.dropped += 1
            self._backlog.append(_Waiting(x, zz, float(u), float(V), tag))
            first = own if own is not None else self.bare.theta if self.bare.ready else None
            if first is not None and self.set_model(first, qbar, V):
                return self._hand_over()
            return []
        self._since_refresh += 1
        if self._since_refresh >= self.refresh:
            self._since_refresh = 0
            if own is not None or self.bare.ready:
                self.set_model(self.bare.theta if own is None else own, qbar, V)
        return [InstrumentedSample(x, zz, self.step(float(u), float(V)), tag)]

    def _hand_over(self) -> list[InstrumentedSample]:
        """The waiting samples with the instruments of the first model, replayed from rest."""
        waiting = list(self._backlog)
        self._backlog.clear()
        zeta = self.replay([w.u for w in waiting], [w.V for w in waiting])
        return [InstrumentedSample(w.X, w.z, zeta[i], w.tag) for i, w in enumerate(waiting)]

    def snapshot(self) -> dict[str, Any]:
        """A copy of the state as plain data, :meth:`restore` continues bit-identically:
        ``counters`` ``has_model``, ``since_refresh`` (samples since the last rebuild),
        ``refused``, ``dropped``, ``waiting`` and the bare RLS's ``bare_k``, ``bare_ready``;
        ``arrays`` the model's ``state``, ``Phi``, ``Gamma``, the bare RLS's ``bare_A``,
        ``bare_b``, ``bare_D``, ``bare_theta`` and the waiting samples, oldest first
        (``backlog_X`` ``(waiting, M, n_max)``, ``backlog_z``, ``backlog_u``, ``backlog_V``,
        ``backlog_tag``: their tags, which must be integers, as int64)."""
        bare = self.bare.snapshot()
        waiting = list(self._backlog)
        m, n = self.bare.mask.shape
        counters = {"has_model": self.has_model, "since_refresh": self._since_refresh, "refused": self.refused,
                    "dropped": self.dropped, "waiting": len(waiting),
                    **{f"bare_{k}": v for k, v in bare["counters"].items()}}
        arrays = {"state": self.state.copy(), "Phi": self.Phi.copy(), "Gamma": self.Gamma.copy(),
                  **{f"bare_{k}": v for k, v in bare["arrays"].items()},
                  "backlog_X": np.array([w.X for w in waiting], dtype=float).reshape(len(waiting), m, n),
                  "backlog_z": np.array([w.z for w in waiting], dtype=float).reshape(len(waiting), m),
                  "backlog_u": np.array([w.u for w in waiting], dtype=float),
                  "backlog_V": np.array([w.V for w in waiting], dtype=float),
                  "backlog_tag": np.array([int(w.tag) for w in waiting], dtype=np.int64)}  # type: ignore[call-overload]
        return {"counters": counters, "arrays": arrays}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (arrays of another shape, or more waiting samples
        than ``max_backlog_span`` holds: :class:`ValueError`)."""
        c, a = saved["counters"], saved["arrays"]
        self.reset()
        self.bare.restore({"counters": {"k": c["bare_k"], "ready": c["bare_ready"]},
                           "arrays": {k: a[f"bare_{k}"] for k in ("A", "b", "D", "theta")}})
        self.state = saved_array(a["state"], self.state, "state")
        self.Phi, self.Gamma = saved_array(a["Phi"], self.Phi, "Phi"), saved_array(a["Gamma"], self.Gamma, "Gamma")
        self._phi, self._gamma = self.Phi.tolist(), self.Gamma.tolist()
        self.has_model, self._since_refresh = bool(c["has_model"]), int(c["since_refresh"])
        self.refused, self.dropped = int(c["refused"]), int(c["dropped"])
        w, (m, n) = int(c["waiting"]), self.bare.mask.shape
        if w > self.max_backlog:
            raise ValueError(f"{w} waiting samples, the backlog holds {self.max_backlog}")
        X = saved_array(a["backlog_X"], np.zeros((w, m, n)), "backlog_X")
        z = saved_array(a["backlog_z"], np.zeros((w, m)), "backlog_z")
        u, V = (saved_array(a[f"backlog_{k}"], np.zeros(w), f"backlog_{k}") for k in ("u", "V"))
        tags = np.asarray(a["backlog_tag"], dtype=np.int64)
        if tags.shape != (w,):
            raise ValueError(f"saved backlog_tag has shape {tags.shape}, expected {(w,)}")
        self._backlog.extend(_Waiting(X[i], z[i], float(u[i]), float(V[i]), int(tags[i])) for i in range(w))

    def _checked(self, X: Regressors, z: npt.ArrayLike, u: float, qbar: float,
                 V: float) -> tuple[FloatArray, FloatArray]:
        if not (type(X) is np.ndarray and X.shape == self.bare.mask.shape):
            X = as_regressors(X, self.layout.sizes)
        x = np.where(self.bare.mask, X, 0.0)  # a copy: the backlog keeps it
        zz = np.array(z, dtype=float)
        if zz.shape != (len(self.layout.sizes),):
            zz = zz.reshape(-1)
            if zz.shape != (len(self.layout.sizes),):
                raise ValueError(f"expected {len(self.layout.sizes)} measured outputs, got shape {zz.shape}")
        # One sum checks every value (a NaN or infinity makes it non-finite); only when it is
        # not finite are the values checked one by one (the sum of huge finite values overflows).
        total = float(x.sum()) + float(zz.sum()) + u + qbar + V
        finite = math.isfinite(total) or (np.isfinite(x).all() and np.isfinite(zz).all()
                                          and all(math.isfinite(v) for v in (u, qbar, V)))
        if not (finite and V > 0):
            raise NonFiniteInput(f"instruments: a regressor, output, excitation u={u!r}, qbar={qbar!r} or "
                                 f"airspeed V={V!r} is not finite (or V <= 0); the sample is refused")
        return x, zz
