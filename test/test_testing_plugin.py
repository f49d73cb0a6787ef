"""The pytest fixtures (rls_uncertainty/testing/plugin.py), used as a user's suite uses them:
examples/user_tests (outside test/, the plugin enabled in its pytest.ini) runs in a pytest of
its own, with the five-line test of docs/testing.md on the bundled bag and on the Twin Otter
replay; a failing test's node is stopped all the same; the domain choice. Nodes run on
domains 43-49 (this machine's sessions use 42-49)."""

import os
import re
import subprocess
import sys
import time

import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.testing.plugin import domains

from conftest import FLIGHT_DATA, ROOT

EXAMPLES = ROOT / "examples" / "user_tests"


def _pytest(args, cwd, **env):
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rls-domains", "43-49",
                           *args], cwd=cwd, capture_output=True, text=True, timeout=600,
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
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:  # a zombie (exited, not yet reaped by init) is not running
        return fh.read().split(") ")[1][0] != "Z"


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
