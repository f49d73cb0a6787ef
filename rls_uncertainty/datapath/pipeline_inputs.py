"""The pipeline's input methods, one per input stream (numpy only): each message is judged by
the pipeline's :class:`.intake.Intake` and, when it may complete samples, they are formed
(:meth:`.pipeline.Pipeline._advance`). :class:`.pipeline.Pipeline` is a :class:`PipelineInputs`."""

from __future__ import annotations

from collections.abc import Sequence

from .intake import Intake
from .sample_output import SampleOutput
from .sampling import Sampler

__all__ = ["PipelineInputs"]


class PipelineInputs:
    """``add_*`` and ``reject*``: plain stamped numbers in the REP-103 body frame and SI."""

    intake: Intake
    sampler: Sampler

    def _advance(self) -> list[SampleOutput]:
        raise NotImplementedError

    def add_imu(self, stamp_ns: int, angular_velocity: Sequence[float],
                linear_acceleration: Sequence[float]) -> list[SampleOutput]:
        """``sensor_msgs/Imu`` in the REP-103 body frame: rad/s and specific force m/s^2."""
        return self._advance() if self.intake.imu(stamp_ns, angular_velocity, linear_acceleration) else []

    def add_airspeed(self, stamp_ns: int, velocity: Sequence[float]) -> list[SampleOutput]:
        """True-airspeed vector in the REP-103 body frame, m/s."""
        return self._advance() if self.intake.airspeed(stamp_ns, velocity) else []

    def add_dynamic_pressure(self, stamp_ns: int, pascal: float) -> list[SampleOutput]:
        return self._advance() if self.intake.dynamic_pressure(stamp_ns, pascal) else []

    def add_thrust(self, stamp_ns: int, force_x: float) -> list[SampleOutput]:
        return self._advance() if self.intake.thrust(stamp_ns, force_x) else []

    def add_excitation(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> list[SampleOutput]:
        """The injected excitation, a ``sensor_msgs/JointState`` like the surfaces (rad)."""
        return self._advance() if self.intake.excitation(stamp_ns, names, positions) else []

    def add_surfaces(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> list[SampleOutput]:
        """``sensor_msgs/JointState`` names and positions (rad), mixed by Eq. 23."""
        return self._advance() if self.intake.surfaces(stamp_ns, names, positions) else []

    def reject_frame(self, stream: str, stamp_ns: int, frame_id: str = "") -> list[SampleOutput]:
        """Count a message of input ``stream`` whose ``header.frame_id`` (``frame_id``) is not
        ``inputs.frame_id`` (:func:`.inputs.feed` checks): rejected as ``frame_mismatch``,
        never used, and like any invalid message it leaves a hole: no sample is interpolated
        across it."""
        return self._advance() if self.intake.frame_mismatch(stream, stamp_ns, frame_id) else []

    def reject(self, stream: str, reason: str, detail: str = "") -> None:
        """Count a message of input ``stream`` that never reached the pipeline's ``add_*``
        (the node could not decode it; ``detail``: why, kept as evidence)."""
        self.intake.undecodable(stream, reason, detail)

    def reject_invalid(self, stream: str, stamp_ns: int, reason: str) -> list[SampleOutput]:
        """Count a message of input ``stream`` stamped ``stamp_ns`` whose values cannot be
        used (``reason``): no sample is formed across it (:meth:`.sampling.Sampler.reject_invalid`)."""
        return self._advance() if self.intake.invalid(stream, stamp_ns, reason) else []

    @property
    def clock_ns(self) -> int | None:
        """The caller's clock (ns) that stamps are checked against (``inputs.max_clock_offset``)."""
        return self.sampler.clock_ns

    @clock_ns.setter
    def clock_ns(self, now: int | None) -> None:
        self.sampler.clock_ns = now
