"""The simulated flight (simulation.flight, make-bag --flight) and the maneuver detector
(datapath.maneuver_detector): the truth against the recording's content, the detector against
the truth, garbage counted. No ROS."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from rls_uncertainty import cli
from rls_uncertainty.datapath.maneuver_detector import (
    Boundary,
    ManeuverDetector,
    ManeuverOptions,
    event_boundary,
    refusal_text,
)
from rls_uncertainty.errors import ConfigError, Refused
from rls_uncertainty.offline.bags import typestore
from rls_uncertainty.settings.models import load_aircraft
from rls_uncertainty.settings.yaml_files import load
from rls_uncertainty.simulation.flight import CONDITIONS, PARAMETERS, TRIM_LEG, simulate_flight
from rls_uncertainty.simulation.multisine import T2_TABLE2
from rls_uncertainty.simulation.t2 import SIGNALS, T2_TRUE

ELEVATOR = T2_TABLE2["elevator"]
# The detector's boundaries against the truth, s: the start is the first window above the
# floor (the low-pass and the multisine's first samples), the end one window after the last
# input, corrected; with the band-limited noise on the elevator too the floor is ~1000 times
# higher and the faint first and last tenths of the multisine fall under it.
BOUND = {"responses": 0.5, "all": 1.5}


@pytest.fixture(scope="module")
def flight():
    return simulate_flight(11)


def _seconds(flight, stamps):
    return (np.asarray(stamps) - flight.streams.start_ns) * 1e-9


def test_truth_is_where_the_surfaces_fly_the_multisine(flight):
    stamps, surfaces = flight.streams.control_surfaces
    t = _seconds(flight, stamps)
    de = surfaces[:, 0]
    np.testing.assert_array_equal(surfaces[:, 0], surfaces[:, 1])  # split elevators, equal
    assert len(flight.maneuvers) >= 10
    assert len({m.condition for m in flight.maneuvers}) == len(CONDITIONS)
    inside = np.zeros(t.size, dtype=bool)
    quiet = float(np.std(de[t < flight.maneuvers[0].start]))  # the first trim leg: sensor noise only
    flown = float(np.sqrt(np.mean(ELEVATOR(np.linspace(0, ELEVATOR.period, 2001)) ** 2)))
    for m in flight.maneuvers:
        assert m.end - m.start == pytest.approx(ELEVATOR.period)
        on = (t >= m.start) & (t <= m.end)
        inside |= on
        # The elevator is the multisine started at the truth's start, plus sensor noise.
        residual = de[on] - ELEVATOR(t[on] - m.start)
        assert np.std(residual) < 1.5 * quiet < 0.1 * flown
    assert np.abs(de[~inside]).max() < 6 * quiet  # the trim legs: no input
    names = [m.name for m in flight.maneuvers]
    assert len(set(names)) == len(names) and names[0] == "TP-01a"
    legs = np.diff([0.0] + [x for m in flight.maneuvers for x in (m.start, m.end)])[::2]
    assert TRIM_LEG[0] <= legs.min() and legs.max() <= TRIM_LEG[1] + 2.0 and np.ptp(legs) > 5.0


def test_true_values_are_what_the_coefficients_fit(flight):
    """CZ = m a_z / (qbar S) (Eq. 1c) from the recorded IMU and air data of each maneuver, fitted
    by least squares on [1, alpha, delta_e]: the truth's CZ_0 (which moves with the dynamic
    pressure) and the derivatives (which do not)."""
    calm = simulate_flight(11, gust_sigma=0.0, band_level=0.0)
    ac = load_aircraft("t2")
    t_air, vel = calm.streams.airspeed
    t_imu, imu = calm.streams.imu
    t_srf, srf = calm.streams.control_surfaces
    qbar = dict(zip(*calm.streams.dynamic_pressure, strict=True))
    alpha = np.arctan2(-vel[:, 2], vel[:, 0])
    az = -np.interp(t_air, t_imu, imu[:, 5])  # aircraft axes
    de = np.interp(t_air, t_srf, srf[:, 0])
    t = _seconds(calm, t_air)
    seen = {}
    for c in CONDITIONS:  # the maneuvers of a condition pooled: the noise on alpha (SNR 12) matters less
        mine = [m for m in calm.maneuvers if m.condition == c.name]
        on = np.any([(t >= m.start) & (t <= m.end) for m in mine], axis=0)
        q = np.array([qbar[s] for s in t_air[on]])
        cz = ac.mass * az[on] / (q * ac.S)
        theta, *_ = np.linalg.lstsq(np.column_stack([np.ones(on.sum()), alpha[on], de[on]]), cz, rcond=None)
        true = mine[0].true
        assert all(m.true == true for m in mine)
        assert theta[0] == pytest.approx(true["CZ_0"], abs=0.01)
        assert theta[1] == pytest.approx(true["CZ_alpha"], rel=0.03)
        assert theta[2] == pytest.approx(true["CZ_delta_e"], rel=0.1)
        seen[c.name] = true
    assert {k: v for k, v in seen["B"].items() if not k.endswith("_0")} == T2_TRUE
    assert abs(seen["B"]["CZ_0"] - seen["C"]["CZ_0"]) > 0.1  # the intercept moves with qbar
    models = load(Path(__file__).parents[1] / "config" / "t2.yaml", "config")["/**"]["ros__parameters"]["models"]
    named = [f"{m}_{'0' if r == '1' else 'q' if r == 'q_hat' else r}" for m in models["enabled"] for r in models[m]]
    assert list(PARAMETERS) == named


def _detect(flight):
    d = ManeuverDetector(ManeuverOptions())
    stamps, surfaces = flight.streams.control_surfaces
    out = []
    for s, x in zip(stamps, surfaces, strict=True):
        out += d.update(int(s), x)
    out += d.finish(int(stamps[-1]))
    return d, out


def _errors(flight, boundaries):
    starts = [b for b in boundaries if b.kind == "start"]
    ends = [b for b in boundaries if b.kind == "end"]
    assert [b.name for b in starts] == [b.name for b in ends]
    assert all(a.stamp_ns < b.stamp_ns for a, b in zip(starts, ends, strict=True))
    found = [(_seconds(flight, a.stamp_ns), _seconds(flight, b.stamp_ns)) for a, b in zip(starts, ends, strict=True)]
    return found


@pytest.mark.parametrize(("seed", "noise_on"), [(11, "responses"), (12, "all")])
def test_the_detector_finds_every_maneuver_and_nothing_in_the_gusts(seed, noise_on):
    flight = simulate_flight(seed, band_limited_on=SIGNALS if noise_on == "all" else ("alpha", "q", "az"),
                             gust_sigma=1.54)
    detector, boundaries = _detect(flight)
    found = _errors(flight, boundaries)
    assert len(found) == len(flight.maneuvers)  # none missed, none false (each matched below, in order)
    for (start, end), m in zip(found, flight.maneuvers, strict=True):
        assert abs(start - m.start) < BOUND[noise_on] and abs(end - m.end) < BOUND[noise_on], (m, start, end)
    assert sum(detector.rejected.values()) == 0 and detector.active is None
    assert [b.name for b in boundaries[:2]] == ["m001", "m001"]


def test_garbage_is_counted_and_the_maneuver_still_found():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 40.0, 0.01)
    x = 1e-4 * rng.standard_normal(t.size)
    on = (t >= 15.0) & (t <= 25.0)
    x[on] += ELEVATOR(t[on] - 15.0)
    d = ManeuverDetector()
    out = []
    for k, (s, v) in enumerate(zip(t, x, strict=True)):
        stamp = round(s * 1e9)
        if k % 97 == 0:
            out += d.update(stamp, [math.nan])
        if k % 89 == 0 and k:
            out += d.update(stamp - 15_000_000, [v])  # behind the previous message
        if k == 1000:
            out += d.update(stamp, [v, v])  # another number of surfaces
        out += d.update(stamp, [v])
        out += d.update(stamp, [v])  # the same stamp again
    out += d.finish(round(t[-1] * 1e9))
    assert d.rejected == {"non_finite": len(range(0, t.size, 97)), "out_of_order": len(range(89, t.size, 89)) + t.size,
                          "shape": 1}
    assert [(b.kind, b.name) for b in out] == [("start", "m001"), ("end", "m001")]
    assert abs(out[0].stamp_ns * 1e-9 - 15.0) < 0.5 and abs(out[1].stamp_ns * 1e-9 - 25.0) < 0.5
    assert math.isfinite(d.power) and math.isfinite(d.floor)


def test_a_maneuver_flown_to_the_end_of_the_data_is_ended_by_finish():
    t = np.arange(0.0, 20.0, 0.01)
    x = np.where(t >= 12.0, ELEVATOR(np.clip(t - 12.0, 0, None)), 0.0) + 1e-4 * np.sin(40 * t)
    d = ManeuverDetector()
    out = [b for s, v in zip(t, x, strict=True) for b in d.update(round(s * 1e9), [v])]
    assert [b.kind for b in out] == ["start"] and d.active == "m001"
    assert d.finish(round(20e9)) == [Boundary("end", round(20e9), "m001")]
    assert d.finish(round(21e9)) == []


def test_options_are_checked_naming_the_parameter():
    with pytest.raises(ConfigError, match=r"maneuvers\.threshold"):
        ManeuverOptions(threshold=1.0)
    with pytest.raises(ConfigError, match=r"maneuvers\.window"):
        ManeuverOptions(window=math.nan)
    with pytest.raises(TypeError):
        ManeuverDetector({"threshold": 3})  # type: ignore[arg-type]


def test_events_are_boundaries_and_garbage_is_refused_with_a_reason():
    assert event_boundary(7, "TP-02a", "start") == Boundary("start", 7, "TP-02a")
    assert event_boundary(8, " TP-02a ", "STOP") == Boundary("end", 8, "TP-02a")
    for key, value, reason in [("TP-02a", "go", "event_value"), ("", "start", "event_key"),
                               ("x" * 65, "stop", "event_key"), ("a\x00b", "stop", "event_key"),
                               (None, "start", "event_type"), ("TP", b"start", "event_type")]:
        got = event_boundary(1, key, value)
        assert got == Refused(reason), (key, value)
        text = refusal_text(got, key, value)
        assert "refused" in text and len(text) < 300 and "\n" not in text


def _read(path, *names):
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([Path(path)], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic in names]
        for conn, t, raw in reader.messages(connections=conns):
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
        return out, reader.start_time


def test_make_bag_flight_writes_the_recording_its_events_and_its_truth(tmp_path, capsys):
    out = tmp_path / "flight"
    assert cli.main(["make-bag", "--flight", "--out", str(out), "--seed", "4"]) == 0
    assert "truth.csv" in capsys.readouterr().out
    with (out / "truth.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["maneuver", "start", "end", "condition", *PARAMETERS]
    want = simulate_flight(4)
    assert [r["maneuver"] for r in rows] == [m.name for m in want.maneuvers]
    assert [float(r["Cm_q"]) for r in rows] == [T2_TRUE["Cm_q"]] * len(rows)
    manifest = yaml.safe_load((out / "flight.yaml").read_text())
    assert manifest["seed"] == 4 and [c["name"] for c in manifest["conditions"]] == [c.name for c in CONDITIONS]
    topics, t0 = _read(out, "/test_point", "/control_surfaces")
    events = [(round((t - t0) * 1e-9, 6), m.key, m.value) for t, m in topics["/test_point"]]
    assert events == [(round(float(r[k]), 6), r["maneuver"], v) for r in rows for k, v in (("start", "start"),
                                                                                          ("end", "stop"))]
    # The recorded surfaces are the simulation's: the elevator moves exactly inside the truth.
    stamps = [t for t, _ in topics["/control_surfaces"]]
    de = np.array([m.position[0] for _, m in topics["/control_surfaces"]])
    assert stamps == want.streams.control_surfaces[0].tolist()
    np.testing.assert_array_equal(de, want.streams.control_surfaces[1][:, 0])
    # make-bag refuses to write over what it did not make.
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    assert cli.main(["make-bag", "--flight", "--out", str(other)]) != 0
    assert "not empty" in capsys.readouterr().err and (other / "notes.txt").read_text() == "keep"
    assert cli.main(["make-bag", "--flight", "--campaign", "2", "--out", str(tmp_path / "x")]) == 2
    assert "give one" in capsys.readouterr().err


def test_the_input_power_is_the_window_variance_of_the_low_passed_surfaces():
    """P against scipy's first-order filter and numpy's variance over the last window."""
    from scipy import signal

    rng = np.random.default_rng(9)
    dt, n = 0.01, 6000  # more messages than the running sums go between exact sums
    x = np.cumsum(rng.standard_normal((n, 2)), axis=0) * 1e-3 + 0.05
    options = ManeuverOptions()
    d = ManeuverDetector(options)
    for k in range(n):
        d.update(round(k * dt * 1e9), x[k])
    a = -math.expm1(-2 * math.pi * options.f_max * dt)
    y = np.column_stack([signal.lfilter([a], [1, a - 1], x[:, j], zi=[(1 - a) * x[0, j]])[0] for j in range(2)])
    held = y[-round(options.window / dt) - 1:]  # the window holds its two ends
    assert d.power == pytest.approx(float(np.var(held, axis=0).sum()), rel=1e-9)
