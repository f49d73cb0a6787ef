"""pytest fixtures for bag-replay tests of the estimator (docs/testing.md).

Enable them with ``pytest -p rls_uncertainty.testing.plugin``, ``addopts = -p
rls_uncertainty.testing.plugin`` in the suite's ``pytest.ini``, or ``pytest_plugins =
["rls_uncertainty.testing.plugin"]`` in its top-level ``conftest.py``:

* ``rls_domain`` (session): the private ROS domain the node under test runs on, claimed for
  the session (:func:`.domain.claim_domain`: a lock no other session on the machine can take
  and no other node seen on its graph) among the ids ``--rls-domains FIRST-LAST`` (ini
  ``rls_domains``; default 42-49) other than the environment's ``ROS_DOMAIN_ID``. The search
  starts at the first id (with pytest-xdist, worker N starts at the N-th) and takes the next
  free one; when none is free every test that needs it errors with one line naming each
  domain's holder and the option to change.
* ``rls_estimator`` (function): ``start(config=None, **overrides) -> EstimatorProcess``
  starts the estimator node in a process of its own on ``rls_domain``
  (:class:`.live.EstimatorProcess`; ``config`` and ``overrides`` as for
  :func:`.offline.replay_bag`); the node dies with the test process whatever ends it, and is
  stopped after the test, in a ``finally``, whether it passed or not. One node at a time per
  fixture: two nodes of one name on a domain would both hear the bag, so ``start`` while a
  node it started still runs fails the test in one line (stop the first, ``node.stop()``, to
  start another).
* ``rls_play`` (function): ``play(bag, node, rate=0.0, timeout=120.0) -> ReplayResult``
  plays a bag to a started node with acknowledgements and collects its outputs
  (:func:`.live.play_to_node`).
* ``rls_live_replay`` (function): ``run(bag, config=None, rate=0.0, timeout=120.0,
  **overrides) -> ReplayResult``: the three above in one call, the node stopped on return.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ..errors import ConfigError
from ..offline.results import ReplayResult
from .domain import DEFAULT_DOMAINS, claim_domain
from .domain import domain_ids as domains
from .live import EstimatorProcess, play_to_node
from .offline import Config, parameters

__all__ = ["rls_domain", "rls_estimator", "rls_play", "rls_live_replay", "domains"]

_ADVICE = "give other ids with --rls-domains FIRST-LAST (or the ini option rls_domains)"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addini("rls_domains", f"ROS domain ids the estimator fixtures may use, FIRST-LAST (default "
                                 f"{DEFAULT_DOMAINS})", default=DEFAULT_DOMAINS)
    parser.getgroup("rls_uncertainty").addoption(
        "--rls-domains", metavar="FIRST-LAST", help="ROS domain ids the estimator fixtures may use (overrides the "
                                                    f"ini option rls_domains; default {DEFAULT_DOMAINS})")


@pytest.fixture(scope="session")
def rls_domain(request: pytest.FixtureRequest) -> Iterator[int]:
    spec = request.config.getoption("--rls-domains") or request.config.getini("rls_domains")
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    try:
        ids = domains(str(spec))
        start = index % len(ids)
        claim = claim_domain(ids[start:] + ids[:start], advice=_ADVICE)
    except ConfigError as exc:
        refused = str(exc)
    else:
        refused = ""
    if refused:  # outside the except: no "during handling of the above exception" in the report
        pytest.fail(f"rls_domain: {refused}", pytrace=False)
    try:
        yield claim.domain
    finally:
        claim.release()


@pytest.fixture
def rls_estimator(rls_domain: int, tmp_path: Path) -> Iterator[Callable[..., EstimatorProcess]]:
    started: list[EstimatorProcess] = []

    def start(config: Config = None, **overrides: Any) -> EstimatorProcess:
        running = [n for n in started if n.running]
        if running:
            pytest.fail(f"rls_estimator: one node at a time: {running[0].log_file.stem} (pid {running[0].proc.pid}) "
                        f"still runs on ROS domain {rls_domain}, and a second node of its name would hear the same "
                        "bag; stop it first (node.stop()) or use it", pytrace=False)
        node = EstimatorProcess(parameters(config, overrides), domain=rls_domain, directory=tmp_path,
                                name=f"estimator{len(started)}")
        started.append(node)
        return node

    try:
        yield start
    finally:
        for node in started:
            node.stop()


@pytest.fixture
def rls_play() -> Callable[..., ReplayResult]:
    return play_to_node


@pytest.fixture
def rls_live_replay(rls_estimator: Callable[..., EstimatorProcess]) -> Callable[..., ReplayResult]:
    def run(bag: str | Path, config: Config = None, *, rate: float = 0.0, timeout: float = 120.0,
            **overrides: Any) -> ReplayResult:
        node = rls_estimator(config, **overrides)
        try:
            return play_to_node(bag, node, rate=rate, timeout=timeout)
        finally:
            node.stop()

    return run
