"""The pre-flight frame check on real PX4 v1.16 firmware (SIH) in the lab rig, flight after flight.

Each flight is a fresh PX4 set up for vision only (``tests/px4/test_px4_lab.py``'s
``LAB_PARAMS``) and a fresh rig (``tests/px4/lab_rig.py``: PX4's ground truth served as an
OptiTrack rigid body), then ``gcs fly --mocap ... --iter 1`` with the lab test's
profile and trajectory: take-off, the frame check (``gcs.flight.mocap.checks.frame_check``),
one short trial, landing. Flights with a correct mapping count the check's false aborts;
flights with the rig's room rotated (``--yaw-offset-deg``: gcs maps the mocap 90 or 180
degrees off the room) say what the check and the rest of gcs do with a wrong mapping. The load
average (1 min) is recorded before and after each flight: other work runs on this machine.

Prints one JSON line per flight as it ends (also appended to ``--out``), then the table of
docs/mocap.md ("The frame check on real firmware").

Usage::

    .venv/bin/python benchmarks/frame_check_px4.py --flights 30 --parallel 2 --wrong 90:2,180:2
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from px4.flying import sitl_profile  # noqa: E402
from px4.lab_rig import LabRig  # noqa: E402
from px4.sitl import STARTED_LINE, Px4Build, Px4Sitl, build_dir  # noqa: E402
from px4.test_px4_lab import LAB_PARAMS  # noqa: E402
from synthetic import CI_FLIGHT, SHORT  # noqa: E402

FLY_TIMEOUT_S = 600  # a hung flight, not a slow one: a loaded machine makes healthy flights slow


def _profile(tmp: Path) -> Path:
    return sitl_profile(tmp, limits=CI_FLIGHT, mocap={})


def _ended(out: str) -> str:
    lines = [ln.strip() for ln in out.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    return errors[-1][len("error:") :].strip() if errors else (lines[-1] if lines else "")


def _text(data: bytes | str | None) -> str:
    return data.decode(errors="replace") if isinstance(data, bytes) else (data or "")


def fly(build: Px4Build, number: int, yaw_deg: float) -> dict:
    """One flight: fresh PX4 and rig, ``gcs fly --iter 1``, the outcome and the check's figures."""
    load_before = os.getloadavg()[0]
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="framecheck-") as tmp_dir:
        tmp = Path(tmp_dir)
        vehicle = Px4Sitl(build, tmp / "px4", LAB_PARAMS, ready=STARTED_LINE)
        try:
            vehicle.start()
            (tmp / "tiny.yaml").write_text(yaml.safe_dump(SHORT))
            with LabRig(vehicle.instance, ["--yaw-offset-deg", str(yaw_deg)]) as rig:
                try:
                    proc = subprocess.run(
                        [sys.executable, "-m", "gcs", "fly", "--connect", vehicle.url,
                         "--mocap", rig.url, "--iter", "1", "--trajectory", str(tmp / "tiny.yaml"),
                         "--profile", str(_profile(tmp)), "--run", str(tmp / "run")],
                        cwd=ROOT, capture_output=True, text=True, timeout=FLY_TIMEOUT_S,
                        env={**os.environ, "COLUMNS": "200", "PYTHONUNBUFFERED": "1"},
                    )  # fmt: skip
                    returncode, out = proc.returncode, proc.stdout + proc.stderr
                except subprocess.TimeoutExpired as timeout:
                    # what it had said by then tells where a flight that slow was
                    said = [_text(timeout.stdout), _text(timeout.stderr)]
                    returncode, out = None, "".join(said)
                    out += f"\nerror: no end after {FLY_TIMEOUT_S} s: {_ended(''.join(said))}"
        finally:
            vehicle.stop()
        sessions = sorted((tmp / "run").glob("session-*.json"))
        session = json.loads(sessions[-1].read_text()) if sessions else {}
    checks = (session.get("mocap") or {}).get("moves") or []
    refused = "pre-flight frame check" in out
    return {
        "flight": number,
        "yaw_offset_deg": yaw_deg,
        "exit": returncode,
        "checked": bool(checks),
        "check_refused": refused,
        "check_passed": "mocap check: the mocap moved with the vehicle's estimate" in out,
        "unjudged": "was not judged" in out,
        "flown_again": "once more with" in out,
        "trial_done": "landed and disarmed" in out and returncode == 0,
        "ended": _ended(out) if returncode != 0 else "completed",
        "checks": checks,
        "load_before": round(load_before, 2),
        "load_after": round(os.getloadavg()[0], 2),
        "wall_s": round(time.monotonic() - t0, 1),
    }


def _figures(flight: dict) -> str:
    if not flight["checks"]:
        return "-"
    c = flight["checks"][-1]
    est = ", ".join(f"{r['gain']:.2f}/{r['angle_deg']:.0f}" for r in c["estimate"])
    seen = ", ".join(f"{r['gain']:.2f}/{r['angle_deg']:.0f}" for r in c["mapping"])
    move = max(abs(x) for x in c["cmd_ned_m"][0])
    return f"{move:.2f} | {est} | {seen} | {c['wander_m']:.3f} | {c['following']}"


def table(flights: list[dict]) -> str:
    """The markdown table of the flights and the summary lines."""
    rows = [
        "| flight | yaw offset | load avg before/after | move [m] | estimate gain/angle N, E "
        "| mocap on estimate gain/angle N, E | wander [m] | following | how it ended |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for f in sorted(flights, key=lambda f: (f["yaw_offset_deg"], f["flight"])):
        rows.append(
            f"| {f['flight']} | {f['yaw_offset_deg']:g} | {f['load_before']:.1f}/"
            f"{f['load_after']:.1f} | {_figures(f)} | {f['ended'][:110]} |"
        )
    good = [f for f in flights if f["yaw_offset_deg"] == 0]
    checked = [f for f in good if f["checked"]]
    false = [f for f in checked if f["check_refused"]]
    rows.append("")
    rows.append(
        f"Correct mapping: {len(good)} flights, {len(checked)} reached the frame check, "
        f"{len(false)} false aborts / {len(checked)} checked flights; "
        f"{sum(f['unjudged'] for f in checked)} with the following unjudged, "
        f"{sum(f['flown_again'] for f in checked)} flown again with longer moves; "
        f"{sum(f['trial_done'] for f in good)} completed the trial and landed."
    )
    for yaw in sorted({f["yaw_offset_deg"] for f in flights} - {0.0}):
        wrong = [f for f in flights if f["yaw_offset_deg"] == yaw]
        rows.append(
            f"Room rotated {yaw:g} deg: {len(wrong)} flights, "
            f"{sum(f['check_refused'] for f in wrong)} refused by the frame check, "
            f"{sum(f['check_passed'] for f in wrong)} passed it, "
            f"{sum(f['trial_done'] for f in wrong)} completed the trial."
        )
    loads = sorted(f["load_before"] for f in flights)
    if loads:
        rows.append(f"Load average (1 min) before the flights: {loads[0]:.1f}-{loads[-1]:.1f}, "
                    f"median {loads[len(loads) // 2]:.1f} (2 cores).")  # fmt: skip
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", type=int, default=30, help="flights with a correct mapping")
    parser.add_argument("--parallel", type=int, default=2, help="PX4 instances at a time")
    parser.add_argument(
        "--wrong", default="90:2,180:2", help="YAW:COUNT of flights with the room rotated"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "logs" / "frame-check-px4.jsonl")
    parser.add_argument("--table-from", type=Path, help="only print the table of a JSONL log")
    args = parser.parse_args()
    if args.table_from:
        lines = args.table_from.read_text().splitlines()
        print(table([json.loads(ln) for ln in lines if ln.strip()]))
        return
    build = Px4Build(build_dir()[0])
    build.runnable()
    wrong: list[float] = []
    for part in filter(None, args.wrong.split(",")):
        yaw, count = part.split(":")
        wrong += [float(yaw)] * int(count)
    # the rotated rooms spread among the correct flights, so that all see the same load
    plan = [0.0] * args.flights
    for i, yaw in enumerate(wrong):
        plan.insert(round((i + 0.5) * len(plan) / len(wrong)), yaw)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    flights: list[dict] = []

    def one(item: tuple[int, float]) -> dict:
        number, yaw = item
        try:
            result = fly(build, number, yaw)
        except Exception as exc:  # noqa: BLE001 - a rig that did not start is a row too
            load = round(os.getloadavg()[0], 2)
            result = {"flight": number, "yaw_offset_deg": yaw, "exit": None, "checked": False,
                      "check_refused": False, "check_passed": False, "unjudged": False,
                      "flown_again": False, "trial_done": False, "checks": [],
                      "ended": f"rig: {type(exc).__name__}: {exc}"[:200],
                      "load_before": load, "load_after": load}  # fmt: skip
        line = json.dumps(result)
        print(line, flush=True)
        with args.out.open("a") as log:
            log.write(line + "\n")
        return result

    with ThreadPoolExecutor(args.parallel) as pool:
        flights = list(pool.map(one, enumerate(plan, start=1)))
    print(table(flights))


if __name__ == "__main__":
    main()
