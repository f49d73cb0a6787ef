"""Typed configuration: aircraft properties, model structures, estimator settings.

Everything is SI. YAML files live in ``config/``; :func:`load_aircraft` and
:func:`load_models` validate them with messages that name the file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import yaml

__all__ = [
    "AircraftConfig",
    "ModelConfig",
    "EstimatorConfig",
    "ConfigError",
    "DEFAULT_MODELS",
    "REGRESSORS",
    "load_aircraft",
    "load_models",
    "config_dir",
]


class ConfigError(ValueError):
    """A configuration value is missing or invalid; the message says which and why."""


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
OUTPUTS = ("CX", "CY", "CZ", "Cl", "Cm", "Cn")
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
    def name(self) -> str:
        return self.output

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """``CZ_0, CZ_alpha, CZ_delta_e``: the output, then the regressor (bias as ``0``)."""
        return tuple(f"{self.output}_{_PARAM_SUFFIX.get(r, r)}" for r in self.regressors)


DEFAULT_MODELS = (
    ModelConfig("CX", ("1", "alpha", "delta_e")),  # Eq. 2a
    ModelConfig("CY", ("1", "beta", "r_hat", "delta_r")),  # Eq. 2b
    ModelConfig("CZ", ("1", "alpha", "delta_e")),  # Eq. 2c
    ModelConfig("Cl", ("1", "beta", "p_hat", "r_hat", "delta_a", "delta_r")),  # Eq. 2d
    ModelConfig("Cm", ("1", "alpha", "q_hat", "delta_e")),  # Eq. 2e
    ModelConfig("Cn", ("1", "beta", "r_hat", "delta_r")),  # Eq. 2f
)


@dataclass(frozen=True)
class EstimatorConfig:
    """Settings of the recursive estimator (see :class:`rls_uncertainty.estimator.EstimatorBank`)."""

    n_lags: int | None = 50
    window: str = "truncated"
    forgetting: float = 1.0
    residual: str = "a_posteriori"
    models: tuple[ModelConfig, ...] = field(default=DEFAULT_MODELS)


def config_dir() -> Path:
    """The package's ``config/`` directory (source tree or ROS install share)."""
    here = Path(__file__).resolve().parent
    for candidate in (here.parent / "config", here / "config"):
        if candidate.is_dir():
            return candidate
    try:  # installed ROS package
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        return Path(get_package_share_directory("rls_uncertainty")) / "config"
    except Exception as exc:  # pragma: no cover - depends on the install
        raise ConfigError("cannot find the rls_uncertainty config directory") from exc


def _read_yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(Path(path).read_text())
    except FileNotFoundError as exc:
        raise ConfigError(f"{path}: no such file") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    return data


def load_aircraft(path_or_name: str | Path) -> AircraftConfig:
    """Aircraft properties from a YAML file, or by name from ``config/aircraft/NAME.yaml``."""
    path = Path(path_or_name)
    if not path.suffix:
        path = config_dir() / "aircraft" / f"{path_or_name}.yaml"
    data = _read_yaml(path)
    section = data.get("aircraft", data)
    required = [f.name for f in fields(AircraftConfig)]
    missing = [k for k in required if k not in section]
    if missing:
        raise ConfigError(f"{path}: aircraft needs {missing}")
    extra = sorted(set(section) - set(required))
    if extra:
        raise ConfigError(f"{path}: unknown aircraft field(s) {extra}")
    try:
        return AircraftConfig(**{k: section[k] for k in required})
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def load_models(spec) -> tuple[ModelConfig, ...]:
    """Model structures from a mapping ``{output: [regressor, ...]}`` (YAML ``models:``)."""
    if not isinstance(spec, dict) or not spec:
        raise ConfigError("models must be a non-empty mapping of output -> list of regressors")
    return tuple(ModelConfig(str(k), tuple(str(r) for r in v)) for k, v in spec.items())
