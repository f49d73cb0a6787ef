"""The pipeline's counters and evidence (rls_uncertainty.datapath.bookkeeping): bounded tables whatever
arrives, and the report the diagnostics and the replay read."""

from __future__ import annotations

from collections import Counter

from rls_uncertainty.datapath.bookkeeping import _EVIDENCE_KEYS, KEY_CHARS, KEYS_KEPT, Bookkeeping, count_bounded
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
    c: Counter = Counter()
    for i in range(3 * KEYS_KEPT):
        count_bounded(c, f"j{i}", "<others>")
    assert len(c) == KEYS_KEPT + 1 and c["<others>"] == 2 * KEYS_KEPT
    long: Counter = Counter()
    count_bounded(long, "k" * 1000, "<others>")
    count_bounded(long, "k" * 999, "<others>")  # the same key once cut
    assert long == Counter({"k" * KEY_CHARS: 2})


def test_the_report_holds_every_counter_as_plain_values():
    book = Bookkeeping.for_streams(STREAMS)
    book.streams["imu"].received = 5
    book.streams["imu"].rejected["duplicate"] = 2
    book.samples_formed, book.samples_used = 4, 3
    book.samples_rejected["gap_imu"] = 1
    r = book.report(pending=7)
    assert r["streams"]["imu"]["accepted"] == 3 and r["streams"]["imu"]["rejected"] == {"duplicate": 2}
    assert (r["samples_formed"], r["samples_used"], r["samples_pending"]) == (4, 3, 7)
    assert r["samples_rejected"] == {"gap_imu": 1} and set(r["streams"]) == set(STREAMS)
