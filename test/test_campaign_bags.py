"""make-bag --campaign (bags.write_campaign_bags): a simulated campaign of replay bags, each
the seeded maneuver simulation.simulate_campaign gives, with its settings in campaign.yaml.
No ROS."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from rls_uncertainty import cli
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.offline.bags import read_inputs, write_campaign_bags
from rls_uncertainty.simulation.t2 import RESPONSES, campaign_seeds, simulate_sensor_streams
from rls_uncertainty.simulation.turbulence import LOW_ALTITUDE_SIGMA_W, DrydenVertical


def test_each_bag_holds_its_seeded_maneuver_in_turbulence(tmp_path):
    gust = DrydenVertical(LOW_ALTITUDE_SIGMA_W["severe"], 389.0)
    paths = write_campaign_bags(tmp_path / "c", 2, gust, band_level=0.1, band_limited_on=RESPONSES, seed=7)
    assert [p.name for p in paths] == ["m001", "m002"]
    manifest = yaml.safe_load((tmp_path / "c" / "campaign.yaml").read_text())
    assert manifest["maneuvers"] == 2 and manifest["seed"] == 7 and manifest["gust_sigma_w_m_s"] == gust.sigma
    assert manifest["band_limited_on"] == list(RESPONSES) and manifest["bags"] == ["m001", "m002"]
    want = simulate_sensor_streams(0.1, campaign_seeds(7, 2)[1], gust=gust, band_limited_on=RESPONSES)
    messages, _ = read_inputs(paths[1])
    imu = [(stamp, m) for kind, stamp, m in messages if kind == "imu"]
    assert [s for s, _ in imu] == want.imu[0].tolist()
    got = np.array([[m.angular_velocity.y, m.linear_acceleration.z] for _, m in imu])
    np.testing.assert_array_equal(got, want.imu[1][:, [1, 5]])


def test_the_command_needs_an_intensity_and_takes_a_word_or_a_number(tmp_path, capsys):
    assert cli.main(["make-bag", "--campaign", "2", "--out", str(tmp_path / "c")]) == 2
    assert "--campaign needs --gust-intensity" in capsys.readouterr().err
    assert cli.main(["make-bag", "--gust-intensity", "light", "--out", str(tmp_path / "c")]) == 2
    assert "give --campaign N" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "stormy", "--out", str(tmp_path / "c")])
    assert "light, moderate, severe" in capsys.readouterr().err
    assert cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "1.2", "--noise", "5", "--out",
                     str(tmp_path / "c")]) == 0
    manifest = yaml.safe_load((tmp_path / "c" / "campaign.yaml").read_text())
    assert manifest["gust_sigma_w_m_s"] == 1.2 and manifest["band_limited_on"] == list(RESPONSES)
    with pytest.raises(ConfigError, match="--campaign"):
        write_campaign_bags(tmp_path / "d", 0, DrydenVertical(1.0, 300.0))


def test_pitch_gust_off_writes_the_maneuvers_without_it_and_says_so(tmp_path, capsys):
    """``--pitch-gust off``: the bags hold the maneuvers simulated without the pitch gust (the
    vertical gust on alpha alone), ``on`` (the default) with it; campaign.yaml records which."""
    gust = DrydenVertical(LOW_ALTITUDE_SIGMA_W["severe"], 389.0)

    def gyro(path):
        messages, _ = read_inputs(path)
        return np.array([m.angular_velocity.y for kind, _, m in messages if kind == "imu"])

    seed = campaign_seeds(2010, 1)[0]
    for word, pitch in (("off", False), ("on", True)):
        out = tmp_path / word
        assert cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "severe", "--seed", "2010",
                         "--pitch-gust", word, "--out", str(out)]) == 0
        assert ("no pitch gust" in capsys.readouterr().out) is not pitch
        manifest = yaml.safe_load((out / "campaign.yaml").read_text())
        assert manifest["pitch_gust"] is pitch
        want = simulate_sensor_streams(0.2, seed, gust=DrydenVertical(gust.sigma, manifest["gust_scale_length_m"]),
                                       band_limited_on=RESPONSES, pitch_gust=pitch)
        np.testing.assert_array_equal(gyro(out / "m001"), want.imu[1][:, 1])
    assert not np.array_equal(gyro(tmp_path / "off" / "m001"), gyro(tmp_path / "on" / "m001"))
    assert cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "severe", "--pitch-gust", "maybe",
                     "--out", str(tmp_path / "bad")]) == 2
    assert "--pitch-gust must be one of ['on', 'off']" in capsys.readouterr().err
    assert cli.main(["make-bag", "--pitch-gust", "off", "--out", str(tmp_path / "one")]) == 2
    assert "--pitch-gust sets the turbulence of a simulated campaign" in capsys.readouterr().err


def test_the_excitation_topic_is_the_multisine_the_simulation_injected(tmp_path):
    """Each campaign bag carries the designed excitation on /fcc/excitation: the surfaces'
    message type, names and stamps, both elevator halves Eq. 24 with Table 2's elevator design
    (at --input-amplitude times its amplitude) from 0.5 s to the end of its period and 0
    outside, the other surfaces 0; noise-free, while the surfaces carry the sensor noise."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import EXCITATION_TOPIC, typestore
    from rls_uncertainty.simulation.multisine import T2_TABLE2

    gust = DrydenVertical(LOW_ALTITUDE_SIGMA_W["moderate"], 389.0)
    (path,) = write_campaign_bags(tmp_path / "c", 1, gust, seed=3, input_amplitude=0.5)
    with AnyReader([path], default_typestore=typestore()) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert conns[EXCITATION_TOPIC].msgtype == conns["/control_surfaces"].msgtype == "sensor_msgs/msg/JointState"
        got = {topic: [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages(connections=[c])]
               for topic, c in conns.items() if topic in (EXCITATION_TOPIC, "/control_surfaces")}
        start = reader.start_time  # the first IMU sample, t = 0 of the simulation
    excitation, surfaces = got[EXCITATION_TOPIC], got["/control_surfaces"]
    assert [t for t, _ in excitation] == [t for t, _ in surfaces]
    assert [m.header.stamp for _, m in excitation] == [m.header.stamp for _, m in surfaces]
    assert all(list(m.name) == list(surfaces[0][1].name) for _, m in excitation)
    t = np.array([(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec - start) * 1e-9 for _, m in excitation])
    design = T2_TABLE2["elevator"]
    tau = t - 0.5
    on = (tau >= 0) & (tau <= design.period)
    arg = 2 * np.pi * np.outer(tau, design.harmonics) / design.period + np.asarray(design.phases)
    want = np.where(on, 0.5 * design.amplitude * (np.sin(arg) @ np.asarray(design.rel_amplitudes)), 0.0)
    positions = np.array([m.position for _, m in excitation])
    np.testing.assert_allclose(positions[:, 0], want, rtol=0, atol=1e-12 * design.amplitude)
    np.testing.assert_array_equal(positions[:, 1], positions[:, 0])
    np.testing.assert_array_equal(positions[:, 2:], 0.0)
    assert on.sum() > 0.8 * on.size and np.abs(positions[:, 0]).max() > 0.2 * design.amplitude
    measured = np.array([m.position[0] for _, m in surfaces])
    assert 0 < np.std(measured - positions[:, 0]) < 0.2 * np.std(positions[:, 0])  # the sensor noise
