"""What is flown and what is estimated of it (numerical core: the standard library only).

:class:`AircraftConfig` (mass, inertias and reference geometry, SI) and :class:`ModelConfig` (one
coefficient of Eq. 1 and its regressors of Eq. 2, :data:`REGRESSORS`; the paper's six are
:data:`DEFAULT_MODELS`). Each checks itself when built, with messages that name the field; the
files they are read from are :mod:`rls_uncertainty.settings.models`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ..errors import ConfigError

__all__ = [
    "AircraftConfig",
    "ModelConfig",
    "DEFAULT_MODELS",
    "OUTPUTS",
    "REGRESSORS",
    "REGRESSOR_UNITS",
    "BIAS_REGRESSOR",
    "ANGLE",
    "NONDIMENSIONAL",
    "BIAS",
]


@dataclass(frozen=True)
class AircraftConfig:
    """Mass (kg), inertias (kg m^2, aircraft body axes), wing area (m^2), span and mean
    aerodynamic chord (m)."""

    name: str
    mass: float
    Ixx: float
    Iyy: float
    Izz: float
    Ixz: float
    S: float
    b: float
    cbar: float

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"aircraft {self.name!r}: {f.name} must be a finite number, got {value!r}")
            if f.name != "Ixz" and value <= 0:
                raise ConfigError(f"aircraft {self.name!r}: {f.name} must be positive, got {value!r}")


# Regressor names of Eq. 2: bias, flow angles, controls and nondimensional rates.
REGRESSORS = {
    "1": "bias",
    "alpha": "angle of attack, rad",
    "beta": "sideslip, rad",
    "delta_e": "elevator, rad",
    "delta_a": "aileron, rad",
    "delta_r": "rudder, rad",
    "p_hat": "p b / 2V",
    "q_hat": "q cbar / 2V",
    "r_hat": "r b / 2V",
}
# The unit of each regressor, for the excitation test of :mod:`..datapath.identifiability`: flow
# angles and surface deflections in rad, the nondimensional rates, and the bias (not tested).
ANGLE, NONDIMENSIONAL, BIAS = "rad", "", None
REGRESSOR_UNITS: dict[str, str | None] = {
    "1": BIAS, "alpha": ANGLE, "beta": ANGLE, "delta_e": ANGLE, "delta_a": ANGLE, "delta_r": ANGLE,
    "p_hat": NONDIMENSIONAL, "q_hat": NONDIMENSIONAL, "r_hat": NONDIMENSIONAL,
}
OUTPUTS = ("CX", "CY", "CZ", "Cl", "Cm", "Cn")
BIAS_REGRESSOR = "1"  # the bias regressor of Eq. 2
_PARAM_SUFFIX = {"1": "0", "p_hat": "p", "q_hat": "q", "r_hat": "r"}


@dataclass(frozen=True)
class ModelConfig:
    """One coefficient model: the output of Eq. 1 and its regressors (Eq. 2 structure)."""

    output: str
    regressors: tuple[str, ...]

    def __post_init__(self) -> None:
        if self.output not in OUTPUTS:
            raise ConfigError(f"model output must be one of {OUTPUTS}, got {self.output!r}")
        if not self.regressors:
            raise ConfigError(f"model {self.output}: needs at least one regressor")
        unknown = [r for r in self.regressors if r not in REGRESSORS]
        if unknown:
            raise ConfigError(
                f"model {self.output}: unknown regressor(s) {unknown}; known: {sorted(REGRESSORS)}"
            )
        if len(set(self.regressors)) != len(self.regressors):
            raise ConfigError(f"model {self.output}: a regressor is listed twice")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """``CZ_0, CZ_alpha, CZ_delta_e``: the output, then the regressor (bias as ``0``)."""
        return tuple(f"{self.output}_{_PARAM_SUFFIX.get(r, r)}" for r in self.regressors)

    @property
    def frequency_parameter_names(self) -> tuple[str, ...]:
        """The parameters the frequency-domain method estimates: :attr:`parameter_names`
        without the bias (``CZ_alpha, CZ_delta_e``), whose regressor ``"1"`` the trim removes
        (docs/frequency.md, F1)."""
        return tuple(p for r, p in zip(self.regressors, self.parameter_names, strict=True) if r != BIAS_REGRESSOR)


DEFAULT_MODELS = (
    ModelConfig("CX", ("1", "alpha", "delta_e")),  # Eq. 2a
    ModelConfig("CY", ("1", "beta", "r_hat", "delta_r")),  # Eq. 2b
    ModelConfig("CZ", ("1", "alpha", "delta_e")),  # Eq. 2c
    ModelConfig("Cl", ("1", "beta", "p_hat", "r_hat", "delta_a", "delta_r")),  # Eq. 2d
    ModelConfig("Cm", ("1", "alpha", "q_hat", "delta_e")),  # Eq. 2e
    ModelConfig("Cn", ("1", "beta", "r_hat", "delta_r")),  # Eq. 2f
)
