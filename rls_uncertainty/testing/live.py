"""The live node under test: the estimator node in a process of its own on a private ROS
domain (:class:`EstimatorProcess`), a bag played to it with ``play``'s flow control, and its
outputs collected as a :class:`..results.ReplayResult` (:func:`play_to_node`).

Delivery is lossless: the player never has more than a window of messages per topic that
the node's reliable subscriptions have not acknowledged (:mod:`..player`), and the node runs
with :data:`REPLAY_PARAMETERS` (reliable inputs, a deep queue, a long input buffer), as for
``rls-uncertainty demo``. Playing starts once discovery has matched every connection from both
of its ends (:func:`_ready`): each side learns of the other separately, seconds apart on a busy
machine, a message published before its reader matched is lost to it, and the node publishes
only on the sample topics its publishers have matched a subscriber on. The node's outputs
are paired by the stamp every array carries (:func:`..outputs.parse_stamp_label`). The run
is complete when the node's ``/diagnostics`` report every message the player published as
received, the samples it used have all been received here, and every model it reports ready
has published for the last of them (with ``estimator.method`` ``frequency`` or ``both``: every
model that published frequency-domain arrays has published them for the last sample due, the
samples used being counted from the start: a run with a reset in it is not waited for
correctly).

The node dies with the process that started it, whatever ends that process (SIGKILL
included): it runs in a process group of its own with Linux's parent-death signal set to
SIGKILL (``prctl(PR_SET_PDEATHSIG)``). The signal follows the *thread* that started the node:
start it from the test's own thread, not from a worker thread that ends before the test.

rclpy is imported when a node is started or played to, not with this module. The domain
isolates the test's DDS traffic (:mod:`.domain` claims one no one else uses; the run stops
with :class:`LiveTimeout` if another node's outputs or another player's inputs appear on it
all the same); discovery follows ``ROS_AUTOMATIC_DISCOVERY_RANGE`` as everywhere in the
package (set it to ``LOCALHOST`` in CI).
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..datapath.outputs import FREQUENCY, FREQUENCY_OUTPUTS, NODE_NAME, SAMPLE_STAMP, parse_stamp_label
from ..errors import BagError, LiveTimeout
from ..extras import optional
from ..offline.bags import input_topics
from ..offline.results import History, ReplayResult, accounting
from ..ros.listener import OutputListener
from ..ros.player import stop_process
from ..settings.parameters import node_config, pipeline_config

__all__ = ["REPLAY_PARAMETERS", "EstimatorProcess", "LiveTimeout", "play_to_node"]

# The node's settings for a lossless replay (docs/tools.md, "play"): reliable inputs with a
# queue deeper than any window the player leaves unacknowledged, an input buffer long enough
# that a node behind its slow streams never expires their messages, no load shedding (a node
# behind a fast replay would otherwise space out its covariances), and reports every 0.2 s
# (the end of a run is read from them). A test's own parameters take precedence.
REPLAY_PARAMETERS: dict[str, Any] = {"qos.reliable": True, "qos.depth": 10_000, "inputs.buffer_duration": 60.0,
                                     "shed_load": False, "diagnostics_period": 0.2}
_VECTORS = ("estimates", "standard_errors", "standard_errors_conventional", "converged")
_FREQUENCY_VECTORS = tuple(f"{FREQUENCY}/{kind}" for kind in FREQUENCY_OUTPUTS)


_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _die_with_parent() -> Callable[[], None]:
    """A ``preexec_fn`` for :class:`subprocess.Popen`: in the child, between fork and exec, ask
    the kernel for SIGKILL when the parent (thread) dies, then leave at once if the parent is
    already gone (it died before the request). libc's ``prctl`` is looked up here, in the
    parent: the child only calls it."""
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent = os.getpid()

    def preexec() -> None:
        prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:
            os._exit(1)

    return preexec


def _nested(params: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted parameter names as the nested mapping of a ROS 2 parameter file."""
    out: dict[str, Any] = {}
    for name, value in params.items():
        *path, leaf = name.split(".")
        d = out
        for part in path:
            d = d.setdefault(part, {})
        d[leaf] = value
    return out


class EstimatorProcess:
    """``python -m rls_uncertainty.ros.node`` with ``parameters`` (dotted names; over
    :data:`REPLAY_PARAMETERS`) written to ``directory/NAME.yaml``, on ROS domain ``domain``,
    its output in ``directory/NAME.log``, in a process group of its own and killed when this
    process dies (module docstring). :meth:`stop` ends it (SIGINT, then SIGKILL after
    ``timeout``); use it in a ``finally`` (the fixtures do)."""

    def __init__(self, parameters: Mapping[str, Any], *, domain: int, directory: str | Path,
                 name: str = "estimator") -> None:
        import yaml  # noqa: PLC0415 - only for the parameter file

        self.parameters = {**REPLAY_PARAMETERS, **parameters}
        self.config = pipeline_config(self.parameters)  # a bad parameter is said here, not in the node's log
        self.node_config = node_config(self.parameters)
        self.domain = int(domain)
        directory = Path(directory)
        self.params_file = directory / f"{name}.yaml"
        self.params_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": _nested(self.parameters)}}))
        self.log_file = directory / f"{name}.log"
        env = {**os.environ, "ROS_DOMAIN_ID": str(self.domain)}
        # preexec_fn with threads about (a DDS participant of an earlier play): the child runs
        # nothing but a resolved libc call and os.getppid, which need no lock another thread holds.
        with open(self.log_file, "w") as log:  # the child writes through its own descriptor
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args",
                 "--params-file", str(self.params_file)],
                stdout=log, stderr=subprocess.STDOUT, env=env, process_group=0,
                preexec_fn=_die_with_parent())  # noqa: PLW1509

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def log(self) -> str:
        """What the node wrote so far."""
        return self.log_file.read_text(errors="replace")

    def stop(self, timeout: float = 15.0) -> int | None:
        """End the node (its exit status; None if it had to be killed)."""
        return self.proc.returncode if stop_process(self.proc, timeout) else None


def _counters(statuses: Sequence[tuple[str, int, str, Mapping[str, str]]]) -> dict[str, Any]:
    """:func:`..results.accounting`'s form of the node's ``/diagnostics`` (its ``inputs`` and
    ``samples`` statuses)."""
    from ..ros.health import parse_statuses  # noqa: PLC0415 - the reader of the node's keys

    health = parse_statuses(statuses, NODE_NAME)
    if health is None:
        return {}
    streams = {s.name: {"received": int(s.get("received", "0")), "accepted": int(s.get("accepted", "0")),
                        "rejected": dict(s.rejected), "expired": int(s.get("expired", "0")),
                        "missing": int(s.get("missing", "0")), "newest_stamp_ns": None} for s in health.streams}
    v = health.samples

    def table(prefix: str) -> dict[str, int]:
        return {k[len(prefix):]: int(n) for k, n in v.items() if k.startswith(prefix)}

    return accounting({"streams": streams, "samples_formed": int(v.get("samples_formed", "0")),
                       "samples_used": int(v.get("samples_used", "0")),
                       "samples_pending": int(v.get("samples_pending", "0")),
                       "samples_rejected": table("samples_rejected."), "resets": table("resets.")})


class _Outputs(OutputListener):
    """The node's sample stamps, vector outputs (by model and kind, by stamp) and newest
    ``/diagnostics``, as they arrive on ``node``."""

    def __init__(self, node: Any, models: Sequence[str], kinds: Sequence[str] = _VECTORS) -> None:
        self.stamps: list[int] = []
        self.arrays: dict[tuple[str, str], dict[int, tuple[float, ...]]] = {(m, k): {} for m in models for k in kinds}
        super().__init__(node, f"/{NODE_NAME}", models, kinds, depth=10_000)

    def _stamp(self, msg: Any) -> None:
        self.stamps.append(int(msg.stamp.sec) * 1_000_000_000 + int(msg.stamp.nanosec))

    def _array(self, model: str, kind: str, msg: Any) -> None:
        self.arrays[(model, kind)][parse_stamp_label(msg.layout.dim[-1].label)] = tuple(msg.data)

    def progress(self) -> tuple[int, ...]:
        """What grows while the node works through the bag: the stamps and arrays here, and
        the messages and samples the node's newest report counts."""
        received = sum(int(v) for k, v in self.values("inputs").items() if k.endswith(".received"))
        return (len(self.stamps), sum(map(len, self.arrays.values())), received,
                int(self.values("samples").get("samples_used") or 0))

    def publishers(self) -> dict[str, int]:
        """The node's newest report's publisher count per input stream."""
        return {k[:-11]: int(v) for k, v in self.values("inputs").items() if k.endswith(".publishers")}

    def inputs_seen(self, streams: Sequence[str]) -> bool:
        """The node's newest report counts a publisher on each of ``streams``."""
        counts = self.publishers()
        return all(counts.get(s, 0) >= 1 for s in streams)

    def intruders(self) -> str | None:
        """Another estimator node's outputs, or another player's inputs, seen here (None:
        only the node under test and this player)."""
        nodes = self.subs[0].get_publisher_count()
        if nodes > 1:
            return (f"{nodes} nodes publish /{NODE_NAME}/{SAMPLE_STAMP}: another node named {NODE_NAME} runs on "
                    "this domain and its samples mix with the node's")
        crowded = {s: n for s, n in self.publishers().items() if n > 1}
        if crowded:
            return ("another player publishes to the node: its inputs have more than this player's publisher ("
                    + ", ".join(f"{s} {n}" for s, n in sorted(crowded.items())) + ")")
        return None


def _wait(spin: Callable[[], None], condition: Callable[[], bool], timeout: float, what: Callable[[], str],
          node: EstimatorProcess, progress: Callable[[], object] | None = None) -> None:
    """Spin until ``condition()``; :class:`LiveTimeout` after ``timeout`` seconds, counted again
    whenever ``progress()`` changes (a busy machine's node is slow, not stuck), or as soon as the
    node exits."""
    deadline = time.monotonic() + timeout
    last = progress() if progress is not None else None
    while not condition():
        if progress is not None and (now := progress()) != last:
            last, deadline = now, time.monotonic() + timeout
        if not node.running:
            raise LiveTimeout(f"the estimator node exited ({node.proc.returncode}) while waiting for {what()}; "
                              f"its log: {node.log_file}\n{node.log()[-2000:]}")
        if time.monotonic() > deadline:  # the log's end too: a test's temporary directory may be gone when read
            quiet = " of no progress" if progress else ""
            raise LiveTimeout(f"no {what()} within {timeout:g} s{quiet}; the node's log: {node.log_file}\n"
                              f"{node.log()[-2000:]}")
        spin()


def _ready(out: _Outputs, player: Any, kinds: Mapping[str, str]) -> Callable[[], bool]:
    """Whether the bag may be played: discovery matched both ends of every connection, seen
    from both sides (each side's view lags the other's by seconds on a busy machine, and a
    message published before its reader matched is lost to it): this player's output
    subscriptions matched the node's publishers, and the node's newest report says it
    publishes on as many sample topics (its publishers matched them); the node's input
    subscriptions matched this player's publishers (its report counts a publisher on each
    stream), and this player's publishers matched a subscription on each input topic."""

    def ready() -> bool:
        return (out.discovered() and out.inputs_seen(list(kinds.values()))
                and all(player.pubs[topic].get_subscription_count() >= 1 for topic in kinds))

    return ready


def _discovery(out: _Outputs, player: Any, kinds: Mapping[str, str]) -> str:
    """What discovery matched so far, seen from each side (:func:`_ready`)."""
    counts = out.publishers()
    node_sees = ", ".join(f"{kind} {counts.get(kind, 0)}" for kind in kinds.values())
    player_sees = ", ".join(f"{kind} {player.pubs[topic].get_subscription_count()}" for topic, kind in kinds.items())
    published_to = out.subscribed()
    return (f"{out.matched()} of the {len(out.subs)} output subscriptions matched the node's publishers; the node "
            f"publishes to {published_to if published_to >= 0 else 'an unreported number of'} of them; "
            f"publishers the node counts per input: {node_sees}; subscriptions matched per input "
            f"here: {player_sees}; {out.reports} report(s) from the node")


def _seen(out: _Outputs, player: Any, kinds: Mapping[str, str], models: Sequence[str]) -> str:
    """What arrived, against what :func:`_complete` waits for, and how many subscriptions each
    input topic's publisher had matched (fewest and most seen while playing, and now)."""
    player.count_subscribers()
    published = {kind: player.stats[topic].published for topic, kind in kinds.items()}
    matched = {kind: f"{player.stats[topic].subscribers_min}-{player.stats[topic].subscribers_max} now "
                     f"{player.pubs[topic].get_subscription_count()}" for topic, kind in kinds.items()}
    counters = _counters(out.diagnostics)
    if not counters:
        return f"published {published} to subscriptions matched {matched}; no report from the node"
    received = {kind: counters["streams"].get(kind, {}).get("received") for kind in published}
    last = out.stamps[-1] if out.stamps else None
    arrays = {m: [kind for (model, kind), got in out.arrays.items() if model == m and last in got] for m in models}
    ready = sorted(name.split("model ", 1)[1] for name, _l, _m, kv in out.diagnostics
                   if name.startswith(f"{NODE_NAME}: model ") and kv.get("ready") == "True")
    return (f"published {published} to subscriptions matched {matched}, the node received {received}; "
            f"it used {counters['samples_used']} samples ({counters['samples_pending']} pending), "
            f"{len(out.stamps)} sample stamps arrived here; "
            f"arrays for the last stamp per model: {arrays}; models ready: {ready}; "
            f"{out.reports} report(s) from the node")


def _complete(out: _Outputs, published: Mapping[str, int], models: Sequence[str], time_domain: bool,
              every: int | None) -> Callable[[], bool]:
    """The run's end (module docstring): every published input counted as received, every
    used sample's stamp here, and the arrays of the last sample from every ready model (the
    time-domain ones when ``time_domain``; the frequency-domain ones, published every
    ``every`` samples, when it is not None)."""

    def done() -> bool:
        counters = _counters(out.diagnostics)
        if not counters:
            return False
        streams = counters["streams"]
        if any(streams.get(kind, {}).get("received", -1) != n for kind, n in published.items()):
            return False
        if len(out.stamps) < counters["samples_used"]:
            return False
        last = out.stamps[-1] if out.stamps else None
        ready = {name.split("model ", 1)[1] for name, _l, _m, kv in out.diagnostics
                 if name.startswith(f"{NODE_NAME}: model ") and kv.get("ready") == "True"}
        if time_domain and not all(last in out.arrays[(m, kind)] for m in models if m in ready for kind in _VECTORS):
            return False
        if every is None or len(out.stamps) < every:
            return True
        due = out.stamps[len(out.stamps) // every * every - 1]
        return all(due in out.arrays[(m, kind)] for m in models if out.arrays[(m, _FREQUENCY_VECTORS[0])]
                   for kind in _FREQUENCY_VECTORS)

    return done


def _collect(out: _Outputs, result: ReplayResult, method: str, history: History, kinds: Sequence[str]) -> set[int]:
    """The ``method``'s arrays of every sample stamp into ``history`` and the result's finals;
    the stamps at which some model published."""
    names = result.parameter_names if method == "time" else result.frequency_parameter_names
    width = sum(map(len, names))
    some: set[int] = set()
    for stamp in out.stamps:
        values = np.full((4, width), np.nan)
        ready = np.zeros(len(result.models), dtype=bool)
        k = 0
        for j, (model, n) in enumerate(zip(result.models, map(len, names), strict=True)):
            rows = [out.arrays[(model, kind)].get(stamp) for kind in kinds]
            if all(r is not None and len(r) == n for r in rows):
                values[:, k:k + n] = rows
                ready[j] = True
                part = values[:, k:k + n]
                result.published(stamp, j, part[0], part[1], part[2], part[3] > 0.5, method=method)
            k += n
        if ready.any():
            some.add(stamp)
        if method == "time" or ready.any():  # the frequency domain publishes on some samples only
            history.append(stamp, values[0], values[1], values[2], values[3] > 0.5, ready)
    return some


def _result(out: _Outputs, params: Mapping[str, Any], published: Mapping[str, int], wall: float,
            data_seconds: float) -> ReplayResult:
    """The collected outputs as a :class:`..results.ReplayResult`, sample by sample."""
    config = pipeline_config(dict(params))
    names = [m.parameter_names for m in config.models]
    models = [m.output for m in config.models]
    history = History(names)
    result = ReplayResult(tuple(models), tuple(map(tuple, names)), history=history,
                          n_messages=sum(published.values()), wall_seconds=wall, data_seconds=data_seconds,
                          methods=config.published_methods)
    stamps = _collect(out, result, "time", history, _VECTORS) if config.publishes_time else set()
    if config.frequency is not None:
        result.frequency_parameter_names = tuple(m.frequency_parameter_names for m in config.models)
        result.frequency_history = History(result.frequency_parameter_names)
        stamps |= _collect(out, result, "frequency", result.frequency_history, _FREQUENCY_VECTORS)
    result.estimates = len(stamps)
    result.counter_values = _counters(out.diagnostics)
    shown = history if config.publishes_time else result.frequency_history
    ever = {model for j, model in enumerate(models) if shown is not None and shown.ready(j).any()}
    prefix = f"{NODE_NAME}: model "
    result.explanations = [f"{name[len(prefix):]}: no estimate: {message}" for name, _l, message, _kv in out.diagnostics
                           if name.startswith(prefix) and name[len(prefix):] not in ever]
    return result


def play_to_node(bag: str | Path, node: EstimatorProcess, *, rate: float = 0.0, timeout: float = 120.0,
                 window: int = 100) -> ReplayResult:
    """Play ``bag`` to the running ``node`` with acknowledgements (``rate`` times real time;
    0: as fast as the acknowledgements allow) and collect its outputs until the run is
    complete (module docstring) or ``timeout`` seconds pass at any one step (waiting for the
    end: seconds without progress, the node's or its outputs'), raising :class:`LiveTimeout`
    that says what was seen (the inputs published, matched and received; the samples used and
    the outputs arrived) with the node's log path and its last lines."""
    with optional("ros", what="playing to a live node"):
        import rclpy  # noqa: PLC0415
        from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

        from ..ros.player import NotAcknowledged, _player_writer_profile, _Publisher  # noqa: PLC0415

    config = node.config
    models = [m.output for m in config.models]
    arrays = (_VECTORS if config.publishes_time else ()) + (_FREQUENCY_VECTORS if config.frequency is not None else ())
    every = config.frequency.every if config.frequency is not None else None
    context = rclpy.Context()
    with _player_writer_profile():
        rclpy.init(context=context, domain_id=node.domain)
        ros = rclpy.create_node("rls_testing_player", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(ros)
    player = None
    try:
        out = _Outputs(ros, models, arrays)
        player = _Publisher(ros, Path(bag), clock=False, reliable=True, window=window)
        kinds = {topic: kind for kind, topic in input_topics(node.node_config.topics).items() if topic in player.pubs}
        if not kinds:
            raise BagError(f"{bag}: none of the node's input topics {sorted(input_topics(node.node_config.topics))}")

        checked = [time.monotonic()]

        def spin() -> None:
            executor.spin_once(timeout_sec=0.01)
            if time.monotonic() - checked[0] >= 0.5:  # a graph query: twice a second is enough
                checked[0] = time.monotonic()
                if (intruders := out.intruders()) is not None:
                    raise LiveTimeout(f"ROS domain {node.domain}: {intruders}; the run's numbers would not be the "
                                      f"node's alone (the node's log: {node.log_file})")

        _wait(spin, _ready(out, player, kinds), timeout,
              lambda: f"discovery of the node's inputs and outputs ({_discovery(out, player, kinds)})", node)
        t0 = time.monotonic()
        try:
            player.run(rate, spin, ack_timeout=timeout)
        except NotAcknowledged as exc:
            raise LiveTimeout(f"{exc}; the node's log: {node.log_file}") from exc
        published = {kinds[t]: s.published for t, s in player.stats.items() if t in kinds}
        _wait(spin, _complete(out, published, models, config.publishes_time, every), timeout,
              lambda: f"complete outputs ({_seen(out, player, kinds, models)})", node, out.progress)
        wall = time.monotonic() - t0
        span = (player.reader.end_time - player.reader.start_time) * 1e-9
        return _result(out, node.parameters, published, wall, span)
    finally:
        if player is not None:
            player.close()
        executor.shutdown()
        ros.destroy_node()
        rclpy.try_shutdown(context=context)
