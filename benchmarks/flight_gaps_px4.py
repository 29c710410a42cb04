"""What real PX4 firmware receives while gcs learns between trials: the gaps in its own log.

Each flight is the flight of ``tests/px4/test_px4_between_trials.py``: a fresh PX4 v1.16 SITL
(SIH) set up for vision only in the lab rig (``tests/px4/lab_rig.py``: PX4's ground truth served
as an OptiTrack rigid body at 120 Hz), logging every vision and setpoint message it receives
(``tests/px4/ulog.py``), and ``gcs fly --mocap ... --iter 4`` with profiles/antx-adaptive.yaml
(the tests' watchdog limits, no frame check) on the lab tests' tiny eight: trial 0, its repeat,
two learned trials; the step after trial 2 refits the model (the model refresh), the one after
trial 3 too before the landing. ``--load N`` runs N processes beside each flight, each burning
one core in a pure-Python loop at nice 19 for the flight's length (the tests' ``cpu_burner``:
a background job taking every cycle the flight leaves); the machine's own load (others' work)
comes on top and is recorded: the load average (1 min) before and after each flight.

Per flight, from PX4's log (PX4's clock, which in SITL lockstep moves 4 ms at a time): the
largest gap between external-vision messages received, and between setpoints received (above
their period: 60 Hz in a trial, MAVSDK's 50 ms re-send while gcs hovers), in the trials, in the
between-trial computation (from a trial's end to gcs's next step once the trial was recorded and
the next setpoints learned) and over the whole spans between trials (the computation, then the
move, settle and hold); how long each computation and each hover between two trials lasted; the
model refresh's verdict. Prints one JSON line per flight as it ends (appended to ``--out``),
then a markdown table and the medians.

Usage::

    .venv/bin/python benchmarks/flight_gaps_px4.py --flights 3 [--load 1]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from px4.flying import forget_transcripts  # noqa: E402
from px4.lab_rig import LabRig  # noqa: E402
from px4.sitl import STARTED_LINE, Px4Build, Px4Sitl, build_dir  # noqa: E402
from px4.test_px4_between_trials import (  # noqa: E402
    REFRESHED_AFTER,
    TRIALS,
    TimedGcs,
    adaptive_lab_profile,
)
from px4.test_px4_lab import LAB_PARAMS  # noqa: E402
from px4.ulog import log_every_message, px4_gaps, read_flight_log  # noqa: E402
from synthetic import SHORT  # noqa: E402

from gcs.io.rundir import RunDir  # noqa: E402

FLY_TIMEOUT_S = 600.0  # a hung flight, not a slow one


@contextlib.contextmanager
def burners(count: int, seconds: float) -> Iterator[None]:
    """``count`` processes each burning one core at nice 19 for at most ``seconds``."""
    code = (
        f"import os, time\nos.nice(19)\nend = time.monotonic() + {seconds}\n"
        "while time.monotonic() < end: pass"
    )
    hogs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(count)]
    try:
        yield
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


def fly(build: Px4Build, number: int, load: int) -> dict:
    """One flight: fresh PX4 and rig, ``gcs fly --iter 4``, the gaps in PX4's log."""
    load_before = os.getloadavg()[0]
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="gaps-px4-") as tmp_dir:
        tmp = Path(tmp_dir)
        log_every_message(tmp / "px4", build.root)
        vehicle = Px4Sitl(build, tmp / "px4", LAB_PARAMS, ready=STARTED_LINE)
        (tmp / "tiny.yaml").write_text(yaml.safe_dump(SHORT))
        profile = adaptive_lab_profile(tmp)
        try:
            vehicle.start()
            with LabRig(vehicle.instance, []) as rig, burners(load, FLY_TIMEOUT_S):
                gcs = TimedGcs(
                    "fly", "--connect", vehicle.url, "--mocap", rig.url, "--iter", TRIALS,
                    "--trajectory", tmp / "tiny.yaml", "--profile", profile, "--run", tmp / "run",
                )  # fmt: skip
                try:
                    code = gcs.wait(FLY_TIMEOUT_S)
                except AssertionError:
                    code = None
        finally:
            vehicle.stop()
            forget_transcripts()
        out = gcs.output()
        row: dict = {"flight": number, "load": load, "exit": code}
        if code == 0:
            run = RunDir.open(tmp / "run")
            log = read_flight_log(max(vehicle.ulogs(), key=lambda p: p.stat().st_size))
            after = out.split(f"trial {REFRESHED_AFTER} flown")[-1].splitlines()
            row |= px4_gaps(run, log, gcs.timed).as_dict()
            # the live line of the refresh, not the printed report's legend
            verdicts = [
                ln.strip()
                for ln in after
                if ln.strip().startswith(("model refreshed", "model kept"))
            ]
            row["refresh"] = verdicts[0] if verdicts else None
        else:
            lines = [ln for ln in out.splitlines() if ln.strip()]
            row["ended"] = lines[-1][:160] if lines else ""
    return row | {
        "load_before": round(load_before, 2),
        "load_after": round(os.getloadavg()[0], 2),
        "wall_s": round(time.monotonic() - t0, 1),
    }


def table(rows: list[dict]) -> str:
    """The markdown table of the flights and the medians."""
    done = [r for r in rows if r.get("exit") == 0]
    lines = [
        "| flight | burners | load avg before/after | vision gap trial / computation / between "
        "[ms] | setpoint gap trial / computation / between [ms] | computation [s] | hover "
        "between trials [s] | refresh |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.get("exit") != 0:
            ended = r.get("ended", "")
            lines.append(f"| {r['flight']} | {r['load']} | {r['load_before']:.1f}/"
                         f"{r['load_after']:.1f} | - | - | - | - | {ended} |")  # fmt: skip
            continue
        lines.append(
            f"| {r['flight']} | {r['load']} | {r['load_before']:.1f}/{r['load_after']:.1f} "
            f"| {r['vision_trial_ms']:.0f} / {r['vision_learning_ms']:.0f} / "
            f"{r['vision_between_ms']:.0f} | {r['setpoint_trial_ms']:.0f} / "
            f"{r['setpoint_learning_ms']:.0f} / {r['setpoint_between_ms']:.0f} "
            f"| {', '.join(f'{s:.1f}' for s in r['learning_s'])} "
            f"| {', '.join(f'{s:.1f}' for s in r['hover_between_s'])} | {r['refresh']} |"
        )
    if done:

        def med(key: str) -> float:
            return statistics.median(r[key] for r in done)

        diff = statistics.median(r["vision_learning_ms"] - r["vision_trial_ms"] for r in done)
        lines.append("")
        lines.append(
            f"Medians of {len(done)} flights: vision {med('vision_trial_ms'):.0f} ms in the "
            f"trials, {med('vision_learning_ms'):.0f} ms in the computation (difference "
            f"{diff:+.0f} ms); setpoints {med('setpoint_trial_ms'):.0f} ms in the trials, "
            f"{med('setpoint_learning_ms'):.0f} ms in the computation (MAVSDK's 50 ms re-send "
            f"there); PX4's clock step {med('tick_ms'):.0f} ms."
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", type=int, default=3, help="flights, one after the other")
    parser.add_argument("--load", type=int, default=0, help="CPU burners beside each flight")
    parser.add_argument("--out", type=Path, default=ROOT / "logs" / "flight-gaps-px4.jsonl")
    parser.add_argument("--table-from", type=Path, help="only print the table of a JSONL log")
    args = parser.parse_args()
    if args.table_from:
        lines = args.table_from.read_text().splitlines()
        print(table([json.loads(ln) for ln in lines if ln.strip()]))
        return
    build = Px4Build(build_dir()[0])
    build.runnable()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for number in range(1, args.flights + 1):
        try:
            row = fly(build, number, args.load)
        except Exception as exc:  # noqa: BLE001 - a vehicle or rig that did not start is a row too
            load = round(os.getloadavg()[0], 2)
            row = {"flight": number, "load": args.load, "exit": None, "load_before": load,
                   "load_after": load, "ended": f"{type(exc).__name__}: {exc}"[:160]}  # fmt: skip
        print(json.dumps(row), flush=True)
        with args.out.open("a") as log:
            log.write(json.dumps(row) + "\n")
        rows.append(row)
    print(table(rows))


if __name__ == "__main__":
    main()
