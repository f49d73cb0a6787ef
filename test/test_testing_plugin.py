"""The pytest fixtures (rls_uncertainty/testing/plugin.py), used as a user's suite uses them:
examples/user_tests (outside test/, the plugin enabled in its pytest.ini) runs in a pytest of
its own, with the five-line test of docs/testing.md on the bundled bag and on the Twin Otter
replay; a failing test's node is stopped all the same; the domain choice: two sessions at
once on one range each claim their own domain (or the second is refused in one line), the node
dies with a test process killed by SIGTERM or SIGKILL, and one node at a time per fixture.
Nodes run on the domains of $RLS_TEST_DOMAINS (default 43-49: this machine's sessions use
42-49)."""

import os
import re
import signal
import subprocess
import sys
import time

import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.testing.plugin import domains

from conftest import FLIGHT_DATA, ROOT

EXAMPLES = ROOT / "examples" / "user_tests"
DOMAINS = os.environ.get("RLS_TEST_DOMAINS", "43-49")


def _command(args, domains=DOMAINS):
    return [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rls-domains", domains, *args]


def _pytest(args, cwd, domains=DOMAINS, **env):
    return subprocess.run(_command(args, domains), cwd=cwd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "RLS_FLIGHT_DATA": str(FLIGHT_DATA), **env})


def test_the_example_user_suite_passes_on_the_bundled_bag_and_the_twin_otter_replay():
    run = _pytest(["-rA", str(EXAMPLES)], ROOT, RLS_REQUIRE_FLIGHT_DATA="1")
    assert run.returncode == 0, run.stdout + run.stderr
    passed = set(re.findall(r"PASSED \S+::(\w+)", run.stdout))
    assert passed == {"test_t2_cm_alpha_is_within_two_corrected_standard_errors",
                      "test_twin_otter_cm_alpha_is_within_two_corrected_standard_errors",
                      "test_the_same_check_in_process_without_ros",
                      "test_every_message_is_used_and_the_flags_hold_once_converged"}, run.stdout


def test_the_docs_five_line_test_is_the_one_the_suite_runs():
    docs = (ROOT / "docs" / "testing.md").read_text()
    example = (EXAMPLES / "test_maneuvers.py").read_text()
    block = re.search(r"```python\n(def test_t2_cm_alpha[^`]*?)```", docs)
    assert block, "docs/testing.md shows the five-line test"
    assert block.group(1) in example
    assert len(block.group(1).strip().splitlines()) == 4  # plus its import: five lines


FAILING = """
from rls_uncertainty.testing import bundled_bag


def test_fails_after_starting_a_node(rls_estimator, rls_play, tmp_path):
    node = rls_estimator("t2")
    (tmp_path.parent / "pid").write_text(str(node.proc.pid))
    rls_play(bundled_bag(), node)
    assert False, "on purpose"
"""


def test_a_failing_tests_node_is_stopped_all_the_same(tmp_path):
    (tmp_path / "test_user.py").write_text(FAILING)
    run = _pytest(["-p", "rls_uncertainty.testing.plugin", "--basetemp", str(tmp_path / "tmp"), "test_user.py"],
                  tmp_path)
    assert run.returncode == 1 and "on purpose" in run.stdout, run.stdout + run.stderr
    pid = int((tmp_path / "tmp" / "pid").read_text())
    deadline = time.monotonic() + 30
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pid)


def _alive(pid):
    try:
        os.kill(pid, 0)
        with open(f"/proc/{pid}/stat") as fh:  # a zombie (exited, not yet reaped by init) is not running
            return fh.read().split(") ")[1][0] != "Z"
    except (ProcessLookupError, FileNotFoundError):
        return False


def _wait(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.05)


def _kill_ours(pid, marker):
    """SIGKILL ``pid`` if it is still a process whose command line names ``marker`` (ours)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            if str(marker).encode() in fh.read():
                os.kill(pid, signal.SIGKILL)
    except (ProcessLookupError, FileNotFoundError):
        pass


def _start(args, cwd, domains, **env):
    """A pytest of its own with the plugin, started and left running."""
    return subprocess.Popen(_command(["-p", "rls_uncertainty.testing.plugin", *args], domains), cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env={**os.environ, **env})


def _first_two():
    ids = domains(DOMAINS)
    assert len(ids) >= 2, f"RLS_TEST_DOMAINS {DOMAINS!r}: these tests need two domains"
    return ids[:2]


# Each session records the domain it holds and keeps it until as many sessions have recorded
# theirs as the test expects, or the test says "release".
HOLD = """
import os
import time
from pathlib import Path


def test_holds_its_domain(rls_domain):
    here = Path(os.environ["RLS_CLAIMS"])
    (here / f"{os.getpid()}.domain").write_text(str(rls_domain))
    deadline = time.monotonic() + 300
    while len(list(here.glob("*.domain"))) < 2 and not (here / "release").exists():
        assert time.monotonic() < deadline, "never released"
        time.sleep(0.05)
"""


def test_two_sessions_at_once_on_one_range_each_claim_their_own_domain(tmp_path):
    (tmp_path / "test_hold.py").write_text(HOLD)
    claims = tmp_path / "claims"
    claims.mkdir()
    first, second = _first_two()
    sessions = [_start(["--basetemp", str(tmp_path / f"t{i}"), "test_hold.py"], tmp_path, f"{first}-{second}",
                       RLS_CLAIMS=str(claims)) for i in range(2)]
    try:
        outs = [p.communicate(timeout=400)[0] for p in sessions]
    finally:
        for p in sessions:
            p.kill()
            p.wait()
    assert [p.returncode for p in sessions] == [0, 0], outs
    held = sorted(int(f.read_text()) for f in claims.glob("*.domain"))
    assert held == [first, second], held  # at the same time, so never the same one


def test_a_second_session_on_a_range_held_by_another_is_refused_in_one_line(tmp_path):
    (tmp_path / "test_hold.py").write_text(HOLD)
    claims = tmp_path / "claims"
    claims.mkdir()
    only = domains(DOMAINS)[0]
    holder = _start(["--basetemp", str(tmp_path / "t0"), "test_hold.py"], tmp_path, str(only), RLS_CLAIMS=str(claims))
    try:
        _wait(lambda: any(claims.glob("*.domain")) or holder.poll() is not None, 300, "claim by the first session")
        assert [f.read_text() for f in claims.glob("*.domain")] == [str(only)], holder.communicate()[0]
        second = _pytest(["-p", "rls_uncertainty.testing.plugin", "--basetemp", str(tmp_path / "t1"), "test_hold.py"],
                         tmp_path, str(only), RLS_CLAIMS=str(claims))
        (claims / "release").touch()
        out = holder.communicate(timeout=300)[0]
    finally:
        holder.kill()
        holder.wait()
    assert holder.returncode == 0, out
    assert second.returncode == 1 and len(list(claims.glob("*.domain"))) == 1, second.stdout
    said = (f"rls_domain: no free ROS domain for the node under test: {only} held by process {holder.pid}; give other "
            "ids with --rls-domains FIRST-LAST (or the ini option rls_domains)")
    assert any(line.endswith(said) for line in second.stdout.splitlines()), second.stdout
    assert "Traceback" not in second.stdout and "exception" not in second.stdout, second.stdout


WAIT_WITH_A_NODE = """
import os
import time
from pathlib import Path


def test_waits_with_a_node(rls_estimator, tmp_path):
    node = rls_estimator("t2")
    (tmp_path.parent / "pid").write_text(str(node.proc.pid))
    deadline = time.monotonic() + 300
    while not (tmp_path.parent / "release").exists():
        assert time.monotonic() < deadline, "never released"
        time.sleep(0.05)
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_the_node_dies_with_a_test_process_ended_by_a_signal(tmp_path, sig):
    (tmp_path / "test_user.py").write_text(WAIT_WITH_A_NODE)
    session = _start(["--basetemp", str(tmp_path / "tmp"), "test_user.py"], tmp_path, DOMAINS)
    pid_file = tmp_path / "tmp" / "pid"
    node = None
    try:
        _wait(lambda: (pid_file.exists() and pid_file.read_text()) or session.poll() is not None, 300,
              "node started by the session")
        assert pid_file.exists(), session.communicate()[0]
        node = int(pid_file.read_text())
        assert _alive(node)
        os.kill(session.pid, sig)  # the pid only, as a CI timeout or `kill PID` does
        session.wait(timeout=60)
        assert session.returncode == -sig
        _wait(lambda: not _alive(node), 60, f"end of the node {node} after the session's end")
    finally:
        session.kill()
        session.wait()
        if node is not None:
            _kill_ours(node, tmp_path)


TWO_NODES = """
def test_two_nodes(rls_estimator, tmp_path):
    first = rls_estimator("t2")
    (tmp_path.parent / "pid").write_text(str(first.proc.pid))
    rls_estimator("t2")
"""


def test_a_second_node_in_one_test_is_refused_in_one_line(tmp_path):
    (tmp_path / "test_user.py").write_text(TWO_NODES)
    run = _pytest(["-p", "rls_uncertainty.testing.plugin", "--basetemp", str(tmp_path / "tmp"), "test_user.py"],
                  tmp_path)
    pid = int((tmp_path / "tmp" / "pid").read_text())
    try:
        assert run.returncode == 1, run.stdout
        said = [line for line in run.stdout.splitlines() if "one node at a time" in line]
        assert said and said[0].endswith("stop it first (node.stop()) or use it"), run.stdout
        assert f"estimator0 (pid {pid}) still runs on ROS domain" in said[0]
        _wait(lambda: not _alive(pid), 60, "end of the first node")
    finally:
        _kill_ours(pid, tmp_path)


@pytest.mark.parametrize("spec,ambient,want", [
    ("42-49", "42", [43, 44, 45, 46, 47, 48, 49]), ("42-49", "0", list(range(42, 50))), ("7", "3", [7]),
])
def test_the_domains_leave_out_the_environments_own(spec, ambient, want):
    assert domains(spec, ambient) == want


@pytest.mark.parametrize("spec,needle", [("-", "FIRST-LAST"), ("a-b", "FIRST-LAST"), ("49-42", "FIRST <= LAST"),
                                         ("5-300", "0 to 232"), ("42", "only the environment's own")])
def test_a_bad_domain_range_is_one_line(spec, needle):
    with pytest.raises(ConfigError, match=re.escape(needle)):
        domains(spec, "42")
