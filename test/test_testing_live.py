"""The live node under test (rls_uncertainty/testing/live.py): the estimator node in its own
process on a private domain (claimed among $RLS_TEST_DOMAINS, default 43-49: this machine's
sessions use 42-49), the bundled bag played to it with acknowledgements, its outputs paired by
stamp: bit-identical, sample by sample, to the in-process replay with the same parameters (one
machine); failures say what was seen, with the node's log path and its last lines, and the wait
for the end runs out only after its timeout without progress; a domain with another node on it
is passed over, and a second estimator on the domain stops the run in one line."""

import os
import re
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError, LiveTimeout
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.testing import (
    REPLAY_PARAMETERS,
    EstimatorProcess,
    claim_domain,
    live,
    parameters,
    play_to_node,
    replay_bag,
)
from rls_uncertainty.testing.domain import domain_ids

from conftest import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"
DOMAINS = domain_ids(os.environ.get("RLS_TEST_DOMAINS", "43-49"))


@pytest.fixture(scope="module")
def domain():
    with claim_domain(DOMAINS) as claim:
        yield claim.domain


def test_the_live_node_publishes_what_the_replay_computes_sample_by_sample(tmp_path, domain):
    node = EstimatorProcess(parameters("t2"), domain=domain, directory=tmp_path)
    try:
        live = play_to_node(BUNDLED, node)
    finally:
        assert node.stop() == 0, node.log()
    assert node.parameters == {**REPLAY_PARAMETERS, **parameters("t2")}
    offline = replay_bag(BUNDLED, node.parameters)
    # 591 samples used, the first ones held back by the publication rule (n + 2 x 50 samples)
    assert live.parameters == offline.parameters and live.estimates == offline.estimates > 450
    for name in offline.parameters:
        for got, want in zip(live.series(name), offline.series(name), strict=True):
            assert np.array_equal(got, want), name  # bit for bit: one machine, one pipeline
        assert live.final(name) == offline.final(name)
    got, want = live.counters(), offline.counters()
    # The node never reaches the end of the data: its last samples wait for their derivative
    # (pending); the replay counts them as end_of_data.
    assert got["samples_pending"] == want["samples_rejected"].pop("end_of_data")
    got["samples_pending"] = 0
    assert got == want
    assert live.n_messages == 4920 and live.data_seconds == pytest.approx(11.995)


def test_the_live_nodes_frequency_domain_topics_are_the_replays_bit_for_bit(tmp_path, domain):
    """estimator.method both, estimates every 3 samples: the node's ~/M/frequency/* arrays, paired
    by their stamps, are the in-process replay's frequency-domain series (and its time-domain
    ones still are), bit for bit on one machine."""
    params = parameters("t2", {"estimator.method": "both", "frequency.every": 3})
    node = EstimatorProcess(params, domain=domain, directory=tmp_path)
    try:
        live = play_to_node(BUNDLED, node)
    finally:
        assert node.stop() == 0, node.log()
    offline = replay_bag(BUNDLED, node.parameters)
    assert live.methods == offline.methods == ("time", "frequency")
    assert live.frequency_parameter_names == offline.frequency_parameter_names
    assert live.estimates == offline.estimates > 450  # after the publication rule, as above
    for name in offline.parameters:
        for got, want in zip(live.series(name), offline.series(name), strict=True):
            assert np.array_equal(got, want), name
    for names in offline.frequency_parameter_names:
        for name in names:
            want = offline.series(name, method="frequency")
            assert len(want.stamps_ns) > 150 and np.all(np.diff(want.stamps_ns) == 3 * 20_000_000)
            for got, expected in zip(live.series(name, method="frequency"), want, strict=True):
                assert np.array_equal(got, expected), name
            assert live.final(name, method="frequency") == offline.final(name, method="frequency")


def test_a_bad_parameter_is_refused_before_a_node_starts(tmp_path):
    with pytest.raises(ConfigError, match=r"estimator\.lag_span"):
        EstimatorProcess({"estimator.lag_span": -5}, domain=DOMAINS[0], directory=tmp_path)
    assert not list(tmp_path.glob("*.log"))


def test_a_node_that_dies_is_named_with_its_log(tmp_path, domain):
    node = EstimatorProcess(parameters("t2"), domain=domain, directory=tmp_path)
    node.proc.kill()
    node.proc.wait()
    try:
        with pytest.raises(LiveTimeout, match=f"estimator node exited.*{tmp_path}"):
            play_to_node(BUNDLED, node, timeout=60)
    finally:
        node.stop()


def test_a_domain_with_another_node_on_it_is_passed_over_or_refused_in_one_line(tmp_path):
    """A node that takes no lock (another tool, one left running) is seen on the graph."""
    with claim_domain(DOMAINS) as claim:
        node = EstimatorProcess(parameters("t2"), domain=claim.domain, directory=tmp_path)
    try:  # the lock released, the node still there
        with pytest.raises(ConfigError) as refused:
            claim_domain([claim.domain], probe=60.0)
        assert str(refused.value) == (f"no free ROS domain for the node under test: {claim.domain} has node(s) "
                                      "/rls_estimator; pass other domain ids")
    finally:
        assert node.stop() == 0, node.log()


def test_a_second_estimator_on_the_domain_stops_the_run_in_one_line(tmp_path, domain):
    """Two nodes of one name on the domain (the fixtures refuse it; the API can be misused):
    the run stops once both publish, instead of collecting their mixed samples."""
    nodes = [EstimatorProcess(parameters("t2"), domain=domain, directory=tmp_path, name=f"twin{i}") for i in range(2)]
    try:
        deadline = time.monotonic() + 120
        while not all("estimating" in node.log() for node in nodes):  # both up before the play
            assert time.monotonic() < deadline and all(node.running for node in nodes), [n.log() for n in nodes]
            time.sleep(0.05)
        with pytest.raises(LiveTimeout, match=f"ROS domain {domain}: 2 nodes publish /rls_estimator/sample_stamp: "
                                              "another node named rls_estimator runs on this domain"):
            play_to_node(BUNDLED, nodes[0], timeout=120)
    finally:
        for node in nodes:
            assert node.stop() == 0, node.log()


def test_a_run_that_never_ends_says_what_was_seen_with_the_nodes_log(tmp_path, domain, monkeypatch):
    """The end condition held back (the run itself is real): LiveTimeout once nothing has grown
    for the timeout, saying what the player published and the node received, the samples used
    and stamps arrived, with the node's log path and its last lines."""
    ended = []
    complete = live._complete

    def never(*args):
        real = complete(*args)
        return lambda: bool(real() and ended.append(time.monotonic()))

    monkeypatch.setattr(live, "_complete", never)
    node = EstimatorProcess(parameters("t2"), domain=domain, directory=tmp_path)
    try:
        with pytest.raises(LiveTimeout) as timed_out:
            play_to_node(BUNDLED, node, timeout=30)
        raised = time.monotonic()
    finally:
        assert node.stop() == 0, node.log()
    said = str(timed_out.value)
    assert ended and raised - ended[0] >= 30 - 1, said  # after the end: the timeout without progress
    assert said.startswith("no complete outputs (published {"), said
    assert " within 30 s of no progress; the node's log: " + str(node.log_file) + "\n" in said
    assert said.endswith(node.log()[-2000:]) and "estimating" in said.split("\n", 1)[1]
    counts = Counter(kind for kind, _stamp, _msg in read_inputs(BUNDLED)[0])
    published = re.search(r"published (\{.*?\}) to subscriptions matched", said).group(1)
    received = re.search(r"the node received (\{.*?\});", said).group(1)
    assert eval(published) == eval(received) == dict(counts), said
    used = int(re.search(r"it used (\d+) samples", said).group(1))
    assert used > 450 and f"{used} sample stamps arrived here" in said, said


def test_discovery_that_does_not_finish_in_time_says_how_far_it_got(tmp_path, domain):
    node = EstimatorProcess(parameters("t2"), domain=domain, directory=tmp_path)
    try:  # a node that has only just started is not discovered within 0.1 s
        with pytest.raises(LiveTimeout, match=r"^no discovery of the node's inputs and outputs \(\d+ of the \d+ output "
                                              r"subscriptions matched the node's publishers; the node publishes to .* "
                                              r"of them; publishers the node counts per input: imu \d+, .*; "
                                              r"subscriptions matched per input here: imu \d+, .*; \d+ report\(s\) "
                                              r"from the node\) within 0.1 s; the node's log: " + re.escape(
                                                  str(Path(tmp_path) / "estimator.log"))):
            play_to_node(BUNDLED, node, timeout=0.1)
    finally:
        node.stop()
