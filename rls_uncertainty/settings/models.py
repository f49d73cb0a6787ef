"""The aircraft and the models: what is flown and what is estimated of it.

:class:`AircraftConfig` (mass, inertias and reference geometry, SI, from a YAML file in
``config/aircraft/``, :func:`load_aircraft`) and :class:`ModelConfig` (one coefficient of Eq. 1
and its regressors of Eq. 2, :data:`REGRESSORS`; the paper's six are :data:`DEFAULT_MODELS`).
Each checks itself when built, with messages that name the file and the field. Also where the
package's data directories are (:func:`package_path`, :func:`config_dir`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path

from ..datapath.identifiability import ANGLE, BIAS, NONDIMENSIONAL
from ..errors import ConfigError
from .yaml_files import load_mapping

__all__ = [
    "AircraftConfig",
    "ModelConfig",
    "DEFAULT_AIRCRAFT",
    "DEFAULT_MODELS",
    "OUTPUTS",
    "REGRESSORS",
    "REGRESSOR_UNITS",
    "BIAS_REGRESSOR",
    "load_aircraft",
    "load_models",
    "config_dir",
    "package_path",
]

# The aircraft of the node's ``aircraft`` parameter by default: the paper's T-2.
DEFAULT_AIRCRAFT = "t2"


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
# The unit of each regressor, for the excitation test of :mod:`.identifiability`: flow angles and
# surface deflections in rad, the nondimensional rates, and the bias (not tested).
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


def package_path(*parts: str) -> Path:
    """A data file or directory of the package (``config``, ``msg_schemas``, ``bags/...``,
    ``package.xml``), looked for in this order: the source tree the package is imported from
    (a checkout, an editable install); the package data of an installed wheel
    (``rls_uncertainty/share/``, the share directory's layout, read with
    :mod:`importlib.resources`); the share directory of a ROS install (ament index)."""
    package = Path(__file__).resolve().parents[1]  # the rls_uncertainty package
    source = package.parent
    if (source / "package.xml").is_file() and (source / "setup.py").is_file():
        candidate = source.joinpath(*parts)
        if candidate.exists():
            return candidate
    data = resources.files("rls_uncertainty").joinpath("share", *parts)
    if isinstance(data, Path) and data.exists():
        return data
    try:  # installed ROS package (colcon)
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        return Path(get_package_share_directory("rls_uncertainty")).joinpath(*parts)
    except Exception as exc:  # not found, whichever way ament says it
        raise ConfigError(f"cannot find the rls_uncertainty data {'/'.join(parts)} (in {source}, {data} or a ROS "
                          "install's share directory): reinstall the package") from exc


def config_dir() -> Path:
    """The package's ``config/`` directory (source tree or ROS install share)."""
    return package_path("config")


def load_aircraft(path_or_name: str | Path) -> AircraftConfig:
    """Aircraft properties from a YAML file, or by name from ``config/aircraft/NAME.yaml``."""
    path = Path(path_or_name)
    if not path.suffix:
        path = config_dir() / "aircraft" / f"{path_or_name}.yaml"
    data = load_mapping(path, "aircraft file")
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


def load_models(spec: object) -> tuple[ModelConfig, ...]:
    """Model structures from a mapping ``{output: [regressor, ...]}`` (YAML ``models:``)."""
    if not isinstance(spec, dict) or not spec:
        raise ConfigError("models must be a non-empty mapping of output -> list of regressors")
    return tuple(ModelConfig(str(k), tuple(str(r) for r in v)) for k, v in spec.items())
