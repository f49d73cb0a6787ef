"""The node's own configuration, beside the pipeline's (:mod:`rls_uncertainty.datapath.config`):
frozen dataclasses, each checking its own fields when it is built. :class:`NodeConfig` holds what
only the ROS node uses, :class:`InputTopics` its input topics. Every field is a
:func:`rls_uncertainty.schema.option`: its default, bounds, unit, meaning and node parameter are
written there and nowhere else. The node's parameters become these objects in
:mod:`.parameters`; where the parameters come from is :mod:`.sources`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields

from ..datapath.outputs import NODE_NAME
from ..errors import ConfigError
from ..schema import check, option

__all__ = [
    "NODE_NAME",
    "DEFAULT_INTAKE_PERIOD",
    "MIN_INTAKE_PERIOD",
    "InputTopics",
    "NodeConfig",
    "intake_period",
]

# intake_period 0: the inputs are taken each estimator period, at most this often apart (s).
DEFAULT_INTAKE_PERIOD = 0.005
# The shortest intake period that may be given (s): each wake of the timer costs CPU of its own.
MIN_INTAKE_PERIOD = 0.001



@dataclass(frozen=True, eq=False)
class InputTopics(Mapping[str, str]):
    """The topic of each input stream (``topics.*``; relative names resolve in the node's
    namespace), a mapping from the stream to its topic (equal to any mapping of the same
    items, as a dict is)."""

    imu: str = option("imu", "sensor_msgs/Imu topic, REP-103 body frame", ros="topics.imu", read_only=True)
    airspeed: str = option("airspeed", "geometry_msgs/Vector3Stamped true-airspeed vector topic, REP-103 body frame, "
                           "m/s", ros="topics.airspeed", read_only=True)
    dynamic_pressure: str = option("dynamic_pressure", "sensor_msgs/FluidPressure dynamic pressure topic, Pa",
                                   ros="topics.dynamic_pressure", read_only=True)
    control_surfaces: str = option("control_surfaces", "sensor_msgs/JointState surface deflection topic, rad",
                                   ros="topics.control_surfaces", read_only=True)
    thrust: str = option("thrust", "geometry_msgs/WrenchStamped thrust topic (force.x, N)", ros="topics.thrust",
                         read_only=True)
    excitation: str = option("excitation", "sensor_msgs/JointState topic of the injected excitation (the designed "
                             "input on each surface, rad, before any feedback): the instruments of "
                             "estimator.algorithm iv with instruments.source excitation", ros="topics.excitation",
                             read_only=True)

    def __post_init__(self) -> None:
        check(self, "topics")

    def __getitem__(self, stream: str) -> str:
        if stream not in self._names():
            raise KeyError(stream)
        return str(getattr(self, stream))

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())

    def __hash__(self) -> int:
        return hash(tuple(self.items()))

    @classmethod
    def _names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))


@dataclass(frozen=True)
class NodeConfig:
    """ROS-only settings: topics, QoS, the services' start state, state file, diagnostics."""

    topics: InputTopics = field(default_factory=InputTopics)
    reliable: bool = option(False, "reliable QoS for the inputs instead of sensor-data (best effort)",
                            ros="qos.reliable", read_only=True)
    depth: int = option(100, "input and output queue depth", low=1, high=100_000, ros="qos.depth", read_only=True)
    enabled: bool = option(True, "estimate from start-up; the ~/enable service gates estimation to maneuvers",
                           ros="enabled")
    state_file: str = option("", "estimator state file: loaded at start-up when it exists and matches, saved on "
                             "shutdown, disable and periodically", ros="state_file", read_only=True)
    state_save_period: float = option(10.0, "seconds between periodic state saves (0 = only on shutdown and "
                                      "disable)", unit="s", low=0.0, high=3600.0, ros="state_save_period")
    diagnostics_period: float = option(1.0, "seconds between /diagnostics messages", unit="s", low=0.05, high=60.0,
                                       ros="diagnostics_period")
    frame_id: str = option("base_link", "frame_id of the ~/sample_stamp header", ros="frame_id")
    shed_load: bool = option(True, "while the node cannot keep up with its inputs, space out frequency-domain "
                             "evaluations, then published covariances (each step logged; restored once it keeps up)",
                             ros="shed_load")
    diagnostics_window: float = option(10.0, "seconds over which /diagnostics levels count rejected, missing and "
                                       "expired messages (cumulative counts are reported beside)", unit="s",
                                       low=0.1, high=3600.0, ros="diagnostics_window")
    intake_period: float = option(0.0, "the longest an input message waits before it is fed: the node takes its "
                                  "inputs in batches this often, at most the estimator period (1 / rate); "
                                  "longer saves CPU, shorter cuts latency. 0: the estimator period, at most "
                                  f"{DEFAULT_INTAKE_PERIOD * 1e3:g} ms; otherwise at least "
                                  f"{MIN_INTAKE_PERIOD * 1e3:g} ms", unit="s", low=0.0, high=0.05,
                                  ros="intake_period")

    def __post_init__(self) -> None:
        check(self, "")
        if 0.0 < self.intake_period < MIN_INTAKE_PERIOD:
            raise ConfigError(f"intake_period must be 0 (the default) or at least {MIN_INTAKE_PERIOD:g} s, got "
                              f"{self.intake_period!r}", parameter="intake_period")

    def check_rate(self, rate: float) -> None:
        """Refuse an intake period longer than the estimator period at ``rate`` Hz, naming
        ``intake_period``: a sample would wait for the next batch, and more than a period's
        inputs would be fed in one pass."""
        if self.intake_period > 1.0 / rate:
            raise ConfigError(f"intake_period {self.intake_period:g} s is longer than the estimator period at rate "
                              f"{rate:g} Hz ({1.0 / rate:g} s): give at most that, or 0 (the estimator period, at "
                              f"most {DEFAULT_INTAKE_PERIOD:g} s)", parameter="intake_period")


def intake_period(setting: float, rate: float) -> float:
    """Seconds between two takes of the inputs (the longest a message waits before it is
    fed): ``setting`` (the ``intake_period`` parameter), or with 0 the estimator period at
    ``rate`` Hz, at most :data:`DEFAULT_INTAKE_PERIOD`."""
    return setting if setting > 0 else min(1.0 / rate, DEFAULT_INTAKE_PERIOD)
