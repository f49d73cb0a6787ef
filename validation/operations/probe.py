"""Probes run inside one source tree (``PYTHONPATH=TREE``), used by before_after.py.

``probe.py replay BAG CONFIG OUT``: the tree's offline replay (``rls_uncertainty.replay.replay``,
what ``rls-uncertainty replay`` runs) and, as one JSON line, the pipeline's counters and each
model's R^2 from ``Pipeline.model_fit`` (the figure the node reports in ``/diagnostics`` as
``model M: R^2``; the replay's printed summary has no R^2).

``probe.py discovery BAG``: with ``ROS_AUTOMATIC_DISCOVERY_RANGE`` unset, calls the node's
``main()`` and ``player.play()`` with ``rclpy.init`` replaced by a probe that records the
variable as the process has it at the moment DDS would start, then stops. No DDS is started.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys

VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"


def replay(bag: str, config: str, out: str) -> None:
    from rls_uncertainty.config import load_parameters_file
    from rls_uncertainty.replay import replay as run

    result = run(bag, load_parameters_file(config), out, progress=False, plots=False)
    pipe = result.pipeline
    c = pipe.counters()
    names = [m.output for m in pipe.config.models]
    fits = {}
    for j, name in enumerate(names):
        fit = pipe.model_fit(j)
        fits[name] = fit.get("r_squared") if fit.get("ready") else None
    streams = {k: {"received": s["received"], "rejected": dict(s["rejected"]), "expired": s["expired"],
                   "missing": s["missing"]} for k, s in c["streams"].items()}
    print(json.dumps({"formed": c["samples_formed"], "used": c["samples_used"],
                      "samples_rejected": dict(c["samples_rejected"]), "streams": streams, "r2": fits}))


def discovery(bag: str) -> None:
    import rclpy

    seen = {}

    class Stop(Exception):
        pass

    def probe(where: str):
        def init(*_args, **_kwargs):
            seen[where] = os.environ.get(VAR, "<unset>")
            raise Stop

        return init

    os.environ.pop(VAR, None)
    from rls_uncertainty import node

    node.rclpy.init = probe("node main()")
    with contextlib.suppress(Stop):
        node.main([])
    os.environ.pop(VAR, None)
    from rls_uncertainty import player

    rclpy.init = probe("play()")
    with contextlib.suppress(Stop):
        player.play(bag)
    print(json.dumps(seen))


if __name__ == "__main__":
    cmd, *rest = sys.argv[1:]
    {"replay": replay, "discovery": discovery}[cmd](*rest)
