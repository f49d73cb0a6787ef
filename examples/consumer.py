#!/usr/bin/env python3
"""A consumer of the estimator node: one model's estimates, standard errors, convergence flags
and covariance, paired by the sample stamp every array carries.

    python examples/consumer.py --model Cm            # every sample: parameter +- 2 sigma, * = converged
    python examples/consumer.py --model CZ --every 25 # every 25th sample (2 Hz at 50 Hz)
    python examples/consumer.py --model Cm --json     # one JSON object per line, for programs

Each ``std_msgs/Float64MultiArray`` of the node names its parameters in ``layout.dim[0].label``
and carries its sample's time in the label of its last dim (``stamp:SEC.NANOSEC``, parsed by
``rls_uncertainty.datapath.outputs.parse_stamp_label``), so arrays are paired by stamp, never by
arrival order (DDS keeps each topic's order, not the order across topics). ``~/M/covariance``
comes only every ``outputs.covariance_decimation`` samples, an ``n x n`` row-major array
(``dim[0]`` rows, ``dim[1]`` columns): it is paired with the estimates of its own stamp,
whichever of the two arrives first. A sample is printed once its estimates, standard errors
and convergence flags are in; a covariance once it and its sample's estimates are in.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import OrderedDict

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import Float64MultiArray

from rls_uncertainty.datapath.outputs import parse_stamp_label

VECTORS = ("estimates", "standard_errors", "converged")
KINDS = (*VECTORS, "covariance")


class Pairing:
    """Arrays of one model in, complete samples out (no ROS: testable on its own).

    :meth:`add` takes ``(kind, names, stamp_ns, data)`` and returns the events it completes:
    ``("sample", stamp, record)`` when the three vectors of a stamp are in, ``("covariance",
    stamp, record)`` when a covariance and the estimates of its stamp are in. At most
    ``keep`` stamps are remembered (the oldest incomplete ones are dropped and counted)."""

    def __init__(self, keep: int = 500) -> None:
        self.keep = keep
        self.pending: OrderedDict[int, dict] = OrderedDict()
        self.dropped = 0

    def add(self, kind: str, names: list[str], stamp: int, data: list[float]) -> list[tuple[str, int, dict]]:
        entry = self.pending.get(stamp)
        if entry is None:
            entry = self.pending[stamp] = {"names": names}
            while len(self.pending) > self.keep:
                _, old = self.pending.popitem(last=False)
                self.dropped += not old.get("done_sample")
        entry[kind] = data
        events = []
        if kind in VECTORS and not entry.get("done_sample") and all(k in entry for k in VECTORS):
            entry["done_sample"] = True
            events.append(("sample", stamp, {k: entry[k] for k in ("names", *VECTORS)}))
        if "covariance" in entry and "estimates" in entry and not entry.get("done_covariance"):
            entry["done_covariance"] = True
            n = len(names)
            flat = entry["covariance"]
            cov = [flat[i * n:(i + 1) * n] for i in range(n)]  # row-major: element (i, j) at i * n + j
            events.append(("covariance", stamp, {"names": names, "estimates": entry["estimates"], "covariance": cov}))
        if entry.get("done_sample") and entry.get("done_covariance"):
            del self.pending[stamp]
        return events


def format_event(model: str, event: str, stamp: int, rec: dict) -> str:
    """The human-readable lines of one event."""
    t = f"{stamp // 10**9}.{stamp % 10**9:09d}"
    names = rec["names"]
    if event == "sample":
        flags = rec["converged"]
        parts = [f"{p} {x:+.5g} +- {2 * s:.3g}{'*' if c else ''}"
                 for p, x, s, c in zip(names, rec["estimates"], rec["standard_errors"], flags, strict=True)]
        state = "converged" if all(flags) else f"{int(sum(flags))}/{len(flags)} converged"
        return f"{t} {model} [{state}] " + ", ".join(parts)
    cov = rec["covariance"]
    sd = [math.sqrt(max(cov[i][i], 0.0)) for i in range(len(names))]
    corr = [[cov[i][j] / (sd[i] * sd[j]) if sd[i] > 0 and sd[j] > 0 else float("nan") for j in range(len(names))]
            for i in range(len(names))]
    lines = [f"{t} {model} covariance (2 sigma from its diagonal; correlations):"]
    for i, p in enumerate(names):
        row = " ".join(f"{c:+.2f}" for c in corr[i])
        lines.append(f"    {p:<12} {rec['estimates'][i]:+.5g} +- {2 * sd[i]:.3g}   [{row}]")
    return "\n".join(lines)


class Consumer(Node):
    """Subscribes to ``/<node>/<model>/{estimates,standard_errors,converged,covariance}``."""

    def __init__(self, model: str, node: str, depth: int, emit) -> None:
        super().__init__("rls_consumer")
        self.model = model
        self.pairing = Pairing()
        self.emit = emit
        self.last_message = None
        qos = QoSProfile(depth=depth, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
        for kind in KINDS:
            self.create_subscription(Float64MultiArray, f"/{node}/{model}/{kind}",
                                     lambda msg, kind=kind: self.on_array(kind, msg), qos)

    def on_array(self, kind: str, msg: Float64MultiArray) -> None:
        self.last_message = time.monotonic()
        dims = msg.layout.dim
        names = dims[0].label.split(",")
        stamp = parse_stamp_label(dims[-1].label)  # the stamp is always in the last dim
        for event in self.pairing.add(kind, names, stamp, list(msg.data)):
            self.emit(*event)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="Cm", help="model to follow (CX, CY, CZ, Cl, Cm, Cn)")
    ap.add_argument("--node", default="rls_estimator", help="name of the estimator node")
    ap.add_argument("--every", type=int, default=1, help="print every N-th sample (covariances always)")
    ap.add_argument("--json", action="store_true", help="one JSON object per event")
    ap.add_argument("--depth", type=int, default=1000, help="subscription queue depth")
    ap.add_argument("--idle", type=float, default=0.0, help="exit after this many seconds without messages "
                    "(once one arrived); 0 = run until interrupted")
    args = ap.parse_args(argv)
    count = {"sample": 0}

    def emit(event: str, stamp: int, rec: dict) -> None:
        if event == "sample":
            count["sample"] += 1
            if (count["sample"] - 1) % args.every:
                return
        if args.json:
            print(json.dumps({"event": event, "stamp": stamp, **rec}), flush=True)
        else:
            print(format_event(args.model, event, stamp, rec), flush=True)

    rclpy.init()
    node = Consumer(args.model, args.node, args.depth, emit)
    try:
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
            if args.idle and node.last_message is not None and time.monotonic() - node.last_message > args.idle:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        print(f"{count['sample']} samples, {node.pairing.dropped} incomplete", file=sys.stderr)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
