"""The maneuver boundaries of simulated flights against their truth: detected from the
control surfaces (datapath.maneuver_detector at its default options) and read from the
/test_point event topic.

    python scripts/maneuver_boundaries.py out/flight_1 out/flight_2 ...

Each DIR is a ``make-bag --flight`` output (the bag and its truth.csv). A detected maneuver
matches the first maneuver of the truth its span overlaps that no other matched; the rest are
false, and a maneuver of the truth matched by none is missed. Prints per flight and over all:
maneuvers, found, missed, false, and the start and end errors (detected minus true, s) as
median and largest magnitude.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from rls_uncertainty.datapath.maneuver_detector import (
    EVENT_TOPIC,
    Boundary,
    ManeuverDetector,
    ManeuverOptions,
    event_boundary,
)
from rls_uncertainty.errors import Refused
from rls_uncertainty.offline.bags import typestore


def _read(path: Path) -> tuple[int, list[tuple[int, list[float]]], list[tuple[int, str, str]]]:
    surfaces, events = [], []
    with AnyReader([path], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic in ("/control_surfaces", f"/{EVENT_TOPIC}")]
        for conn, t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == "/control_surfaces":
                surfaces.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, list(msg.position)))
            else:
                events.append((t, msg.key, msg.value))
        return reader.start_time, surfaces, events


def _spans(boundaries: list[Boundary], t0: int) -> list[tuple[float, float]]:
    starts = {b.name: b.stamp_ns for b in boundaries if b.kind == "start"}
    return [((starts[b.name] - t0) * 1e-9, (b.stamp_ns - t0) * 1e-9) for b in boundaries if b.kind == "end"]


def _match(found: list[tuple[float, float]], truth: list[tuple[float, float]]) -> tuple[list, int, int]:
    used: set[int] = set()
    errors, false = [], 0
    for start, end in found:
        k = next((i for i, (s, e) in enumerate(truth) if i not in used and start < e and s < end), None)
        if k is None:
            false += 1
            continue
        used.add(k)
        errors.append((start - truth[k][0], end - truth[k][1]))
    return errors, len(truth) - len(used), false


def _line(name: str, n: int, errors: list, missed: int, false: int) -> str:
    e = np.abs(np.array(errors, dtype=float).reshape(-1, 2))
    med = np.median(np.array(errors, dtype=float).reshape(-1, 2), axis=0) if errors else [np.nan, np.nan]
    big = e.max(axis=0) if errors else [np.nan, np.nan]
    return (f"{name:<28}{n:>4}{len(errors):>6}{missed:>7}{false:>6}   start {med[0]:+.3f} / {big[0]:.3f}   "
            f"end {med[1]:+.3f} / {big[1]:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("flights", nargs="+", type=Path)
    args = ap.parse_args()
    totals: dict[str, list] = {"detected": [[], 0, 0, 0], "events": [[], 0, 0, 0]}
    print(f"{'':<28}{'n':>4}{'found':>6}{'missed':>7}{'false':>6}   errors, s: median / largest |error|")
    for path in args.flights:
        with (path / "truth.csv").open() as f:
            truth = [(float(r["start"]), float(r["end"])) for r in csv.DictReader(f)]
        t0, surfaces, events = _read(path)
        detector = ManeuverDetector(ManeuverOptions())
        detected: list[Boundary] = []
        for stamp, x in surfaces:
            detected += detector.update(stamp, x)
        detected += detector.finish(surfaces[-1][0])
        read = [event_boundary(t, k, v) for t, k, v in events]
        assert not any(isinstance(b, Refused) for b in read)
        for kind, boundaries in (("detected", detected), ("events", read)):
            errors, missed, false = _match(_spans(boundaries, t0), truth)  # type: ignore[arg-type]
            print(_line(f"{path.name} {kind}", len(truth), errors, missed, false))
            total = totals[kind]
            total[0] += errors
            total[1] += len(truth)
            total[2] += missed
            total[3] += false
    for kind, (errors, n, missed, false) in totals.items():
        print(_line(f"all {kind}", n, errors, missed, false))


if __name__ == "__main__":
    main()
