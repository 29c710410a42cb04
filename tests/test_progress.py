"""Progress off a terminal: plain lines, at most one per interval, and one at the end."""

from __future__ import annotations

import io

from rich.console import Console

from gcs.app.progress import clock, progress_lines, track


def test_plain_lines_every_interval_and_at_the_end() -> None:
    now = [100.0]
    lines: list[str] = []
    progress = progress_lines(lines.append, "study", "chunks", 10.0, lambda: now[0])
    for done, t in ((0, 100.0), (1, 104.0), (2, 111.0), (3, 115.0), (4, 118.0)):
        now[0] = t
        progress(done, 4)
    assert lines == [
        "study: 0/4 chunks, 00:00:00 elapsed",
        "study: 2/4 chunks, 00:00:11 elapsed, about 00:00:11 remaining",
        "study: 4/4 chunks, 00:00:18 elapsed",
    ]


def test_a_pipe_gets_lines_not_a_bar() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=200)
    with track(console, "montecarlo", "tasks", interval_s=0.0) as progress:
        progress(1, 2)
        progress(2, 2)
    text = out.getvalue()
    assert "montecarlo: 1/2 tasks" in text and "montecarlo: 2/2 tasks" in text
    assert "\x1b" not in text  # no control codes in a file


def test_clock() -> None:
    assert clock(3725.4) == "01:02:05" and clock(-1) == "00:00:00"


def test_a_flight_off_a_terminal_says_each_trials_progress_in_plain_lines() -> None:
    from gcs.app.fly_view import live_progress
    from gcs.flight.campaign import TrialProgress, TrialStarted

    out = io.StringIO()
    console = Console(file=out, force_terminal=False, width=100)
    progress, on_event = live_progress(console)
    with progress:
        on_event(TrialStarted(trial=2, number=1, iterations=3, n_setpoints=4, duration_s=0.2))
        for k in range(1, 5):
            on_event(TrialProgress(trial=2, k=k, n=4, err_m=0.1))
    lines = [line for line in out.getvalue().splitlines() if line.strip()]
    # the live error of the trial's one segment (tests/test_live_segments.py), then progress
    assert [ln for ln in lines if "from the setpoint in force" in ln] == [
        "trial 2 0.0-0.2 s: mean 0.100 m, largest 0.100 m from the setpoint in force (lag included)"
    ]
    lines = [ln for ln in lines if "from the setpoint in force" not in ln]
    assert lines[0].startswith("trial 2 started: 4 setpoints")
    # the first sample at once, the last at the end; nothing in between within 10 s
    assert [line.split(",")[0] for line in lines[1:]] == [
        "trial 2: 1/4 setpoints",
        "trial 2: 4/4 setpoints",
    ]
    assert "\x1b" not in out.getvalue()  # no control codes in a pipe


def test_a_flight_on_a_terminal_says_no_plain_progress_lines() -> None:
    from gcs.app.fly_view import live_progress
    from gcs.flight.campaign import TrialProgress, TrialStarted

    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=100)
    progress, on_event = live_progress(console)
    with progress:
        on_event(TrialStarted(trial=0, number=1, iterations=1, n_setpoints=2, duration_s=0.1))
        on_event(TrialProgress(trial=0, k=1, n=2, err_m=0.1))
    assert "setpoints, 00:00" not in out.getvalue()
