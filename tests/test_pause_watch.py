"""The test session's pause watch (tests/pause_watch.py), on a clock of its own."""

import os
from pathlib import Path

import pause_watch
from pause_watch import PAUSE_S, PauseWatch, steal_s


class _Clock:
    """A monotonic clock that a sleep advances by what it was asked, or more when told."""

    def __init__(self, extra_s: dict[int, float]) -> None:
        self.now_s, self.calls, self.extra_s = 100.0, 0, extra_s

    def sleep(self, duration_s: float) -> None:
        self.now_s += duration_s + self.extra_s.get(self.calls, 0.0)
        self.calls += 1


def test_wakes_later_than_the_pause_limit_are_noted_with_their_length() -> None:
    clock = _Clock({3: 0.5, 7: PAUSE_S / 2, 9: 0.2})
    watch = PauseWatch(clock=lambda: clock.now_s, sleep=clock.sleep, wall=lambda: 1e9)
    watch.watch(wakes=12)
    assert [round(late, 9) for _, late in watch.pauses] == [0.5, 0.2]
    assert clock.calls == 12


def test_the_summary_lists_the_longest_pauses_in_time_order(monkeypatch) -> None:
    monkeypatch.setattr(pause_watch, "SHOWN", 2)
    watch = PauseWatch(clock=lambda: 60.0)
    watch.pauses = [(1e9 + 0.25, 0.3), (1e9 + 10.0, 0.2), (1e9 - 5.0, 0.6)]
    line = watch.summary()
    assert "3 in 60 s" in line
    assert "the longest 0.60 s at 01:46:35.0 UTC, 0.30 s at 01:46:40.2 UTC" in line
    assert "0.20 s" not in line
    assert PauseWatch(clock=lambda: 5.0).summary().split(": ")[1].startswith("none in 5 s")


def test_steal_is_read_from_the_cpu_line_and_unknown_without_one(tmp_path: Path) -> None:
    stat = tmp_path / "stat"
    stat.write_text("cpu  10 0 5 100 0 0 0 250 0 0\ncpu0 1 0 0 0 0 0 0 0 0 0\n")
    assert steal_s(stat) == 250 / os.sysconf("SC_CLK_TCK")
    stat.write_text("intr 5\n")
    assert steal_s(stat) is None
    assert steal_s(tmp_path / "absent") is None
