"""executors.py: jobs in local processes or on a Dask cluster give their results in the order
of the jobs, identical whichever executor ran them; a worker killed in the middle loses no
job; an unreachable scheduler is one error within the timeout. The cluster is a LocalCluster
on 127.0.0.1 (two worker processes, no dashboard), closed at the end. No ROS."""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import time
from pathlib import Path

import pytest

from rls_uncertainty import cli
from rls_uncertainty.campaign import CampaignSettings, Maneuver, run_campaign
from rls_uncertainty.campaign.run import run_maneuver
from rls_uncertainty.errors import ConfigError, SchedulerUnreachable
from rls_uncertainty.executors import DaskCluster, LocalProcesses, Lost, executor_for
from rls_uncertainty.settings import node_config, pipeline_config
from rls_uncertainty.testing import parameters

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def jobs():
    """Ten maneuvers: spans of the bundled bag, each different."""
    p = parameters("t2")
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    return [(Maneuver(f"m{i}", str(BUNDLED), 0.1 * i, 11.0 + 0.05 * i), settings) for i in range(10)]


@pytest.fixture(scope="module")
def serial(jobs):
    return LocalProcesses(1).run(run_maneuver, jobs)


@pytest.fixture(scope="module")
def cluster():
    from distributed import Client, LocalCluster

    # dashboard_address=None turns the dashboard off but not the scheduler's HTTP server (health and
    # metrics routes), which then takes port 8787; on an ephemeral loopback port two test runs
    # side by side do not contend for it.
    c = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                     scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
    client = Client(c, set_as_default=False)  # the executor must work without a default client
    try:
        yield c, client
    finally:
        client.close()
        c.close()


def _same(a, b):
    return [(r.name, r.rows) for r in a] == [(r.name, r.rows) for r in b]


def test_local_processes_return_the_jobs_in_order_identical_to_one_process(jobs, serial):
    ticks = []
    got = LocalProcesses(2).run(run_maneuver, jobs, lambda i, n: ticks.append((i, n)))
    assert _same(got, serial) and [r.name for r in got] == [f"m{i}" for i in range(10)]
    assert ticks == [(i, 10) for i in range(1, 11)]


def test_a_local_worker_killed_in_the_middle_loses_no_job(jobs, serial):
    killed = []

    def kill_one(i, n):
        if not killed:
            child = multiprocessing.active_children()[0]  # a worker of the pool
            os.kill(child.pid, signal.SIGKILL)
            killed.append((child.pid, i, n))

    got = LocalProcesses(2).run(run_maneuver, jobs, kill_one)
    assert killed and killed[0][1] < 10  # killed while jobs were left
    assert _same(got, serial)


def _die(_job: int) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_job_whose_worker_dies_every_time_is_lost_not_raised():
    got = LocalProcesses(2).run(_die, [1, 2])
    assert all(isinstance(r, Lost) and "died" in r.why for r in got)


def test_a_dask_cluster_gives_the_local_results_bit_for_bit(cluster, jobs, serial):
    c, _client = cluster
    got = DaskCluster(c.scheduler_address).run(run_maneuver, jobs)
    assert _same(got, serial)
    campaign = run_campaign([m for m, _ in jobs], jobs[0][1], DaskCluster(c.scheduler_address))
    local = run_campaign([m for m, _ in jobs], jobs[0][1], LocalProcesses(2))
    assert campaign.table == local.table and campaign.summary() == local.summary()


def test_a_dask_worker_killed_in_the_middle_loses_no_job(cluster, jobs, serial):
    c, client = cluster
    before = client.run(os.getpid)
    killed = []

    def kill_one(i, n):
        if not killed:
            pid = sorted(before.values())[0]
            os.kill(pid, signal.SIGKILL)
            killed.append((pid, i))

    got = DaskCluster(c.scheduler_address).run(run_maneuver, jobs, kill_one)
    assert killed and killed[0][1] < 10
    assert _same(got, serial)
    deadline = time.monotonic() + 60
    while len(client.scheduler_info()["workers"]) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)  # the nanny restarts the worker for the next test
    assert killed[0][0] not in client.run(os.getpid).values()


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_is_one_error_within_the_timeout(capsys, tmp_path):
    address = f"tcp://127.0.0.1:{_closed_port()}"
    t0 = time.monotonic()
    with pytest.raises(SchedulerUnreachable, match=f"cannot reach the Dask scheduler at {address} within 2 s"):
        DaskCluster(address, timeout=2).run(run_maneuver, [])
    assert time.monotonic() - t0 < 30
    assert cli.main(["campaign", str(BUNDLED), "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("rls-uncertainty campaign: error: cannot reach the Dask scheduler")
    assert not (tmp_path / "out").exists()


def test_workers_and_a_scheduler_together_are_refused():
    with pytest.raises(ConfigError, match="drop --jobs"):
        executor_for("tcp://127.0.0.1:8786", 2, "--jobs")
    with pytest.raises(ConfigError, match="--workers"):
        LocalProcesses(0)


def test_the_test_cluster_serves_on_loopback_ports_of_its_own(cluster):
    # Tests start servers on 127.0.0.1 only; the scheduler's HTTP server must not take the
    # fixed dashboard port a second test run (or a user's dashboard) would also want.
    from urllib.parse import urlsplit

    c, _client = cluster
    url = urlsplit(c.dashboard_link)
    assert url.hostname == "127.0.0.1" and url.port not in (None, 8787)
