"""``make-bag --flight``: a simulated flight-test day as one replay recording, with its truth.

The directory written is a ROS 2 bag (``NAME.mcap`` and ``metadata.yaml``; the standard input
topics, as ``make-bag`` writes them) holding the flight of :func:`.simulation.flight.simulate_flight`
and the event topic ``/test_point`` (``diagnostic_msgs/msg/KeyValue``: ``key`` the test point,
``TP-02a``, ``value`` ``start`` at the first sample of its input and ``stop`` at the last),
beside which lie

* ``truth.csv``: one row per maneuver, in the order flown: ``maneuver, start, end`` (s from
  the recording's start, the input's first and last instants), ``condition``, then the true
  value of each parameter of the T-2 models (``CZ_0, CZ_alpha, ...``, as the estimates name
  them);
* ``flight.yaml``: the settings (seed, conditions with their airspeed and dynamic pressure,
  turbulence, noise).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

from ..datapath.maneuver_detector import EVENT_TOPIC, EVENT_TYPE
from ..simulation.flight import CONDITIONS, PARAMETERS, Flight
from .bags import typestore, write_sensor_streams

__all__ = ["TRUTH_FILE", "MANIFEST_FILE", "truth_csv", "write_flight_bag"]

TRUTH_FILE = "truth.csv"
MANIFEST_FILE = "flight.yaml"


def truth_csv(flight: Flight) -> str:
    """``truth.csv``'s text (module docstring); numbers as Python writes them (exact)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["maneuver", "start", "end", "condition", *PARAMETERS])
    for m in flight.maneuvers:
        w.writerow([m.name, repr(m.start), repr(m.end), m.condition, *(repr(m.true[p]) for p in PARAMETERS)])
    return out.getvalue()


def _events(flight: Flight) -> list[tuple[int, str, str, object]]:
    key_value = typestore().types[EVENT_TYPE]
    out: list[tuple[int, str, str, object]] = []
    for m in flight.maneuvers:
        for at, value in ((m.start, "start"), (m.end, "stop")):
            out.append((flight.streams.start_ns + round(at * 1e9), f"/{EVENT_TOPIC}", EVENT_TYPE,
                        key_value(key=m.name, value=value)))
    return out


def write_flight_bag(path: str | Path, seed: int = 2010, *, force: bool = False, band_level: float = 0.2,
                     band_limited_on: Sequence[str] | None = None, gust_sigma: float | None = None) -> Flight:
    """Simulate the flight of ``seed`` and write it at ``path`` (module docstring; atomic, and
    an existing non-empty ``path`` only with ``force``, as ``make-bag``). ``band_limited_on``
    None and ``gust_sigma`` None: the simulation's defaults (the responses; light turbulence)."""
    import yaml  # noqa: PLC0415 - the manifest only

    from ..simulation.flight import simulate_flight  # noqa: PLC0415 - scipy only when simulating
    from ..simulation.t2 import BAND_LIMITED_ON, SimulationConfig  # noqa: PLC0415
    from ..simulation.turbulence import LOW_ALTITUDE_SIGMA_W  # noqa: PLC0415

    on = tuple(BAND_LIMITED_ON if band_limited_on is None else band_limited_on)
    sigma = LOW_ALTITUDE_SIGMA_W["light"] if gust_sigma is None else float(gust_sigma)
    flight = simulate_flight(seed, gust_sigma=sigma, band_level=band_level, band_limited_on=on)
    conditions = []
    for c in CONDITIONS:
        cfg = c.config(1.0)
        conditions.append({"name": c.name, "airspeed_m_s": cfg.airspeed, "dynamic_pressure_pa": cfg.qbar})
    manifest = {"seed": seed, "maneuvers": len(flight.maneuvers), "duration_s": flight.duration,
                "conditions": conditions, "altitude_m": SimulationConfig().altitude,
                "gust_sigma_w_m_s": sigma, "band_limited_noise": band_level, "band_limited_on": list(on),
                "event_topic": f"/{EVENT_TOPIC}", "truth": TRUTH_FILE,
                "simulation": "rls_uncertainty.simulation.flight.simulate_flight"}
    files = {TRUTH_FILE: truth_csv(flight), MANIFEST_FILE: yaml.safe_dump(manifest, sort_keys=False)}
    write_sensor_streams(path, flight.streams, force=force, events=_events(flight), files=files)
    return flight
