"""Where each instrument goes: a model's instrument vector laid out like its regressor vector.

For a model with regressors among ``1, alpha, q_hat, delta_e`` (Eq. 2c, 2e), in the model's
own order (I1):

    regressor   1     alpha      q_hat                delta_e
    instrument  1     alpha_o    cbar/(2V) q_o        u

``(alpha_o, q_o)`` is the state of the auxiliary model (:mod:`.discrete`) driven by the
injected elevator excitation ``u``, in perturbations from trim; the bias column absorbs the
trim (the regressors are absolute angles). The bank's ``(M, n_max)`` layout is kept: row ``j``
holds model ``j``'s instruments first, the padding is 0. Any other regressor (``beta``,
``p_hat``, ``r_hat``, ``delta_a``, ``delta_r``) has no instrument here, and the auxiliary model
needs the C_Z model with ``alpha`` and ``delta_e`` and the C_m model with ``alpha``, ``q_hat``
and ``delta_e``: other model sets are refused with a :class:`ConfigError`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..aero.models import ModelConfig
from ..errors import ConfigError
from .discrete import DERIVATIVES

__all__ = ["SERVED", "InstrumentLayout"]

FloatArray = npt.NDArray[np.float64]

# The regressors the short-period auxiliary model instruments, and the slot of each in the
# per-sample vector (1, alpha_o, q_hat_o, u, 0) that :meth:`InstrumentLayout.assemble` fills.
SERVED = {"1": 0, "alpha": 1, "q_hat": 2, "delta_e": 3}
_PADDING = 4
# Where each of :data:`DERIVATIVES` is estimated: (model output, regressor); C_Z_q optional.
_NEEDED = {"CZ_alpha": ("CZ", "alpha"), "CZ_delta_e": ("CZ", "delta_e"), "Cm_alpha": ("Cm", "alpha"),
           "Cm_q": ("Cm", "q_hat"), "Cm_delta_e": ("Cm", "delta_e")}
_OPTIONAL = {"CZ_q": ("CZ", "q_hat")}
_SETTING = "estimator.algorithm"


class InstrumentLayout:
    """The models' instrument layout and where the auxiliary model's derivatives are in the
    estimates; refuses (:class:`ConfigError`, one line naming ``estimator.algorithm``) models
    it cannot serve."""

    def __init__(self, models: Sequence[ModelConfig]) -> None:
        self.models = tuple(models)
        if not self.models:
            raise ConfigError(f"{_SETTING}: iv needs at least one model", parameter=_SETTING)
        for m in self.models:
            other = [r for r in m.regressors if r not in SERVED]
            if other:
                raise ConfigError(
                    f"{_SETTING}: iv cannot instrument model {m.output}'s regressor(s) {', '.join(other)}: "
                    f"the short-period auxiliary model serves only {', '.join(SERVED)} "
                    f"(use instruments.source delayed or auto, {_SETTING}: rls, or leave {m.output} out of "
                    "models.enabled)", parameter=_SETTING)
        self.sizes = tuple(len(m.regressors) for m in self.models)
        self.n_max = max(self.sizes)
        where = self._locate()
        self._present = np.array([w is not None for w in where])
        self._flat = np.array([0 if w is None else w[0] * self.n_max + w[1] for w in where])
        self._select = np.full((len(self.models), self.n_max), _PADDING)
        for j, m in enumerate(self.models):
            self._select[j, : self.sizes[j]] = [SERVED[r] for r in m.regressors]
        self._values = np.zeros(_PADDING + 1)

    def _locate(self) -> list[tuple[int, int] | None]:
        """``(model, column)`` of each of :data:`DERIVATIVES` (``None``: an optional one absent)."""
        outputs = {m.output: j for j, m in enumerate(self.models)}
        where: list[tuple[int, int] | None] = []
        missing = []
        for name in DERIVATIVES:
            output, regressor = _NEEDED.get(name) or _OPTIONAL[name]
            j = outputs.get(output)
            if j is not None and regressor in self.models[j].regressors:
                where.append((j, self.models[j].regressors.index(regressor)))
            else:
                where.append(None)
                if name in _NEEDED:
                    missing.append(name)
        if missing:
            raise ConfigError(
                f"{_SETTING}: iv builds its auxiliary short-period model from the CZ model (1, alpha, delta_e) "
                f"and the Cm model (1, alpha, q_hat, delta_e); these models do not estimate {', '.join(missing)}",
                parameter=_SETTING)
        return where

    def derivatives(self, theta: npt.ArrayLike) -> FloatArray:
        """The :data:`DERIVATIVES` values (``C_Z_q`` 0 when not estimated) from the estimates
        ``theta`` ``(M, n_max)`` (the bank's ``theta_all`` layout); NaN where not available."""
        t = np.asarray(theta, dtype=float)
        if t.shape != (len(self.models), self.n_max):
            raise ValueError(f"expected estimates of shape {(len(self.models), self.n_max)}, got {t.shape}")
        out: FloatArray = np.where(self._present, t.ravel()[self._flat], 0.0)
        return out

    def assemble(self, alpha: float, q: float, u: float, V: float, cbar: float) -> FloatArray:
        """The ``(M, n_max)`` instruments of one sample from the auxiliary state ``(alpha, q)``,
        the excitation ``u`` and the airspeed ``V`` (``q_hat = cbar q / (2V)``)."""
        v = self._values
        v[0], v[1], v[2], v[3] = 1.0, alpha, cbar * q / (2.0 * V), u
        out: FloatArray = v[self._select]
        return out
