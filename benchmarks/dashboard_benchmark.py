#!/usr/bin/env python3
"""The dashboard under a live replay: latency from the node's publish to the page, and the
dashboard server's CPU; or (``--replay-minutes``) its peak memory and time showing a long
finished replay. Prints figures; asserts nothing.

    .venv/bin/python benchmarks/dashboard_benchmark.py [--bag bags/t2_maneuver] [--config t2]
        [--models CX CY CZ Cl Cm Cn] [--rate 1]
    .venv/bin/python benchmarks/dashboard_benchmark.py --replay-minutes 20 60 [--keep DIR] [--pythonpath SRC]

Before/after: run this script of one checkout with ``cwd`` another checkout's root (the
commands run ``python -m rls_uncertainty...`` there), or give ``--pythonpath SRC`` for the
replay memory.

The estimator node and the dashboard run in their own processes; the bag is played at
``--rate`` (1 = real time) while a headless Chromium (Debian's, through Playwright) shows the
page. Latency per sample batch: the page's receive time (``performance.timeOrigin +
performance.now()``, wall clock) minus the DDS source timestamp of the sample's last array
(the node's publish time, wall clock, same machine); split into node -> server (the server's
send time) and server -> page. CPU: the dashboard process's user + system time
(/proc/PID/stat) over the play, as a percentage of one core.

Replay memory: a seeded T-2 recording ``--replay-minutes`` long (made as
``replay_memory_benchmark.py`` makes it) is replayed, then ``dashboard --replay`` shows it; the
figures are the time from start until the page's socket says the replay was read to its end,
and the dashboard's peak resident memory then (``VmHWM``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from rls_uncertainty.ros.player import stop_process

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
REPLAY_NODE = ["-p", "qos.reliable:=true", "-p", "qos.depth:=10000", "-p", "inputs.buffer_duration:=60.0"]
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--no-first-run"]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def percentile(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def start_dashboard() -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "dashboard", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    line: list[str] = []
    t = threading.Thread(target=lambda: line.append(proc.stdout.readline()), daemon=True)
    t.start()
    t.join(60)
    if not line or not line[0].startswith("serving "):
        proc.kill()
        sys.exit(f"dashboard did not start: {line}")
    return proc, line[0].split()[1]


def stop(proc: subprocess.Popen) -> str:
    stop_process(proc, 30)
    return proc.stderr.read() if proc.stderr else ""


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


async def _read_to_end(url: str, timeout: float) -> str:
    """The page socket's messages until the replay is read (its banner text)."""
    import aiohttp

    async with aiohttp.ClientSession() as session, session.ws_connect(url.rstrip("/") + "/ws",
                                                                       max_msg_size=0) as ws:
        async def until_read() -> str:
            async for msg in ws:
                data = json.loads(msg.data)
                if data.get("type") == "health" and data.get("state") in ("replay", "replay_error"):
                    return str(data["text"])
            return "socket closed"

        return await asyncio.wait_for(until_read(), timeout)


def replay_memory(minutes_list: list[float], keep: str | None, pythonpath: str | None) -> int:
    tree = pythonpath or str(ROOT)
    env = {**os.environ, **({"PYTHONPATH": pythonpath} if pythonpath else {})}
    print(f"package from {tree}")
    print(f"{'recording':<12}{'samples shown':>40}{'read s':>9}{'peak RSS MB':>13}")
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(keep) if keep else Path(tmp)
        for minutes in minutes_list:
            bag, est = base / f"t2_{minutes:g}min", base / f"t2_{minutes:g}min_est"
            if not bag.exists():
                subprocess.run([sys.executable, str(ROOT / "benchmarks" / "replay_memory_benchmark.py"), "--make",
                                str(bag), str(minutes)], check=True, cwd=ROOT)
            if not est.exists():
                subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "replay", str(bag), "--config",
                                str(ROOT / "config" / "t2.yaml"), "--out", str(est), "--quiet", "--no-figures"],
                               check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
            t0 = time.monotonic()
            proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "dashboard", "--port", "0",
                                     "--replay", str(est)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True, cwd=tree, env=env)
            try:
                url = proc.stdout.readline().split()[1]
                text = asyncio.run(_read_to_end(url, 3600))
                seconds, peak = time.monotonic() - t0, peak_rss_mb(proc.pid)
            finally:
                stop(proc)
            shown = text.rsplit(": ", 1)[-1]
            print(f"{minutes:<8g}min{shown:>40}{seconds:>9.1f}{peak:>13.0f}", flush=True)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bag", default=str(ROOT / "bags" / "t2_maneuver"))
    parser.add_argument("--config", default=str(ROOT / "config" / "t2.yaml"))
    parser.add_argument("--models", nargs="+", default=["CX", "CY", "CZ", "Cl", "Cm", "Cn"])
    parser.add_argument("--rate", default="1")
    parser.add_argument("--replay-minutes", type=float, nargs="+", help="peak memory showing T-2 replays this long")
    parser.add_argument("--keep", help="directory for the long recordings and replays (kept; made when missing)")
    parser.add_argument("--pythonpath", help="run the dashboard of this source tree (replay memory)")
    args = parser.parse_args()
    if args.replay_minutes:
        return replay_memory(args.replay_minutes, args.keep, args.pythonpath)
    from playwright.sync_api import sync_playwright

    models = "[" + ",".join(args.models) + "]"
    node = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args",
                             "--params-file", args.config, *REPLAY_NODE, "-p", f"models.enabled:={models}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    dashboard, url = start_dashboard()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=FLAGS)
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url)
            deadline = time.monotonic() + 60
            while page.evaluate("document.getElementById('banner').dataset.state") != "no_samples":
                if time.monotonic() > deadline:
                    sys.exit("the dashboard never saw the node")
                time.sleep(0.2)
            cpu0, wall0 = cpu_seconds(dashboard.pid), time.monotonic()
            play = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", args.bag, "--rate", args.rate,
                                   "--subscribers", "1", "--wait", "60"],
                                  check=False, capture_output=True, text=True, cwd=ROOT)
            time.sleep(1.0)
            cpu1, wall1 = cpu_seconds(dashboard.pid), time.monotonic()
            records = page.evaluate("window.rlsLatency")
            models_shown = page.evaluate("[...document.querySelectorAll('section.model')].map(s => s.dataset.model)")
            browser.close()
    finally:
        err = stop(dashboard)
        stop_process(node, 30)
    if play.returncode != 0:
        print(play.stderr)
    total = [r["received_ms"] - r["published_ns"] * 1e-6 for r in records if r["published_ns"]]
    to_server = [(r["sent_ns"] - r["published_ns"]) * 1e-6 for r in records if r["published_ns"]]
    to_page = [r["received_ms"] - r["sent_ns"] * 1e-6 for r in records]
    print(f"bag {args.bag} at rate {args.rate}, models enabled {models}; page shows {models_shown}")
    print(f"{len(records)} sample batches pushed to the page")
    for name, values in (("node publish -> page", total), ("node publish -> server send", to_server),
                         ("server send -> page", to_page)):
        print(f"  {name:<28} median {statistics.median(values):7.2f} ms   p99 {percentile(values, 0.99):7.2f} ms   "
              f"max {max(values):7.2f} ms")
    print(f"dashboard CPU over the play: {cpu1 - cpu0:.2f} s in {wall1 - wall0:.1f} s = "
          f"{100 * (cpu1 - cpu0) / (wall1 - wall0):.1f}% of one core")
    print(err.strip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
