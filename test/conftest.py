"""Test session set-up: DDS stays on loopback and each run gets its own ROS domain; the
shared flight recordings are read from ../shared/flight_data (or $RLS_FLIGHT_DATA)."""

import os
import sys
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))

ROOT = Path(__file__).resolve().parents[1]
FLIGHT_DATA = Path(os.environ.get("RLS_FLIGHT_DATA", ROOT.parent / "shared" / "flight_data")).resolve()
sys.path.insert(0, str(Path(__file__).resolve().parent))
