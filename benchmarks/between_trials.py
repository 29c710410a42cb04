"""What the vehicle receives while gcs learns between trials: the learning in a thread of the
flight process (as before) or in a worker process of its own (``gcs.app.source_worker``).

Each flight is ``gcs fly --connect ... --mocap ...`` on the indoor mock (``profiles/
mock-mocap.yaml``: no GPS, it navigates on the vision gcs forwards from the mock arena's NatNet
stream at 120 Hz) with ``profiles/antx-adaptive.yaml`` (a ``mocap`` section added, the model's
gain 40 % too strong as in tests/test_fly_adaptive_virtual.py, and one repeat of trial 0, so
that the learning step after trial 2 refreshes the model; the tests' watchdog limits,
``tests/synthetic.py:CI_FLIGHT``, as the machine is shared), ``--iter 4`` trials of
``eight-short``, with ``--load`` processes burning CPU beside it (each bounded in time). Two
modes, alternated ``--pairs`` times:

- ``thread``: the run's trial source built in the flight process and called in its threads
  (``asyncio.to_thread``), as gcs did before the worker process;
- ``process``: ``gcs fly`` as it is (the source in its worker process).

Per flight, from the mock's own records (vehicle clock) and the run's trial sidecars: the largest
gap between external-vision messages received, and between setpoints received, during the trials
and between them (from the end of a trial to the start of the next, after the last one to the
landing); the hover time between two trials (end of one trial to the start of the next); whether
the flight completed (a stale mocap stream aborts it).

``--ticker SECONDS`` measures the same without flying, in one process: a 120 Hz asyncio ticker
(what the flight loop needs: a tick per mocap frame) beside a stand-in for a learning step
(SECONDS of CPU time in pure-Python loops, as the model refresh is), called with
``asyncio.to_thread`` on a trial source in this process (``thread``) or in its worker
(``process``); per mode the share of the ticker's periods in which a tick came (one that
catches up late fills no earlier period) and the largest gap between two ticks,
alternated ``--pairs`` times.

``--no-stream-watch`` flies without gcs's own mocap stream watch (only a reader that ended
stops the flight): on a loaded machine it can end a flight on the reader's delays before any
learning, while the vehicle still receives the vision (tests/test_source_worker_e2e.py).

Usage: ``flock /tmp/gcs-live.lock .venv/bin/python benchmarks/between_trials.py [--pairs 1]
[--load 1] [--iter 4] [--ticker 5] [--no-stream-watch] [--keep DIR]``. Prints one line per
flight (or ticker run), then the medians per mode.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from flight_gaps import Gaps, gaps  # noqa: E402
from synthetic import CI_FLIGHT  # noqa: E402

from gcs.app.source_worker import WorkerSource  # noqa: E402
from gcs.io.rundir import RunDir  # noqa: E402
from gcs.mock.mocap.arena import ArenaOptions  # noqa: E402
from gcs.mock.process import MockProcess  # noqa: E402

INDOOR = ROOT / "profiles" / "mock-mocap.yaml"
TRAJECTORY = ROOT / "trajectories" / "eight-short.yaml"
TIMEOUT_S = 900.0


class InProcess:
    """``WorkerSource``'s stand-in of the ``thread`` mode: the source built in this process."""

    def __init__(self, build, args=(), callbacks=None):  # noqa: ANN001
        callbacks = callbacks or {}
        self.source = build(*args, notify=lambda kind, payload: callbacks[kind](payload))

    def __enter__(self):  # noqa: ANN204
        return self.source

    def __exit__(self, *exc: object) -> None:
        pass


def child(mode: str, watch: bool, argv: list[str]) -> None:
    """Run ``gcs`` with the trial source in a thread (``thread``) or its worker (``process``)."""
    import gcs.app.fly
    import gcs.app.session
    from gcs.cli import app
    from gcs.flight.mocap.link import MocapLink

    class VehicleJudged(MocapLink):
        """Without gcs's stream watch: only a reader that ended stops the flight."""

        def problem(self) -> str | None:
            return self.client.problem()

    if mode == "thread":
        gcs.app.fly.WorkerSource = InProcess  # type: ignore[misc,assignment]
    if not watch:
        gcs.app.session.MocapLink = VehicleJudged  # type: ignore[misc]
    app(argv, prog_name="gcs")


class Busy:
    """A trial source whose ``record`` is ``seconds`` of pure-Python loops (a learning step)."""

    def __init__(self, seconds: float, notify=None) -> None:  # noqa: ANN001
        self.seconds = seconds

    def hover_point_for(self, j: int) -> np.ndarray:
        return np.zeros(3)

    def record(self, j: int, recording: object) -> None:
        end = time.thread_time() + self.seconds
        total = 0
        while time.thread_time() < end:
            for i in range(1000):
                total += i * i


def busy(seconds: float, *, notify) -> Busy:  # noqa: ANN001
    return Busy(seconds)


def ticker(mode: str, seconds: float, rate_hz: float = 120.0) -> tuple[float, float]:
    """Share of the ticks that came and the largest gap [s], while the source is busy."""

    async def run(source: object) -> tuple[float, float]:
        ticks: list[float] = []
        job = asyncio.ensure_future(asyncio.to_thread(source.record, 0, None))
        period, t0 = 1.0 / rate_hz, time.monotonic()
        while not job.done():
            ticks.append(time.monotonic())
            await asyncio.sleep(max(0.0, t0 + len(ticks) * period - time.monotonic()))
        await job
        slots = np.floor((np.asarray(ticks) - t0) * rate_hz)  # a catch-up tick fills no gap
        return len(np.unique(slots)) / (slots[-1] + 1), float(max(np.diff(ticks)))

    if mode == "thread":
        return asyncio.run(run(Busy(seconds)))
    with WorkerSource(busy, (seconds,)) as source:
        source.hover_point_for(0)  # started and built before the measurement
        return asyncio.run(run(source))


def adaptive_profile(tmp: Path) -> Path:
    data = yaml.safe_load((ROOT / "profiles" / "antx-adaptive.yaml").read_text())
    data["model"]["num"] = [1.4 * v for v in data["model"]["num"]]
    data["learning"]["adaptive"]["repeats"] = 1  # the refresh after trial 2, in --iter 4
    data["flight"] = dict(data.get("flight") or {}, **CI_FLIGHT)
    data["mocap"] = {}
    path = tmp / "antx-adaptive-mocap.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def burners(count: int, seconds: float) -> list[subprocess.Popen]:
    code = f"import time\nend = time.monotonic() + {seconds}\nwhile time.monotonic() < end: pass"
    return [subprocess.Popen([sys.executable, "-c", code]) for _ in range(count)]


def flight(
    tmp: Path, mode: str, seed: int, iterations: int, load: int, watch: bool
) -> tuple[Gaps | None, str]:
    run_path = tmp / f"run-{mode}-{seed}"
    watch = [] if watch else ["--no-stream-watch"]
    stats = tmp / f"stats-{mode}-{seed}.json"
    with MockProcess(config_path=INDOOR, seed=seed, stats_path=stats, arena=ArenaOptions()) as m:
        argv = [
            "fly", "--connect", m.url, "--mocap", m.mocap_url, "--iter", str(iterations),
            "--trajectory", str(TRAJECTORY), "--profile", str(adaptive_profile(tmp)),
            "--run", str(run_path),
        ]  # fmt: skip
        hogs = burners(load, TIMEOUT_S)
        try:
            proc = subprocess.run(
                [sys.executable, __file__, "--child", mode, *watch, "--", *argv],
                cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S,
                env={**os.environ, "COLUMNS": "200"},
            )  # fmt: skip
        finally:
            for hog in hogs:
                hog.kill()
                hog.wait()
    out = proc.stdout + proc.stderr
    why = [line.strip() for line in out.splitlines() if "aborting" in line or "error" in line]
    outcome = "ok" if proc.returncode == 0 else f"exit {proc.returncode}: {' / '.join(why)}"
    run = RunDir.open(run_path)
    if not run.complete_trials():
        return None, outcome
    return gaps(run, json.loads(stats.read_text())), outcome


def ms(value: float) -> str:
    return f"{1e3 * value:6.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=1)
    parser.add_argument("--load", type=int, default=1, help="CPU-burning processes beside")
    parser.add_argument("--iter", type=int, default=4)
    parser.add_argument("--child", choices=("thread", "process"))
    parser.add_argument(
        "--no-stream-watch",
        action="store_true",
        help="fly without gcs's mocap stream watch (the vehicle's reception is measured)",
    )
    parser.add_argument("--keep", help="keep the runs and the mock's records in a folder here")
    parser.add_argument("--ticker", type=float, help="learning seconds beside a 120 Hz ticker")
    args, rest = parser.parse_known_args()
    if args.child is not None:
        child(args.child, not args.no_stream_watch, [a for a in rest if a != "--"])
        return
    if args.ticker is not None:
        print(f"load: {os.getloadavg()[0]:.1f} (1-min average) + {args.load} CPU burner(s)")
        hogs = burners(args.load, TIMEOUT_S)
        try:
            for _ in range(args.pairs):
                for mode in ("thread", "process"):
                    share, gap = ticker(mode, args.ticker)
                    print(
                        f"ticker {mode:8}: {100 * share:5.1f} % of the 120 Hz periods ticked, "
                        f"largest gap {ms(gap)} ms, beside {args.ticker:g} s of learning "
                        f"[load {os.getloadavg()[0]:.1f}]",
                        flush=True,
                    )
        finally:
            for hog in hogs:
                hog.kill()
                hog.wait()
        return
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) + {args.load} CPU burner(s)")
    print("mode     seed  vision max gap [ms]  setpoint max gap [ms]  hover between trials [s]")
    print("                trial    between     trial    between")
    results: dict[str, list[Gaps]] = {"thread": [], "process": []}
    keep = contextlib.nullcontext(tempfile.mkdtemp(dir=args.keep)) if args.keep else None
    with keep or tempfile.TemporaryDirectory() as tmp:
        print(f"runs in {tmp}" if args.keep else "", end="\n" if args.keep else "")
        for pair in range(args.pairs):
            for mode in ("thread", "process"):
                seed = 10 + pair
                watch = not args.no_stream_watch
                g, outcome = flight(Path(tmp), mode, seed, args.iter, args.load, watch)
                if g is None:
                    print(f"{mode:8} {seed:4}  (no complete trial) {outcome}")
                    continue
                results[mode].append(g)
                hovers = ", ".join(f"{h:.1f}" for h in g.hover_between_s)
                print(
                    f"{mode:8} {seed:4}  {ms(g.vision_trial_s)}   {ms(g.vision_between_s)}    "
                    f"{ms(g.setpoint_trial_s)}   {ms(g.setpoint_between_s)}   {hovers}  "
                    f"[{outcome}; load {os.getloadavg()[0]:.1f}]",
                    flush=True,
                )
    for mode, rows in results.items():
        if not rows:
            continue

        def med(key: str, rows: list[Gaps] = rows) -> float:
            return statistics.median(getattr(g, key) for g in rows)

        hovers = [h for g in rows for h in g.hover_between_s]
        print(
            f"median {mode}: vision {ms(med('vision_trial_s'))} / {ms(med('vision_between_s'))} "
            f"ms, setpoints {ms(med('setpoint_trial_s'))} / {ms(med('setpoint_between_s'))} ms "
            f"(trial / between); hover between trials {statistics.median(hovers):.1f} s"
        )


if __name__ == "__main__":
    main()
