"""The pipeline that the node and the replay share, end to end: samples against an
independent interpolation and reduction, alignment of the differentiator's lag, estimates
against batch least squares, the bookkeeping of every bad input, and the lifecycle (disable,
reset, reconfigure, state file). Input sanity: plausibility limits (and a corrupted bag
replayed), the last guard before publishing, bounded tables, input frames. The parts have
their own tests (test_sampling, test_aero, test_state_file, test_config,
test_differentiation). No ROS, no DDS (bags through rosbags)."""

import copy
import csv
import dataclasses
import math
import struct
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from bag_samples import changed_messages
from interleaving import interleave

from rls_uncertainty.aero.differentiation import DifferentiatorConfig, differentiate
from rls_uncertainty.aero.surface_mixing import SurfaceMixing
from rls_uncertainty.datapath.bookkeeping import WITHHELD_PROBLEM
from rls_uncertainty.datapath.outputs import OutputLayout
from rls_uncertainty.datapath.pipeline import STREAMS, Pipeline, StateFileError
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_aircraft, load_parameters_file, pipeline_config
from rls_uncertainty.simulation.t2 import simulate_sensor_streams

T2 = load_aircraft("t2")
T2_PARAMS = {"models.enabled": ["CZ", "Cm"], "surfaces.elevator": ["elevator_left", "elevator_right"]}
MS = 1_000_000
BUNDLED = Path(__file__).resolve().parents[1] / "bags" / "t2_maneuver"


KINDS = ("imu", "airspeed", "dynamic_pressure", "control_surfaces", "thrust")


def stream_events(st, shift_ns=0):
    """Each stream of a SensorStreams set as its own list of ``(stamp, kind, values)``."""
    out = {}
    for kind in KINDS:
        stamps, values = getattr(st, kind)
        out[kind] = [(int(stamps[k]) + shift_ns, kind, values[k]) for k in range(stamps.size)]
    return out


def in_stamp_order(streams):
    """Every message of ``{kind: events}`` in stamp order (stable by stream)."""
    events = [(e[0], KINDS.index(kind), e) for kind, evs in streams.items() for e in evs]
    events.sort(key=lambda x: (x[0], x[1]))
    return [e for _t, _r, e in events]


def apply(pipe, events, surface_names=("elevator_left", "elevator_right", "aileron_left", "aileron_right", "rudder")):
    """Feed ``(stamp, kind, values)`` events (values None: a message rejected for its values,
    as the physical-limit checks do); returns the outputs."""
    outs = []
    for stamp, kind, v in events:
        if v is None:
            outs += pipe.reject_invalid(kind, stamp, "invalid")
        elif kind == "imu":
            outs += pipe.add_imu(stamp, v[:3], v[3:])
        elif kind == "airspeed":
            outs += pipe.add_airspeed(stamp, v)
        elif kind == "dynamic_pressure":
            outs += pipe.add_dynamic_pressure(stamp, float(v))
        elif kind == "control_surfaces":
            outs += pipe.add_surfaces(stamp, list(surface_names), v)
        else:
            outs += pipe.add_thrust(stamp, float(v))
    return outs


def published(pipe, out):
    """The rows of ``out`` that leave the pipeline (:meth:`.outputs.OutputLayout.rows`)."""
    return list(OutputLayout.of(pipe).rows(out))


def feed_streams(pipe, st):
    """Every message of a SensorStreams set, in stamp order (stable by stream)."""
    return apply(pipe, in_stamp_order(stream_events(st)), st.surface_names)


@pytest.fixture(scope="module")
def t2_run():
    st = simulate_sensor_streams(0.2, 250)
    pipe = Pipeline(pipeline_config(T2_PARAMS), record=True)
    outs = feed_streams(pipe, st)
    pipe.finish()
    return st, pipe, outs


def test_samples_equal_an_independent_interpolation_and_reduction(t2_run):
    st, pipe, _ = t2_run
    P = 20 * MS
    t_imu, imu = st.imu
    t_air, vel = st.airspeed
    t_srf, srf = st.control_surfaces
    first = max(t_imu[0], t_air[0], t_srf[0])
    last = min(t_imu[-1], t_air[-1], t_srf[-1])
    grid = np.arange(-(-first // P) * P, last + 1, P)
    rel = lambda t: (t - st.start_ns) * 1e-9  # noqa: E731
    # IMU stamps fall on the grid; air data and surfaces are interpolated linearly.
    i = np.searchsorted(t_imu, grid)
    assert np.all(t_imu[i] == grid)
    q = -imu[i, 1]
    az = -imu[i, 5]
    u = np.interp(rel(grid), rel(t_air), vel[:, 0])
    w = -np.interp(rel(grid), rel(t_air), vel[:, 2])
    alpha = np.arctan2(w, u)
    V = np.hypot(u, w)
    de = np.interp(rel(grid), rel(t_srf), 0.5 * (srf[:, 0] + srf[:, 1]))
    qbar = st.dynamic_pressure[1][0]
    q_dot = differentiate(q, 0.02, DifferentiatorConfig())
    keep = np.isfinite(q_dot)
    CZ = T2.mass * az / (qbar * T2.S)
    Cm = T2.Iyy * q_dot / (qbar * T2.S * T2.cbar)
    q_hat = q * T2.cbar / (2 * V)

    t_rec = np.array([r[0] for r in pipe.regression])
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    assert np.array_equal(t_rec, grid[keep])
    np.testing.assert_allclose(X[:, 0, :3], np.column_stack([np.ones(keep.sum()), alpha[keep], de[keep]]),
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(X[:, 1, :4], np.column_stack([np.ones(keep.sum()), alpha[keep], q_hat[keep], de[keep]]),
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(z[:, 0], CZ[keep], rtol=1e-12)
    np.testing.assert_allclose(z[:, 1], Cm[keep], rtol=1e-9, atol=1e-12)


def test_final_estimates_equal_batch_least_squares(t2_run):
    _st, pipe, outs = t2_run
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    for j, n in enumerate(pipe.sizes):
        ols = np.linalg.lstsq(X[:, j, :n], z[:, j], rcond=None)[0]
        np.testing.assert_allclose(outs[-1].theta[j, :n], ols, rtol=1e-8)
    # Corrected standard errors exceed the conventional ones for this colored-noise maneuver.
    assert np.all(outs[-1].se[:, :3] > 2 * outs[-1].se_conventional[:, :3])


def test_every_sample_and_message_is_accounted_for(t2_run):
    st, pipe, outs = t2_run
    c = pipe.counters()
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values()) + c["samples_pending"]
    assert c["samples_rejected"] == {"differentiator_warmup": 4, "end_of_data": 4}
    for kind, s in c["streams"].items():
        assert s["received"] == (getattr(st, kind)[0].size if kind in KINDS else 0)  # (the fed streams)
        assert s["accepted"] == s["received"]
    assert len(outs) == c["samples_used"]
    for out in outs:
        for _j, _name, _names, th, se, sc in published(pipe, out):
            assert np.all(np.isfinite(th)) and np.all(np.isfinite(se)) and np.all(np.isfinite(sc))


# ----------------------------------------------------------------------------- identifiability
def test_the_clean_maneuver_keeps_every_flag_the_monitor_gives(t2_run):
    """On the seeded T-2 maneuver every parameter is identifiable once its estimate settles: the
    published flags are, sample by sample, those of a convergence monitor run independently on
    the published estimates, and every parameter ends flagged."""
    from rls_uncertainty.datapath.convergence import ConvergenceMonitor

    _st, pipe, outs = t2_run
    monitor = ConvergenceMonitor(pipe.sizes, dataclasses.replace(pipe.config.convergence, rate_hz=pipe.config.rate))
    for out in outs:
        flags, model_flags = monitor.update(out.stamp_ns, out.theta, out.se, out.ready)
        assert np.array_equal(out.converged, flags) and np.array_equal(out.model_converged, model_flags)
    assert outs[-1].model_converged.all()
    assert all(pipe.model_report(j)["identifiable"] for j in range(2))


def _hostile(streams, params):
    """Feed ``streams`` message by message; the outputs, and whether a flag was ever held back."""
    pipe = Pipeline(pipeline_config({**T2_PARAMS, **params}), record=True)
    outs, held = [], np.zeros((2, 4), dtype=bool)
    for event in in_stamp_order(stream_events(streams)):
        outs += apply(pipe, [event], streams.surface_names)
        held |= pipe.identifiability.held_back
    pipe.finish()
    return pipe, outs, held


def test_a_surface_commanded_twice_is_never_flagged_and_the_reason_names_both():
    """Rudder = elevator + 1e-6 rad of noise, with a C_Z model on both: the batch regressors make
    (X'X)^-1 correlate the two slopes at -1 to within 1e-3; the estimates are published with
    their (huge) standard errors but never flagged converged, although the estimates settle
    (the monitor would flag them), and the model report says why."""
    st = simulate_sensor_streams(0.2, 250)
    srf = st.control_surfaces[1].copy()
    srf[:, 4] = srf[:, 0] + np.random.default_rng(19).normal(0.0, 1e-6, srf.shape[0])
    st = dataclasses.replace(st, control_surfaces=(st.control_surfaces[0], srf))
    pipe, outs, held = _hostile(st, {"models.CZ": ["1", "alpha", "delta_e", "delta_r"]})
    X = np.array([r[1][0] for r in pipe.regression])
    inverse = np.linalg.inv(X.T @ X)
    assert inverse[2, 3] / np.sqrt(inverse[2, 2] * inverse[3, 3]) < -0.999
    assert outs[-1].ready[0] and np.all(outs[-1].se[0] > 0)
    assert not any(out.converged[0, 2:4].any() for out in outs) and held[0, 2:4].all()
    report = pipe.model_report(0)
    assert report["not_identifiable"] == "CZ_delta_e,CZ_delta_r" and not report["converged"]
    assert report["identifiability"].startswith("CZ: delta_e and delta_r correlated -")
    assert pipe.model_report(1)["identifiable"] and outs[-1].model_converged[1]


def test_sensor_noise_without_a_maneuver_explains_nothing_and_nothing_is_flagged():
    """Trim plus white sensor noise: a batch fit of the recorded regression explains under 5 % of
    either output, and no parameter is ever flagged."""
    st = simulate_sensor_streams(0.2, 250)
    rng = np.random.default_rng(7)
    imu = st.imu[1].copy()
    imu[:, 1] = 0.002 * rng.standard_normal(imu.shape[0])
    imu[:, 5] = np.median(imu[:, 5]) + 0.02 * rng.standard_normal(imu.shape[0])
    srf = st.control_surfaces[1].copy()
    srf[:, 0] = srf[:, 1] = 0.0005 * rng.standard_normal(srf.shape[0])
    vel = st.airspeed[1].copy()
    a = np.median(np.arctan2(-vel[:, 2], vel[:, 0])) + 0.001 * rng.standard_normal(vel.shape[0])
    speed = np.hypot(vel[:, 0], vel[:, 2])
    vel[:, 0], vel[:, 2] = speed * np.cos(a), -speed * np.sin(a)
    st = dataclasses.replace(st, imu=(st.imu[0], imu), control_surfaces=(st.control_surfaces[0], srf),
                             airspeed=(st.airspeed[0], vel))
    pipe, outs, _held = _hostile(st, {})
    for j, n in enumerate(pipe.sizes):
        X = np.array([r[1][j, :n] for r in pipe.regression])
        z = np.array([r[2][j] for r in pipe.regression])
        residual = z - X @ np.linalg.lstsq(X, z, rcond=None)[0]
        r2 = 1.0 - residual @ residual / np.sum((z - z.mean()) ** 2)
        assert r2 < 0.05 and pipe.model_fit(j)["r_squared"] == pytest.approx(r2, rel=1e-6, abs=1e-9)
        assert "no regressor explains the output" in pipe.model_report(j)["identifiability"]
    assert not any(out.converged.any() for out in outs)


def test_a_regressor_that_never_moves_is_named():
    """C_Z with sideslip on a longitudinal maneuver (beta = 0 throughout): the model never
    initializes, and its report names beta and its standard deviation."""
    pipe, outs, _held = _hostile(simulate_sensor_streams(0.2, 250), {"models.CZ": ["1", "alpha", "beta", "delta_e"]})
    assert not any(out.ready[0] for out in outs)
    report = pipe.model_report(0)
    assert not report["ready"] and report["identifiability"].startswith(
        "CZ: regressor beta not excited (std 0 rad in 591 samples since start")


# ----------------------------------------------------------------------------- synthetic input
class Synthetic:
    """Clean signals on every stream: q = A sin(w t) (so q_dot is known), constant airspeed."""

    V = 40.0
    A = 0.1
    W = 2 * math.pi * 1.0

    def __init__(self, pipe, t0=10**18, bad=None):
        """``bad``: ``(stream, ms, value)`` replaces one message's value (the IMU's value is
        ``(gyro, accel)``; the air data's ``vector`` or ``qbar``)."""
        self.pipe, self.t0, self.outs = pipe, t0, []
        self.bad = bad

    def q(self, t):
        return self.A * math.sin(self.W * (t - self.t0) * 1e-9)

    def _bad(self, stream, t):
        b = self.bad
        return b[2] if b is not None and b[0] == stream and t == self.t0 + b[1] * MS else None

    def imu(self, t, **kw):
        gyro, accel = self._bad("imu", t) or (kw.get("gyro", (0.0, -self.q(t), 0.0)), kw.get("accel", (0.1, 0.0, 9.8)))
        self.outs += self.pipe.add_imu(t, gyro, accel)

    def air(self, t, vec=None):
        bad_vec, bad_qbar = self._bad("airspeed", t), self._bad("dynamic_pressure", t)
        self.outs += self.pipe.add_airspeed(t, bad_vec or vec or (self.V, 0.0, -0.05 * self.V))
        self.outs += self.pipe.add_dynamic_pressure(t, 0.5 * 1.2 * self.V**2 if bad_qbar is None else bad_qbar)

    def surfaces(self, t, names=None, positions=None):
        names = names or ["elevator", "aileron_left", "aileron_right", "rudder"]
        positions = self._bad("control_surfaces", t) or positions or \
            [0.01 * math.cos(3 * (t - self.t0) * 1e-9), -0.02, 0.04, 0.0]
        self.outs += self.pipe.add_surfaces(t, names, positions)

    def run(self, start_ms, end_ms, imu_ms=5, air_ms=20, srf_ms=10, skip_air=None):
        for ms in range(start_ms, end_ms):
            t = self.t0 + ms * MS
            if ms % imu_ms == 0:
                self.imu(t)
            if ms % air_ms == 3 and not (skip_air and skip_air[0] <= ms < skip_air[1]):
                self.air(t)
            if ms % srf_ms == 1:
                self.surfaces(t)


def pitch_pipeline(**params):
    base = {"models.enabled": ["Cm"], "models.Cm": ["1", "q_hat", "delta_e"], "aircraft": "t2"}
    base.update(params)
    return Pipeline(pipeline_config(base), record=True)


@pytest.mark.parametrize("window,lag", [(9, 4), (9, 0), (17, 8), (7, 2)])
def test_differentiator_lag_keeps_every_signal_aligned(window, lag):
    pipe = pitch_pipeline(**{"differentiator.window": window, "differentiator.lag": lag})
    syn = Synthetic(pipe)
    syn.run(0, 3000)
    t = np.array([(r[0] - syn.t0) * 1e-9 for r in pipe.regression])
    X = np.array([r[1][0] for r in pipe.regression])
    z = np.array([r[2][0] for r in pipe.regression])
    qbar = 0.5 * 1.2 * syn.V**2
    V = math.hypot(syn.V, 0.05 * syn.V)
    # q_hat at the sample's own stamp, exactly.
    np.testing.assert_allclose(X[:, 1] * 2 * V / T2.cbar, syn.A * np.sin(syn.W * t), atol=1e-12)
    # Cm carries q_dot of the same stamp (p = r = 0): a one-sample misalignment would be an
    # error of about A w^2 dt = 0.08; the differentiator's own error is 10x smaller (it is
    # largest for the causal lag 0, about 1% of the amplitude).
    q_dot = z * qbar * T2.S * T2.cbar / T2.Iyy
    err = np.max(np.abs(q_dot - syn.A * syn.W * np.cos(syn.W * t)))
    misaligned = np.max(np.abs(q_dot[1:] - syn.A * syn.W * np.cos(syn.W * t[:-1])))
    assert err < 0.1 * syn.A * syn.W**2 * 0.02
    assert misaligned > 0.5 * syn.A * syn.W**2 * 0.02
    # The Eq. 23 elevator: the first joint (sampled at 1, 11, 21 ... ms, interpolated).
    np.testing.assert_allclose(X[:, 2], 0.01 * np.cos(3 * t), atol=2e-6)


def test_surfaces_are_mixed_by_the_configured_eq_23_before_sampling():
    """The mixing itself is tested in test_aero; here: the pipeline buffers exactly what the
    configured SurfaceMixing gives for the message."""
    params = {"models.enabled": ["Cl"], "surfaces.aileron_right": ["ar1", "ar2"],
              "surfaces.aileron_left": ["al"], "surfaces.rudder": ["r1", "r2"]}
    pipe = Pipeline(pipeline_config(params))
    names, positions = ["ar1", "ar2", "al", "r1", "r2", "elevator"], [0.1, 0.3, -0.2, 0.01, 0.03, 0.0]
    pipe.add_surfaces(5, names, positions)
    expected = SurfaceMixing(elevator=("elevator",), aileron_right=("ar1", "ar2"), aileron_left=("al",),
                             rudder=("r1", "r2")).layout(tuple(names)).deflections(positions)
    assert pipe.sampler.streams["control_surfaces"].values == [expected]
    assert expected[1] == pytest.approx(0.2)
    assert "control_surfaces" in pipe.required
    no_surfaces = pipeline_config({"models.enabled": ["CZ"], "models.CZ": ["1", "alpha"]})
    assert "control_surfaces" not in Pipeline(no_surfaces).required


def test_bad_messages_are_counted_and_never_reach_the_outputs():
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 1000)
    t = syn.t0 + 1000 * MS
    syn.imu(t, gyro=(float("nan"), 0.0, 0.0))  # NaN field
    syn.imu(t + 1 * MS, gyro=(0.0, float("inf"), 0.0))  # Inf field
    syn.imu(t + 1 * MS)  # duplicate stamp (of the Inf message)
    for k in range(30):  # a burst of old messages
        syn.imu(syn.t0 + (500 + k) * MS)
    syn.surfaces(t, names=["elevator", "rudder"], positions=[0.0])  # mismatched arrays
    syn.surfaces(t + MS // 2, names=["rudder", "aileron_left", "aileron_right"], positions=[0.0] * 3)  # no elevator
    syn.surfaces(t + 2 * MS, names=["elevator", "aileron_left", "aileron_right", "rudder", "flap"],
                 positions=[0.0, 0.0, 0.0, 0.0, 0.3])  # unknown joint: counted, message used
    syn.air(t + 3 * MS, vec=(float("nan"), 0.0, 0.0))
    pipe.reject("thrust", "malformed: ValueError")  # the node could not decode a message
    syn.run(1004, 2000)
    pipe.finish()
    c = pipe.counters()
    assert c["streams"]["imu"]["rejected"] == {"non_finite": 2, "duplicate": 1, "out_of_order": 30}
    assert c["streams"]["control_surfaces"]["rejected"] == {"mismatched_arrays": 1, "missing_joint": 1}
    assert c["streams"]["airspeed"]["rejected"] == {"non_finite": 1}
    assert c["streams"]["thrust"]["rejected"] == {"malformed: ValueError": 1}
    assert c["unknown_joints"] == {"flap": 1}
    for s in c["streams"].values():
        assert s["received"] == s["accepted"] + sum(s["rejected"].values())
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    # No sample is interpolated across a non-finite message: IMU 995 ms, NaN 1000, Inf 1001,
    # then 1005 ms skips the 1000 ms grid point; air data 983 ms, NaN 1003, then 1023 ms skips
    # 1020 ms. The two JointStates that cannot be mixed (1000, 1000.5 ms) are holes in the
    # interval already skipped. The 4 samples in the delay line are dropped and the differentiator warms up again.
    assert c["samples_rejected"] == {"differentiator_warmup": 8, "end_of_data": 4, "invalid_imu": 1,
                                     "invalid_airspeed": 1, "discontinuity": 4}
    t_used = {(r[0] - syn.t0) // MS for r in pipe.regression}
    assert not t_used & {1000, 1020}
    for out in syn.outs:
        for _j, _n, _names, th, se, sc in published(pipe, out):
            assert np.isfinite(th).all() and np.isfinite(se).all() and np.isfinite(sc).all()


def test_zero_and_backwards_airspeed_messages_are_rejected_one_by_one():
    """Zero airspeed, flying backwards and flying sideways are impossible as messages: each is
    rejected with its reason and no regression row is formed from it (q_hat carries 1/V)."""
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 1000)
    bad = {0: (0.0, 0.0, 0.0), 1: (-40.0, 0.0, 2.0), 2: (1.0, 40.0, 0.0), 3: (0.0, 0.0, -40.0)}
    for ms in range(1000, 2000):
        t = syn.t0 + ms * MS
        if ms % 5 == 0:
            syn.imu(t)
        if ms % 20 == 3:
            syn.air(t, vec=bad.get((ms - 1003) // 100) if ms in range(1003, 1400, 100) else None)
        if ms % 10 == 1:
            syn.surfaces(t)
    syn.run(2000, 3000)
    pipe.finish()
    c = pipe.counters()
    assert c["streams"]["airspeed"]["rejected"] == {
        "implausible_airspeed": 1, "implausible_alpha": 2, "implausible_beta": 1}
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    t = np.array([(r[0] - syn.t0) * 1e-9 for r in pipe.regression])
    X = np.array([r[1][0] for r in pipe.regression])
    V = math.hypot(syn.V, 0.05 * syn.V)  # the only airspeed any used sample may see
    np.testing.assert_allclose(X[:, 1] * 2 * V / T2.cbar, syn.A * np.sin(syn.W * t), atol=1e-12)
    assert pipe.bank.k == c["samples_used"] > 80  # of 141 in the clean run


# Absurd values (a flipped bit, a wrong unit, a crafted message), one message each, in the
# middle of a clean run: (stream, ms, value, reason). IMU at 5 ms, air data at 3 + 20 k ms,
# surfaces at 1 + 10 k ms.
ABSURD = {
    "gyro 1e100 rad/s": ("imu", 1005, ((0.0, 1e100, 0.0), (0.1, 0.0, 9.8)), "implausible_angular_rate"),
    "acceleration 1e150": ("imu", 1005, ((0.0, -0.05, 0.0), (0.1, 0.0, 1e150)), "implausible_specific_force"),
    "surface 1e150": ("control_surfaces", 1011, [1e150, -0.02, 0.04, 0.0], "implausible_surface"),
    "dynamic pressure 1e-300 Pa": ("dynamic_pressure", 1023, 1e-300, "implausible_dynamic_pressure"),
    "negative airspeed": ("airspeed", 1023, (-40.0, 0.0, 2.0), "implausible_alpha"),
    "alpha 179.3 deg": ("airspeed", 1023, (-40.0, 0.0, -0.5), "implausible_alpha"),
    "airspeed 1e300": ("airspeed", 1023, (1e300, 0.0, 0.0), "implausible_airspeed"),
    "gyro subnormal, accel -0.0": ("imu", 1005, ((5e-324, -0.0, 0.0), (-0.0, 0.0, 9.8)), None),  # plausible
}


@pytest.fixture(scope="module")
def clean_pitch_run():
    pipe = pitch_pipeline()
    Synthetic(pipe).run(0, 3000)
    pipe.finish()
    return pipe


@pytest.mark.parametrize("case", ABSURD)
def test_one_absurd_value_is_rejected_and_changes_nothing_else(case, clean_pitch_run):
    """Before: the gyro case published NaN/Inf estimates from then on, the others finite but
    ruined estimates (R^2 of CZ 0.91 -> 0.006 for one 1e150 acceleration on the bundled bag).
    Now the message is counted with its reason, every used sample equals the clean run's at
    the same stamp (the elevator is interpolated over 20 ms instead of 10 ms where its message
    is missing: 1e-6 rad; samples next to the message may be skipped), and the estimates are
    the batch least squares of those samples."""
    stream, ms, value, reason = ABSURD[case]
    pipe = pitch_pipeline()
    syn = Synthetic(pipe, bad=(stream, ms, value))
    syn.run(0, 3000)
    pipe.finish()
    c = pipe.counters()
    assert c["streams"][stream]["rejected"] == ({reason: 1} if reason else {})
    for other in set(STREAMS) - {stream}:
        assert c["streams"][other]["rejected"] == {}
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    clean = {r[0]: r for r in clean_pitch_run.regression}
    assert len(pipe.regression) >= len(clean) - 20
    for t, X, z in pipe.regression:
        np.testing.assert_allclose(X, clean[t][1], rtol=0, atol=1e-6)
        np.testing.assert_allclose(z, clean[t][2], rtol=1e-9, atol=1e-12)
    rows = [row for out in syn.outs for row in published(pipe, out)]
    assert rows and all(np.isfinite(np.concatenate(r[3:])).all() for r in rows)
    X = np.array([r[1][0, :3] for r in pipe.regression])
    z = np.array([r[2][0] for r in pipe.regression])
    np.testing.assert_allclose(pipe.bank.theta_all()[0, :3], np.linalg.lstsq(X, z, rcond=None)[0], rtol=1e-8)


def test_derived_dynamic_pressure_is_judged_per_sample():
    """Without the pressure topic qbar = rho V^2 / 2: thin air (0.01 kg/m^3) at 25 m/s gives
    3.1 Pa, below limits.dynamic_pressure_min, so every sample is rejected though each message
    was plausible; 0.05 kg/m^3 (15.6 Pa) is used."""
    for rho, used in ((0.01, False), (0.05, True)):
        pipe = pitch_pipeline(**{"inputs.use_dynamic_pressure": False, "inputs.air_density": rho})
        syn = Synthetic(pipe)
        syn.V = 25.0
        syn.run(0, 2000)
        pipe.finish()
        c = pipe.counters()
        assert all(not s["rejected"] for s in c["streams"].values())
        assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
        if used:
            assert c["samples_used"] > 80 and "implausible_dynamic_pressure" not in c["samples_rejected"]
        else:
            assert c["samples_used"] == 0 and not syn.outs
            assert c["samples_rejected"]["implausible_dynamic_pressure"] == c["samples_formed"] - 8


def test_the_limits_are_parameters():
    """A tighter limit rejects what the default accepts: a pitch rate of 0.2 sin(w t) rad/s
    against limits.angular_rate 0.15."""
    pipe = pitch_pipeline(**{"limits.angular_rate": 0.15})
    syn = Synthetic(pipe)
    syn.A = 0.2
    syn.run(0, 1000)
    beyond = sum(1 for k in range(200) if abs(syn.q(syn.t0 + 5 * k * MS)) > 0.15)
    assert beyond > 50
    assert pipe.counters()["streams"]["imu"]["rejected"] == {"implausible_angular_rate": beyond}


def test_a_refused_estimator_update_is_counted_and_changes_nothing(monkeypatch):
    """The estimator raises NonFiniteInput, state unchanged, for an update that would make its
    state non-finite (estimator.py); the pipeline counts the sample as non_finite_regression."""
    from rls_uncertainty.errors import NonFiniteInput

    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 1000)
    k, theta = pipe.bank.k, pipe.bank.theta_all()
    real_update, calls = pipe.bank.update, []

    def refusing(X, z):
        calls.append(1)
        if len(calls) <= 3:
            raise NonFiniteInput("update would overflow")
        return real_update(X, z)

    monkeypatch.setattr(pipe.bank, "update", refusing)
    n_out = len(syn.outs)
    syn.run(1000, 1061)  # three samples
    assert pipe.bank.k == k and np.array_equal(pipe.bank.theta_all(), theta, equal_nan=True)
    assert len(syn.outs) == n_out
    syn.run(1061, 2000)
    pipe.finish()
    c = pipe.counters()
    assert c["samples_rejected"]["non_finite_regression"] == 3
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())


def test_a_model_whose_outputs_are_not_finite_is_withheld_and_counted(monkeypatch):
    """The last guard (unreachable through the inputs): a ready model whose estimates are not
    finite publishes nothing, is counted, and its fit says why; after a reset it recovers. (The
    noise-free synthetic C_Z fits exactly: its zero standard errors are withheld at every
    sample by the same guard, which Cm's break does not change.)"""
    pipe = pitch_pipeline(**{"models.enabled": ["CZ", "Cm"], "models.CZ": ["1", "delta_e"]})
    syn = Synthetic(pipe)
    syn.run(0, 3000)  # (published from 2.1 s: the publication rule)
    assert pipe.model_fit(1)["ready"] and pipe.model_fit(1)["outputs_withheld"] == 0
    cz_before = pipe.counters()["outputs_withheld"]["CZ"]
    assert cz_before > 0 and not syn.outs[-1].ready[0]
    real_theta = pipe.bank.theta_all

    def broken():
        theta = real_theta()
        theta[1, 1] = math.inf  # Cm_q
        return theta

    monkeypatch.setattr(pipe.bank, "theta_all", broken)
    n_out = len(syn.outs)
    syn.run(3000, 3400)
    new = syn.outs[n_out:]
    assert len(new) == 20
    assert [row.model for out in new for row in published(pipe, out)] == []
    assert all(not out.ready[1] for out in new)
    assert pipe.counters()["outputs_withheld"] == {"CZ": cz_before + 20, "Cm": 20}
    fit = pipe.model_fit(1)
    assert fit["ready"] is False and "withheld" in fit["problem"] and fit["outputs_withheld"] == 20
    # Even an output built by hand leaves (OutputLayout.rows) only with finite rows.
    hand = new[-1]._replace(ready=np.array([True, True]))
    assert [row.model for row in published(pipe, hand)] == ["CZ"]
    monkeypatch.undo()
    pipe.reset("service")
    syn.run(3400, 6400)
    assert pipe.model_fit(1)["ready"] and pipe.counters()["outputs_withheld"]["Cm"] == 20


def test_r_squared_of_a_constant_output_is_not_reported_as_ok():
    """CY with no lateral motion (ay = 0, so CY = 0 exactly, its standard error 0): the fit
    is not ready and says why, and the estimate with its zero standard error is withheld at
    every sample (the last guard), counted; Cm is published."""
    pipe = pitch_pipeline(**{"models.enabled": ["CY", "Cm"], "models.CY": ["1"]})
    syn = Synthetic(pipe)
    syn.run(0, 3000)
    fit = pipe.model_fit(0)
    assert fit == {"ready": False, "samples": pipe.bank.k, "problem": WITHHELD_PROBLEM,
                   "outputs_withheld": pipe.counters()["outputs_withheld"]["CY"]}
    assert fit["outputs_withheld"] == sum(o.index >= pipe.bank.publish_at[0] for o in syn.outs) > 0
    assert pipe.model_fit(1)["ready"] and math.isfinite(pipe.model_fit(1)["r_squared"])
    assert [row.model for row in published(pipe, syn.outs[-1])] == ["Cm"]


def test_a_stream_that_stops_skips_its_gap_and_restarts_the_differentiator():
    pipe = pitch_pipeline(**{"inputs.max_gap": 0.25})
    syn = Synthetic(pipe)
    syn.run(0, 6000, skip_air=(2000, 4000))
    pipe.finish()
    c = pipe.counters()
    # Air data at 1983 ms then 4003 ms: grid points 2000 ... 4000 ms lie in the gap.
    assert c["samples_rejected"]["gap_airspeed"] == len(range(2000, 4001, 20))
    # The 4 samples waiting for the differentiator are dropped, and it warms up again.
    assert c["samples_rejected"]["discontinuity"] == 4
    assert c["samples_rejected"]["differentiator_warmup"] == 8
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    t = np.array([(r[0] - syn.t0) // MS for r in pipe.regression])
    assert not np.any((t >= 1983) & (t <= 4003 + 4 * 20))


def test_a_lagging_stream_is_never_extrapolated_and_buffers_stay_bounded():
    pipe = pitch_pipeline(**{"inputs.buffer_duration": 1.0})
    syn = Synthetic(pipe)
    syn.run(0, 1000)
    newest_air = pipe.sampler.streams["airspeed"].last
    for ms in range(1000, 6000, 5):  # IMU and surfaces keep coming, air data stops
        syn.imu(syn.t0 + ms * MS)
        if ms % 10 == 0:
            syn.surfaces(syn.t0 + ms * MS + MS)
        assert len(pipe.sampler.streams["imu"].stamps) <= 1.0 * 200 + 2
    assert pipe.regression[-1][0] <= newest_air
    assert pipe.bookkeeping.streams["imu"].expired > 0
    syn.run(6000, 8000)  # air data returns: the gap is skipped, estimation resumes
    pipe.finish()
    c = pipe.counters()
    assert c["samples_rejected"]["expired_imu"] + c["samples_rejected"]["gap_airspeed"] > 0
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    assert pipe.regression[-1][0] > syn.t0 + 7000 * MS


def test_disable_counts_samples_and_reset_restarts():
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 1000)
    k = pipe.bank.k
    pipe.enabled = False
    syn.run(1000, 2000)
    assert pipe.bank.k == k
    assert pipe.bookkeeping.samples_rejected["estimation_disabled"] == 50
    pipe.enabled = True
    pipe.reset("service")
    assert pipe.bank.k == 0 and pipe.bookkeeping.resets["service"] == 1
    # Every input state went with it: the 4 samples waiting in the delay line, the buffers.
    assert pipe.bookkeeping.samples_rejected["reset_service"] == 4 and pipe.sampler.buffered() == 0
    syn.run(2000, 3000)
    # The grid restarts at the first point every stream covers (2020 ms, after air data at
    # 2003 ms) up to 2980 ms: 49 samples, 4 of them warming the differentiator up and the last
    # 4 still in its delay line.
    assert pipe.bank.k == 49 - 4 - 4
    # Older stamps are accepted again after a reset (a replay started over): 20 ... 980 ms.
    pipe.reset("service")
    syn.run(0, 1000)
    assert pipe.bank.k == 49 - 4 - 4 and all(not s["rejected"] for s in pipe.counters()["streams"].values())


def test_state_file_resumes_and_refuses_other_configurations(tmp_path):
    """The file format is tested in test_state_file; here: a pipeline resumes another's
    estimator, samples-used count and model fit, and refuses a state of another configuration."""
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 2000)
    path = tmp_path / "state.npz"
    pipe.save_state(path)
    resumed = pitch_pipeline()
    resumed.load_state(path)
    np.testing.assert_array_equal(resumed.bank.theta_all(), pipe.bank.theta_all())
    np.testing.assert_array_equal(resumed.bank.standard_errors_all(), pipe.bank.standard_errors_all())
    assert resumed.counters()["samples_used"] == pipe.counters()["samples_used"] == pipe.bank.k
    assert resumed.model_fit(0) == pipe.model_fit(0)
    row = np.array([[1.0, 0.01, 0.02]])
    pipe.bank.update(row, [0.3])
    resumed.bank.update(row, [0.3])
    np.testing.assert_array_equal(resumed.bank.theta_all(), pipe.bank.theta_all())
    other = pitch_pipeline(**{"estimator.lag_span": 0.2})
    with pytest.raises(StateFileError, match="another"):
        other.load_state(path)


@pytest.mark.parametrize("burn_in", [-1, 0.4])
def test_state_file_with_auto_lags_and_a_residual_burn_in_resumes_and_refuses_another_burn_in(tmp_path, burn_in):
    """With lag_selection auto (the bank's n_lags is "auto") a pipeline resumes its own state
    file, and a state saved with one residual burn-in is refused under another (the default
    -1 is 1 s, 50 samples at 50 Hz, with auto)."""
    params = {"estimator.lag_selection": "auto", "estimator.residual_burn_in_span": burn_in}
    pipe = pitch_pipeline(**params)
    assert pipe.bank.options.burn_in == (50 if burn_in < 0 else 20)
    Synthetic(pipe).run(0, 3000)
    path = tmp_path / "state.npz"
    pipe.save_state(path)
    resumed = pitch_pipeline(**params)
    resumed.load_state(path)
    np.testing.assert_array_equal(resumed.bank.standard_errors_all(), pipe.bank.standard_errors_all())
    for other_burn_in in (0, 0.14):
        other = pitch_pipeline(**{**params, "estimator.residual_burn_in_span": other_burn_in})
        with pytest.raises(StateFileError, match="another"):
            other.load_state(path)


def test_pipeline_imports_no_ros():
    import subprocess

    code = "import sys, rls_uncertainty.datapath.pipeline, rls_uncertainty.datapath.inputs, " \
           "rls_uncertainty.datapath.outputs; " \
           "sys.exit(any(m.split('.')[0] in ('rclpy', 'rosbags') for m in sys.modules))"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


@pytest.mark.parametrize("module", ["datapath.sampling", "aero.surface_mixing", "aero.coefficients",
                                    "aero.differentiation", "state_file"])
def test_the_numerical_core_imports_numpy_only(module):
    import subprocess

    code = f"import sys, rls_uncertainty.{module}; " \
           "print(sorted({m.split('.')[0] for m in sys.modules} & {'rclpy', 'rosbags', 'yaml', 'scipy', 'mcap'}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_reconfiguration_keeps_every_count():
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 1003)
    before = pipe.counters()
    buffered = sum(len(s.stamps) for s in pipe.sampler.streams.values())
    pending = before["samples_pending"]
    assert buffered > 0 and pending > 0
    new_cfg = pipeline_config({"models.enabled": ["Cm"], "models.Cm": ["1", "q_hat", "delta_e"],
                               "estimator.lag_span": 0.2})
    book = pipe.bookkeeping
    pipe = pipe.reconfigured(new_cfg)
    assert pipe.bookkeeping is book and pipe.sampler.counts == book.streams
    syn.pipe = pipe
    after = pipe.counters()
    assert pipe.bank.k == 0 and pipe.config.estimator.lags == 10
    assert after["resets"] == {"parameters_changed": 1}
    assert after["samples_rejected"]["reset_parameters_changed"] == pending
    assert sum(s["expired"] for s in after["streams"].values()) == buffered
    for name, s in after["streams"].items():
        assert s["received"] == before["streams"][name]["received"]
    syn.run(1003, 3000)
    pipe.finish()
    c = pipe.counters()
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    assert pipe.bank.k > 0


def test_messages_lost_in_transport_are_counted_from_stamp_gaps():
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    dropped = {1200, 1205, 1210, 1500}  # IMU messages (5 ms) that never arrive
    for ms in range(3000):
        t = syn.t0 + ms * MS
        if ms % 5 == 0 and ms not in dropped:
            syn.imu(t)
        if ms % 20 == 3:
            syn.air(t)
        if ms % 10 == 1:
            syn.surfaces(t)
    c = pipe.counters()["streams"]
    assert c["imu"]["missing"] == len(dropped)
    assert c["airspeed"]["missing"] == 0 and c["control_surfaces"]["missing"] == 0


# ----------------------------------------------------------------------------- timelines
S = 1_000_000_000


@pytest.fixture(scope="module")
def t2_streams():
    """The bundled bag's maneuver (``make-bag`` writes these streams), stream by stream."""
    st = simulate_sensor_streams(0.2, 250)
    return st, stream_events(st)


def _interleave(rng, runs, weighted):
    """Each stream's messages of consecutive runs in order, the streams randomly interleaved;
    returns ``(event, run)`` pairs."""
    return interleave(rng, {kind: [(e, r) for r, run in enumerate(runs) for e in run[kind]] for kind in KINDS},
                      weighted)


def _same_outputs(a, b):
    assert [o.stamp_ns for o in a] == [o.stamp_ns for o in b]
    for x, y in zip(a, b, strict=True):
        for field in ("theta", "se", "se_conventional", "ready"):
            np.testing.assert_array_equal(getattr(x, field), getattr(y, field))


@pytest.mark.parametrize("seed,weighted,buffer", [(1, False, 60.0), (2, True, 2.0), (3, True, 60.0)])
def test_a_looped_bag_gives_each_run_the_numbers_of_a_fresh_pipeline(t2_streams, seed, weighted, buffer):
    """The bag played three times to one pipeline (stamps restart each time), its streams
    randomly interleaved: each run's outputs are bit-identical to a fresh pipeline's on that
    run alone (fed in the same order), each backward jump counted as one restart."""
    _st, run = t2_streams
    rng = np.random.default_rng(seed)
    events = _interleave(rng, [run, run, run], weighted)
    params = {**T2_PARAMS, "inputs.buffer_duration": buffer}
    looped = Pipeline(pipeline_config(params))
    outs = apply(looped, [e for e, _r in events])  # run after run: a run ends before the next starts
    looped.finish()
    fresh = []
    for r in range(3):
        pipe = Pipeline(pipeline_config(params))
        fresh.append(apply(pipe, [e for e, rr in events if rr == r]))
    _same_outputs(outs, fresh[0] + fresh[1] + fresh[2])
    assert len(fresh[0]) > 500
    c = looped.counters()
    assert c["resets"] == {"stamps_jumped_backwards": 2}
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    # Only stragglers: messages of a run that arrived after its last sample was formed.
    for name, stream in c["streams"].items():
        assert set(stream["rejected"]) <= {"previous_timeline"}, name


def test_a_stamp_years_ahead_or_first_stamps_of_zero_change_no_number(t2_streams):
    _st, run = t2_streams
    events = in_stamp_order(run)
    want = apply(Pipeline(pipeline_config(T2_PARAMS)), events)
    i = next(j for j in range(700, 800) if events[j][1] == "imu")
    future = (events[i][0] + 3 * 365 * 86400 * S, "imu", events[i][2])
    pipe = Pipeline(pipeline_config(T2_PARAMS))
    _same_outputs(apply(pipe, [*events[:i], future, *events[i:]]), want)
    c = pipe.counters()
    assert c["streams"]["imu"]["rejected"] == {"stamp_jump": 1}
    assert c["samples_formed"] == 599 and c["resets"] == {}
    # Every stream's first message stamped 0 (published before the clock was set): one
    # forward restart, not 8.8e10 grid points counted as formed and skipped.
    zeros = [(0, kind, run[kind][0][2]) for kind in KINDS]
    pipe = Pipeline(pipeline_config(T2_PARAMS))
    _same_outputs(apply(pipe, zeros + events), want)
    c = pipe.counters()
    assert c["resets"] == {"stamps_jumped_forward": 1}
    assert c["samples_formed"] == 599 + 1  # the sample at stamp 0, dropped from the delay line
    assert c["samples_rejected"]["reset_stamps_jumped_forward"] == 1


def test_a_forward_jump_keeps_the_estimator_and_a_backward_one_restarts_it():
    pipe = pitch_pipeline()
    syn = Synthetic(pipe)
    syn.run(0, 3000)
    k = pipe.bank.k
    syn.run(20000, 23000)  # every stream silent for 17 s (more than inputs.max_stamp_jump)
    c = pipe.counters()
    assert c["resets"] == {"stamps_jumped_forward": 1}
    assert not any(r.startswith("gap_") for r in c["samples_rejected"])  # no 17 s of grid points
    assert pipe.bank.k > k + 100  # the same flight: the estimator went on
    k = pipe.bank.k
    syn.run(0, 3000)  # the data starts over (a looped replay)
    assert pipe.counters()["resets"] == {"stamps_jumped_forward": 1, "stamps_jumped_backwards": 1}
    assert pipe.bank.k < k and pipe.bank.k == 149 - 4 - 4  # 20 ... 2980 ms, warm-up, delay line


def test_a_zero_dynamic_pressure_message_is_a_hole_no_sample_is_formed_across(t2_streams):
    """What the physical-limit check does with a dynamic pressure <= 0 (``reject_invalid``):
    the grid points between the valid messages around it are rejected, none is formed from an
    interpolation with it, and the differentiator restarts as at a gap."""
    _st, run = t2_streams
    qbar = list(run["dynamic_pressure"])
    k = 250
    t_bad = qbar[k][0]
    qbar[k] = (t_bad, "dynamic_pressure", None)
    params = {**T2_PARAMS, "inputs.use_dynamic_pressure": True}
    pipe = Pipeline(pipeline_config(params), record=True)
    apply(pipe, in_stamp_order({**run, "dynamic_pressure": qbar}))
    pipe.finish()
    before, after = qbar[k - 1][0], qbar[k + 1][0]
    P = 20 * MS
    inside = [t for t in range(-(-before // P) * P, after, P) if t > before]
    assert len(inside) == 2  # 50 Hz air data, 4 ms after the grid: two grid points around it
    c = pipe.counters()
    assert c["samples_rejected"]["invalid_dynamic_pressure"] == 2
    assert c["samples_rejected"]["discontinuity"] == 4
    assert c["streams"]["dynamic_pressure"]["rejected"] == {"invalid": 1}
    used = np.array([r[0] for r in pipe.regression])
    assert not np.any((used > before) & (used < after))
    # Every other sample is used as without the bad message.
    plain = Pipeline(pipeline_config(params), record=True)
    apply(plain, in_stamp_order(run))
    plain.finish()
    assert plain.counters()["samples_formed"] == c["samples_formed"]
    assert c["samples_used"] == plain.counters()["samples_used"] - 2 - 4 - 4


def test_messages_far_from_the_clock_are_rejected_when_a_clock_is_given():
    pipe = pitch_pipeline(**{"inputs.max_clock_offset": 60.0})
    assert pipe.needs_clock and not pitch_pipeline().needs_clock
    syn = Synthetic(pipe)
    pipe.clock_ns = syn.t0
    syn.imu(syn.t0 - 61 * S)
    syn.imu(0)
    syn.run(0, 1000)
    c = pipe.counters()["streams"]
    assert c["imu"]["rejected"] == {"far_from_clock": 2}
    assert c["airspeed"]["rejected"] == {} and pipe.bank.k > 0


# ----------------------------------------------------------------------------- frames

@pytest.fixture(scope="module")
def bundled_messages():
    """The bundled bag's messages, decoded by rls_uncertainty.datapath.cdr as the node decodes them."""
    from rls_uncertainty.offline.bags import read_inputs

    return read_inputs(BUNDLED)[0]


CFG_LAG = 4  # differentiator.lag of config/t2.yaml: samples dropped at a skip, then warm-up


def _t2_config(**params):
    return pipeline_config({**load_parameters_file("t2"), **params})


def _relabelled(messages, kind, every, frame):
    """The message of ``kind`` in the middle of every ``every`` relabelled ``frame`` (copies),
    and how many."""
    out, n = [], 0
    for msg_kind, stamp, msg in messages:
        if msg_kind == kind:
            n += 1
            if n % every == every // 2:
                relabelled = copy.deepcopy(msg)
                relabelled.header.frame_id = frame
                out.append((msg_kind, stamp, relabelled))
                continue
        out.append((msg_kind, stamp, msg))
    return out, (n + every // 2) // every


def test_inputs_in_another_frame_are_rejected_as_frame_mismatch(bundled_messages):
    """messages.feed (the node's and the replay's only way in) compares header.frame_id with
    inputs.frame_id. The bundled bag is in base_link, the default: nothing is rejected. Six air
    data messages relabelled pitot_link are rejected (their numbers would be in an unknown
    frame) and leave holes: the two grid points around each, interpolated from air data, are
    skipped (and the differentiator restarts), every other sample is the clean run's.
    An empty inputs.frame_id checks nothing; a frame no input carries rejects everything."""
    assert {m.header.frame_id for _k, _s, m in bundled_messages} == {"base_link"}
    clean = run_pipeline(bundled_messages, _t2_config())
    c_clean = clean.pipeline.counters()
    assert all(not s["rejected"] for s in c_clean["streams"].values())
    relabelled, n = _relabelled(bundled_messages, "airspeed", 100, "pitot_link")
    assert n == 6
    result = run_pipeline(relabelled, _t2_config())
    c = result.pipeline.counters()
    assert c["streams"]["airspeed"]["rejected"] == {"frame_mismatch": n}
    assert c["streams"]["airspeed"]["received"] == c_clean["streams"]["airspeed"]["received"]
    assert c["samples_rejected"]["invalid_airspeed"] == 2 * n
    assert c["samples_used"] == c_clean["samples_used"] - n * (2 + 2 * CFG_LAG)  # skipped, flushed, warm-up
    rows = {t: (X, z) for t, X, z in clean.pipeline.regression}
    for t, X, z in result.pipeline.regression:
        np.testing.assert_array_equal(X, rows[t][0])
        np.testing.assert_array_equal(z, rows[t][1])
    unchecked = run_pipeline(relabelled, _t2_config(**{"inputs.frame_id": ""}), record=False).pipeline.counters()
    assert unchecked["streams"]["airspeed"]["rejected"] == {} and unchecked["samples_used"] == c_clean["samples_used"]
    other = run_pipeline(bundled_messages, _t2_config(**{"inputs.frame_id": "body"}), record=False)
    c = other.pipeline.counters()
    assert not other.outputs and c["samples_formed"] == 0
    for kind, s in c["streams"].items():
        n = c_clean["streams"][kind]["received"]  # (a stream the bag does not carry: nothing)
        assert s["rejected"] == ({"frame_mismatch": n} if n else {})


def test_converted_and_generated_bags_carry_the_default_frame():
    """bags.convert and the bundled bag's generator build every input with one header
    builder: its frame is the default inputs.frame_id (the real conversions are checked in
    the report: the three Twin Otter flights convert to base_link on every topic)."""
    from rls_uncertainty.offline.bags import _standard_message, typestore
    from rls_uncertainty.settings import parameter_defaults

    store = typestore()
    values = {"imu": [0.0] * 6, "airspeed": [40.0, 0.0, 0.0], "dynamic_pressure": 900.0,
              "control_surfaces": [0.0], "thrust": 10.0, "excitation": [0.0]}
    for kind in STREAMS:
        msg = _standard_message(store, kind, 10**18, values[kind], ["elevator"])
        assert msg.header.frame_id == parameter_defaults()["inputs.frame_id"] == "base_link"


# ----------------------------------------------------------------------------- bounded tables
def test_a_flood_of_unknown_joint_names_keeps_every_table_small():
    """100k distinct unknown JointState names once added a counter each, all sent in every
    /diagnostics message (74 -> 154 MB, 3.6 MB messages). Now the first 32 names
    are counted by name and the rest under one key; every occurrence is still counted, the
    messages are still used, and memory does not grow with the names."""
    from rls_uncertainty.datapath.bookkeeping import KEYS_KEPT, OTHER_JOINTS

    pipe = Pipeline(pipeline_config({"models.enabled": ["Cm"], "models.Cm": ["1", "q_hat", "delta_e"]}))
    syn = Synthetic(pipe)
    base = ["elevator", "aileron_left", "aileron_right", "rudder"]
    per_message, n_messages = 100, 1000  # 100k names in 10 s of surfaces at 100 Hz

    def run(first_ms, last_ms):
        for ms in range(first_ms, last_ms):
            t = syn.t0 + ms * MS
            if ms % 5 == 0:
                syn.imu(t)
            if ms % 20 == 3:
                syn.air(t)
            if ms % 10 == 1:
                k = ms // 10
                syn.surfaces(t, names=base + [f"junk_{k}_{i}" for i in range(per_message)],
                             positions=[0.01, -0.02, 0.04, 0.0] + [1e300] * per_message)
            syn.outs.clear()

    run(0, 10)  # the first message: its names fill the table
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    run(10, 10 * n_messages)
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    c = pipe.counters()
    unknown = c["unknown_joints"]
    assert len(unknown) == KEYS_KEPT + 1
    assert sum(unknown.values()) == per_message * n_messages
    assert unknown[OTHER_JOINTS] == per_message * n_messages - KEYS_KEPT
    assert c["streams"]["control_surfaces"]["accepted"] == n_messages  # unknown joints are not errors
    assert c["samples_used"] > 450
    assert len(repr(c)) < 4000
    assert grown < 500_000, grown  # a counter per name would hold > 10 MB


def test_caller_given_rejection_reasons_are_bounded_and_long_keys_cut():
    from rls_uncertainty.datapath.bookkeeping import KEY_CHARS, KEYS_KEPT, OTHER_REASONS

    pipe = pitch_pipeline()
    for k in range(1000):
        pipe.reject("thrust", f"malformed: Error{k}")
    rejected = pipe.counters()["streams"]["thrust"]["rejected"]
    assert len(rejected) == KEYS_KEPT + 1 and rejected[OTHER_REASONS] == 1000 - KEYS_KEPT
    assert pipe.counters()["streams"]["thrust"]["received"] == 1000
    syn = Synthetic(pipe)
    syn.surfaces(syn.t0, names=["elevator", "aileron_left", "aileron_right", "rudder", "x" * 10**6],
                 positions=[0.0] * 5)
    assert list(pipe.counters()["unknown_joints"]) == ["x" * KEY_CHARS]


# ----------------------------------------------------------------------------- replay
def _flip(raw: bytes, value: float, bit: int) -> bytes:
    """``raw`` with one bit of the little-endian double ``value`` (found once) flipped."""
    packed = struct.pack("<d", value)
    at = raw.find(packed)
    assert at > 0 and raw.find(packed, at + 1) < 0
    flipped = struct.pack("<q", struct.unpack("<q", packed)[0] ^ (1 << bit))
    return raw[:at] + flipped + raw[at + 8:]


def test_a_flipped_bit_in_a_recorded_double_is_counted_and_never_replayed(tmp_path, capsys):
    """One flipped exponent bit in a recorded pitch rate (-0.111 rad/s at 2.94 s, an
    IMU message on the 50 Hz grid, becomes -2.0e307) made the replay exit 0 with 1780 NaN or
    Inf numbers in its CSV (Cm from then on). Now the message is rejected as
    implausible_angular_rate, the CSV holds only finite numbers, and the summary says so."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty import cli
    from rls_uncertainty.datapath.cdr import decode
    from rls_uncertainty.offline.bags import write_replay

    records, flipped = [], None
    with AnyReader([BUNDLED]) as reader:
        for i, (conn, t, recorded) in enumerate(reader.messages()):
            raw = bytes(recorded)
            if conn.topic == "/imu" and i >= 1200 and t % (20 * MS) == 0 and flipped is None:  # used by a sample
                y = decode(conn.msgtype, raw).angular_velocity.y
                raw = _flip(raw, y, 62)
                flipped = decode(conn.msgtype, raw).angular_velocity.y
            records.append((t, conn.topic, conn.msgtype, raw))
    assert math.isfinite(flipped) and abs(flipped) > 1e300
    bag = write_replay(tmp_path / "flipped", records)
    out = tmp_path / "out"
    code = cli.main(["replay", str(bag), "--config", "t2", "--out", str(out), "--no-figures", "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "imu: 2400 received, rejected {'implausible_angular_rate': 1}" in text
    with open(out / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) > 1000
    values = np.array([[float(r[k]) for k in ("estimate", "std_error", "std_error_conventional")] for r in rows])
    assert np.isfinite(values).all()


# ----------------------------------------------------------------------------- consistency across streams

def _final(result):
    """Final estimates, corrected SEs and R^2 of each model of a replay."""
    pipe, last = result.pipeline, result.outputs[-1]
    return last.theta, last.se, [pipe.model_fit(j)["r_squared"] for j in range(len(pipe.models))]


def test_a_dynamic_pressure_inconsistent_with_the_airspeed_is_never_estimated(bundled_messages):
    """Before: dynamic pressure messages of 5 Pa (plus 1e-9 Pa steps) with the bag's 30-60 m/s
    airspeed gave C_Z_alpha -708, flagged converged. 2 qbar / V^2 is then at most 0.011
    kg/m^3, below limits.air_density_min: every sample is inconsistent_dynamic_pressure, none
    reaches the estimator. The clean bag (1.18 kg/m^3) loses none."""
    clean = run_pipeline(bundled_messages, _t2_config(), record=False).pipeline.counters()
    assert "inconsistent_dynamic_pressure" not in clean["samples_rejected"]

    def five_pascal(k, msg):
        msg.fluid_pressure = 5.0 + k * 1e-9

    messages = changed_messages(bundled_messages, "dynamic_pressure", five_pascal)
    result = run_pipeline(messages, _t2_config(), record=False)
    c = result.pipeline.counters()
    assert c["samples_used"] == 0 and not any(out.ready.any() for out in result.outputs)
    assert c["samples_rejected"]["inconsistent_dynamic_pressure"] == clean["samples_used"]
    assert all(not s["rejected"] for s in c["streams"].values())  # every message is plausible on its own
    # A density just inside the range is used: 0.06 kg/m^3 (the air at 20 km) for every sample.
    V = {stamp: math.hypot(m.vector.x, m.vector.y, m.vector.z) for kind, stamp, m in bundled_messages
         if kind == "airspeed"}

    def thin_air(k, msg):
        msg.fluid_pressure = 0.5 * 0.06 * V[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] ** 2

    thin = run_pipeline(changed_messages(bundled_messages, "dynamic_pressure", thin_air), _t2_config(), record=False)
    assert thin.pipeline.counters()["samples_used"] == clean["samples_used"]


def test_gyro_spikes_never_reach_the_estimator(bundled_messages):
    """Before: a pitch rate of 19.999 rad/s (just inside limits.angular_rate) in one IMU
    message every 0.5 s, each on a 50 Hz grid point, gave C_m R^2 0.000 and C_m_q -0.03
    against -40.7 on the clean bag (true -53.25), every parameter flagged converged. Each
    spike implies about 4000 rad/s^2 over its 5 ms interval: it is rejected as
    implausible_angular_acceleration and leaves a hole, the message after it is judged
    against the one before it and used. The estimates then stay within two corrected SEs of
    the clean bag's (fewer samples: about 9 around each hole), and R^2 within 0.01."""
    clean = run_pipeline(bundled_messages, _t2_config(), record=False)

    def spike(k, msg):
        if k < 100 or k % 100:
            return False
        msg.angular_velocity.y = 19.999

    spiked = run_pipeline(changed_messages(bundled_messages, "imu", spike), _t2_config(), record=True)
    c = spiked.pipeline.counters()
    assert c["streams"]["imu"]["rejected"] == {"implausible_angular_acceleration": 23}
    assert c["samples_rejected"]["invalid_imu"] == 23
    q_hat = np.array([X[1, 2] for _t, X, _z in spiked.pipeline.regression])  # Cm's q_hat column
    # No spike in any regression row: one would give q_hat >= 19.999 cbar / (2 x 60 m/s) = 0.046
    # (the clean bag's pitch rates stay within 0.14 rad/s, q_hat within 0.0007).
    assert np.abs(q_hat).max() < 0.002
    theta, _se, r2 = _final(spiked)
    theta0, se0, r20 = _final(clean)
    real = np.isfinite(theta0)
    assert (np.abs(theta - theta0)[real] < 2 * se0[real]).all()
    np.testing.assert_allclose(r2, r20, atol=0.01)
