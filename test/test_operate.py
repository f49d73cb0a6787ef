"""`rls-uncertainty status | enable | disable | reset` against the estimator node in its own
process over DDS (loopback), under a namespace: the services are called and their answers
printed, the node's state really changes (its /diagnostics say so), the status table shows the
node's streams and models; with no node, a clear error and exit status 1; against two nodes of
one name, every call reaches both, each answer is printed and the twins are said, and the exit
status is 1 unless all answered alike."""

from __future__ import annotations

import io
import subprocess
import sys
import time

import pytest

from rls_uncertainty.datapath.inputs import STREAMS
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from ros_harness import ROOT, NodeProcess

T2 = str(ROOT / "config" / "t2.yaml")
NODE = "/ops/rls_estimator"


def _cli(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=timeout)


@pytest.fixture
def node(tmp_path):
    n = NodeProcess(tmp_path, "--params-file", T2, "-r", "__ns:=/ops")
    try:
        yield n
    finally:
        assert n.stop() == 0, n.text()


def _status_once() -> str:
    r = _cli("status", "--once", "--node", NODE, "--timeout", "60")
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_enable_disable_reset_call_the_node_and_print_its_answer(node):
    r = _cli("disable", "--node", NODE, "--timeout", "60")
    assert (r.returncode, r.stdout) == (0, f"{NODE}: estimation disabled (samples counted, not used)\n"), r.stderr
    deadline = time.monotonic() + 60
    while "estimation disabled" not in (text := _status_once()) and time.monotonic() < deadline:
        pass
    assert "estimation disabled" in text  # the node's own samples message says so
    r = _cli("enable", "--node", NODE, "--timeout", "60")
    assert (r.returncode, r.stdout) == (0, f"{NODE}: estimation enabled\n"), r.stderr
    r = _cli("reset", "--node", NODE, "--timeout", "60")
    assert r.returncode == 0 and r.stdout.startswith(f"{NODE}: estimator and inputs reset"), r.stderr
    assert "service" in node.text() or "reset" in node.text()


def test_status_once_prints_the_streams_and_models_of_the_node(node):
    text = _status_once()
    lines = text.splitlines()
    assert lines[0].startswith(NODE) and "ROS_DOMAIN_ID=" in lines[0]
    assert lines[1].startswith("inputs: WARN")  # nothing is published to it: its inputs are silent
    table = {line.split()[0]: line for line in lines if line and line.split()[0] in STREAMS}
    assert set(table) == set(STREAMS)
    assert "never received" in table["imu"]
    tables = [lines[i + 1:lines.index("", i) if "" in lines[i:] else len(lines)]
              for i, line in enumerate(lines) if line.startswith("model ")]
    model_table, parameter_table = tables  # models, then their parameters (config/t2.yaml)
    assert {line.split()[0]: line.split()[1] for line in model_table} == {"CZ": "initializing", "Cm": "initializing"}
    cfg = pipeline_config(load_parameters_file(T2))
    assert [tuple(line.split()[:3]) for line in parameter_table] == [
        (m.output, p, "time") for m in cfg.models for p in m.parameter_names]
    assert all(line.split()[3:5] == ["-", "initializing"] for line in parameter_table), parameter_table


def test_the_status_table_names_the_parameters_held_back_and_why():
    """The model rows of one report as the node writes them (its keys, docs/node.md): the
    parameters whose flag is held back, and the node's reason below the table."""
    from rls_uncertainty.ros.health import parse_statuses
    from rls_uncertainty.ros.operate import format_health

    why = ("Cm: no regressor explains the output (R^2 0.493, identifiability.min_r_squared 0.5): not identifiable; "
           "excite the model or check its output")
    statuses = [("rls_estimator: inputs", 0, "all inputs fresh", {"recent_window_s": "10"}),
                ("rls_estimator: samples", 0, "992 of 1000 samples used", {"samples_pending": "4"}),
                ("rls_estimator: model Cl", 0, "R^2 0.984", {"ready": "True", "samples": "992", "r_squared": "0.98447",
                                                             "lags": "50", "converged": "True", "held_back": ""}),
                ("rls_estimator: model Cm", 1, f"R^2 0.493; {why}",
                 {"ready": "True", "samples": "992", "r_squared": "0.49316", "lags": "50", "converged": "False",
                  "converged_parameters": "", "held_back": "Cm_0,Cm_alpha,Cm_q,Cm_delta_e", "identifiability": why})]
    lines = format_health("/rls_estimator", parse_statuses(statuses, "rls_estimator")).splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("model "))
    assert lines[header].split()[-2:] == ["held", "back"]
    assert lines[header + 1].split() == ["Cl", "ready", "992", "0.984", "50", "all", "-"]
    assert lines[header + 2].split() == ["Cm", "ready", "992", "0.493", "50", "-", "Cm_0,Cm_alpha,Cm_q,Cm_delta_e"]
    assert lines[header + 3] == f"  {why}" and len(lines) == header + 4


def test_the_status_says_which_estimation_methods_the_node_publishes():
    from rls_uncertainty.ros.health import parse_statuses
    from rls_uncertainty.ros.operate import format_health, published_methods

    topics = ["/ops/rls_estimator/CZ/estimates", "/ops/rls_estimator/CZ/frequency/estimates",
              "/ops/rls_estimator/Cm/frequency/converged", "/other/rls_estimator/Cm/estimates", "/diagnostics"]
    assert published_methods(topics, NODE) == ["time", "frequency"]
    assert published_methods(topics[1:], NODE) == ["frequency"]  # estimator.method frequency
    assert published_methods(topics[2:], NODE) == []  # no estimates topic of this node: not said
    statuses = [("rls_estimator: inputs", 0, "all inputs fresh", {"recent_window_s": "10"}),
                ("rls_estimator: samples", 0, "no sample yet", {})]
    health = parse_statuses(statuses, "rls_estimator")
    assert "estimates published" not in format_health(NODE, health)
    lines = format_health(NODE, health, ["time", "frequency"]).splitlines()
    assert ("estimates published: time domain (RLS, ~/M/estimates), frequency domain (~/M/frequency/estimates)"
            in lines)


def test_status_of_a_node_publishing_both_methods_says_so(tmp_path):
    """A node started with estimator.method both: the status names both methods (read from the
    ROS graph once its topics are discovered)."""
    n = NodeProcess(tmp_path, "--params-file", T2, "-r", "__ns:=/ops",
                    "-p", "estimator.method:=both")
    try:
        deadline = time.monotonic() + 90
        expected = "estimates published: time domain (RLS, ~/M/estimates), frequency domain (~/M/frequency/estimates)"
        while expected not in (text := _status_once()):
            assert time.monotonic() < deadline, text
    finally:
        assert n.stop() == 0, n.text()


def test_no_node_gives_a_clear_error_and_exit_status_1():
    for args in (("enable",), ("reset",), ("status", "--once")):
        r = _cli(*args, "--node", "/nobody/rls_estimator", "--timeout", "1")
        assert r.returncode == 1, r
        assert r.stderr.startswith(f"rls-uncertainty {args[0]}: error: no ") and "ROS_DOMAIN_ID=" in r.stderr
        assert "/nobody/rls_estimator" in r.stderr and r.stdout == ""


def test_a_bad_node_name_is_a_usage_error():
    r = _cli("status", "--node", "/bad name")
    assert r.returncode == 2 and "--node" in r.stderr and "Traceback" not in r.stderr


MARKS = {"disable": "estimation disabled", "enable": "estimation enabled", "reset": "estimator and inputs reset"}


def test_enable_disable_reset_reach_both_twins_and_say_so(tmp_path):
    """Two nodes of one name; each command run as soon as both are up (this command's own
    discovery then races the call): both log every call, and the command says there are two."""
    twins = [NodeProcess(tmp_path, "--params-file", T2, "-r", "__ns:=/ops", name=f"twin{i}") for i in range(2)]
    try:
        deadline = time.monotonic() + 120
        while not all("estimating" in t.text() for t in twins):
            assert time.monotonic() < deadline and all(t.proc.poll() is None for t in twins), [t.text() for t in twins]
            time.sleep(0.05)
        for command in ("disable", "enable", "reset") * 2:
            before = [t.text().count(MARKS[command]) for t in twins]
            r = _cli(command, "--node", NODE, "--timeout", "60")
            lines = r.stdout.splitlines()
            assert r.returncode == 0, r.stdout + r.stderr
            assert lines[0].startswith(f"{NODE}: 2 nodes answer to this name, and each gets every call"), r.stdout
            assert [line.split("]: ")[0] for line in lines[1:]] == [f"{NODE} [answer 1 of 2", f"{NODE} [answer 2 of 2"]
            assert all(MARKS[command] in line for line in lines[1:])
            deadline = time.monotonic() + 60
            while not all(t.text().count(MARKS[command]) > b for t, b in zip(twins, before, strict=True)):
                assert time.monotonic() < deadline, f"{command}: a twin never logged it: {[t.text() for t in twins]}"
                time.sleep(0.05)
    finally:
        for t in twins:
            assert t.stop() == 0, t.text()


@pytest.mark.parametrize("answers,nodes,code,said", [
    ([(True, "estimation enabled")], 1, 0, None),
    ([(False, "refused")], 1, 1, None),
    ([(True, "estimation enabled")] * 2, 2, 0, None),
    ([(True, "estimation enabled")], 2, 1, "1 of the 2 nodes named /ops/rls_estimator did not answer within 5 s"),
    ([(True, "estimation enabled"), (False, "refused")], 2, 1, "did not all succeed alike"),
    ([(True, "a"), (True, "b")], 1, 1, "did not all succeed alike"),  # more answers than nodes counted: twins
], ids=["one", "one_refused", "twins", "a_twin_silent", "twins_differ", "uncounted_twin"])
def test_the_answers_of_twins_decide_the_exit_status(answers, nodes, code, said, capsys):
    from rls_uncertainty.ros.operate import report

    out = io.StringIO()
    assert report("enable", NODE, answers, nodes, 5.0, out=out) == code
    lines = out.getvalue().splitlines()
    counted = max(nodes, len(answers))
    if counted == 1:
        assert lines == [f"{NODE}: {answers[0][1]}"]
    else:
        assert lines[0].startswith(f"{NODE}: {counted} nodes answer to this name")
        assert lines[1:] == [f"{NODE} [answer {i} of {counted}]: {m}" for i, (_s, m) in enumerate(answers, 1)]
    err = capsys.readouterr().err
    assert (err == "") if said is None else (err.startswith("rls-uncertainty enable: error: ") and said in err), err


def test_a_call_sent_again_says_so():
    from rls_uncertainty.ros.operate import report

    out = io.StringIO()
    assert report("reset", NODE, [(True, "reset")] * 2, 2, 5.0, sends=2, out=out) == 0
    assert out.getvalue().splitlines()[0].endswith(
        "; sent 2 times, as the earlier calls did not reach every node (a node may have had it more than once)")


def test_status_follows_the_node_through_a_silence_until_sigterm(tmp_path):
    """`status` (not --once) keeps printing the node's reports long past --timeout; a node
    frozen (SIGSTOP) longer than that is said silent and still on the graph, its next report
    after SIGCONT is said back; SIGTERM ends status with exit status 0."""
    import signal
    import threading

    lines: list[str] = []

    def reports() -> int:
        return sum(line.startswith(f"{NODE}  (ROS_DOMAIN_ID=") for line in list(lines))

    node = NodeProcess(tmp_path, "--params-file", T2, "-r", "__ns:=/ops", "-p", "diagnostics_period:=0.2")
    status = reader = None
    try:
        _status_once()  # the node reports: from now on --timeout 1 applies
        status = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "status", "--node", NODE,
                                   "--timeout", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  cwd=ROOT)
        out = status.stdout
        reader = threading.Thread(target=lambda: lines.extend(iter(out.readline, "")), daemon=True)
        reader.start()

        def wait_for(condition, what: str) -> None:
            deadline = time.monotonic() + 120
            while not condition():
                assert status.poll() is None, (what, status.returncode, status.stderr.read(), lines[-5:])
                assert time.monotonic() < deadline, (what, lines[-5:])
                time.sleep(0.05)

        wait_for(lambda: reports() >= 1, "a first report")
        first = time.monotonic()
        # Ten times the --timeout of 1 s, reporting all along (it used to give up after 3-5).
        wait_for(lambda: reports() >= 20 and time.monotonic() - first > 10, "reports for 10 s")
        node.proc.send_signal(signal.SIGSTOP)
        try:
            wait_for(lambda: any(": no report for " in line for line in list(lines)), "the silence said")
            gone = next(line for line in list(lines) if ": no report for " in line)
            assert f"{NODE}: no report for " in gone and "still on the ROS graph" in gone, gone
        finally:
            node.proc.send_signal(signal.SIGCONT)
        wait_for(lambda: any(f"{NODE} is back after " in line for line in list(lines)), "the return said")
        status.send_signal(signal.SIGTERM)
        assert status.wait(timeout=60) == 0, status.stderr.read()
    finally:
        if status is not None:
            if status.poll() is None:
                status.kill()
                status.wait()
            if reader is not None:
                reader.join(timeout=10)
            status.stdout.close()
            status.stderr.close()
        assert node.stop() == 0, node.text()
