"""Stopping a campaign (rls_uncertainty/cli, executors.py, files.py): Ctrl-C, SIGTERM, SIGKILL
and a dead Dask scheduler end the run with nothing left running and nothing left half-written.

Each command runs as a subprocess in a process group of its own (its workers are in it too);
the tests wait on conditions (the workers started, the unfinished output directory made, the
group empty) with generous deadlines, and kill whatever they started in a ``finally``. No ROS.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from rls_uncertainty.executors import LocalProcesses, usable_cores

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
DEADLINE = 120.0  # s: generous, for a loaded machine


def _group(pgid: int) -> list[int]:
    """The live processes (not zombies) of process group ``pgid``, from /proc."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) ": state ppid pgrp ...
        if int(fields[2]) == pgid and fields[0] != "Z":
            found.append(int(entry))
    return found


def _wait_for(condition: Callable[[], object], what: str, deadline: float = DEADLINE) -> object:
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"not within {deadline:g} s: {what}")


def _partials(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".partial"))


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}


# A command's child starts from Python's own SIGINT handler and the default SIGTERM and SIGHUP,
# as from a terminal, whatever this run was started with: one started in the background ignores
# SIGINT (nohup: SIGHUP), and a child inherits that (Python keeps an ignored signal ignored).
_FROM_A_TERMINAL = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
                    "signal.signal(signal.SIGTERM, signal.SIG_DFL); signal.signal(signal.SIGHUP, signal.SIG_DFL)\n")
_COMMAND = [sys.executable, "-c", _FROM_A_TERMINAL + "import runpy; runpy.run_module('rls_uncertainty.cli', "
            "run_name='__main__', alter_sys=True)"]


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([*_COMMAND, *args], cwd=cwd, env=_env(),
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _kill_group(proc: subprocess.Popen) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(60)
    for pid in _group(proc.pid):  # (a group outlives its leader)
        os.kill(pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def many(tmp_path_factory):
    """A maneuvers file of 200 spans of the bundled bag: a campaign that runs long enough to
    be stopped in the middle (tens of seconds on two idle cores)."""
    f = tmp_path_factory.mktemp("many") / "maneuvers.yaml"
    spans = [{"name": f"m{i:03d}", "start": 0.01 * (i % 50), "end": 11.0 + 0.005 * (i % 100)} for i in range(200)]
    f.write_text(yaml.safe_dump({"maneuvers": spans}))
    return f


def _campaign(many: Path, out: Path, *extra: str) -> list[str]:
    return ["campaign", str(BUNDLED), "--maneuvers", str(many), "--config", str(ROOT / "config" / "t2.yaml"),
            "--out", str(out), "--no-figures", "--quiet", *extra]


def _running(proc: subprocess.Popen, directory: Path, workers: int) -> None:
    """Wait until the campaign's workers run and its unfinished output directory exists."""
    _wait_for(lambda: (len(_group(proc.pid)) >= 1 + workers and _partials(directory)) or proc.poll() is not None,
              f"the campaign's {workers} workers and its .partial directory")
    assert proc.poll() is None, proc.communicate()


@pytest.mark.parametrize("sig,group,code", [(signal.SIGTERM, False, 143), (signal.SIGINT, True, 130),
                                            (signal.SIGHUP, True, 129)],
                         ids=["SIGTERM", "SIGINT to the group (Ctrl-C)", "SIGHUP to the group (terminal closed)"])
def test_a_stopped_campaign_ends_in_one_line_leaving_no_worker_and_no_output(tmp_path, many, sig, group, code):
    out = tmp_path / "out"
    proc = _start(_campaign(many, out, "--workers", "2"), tmp_path)
    try:
        _running(proc, tmp_path, 2)
        workers = [pid for pid in _group(proc.pid) if pid != proc.pid]
        if group:
            os.killpg(proc.pid, sig)
        else:
            os.kill(proc.pid, sig)
        stdout, stderr = proc.communicate(timeout=DEADLINE)
        assert proc.returncode == code, stderr
        assert stderr == f"rls-uncertainty campaign: stopped by {signal.Signals(sig).name}; its unfinished output " \
                         "removed\n"
        assert stdout == ""
        # The main process ended its workers before it exited: nothing of the group is left.
        assert _group(proc.pid) == [] and not any(Path(f"/proc/{pid}").exists() for pid in workers)
        assert _partials(tmp_path) == [] and not out.exists()
    finally:
        _kill_group(proc)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stopped_replay_ends_in_one_line_leaving_no_output(tmp_path, sig):
    out = tmp_path / "out"
    proc = _start(["replay", str(BUNDLED), "--config", "t2", "--out", str(out), "--quiet"], tmp_path)
    try:
        _wait_for(lambda: _partials(tmp_path) or proc.poll() is not None, "the replay's .partial directory")
        assert proc.poll() is None, proc.communicate()
        os.kill(proc.pid, sig)
        stdout, stderr = proc.communicate(timeout=DEADLINE)
        assert (proc.returncode, stdout) == (128 + sig, "")
        name = signal.Signals(sig).name
        assert stderr == f"rls-uncertainty replay: stopped by {name}; its unfinished output removed\n"
        assert _partials(tmp_path) == [] and not out.exists()
    finally:
        _kill_group(proc)


# A replay in a child whose stopping signal lands where Python cannot propagate an exception
# (WHERE: a __del__ or a weakref callback), or turns it into another (Python 3.11: a RuntimeError
# raised from it, in a __set_name__), at the 50th sample (its unfinished output directory made):
# the command's handler runs there, and Python would print "Exception ignored" and go on.
# It prints where the signal landed after the command returns.
_SWALLOWED = _FROM_A_TERMINAL + """
import signal, sys, weakref
from rls_uncertainty.cli import main
from rls_uncertainty.offline import replay
landed = []
class Swallow:
    def __del__(self):
        landed.append("__del__")
        signal.raise_signal({signum})  # the handler runs at once, inside __del__
class Owner:
    pass
class Named:
    def __set_name__(self, owner, name):
        landed.append("__set_name__")
        signal.raise_signal({signum})
def callback(_ref):
    landed.append("weakref callback")
    signal.raise_signal({signum})
sample, calls = replay._Run.sample, []
def swallowing(self, out):
    calls.append(out)
    if len(calls) == 50:
        if {where!r}.startswith("__del__"):
            Swallow()
        elif {where!r} == "__set_name__":
            type("Made", (), {{"named": Named()}})
        else:
            owner = Owner()
            ref = weakref.ref(owner, callback)
            del owner
    sample(self, out)
replay._Run.sample = swallowing
code = main(["replay", {bag!r}, "--config", "t2", "--out", {out!r}, "--quiet"])
print(*landed)
sys.exit(code)
"""


@pytest.mark.parametrize(("where", "sig"), [("__del__", signal.SIGINT), ("weakref callback", signal.SIGTERM),
                                           ("__set_name__", signal.SIGINT)])
def test_a_stop_landing_where_python_cannot_raise_it_still_stops_the_replay(tmp_path, where, sig):
    out = tmp_path / "out"
    code = _SWALLOWED.format(signum=int(sig), where=where, bag=str(BUNDLED), out=str(out))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True,
                          timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (128 + sig, f"{where}\n"), proc.stderr
    name = signal.Signals(sig).name
    assert proc.stderr == f"rls-uncertainty replay: stopped by {name}; its unfinished output removed\n"
    assert list(tmp_path.iterdir()) == []


# A child that sends itself SIGINT when the import system first looks for MODULE: Ctrl-C
# arriving while the command still loads its modules (or, for the parser's flags module,
# while it builds its command line).
_INTERRUPT_AT_IMPORT = _FROM_A_TERMINAL + """
import os, signal, sys
class Trip:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Trip())
from rls_uncertainty.cli import {entry}
sys.exit({entry}({args}))
"""


@pytest.mark.parametrize(("module", "entry", "args", "program"), [
    ("rls_uncertainty.cli.commands", "main", "['replay', {bag!r}, '--out', {out!r}]", "rls-uncertainty"),
    ("rls_uncertainty.cli.flags", "main", "['replay', {bag!r}, '--out', {out!r}]", "rls-uncertainty"),
    ("rls_uncertainty.cli.commands", "estimator_node", "", "estimator_node"),
])
def test_ctrl_c_while_the_command_starts_is_one_line_and_writes_nothing(tmp_path, module, entry, args, program):
    out = tmp_path / "out"
    code = _INTERRUPT_AT_IMPORT.format(module=module, entry=entry, args=args.format(bag=str(BUNDLED), out=str(out)))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (130, "")
    assert proc.stderr == f"{program}: stopped by SIGINT while starting; nothing written\n"
    assert list(tmp_path.iterdir()) == []


# A child that, when the import system first looks for rclpy, takes a Ctrl-C and raises an
# ImportError from it, as rclpy's C extension does when the interrupt lands while it initializes
# ("ImportError: initialization failed", the KeyboardInterrupt its cause).
_INTERRUPT_AS_IMPORT_ERROR = _FROM_A_TERMINAL + """
import signal, sys
class Trip:
    def find_spec(self, name, path=None, target=None):
        if name == "rclpy":
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt as exc:
                raise ImportError("initialization failed") from exc
        return None
sys.meta_path.insert(0, Trip())
"""

# The same ImportError caught by the code that imported the module, which goes on without it
# (an accelerator's pure-Python fallback): a Ctrl-C nothing raises.
_INTERRUPT_SWALLOWED = _INTERRUPT_AS_IMPORT_ERROR.replace('if name == "rclpy":', """if name == "rclpy":
            try:
                import _no_such_accelerator
            except ImportError:
                pass
        if name == "_no_such_accelerator":""")


@pytest.mark.parametrize("landing", ["as it is", "as an ImportError", "swallowed by an import's fallback"])
def test_ctrl_c_while_the_node_module_loads_is_one_line(tmp_path, landing):
    """``python -m rls_uncertainty.ros.node`` (the demo's and the testing plugin's way to start
    the node), interrupted while it imports rclpy: the console script's line and status, also
    when the interrupt comes back as the C extension's ImportError, or as one that the importing
    code caught (the node would otherwise start as if no Ctrl-C had come, and run on)."""
    child = {"as it is": _INTERRUPT_AT_IMPORT.split("from rls_uncertainty.cli")[0].format(module="rclpy"),
             "as an ImportError": _INTERRUPT_AS_IMPORT_ERROR,
             "swallowed by an import's fallback": _INTERRUPT_SWALLOWED}[landing]
    code = child + "import runpy\nrunpy.run_module('rls_uncertainty.ros.node', run_name='__main__', alter_sys=True)\n"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (130, "")
    assert proc.stderr == "estimator_node: stopped by SIGINT while starting; nothing written\n"


# A child that sends itself SIGINT at the first module the import system looks for once
# ``rls_uncertainty.cli`` has started loading: Ctrl-C as the console script's import of the
# command line's module ends, before ``main`` runs (that module loads nothing of its own).
_INTERRUPT_AFTER_CLI = _FROM_A_TERMINAL + """
import os, signal, sys
class Trip:
    armed = False
    def find_spec(self, name, path=None, target=None):
        if name == "rls_uncertainty.cli":
            Trip.armed = True
        elif Trip.armed:
            Trip.armed = False
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Trip())
from rls_uncertainty.cli import main
sys.exit(main(["replay", {bag!r}, "--out", {out!r}]))
"""


def test_ctrl_c_as_the_command_line_module_loads_is_one_line(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-c", _INTERRUPT_AFTER_CLI.format(bag=str(BUNDLED), out=str(out))],
                          cwd=tmp_path, capture_output=True, text=True, timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (130, "")
    assert proc.stderr == "rls-uncertainty: stopped by SIGINT while starting; nothing written\n"
    assert list(tmp_path.iterdir()) == []


# A child whose Ctrl-C lands, while the command loads its flags module, where Python cannot
# raise it as it is (WHERE: a __del__, a weakref callback, a __set_name__), or in code that
# catches it and raises another exception in its place (numpy does, when the interrupt lands
# while its C code imports a module).
_LANDING_WHILE_STARTING = _FROM_A_TERMINAL + """
import signal, sys, weakref
class Swallow:
    def __del__(self):
        signal.raise_signal(signal.SIGINT)  # the handler runs at once, inside __del__
class Owner:
    pass
class Named:
    def __set_name__(self, owner, name):
        signal.raise_signal(signal.SIGINT)
def callback(_ref):
    signal.raise_signal(signal.SIGINT)
class Trip:
    def find_spec(self, name, path=None, target=None):
        if name != "rls_uncertainty.cli.flags":
            return None
        if {where!r}.startswith("__del__"):
            Swallow()
        elif {where!r} == "__set_name__":
            type("Made", (), {{"named": Named()}})
        elif {where!r} == "weakref callback":
            owner = Owner()
            ref = weakref.ref(owner, callback)
            del owner
        elif {where!r} == "swallowed by an import's fallback":
            try:
                try:
                    signal.raise_signal(signal.SIGINT)
                except KeyboardInterrupt as exc:
                    raise ImportError("could not import the accelerator") from exc
            except ImportError:
                pass  # (the pure-Python fallback: the standard library's XML module does this)
        else:
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                raise ImportError("could not import module") from None
        return None
sys.meta_path.insert(0, Trip())
if {where!r} == "__del__, the start-up over before it is raised again":
    from rls_uncertainty.cli import stopping
    stopping._thread = type("NoThreads", (), {{"start_new_thread": lambda *a: None}})
from rls_uncertainty.cli import {entry}
sys.exit({entry}({args}))
"""


@pytest.mark.parametrize("where", ["__del__", "__del__, the start-up over before it is raised again",
                                   "weakref callback", "__set_name__", "another exception",
                                   "swallowed by an import's fallback"])
def test_ctrl_c_while_starting_is_one_line_wherever_it_lands(tmp_path, where):
    out = tmp_path / "out"
    code = _LANDING_WHILE_STARTING.format(where=where, entry="main", args=f"['replay', {str(BUNDLED)!r}, '--out', "
                                          f"{str(out)!r}]")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (130, ""), proc.stderr
    assert proc.stderr == "rls-uncertainty: stopped by SIGINT while starting; nothing written\n"
    assert list(tmp_path.iterdir()) == []


# A child in which Ctrl-C arrives as ``main`` hands the parsed command line to ``run`` (as
# ``estimator_node`` hands over to the node's main), before their own handling of it starts.
_INTERRUPT_AT_HANDOVER = _FROM_A_TERMINAL + """
import signal, sys
from rls_uncertainty.cli import commands
def interrupted(*args):
    signal.raise_signal(signal.SIGINT)
    raise AssertionError("not interrupted")
commands.run = interrupted
commands.load_estimator_node = lambda: interrupted
from rls_uncertainty.cli import {entry}
sys.exit({entry}({args}))
"""


@pytest.mark.parametrize(("entry", "args", "program"), [
    ("main", "['replay', {bag!r}, '--out', {out!r}]", "rls-uncertainty"),
    ("estimator_node", "", "estimator_node"),
], ids=["rls-uncertainty", "estimator_node"])
def test_ctrl_c_as_the_command_takes_over_is_one_line(tmp_path, entry, args, program):
    code = _INTERRUPT_AT_HANDOVER.format(entry=entry, args=args.format(bag=str(BUNDLED), out=str(tmp_path / "out")))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=DEADLINE)
    # Once the command has been called, main no longer knows what it wrote: the line says less.
    assert (proc.returncode, proc.stdout, proc.stderr) == (130, "", f"{program}: stopped by SIGINT\n")
    assert list(tmp_path.iterdir()) == []


# ``main`` called from a program, Ctrl-C arriving while the replay's stopping handlers are put
# in (just after SIGTERM's): the program gets its own handlers back.
_INTERRUPT_WHILE_HANDLERS_GO_IN = _FROM_A_TERMINAL + """
import signal, sys
from rls_uncertainty.cli import main
put_in = signal.signal
def signal_then_interrupt(signum, handler):
    before = put_in(signum, handler)
    if signum == signal.SIGTERM and handler is not signal.SIG_DFL:
        signal.raise_signal(signal.SIGINT)
    return before
signal.signal = signal_then_interrupt
code = main(["replay", {bag!r}, "--out", {out!r}])
signal.signal = put_in
print(signal.getsignal(signal.SIGINT) is signal.default_int_handler, signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
      signal.getsignal(signal.SIGHUP) == signal.SIG_DFL, sys.unraisablehook is sys.__unraisablehook__)
sys.exit(code)
"""


def test_ctrl_c_while_the_stopping_handlers_go_in_leaves_the_callers_handlers(tmp_path):
    out = tmp_path / "out"
    code = _INTERRUPT_WHILE_HANDLERS_GO_IN.format(bag=str(BUNDLED), out=str(out))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=DEADLINE)
    assert (proc.returncode, proc.stdout) == (130, "True True True True\n"), proc.stderr
    assert proc.stderr == "rls-uncertainty replay: stopped by SIGINT; its unfinished output removed\n"
    assert list(tmp_path.iterdir()) == []


def test_a_killed_campaign_takes_its_workers_with_it_and_the_next_run_removes_its_partial(tmp_path, many):
    out = tmp_path / "out"
    proc = _start(_campaign(many, out, "--workers", "2"), tmp_path)
    try:
        _running(proc, tmp_path, 2)
        left = _partials(tmp_path)
        os.kill(proc.pid, signal.SIGKILL)  # the main process only: nothing of it runs to clean up
        proc.wait(DEADLINE)
        _wait_for(lambda: _group(proc.pid) == [], "the workers' end after their parent's")
        assert _partials(tmp_path) == left and len(left) == 1  # SIGKILL: nothing can remove it at once
    finally:
        _kill_group(proc)
    one = tmp_path / "one.yaml"
    one.write_text(yaml.safe_dump({"maneuvers": [{"name": "m", "start": 0.0, "end": 11.0}]}))
    again = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", *_campaign(one, out)], cwd=tmp_path,
                           env=_env(), capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert _partials(tmp_path) == [] and (out / "table4.csv").is_file()


_ORPHANS = """
import ctypes, sys, time
from rls_uncertainty.executors import LocalProcesses
if sys.argv[1] == "pipe":  # no parent-death signal: the workers see the end of their pipes
    ctypes.CDLL = lambda *a, **k: (_ for _ in ()).throw(OSError("no prctl"))
print("running", flush=True)
LocalProcesses(2).run(time.sleep, [float(sys.argv[2])] * 4)
"""


@pytest.mark.parametrize("how,seconds", [("pdeathsig", 3600.0), ("pipe", 1.0)])
def test_local_workers_end_when_their_parent_is_killed(how, seconds):
    """With the kernel's parent-death signal the workers die at once, in the middle of a job;
    without it (other systems), each ends at the end of its job, when it finds its pipe
    closed: it holds no copy of the parent's end, nor of another worker's."""
    proc = subprocess.Popen([sys.executable, "-c", _ORPHANS, how, str(seconds)], env=_env(),
                            stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert proc.stdout.readline() == "running\n"
        _wait_for(lambda: len(_group(proc.pid)) == 3, "two workers")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(DEADLINE)
        _wait_for(lambda: _group(proc.pid) == [], "the workers' end")
    finally:
        _kill_group(proc)
        proc.stdout.close()


def test_workers_are_capped_at_the_cores_and_the_jobs_and_said_once(tmp_path, capsys):
    from rls_uncertainty import cli

    cores = len(os.sched_getaffinity(0))
    assert usable_cores() == cores
    many = LocalProcesses(100000)
    assert many.workers == cores and many.description == f"{cores} local process{'es' if cores > 1 else ''}"
    pids = set(many.run(_pid, list(range(8))))
    assert len(pids) <= min(cores, 8)
    if cores > 1:
        assert os.getpid() not in pids  # worker processes ran them
    assert many.capped(1, "maneuver") == ("--workers 100000: using 1 local process instead: at most one per core "
                                          f"({cores} here) and one per maneuver (1 here)")
    assert LocalProcesses(1).capped(3) is None and LocalProcesses().capped(3) is None
    spans = tmp_path / "three.yaml"
    spans.write_text(yaml.safe_dump({"maneuvers": [{"name": f"m{i}", "start": 0.1 * i, "end": 11.0}
                                                   for i in range(3)]}))
    assert cli.main(_campaign(spans, tmp_path / "out", "--workers", "100000")) == 0
    err = capsys.readouterr().err
    used = min(cores, 3)
    assert err == (f"rls-uncertainty campaign: --workers 100000: using {used} local process{'es' if used > 1 else ''} "
                   f"instead: at most one per core ({cores} here) and one per maneuver (3 here)\n")


def _pid(_job: int) -> int:
    return os.getpid()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_dead_scheduler_ends_the_campaign_in_one_line(tmp_path, many):
    """The scheduler SIGKILLed while the campaign's jobs run on its workers: exit 2, one line
    naming the scheduler, no traceback, no output, the client closed (the command ends)."""
    pytest.importorskip("distributed")
    dask = Path(sys.executable).parent / "dask"
    address = f"tcp://127.0.0.1:{_free_port()}"
    port = address.rsplit(":", 1)[1]
    started = []
    try:
        scheduler = subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", port,
                                      "--no-dashboard"], env=_env(), stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, start_new_session=True)
        started.append(scheduler)
        started.append(subprocess.Popen([str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                         "--no-dashboard"], env=_env(), stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL, start_new_session=True))
        from distributed import Client

        with Client(address, timeout=DEADLINE, set_as_default=False) as client:
            _wait_for(lambda: client.scheduler_info()["workers"], "a worker on the scheduler")
            proc = _start(_campaign(many, tmp_path / "out", "--scheduler", address), tmp_path)
            started.append(proc)
            _wait_for(lambda: any(client.processing().values()) or proc.poll() is not None,
                      "the campaign's jobs running on the cluster")
            assert proc.poll() is None, proc.communicate()
        os.killpg(scheduler.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=DEADLINE)
        assert proc.returncode == 2 and stdout == ""
        assert stderr.startswith(f"rls-uncertainty campaign: error: lost the Dask scheduler at {address} after ")
        assert stderr.count("\n") == 1 and "Traceback" not in stderr
        assert _partials(tmp_path) == [] and not (tmp_path / "out").exists()
    finally:
        for p in started:
            _kill_group(p)

