"""The frequency-domain estimator beside the pipeline's time-domain one (numpy only).

With ``estimator.method: frequency`` or ``both`` (:attr:`.config.PipelineConfig.method`) the
pipeline hands every regression row it gives the time-domain estimator to one
:class:`FrequencyPath` as well (docs/frequency.md, "In the node"):

* **The rows.** The same samples, in the same order: a row the frequency-domain estimator
  would refuse (:meth:`.frequency.FrequencyBank.check`) is refused before either estimator
  takes it, so both hold the same record. The bias regressor ``"1"`` is left out (the trim
  removes it, F1): the frequency-domain parameters of a model are its
  :attr:`.config.ModelConfig.frequency_parameter_names`. Samples are taken as consecutive,
  across a dropout too, as the time-domain estimator's lag products take them (the transform's
  clock counts the samples used).
* **Instruments.** With ``estimator.algorithm: iv`` each row comes with the instruments the
  time-domain estimator takes (:mod:`.instrument_path`), laid out like the regressors; the bias
  instrument is left out like the bias, the others are transformed with the regressors and the
  bank estimates with instrumental variables (docs/frequency.md, F11-F12). Rows that waited for
  the first auxiliary model reach both estimators together, in their order
  (:meth:`FrequencyPath.take`: no results for them, as the time domain gives none).
* **When it publishes.** Estimates and both standard errors are computed on the samples whose
  count since the start (or the last restart) is a multiple of ``frequency.every``, and a
  :class:`FrequencyOutput` is made for those samples only, stamped with that sample's time:
  with ``every > 1`` the numbers belong to the sample they are published with, nothing is
  repeated in between.
* **Convergence.** A second :class:`.convergence.ConvergenceMonitor` on the frequency-domain
  estimates and corrected standard errors, fed the published samples; a parameter the data
  cannot identify (:class:`.identifiability.IdentifiabilityMonitor`, judged on the same
  sample from the time-domain fit) is never flagged.
* **Nothing non-finite, zero or rounding-level leaves.** A model the bank withholds (an exact
  fit, a corrected covariance with a negative variance: :attr:`.frequency.FrequencyBank.withheld`),
  or whose estimates or standard errors are not all finite, or whose standard errors are not
  above :data:`.guard.SE_FLOOR` of its estimates, is marked not ready in that output
  and counted (``outputs_withheld`` under ``M/frequency``).

A new path is made whenever the time-domain estimator restarts (``~/reset``, a new timeline, a
new configuration). The state file holds its bank's record (:meth:`FrequencyPath.snapshot`,
:mod:`.frequency.state`): a node resumed from one continues the frequency-domain record where it
stopped; the second convergence monitor restarts, as the time domain's does.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..aero.models import BIAS_REGRESSOR
from ..estimator.state import MAX_COUNT as MAX_SAVED_COUNT
from ..frequency import FrequencyBank
from ..frequency import state as record
from .convergence import ConvergenceMonitor
from .guard import withheld as unpublishable

if TYPE_CHECKING:  # annotations only
    from .bookkeeping import Tally
    from .config import PipelineConfig
    from .identifiability import IdentifiabilityMonitor

__all__ = ["FrequencyOutput", "FrequencyPath", "WITHHELD_SUFFIX"]

# outputs_withheld counts a model's withheld frequency-domain outputs under "<model>/frequency".
WITHHELD_SUFFIX = "/frequency"


class FrequencyOutput(NamedTuple):
    """The frequency-domain results of one sample, ``(M, q_max)`` arrays over each model's
    :attr:`.config.ModelConfig.frequency_parameter_names` (padding NaN or False):
    ``theta``, ``se`` (corrected, docs/frequency.md F7-F10), ``se_conventional`` (F5),
    ``ready`` ``(M,)`` (false too where a value was not finite: withheld), ``converged`` and
    ``model_converged`` (the second monitor's flags), ``lags`` ``(M,)``: the lags of the
    residual autocovariance behind ``se`` (``frequency.lag_span``, fewer while the record is
    shorter; 0 for models not ready)."""

    theta: np.ndarray
    se: np.ndarray
    se_conventional: np.ndarray
    ready: np.ndarray
    converged: np.ndarray
    model_converged: np.ndarray
    lags: np.ndarray


class FrequencyPath:
    """The frequency-domain estimator of a pipeline's models (module docstring). ``config``
    must have ``frequency`` options (``estimator.method`` not ``time``)."""

    def __init__(self, config: PipelineConfig) -> None:
        options = config.frequency
        if options is None:
            raise ValueError("the frequency path needs frequency options (estimator.method: frequency or both)")
        self.outputs = [m.output for m in config.models]
        self.parameter_names = [m.frequency_parameter_names for m in config.models]
        self.sizes = [len(names) for names in self.parameter_names]
        instrumented = config.estimator.algorithm == "iv"
        self.bank = FrequencyBank(self.sizes, options, instruments=instrumented)
        self.every, self.n_lags = options.every, options.n_lags
        rows = [m.regressors for m in config.models]
        n_max, q = max(map(len, rows)), max(self.sizes)
        # Where each frequency-domain regressor sits in the time-domain row (M, n_max), flattened,
        # and where it goes in this path's (M, q): the regressors of Eq. 2 without the bias.
        self._take = np.array([j * n_max + i for j, row in enumerate(rows) for i, r in enumerate(row)
                               if r != BIAS_REGRESSOR], dtype=np.intp)
        self._put = np.array([j * q + k for j, size in enumerate(self.sizes) for k in range(size)], dtype=np.intp)
        self._X = np.zeros((len(rows), q))
        self._W: np.ndarray | None = np.zeros((len(rows), q)) if instrumented else None
        self.real = np.arange(q) < np.array(self.sizes)[:, None]  # (M, q): not padding
        self._monitor = ConvergenceMonitor(self.sizes, replace(config.convergence, rate_hz=config.rate))
        self._row: np.ndarray | None = None
        self.last: FrequencyOutput | None = None  # the newest published results

    def check(self, X: np.ndarray, z: np.ndarray, zeta: np.ndarray | None = None) -> None:
        """Take the time-domain regression row ``X`` ``(M, n_max)``, ``z`` ``(M,)`` and, with
        ``estimator.algorithm: iv``, its instruments ``zeta`` laid out like ``X``, or raise
        :class:`.errors.NonFiniteInput` (nothing changes); :meth:`add` or :meth:`take` then uses it."""
        self._X.flat[self._put] = X.flat[self._take]
        W = self._W
        if W is not None:
            if zeta is None:
                raise ValueError("the frequency path estimates with instruments: each row needs its zeta")
            W.flat[self._put] = zeta.flat[self._take]
        self._row = self.bank.check(self._X, z, W)

    def take(self) -> None:
        """Advance by the row :meth:`check` took without results: a row handed over with
        others (the rows that waited for the instruments), not the sample being published."""
        row, self._row = self._row, None
        if row is None:
            raise RuntimeError("FrequencyPath.take without a checked row")
        self.bank.add(row)

    def add(self, stamp_ns: int, withheld: Tally, quality: IdentifiabilityMonitor) -> FrequencyOutput | None:
        """Advance by the row :meth:`check` took; on the samples that publish (every
        ``frequency.every``-th) the results, else None. ``withheld`` counts the models whose
        results were not finite; ``quality`` has judged the same sample."""
        row, self._row = self._row, None
        if row is None:
            raise RuntimeError("FrequencyPath.add without a checked row")
        bank = self.bank
        bank.add(row)
        if bank.n_samples % self.every:
            return None
        theta = bank.theta_all()
        se = bank.standard_errors_all("corrected")
        se_conv = bank.standard_errors_all("conventional")
        ready = bank.ready
        bad = unpublishable(ready, self.real, theta, se, se_conv) | bank.withheld
        for j in np.flatnonzero(bad).tolist():
            withheld.count(self.outputs[j] + WITHHELD_SUFFIX)
        ready &= ~bad
        flags, model_flags = self._monitor.update(stamp_ns, theta, se, ready)
        if flags.any():  # a parameter the data cannot identify is never flagged
            ok = np.zeros(flags.shape, dtype=bool)
            ok.flat[self._put] = quality.identifiable.flat[self._take]
            flags &= ok
            model_flags &= (ok | ~self.real).all(axis=1)
        lags = np.where(ready, min(self.n_lags, bank.n_samples - 1), 0)
        self.last = FrequencyOutput(theta, se, se_conv, ready, flags, model_flags, lags)
        return self.last

    def report(self, j: int) -> dict:
        """Model ``j``'s frequency-domain fit for ``/diagnostics``, keys prefixed ``frequency.``:
        ``ready`` (published at the last evaluation), ``samples``, and once solved
        ``r_squared`` and ``residual_rho1`` (:meth:`.frequency.FrequencyBank.fit`), ``converged``
        and, until published, ``publish_at_samples``."""
        bank, last = self.bank, self.last
        ready = bool(last is not None and last.ready[j])
        out: dict = {"frequency.ready": ready, "frequency.samples": bank.n_samples}
        if bank.solved[j]:
            r2, rho1 = bank.fit()
            out["frequency.r_squared"], out["frequency.residual_rho1"] = float(r2[j]), float(rho1[j])
        if ready:
            assert last is not None
            out["frequency.converged"] = bool(last.model_converged[j])
        else:
            out["frequency.publish_at_samples"] = int(bank.publish_at[j])
        return out

    # ------------------------------------------------------------------ the state file
    def snapshot(self) -> dict[str, Any]:
        """The bank's record as plain data, for the state file: ``counters`` (``n``,
        ``evaluated_at``, ``repairs``, ``due``) and ``fq_`` arrays (:func:`.frequency.state.snapshot`).
        :meth:`restore` continues bit-identically."""
        return record.snapshot(self.bank)

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (of a path of this configuration: its checks are the
        state file's, :func:`..state_file.load_state`; here only shapes, :class:`ValueError`)."""
        record.restore(self.bank, saved)

    def state_spec(self) -> dict[str, Any]:
        """What a saved record must hold besides its arrays' layout: ``prefix`` (of the arrays'
        names), ``integers`` (each counter's ``(low, high)``), ``flags`` (the boolean counters) and
        ``results`` (the arrays of the last evaluation's results, NaN where there are none)."""
        counts = (0, MAX_SAVED_COUNT)
        return {"prefix": record.PREFIX, "integers": {"n": counts, "evaluated_at": counts, "repairs": counts},
                "flags": ("due",), "results": record.RESULTS}

    def state_layout(self, evaluated_at: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """``{name: (shape, dtype)}`` of :meth:`snapshot`'s arrays, last evaluated at sample
        ``evaluated_at``."""
        return record.layout(self.bank, evaluated_at)
