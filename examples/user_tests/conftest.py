"""The recordings this example suite replays: the bundled T-2 bag, and the NASA Twin Otter's
longitudinal maneuver converted from the shared flight data (../shared/flight_data beside the
checkout, or $RLS_FLIGHT_DATA) with the package's fti_msgs mapping. Without the recordings
the Twin Otter tests are skipped, unless RLS_REQUIRE_FLIGHT_DATA=1 (then they fail)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from rls_uncertainty.offline.bags import convert, schema_dir

ROOT = Path(__file__).resolve().parents[2]
FLIGHT_DATA = Path(os.environ.get("RLS_FLIGHT_DATA") or ROOT.parent / "shared" / "flight_data")


@pytest.fixture(scope="session")
def twin_otter_longitudinal(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """totter_9752ed20 as a replay bag on the standard topics."""
    source = FLIGHT_DATA / "totter_9752ed20"
    if not source.is_dir():
        reason = f"no Twin Otter recording at {source}"
        if os.environ.get("RLS_REQUIRE_FLIGHT_DATA", "") not in ("", "0"):
            pytest.fail(reason, pytrace=False)
        pytest.skip(reason)
    bag = tmp_path_factory.mktemp("bags") / "totter_9752ed20"
    convert(source, schema_dir() / "fti_msgs" / "mapping.yaml", bag)
    return bag
