"""Latency and CPU of the mocap client against the mock Motive (NatNet over loopback).

The mock server runs in a process of its own (as Motive would), sending a circle at each
rate; this process runs only the client (the ``motioncapture`` library in its reader process,
the client thread here). Each delivered sample is matched to the frame the server sent by its
position (float32, exact: the marker noise makes every frame unique). Figures per rate:

- ``library_ms``: server send -> the library returned the frame in the reader process;
- ``delivered_ms``: server send -> the sample reached the client thread here (+ pipe);
- ``delivered_fraction``: samples / frames sent during the run (the library keeps only the
  newest frame when it falls behind);
- ``reader_cpu_pct``, ``thread_cpu_pct``: CPU of the reader process and of the client thread,
  percent of one core;
- ``baseline_ms``: the same frames received by a plain socket in a thread of this process
  (joined to the group, no library, no parsing), the floor of what any client could do here;
  ``delivered_over_baseline`` is the ratio of the medians.

Usage: .venv/bin/python benchmarks/mocap_latency.py [--seconds 10]
Output: a table, then one JSON line per rate (medians, 95th and 99th percentiles, max).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import socket
import struct
import threading
import time

import numpy as np

from gcs.core.frames import mapping_for
from gcs.flight.mocap.client import MocapClient, MocapSample
from gcs.io.mocap_source import parse_mocap_url
from gcs.mock.mocap.scripted import Circle, in_room
from gcs.mock.mocap.server import NatNetServer

RATES_HZ = (100.0, 240.0)


def _serve(rate_hz: float, urls: mp.Queue, stop: mp.Event, sent: mp.Queue) -> None:
    pose = in_room(Circle(radius_m=1.0, period_s=4.0), mapping_for("optitrack"))
    with NatNetServer(pose, rate_hz=rate_hz, noise_m=2e-4) as server:
        urls.put((server.url, server.data_port))
        stop.wait()
    sent.put([(f.pos_m, f.frame_number, f.t_send_s) for f in server.sent])


def _baseline(port: int, group: str, stop: threading.Event, out: list) -> None:
    """Receive the frames on a plain socket: (frame number, receipt time)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("0.0.0.0", port))
    mreq = socket.inet_aton(group) + socket.inet_aton("127.0.0.1")
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
    sock.settimeout(0.2)
    while not stop.is_set():
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        out.append((struct.unpack_from("<i", data, 4)[0], time.monotonic()))
    sock.close()


def _stats(values_s: list[float]) -> dict[str, float]:
    ms = 1e3 * np.asarray(values_s)
    return {
        "median": round(float(np.median(ms)), 3),
        "p95": round(float(np.percentile(ms, 95)), 3),
        "p99": round(float(np.percentile(ms, 99)), 3),
        "max": round(float(ms.max()), 3),
    }


def measure(rate_hz: float, seconds: float) -> dict:
    """Run the server at ``rate_hz`` for ``seconds`` and measure the client."""
    ctx = mp.get_context("spawn")
    urls, sent_q, stop = ctx.Queue(), ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=_serve, args=(rate_hz, urls, stop, sent_q))
    proc.start()
    delivered: list[tuple[MocapSample, float]] = []
    url, data_port = urls.get(timeout=30)
    client = MocapClient(
        parse_mocap_url(url),
        on_sample=lambda s: delivered.append((s, time.monotonic())),
    ).start()
    raw: list[tuple[int, float]] = []
    raw_stop = threading.Event()
    raw_thread = threading.Thread(
        target=_baseline, args=(data_port, "239.255.42.99", raw_stop, raw), daemon=True
    )
    raw_thread.start()
    client.wait_until(lambda s: s.tracked, 10.0)
    t0, cpu0 = time.monotonic(), client.cpu_seconds()
    client.wait_until(lambda s: s.t_receipt_s > t0 + seconds, seconds + 10.0)
    t1, cpu1 = time.monotonic(), client.cpu_seconds()
    client.stop()
    raw_stop.set()
    raw_thread.join()
    stop.set()
    records = sent_q.get(timeout=30)
    proc.join()
    sent = {pos: t_send for pos, _, t_send in records}
    by_number = {number: t_send for _, number, t_send in records}
    run = [(s, t) for s, t in delivered if s.tracked and s.t_receipt_s >= t0]
    matched = [(s, t, sent[s.pos_m]) for s, t in run if s.pos_m in sent]
    baseline = [t - by_number[n] for n, t in raw if n in by_number and t0 <= t <= t1]
    delivered_ms = _stats([t - t_send for _, t, t_send in matched])
    baseline_ms = _stats(baseline)
    span = (matched[0][2], matched[-1][2])
    frames = sum(1 for t_send in sent.values() if span[0] <= t_send <= span[1])
    return {
        "rate_hz": rate_hz,
        "seconds": round(seconds, 1),
        "samples": len(matched),
        "delivered_fraction": round(len(matched) / frames, 4),
        "library_ms": _stats([s.t_receipt_s - t_send for s, _, t_send in matched]),
        "delivered_ms": delivered_ms,
        "baseline_ms": baseline_ms,
        "delivered_over_baseline": round(delivered_ms["median"] / baseline_ms["median"], 2),
        "reader_cpu_pct": round(100 * (cpu1["reader"] - cpu0["reader"]) / (t1 - t0), 2),
        "thread_cpu_pct": round(100 * (cpu1["thread"] - cpu0["thread"]) / (t1 - t0), 2),
    }


def main() -> None:
    """Measure at each rate and print the table and JSON lines."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    results = [measure(rate, args.seconds) for rate in RATES_HZ]
    print(f"{'rate':>6} {'library ms (med/p99)':>22} {'delivered ms (med/p99)':>24} "
          f"{'baseline ms (med/p99)':>23} {'ratio':>6} {'fraction':>9} {'reader %':>9} "
          f"{'thread %':>9}")  # fmt: skip
    for r in results:
        lib, dlv, raw = r["library_ms"], r["delivered_ms"], r["baseline_ms"]
        print(
            f"{r['rate_hz']:>6.0f} {lib['median']:>12.3f} / {lib['p99']:<7.3f} "
            f"{dlv['median']:>13.3f} / {dlv['p99']:<8.3f} {raw['median']:>12.3f} / "
            f"{raw['p99']:<8.3f} {r['delivered_over_baseline']:>6.2f} "
            f"{r['delivered_fraction']:>9.4f} {r['reader_cpu_pct']:>9.2f} "
            f"{r['thread_cpu_pct']:>9.2f}"
        )
    for r in results:
        print(json.dumps(r))


if __name__ == "__main__":
    main()
