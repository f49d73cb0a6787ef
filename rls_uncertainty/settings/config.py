"""Typed configuration: aircraft properties, model structures, and the nested settings of the
pipeline (estimator, differentiator, input handling, Eq. 23 surface mixing).

Everything is SI. YAML files live in ``config/``; :func:`load_aircraft` and
:func:`load_models` validate them with messages that name the file and the field. One table,
:data:`PARAMETERS`, defines every setting the node declares as a ROS parameter and the
replay reads from the same parameter files; :func:`pipeline_config` turns those dotted
parameters into a :class:`PipelineConfig`. Each dataclass validates its own fields when it is
built, so a configuration that exists is a valid one.

Where the node's parameters come from, and what is refused. The node reads its command line
before rcl does (:func:`startup_parameters`; the syntax and rcl's reading of values and files
are in :mod:`.ros_arguments`), and the replay's ``--config`` is read by the same rules
(:func:`load_parameters_file`). A misconfiguration stops the node before it starts, in one
line naming the parameter, the reason and where the value came from, exit status 2:

* a value out of range, of the wrong type or not one of the choices; a parameter file that is
  missing, unreadable or not valid YAML, or not laid out as ``NODE: ros__parameters:``; a
  malformed ``-p``, ``-r`` or ``--params-file`` argument; an argument outside ``--ros-args``;
* a parameter the node does not know (``estimator.lag``), given with ``-p`` (with no node
  prefix or this node's) or in a file section that names this node (``rls_estimator:``,
  ``/NAMESPACE/rls_estimator:``), with the closest known name as a suggestion
  (``did you mean estimator.lag_span?``);
* an unknown parameter in a wildcard section (``/**:``, ``/*:``) when it can only be meant for
  this node: in one of its groups (``estimator.``, ``inputs.``, ``limits.``, ...) or close to
  one of its names;
* a parameter file none of whose sections applies to this node (``rls_estimatr:``), by name,
  namespace or wildcard as rcl matches them (the replay, which has no namespace, takes the
  sections named ``rls_estimator`` in any namespace and the wildcard ones).

One WARN line each, and the node starts: the other unknown names of a wildcard section (such a
section applies to every node of a launch, so they may be meant for another), the sections of
a file that are for other nodes, and a ``-p OTHER_NODE:NAME:=VALUE`` rule for another node.
The parameters every ROS 2 node has (``use_sim_time``, ``start_type_description_service``,
``qos_overrides.*``) are known. A later source wins, as in rcl: files and ``-p`` rules in
command-line order, sections in file order.
"""

from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from numbers import Integral
from pathlib import Path
from typing import Any

import yaml

from ..aero.differentiation import MAX_ORDER, MAX_WINDOW, MIN_WINDOW, DifferentiatorConfig
from ..aero.surface_mixing import SURFACES, SurfaceMixing
from ..datapath.convergence import ConvergenceConfig
from ..datapath.identifiability import ANGLE, BIAS, NONDIMENSIONAL, IdentifiabilityConfig
from ..datapath.limits import PlausibilityLimits
from ..errors import ConfigError
from ..estimator.options import MAX_BURN_IN, RESIDUALS, WINDOWS, EstimatorOptions, Lags
from ..frequency.options import MAX_LAGS as FREQUENCY_MAX_LAGS
from ..frequency.options import MAX_TRIM, FrequencyOptions
from .ros_arguments import (
    ParameterFile,
    ParameterRule,
    in_rcl_order,
    parse_ros_arguments,
    pattern_matches,
    read_parameter_file,
)

__all__ = [
    "AircraftConfig",
    "ModelConfig",
    "EstimatorOptions",
    "InputConfig",
    "PlausibilityLimits",
    "OutputConfig",
    "ConfigError",
    "DEFAULT_MODELS",
    "REGRESSORS",
    "load_aircraft",
    "load_models",
    "config_dir",
    "package_path",
    "ParamSpec",
    "PARAMETERS",
    "PipelineConfig",
    "NodeConfig",
    "parameter_defaults",
    "pipeline_config",
    "estimator_options",
    "frequency_options",
    "METHODS",
    "BIAS_REGRESSOR",
    "node_config",
    "load_parameters_file",
    "node_parameters_file",
    "NODE_NAME",
    "NodeParameters",
    "node_parameters",
    "startup_parameters",
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
    """A data directory of the package (``config``, ``msg_schemas``, ``bags/...``): from the
    source tree, or from the ROS install's share directory."""
    here = Path(__file__).resolve().parents[1]  # the rls_uncertainty package
    for base in (here.parent, here):
        candidate = base.joinpath(*parts)
        if candidate.exists():
            return candidate
    try:  # installed ROS package
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        return Path(get_package_share_directory("rls_uncertainty")).joinpath(*parts)
    except Exception as exc:  # pragma: no cover - depends on the install
        raise ConfigError(f"cannot find the rls_uncertainty directory {'/'.join(parts)}") from exc


def config_dir() -> Path:
    """The package's ``config/`` directory (source tree or ROS install share)."""
    return package_path("config")


def read_yaml(path: Path) -> dict:
    """A YAML file whose top level is a mapping; problems are :class:`ConfigError` naming the file."""
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
    data = read_yaml(path)
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


# ---------------------------------------------------------------------------------------------
# Pipeline and node settings: one table of parameters shared by the ROS node (declared ROS
# parameters with descriptions and ranges), the offline replay (``--config``, the same ROS
# parameter YAML) and the tests.


@dataclass(frozen=True)
class ParamSpec:
    """A setting: dotted name, default, description and the allowed values."""

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None


_EQ2 = {m.output: list(m.regressors) for m in DEFAULT_MODELS}
LAG_SELECTIONS = ("fixed", "auto")
# estimator.method: which estimates are published (docs/frequency.md, "In the node").
METHODS = ("time", "frequency", "both")
# residual_burn_in_span's default with automatic lags, s (AUTO_BURN_IN samples at the paper's 50 Hz).
AUTO_BURN_IN_SPAN = 1.0
MAX_LAGS = 100_000  # the most lags a span may ask for (the memory of Eq. 22's lag products)
# Parameters renamed when the lag window began to follow time: said when an old file names them.
RENAMED = {
    "estimator.lags": "estimator.lag_span, in seconds (lags / rate: 50 lags at 50 Hz = 1.0; -1 all lags)",
    "estimator.max_lags": "estimator.max_lag_span, in seconds (max_lags / rate)",
    "estimator.residual_burn_in": "estimator.residual_burn_in_span, in seconds (samples / rate; -1 the default)",
}

PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("rate", 50.0, "estimator sample rate, Hz; input streams are interpolated to it", 1.0, 1000.0),
    ParamSpec(
        "aircraft", "t2",
        "aircraft properties: a name in config/aircraft/ (t2, twin_otter_f1_017, ...) or a YAML path",
    ),
    ParamSpec("models.enabled", list(OUTPUTS), "models to estimate, a subset of CX, CY, CZ, Cl, Cm, Cn"),
    *(
        ParamSpec(f"models.{out}", _EQ2[out], f"regressors of the {out} model (Eq. 2); names: " + ", ".join(REGRESSORS))
        for out in OUTPUTS
    ),
    ParamSpec(
        "estimator.lag_span", 1.0,
        "time span of the residual autocorrelation kept in the corrected covariance (Eq. 22), s: lags = lag_span x "
        "rate (1.0 s: the paper's 50 lags at 50 Hz), so the standard errors do not depend on the rate; -1 keeps all "
        "lags (Eq. 20), 0 is the conventional covariance",
        -1.0, 2000.0,
    ),
    ParamSpec(
        "estimator.window", "truncated",
        "lag window: truncated (Eq. 22) or bartlett (always positive semi-definite)",
        choices=WINDOWS,
    ),
    ParamSpec(
        "estimator.forgetting", 1.0,
        "exponential forgetting factor; 1 is the paper's growing-memory estimator",
        0.5, 1.0,
    ),
    ParamSpec(
        "estimator.residual", "standardized",
        "residual used in Eqs. 16-17: standardized (innovation / sqrt(1 + x'Dx), makes Eq. 16 equal the batch Eq. "
        "14), a_posteriori (z - x'theta_k) or a_priori (z - x'theta_k-1)",
        choices=RESIDUALS,
    ),
    ParamSpec(
        "estimator.lag_selection", "fixed",
        "fixed: estimator.lag_span; auto: each model's lags chosen from its residual autocorrelation at every sample "
        "(Politis flat-top rule, truncated window only), up to estimator.max_lag_span",
        choices=LAG_SELECTIONS,
    ),
    ParamSpec(
        "estimator.max_lag_span", 1.0,
        "with estimator.lag_selection auto: the longest lag span the rule may choose, and the memory kept (as "
        "estimator.lag_span of that value), s",
        0.001, 2000.0,
    ),
    ParamSpec(
        "estimator.residual_burn_in_span", -1.0,
        "time after each model's initialization whose residuals are left out of the residual autocorrelation "
        f"(Eq. 17; the first residuals, while the estimate is still poor, inflate it), s; -1: {AUTO_BURN_IN_SPAN:g} s "
        "with estimator.lag_selection auto, 0 (the paper) with fixed lags",
        -1.0, 2000.0,
    ),
    ParamSpec(
        "estimator.method", "time",
        "estimates published: time (recursive least squares, ~/M/estimates ...), frequency (equation error on a "
        "recursive Fourier transform, ~/M/frequency/estimates ...) or both (docs/frequency.md)",
        choices=METHODS,
    ),
    ParamSpec("frequency.f_min", 0.1, "frequency-domain method: lowest frequency of the grid, Hz", 1e-6, 1000.0),
    ParamSpec(
        "frequency.f_max", 1.5,
        "frequency-domain method: highest frequency of the grid (included when a whole number of f_step from "
        "f_min), Hz; below rate / 2",
        1e-6, 1000.0,
    ),
    ParamSpec("frequency.f_step", 0.04, "frequency-domain method: grid step, Hz (at most 1000 frequencies)", 1e-6,
              1000.0),
    ParamSpec(
        "frequency.trim_span", 0.0,
        "frequency-domain method: the trim subtracted from every signal is the mean of the samples of this first "
        "span, s (steady flight before the excitation); 0: the first sample",
        0.0, 200.0,
    ),
    ParamSpec(
        "frequency.lag_span", 1.0,
        "frequency-domain method: time span of the residual autocorrelation kept in the corrected covariance, s "
        "(lags = lag_span x rate); 0 keeps R(0) only",
        0.0, 2000.0,
    ),
    ParamSpec(
        "frequency.every", 1,
        "frequency-domain method: estimates and standard errors computed and published every this many samples "
        "(the transform advances every sample)",
        1, 1000000,
    ),
    ParamSpec("differentiator.window", 9, "angular-acceleration differentiator window, samples", MIN_WINDOW,
              MAX_WINDOW),
    ParamSpec(
        "differentiator.order", 3,
        "local polynomial order of the differentiator (below differentiator.window; weights exact at every setting)",
        1, MAX_ORDER,
    ),
    ParamSpec(
        "differentiator.lag", 4,
        "differentiator fixed lag, samples (0 = causal); every signal is delayed by it",
        0, MAX_WINDOW - 1,
    ),
    ParamSpec(
        "inputs.use_dynamic_pressure", True,
        "use the dynamic_pressure topic; false computes 0.5 rho V^2 with inputs.air_density",
    ),
    ParamSpec(
        "inputs.air_density", 1.225,
        "air density for 0.5 rho V^2 when the dynamic pressure topic is not used, kg/m^3",
        0.01, 2.0,
    ),
    ParamSpec("inputs.use_thrust", True, "use the thrust topic (force.x, N) in Eq. 1a; false sets thrust to 0"),
    ParamSpec(
        "inputs.max_gap", 0.25,
        "largest gap between two messages of one stream that is interpolated across, s",
        0.001, 10.0,
    ),
    ParamSpec(
        "inputs.buffer_duration", 2.0,
        "how far a stream may run ahead of the slowest one before its old messages expire, s",
        0.1, 60.0,
    ),
    # Stream timelines: jumps of a stream's stamps, the
    # node's clock, and the count bound of the buffers (sampling.py's docstring has the policy).
    ParamSpec(
        "inputs.max_stamp_jump", 5.0,
        "a stamp this far behind a stream's newest, or this far ahead of it and of every stream, is a jump candidate: "
        "held until inputs.jump_confirmation more messages confirm a new timeline (a looped replay restarts), else "
        "rejected as stamp_jump, s",
        0.01, 1.0e9,
    ),
    ParamSpec(
        "inputs.jump_confirmation", 5,
        "messages after a jump candidate that must continue its stamps before the jump is taken as real (0: at once)",
        0, 1000,
    ),
    ParamSpec(
        "inputs.max_clock_offset", 0.0,
        "reject messages stamped farther than this from the node's clock as far_from_clock, s; 0 = off (replays "
        "played without /clock keep their recorded stamps)",
        0.0, 1.0e9,
    ),
    ParamSpec(
        "inputs.max_buffered", 20000,
        "messages buffered per stream at most (2 s at 10 kHz); beyond it the oldest expire",
        10, 10000000,
    ),
    # Input sanity: the body frame the inputs must be stamped in,
    # and what a measurement of an aircraft in flight can be (limits.PlausibilityLimits says
    # why each default is beyond any aircraft this package targets). A message out of bounds
    # is rejected as implausible_<field>; a sample (interpolated, or qbar from air density) too.
    ParamSpec(
        "inputs.frame_id", "base_link",
        "header.frame_id every input must carry (the REP-103 body frame); a message in another frame is "
        "rejected as frame_mismatch; empty: not checked",
    ),
    ParamSpec(
        "limits.airspeed_min", 3.0,
        "lowest plausible true airspeed, m/s (flow angles and p b/2V are noise below it); rejected as "
        "implausible_airspeed",
        0.1, 100.0,
    ),
    ParamSpec(
        "limits.airspeed_max", 400.0,
        "highest plausible true airspeed, m/s (supersonic at any altitude); rejected as implausible_airspeed",
        1.0, 3000.0,
    ),
    ParamSpec(
        "limits.alpha", 1.0,
        "largest plausible angle of attack, either sign, rad (57 deg; flying backwards is near 3.14); rejected as "
        "implausible_alpha",
        0.05, 1.5,
    ),
    ParamSpec(
        "limits.beta", 0.6,
        "largest plausible sideslip angle, either sign, rad (34 deg); rejected as implausible_beta",
        0.05, 1.5,
    ),
    ParamSpec(
        "limits.angular_rate", 20.0,
        "largest plausible body rate about any axis, rad/s (1150 deg/s); rejected as implausible_angular_rate",
        0.1, 100.0,
    ),
    ParamSpec(
        "limits.specific_force", 200.0,
        "largest plausible specific force along any axis, m/s^2 (20 g); rejected as "
        "implausible_specific_force",
        1.0, 2000.0,
    ),
    ParamSpec(
        "limits.surface", 1.0,
        "largest plausible deflection of a mixed control-surface joint, either sign, rad (57 deg); rejected as "
        "implausible_surface",
        0.01, 1.5,
    ),
    ParamSpec(
        "limits.dynamic_pressure_min", 5.0,
        "lowest plausible dynamic pressure, Pa (3 m/s at sea level; Eq. 1 divides by it); rejected as "
        "implausible_dynamic_pressure",
        0.01, 10000.0,
    ),
    ParamSpec(
        "limits.dynamic_pressure_max", 1.0e5,
        "highest plausible dynamic pressure, Pa (400 m/s at sea level); rejected as "
        "implausible_dynamic_pressure",
        1.0, 1.0e7,
    ),
    ParamSpec(
        "limits.thrust", 2.0e6,
        "largest plausible thrust, either sign (reverse thrust), N (above the largest aircraft's total "
        "thrust); rejected as implausible_thrust",
        1.0, 1.0e8,
    ),
    ParamSpec(
        "limits.air_density_min", 0.05,
        "lowest plausible air density 2 qbar/V^2 implied by the measured dynamic pressure and the true airspeed, "
        "kg/m^3 (the air at 21 km is 0.07); a sample below is rejected as inconsistent_dynamic_pressure",
        0.005, 10.0,
    ),
    ParamSpec(
        "limits.air_density_max", 2.0,
        "highest plausible air density 2 qbar/V^2 implied by the measured dynamic pressure and the true airspeed, "
        "kg/m^3 (-60 C at 1085 hPa is 1.77); a sample above is rejected as inconsistent_dynamic_pressure",
        0.01, 100.0,
    ),
    ParamSpec(
        "limits.angular_acceleration", 500.0,
        "largest plausible change of a body rate between consecutive imu messages over their interval, rad/s^2 "
        "(a gyro spike of 10 rad/s in one 50 Hz message is 500); rejected as implausible_angular_acceleration",
        1.0, 1.0e6,
    ),
    ParamSpec("surfaces.elevator", ["elevator"], "JointState names averaged into the elevator deflection (Eq. 23)"),
    ParamSpec(
        "surfaces.aileron_right", ["aileron_right"],
        "JointState names of right ailerons; delta_a = (right - left)/2 (Eq. 23)",
    ),
    ParamSpec("surfaces.aileron_left", ["aileron_left"], "JointState names of left ailerons"),
    ParamSpec(
        "surfaces.aileron_combined", "",
        "JointState name that already holds (right - left)/2; when set, aileron_right/left are ignored",
    ),
    ParamSpec("surfaces.rudder", ["rudder"], "JointState names averaged into the rudder deflection (Eq. 23)"),
    ParamSpec("topics.imu", "imu", "sensor_msgs/Imu topic, REP-103 body frame"),
    ParamSpec(
        "topics.airspeed", "airspeed",
        "geometry_msgs/Vector3Stamped true-airspeed vector topic, REP-103 body frame, m/s",
    ),
    ParamSpec("topics.dynamic_pressure", "dynamic_pressure", "sensor_msgs/FluidPressure dynamic pressure topic, Pa"),
    ParamSpec("topics.control_surfaces", "control_surfaces", "sensor_msgs/JointState surface deflection topic, rad"),
    ParamSpec("topics.thrust", "thrust", "geometry_msgs/WrenchStamped thrust topic (force.x, N)"),
    ParamSpec("qos.reliable", False, "reliable QoS for the inputs instead of sensor-data (best effort)"),
    ParamSpec("qos.depth", 100, "input and output queue depth", 1, 100000),
    ParamSpec("enabled", True, "estimate from start-up; the ~/enable service gates estimation to maneuvers"),
    ParamSpec(
        "state_file", "",
        "estimator state file: loaded at start-up when it exists and matches, saved on shutdown, disable and "
        "periodically",
    ),
    ParamSpec(
        "state_save_period", 10.0,
        "seconds between periodic state saves (0 = only on shutdown and disable)",
        0.0, 3600.0,
    ),
    ParamSpec("diagnostics_period", 1.0, "seconds between /diagnostics messages", 0.05, 60.0),
    ParamSpec("frame_id", "base_link", "frame_id of the ~/sample_stamp header"),
    # Outputs for consumers and long flights: convergence flags, full
    # covariances, and the window of the /diagnostics levels.
    ParamSpec("convergence.window", 2.0,
              "convergence flags (~/M/converged): seconds of history that must be settled; "
              "window x rate may not exceed 4094 samples", 0.05, 60.0),
    ParamSpec("convergence.band", 1.0,
              "convergence flags: every estimate of the window within this many current corrected standard errors "
              "of the current estimate", 0.01, 1e6),
    ParamSpec("convergence.max_se_rate", 0.25,
              "convergence flags: every standard error of the window within a factor exp(max_se_rate x age) of the "
              "current one, 1/s", 0.001, 100.0),
    ParamSpec("identifiability.max_correlation", 0.9998,
              "convergence flags: two parameters whose estimates are correlated beyond this (either sign, from the "
              "corrected covariance) are not identifiable and never flagged", 0.5, 0.999999),
    ParamSpec("identifiability.min_r_squared", 0.5,
              "convergence flags: a model whose R^2 is below this explains nothing; none of its parameters is "
              "flagged", 0.0, 0.99),
    ParamSpec("identifiability.angle_resolution", 1.0e-4,
              "convergence flags: a flow angle or surface regressor whose standard deviation since the start is at "
              "most this is not excited and its parameter never flagged, rad", 0.0, 0.1),
    ParamSpec("identifiability.rate_resolution", 1.0e-6,
              "the same for the nondimensional rates p b/2V, q cbar/2V, r b/2V", 0.0, 0.01),
    ParamSpec("outputs.covariance_decimation", 10,
              "publish ~/M/covariance and ~/M/covariance_conventional for samples whose grid index (stamp x rate) "
              "is a multiple of this; 0 = never", 0, 100000),
    ParamSpec("diagnostics_window", 10.0,
              "seconds over which /diagnostics levels count rejected, missing and expired messages (cumulative "
              "counts are reported beside)", 0.1, 3600.0),
)
PARAMETER_NAMES = {p.name: p for p in PARAMETERS}


def parameter_defaults() -> dict[str, Any]:
    return {p.name: (list(p.default) if isinstance(p.default, list) else p.default) for p in PARAMETERS}


def _check_value(spec: ParamSpec, value: Any) -> Any:
    """The value converted to the spec's type, or a :class:`ConfigError` saying why not."""
    d = spec.default
    where = f"parameter {spec.name!r}"
    if isinstance(d, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
    elif isinstance(d, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
    elif isinstance(d, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{where} must be a finite number, got {value!r}")
        value = float(value)
    elif isinstance(d, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
    elif isinstance(d, list):
        if value is None:
            value = []
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{where} must be a list of strings, got {value!r}")
        value = [v for v in value if v != ""]
    if spec.low is not None and not spec.low <= value <= spec.high:
        raise ConfigError(f"{where} must be in [{spec.low:g}, {spec.high:g}], got {value!r}")
    if spec.choices is not None and value not in spec.choices:
        raise ConfigError(f"{where} must be one of {list(spec.choices)}, got {value!r}")
    return value


def _validated(params: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(params) - set(PARAMETER_NAMES) - {"use_sim_time"})
    if unknown:
        raise ConfigError(f"unknown parameter(s) {unknown}{_suggestion(unknown[0])}")
    values = parameter_defaults()
    for name, value in params.items():
        if name in PARAMETER_NAMES:
            values[name] = _check_value(PARAMETER_NAMES[name], value)
    return values


def _finite(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


@dataclass(frozen=True)
class InputConfig:
    """How the input streams are used (``inputs.*`` parameters): the dynamic-pressure topic or
    ``0.5 air_density V^2`` (kg/m^3), the thrust topic or zero thrust, the longest gap
    interpolated across and how far a stream may run ahead before its old messages expire (s),
    the stream timelines (:mod:`.sampling`): the stamp jump (s) that needs
    ``jump_confirmation`` messages to be taken as a new timeline, the largest offset from the
    node's clock (s, 0 = not checked) and the most messages buffered per stream; and the
    ``header.frame_id`` every input must carry (empty: not checked)."""

    use_dynamic_pressure: bool = True
    air_density: float = 1.225
    use_thrust: bool = True
    max_gap: float = 0.25
    buffer_duration: float = 2.0
    # Stream timelines: jump threshold (s), confirmations, clock check (s, 0 = off), count bound.
    max_stamp_jump: float = 5.0
    jump_confirmation: int = 5
    max_clock_offset: float = 0.0
    max_buffered: int = 20000
    frame_id: str = "base_link"

    def __post_init__(self) -> None:
        for name in ("air_density", "max_gap", "buffer_duration", "max_stamp_jump"):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ConfigError(f"inputs.{name} must be a positive number, got {value!r}")
        if not (_finite(self.max_clock_offset) and self.max_clock_offset >= 0):
            raise ConfigError(f"inputs.max_clock_offset must be 0 (off) or positive, got {self.max_clock_offset!r}")
        for name, low in (("jump_confirmation", 0), ("max_buffered", 10)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
                raise ConfigError(f"inputs.{name} must be an integer >= {low}, got {value!r}")
        if self.max_stamp_jump < self.max_gap:
            raise ConfigError(f"inputs.max_stamp_jump ({self.max_stamp_jump} s) must be at least "
                              f"inputs.max_gap ({self.max_gap} s)")
        if not isinstance(self.frame_id, str):
            raise ConfigError(f"inputs.frame_id must be a string, got {self.frame_id!r}")

    @property
    def max_gap_ns(self) -> int:
        return int(round(self.max_gap * 1e9))

    @property
    def buffer_ns(self) -> int:
        return int(round(self.buffer_duration * 1e9))

    @property
    def max_stamp_jump_ns(self) -> int:
        return int(round(self.max_stamp_jump * 1e9))

    @property
    def max_clock_offset_ns(self) -> int:
        return int(round(self.max_clock_offset * 1e9))


@dataclass(frozen=True)
class OutputConfig:
    """What the pipeline computes for its consumers beyond estimates and standard errors
    (``outputs.*`` parameters): full covariance matrices for the samples whose grid index is a
    multiple of ``covariance_decimation`` (0: never)."""

    covariance_decimation: int = 10

    def __post_init__(self) -> None:
        d: Any = self.covariance_decimation
        if isinstance(d, bool) or not isinstance(d, Integral) or d < 0:
            raise ConfigError(f"outputs.covariance_decimation must be an integer >= 0, got {d!r}")


@dataclass(frozen=True)
class PipelineConfig:
    """Everything that decides the numbers: sample rate (Hz), aircraft, models, and the nested
    estimator, differentiator, input, surface-mixing and plausibility settings. The node and
    the offline replay build it the same way (:func:`pipeline_config`)."""

    aircraft: AircraftConfig
    models: tuple[ModelConfig, ...] = DEFAULT_MODELS
    rate: float = 50.0
    estimator: EstimatorOptions = field(default_factory=EstimatorOptions)
    differentiator: DifferentiatorConfig = DifferentiatorConfig()
    inputs: InputConfig = InputConfig()
    surfaces: SurfaceMixing = SurfaceMixing()
    limits: PlausibilityLimits = PlausibilityLimits()
    # Consumers' outputs (not part of the fingerprint: they do not change the estimator state).
    convergence: ConvergenceConfig = field(default_factory=ConvergenceConfig)
    identifiability: IdentifiabilityConfig = field(default_factory=IdentifiabilityConfig)
    outputs: OutputConfig = OutputConfig()
    # estimator.method and, unless it is "time", the frequency-domain estimator's options.
    method: str = "time"
    frequency: FrequencyOptions | None = None

    def __post_init__(self) -> None:
        if not (_finite(self.rate) and self.rate > 0):
            raise ConfigError(f"rate must be a positive number, got {self.rate!r}")
        self._check_method()
        held = math.ceil(self.convergence.window * self.rate) + 2
        if held > self.convergence.max_samples:
            raise ConfigError(
                f"convergence.window ({self.convergence.window:g} s) at rate {self.rate:g} Hz spans {held - 2} "
                f"samples; at most {self.convergence.max_samples - 2} are kept (shorten the window)"
            )
        if not self.models:
            raise ConfigError("at least one model must be enabled")
        outputs = [m.output for m in self.models]
        if len(set(outputs)) != len(outputs):
            raise ConfigError(f"a model is enabled twice: {outputs}")
        for m in self.models:
            for surface in SURFACES:
                if surface in m.regressors and not self.surfaces.names(surface):
                    raise ConfigError(
                        f"model {m.output} uses {surface} but no control surface is mapped to it "
                        "(surfaces.* parameters)"
                    )
        if self.inputs.max_gap * self.rate < 1.0:
            raise ConfigError(
                f"inputs.max_gap ({self.inputs.max_gap} s) is shorter than one estimator sample "
                f"(1/rate = {1 / self.rate:g} s)"
            )

    def _check_method(self) -> None:
        """``method`` and ``frequency`` agree, and every model has a parameter the frequency
        domain estimates, on a grid with more frequencies than parameters (F5)."""
        if self.method not in METHODS:
            raise ConfigError(f"estimator.method must be one of {list(METHODS)}, got {self.method!r}")
        if (self.method == "time") != (self.frequency is None):
            raise ConfigError(f"estimator.method {self.method} needs frequency options exactly when it is not 'time'")
        if self.frequency is None:
            return
        if self.frequency.rate_hz != self.rate:
            raise ConfigError(f"frequency options at {self.frequency.rate_hz} Hz for a pipeline at rate {self.rate} Hz")
        for m in self.models:
            if not m.frequency_parameter_names:
                raise ConfigError(f"model {m.output} has no regressor but the bias '1', which the frequency-domain "
                                  f"method does not estimate (estimator.method: {self.method}): give models."
                                  f"{m.output} a regressor, leave it out of models.enabled or use "
                                  "estimator.method: time")
        grid = self.frequency.frequencies().size
        most = max(len(m.frequency_parameter_names) for m in self.models)
        if grid <= most:
            raise ConfigError(f"the frequency grid (frequency.f_min .. f_max every f_step) has {grid} frequencies, a "
                              f"model {most} frequency-domain parameters: it needs more frequencies (lower "
                              "frequency.f_step or widen the band)")

    @property
    def publishes_time(self) -> bool:
        """``estimator.method`` publishes the time-domain estimates (``time``, ``both``)."""
        return self.method != "frequency"

    @property
    def published_methods(self) -> tuple[str, ...]:
        """The estimates ``estimator.method`` publishes: ``("time",)``, ``("frequency",)`` or both."""
        return ("time",) * self.publishes_time + ("frequency",) * (self.frequency is not None)

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.rate))

    def fingerprint(self) -> dict:
        """What a saved estimator state must match to be resumed."""
        return {
            "aircraft": [getattr(self.aircraft, f.name) for f in fields(AircraftConfig)],
            "models": [[m.output, *m.regressors] for m in self.models],
            "rate": self.rate,
            "estimator": self.estimator.resolved().as_dict(),
        }


@dataclass(frozen=True)
class NodeConfig:
    """ROS-only settings: topics, QoS, services' start state, state file, diagnostics."""

    topics: dict
    reliable: bool = False
    depth: int = 100
    enabled: bool = True
    state_file: str = ""
    state_save_period: float = 10.0
    diagnostics_period: float = 1.0
    frame_id: str = "base_link"
    diagnostics_window: float = 10.0


def pipeline_config(params: dict[str, Any] | None = None) -> PipelineConfig:
    """A :class:`PipelineConfig` from dotted parameters (ROS parameters or a flattened YAML);
    missing ones take their defaults. Raises :class:`ConfigError` naming the bad setting."""
    v = _validated(params or {})
    enabled = v["models.enabled"]
    bad = [m for m in enabled if m not in OUTPUTS]
    if bad:
        raise ConfigError(f"parameter 'models.enabled': unknown model(s) {bad}; known: {list(OUTPUTS)}")
    models = tuple(ModelConfig(out, tuple(v[f"models.{out}"])) for out in enabled)
    # Lists from YAML or ROS parameters become the tuples SurfaceMixing holds.
    surfaces: dict[str, Any] = {k: tuple(x) if isinstance(x, list) else x for k, x in _section(v, "surfaces").items()}
    return PipelineConfig(
        aircraft=load_aircraft(v["aircraft"]),
        models=models,
        rate=v["rate"],
        estimator=estimator_options(v),
        differentiator=DifferentiatorConfig(**_section(v, "differentiator")),
        inputs=InputConfig(**_section(v, "inputs")),
        surfaces=SurfaceMixing(**surfaces),
        limits=PlausibilityLimits(**_section(v, "limits")),
        convergence=ConvergenceConfig(**_section(v, "convergence")),  # rate_hz: the pipeline uses rate
        identifiability=IdentifiabilityConfig(**_section(v, "identifiability")),
        outputs=OutputConfig(**_section(v, "outputs")),
        method=v["estimator.method"],
        frequency=frequency_options(v),
    )


def _span_samples(name: str, span: float, rate: float, most: int) -> int:
    """``span`` seconds at ``rate`` Hz as a sample count, rounded (half up); a positive span of
    less than half a sample, or one of more than ``most`` samples, is refused naming ``name``."""
    n = math.floor(span * rate + 0.5)
    if n < 1:
        raise ConfigError(f"parameter {name!r} = {span:g} s is less than one sample at rate {rate:g} Hz "
                          f"({1 / rate:g} s); give at least {0.5 / rate:g} s, or 0")
    if n > most:
        raise ConfigError(f"parameter {name!r} = {span:g} s at rate {rate:g} Hz is {n} samples; at most {most} are "
                          f"held: shorten {name} or lower rate")
    return n


def _lag_count(values: dict[str, Any]) -> Lags:
    """``estimator.lag_span`` as the estimator's ``lags``: -1 all, 0 none, else seconds x rate."""
    span = values["estimator.lag_span"]
    if span == -1.0:
        return "all"
    if span == 0.0:
        return 0
    if span < 0:
        raise ConfigError(f"parameter 'estimator.lag_span' must be -1 (all lags), 0 (the conventional covariance) or "
                          f"a positive number of seconds, got {span!r}")
    return _span_samples("estimator.lag_span", span, values["rate"], MAX_LAGS)


def estimator_options(values: dict[str, Any]) -> EstimatorOptions:
    """The ``estimator.*`` parameters as :class:`.estimator.EstimatorOptions`. The lag window
    follows time, not samples (``docs/estimator.md``): ``estimator.lag_span`` seconds are
    ``lags = lag_span x rate`` (-1: ``"all"``, 0: none), ``estimator.max_lag_span`` the
    ``max_lags`` of ``estimator.lag_selection: auto`` (``lags="auto"``), and
    ``estimator.residual_burn_in_span`` the ``residual_burn_in`` (-1: ``AUTO_BURN_IN_SPAN`` s
    with auto, 0 with fixed lags); ``window``, ``forgetting`` and ``residual`` as they are.
    Raises :class:`ConfigError` naming the parameter."""
    rate = values["rate"]
    auto = values["estimator.lag_selection"] == "auto"
    burn_in = values["estimator.residual_burn_in_span"]
    if burn_in == -1.0:
        burn_in = AUTO_BURN_IN_SPAN if auto else 0.0
    elif burn_in < 0:
        raise ConfigError(f"parameter 'estimator.residual_burn_in_span' must be -1 (the default) or a number of "
                          f"seconds >= 0, got {burn_in!r}")
    return EstimatorOptions(
        lags="auto" if auto else _lag_count(values),
        window=values["estimator.window"],
        forgetting=values["estimator.forgetting"],
        residual=values["estimator.residual"],
        max_lags=_span_samples("estimator.max_lag_span", values["estimator.max_lag_span"], rate, MAX_LAGS),
        residual_burn_in=_span_samples("estimator.residual_burn_in_span", burn_in, rate, MAX_BURN_IN) if burn_in else 0,
    )


def frequency_options(values: dict[str, Any]) -> FrequencyOptions | None:
    """The ``frequency.*`` parameters as :class:`.frequency.FrequencyOptions`, or None when
    ``estimator.method`` is ``time`` (then they are not used, and a grid the rate cannot carry
    is not refused). The spans follow time: ``frequency.trim_span`` seconds are the
    ``trim_samples`` averaged as trim (0: the first sample), ``frequency.lag_span`` the
    ``n_lags`` (0: none); the grid is in Hz, ``frequency.every`` in samples. Raises
    :class:`ConfigError` naming the parameter."""
    if values["estimator.method"] == "time":
        return None
    rate = values["rate"]
    trim, lags = values["frequency.trim_span"], values["frequency.lag_span"]
    return FrequencyOptions(
        rate_hz=rate,
        f_min=values["frequency.f_min"],
        f_max=values["frequency.f_max"],
        f_step=values["frequency.f_step"],
        trim_samples=_span_samples("frequency.trim_span", trim, rate, MAX_TRIM) if trim else 1,
        n_lags=_span_samples("frequency.lag_span", lags, rate, FREQUENCY_MAX_LAGS) if lags else 0,
        every=values["frequency.every"],
    )


def _section(values: dict[str, Any], prefix: str) -> dict[str, Any]:
    """The ``prefix.*`` parameters by their name in the section (the dataclass field names)."""
    return {k.split(".", 1)[1]: x for k, x in values.items() if k.startswith(prefix + ".")}


def node_config(params: dict[str, Any] | None = None) -> NodeConfig:
    v = _validated(params or {})
    return NodeConfig(
        topics=_section(v, "topics"),
        reliable=v["qos.reliable"],
        depth=v["qos.depth"],
        enabled=v["enabled"],
        state_file=v["state_file"],
        state_save_period=v["state_save_period"],
        diagnostics_period=v["diagnostics_period"],
        frame_id=v["frame_id"],
        diagnostics_window=v["diagnostics_window"],
    )


# ---------------------------------------------------------------------------------------------
# The node's parameters from its ROS sources (``-p`` rules and parameter files, read as rcl reads
# them by :mod:`.ros_arguments`): the policy of the module docstring.

# The node's name: its parameter sections, its private topics (/rls_estimator/..., see outputs) and
# its diagnostics ("rls_estimator: ...").
NODE_NAME = "rls_estimator"
# Parameters of every ROS 2 node (rclpy declares them), accepted beside the table's.
ROS_PARAMETERS = {"use_sim_time": False, "start_type_description_service": True}
_ROS_PREFIXES = ("qos_overrides.",)
_GROUPS = frozenset(p.name.split(".", 1)[0] for p in PARAMETERS if "." in p.name)


@dataclass(frozen=True)
class NodeParameters:
    """The node's parameter values from its sources (dotted name -> value as given, the ROS
    parameters of every node included), where each came from, and the warnings to log."""

    values: dict[str, Any]
    origins: dict[str, str]
    warnings: tuple[str, ...]


def _suggestion(name: str) -> str:
    if name in RENAMED:
        return f" (renamed: {RENAMED[name]})"
    close = difflib.get_close_matches(name, [*PARAMETER_NAMES, *ROS_PARAMETERS], n=1, cutoff=0.75)
    return f" (did you mean {close[0]}?)" if close else ""


def _ours(name: str) -> bool:
    """A name that can only be meant for this node: in one of its groups, or close to one of its names."""
    return name.split(".", 1)[0] in _GROUPS or bool(_suggestion(name))


def _known(name: str) -> bool:
    return name in PARAMETER_NAMES or name in ROS_PARAMETERS or name.startswith(_ROS_PREFIXES)


def _applies(node_name: str, fqn: str | None) -> Callable[[str], bool]:
    """Whether a node pattern applies to the node ``fqn`` (None: ``node_name`` in any namespace)."""
    if fqn is not None:
        return lambda pattern: pattern_matches(pattern, fqn)
    return lambda pattern: pattern.rsplit("/", 1)[-1] in (node_name, "*", "**")


def _source_notes(source: ParameterFile | ParameterRule, node_name: str, applies: Callable[[str], bool],
                  shown: str) -> list[str]:
    """The warnings about a source's parts for other nodes; a file with no part for the node
    (``shown``) is a :class:`ConfigError`."""
    if isinstance(source, ParameterRule):
        return [] if applies(source.pattern) else [f"{source.text}: for node {source.pattern}, not {shown}: ignored"]
    if not any(applies(s.pattern) for s in source.sections):
        keys = [s.key for s in source.sections]
        close = difflib.get_close_matches(node_name, [s.node_name for s in source.sections], n=1, cutoff=0.6)
        hint = f"; did you mean {node_name}?" if close else ""
        held = f"it has sections for {', '.join(keys)}{hint}" if keys else "it has no 'NODE: ros__parameters:' section"
        raise ConfigError(f"parameter file {source.path}: no section for node {shown} ({held}); name the node "
                          f"({node_name}, /NAMESPACE/{node_name}) or use a wildcard (/**)")
    others = [s.key for s in source.sections if not applies(s.pattern)]
    return [f"parameter file {source.path}: sections for other nodes ignored: {', '.join(others)}"] if others else []


def _checked(values: dict[str, Any], origins: dict[str, str]) -> dict[str, Any]:
    """Each value converted to its parameter's type, or a :class:`ConfigError` naming where it came from."""
    out = {}
    for name, given in values.items():
        spec = PARAMETER_NAMES.get(name)
        try:
            if spec is not None:
                out[name] = _check_value(spec, given)
            elif name in ROS_PARAMETERS and not isinstance(given, bool):
                raise ConfigError(f"parameter {name!r} must be true or false, got {given!r}")
            else:
                out[name] = given
        except ConfigError as exc:
            raise ConfigError(f"{exc} (from {origins[name]})") from exc
    return out


def node_parameters(sources: Sequence[ParameterFile | ParameterRule], node_name: str = NODE_NAME,
                    fqn: str | None = None) -> NodeParameters:
    """The values the sources give the node ``fqn`` (``None``: named ``node_name`` in any
    namespace), in rcl's order (:func:`.ros_arguments.in_rcl_order`), checked against
    :data:`PARAMETERS` by the policy of the module docstring; a refusal is a
    :class:`ConfigError` naming the source."""
    applies = _applies(node_name, fqn)
    notes = [note for source in sources for note in _source_notes(source, node_name, applies, fqn or node_name)]
    values: dict[str, Any] = {}
    origins: dict[str, str] = {}
    unknown: dict[str, list[str]] = {}
    for a in in_rcl_order(sources, applies):
        if _known(a.name):
            values[a.name], origins[a.name] = a.value, a.origin
        elif a.exact or _ours(a.name):
            raise ConfigError(f"{a.origin}: unknown parameter {a.name!r}{_suggestion(a.name)}")
        else:  # in a wildcard section of a file
            unknown.setdefault(a.source, []).append(a.name)
    notes += [f"{where}: parameters that are not this node's ignored (meant for other nodes?): {', '.join(names)}"
              for where, names in unknown.items()]
    return NodeParameters(_checked(values, origins), origins, tuple(notes))


def _parameter_file_path(path_or_name: str | Path) -> Path:
    path = Path(path_or_name)
    return path if path.suffix else config_dir() / f"{path_or_name}.yaml"


def node_parameters_file(path_or_name: str | Path, node_name: str = NODE_NAME) -> NodeParameters:
    """The node's parameters from a ROS 2 parameter file (``NODE: ros__parameters: ...``, the
    file the node takes with ``--params-file``), or by name from ``config/NAME.yaml``, read as
    the node reads it (:func:`node_parameters`) for ``node_name`` in any namespace."""
    return node_parameters([read_parameter_file(_parameter_file_path(path_or_name))], node_name)


def load_parameters_file(path_or_name: str | Path, node_name: str = NODE_NAME) -> dict[str, Any]:
    """The dotted pipeline and node parameters of :func:`node_parameters_file` (its warnings
    issued as :class:`UserWarning`)."""
    params = node_parameters_file(path_or_name, node_name)
    for note in params.warnings:
        warnings.warn(note, stacklevel=2)
    return {k: v for k, v in params.values.items() if k in PARAMETER_NAMES}


def startup_parameters(argv: Sequence[str], node_name: str = NODE_NAME) -> NodeParameters:
    """The node's parameters from its command line (``argv`` as ``rclpy.init`` takes it), every
    one checked and the whole configuration built once (the aircraft file read), before rcl
    sees them. Arguments outside ``--ros-args`` (the program's path first) are refused: the
    node takes none of its own."""
    args = parse_ros_arguments(argv, node_name)
    others = list(args.other_arguments)
    if others and argv and argv[0] == others[0]:
        others.pop(0)  # the program
    if others:
        raise ConfigError(f"unexpected argument(s) {' '.join(others)}: the node takes ROS arguments only, after "
                          "--ros-args (e.g. --ros-args -p rate:=100.0 --params-file config/t2.yaml)")
    params = node_parameters(args.sources, args.node_name, args.fqn)
    ours = {k: v for k, v in params.values.items() if k in PARAMETER_NAMES}
    pipeline_config(ours)
    node_config(ours)
    return params
