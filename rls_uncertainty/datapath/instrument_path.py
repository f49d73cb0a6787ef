"""``estimator.algorithm iv`` in the data path: instruments for each regression row (numpy only).

The pipeline hands every row it would give the estimator to :meth:`InstrumentPath.update`.
With ``instruments.source`` resolved to ``excitation`` (:meth:`..instruments.options.InstrumentOptions.resolved_source`)
the injected elevator excitation comes aligned with the row (the ``excitation`` input stream,
mixed by Eq. 23 like the surfaces and delayed with its sample) and
:class:`..instruments.ShortPeriodAuxiliary` turns it into instruments through an auxiliary
short-period model; until its first model exists the rows wait (bounded by
``instruments.max_backlog_span``; older ones are rejected as ``instruments_not_ready``) and are
then handed over together, each with its stamp. With ``delayed``,
:class:`..instruments.DelayedRegressors` instruments each row with the measured surfaces and the
regressors ``instruments.delay_span`` earlier; a row without that earlier row (the first ones,
after a gap) is rejected as ``instruments_not_ready``.
:class:`..instruments.InstrumentStrength` keeps the sums of the weak-instrument measure
(the smallest canonical correlation ``rho_min`` between a model's instruments and regressors),
judged every ``instruments.refresh_span``: a model whose instruments are weak is never
flagged converged, and the reason is its parameters' state (:mod:`.states`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..aero.models import BIAS_REGRESSOR
from ..errors import NonFiniteInput
from ..instruments import DelayedRegressors, InstrumentStrength, ShortPeriodAuxiliary

if TYPE_CHECKING:  # annotations only
    from ..aero.coefficients import FlightState
    from ..estimator import EstimatorBank
    from .bookkeeping import Bookkeeping
    from .config import PipelineConfig
    from .frequency_path import FrequencyPath

__all__ = ["InstrumentPath", "InstrumentedRow", "MAX_SAVED_COUNT"]

MAX_SAVED_COUNT = 2**53  # the largest sample count a saved state may hold (exact as a float)
# The saved arrays whose first axis is the rows held (waiting, or kept for their delay).
_ROWS = ("iv_backlog_", "iv_history_")


class InstrumentedRow(NamedTuple):
    """A regression row for the estimator: its stamp (ns), regressors ``X`` ``(M, n_max)``,
    outputs ``z`` ``(M,)`` and instruments ``zeta`` laid out like ``X``."""

    stamp_ns: int
    X: np.ndarray
    z: np.ndarray
    zeta: np.ndarray


class InstrumentPath:
    """The instruments of one estimator's rows (a new estimator gets a new path)."""

    def __init__(self, config: PipelineConfig) -> None:
        opts = config.instruments
        self.options = opts
        self.source = opts.resolved_source(config.models)
        self.aux: ShortPeriodAuxiliary | DelayedRegressors
        if self.source == "excitation":
            self.aux = ShortPeriodAuxiliary(config.models, config.aircraft, config.rate,
                                            refresh_span=opts.refresh_span, max_backlog_span=opts.max_backlog_span)
        else:
            self.aux = DelayedRegressors(config.models, max(1, round(opts.delay_span * config.rate)),
                                         config.period_ns)
        sizes = [len(m.regressors) for m in config.models]
        bias = [m.regressors.index(BIAS_REGRESSOR) if BIAS_REGRESSOR in m.regressors else None
                for m in config.models]
        self.strength = InstrumentStrength(sizes, bias, opts.weak_below)
        self._judge_every = max(1, round(opts.refresh_span * config.rate))
        self._since = 0
        self._config = config
        self.rho_min = np.full(len(sizes), np.nan)  # at the last judgement
        self.weak = np.zeros(len(sizes), dtype=bool)

    @property
    def waiting(self) -> int:
        """Rows waiting for the first auxiliary model (neither used nor rejected yet)."""
        return self.aux.waiting

    def update(self, stamp_ns: int, X: np.ndarray, z: np.ndarray, u: float | None, qbar: float, V: float,
               estimates: np.ndarray | None) -> tuple[list[InstrumentedRow], int]:
        """One row (stamped ``stamp_ns``) with the excitation ``u`` (rad, the elevator's; None
        with delayed instruments) and the estimator's newest ``estimates`` (None before any): the
        rows to give the estimator now with their instruments, and how many rows were dropped
        without instruments (a full backlog; with delayed instruments, no row a delay earlier).
        A non-finite input raises :class:`..errors.NonFiniteInput` and changes nothing."""
        dropped = self.aux.dropped
        if isinstance(self.aux, DelayedRegressors):
            rows = self.aux.update(X, z, int(stamp_ns))
        else:
            assert u is not None  # the excitation is a required stream with these instruments
            rows = self.aux.update(X, z, u, qbar, V, estimates, tag=int(stamp_ns))
        dropped = self.aux.dropped - dropped
        out = [InstrumentedRow(int(r.tag), r.X, r.z, r.instruments) for r in rows]  # type: ignore[call-overload]
        for r in out:
            self.strength.update(r.X, r.zeta)
        self._since += len(out)
        if self._since >= self._judge_every:
            self._since = 0
            self.rho_min = self.strength.rho_min()
            self.weak = self.strength.weak()
        return out, dropped

    def feed(self, t: int, X: np.ndarray, z: np.ndarray, u: Sequence[float] | None, state: FlightState,
             estimates: np.ndarray | None, bank: EstimatorBank, book: Bookkeeping,
             used: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None],
             frequency: FrequencyPath | None = None) -> bool:
        """Row ``t`` (the excitation ``u`` delayed with it, ``state`` its flight state) and the
        rows that waited for the first auxiliary model go to ``bank`` with their instruments,
        each then reported to ``used``; refusals are counted in ``book``. With ``frequency``
        (``estimator.method`` frequency or both) every row is checked there first (a row either
        estimator refuses is used by neither) and the rows that waited are taken there too, in
        order (row ``t`` is added by the caller, with its results). Whether row ``t`` reached
        the estimator (False: it waits, or was refused)."""
        if estimates is None and bank.k:  # a resumed bank before its first output: its estimates
            estimates = bank.theta_all()
        try:
            rows, dropped = self.update(t, X, z, None if u is None else u[0], float(state.qbar), float(state.V),
                                        estimates)
        except NonFiniteInput:
            book.reject_samples("non_finite_regression")
            return False
        if dropped:
            book.reject_samples("instruments_not_ready", dropped)
        reached = False
        for row in rows:
            try:
                if frequency is not None:
                    frequency.check(row.X, row.z, row.zeta)
                bank.update(row.X, row.z, instruments=row.zeta)
            except NonFiniteInput:
                book.reject_samples("non_finite_regression")
                continue
            used(row.stamp_ns, row.X, row.z, row.zeta)
            reached = row.stamp_ns == t
            if frequency is not None and not reached:  # a row that waited: no results of its own
                frequency.take()
        return reached

    # ------------------------------------------------------------------ the state file
    def snapshot(self) -> dict[str, Any]:
        """The instruments' state as plain data, for the state file: ``counters`` (``source``,
        ``since_judged``, ``strength_k`` and the source's own, :meth:`.ShortPeriodAuxiliary.snapshot`
        or :meth:`.DelayedRegressors.snapshot`) and ``arrays`` named as the file stores them
        (``iv_`` and the source's names; ``iv_S_zz``, ``iv_S_xx``, ``iv_S_zx`` the strength's
        sums; ``iv_rho_min`` the last judgement, NaN before one). :meth:`restore` continues
        bit-identically."""
        aux, strength = self.aux.snapshot(), self.strength.snapshot()
        counters = {"source": self.source, "since_judged": self._since, "strength_k": strength["counters"]["k"],
                    **aux["counters"]}
        arrays = {f"iv_{k}": v for k, v in (aux["arrays"] | strength["arrays"]).items()}
        return {"counters": counters, "arrays": {**arrays, "iv_rho_min": self.rho_min.copy()}}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (of a path of this configuration: its checks are the
        state file's, :func:`..state_file.load_state`; here only shapes, :class:`ValueError`)."""
        c = dict(saved["counters"])
        arrays = {k[3:]: v for k, v in saved["arrays"].items()}
        if c.pop("source") != self.source:
            raise ValueError(f"saved instruments of another source than {self.source}")
        self._since = int(c.pop("since_judged"))
        self.strength.restore({"counters": {"k": c.pop("strength_k")}, "arrays": arrays})
        self.aux.restore({"counters": c, "arrays": arrays})
        rho = np.array(arrays["rho_min"], dtype=float)
        if rho.shape != self.rho_min.shape:
            raise ValueError(f"saved rho_min has shape {rho.shape}, expected {self.rho_min.shape}")
        self.rho_min = rho
        with np.errstate(invalid="ignore"):
            self.weak = rho < self.options.weak_below

    def state_spec(self) -> dict[str, Any]:
        """What a saved state of this path must hold besides its arrays' layout: ``source``,
        ``integers`` (each counter's ``(low, high)``), ``flags`` (the boolean counters),
        ``rows`` (the counter giving the rows held) and ``span_ns`` (delayed: the longest
        stamp span the rows held may cover, else None)."""
        counts = {"since_judged": (0, self._judge_every - 1), "strength_k": (0, MAX_SAVED_COUNT),
                  "dropped": (0, MAX_SAVED_COUNT)}
        if isinstance(self.aux, DelayedRegressors):
            return {"source": self.source, "integers": {**counts, "history": (0, self.aux.delay + 1)},
                    "flags": (), "rows": "history", "span_ns": self.aux.span_ns}
        integers = {**counts, "since_refresh": (0, self.aux.refresh - 1), "refused": (0, MAX_SAVED_COUNT),
                    "waiting": (0, self.aux.max_backlog), "bare_k": (0, MAX_SAVED_COUNT)}
        return {"source": self.source, "integers": integers, "flags": ("has_model", "bare_ready"),
                "rows": "waiting", "span_ns": None}

    def state_layout(self, rows: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """``{name: (shape, dtype)}`` of :meth:`snapshot`'s arrays with ``rows`` rows held."""
        fresh = InstrumentPath(self._config).snapshot()["arrays"]
        return {name: ((rows, *a.shape[1:]) if name.startswith(_ROWS) else a.shape, a.dtype)
                for name, a in fresh.items()}

    def weak_reason(self, j: int) -> str:
        """Why model ``j``'s parameters are held back for weak instruments, or ''."""
        if not self.weak[j]:
            return ""
        rho = float(self.rho_min[j])
        return (f"weak instruments (rho_min {rho:.3f} < instruments.weak_below {self.options.weak_below:g}: "
                + ("is the excitation injected and on topics.excitation?)" if self.source == "excitation" else
                   "does the maneuver move the delayed regressors? try a shorter instruments.delay_span)")
                if math.isfinite(rho) else "")
