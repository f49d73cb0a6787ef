"""Every setting, defined once, and where the node's come from; read without rclpy.

- :mod:`.models`: the aircraft and model files (the classes are :mod:`rls_uncertainty.aero.models`'s).
- :mod:`.config`: the node's own options, :class:`NodeConfig` (the pipeline's, :class:`PipelineConfig`,
  are :mod:`rls_uncertainty.datapath.config`'s).
- :mod:`.parameters`: the node's parameters, generated from the options classes' fields
  (:mod:`rls_uncertainty.schema`), and back into the options (:func:`pipeline_config`).
- :mod:`.sources`: where the node's parameters come from (``--ros-args``, parameter files) and
  what is refused; :mod:`.ros_arguments` reads them as rcl does.
- :mod:`.yaml_files`: the package's one YAML reader and its error policy.

The names below are the public face; each is defined in one of those modules. Imports the
numerical core's options classes and the standard library, numpy and yaml.
"""

from ..aero.models import DEFAULT_MODELS, REGRESSOR_UNITS, REGRESSORS, AircraftConfig, ModelConfig
from ..datapath.config import InputConfig, OutputConfig, PipelineConfig
from .config import NODE_NAME, InputTopics, NodeConfig
from .models import config_dir, load_aircraft, load_models, package_path
from .parameters import PARAMETERS, Parameter, node_config, parameter_defaults, pipeline_config
from .sources import NodeParameters, load_parameters_file, node_parameters_file, startup_parameters

__all__ = [
    "NODE_NAME",
    "InputConfig",
    "InputTopics",
    "NodeConfig",
    "OutputConfig",
    "PipelineConfig",
    "DEFAULT_MODELS",
    "REGRESSORS",
    "REGRESSOR_UNITS",
    "package_path",
    "AircraftConfig",
    "ModelConfig",
    "config_dir",
    "load_aircraft",
    "load_models",
    "PARAMETERS",
    "Parameter",
    "node_config",
    "parameter_defaults",
    "pipeline_config",
    "NodeParameters",
    "load_parameters_file",
    "node_parameters_file",
    "startup_parameters",
]
