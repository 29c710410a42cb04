import contextlib
import sys
import time
from pathlib import Path

import pytest
from hypothesis import settings

# tests/synthetic.py is a helper module shared by several test files
sys.path.insert(0, str(Path(__file__).parent))

import pause_watch  # noqa: E402
from flight_slots import (  # noqa: E402
    deal,
    firmware_slot_count,
    flight_slot,
    slot_directory,
    worker_number,
)
from px4.sitl import ENV_VAR, ROOT, Px4Build, Px4BuildError, build_dir  # noqa: E402

# No test is timed (numbers live in benchmarks/): Hypothesis's per-example deadline, 200 ms by
# default, would fail a correct example on a busy machine (make test runs the quick tests at a
# lower priority beside the flights)
settings.register_profile("gcs", deadline=None)
settings.load_profile("gcs")

# The real-firmware tests (tests/px4/) run whenever a PX4 SITL build is there: PX4_SITL_DIR, or
# ../shared/px4-v1.16-sitl beside the checkout. Without one they are not collected, and the
# session says so in one line.
_PX4_DIR, _PX4_CHOSEN = build_dir()
_PX4_PRESENT = (_PX4_DIR / "bin" / "px4").is_file()
collect_ignore = [] if _PX4_PRESENT else ["px4"]


def pytest_configure(config) -> None:
    if not hasattr(config, "workerinput"):  # the session's own process (tests/pause_watch.py)
        config.pause_watch = pause_watch.start_process()
    if _PX4_CHOSEN:  # a build the user named must be one
        try:
            Px4Build(_PX4_DIR).check()
        except Px4BuildError as exc:
            raise pytest.UsageError(f"{ENV_VAR}: {exc}") from None


def pytest_unconfigure(config) -> None:
    watch = getattr(config, "pause_watch", None)
    if watch is not None and watch.poll() is None:  # no summary was printed (interrupted)
        watch.kill()
        watch.wait()


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items) -> None:
    """Flights first, the real firmware's first of all, longest first (their ``flight_s``
    markers), dealt to the workers.

    The end-to-end tests run in real time (tens of seconds to minutes each), the rest in
    milliseconds. ``make test`` runs ``pytest -n 2 --dist worksteal``: the workers start on
    equal parts of this order and an idle one steals from the end of another's queue. Dealt
    (tests/flight_slots.py, :func:`deal`), as many parts as the machine has firmware slots
    start with their share of the real-firmware flights, each flight to the part with the least
    flight time so far, the others with the mock's; the mock's long flights go, longest first,
    to the part with the least flight time so far, then the other tests in turn: the vehicles
    fly at once from the start, the parts' flights end together, and the quick tests fill the
    end instead of one worker finishing a long flight alone.

    It runs last (``trylast``), after ``-m`` and ``--deselect`` have taken out the tests that do
    not run, so that the parts are those of the tests that do. Dealt before them, the flights
    part of ``make test`` dealt every test of the suite, then ``-m`` left 102, which the workers
    split anew: the identify flight (184 s) came last in the lab-floor flight's part, started
    when that one ended, six and a half minutes in, and ended the part three minutes after the
    other firmware flights."""
    items.sort(
        key=lambda item: (
            item.get_closest_marker("px4") is None,
            -flight_s(item),
            item.get_closest_marker("e2e") is None,
        )
    )
    workers = getattr(config, "workerinput", {}).get("workercount", 2)
    items[:] = deal(
        items,
        workers,
        firmware_slot_count(),
        lambda item: item.get_closest_marker("px4"),
        flight_s,
    )


def flight_s(item) -> float:
    """A flight's expected length [s], its ``flight_s`` marker (0 without one): every firmware
    test has one, and the mock's flights of 20 s or more."""
    marker = item.get_closest_marker("flight_s")
    return float(marker.args[0]) if marker is not None else 0.0


@pytest.fixture(autouse=True)
def _a_flight_slot_of_the_machine(request: pytest.FixtureRequest):
    """A test of the flights holds one of the machine's flight slots while it runs, one of the
    real firmware first a firmware slot (tests/flight_slots.py: two test runs on one machine
    share them)."""
    if not any(request.node.get_closest_marker(m) for m in ("e2e", "px4", "live")):
        yield
        return
    worker = worker_number()
    asked = time.monotonic()
    with contextlib.ExitStack() as held:
        if request.node.get_closest_marker("px4"):
            held.enter_context(
                flight_slot(worker, firmware_slot_count(), slot_directory("firmware"))
            )
        held.enter_context(flight_slot(worker))
        # how long the slots kept the test waiting, in its record (tests/px4/conftest.py)
        request.node.user_properties.append(("slot_wait_s", time.monotonic() - asked))
        request.node.user_properties.append(("worker", worker))
        yield


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """One line on the machine's pauses (tests/pause_watch.py); one on the real-firmware tests:
    how many ran and passed, or why none ran."""
    watch = getattr(config, "pause_watch", None)
    if watch is not None:
        terminalreporter.write_line(pause_watch.summary_of(watch))
    if not _PX4_PRESENT:
        where = _PX4_DIR.relative_to(ROOT.parent)
        terminalreporter.write_line(
            f"real PX4 firmware tests not collected: no PX4 SITL build at ../{where}; run them "
            f"with {ENV_VAR}=<PX4-Autopilot>/build/px4_sitl_default make test"
        )
        return
    counts: dict[str, int] = {}
    for outcome in ("passed", "failed", "error", "skipped"):
        for report in terminalreporter.stats.get(outcome, []):
            if "px4" in getattr(report, "keywords", {}) and (
                report.when == "call" or outcome in ("error", "skipped")
            ):
                counts[outcome] = counts.get(outcome, 0) + 1
    if counts:
        said = ", ".join(f"{n} {outcome}" for outcome, n in counts.items())
        terminalreporter.write_line(f"real PX4 firmware tests ({_PX4_DIR}): {said}")
