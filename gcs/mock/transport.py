"""The mock drone's UDP transport and its two clocks (a part of the mock's server).

One UDP socket bound on ``127.0.0.1:PORT``; every datagram sent goes through
:meth:`Transport._transmit`, where the injected link faults act (a lost link, a telemetry
dropout, packet loss, latency); every datagram received goes through :meth:`Transport._drain`
(the same faults, inbound). Only the injected latency is wall time.

Vehicle time. The vehicle's clock is ``Faults.clock_rate`` times the monotonic clock since
boot (1 by default): the physics, the PX4 timeouts, the stream periods and every time stamp
sent run on it (:meth:`Transport._t`), as in a simulator that is slower (or faster) than real
time.
"""

from __future__ import annotations

import heapq
import time
from typing import Any

__all__ = ["DatagramWriter", "Transport"]


class DatagramWriter:
    """File-like sink that pymavlink's ``*_send`` methods write packed datagrams into."""

    def __init__(self, server: Any) -> None:
        self.server = server

    def write(self, buf: bytes) -> None:
        """Send one packed datagram."""
        self.server._transmit(bytes(buf))


class Transport:
    """Socket, link faults and clocks of :class:`gcs.mock.server.MockServer` (its state)."""

    def _t(self, now: float | None = None) -> float:
        """Vehicle time [s] at a monotonic time (default: now)."""
        return ((time.monotonic() if now is None else now) - self.t0) * self.clock_rate

    def _wall(self, t_s: float) -> float:
        """Monotonic time [s] of a vehicle time."""
        return self.t0 + t_s / self.clock_rate

    def _t_offboard(self) -> float | None:
        first = self.vehicle.first_offboard_t_s
        return None if first is None else self._t() - first

    def _transmit(self, buf: bytes) -> None:
        f = self.faults
        t_off = self._t_offboard()
        if f.link_lost(t_off) or (self._telemetry_now and f.dropout_active(t_off)):
            self.counts["tx_dropped"] += 1
            return
        if f.loss_fraction > 0 and self._fault_rng.random() < f.loss_fraction:
            self.counts["tx_dropped"] += 1
            return
        if f.latency_ms > 0:
            self._push_delayed("out", buf, None)
            return
        self._sendto(buf)

    def _sendto(self, buf: bytes) -> None:
        for peer in self.peers:
            try:
                self.sock.sendto(buf, peer)
                self.counts["tx"] += 1
            except OSError:
                pass  # nobody listening (ICMP port unreachable); UDP carries on

    def _push_delayed(self, kind: str, buf: bytes, addr: tuple[str, int] | None) -> None:
        self._delayed_seq += 1
        due = time.monotonic() + self.faults.latency_ms / 1000.0
        heapq.heappush(self._delayed, (due, self._delayed_seq, kind, buf, addr))

    def _release_delayed(self, now: float) -> None:
        while self._delayed and self._delayed[0][0] <= now:
            _, _, kind, buf, addr = heapq.heappop(self._delayed)
            if kind == "out":
                self._sendto(buf)
            else:
                assert addr is not None
                self._handle_datagram(buf, addr)

    def _drain(self) -> None:
        f = self.faults
        while True:
            try:
                data, addr = self.sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP error from an earlier send
            self.counts["rx"] += 1
            if f.link_lost(self._t_offboard()) or (
                f.loss_fraction > 0 and self._fault_rng.random() < f.loss_fraction
            ):
                self.counts["rx_dropped"] += 1
                continue
            if f.latency_ms > 0:
                self._push_delayed("in", data, addr)
            else:
                self._handle_datagram(data, addr)
