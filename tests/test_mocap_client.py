"""The mocap client's journal (a trial's raw-sample file) as the reader's records feed it: no
reader process, no server, no real time."""

from __future__ import annotations

import numpy as np

from gcs.flight.mocap.client import MocapClient
from gcs.flight.mocap.reader import SAMPLE
from gcs.io.mocap_source import parse_mocap_url


def client() -> MocapClient:
    """A client that is never started: its records come from :func:`deliver`."""
    return MocapClient(parse_mocap_url("optitrack://127.0.0.1/drone"))


def deliver(c: MocapClient, seqs: range) -> None:
    """The reader's frames ``seqs`` (120 Hz, tracked), as the client's thread takes them."""
    for seq in seqs:
        c._record(b"S", SAMPLE.pack(seq, 100.0 + seq / 120, True, 0.0, 1.5, 0.0, 1.0, 0, 0, 0))


def test_a_journal_holds_the_samples_from_its_start_to_its_drain_and_none_outside() -> None:
    c = client()
    deliver(c, range(0, 12_000))  # the stream before the first trial: 100 s at 120 Hz
    assert len(c.drain()) == 0  # not kept: a trial's start has nothing to empty
    c.start_journal()
    deliver(c, range(12_000, 12_720))
    trial = c.drain()
    np.testing.assert_array_equal(trial.seq, np.arange(12_000, 12_720))
    assert trial.tracked.all()
    deliver(c, range(12_720, 13_000))  # the hover between trials: not kept either
    assert len(c.drain()) == 0
    c.start_journal()
    deliver(c, range(13_000, 13_010))
    np.testing.assert_array_equal(c.drain().seq, np.arange(13_000, 13_010))
    assert c.stats()["samples"] == 13_010 and c.stats()["journal_dropped"] == 0


def test_a_journal_starts_with_the_last_pre_s_of_the_stream() -> None:
    c = client()
    deliver(c, range(0, 240))  # received at 100 + seq / 120 s
    c.start_journal(pre_s=0.254, now_s=100.0 + 239 / 120)  # 30.48 frame periods back
    deliver(c, range(240, 250))
    np.testing.assert_array_equal(c.drain().seq, np.arange(209, 250))


def test_a_journal_started_again_begins_afresh() -> None:
    c = client()
    c.start_journal()
    deliver(c, range(0, 50))
    c.start_journal()  # a trial flown again after one that was never drained
    deliver(c, range(50, 60))
    np.testing.assert_array_equal(c.drain().seq, np.arange(50, 60))


def test_the_health_window_sees_the_stream_whether_or_not_a_journal_is_open() -> None:
    c = client()
    deliver(c, range(0, 240))
    latest = c.latest()
    assert latest is not None and latest.seq == 239
    assert len(c.recent(1.0, now_s=100.0 + 239 / 120)) == 121  # the last second, both ends in
