"""Peak memory and time of ``replay``, ``convert`` and ``play`` on long recordings: the
figures that show whether memory grows with the recording's length.

The recordings are the seeded T-2 simulation (``simulation.simulate_sensor_streams``) made
``--minutes`` long, on the standard topics (IMU 200 Hz, airspeed and dynamic pressure 50 Hz,
surfaces 100 Hz, thrust 10 Hz: 24,600 messages a minute, 1.48 million an hour), written with
the package's own streaming bag writer (``bags.write_sensor_streams``) into a temporary
directory (or ``--bags DIR``, kept and reused). Each command runs in a process of its own;
its peak resident memory is the kernel's count for that process (``ru_maxrss`` of
``wait4``), its time the wall clock. The recordings are made in processes of their own too:
a child's peak counts the memory it inherits from its parent before ``exec``, so the parent
stays small.

* ``replay BAG --config t2 --out DIR --quiet`` (plots included);
* ``convert BAG --mapping M --out DIR``, ``M`` maps the standard topics onto themselves
  (the surfaces' positions averaged into one joint: every message converted);
* ``play BAG --rate 0`` with no subscriber (``--play``; needs ROS, keep its domain private).

``--pythonpath SRC`` runs the commands on another source tree's package (for a before/after
comparison: ``git archive COMMIT | tar -x -C SRC``) with the same interpreter.

    .venv/bin/python benchmarks/replay_memory_benchmark.py --minutes 20 60 [--play] [--bags DIR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

IDENTITY_MAPPING = """\
imu: {topic: /imu}
airspeed: {topic: /airspeed}
dynamic_pressure: {topic: /dynamic_pressure}
control_surfaces:
  topic: /control_surfaces
  joints: {elevator: {field: position, reduce: mean}}
thrust: {topic: /thrust}
"""


def make_bag(path: Path, minutes: float) -> None:
    """The recording, made in a process of its own (this one stays small: see above)."""
    subprocess.run([sys.executable, __file__, "--make", str(path), str(minutes)], check=True, cwd=ROOT)


def _make(path: str, minutes: str) -> None:
    from rls_uncertainty.offline.bags import write_sensor_streams
    from rls_uncertainty.simulation.t2 import SimulationConfig, simulate_sensor_streams

    streams = simulate_sensor_streams(cfg=replace(SimulationConfig(), duration=60.0 * float(minutes)))
    write_sensor_streams(path, streams)


def measure(args: list[str], pythonpath: str | None) -> tuple[float, float, int]:
    """(wall seconds, peak RSS in MB, exit status) of ``python -m rls_uncertainty.cli ARGS``."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", *args], env=env, cwd=pythonpath or ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _pid, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read() if proc.stderr else ""
    if proc.returncode:
        print(f"  ({' '.join(args[:2])} exit {proc.returncode}: {err.strip()[-300:]})")
    return wall, usage.ru_maxrss / 1024.0, proc.returncode


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, nargs="+", default=[20.0, 60.0])
    ap.add_argument("--bags", help="directory for the recordings (kept; made when missing)")
    ap.add_argument("--pythonpath", help="run the commands on this source tree's package")
    ap.add_argument("--play", action="store_true", help="also play each bag (DDS, no subscriber)")
    ap.add_argument("--skip", nargs="*", default=[], choices=["replay", "convert"], help="commands not to run")
    args = ap.parse_args()
    tree = args.pythonpath or str(ROOT)
    print(f"package from {tree}")
    with tempfile.TemporaryDirectory() as tmp:
        bags = Path(args.bags) if args.bags else Path(tmp)
        mapping = Path(tmp) / "identity.yaml"
        mapping.write_text(IDENTITY_MAPPING)
        print(f"{'recording':<22}{'messages':>10}  {'command':<8}{'time s':>9}{'peak RSS MB':>13}")
        for minutes in args.minutes:
            bag = bags / f"t2_{minutes:g}min"
            if not bag.exists():
                make_bag(bag, minutes)
            n = 24_600 * minutes  # 200 + 2 x 50 + 100 + 10 messages per second
            runs = []
            if "replay" not in args.skip:
                runs.append(("replay", ["replay", str(bag), "--config", str(ROOT / "config" / "t2.yaml"),
                                        "--out", str(Path(tmp) / f"r{minutes:g}"), "--quiet"]))
            if "convert" not in args.skip:
                runs.append(("convert", ["convert", str(bag), "--mapping", str(mapping), "--out",
                                         str(Path(tmp) / f"c{minutes:g}")]))
            if args.play:
                runs.append(("play", ["play", str(bag), "--rate", "0", "--subscribers", "0", "--delay", "0"]))
            for name, cmd in runs:
                wall, rss, _code = measure(cmd, args.pythonpath)
                label = f"{minutes:g} min at 200 Hz IMU"
                print(f"{label:<22}{n:>10,.0f}  {name:<8}{wall:>9.1f}{rss:>13.0f}", flush=True)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--make"]:
        _make(*sys.argv[2:4])
        raise SystemExit(0)
    raise SystemExit(main())
