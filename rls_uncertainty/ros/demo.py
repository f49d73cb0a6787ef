"""``rls-uncertainty demo``: the estimator node on the bundled T-2 bag over DDS, beside the
offline replay of the same bag.

The demo starts the node in a process of its own under a namespace of its own,
``/rls_demo_<pid>_<random>`` (:func:`private_namespace`): the node is
``<namespace>/rls_estimator``, its inputs are the relative topics ``<namespace>/imu``, ...
(the node's default topic names are relative) and the bag is played there, with the settings
of a lossless replay (:data:`REPLAY_PARAMETERS`). So another ``/rls_estimator`` on the same
ROS domain, or a bag someone plays on ``/imu``, neither hears the demo nor disturbs it. The
demo listens to the node's outputs, and prints the final estimates beside the offline numbers
with the largest relative difference; exit status 1, with the reason, when the node published
another number of samples than the replay or other numbers.
"""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

from ..datapath.outputs import ARRAY_OUTPUTS, NODE_NAME
from .environment import where
from .listener import OutputListener
from .player import NoAudience, _check_rate, _player_writer_profile, _Publisher, bundled_bag, stop_process

if TYPE_CHECKING:
    from rclpy.node import Node

    from ..datapath.config import PipelineConfig
    from ..datapath.pipeline import SampleOutput

__all__ = ["demo", "private_namespace", "REPLAY_PARAMETERS"]

# The node's settings for a lossless replay at any pace (docs/tools.md, play): reliable inputs
# whose queues are deeper than any topic of the bundled bag, so a node that falls behind (a
# busy machine) delays messages instead of overwriting them; and a long input buffer: a node
# that falls behind takes about one message per topic per executor round, so its slow streams
# run seconds ahead of the IMU, and with the default 2 s their messages would expire.
REPLAY_PARAMETERS: dict[str, bool | int | float] = {"qos.reliable": True, "qos.depth": 10_000,
                                                    "inputs.buffer_duration": 60.0}
# Seconds the demo waits for the node's next sample before it says the node stopped short.
_PATIENCE_S = 30.0


class _Failed(Exception):
    """The demo could not run to its end; the message says why (printed, exit status 1)."""


class _Dimension(Protocol):
    @property
    def label(self) -> str: ...


class _Layout(Protocol):
    @property
    def dim(self) -> Sequence[_Dimension]: ...


class _ArrayMessage(Protocol):
    """What the demo reads of a ``std_msgs/Float64MultiArray`` (rosidl's classes are untyped)."""

    @property
    def layout(self) -> _Layout: ...

    @property
    def data(self) -> Sequence[float]: ...


def private_namespace() -> str:
    """A namespace no other process uses: ``/rls_demo_<pid>_<4 random hex digits>``."""
    return f"/rls_demo_{os.getpid()}_{secrets.token_hex(2)}"


def _start_node(params_path: str, namespace: str) -> tuple[subprocess.Popen[str], str]:
    """The estimator node for a reliable replay under ``namespace``, in a process of its own;
    and its log file's name. The node writes its log through its own copy of the file
    descriptor: ours is closed once the node is started; the file stays (delete=False) until
    the demo succeeds."""
    import tempfile  # noqa: PLC0415

    settings = [arg for name, value in REPLAY_PARAMETERS.items()
                for arg in ("-p", f"{name}:={str(value).lower() if isinstance(value, bool) else value}")]
    with tempfile.NamedTemporaryFile("w+", prefix="rls_demo_node_", suffix=".log", delete=False) as node_log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args", "--params-file", params_path,
             "-r", f"__ns:={namespace}", *settings],
            stdout=node_log, stderr=subprocess.STDOUT, text=True,
        )
    return proc, node_log.name


class _Outputs(OutputListener):
    """What the demo's listener keeps of the outputs of the node ``node_name``: the number of
    samples published and the latest array of each topic."""

    def __init__(self, node: Node, node_name: str, models: Sequence[str]) -> None:
        self.samples = 0
        self.latest: dict[tuple[str, str], _ArrayMessage] = {}
        super().__init__(node, node_name, models, ARRAY_OUTPUTS, depth=1000)

    def _stamp(self, msg: object) -> None:
        self.samples += 1

    def _array(self, model: str, kind: str, msg: _ArrayMessage) -> None:
        self.latest[(model, kind)] = msg

    def arrays(self, model: str) -> list[_ArrayMessage | None]:
        """The latest estimates, corrected and conventional standard errors of ``model``."""
        return [self.latest.get((model, suffix)) for suffix in ARRAY_OUTPUTS]


def _spin_for(spin: Callable[[], object], seconds: float, until: Callable[[], bool] = lambda: False) -> bool:
    """Spin for ``seconds`` or until ``until()`` holds (then True)."""
    deadline = time.monotonic() + seconds
    while not until():
        if time.monotonic() >= deadline:
            return False
        spin()
    return True


def _spin_while_coming(spin: Callable[[], object], count: Callable[[], int], want: int, patience: float) -> None:
    """Spin until ``count()`` reaches ``want`` or has not grown for ``patience`` seconds (a
    busy machine makes the node slow, not short)."""
    last, since = count(), time.monotonic()
    while count() < want:
        spin()
        if count() != last:
            last, since = count(), time.monotonic()
        elif time.monotonic() - since > patience:
            return


def demo(rate: float = 4.0, params_file: str = "t2") -> int:
    """The live node on the bundled bag: estimates over DDS beside the offline replay."""
    _check_rate(rate)
    # DDS discovery stays on this machine unless the caller chose otherwise.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415

    from ..offline.bags import InputStream  # noqa: PLC0415
    from ..offline.replay import run_pipeline  # noqa: PLC0415
    from ..settings.models import config_dir  # noqa: PLC0415
    from ..settings.parameters import pipeline_config  # noqa: PLC0415
    from ..settings.sources import load_parameters_file  # noqa: PLC0415

    bag = bundled_bag()
    params_path = str(config_dir() / f"{params_file}.yaml")
    config = pipeline_config({**load_parameters_file(params_path), **REPLAY_PARAMETERS})
    namespace = private_namespace()
    node_name = f"{namespace}/{NODE_NAME}"
    print(f"starting the estimator node ({params_path}) and playing {bag} to it over DDS at {rate:g}x ...")
    print(f"under a namespace of its own ({where()}): the node is {node_name}, its inputs {namespace}/imu, ...; "
          "other nodes on the domain neither hear the demo nor disturb it")
    node_proc, node_log = _start_node(params_path, namespace)
    node = player = None
    try:
        with _player_writer_profile():  # (rclpy's signal handlers left out as in play)
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
            node = rclpy.create_node("rls_demo", namespace=namespace)
        outputs = _Outputs(node, node_name, [m.output for m in config.models])

        def spin() -> None:
            rclpy.spin_once(node, timeout_sec=0.01)
            if node_proc.poll() is not None:
                raise _Failed(f"the estimator node exited with status {node_proc.returncode}")

        player = _Publisher(node, bag, clock=False, reliable=True, namespace=namespace)
        player.find_audience(_PATIENCE_S, 1, 1.0, spin)  # the node's five subscriptions, matched
        if not _spin_for(spin, _PATIENCE_S, outputs.discovered):
            raise _Failed(f"the estimator node's outputs were not discovered within {_PATIENCE_S:g} s ("
                          f"{outputs.matched()} of {len(outputs.subs)} subscriptions matched its publishers; its "
                          f"report says it publishes on {outputs.subscribed()} topics, -1: no report)")
        player.run(rate, spin)
        with InputStream(bag) as stream:
            offline = run_pipeline(stream, config, record=False)
        want = len(offline.outputs)
        _spin_while_coming(spin, lambda: outputs.samples, want, _PATIENCE_S)
        _spin_for(spin, 0.5)  # anything beyond want would show now
    except (_Failed, NoAudience) as exc:
        print(f"demo failed: {exc}; the node's log: {node_log}", file=sys.stderr)
        return 1
    finally:
        if player is not None:
            player.close()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        stop_process(node_proc)
    print(f"\nlive node: {outputs.samples} samples published (offline replay: {want})\n")
    worst = _compare(config, outputs, offline.outputs[-1], node_log)
    if worst is None:
        return 1
    if outputs.samples != want or worst >= 1e-9:
        what = (f"the node published {outputs.samples} samples, the offline replay {want}" if outputs.samples != want
                else f"the node's numbers differ from the offline replay's by up to {worst:.1e} (relative)")
        print(f"\ndemo failed: {what}; the node's log: {node_log}", file=sys.stderr)
        return 1
    os.unlink(node_log)
    print("Conventional standard errors assume white residuals (Eq. 13); the corrected ones use the recursive\n"
          "residual autocorrelation (Eqs. 17-22) and cover the real scatter of the estimates (Table 3).")
    return 0


def _compare(config: PipelineConfig, outputs: _Outputs, last: SampleOutput, node_log: str) -> float | None:
    """Print the live node's last estimates beside the true values and the largest relative
    difference from the offline replay's last sample (returned; None if a model sent nothing)."""
    import numpy as np  # noqa: PLC0415

    from ..offline.report import results_table, rows_from_arrays  # noqa: PLC0415
    from ..simulation.t2 import T2_TRUE  # noqa: PLC0415

    rows = []
    worst = 0.0
    for j, m in enumerate(config.models):
        est, se, sc = outputs.arrays(m.output)
        if est is None or se is None or sc is None:
            print(f"{m.output}: no estimate received from the node; its log: {node_log}")
            return None
        names = est.layout.dim[0].label.split(",")
        rows += rows_from_arrays(names, est.data, sc.data, se.data, T2_TRUE)
        n = len(names)
        pairs = ((est.data, last.theta[j, :n]), (se.data, last.se[j, :n]), (sc.data, last.se_conventional[j, :n]))
        for live, off in pairs:
            worst = max(worst, float(np.max(np.abs(np.array(live) - off) / np.abs(off))))
    print(results_table(rows))
    print(f"\nlargest relative difference between the live node and the offline replay: {worst:.1e}")
    return worst
