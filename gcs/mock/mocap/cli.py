"""``python -m gcs.mock.mocap``: the mock OptiTrack Motive as a program."""

from __future__ import annotations

import json
import signal
import sys
from typing import Annotated

import typer

from gcs.core.frames import SYSTEM_FRAMES, mapping_for
from gcs.io.scheduling import raise_thread
from gcs.mock.child import end_with_parent
from gcs.mock.mocap.natnet import VERSIONS
from gcs.mock.mocap.scripted import Circle, Hover, in_room
from gcs.mock.mocap.server import FaultWindow, NatNetServer, PoseFn, parse_fault_window

__all__ = ["mocap_command", "parse_window", "parse_version", "serve"]


def parse_window(kind: str, text: str) -> FaultWindow:
    """Parse ``START:DURATION`` (or ``START:DURATION:DX:DY:DZ`` for a jump).

    ``text``: option value [s, s, m, m, m].
    """
    try:
        return parse_fault_window(kind, text, f"--{kind}")
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc


def parse_version(text: str) -> tuple[int, int]:
    """Parse a NatNet version ``MAJOR.MINOR``."""
    try:
        major, minor = (int(v) for v in text.split("."))
    except ValueError:
        major, minor = -1, -1
    if (major, minor) not in VERSIONS:
        known = ", ".join(f"{a}.{b}" for a, b in VERSIONS)
        raise typer.BadParameter(f"--natnet must be one of {known}, got {text!r}")
    return major, minor


def _faults(options: dict[str, list[str]]) -> tuple[FaultWindow, ...]:
    return tuple(parse_window(kind, text) for kind, texts in options.items() for text in texts)


def mocap_command(
    body: Annotated[str, typer.Option("--body", help="Rigid body name.")] = "drone",
    rate_hz: Annotated[
        float, typer.Option("--rate", min=50.0, max=360.0, help="Frame rate, Hz.")
    ] = 120.0,
    natnet: Annotated[
        str, typer.Option("--natnet", help="NatNet version: 3.0 3.1 4.0 4.1.")
    ] = "4.1",
    noise_mm: Annotated[
        float, typer.Option("--noise-mm", min=0.0, help="Marker noise, mm (1 sigma per axis).")
    ] = 0.2,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the marker noise.")] = 0,
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="Command port on 127.0.0.1; 0 = free.")
    ] = 0,
    room: Annotated[
        str, typer.Option("--room", help=f"Axes of the mocap: {', '.join(SYSTEM_FRAMES)}.")
    ] = "optitrack",
    yaw_offset_deg: Annotated[
        float, typer.Option("--yaw-offset-deg", help="Heading of the room's north axis, deg.")
    ] = 0.0,
    latency_ms: Annotated[
        float,
        typer.Option(
            "--latency-ms",
            min=0.0,
            max=50.0,
            help="Time from the body's motion to the frame, ms: each frame shows the body as "
            "it was this long before.",
        ),
    ] = 0.0,
    circle: Annotated[
        str | None,
        typer.Option("--circle", help="Fly RADIUS:PERIOD (m, s) around (0, 0, -1) NED."),
    ] = None,
    occlusion: Annotated[
        list[str] | None, typer.Option("--occlusion", help="START:DURATION, s (repeatable).")
    ] = None,
    dropout: Annotated[
        list[str] | None, typer.Option("--dropout", help="No frames START:DURATION, s.")
    ] = None,
    freeze: Annotated[
        list[str] | None, typer.Option("--freeze", help="Same frame repeated START:DURATION, s.")
    ] = None,
    jump: Annotated[
        list[str] | None,
        typer.Option("--jump", help="START:DURATION:DX:DY:DZ, s and m (mocap axes)."),
    ] = None,
) -> None:
    """Run a mock OptiTrack Motive streaming one rigid body over NatNet.

    It binds two UDP sockets on 127.0.0.1 (command port ``--port``, data port any free one),
    sends frames to the multicast group 239.255.42.99 through the loopback interface only,
    and prints exactly one line on stdout, ``READY optitrack://127.0.0.1:<port>/<body>?
    interface=127.0.0.1``: the URL of gcs's mocap client. The vehicle hovers at 1 m above
    the origin (or flies ``--circle``) in NED; the room's axes (``--room``, Motive's Y-up
    by default, and ``--yaw-offset-deg``) say how the mocap sees it. Fault times count from
    the start of the program. SIGTERM or Ctrl-C stops it and prints its counters (JSON) on
    stderr.

    ``--latency-ms`` is the time from the body's motion to the frame: each frame carries the
    pose of that long before (never extrapolated to now), and its mid-exposure stamp is that
    much older than the frame's instant, so the system latency a NatNet client computes
    (transmit minus mid-exposure) shows it. OptiTrack's "Latency Measurements" page (NatNet
    SDK) defines that system latency and puts the camera's own part, for a PrimeX 41, at
    2.78 ms at 360 Hz up to 5.56 ms at 180 Hz and below. PX4's "Using Vision or Motion
    Capture Systems" page (v1.16) sets EKF2_EV_DELAY (0-300 ms) to the gap between a
    measurement's timestamp and its capture, zero only with true capture stamps and time
    synchronisation, else tuned by hand since the delays of the whole mocap-to-PX4 chain are
    specific to each set-up. The range, 0-50 ms, spans a Motive alone up to such a chain, as
    far as gcs's pre-flight check accepts for EKF2_EV_DELAY.

    Examples:

        python -m gcs.mock.mocap --rate 240 --circle 1:6

        python -m gcs.mock.mocap --occlusion 5:0.5 --jump 8:0.05:0.3:0:0
    """
    version = parse_version(natnet)
    faults = _faults(
        {
            "occlusion": occlusion or [],
            "dropout": dropout or [],
            "freeze": freeze or [],
            "jump": jump or [],
        }
    )
    if circle is None:
        truth = Hover()
    else:
        try:
            radius, period = (float(v) for v in circle.split(":"))
        except ValueError:
            raise typer.BadParameter(f"--circle must be RADIUS:PERIOD, got {circle!r}") from None
        truth = Circle(radius_m=radius, period_s=period)
    serve(
        truth,
        body=body,
        rate_hz=rate_hz,
        version=version,
        noise_mm=noise_mm,
        seed=seed,
        port=port,
        room=room,
        yaw_offset_deg=yaw_offset_deg,
        latency_ms=latency_ms,
        faults=faults,
    )


def serve(
    pose_ned: PoseFn,
    *,
    body: str = "drone",
    rate_hz: float = 120.0,
    version: tuple[int, int] = (4, 1),
    noise_mm: float = 0.2,
    seed: int = 0,
    port: int = 0,
    room: str = "optitrack",
    yaw_offset_deg: float = 0.0,
    latency_ms: float = 0.0,
    faults: tuple[FaultWindow, ...] = (),
    epoch_s: float | None = None,
) -> None:
    """Serve a NED truth as the mock Motive until SIGTERM or Ctrl-C: the body of
    :func:`mocap_command`, for any pose function of time.

    Prints ``READY <url>`` on stdout once it serves, a line on stderr saying where, and its
    counters (JSON) on stderr when it stops.

    ``pose_ned``: ``pose_ned(t_s) -> (pos_m, quat_wxyz)`` in NED at server time ``t_s``, or None
    (out of view); seen through the room's axes (:func:`gcs.mock.mocap.scripted.in_room`).
    ``rate_hz``: frame rate [Hz]. ``noise_mm``: marker noise [mm]. ``port``: command port (0 = any
    free port). ``room``: named convention of the room's axes. ``yaw_offset_deg``: heading of the
    room's north axis [deg]. ``latency_ms``: time from the body's motion to the frame [ms].
    ``faults``: fault windows, in seconds from the start. ``epoch_s``: ``time.monotonic()`` at
    server time 0 (a pose function on the monotonic clock shares it); None: when the server is
    created.
    """
    raise_thread()  # as a real Motive is never starved by gcs's machine (gcs.io.scheduling)
    server = NatNetServer(
        in_room(pose_ned, mapping_for(room, yaw_offset_deg=yaw_offset_deg)),
        body_name=body,
        rate_hz=rate_hz,
        version=version,
        noise_m=noise_mm / 1000.0,
        faults=faults,
        seed=seed,
        command_port=port,
        latency_s=latency_ms / 1000.0,
        epoch_s=epoch_s,
    )
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: server.stop())
    end_with_parent()  # a killed parent does not leave it serving
    print(f"READY {server.url}", flush=True)
    print(
        f"mock Motive (NatNet {version[0]}.{version[1]}) on 127.0.0.1:{server.command_port}, "
        f"frames to {server.multicast_group}:{server.data_port} on loopback; Ctrl-C to stop",
        file=sys.stderr,
        flush=True,
    )
    try:
        server.serve()
    finally:
        server.close()
        print(json.dumps(server.stats()), file=sys.stderr, flush=True)
