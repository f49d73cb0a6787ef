"""A campaign of one recording cut into maneuvers by their boundaries, as the node cuts its stream.

``rls-uncertainty campaign RECORDING --config CFG --out DIR`` with ``maneuvers.source`` ``events``
(the test-point messages on ``maneuvers.topic``) or ``detect`` (the excitation) runs the whole
recording once through the replay's pipeline (:func:`..offline.replay.run_pipeline`) with the
:class:`..datapath.maneuvers.ManeuverTracker` the node uses: each maneuver starts the estimator
afresh (inputs kept) and its end gives its rows. The rows are the tracker's, so they are those
of ``replay``'s ``maneuvers.csv`` on the same recording and of the node's history fed the same
messages; the regression rows are kept, so each row has the corrected standard error with all
lags (Eq. 20) over the maneuver's rows too. ``--min-span`` is the too-short rule. The events
refused (a stop without a start, a start twice, an empty name, ...) are counted at the end of
the summary; a recording in which no maneuver is found is an error (nothing written).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

from ..datapath.maneuvers import ManeuverRecord, ManeuverTracker
from ..errors import BagError
from ..files import output_directory
from ..offline.bags import InputStream, check_bag
from ..offline.figures import FigureOptions
from ..offline.replay import run_pipeline
from . import DEFAULT_FIGURES, CampaignResult, write_campaign
from .maneuvers import CampaignSettings
from .run import ManeuverResult
from .table4 import table4

__all__ = ["split_recording", "split_campaign_to", "results_of"]



def results_of(records: Iterable[ManeuverRecord], origin_ns: int) -> list[ManeuverResult]:
    """The tracker's maneuvers as campaign results, start and end in s from ``origin_ns``."""
    return [ManeuverResult(rec.name, tuple(rec.rows),
                           rec.duration, {}, start=(rec.start_ns - origin_ns) * 1e-9,
                           end=(rec.end_ns - origin_ns) * 1e-9, models=rec.models)
            for rec in records]


def _refused(tracker: ManeuverTracker, topic: str) -> str:
    """The events ``tracker`` refused, by reason, in words (empty: none)."""
    if not tracker.rejected:
        return ""
    reasons = ", ".join(f"{reason} {n}" for reason, n in sorted(tracker.rejected.items()))
    return f"{sum(tracker.rejected.values())} events on {topic} refused ({reasons}; docs/maneuvers.md)"


def split_recording(bag: str | Path, settings: CampaignSettings) -> tuple[list[ManeuverResult], tuple[str, ...]]:
    """The maneuvers of the recording ``bag`` by ``settings.config.maneuvers`` (module docstring)
    and the notes for the summary (the events refused). A recording in which no maneuver is
    found is a :class:`.errors.BagError` saying why."""
    config = settings.config
    source, topic = config.maneuvers.source, config.maneuvers.topic
    events = topic if source == "events" else None
    with InputStream(bag, dict(settings.topics), strict=settings.strict, events=events) as stream:
        result = run_pipeline(stream, config, record=True, keep_outputs=False, min_span=settings.min_span)
    tracker = result.maneuvers
    assert tracker is not None  # (maneuvers.source is not off)
    refused = _refused(tracker, topic)
    if not tracker.history:
        why = (refused or f"no start and stop event on maneuvers.topic {topic}") if source == "events" else \
            "the control surfaces' excitation never rose maneuvers.threshold over its trim noise floor"
        raise BagError(f"{bag}: no maneuver found by maneuvers.source {source}: {why}")
    return results_of(tracker.history, stream.t0), (refused,) if refused else ()


def split_campaign_to(out: str | Path, bag: str | Path, settings: CampaignSettings, *,
                      figures: FigureOptions | None = DEFAULT_FIGURES, progress: bool | None = False,
                      force: bool = False, inputs: Iterable[str | Path] = ()) -> CampaignResult:
    """:func:`split_recording` and its campaign files written to ``out`` (complete or absent;
    never over the recording or ``inputs``), in this process."""
    check_bag(bag)
    with output_directory(out, force=force, inputs=(bag, *inputs)) as tmp:
        t0 = time.perf_counter()
        results, notes = split_recording(bag, settings)
        campaign = CampaignResult(results, table4(results), settings, "this process (one recording)",
                                  time.perf_counter() - t0, notes=notes)
        t1 = time.perf_counter()
        written = write_campaign(campaign, tmp, figures=figures, progress=progress)
        campaign.written = {k: Path(out) / p.relative_to(tmp) for k, p in written.items()}
        campaign.write_seconds = time.perf_counter() - t1
    return campaign
