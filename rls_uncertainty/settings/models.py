"""The aircraft and the models read from files: :func:`load_aircraft` (a YAML file in
``config/aircraft/``, or a path) and :func:`load_models`, with messages that name the file and
the field; the classes themselves are :mod:`rls_uncertainty.aero.models`'s. Also where the
package's data directories are (:func:`package_path`, :func:`config_dir`).
"""

from __future__ import annotations

from dataclasses import fields
from importlib import resources
from pathlib import Path

from ..aero.models import (
    BIAS_REGRESSOR,
    DEFAULT_MODELS,
    OUTPUTS,
    REGRESSOR_UNITS,
    REGRESSORS,
    AircraftConfig,
    ModelConfig,
)
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
