"""The reader process: the ``motioncapture`` library, alone in a process of its own.

Why a process and not a thread: ``motioncapture.connect`` (1.1) holds Python's GIL while it
waits, without a timeout, for the server's answer to ``NAT_CONNECT``; a server that does not
answer therefore freezes every thread of the process, the asyncio loop that streams setpoints
included (verified: a ticker thread stops dead). ``waitForNextFrame`` releases the GIL but
blocks without a timeout and cannot be interrupted from another thread, and the library parses
datagrams with unchecked ``memcpy``. In a process of its own, a hung connect is ended by a
timeout, a stopped server by a signal, and a crash costs the mocap stream, not the flight.

The process is started by :class:`gcs.flight.mocap.client.MocapClient` in its own session
(a Ctrl-C in the terminal does not reach it: gcs decides when the stream ends, e.g. after
landing) and dies with its parent (``PR_SET_PDEATHSIG``). It writes records to the file
descriptor it is given, each ``kind (1 byte) | length (uint16) | payload``:

- ``C``: connected (the server answered), no payload;
- ``S``: a frame: ``int64 seq, float64 t_receipt_s, bool tracked, 3 float64 position,
  4 float64 quaternion w x y z`` (little-endian), the rigid body's pose in the system's axes;
- ``N``: the names of the rigid bodies tracked in the frame, JSON, sent when they change;
- ``E``: an error, UTF-8 text; the process then exits.

``t_receipt_s`` is ``time.monotonic()`` right after ``waitForNextFrame`` returned: on Linux the
monotonic clock is shared by all processes, so it is comparable with the parent's.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import math
import os
import signal
import struct
import sys
import time
from typing import Any

from gcs.io.scheduling import raise_thread

__all__ = ["SAMPLE", "HEADER", "pack_record", "main"]

HEADER = struct.Struct("<cH")
SAMPLE = struct.Struct("<qd?3d4d")
_PR_SET_PDEATHSIG = 1


def pack_record(kind: bytes, payload: bytes = b"") -> bytes:
    """One record of the reader's output.

    Parameters
    ----------
    kind : bytes
        ``b"C"``, ``b"S"``, ``b"N"`` or ``b"E"``.
    payload : bytes
        Its payload (at most 65535 bytes; longer text is cut).

    Returns
    -------
    bytes
    """
    payload = payload[:0xFFFF]
    return HEADER.pack(kind, len(payload)) + payload


def _die_with_parent() -> None:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: the parent's stop() still ends us
        pass


def _run(out: int, system: str, config: dict[str, str], body: str) -> None:
    def put(kind: bytes, payload: bytes = b"") -> None:
        os.write(out, pack_record(kind, payload))

    try:
        import motioncapture
    except ImportError:
        put(b"E", b"the motioncapture package is not installed (pip install motioncapture)")
        return
    try:
        mocap = motioncapture.connect(system, config)
    except Exception as exc:  # the library raises plain RuntimeErrors from C++
        put(b"E", f"{system} connect failed: {exc}".encode())
        return
    put(b"C")
    names: list[str] = []
    seq = 0
    nan3, nan4 = (math.nan,) * 3, (math.nan,) * 4
    while True:
        mocap.waitForNextFrame()
        t_receipt = time.monotonic()
        bodies = mocap.rigidBodies
        seen = sorted(bodies)
        if seen != names:
            names = seen
            put(b"N", json.dumps(names).encode())
        rb = bodies.get(body)
        if rb is None:
            put(b"S", SAMPLE.pack(seq, t_receipt, False, *nan3, *nan4))
        else:
            q = rb.rotation
            put(b"S", SAMPLE.pack(seq, t_receipt, True, *rb.position.tolist(), q.w, q.x, q.y, q.z))
        seq += 1


def main(argv: list[str] | None = None) -> int:
    """Entry point: ``python -m gcs.flight.mocap.reader FD JSON``.

    Parameters
    ----------
    argv : list of str or None
        ``[fd, json]`` with ``json`` = ``{"system": ..., "config": {...}, "body": ...}``;
        None reads ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit code.
    """
    args = sys.argv[1:] if argv is None else argv
    out = int(args[0])
    spec: dict[str, Any] = json.loads(args[1])
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()
    raise_thread()  # its receipt times are the stream's: gcs.io.scheduling
    try:
        _run(out, spec["system"], spec["config"], spec["body"])
    except BrokenPipeError:
        return 0  # the client has gone
    except Exception as exc:
        with contextlib.suppress(OSError):
            os.write(out, pack_record(b"E", f"mocap reader failed: {exc!r}".encode()))
        return 1
    return 1


if __name__ == "__main__":
    sys.exit(main())
