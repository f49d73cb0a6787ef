"""pytest fixtures for bag-replay tests of the estimator (docs/testing.md).

Enable them with ``pytest -p rls_uncertainty.testing.plugin``, ``addopts = -p
rls_uncertainty.testing.plugin`` in the suite's ``pytest.ini``, or ``pytest_plugins =
["rls_uncertainty.testing.plugin"]`` in its top-level ``conftest.py``:

* ``rls_domain`` (session): the private ROS domain the node under test runs on. The first of
  the ids ``--rls-domains FIRST-LAST`` (ini ``rls_domains``; default 42-49) that is not the
  environment's ``ROS_DOMAIN_ID``; with pytest-xdist, worker N takes the N-th of them (modulo
  their number), so parallel workers do not hear each other.
* ``rls_estimator`` (function): ``start(config=None, **overrides) -> EstimatorProcess``
  starts the estimator node in a process of its own on ``rls_domain``
  (:class:`.live.EstimatorProcess`; ``config`` and ``overrides`` as for
  :func:`.offline.replay_bag`); every node started is stopped after the test, in a
  ``finally``, whether it passed or not. One node at a time per domain: two nodes of one
  name on a domain would both hear the bag.
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
from .live import EstimatorProcess, play_to_node
from .offline import Config, parameters

__all__ = ["rls_domain", "rls_estimator", "rls_play", "rls_live_replay", "domains"]

DEFAULT_DOMAINS = "42-49"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addini("rls_domains", f"ROS domain ids the estimator fixtures may use, FIRST-LAST (default "
                                 f"{DEFAULT_DOMAINS})", default=DEFAULT_DOMAINS)
    parser.getgroup("rls_uncertainty").addoption(
        "--rls-domains", metavar="FIRST-LAST", help="ROS domain ids the estimator fixtures may use (overrides the "
                                                    f"ini option rls_domains; default {DEFAULT_DOMAINS})")


def domains(spec: str, ambient: str | None = None) -> list[int]:
    """The domain ids of ``FIRST-LAST`` (or one id) other than ``ambient`` (the environment's
    ``ROS_DOMAIN_ID``, 0 when unset); a :class:`..errors.ConfigError` when none is left."""
    first, _, last = spec.strip().partition("-")
    try:
        lo, hi = int(first), int(last or first)
    except ValueError:
        raise ConfigError(f"rls_domains: expected FIRST-LAST (e.g. {DEFAULT_DOMAINS}), got {spec!r}") from None
    if not 0 <= lo <= hi <= 232:
        raise ConfigError(f"rls_domains: ROS domain ids are 0 to 232 with FIRST <= LAST, got {spec!r}")
    ambient = ambient if ambient is not None else os.environ.get("ROS_DOMAIN_ID", "0")
    left = [d for d in range(lo, hi + 1) if str(d) != ambient.strip()]
    if not left:
        raise ConfigError(f"rls_domains {spec!r}: only the environment's own ROS_DOMAIN_ID; give others")
    return left


@pytest.fixture(scope="session")
def rls_domain(request: pytest.FixtureRequest) -> int:
    spec = request.config.getoption("--rls-domains") or request.config.getini("rls_domains")
    ids = domains(str(spec))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    return ids[index % len(ids)]


@pytest.fixture
def rls_estimator(rls_domain: int, tmp_path: Path) -> Iterator[Callable[..., EstimatorProcess]]:
    started: list[EstimatorProcess] = []

    def start(config: Config = None, **overrides: Any) -> EstimatorProcess:
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
