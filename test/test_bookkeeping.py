"""The pipeline's counters and evidence (rls_uncertainty.datapath.bookkeeping): bounded tables whatever
arrives, and the report the diagnostics and the replay read."""

from __future__ import annotations

import pytest

from rls_uncertainty.datapath.bookkeeping import (
    _EVIDENCE_KEYS,
    KEY_CHARS,
    KEYS_KEPT,
    NO_TOTALS,
    OTHER_REASONS,
    SAMPLES,
    Bookkeeping,
    Tally,
    Totals,
    Window,
    growth,
    increase,
)
from rls_uncertainty.datapath.pipeline import STREAMS


def test_evidence_keeps_the_newest_per_pair_and_a_bounded_number_of_pairs():
    book = Bookkeeping.for_streams(STREAMS)
    book.note("imu", "non_finite", (1.0,))
    book.note("imu", "non_finite", (2.0,))
    assert book.evidence == {("imu", "non_finite"): (2.0,)}
    for i in range(10 * _EVIDENCE_KEYS):
        book.note("imu", f"reason{i}", i)
    assert len(book.evidence) == _EVIDENCE_KEYS
    book.note("imu", "non_finite", (3.0,))  # a pair already kept is still updated
    assert book.evidence[("imu", "non_finite")] == (3.0,)


def test_counted_keys_are_bounded_and_cut():
    c = Tally("<others>")
    for i in range(3 * KEYS_KEPT):
        assert c.count(f"j{i}") == (f"j{i}" if i < KEYS_KEPT else "<others>")
    assert len(c) == KEYS_KEPT + 1 and c["<others>"] == 2 * KEYS_KEPT and c.total() == 3 * KEYS_KEPT
    long = Tally()
    assert long.count("k" * 1000) == "k" * KEY_CHARS
    long.count("k" * 999)  # the same key once cut
    assert long == {"k" * KEY_CHARS: 2}


def test_a_tally_reads_as_a_mapping_and_is_written_only_by_count():
    c = Tally()
    c.count("gap_imu", 3)
    c.count("duplicate")
    c.count("gap_imu")
    assert list(c) == ["gap_imu", "duplicate"] and dict(c) == {"gap_imu": 4, "duplicate": 1}
    assert c["never"] == 0 and "never" not in c and c.get("never") is None and c.get("never", 0) == 0
    assert "gap_imu" in c and c.total() == 5 and Tally().total() == 0 and not Tally()
    with pytest.raises(TypeError):
        c["gap_imu"] = 0  # type: ignore[index]


def test_the_report_holds_every_counter_as_plain_values():
    book = Bookkeeping.for_streams(STREAMS)
    book.streams["imu"].received = 5
    assert book.streams["imu"].reject("duplicate", 2) == "duplicate"
    book.samples_formed, book.samples_used = 4, 3
    book.reject_samples("gap_imu")
    r = book.report(pending=7)
    assert r["streams"]["imu"]["accepted"] == 3 and r["streams"]["imu"]["rejected"] == {"duplicate": 2}
    assert (r["samples_formed"], r["samples_used"], r["samples_pending"]) == (4, 3, 7)
    assert r["samples_rejected"] == {"gap_imu": 1} and set(r["streams"]) == set(STREAMS)
    assert all(type(r[k]) is dict for k in ("samples_rejected", "resets", "unknown_joints", "outputs_withheld"))
    assert type(r["streams"]["imu"]["rejected"]) is dict


def test_a_rejected_sample_keeps_its_evidence_under_the_reason_it_was_counted_as():
    book = Bookkeeping.for_streams(STREAMS)
    for i in range(KEYS_KEPT):
        book.reject_samples(f"r{i}")
    book.reject_samples("one_too_many", 2, evidence=(1.0, 2.0))
    assert book.samples_rejected[OTHER_REASONS] == 2 and "one_too_many" not in book.samples_rejected
    assert book.evidence == {(SAMPLES, OTHER_REASONS): (1.0, 2.0)}


def _report(received, rejected, missing=0, expired=0, formed=0, used=0, samples_rejected=None):
    stream = {"received": received, "accepted": received - sum(rejected.values()), "rejected": rejected,
              "missing": missing, "expired": expired}
    return {"streams": {"imu": stream}, "samples_formed": formed, "samples_used": used,
            "samples_rejected": samples_rejected or {}}


def test_totals_add_up_a_report_and_growth_counts_a_restarted_counter_from_zero():
    t = Totals.of(_report(10, {"duplicate": 2, "non_finite": 3}, missing=4, expired=1, formed=7, used=5,
                          samples_rejected={"gap_imu": 2}))
    assert (t.received["imu"], t.accepted["imu"], t.rejected_total("imu")) == (10, 5, 5)
    assert (t.missing["imu"], t.expired["imu"], t.formed, t.used) == (4, 1, 7, 5)
    assert t.rejected_total("thrust") == 0 and NO_TOTALS.rejected_total("imu") == 0
    assert increase(9, 4) == 5 and increase(3, 4) == 3  # went down: restarted, counts from zero
    assert growth({"a": 5, "b": 9, "c": 2, "d": 1}, {"a": 1, "b": 9, "c": 7}) == [("a", 4), ("c", 2), ("d", 1)]


def test_the_window_gives_the_newest_totals_at_least_a_window_old():
    window = Window(NO_TOTALS)
    seen = []
    for k in range(1, 8):  # totals k at k seconds (steady time), a 2.5 s window
        before, whole = window.advance(1.0, Totals.of(_report(k, {})), 2.5)
        seen.append((before.received.get("imu", 0), whole))
    # At k s the newest totals at least 2.5 s old are those of k - 3 s (0 s: the start, all zero).
    assert seen == [(0, False), (0, False), (0, True), (1, True), (2, True), (3, True), (4, True)]
    assert window.time == 7.0
    assert window.advance(-5.0, NO_TOTALS, 2.5)[0].received["imu"] == 4  # time never runs back
