"""Each input message judged on its own and against the previous IMU message
(rls_uncertainty.datapath.intake): a body rate that changes faster than limits.angular_acceleration
allows is a gyro spike, refused with its reason and evidence, and the stream goes on against
the message before it. Pure Python: the intake, a sampler and the bookkeeping, no pipeline."""

import math

import numpy as np
import pytest

from rls_uncertainty.aero.surface_mixing import SurfaceMixing
from rls_uncertainty.datapath.bookkeeping import Bookkeeping
from rls_uncertainty.datapath.intake import Intake
from rls_uncertainty.datapath.limits import PlausibilityLimits, message_value
from rls_uncertainty.datapath.pipeline import STREAMS
from rls_uncertainty.datapath.sampling import Sampler

MS = 1_000_000
DT = 20 * MS  # a 50 Hz IMU
MAX_GAP = 250 * MS  # inputs.max_gap's default
LIMITS = PlausibilityLimits()  # angular_acceleration 500 rad/s^2: 10 rad/s per 20 ms


class RecordingSampler(Sampler):
    """A sampler that keeps the pitch rate of every message it accepts."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.accepted = []

    def add(self, stream, stamp, values, finite=True):
        before = sum(stream.counts.rejected.values())
        due = super().add(stream, stamp, values, finite)
        if finite and sum(stream.counts.rejected.values()) == before:
            self.accepted.append(values[1])
        return due


def intake(limits=LIMITS):
    book = Bookkeeping.for_streams(STREAMS)
    sampler = RecordingSampler(STREAMS, ("imu",), period_ns=DT, max_gap_ns=MAX_GAP, buffer_ns=2000 * MS,
                               counts=book.streams)
    return Intake(sampler, limits, SurfaceMixing(), book)


def feed(it, stamps_ns, pitch_rates):
    for t, q in zip(stamps_ns, pitch_rates, strict=True):
        it.imu(int(t), (0.01, q, -0.02), (0.3, 0.0, 9.8))
    return it.book.streams["imu"]


def accepted_rates(it):
    """The pitch rates of the messages the sampler accepted, in order."""
    return it.sampler.accepted


def smooth(n):
    """A pitch rate of 0.3 sin(2 pi t) rad/s at 50 Hz: at most 1.9 rad/s^2."""
    t = np.arange(n) * DT
    return t, 0.3 * np.sin(2 * np.pi * t * 1e-9)


def test_a_gyro_spike_is_refused_and_the_next_message_is_judged_against_the_one_before():
    t, q = smooth(200)
    q[[50, 120]] = 19.999
    it = intake()
    counts = feed(it, t, q)
    assert dict(counts.rejected) == {"implausible_angular_acceleration": 2}
    assert counts.received == 200 and accepted_rates(it) == [x for x in q if x != 19.999]
    # The evidence is the newest spike's: its interval and the rates' changes, which the
    # report turns into rad/s^2.
    evidence = it.book.evidence[("imu", "implausible_angular_acceleration")]
    assert evidence == pytest.approx((0.02, 0.0, 19.999 - q[119], 0.0), rel=1e-12)
    assert message_value("implausible_angular_acceleration", evidence) == pytest.approx((19.999 - q[119]) / 0.02)


def test_the_bound_is_on_the_acceleration_not_on_the_duration():
    """Two messages of 19.999 rad/s in a row at 50 Hz: the first implies 1000 rad/s^2 and is
    refused; the second lies 40 ms after the last accepted one, which 500 rad/s^2 can reach
    (20 rad/s), and is accepted; the drop back after it is refused once the same way. A
    glitch that lasts as long as a real maneuver would is judged as one."""
    t, q = smooth(100)
    q[[10, 11]] = 19.999  # the pitch rate is near +0.3 rad/s there
    it = intake()
    counts = feed(it, t, q)
    assert abs(q[11] - q[9]) <= 500 * 0.04 and abs(q[12] - q[11]) > 500 * 0.02
    assert dict(counts.rejected) == {"implausible_angular_acceleration": 2}
    assert accepted_rates(it) == [*q[:10], q[11], *q[13:]]


def test_every_accepted_change_is_within_the_bound_and_the_bound_is_the_parameter():
    """Pitch rates whose changes straddle the bound: each message is accepted exactly
    when its change from the previous accepted one is at most limits.angular_acceleration
    times their interval, checked here against the messages themselves. A larger
    limits.angular_acceleration accepts them all."""
    rng = np.random.default_rng(3)
    t = np.arange(400) * DT
    q = rng.uniform(-6.5, 6.5, 400)  # changes up to 13 rad/s; the bound is 10 rad/s per 20 ms
    it = intake()
    counts = feed(it, t, q)
    expected, previous = [], None
    for tk, qk in zip(t, q, strict=True):
        if previous is None or abs(qk - previous[1]) <= 500.0 * (tk - previous[0]) * 1e-9 or tk - previous[0] > MAX_GAP:
            expected.append(qk)
            previous = (tk, qk)
    assert accepted_rates(it) == expected
    assert counts.rejected["implausible_angular_acceleration"] == 400 - len(expected) > 10
    loose = intake(PlausibilityLimits(angular_acceleration=1e5))
    assert not feed(loose, t, q).rejected


def test_a_spike_in_the_first_message_costs_at_most_the_time_the_bound_needs_to_reach_it():
    """The first message has nothing to be judged against. When it is a spike the messages
    after it are refused until the bound allows their change (|0 - 19.999| / 500 = 40 ms:
    the next message, 20 ms on, is refused, the one 40 ms on accepted); a new reference is
    never further than inputs.max_gap."""
    t, q = smooth(20)
    q[0] = 19.999
    it = intake()
    counts = feed(it, t, q)
    assert dict(counts.rejected) == {"implausible_angular_acceleration": 1}
    assert accepted_rates(it)[:2] == [19.999, q[2]]
    tight = intake(PlausibilityLimits(angular_acceleration=5.0))  # 20 rad/s would take 4 s
    counts = feed(tight, t, q)
    gap = MAX_GAP // DT  # refused until more than max_gap after the spike: 12 messages
    assert counts.rejected["implausible_angular_acceleration"] == gap
    assert accepted_rates(tight)[1] == q[gap + 1]


def test_stamps_that_do_not_continue_the_stream_are_not_compared():
    """After a gap longer than inputs.max_gap, or on a new timeline (stamps back to the start
    of a looped replay), the first message becomes the reference instead of being compared
    with rates of another time; a duplicate stamp changes nothing."""
    it = intake()
    feed(it, [0, DT, 2 * DT], [0.0, 0.1, 0.2])
    feed(it, [2 * DT + MAX_GAP + MS], [15.0])  # after a gap: not compared, the new reference
    feed(it, [2 * DT + MAX_GAP + MS + DT], [15.5])  # continues it
    assert not it.book.streams["imu"].rejected
    it = intake()
    feed(it, [0, DT, 2 * DT], [0.0, 0.1, 0.2])
    counts = feed(it, [2 * DT, 3 * DT], [19.0, 0.25])  # a duplicate stamp carrying a spike
    assert dict(counts.rejected) == {"duplicate": 1}
    assert accepted_rates(it) == [0.0, 0.1, 0.2, 0.25]


def test_a_message_refused_for_its_own_values_is_never_the_reference():
    it = intake()
    feed(it, [0, DT], [0.0, 0.1])
    it.imu(2 * DT, (0.0, math.nan, 0.0), (0.0, 0.0, 9.8))  # non_finite
    it.imu(3 * DT, (0.0, 25.0, 0.0), (0.0, 0.0, 9.8))  # beyond limits.angular_rate
    counts = feed(it, [4 * DT], [0.3])  # judged against 0.1 at 20 ms: 2.5 rad/s^2
    assert dict(counts.rejected) == {"non_finite": 1, "implausible_angular_rate": 1}
    assert accepted_rates(it) == [0.0, 0.1, 0.3]
