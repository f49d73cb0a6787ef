"""Test session set-up: DDS stays on loopback and each run gets its own ROS domain; the
shared flight recordings are read from ../shared/flight_data (or $RLS_FLIGHT_DATA).

Flight-data policy. A test needs the recordings if it carries ``@pytest.mark.flight_data``,
or if its code or a fixture it uses names ``FLIGHT_DATA`` (those are marked automatically). When the
directory is absent such a test is skipped, with the path it looked for as the reason: a
copy without ../shared (a colcon workspace, a tarball) still tests everything else. Under
``RLS_REQUIRE_FLIGHT_DATA=1`` (set by .ci/run) the same situation is a failure instead, so CI
can never pass by skipping the real-data tests.

Parallel runs. The README's test command runs the suite on two pytest-xdist workers (``-n 2
--dist loadfile``: a module's tests, and its module-scoped fixtures, on one worker). Each worker
has a ROS domain of its own, so the DDS tests of two modules never hear each other: the first
worker (or a run without xdist) the run's ``ROS_DOMAIN_ID``, worker N the first domain from
``ROS_DOMAIN_ID + 100 N`` on (modulo 233) that is neither the run's nor one of
``$RLS_TEST_DOMAINS`` (the live tests' private domains) and that it can lock the way a live
test's claim does (:func:`rls_uncertainty.testing.domain.lock_domain`), held while it runs.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path
from types import CodeType

import pytest

# A test run started as a background job of a non-interactive shell inherits SIGINT ignored, and
# so would every node, command and probe it starts; the tests of Ctrl-C need it to mean Ctrl-C.
# (A caught signal is reset to its default in the programs a process starts.)
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))


def _worker_domain() -> object:
    """Worker N's own ROS domain (N >= 1; module docstring), set as ``ROS_DOMAIN_ID``; its lock,
    kept while the worker runs (None for the first worker)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    n = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    if n == 0:
        return None
    from rls_uncertainty.testing.domain import domain_ids, lock_domain

    run = int(os.environ["ROS_DOMAIN_ID"])
    private = set(domain_ids(os.environ.get("RLS_TEST_DOMAINS", "43-49")))
    ids = [d for d in ((run + 100 * n + k) % 233 for k in range(233)) if d != run and d not in private]
    claim = lock_domain(ids)
    if claim is None:
        raise RuntimeError(f"pytest-xdist worker {worker}: every ROS domain's lock is held")
    os.environ["ROS_DOMAIN_ID"] = str(claim.domain)
    return claim


_WORKER_DOMAIN = _worker_domain()

ROOT = Path(__file__).resolve().parents[1]
FLIGHT_DATA = Path(os.environ.get("RLS_FLIGHT_DATA") or ROOT.parent / "shared" / "flight_data").resolve()
REQUIRE_FLIGHT_DATA = os.environ.get("RLS_REQUIRE_FLIGHT_DATA", "") not in ("", "0")
sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture(scope="module")
def ros():
    """rclpy initialised for the DDS tests of one module, shut down after them (such a module
    says ``pytestmark = pytest.mark.usefixtures("ros")``)."""
    import rclpy

    rclpy.init()
    yield
    rclpy.try_shutdown()


def require_flight_data() -> None:
    """Skip the calling test (fail it under RLS_REQUIRE_FLIGHT_DATA) if the recordings are absent."""
    if FLIGHT_DATA.is_dir():
        return
    reason = (
        f"flight recordings not found at {FLIGHT_DATA} "
        "(put shared/flight_data beside the checkout, or set RLS_FLIGHT_DATA)"
    )
    if REQUIRE_FLIGHT_DATA:
        pytest.fail(f"{reason}; RLS_REQUIRE_FLIGHT_DATA is set, so a missing recording fails", pytrace=False)
    pytest.skip(reason)


def _names_flight_data(code: CodeType) -> bool:
    """Whether a function's code (or a lambda or comprehension inside it) reads FLIGHT_DATA."""
    return "FLIGHT_DATA" in code.co_names or any(
        _names_flight_data(c) for c in code.co_consts if isinstance(c, CodeType)
    )


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "flight_data: needs the recordings in ../shared/flight_data or $RLS_FLIGHT_DATA; skipped when "
        "absent, a failure when RLS_REQUIRE_FLIGHT_DATA=1",
    )


def _uses_flight_data(item: pytest.Item) -> bool:
    functions = [getattr(item, "function", None)]
    fixtures = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
    functions += [defs[-1].func for defs in fixtures.values() if defs]
    codes = [getattr(f, "__code__", None) for f in functions]
    return any(code is not None and _names_flight_data(code) for code in codes)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if _uses_flight_data(item):
            item.add_marker(pytest.mark.flight_data)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    # Before any fixture runs: a module-scoped fixture converting the recordings would
    # otherwise fail with FileNotFoundError instead of the reason above.
    if item.get_closest_marker("flight_data") is not None:
        require_flight_data()
