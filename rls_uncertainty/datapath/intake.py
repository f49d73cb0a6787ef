"""Each input message judged on its own, then handed to the sampler (pure Python).

:class:`Intake` is the message side of a :class:`.pipeline.Pipeline`: it takes plain stamped
numbers in the REP-103 body frame and SI, checks them against the ``limits.*`` parameters
(:class:`.limits.PlausibilityLimits`), mixes JointState surfaces into Eq. 23's deflections
(:mod:`.surface_mixing`) and hands the result to the :class:`.sampling.Sampler`, which counts
every message as accepted or rejected with its reason. A message refused for its content (a
non-finite or implausible value, a JointState that cannot be mixed, another frame than
``inputs.frame_id``) leaves a hole at its stamp: no sample is interpolated across it. What
the newest refused message of each kind carried is kept as evidence
(:meth:`.bookkeeping.Bookkeeping.note`) for the misconfiguration reports of :mod:`.alerts`.

An IMU message is also judged against the one before it: a body rate that changed faster than
``limits.angular_acceleration`` allows since the previous IMU message passed on (a gyro spike)
is rejected as ``implausible_angular_acceleration``
(:meth:`.limits.PlausibilityLimits.rate_change_rejection`; :mod:`.limits` says why on the
messages). The previous message is the newest one passed to the sampler; a refused message
does not replace it, so the message after a spike is judged against the one before the spike.
Messages more than ``inputs.max_gap`` after it, or stamped before it (a new timeline), are not
compared and become the new reference: a stream that really moved is accepted again after at
most ``inputs.max_gap``.

Every method returns whether samples may be due (:meth:`.sampling.Sampler.due`); the pipeline
then forms them.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..aero.surface_mixing import MISMATCHED, MISSING, SurfaceMixer, SurfaceMixing
from ..errors import Refused
from .bookkeeping import EVIDENCE_ITEMS, KEY_CHARS, Bookkeeping
from .limits import PlausibilityLimits
from .sampling import Sampler
from .streams import Stream

__all__ = ["Intake"]


def _names(names: Sequence[str]) -> tuple[tuple[str, ...], int]:
    """A JointState's names as evidence: the first few, cut, and how many there were (with
    the number of positions and the ``surfaces.*`` fields whose joints are missing, the
    evidence of ``missing_joint`` and ``mismatched_arrays``)."""
    return tuple(str(n)[:KEY_CHARS] for n in names[:EVIDENCE_ITEMS]), len(names)


class Intake:
    """The input messages of one pipeline: judged against ``limits``, surfaces mixed by
    ``surfaces``, then buffered by ``sampler``; every refusal counted in ``book``."""

    def __init__(self, sampler: Sampler, limits: PlausibilityLimits, surfaces: SurfaceMixing,
                 book: Bookkeeping) -> None:
        self.sampler = sampler
        self.limits = limits
        self.book = book
        self._mixer = SurfaceMixer(surfaces)
        streams = sampler.streams
        self._imu, self._airspeed, self._surfaces = streams["imu"], streams["airspeed"], streams["control_surfaces"]
        self._qbar, self._thrust = streams["dynamic_pressure"], streams["thrust"]
        self._excitation = streams["excitation"]
        self._max_gap_ns = sampler.max_gap_ns
        self._rates: tuple[int, float, float, float] | None = None  # the previous IMU message: stamp, rates

    def imu(self, stamp_ns: int, angular_velocity: Sequence[float], linear_acceleration: Sequence[float]) -> bool:
        """``sensor_msgs/Imu``: body rates (rad/s) and specific force (m/s^2)."""
        wx, wy, wz = angular_velocity
        fx, fy, fz = linear_acceleration
        values = (wx, wy, wz, fx, fy, fz)
        reason = self.limits.imu_rejection(angular_velocity, linear_acceleration)
        if reason is not None:
            return self._invalid(self._imu, stamp_ns, values, reason)
        stamp_ns = int(stamp_ns)
        previous = self._rates
        if previous is not None:
            dt_ns = stamp_ns - previous[0]
            if dt_ns == 0:  # a duplicate stamp (the sampler refuses it): the reference stays
                return self.sampler.add(self._imu, stamp_ns, values)
            if 0 < dt_ns <= self._max_gap_ns:
                change = (wx - previous[1], wy - previous[2], wz - previous[3])
                reason = self.limits.rate_change_rejection(dt_ns * 1e-9, change)
                if reason is not None:
                    return self._invalid(self._imu, stamp_ns, (dt_ns * 1e-9, *change), reason)
        self._rates = (stamp_ns, wx, wy, wz)
        return self.sampler.add(self._imu, stamp_ns, values)

    def airspeed(self, stamp_ns: int, velocity: Sequence[float]) -> bool:
        """True-airspeed vector, m/s."""
        vx, vy, vz = velocity
        reason = self.limits.airspeed_rejection(velocity)
        if reason is not None:
            return self._invalid(self._airspeed, stamp_ns, (vx, vy, vz), reason)
        return self.sampler.add(self._airspeed, int(stamp_ns), (vx, vy, vz))

    def dynamic_pressure(self, stamp_ns: int, pascal: float) -> bool:
        reason = self.limits.dynamic_pressure_rejection(pascal)
        if reason is not None:
            return self._invalid(self._qbar, stamp_ns, (pascal,), reason)
        return self.sampler.add(self._qbar, int(stamp_ns), (pascal,))

    def thrust(self, stamp_ns: int, force_x: float) -> bool:
        reason = self.limits.thrust_rejection(force_x)
        if reason is not None:
            return self._invalid(self._thrust, stamp_ns, (force_x,), reason)
        return self.sampler.add(self._thrust, int(stamp_ns), (force_x,))

    def surfaces(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> bool:
        """``sensor_msgs/JointState`` names and positions (rad), mixed by Eq. 23."""
        return self._joints(self._surfaces, stamp_ns, names, positions)

    def excitation(self, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> bool:
        """The injected excitation: a ``sensor_msgs/JointState`` of the same joints as the
        surfaces, mixed by Eq. 23 the same way, judged by the same limits."""
        return self._joints(self._excitation, stamp_ns, names, positions)

    def _joints(self, stream: Stream, stamp_ns: int, names: Sequence[str], positions: Sequence[float]) -> bool:
        layout = self._mixer.layout(names) if len(positions) == len(names) else MISMATCHED
        if isinstance(layout, Refused):  # unusable at its stamp, like any invalid message: a hole
            missing = tuple(self._mixer.mixing.missing(names)) if layout == MISSING else ()
            self.book.note(stream.name, layout.reason, (*_names(names), len(positions), missing))
            return self._reject(stream, stamp_ns, layout.reason)
        unknown = self.book.unknown_joints
        for n in layout.unknown:
            unknown.count(n)
        used = [positions[i] for i in layout.used]
        reason = self.limits.surface_rejection(used)
        if reason is not None:
            return self._invalid(stream, stamp_ns, tuple(used), reason)
        de, da, dr = layout.deflections(positions)
        return self.sampler.add(stream, int(stamp_ns), (de, da, dr))

    def _invalid(self, stream: Stream, stamp_ns: int, values: tuple, reason: str) -> bool:
        """A message whose values are refused: ``non_finite`` goes to the sampler as a value
        hole, the other reasons are rejected at the message's stamp; either way it is a hole
        (:mod:`.sampling`), and its values are the evidence (of ``implausible_angular_acceleration``:
        the interval and the rates' changes, :func:`.limits.message_value`)."""
        self.book.note(stream.name, reason, values)
        if reason == "non_finite":
            return self.sampler.add(stream, int(stamp_ns), values, False)
        return self._reject(stream, stamp_ns, reason)

    def _reject(self, stream: Stream, stamp_ns: int, reason: str) -> bool:
        return self.sampler.reject_invalid(stream, int(stamp_ns), reason)

    def frame_mismatch(self, stream: str, stamp_ns: int, frame_id: str) -> bool:
        """A message in frame ``frame_id``, not ``inputs.frame_id``: its numbers are in a frame
        the pipeline cannot convert, so it is rejected as ``frame_mismatch`` (a hole)."""
        self.book.note(stream, "frame_mismatch", str(frame_id)[:KEY_CHARS])
        return self._reject(self.sampler.streams[stream], stamp_ns, "frame_mismatch")

    def invalid(self, stream: str, stamp_ns: int, reason: str) -> bool:
        """A message of ``stream`` stamped ``stamp_ns`` whose values the caller found unusable
        (``reason``): no sample is formed across it."""
        return self._reject(self.sampler.streams[stream], stamp_ns, reason)

    def undecodable(self, stream: str, reason: str, detail: str = "") -> None:
        """A message of ``stream`` that has no stamp (it could not be decoded). Reasons are
        the caller's: a stream keeps at most :data:`.bookkeeping.KEYS_KEPT` distinct ones,
        later new ones count as :data:`.bookkeeping.OTHER_REASONS`."""
        reason = self.sampler.reject(self.sampler.streams[stream], reason)
        if detail:
            self.book.note(stream, reason, detail[:2 * KEY_CHARS])
