"""Fixtures of the real-firmware tests: a PX4 SITL vehicle per test, its records kept when the
test fails, and the test's figures written for docs/px4-sitl.md (tools/px4_sitl_table.py)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from px4.flying import forget_transcripts, keep_transcripts, kill_leftovers
from px4.sitl import FAILURES, READY_LINE, ROOT, STARTED_LINE, Px4Build, Px4Sitl, build_dir

FIGURES = ROOT / "logs" / "px4-sitl"


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    """Keep each phase's report on the item: the fixtures' teardown asks whether the test failed."""
    report = yield
    setattr(item, f"report_{report.when}", report)
    return report


def _failed(node) -> bool:
    return any(
        getattr(getattr(node, f"report_{when}", None), "failed", False)
        for when in ("setup", "call")
    )


@pytest.fixture(autouse=True)
def _no_gcs_left_running(request, tmp_path: Path) -> Iterator[None]:
    """A test that fails mid-flight leaves its gcs process running: killed after the test. On
    failure what each gcs process said and the test's run directories are copied to
    ``logs/px4-failures/<test>-<time>-gcs/`` (beside the vehicles' records)."""
    yield
    for pid in kill_leftovers():
        print(f"gcs process {pid} was still running after the test: killed")
    if _failed(request.node):
        dest = FAILURES / f"{request.node.name}-{time.strftime('%Y%m%d-%H%M%S')}-gcs"
        keep_transcripts(dest, tmp_path)
        print(f"gcs output and run directories of the failed test kept in {dest.relative_to(ROOT)}")
    else:
        forget_transcripts()


@pytest.fixture(scope="session")
def px4_build() -> Px4Build:
    """The firmware (``PX4_SITL_DIR`` or ``../shared/px4-v1.16-sitl``), made runnable once."""
    build = Px4Build(build_dir()[0])
    build.runnable()
    return build


@pytest.fixture
def px4_factory(px4_build: Px4Build, tmp_path: Path, request) -> Iterator:
    """Start vehicles: ``px4_factory(params=None, ready=READY_LINE)`` returns a started
    :class:`Px4Sitl` (its ``ready`` line printed), each in a
    fresh working directory under the test's tmp dir, stopped after the test; on failure its
    output and ULog logs are copied to ``logs/px4-failures/<test>/`` (the path is printed) and
    a digest of them printed (a CI transcript keeps it when the files are gone)."""
    vehicles: list[Px4Sitl] = []

    def start(params: dict[str, float] | None = None, ready: str = READY_LINE) -> Px4Sitl:
        vehicle = Px4Sitl(px4_build, tmp_path / f"px4-{len(vehicles)}", params, ready=ready)
        vehicles.append(vehicle)
        return vehicle.start()

    yield start
    for vehicle in vehicles:
        vehicle.stop()
    if _failed(request.node):
        stamp = time.strftime("%Y%m%d-%H%M%S")
        for i, vehicle in enumerate(vehicles):
            dest = FAILURES / f"{request.node.name}-{stamp}-{i}"
            vehicle.keep(dest)
            print(f"PX4 output and ULog of the failed test kept in {dest.relative_to(ROOT)}")
            print(vehicle.digest())


@pytest.fixture
def px4(px4_factory) -> Px4Sitl:
    """One ready PX4 SITL vehicle (GPS, the default airframe)."""
    return px4_factory()


@pytest.fixture
def px4_booting(px4_factory) -> Px4Sitl:
    """One PX4 SITL vehicle (GPS, the default airframe) whose start-up script has run (its
    MAVLink links up) while EKF2 may still be initialising: gcs, started at once, waits for a
    valid position and PX4's pre-arm checks as on any vehicle just powered up, and PX4's last
    seconds of boot overlap gcs's own start."""
    return px4_factory(ready=STARTED_LINE)


@pytest.fixture
def px4_figures(request) -> Iterator[dict]:
    """A dict the test fills with its figures; written to ``logs/px4-sitl/<test>.json`` with the
    test's outcome and duration, and the outcome appended to ``logs/px4-sitl/history.jsonl``
    (``tools/px4_sitl_table.py`` makes docs/px4-sitl.md of them)."""
    figures: dict = {}
    t0 = time.monotonic()
    yield figures
    FIGURES.mkdir(parents=True, exist_ok=True)
    slots = dict(request.node.user_properties)
    record = {
        "test": request.node.name,
        "file": request.node.path.name,
        "doc": (request.node.function.__doc__ or "").strip(),
        "passed": not _failed(request.node),
        "duration_s": round(time.monotonic() - t0, 1),
        # the flight slots' wait before the test and its worker (tests/conftest.py)
        "slot_wait_s": round(slots.get("slot_wait_s", 0.0), 1),
        "worker": slots.get("worker"),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "figures": figures,
    }
    path = FIGURES / f"{request.node.name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=1) + "\n")
    tmp.replace(path)
    # one line per run of each test: the table's pass counts (a single write in append mode)
    line = {k: record[k] for k in ("test", "passed", "duration_s", "finished")}
    with (FIGURES / "history.jsonl").open("a") as history:
        history.write(json.dumps(line) + "\n")
