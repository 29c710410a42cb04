"""``gcs mock``: run the mock drone (the main CLI registers :func:`mock_command`)."""

from __future__ import annotations

import math
import signal
import sys
from pathlib import Path
from typing import Annotated

import typer

from gcs.errors import GcsError
from gcs.io.scheduling import freeze_heap, raise_thread
from gcs.mock.child import end_with_parent
from gcs.mock.config import Faults, load_mock_config
from gcs.mock.mocap.arena import ArenaOptions, parse_arena_fault

__all__ = [
    "mock_command",
    "parse_dropout",
    "parse_gust",
    "parse_estimator_fault",
    "faults_cli_args",
    "run_mock",
    "arena_options",
]


def _floats(text: str, count: int, what: str, fmt: str) -> list[float]:
    parts = text.split(":")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count:
        raise typer.BadParameter(f"{what} must be {fmt}, got {text!r}")
    return values


def parse_dropout(text: str) -> tuple[float, float]:
    """Parse ``START:DURATION`` [s].

    Returns: start and duration [s].
    """
    start, duration = _floats(text, 2, "--dropout", "START:DURATION")
    return start, duration


def parse_gust(text: str) -> tuple[float, float, float, float]:
    """Parse ``START:DURATION:VN:VE`` (s, s, m/s, m/s).

    Returns: start [s], duration [s], wind north and east [m/s].
    """
    start, duration, vn, ve = _floats(text, 4, "--gust", "START:DURATION:VN:VE")
    return start, duration, vn, ve


def parse_estimator_fault(
    text: str, option: str, timed: bool = True
) -> tuple[float, float | None, tuple[float, float, float]]:
    """Parse ``T:D:N:E:D`` (``--drift``, ``--divergence``) or ``T:N:E:D`` (``--jump``).

    ``option``: the option's name, for the message. ``timed``: the value has a duration (drift,
    divergence); ``--jump`` has none.

    Returns: start [s], duration [s] (None for a jump) and the NED vector.
    """
    if timed:
        start, duration, n, e, d = _floats(text, 5, option, "T:D:N:E:D")
        return start, duration, (n, e, d)
    start, n, e, d = _floats(text, 4, option, "T:N:E:D")
    return start, None, (n, e, d)


def _vector(v: tuple[float, float, float] | None) -> str:
    assert v is not None
    return ":".join(repr(float(x)) for x in v)


def faults_cli_args(faults: Faults) -> list[str]:
    """Command-line options of ``gcs mock`` that reproduce a :class:`Faults`.

    Returns: options, empty for no faults.
    """
    args: list[str] = []
    if faults.loss_fraction:
        args += ["--loss", repr(faults.loss_fraction)]
    if faults.latency_ms:
        args += ["--latency-ms", repr(faults.latency_ms)]
    if faults.dropout_start_s is not None:
        args += ["--dropout", f"{faults.dropout_start_s!r}:{faults.dropout_duration_s!r}"]
    if faults.link_loss_at_s is not None:
        args += ["--link-loss-at", repr(faults.link_loss_at_s)]
    if faults.link_loss_duration_s is not None:
        args += ["--link-loss-for", repr(faults.link_loss_duration_s)]
    if faults.clock_rate != 1.0:
        args += ["--clock-rate", repr(faults.clock_rate)]
    if faults.gust_start_s is not None:
        args += [
            "--gust",
            f"{faults.gust_start_s!r}:{faults.gust_duration_s!r}:"
            f"{faults.gust_vn_m_s!r}:{faults.gust_ve_m_s!r}",
        ]
    if faults.drift_start_s is not None:
        duration = faults.drift_duration_s if faults.drift_duration_s is not None else math.inf
        args += [
            "--drift",
            f"{faults.drift_start_s!r}:{duration!r}:{_vector(faults.drift_ned_m_s)}",
        ]
    if faults.divergence_start_s is not None:
        d = faults.divergence_duration_s
        duration = d if d is not None else math.inf
        vector = _vector(faults.divergence_ned_m_s2)
        args += ["--divergence", f"{faults.divergence_start_s!r}:{duration!r}:{vector}"]
    if faults.jump_at_s is not None:
        args += ["--jump", f"{faults.jump_at_s!r}:{_vector(faults.jump_ned_m)}"]
    return args


def run_mock(
    config: Path | None,
    faults: Faults,
    seed: int = 0,
    port: int = 0,
    gcs_port: int | None = None,
    stats_out: Path | None = None,
    arena: ArenaOptions | None = None,
) -> None:
    """Bind, announce ``READY <url>`` on stdout, run until SIGTERM/SIGINT, write the stats.

    With ``arena``, a ``MOCAP <url>`` line (the mock Motive's URL) comes first.

    ``config``: mock profile (YAML); None for the defaults. ``seed``: seed of gusts, noise and
    packet loss. ``port``: UDP port on 127.0.0.1 (0 = ephemeral). ``gcs_port``: also send to a GCS
    listening on 127.0.0.1:gcs_port. ``stats_out``: where to write the JSON statistics on exit.
    ``arena``: serve the vehicle's true pose over NatNet (a mock OptiTrack Motive).
    """
    import json

    from gcs.io.atomic import atomic_write_text
    from gcs.mock.server import MockServer

    cfg = load_mock_config(config)
    raise_thread()  # as PX4 SITL runs its own threads (gcs.io.scheduling); the arena's inherits
    server = MockServer(cfg, faults, seed=seed, port=port, gcs_port=gcs_port, arena=arena)
    freeze_heap()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: server.stop())
    signal.signal(signal.SIGUSR1, lambda *_: server.lose_link_now())
    end_with_parent()  # a killed parent does not leave it flying
    if server.arena is not None:
        sys.stdout.write(f"MOCAP {server.arena.url}\n")
        print(
            f"mock Motive (NatNet) of the vehicle's true pose at {server.arena.url}",
            file=sys.stderr,
            flush=True,
        )
    sys.stdout.write(f"READY {server.url}\n")
    sys.stdout.flush()
    print(
        f"mock drone (PX4 quadrotor, sysid {cfg.px4.system_id}) on 127.0.0.1:{server.port}; "
        f"connect MAVSDK to {server.url}; Ctrl-C to stop",
        file=sys.stderr,
        flush=True,
    )
    try:
        server.run()
    finally:
        if stats_out is not None:
            atomic_write_text(stats_out, json.dumps(server.stats()))


def mock_command(
    config: Annotated[
        Path | None, typer.Option("--config", help="Mock profile (YAML), e.g. profiles/mock.yaml.")
    ] = None,
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="UDP port on 127.0.0.1; 0 = any free.")
    ] = 0,
    gcs_port: Annotated[
        int | None,
        typer.Option("--gcs-port", min=1, max=65535, help="Also send to a GCS on this port."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of gusts, noise, packet loss.")] = 0,
    loss: Annotated[
        float, typer.Option("--loss", min=0.0, max=0.99, help="Datagram loss fraction.")
    ] = 0.0,
    latency_ms: Annotated[
        float, typer.Option("--latency-ms", min=0.0, help="Added one-way latency, ms.")
    ] = 0.0,
    dropout: Annotated[
        str | None, typer.Option("--dropout", help="Telemetry dropout START:DURATION, s.")
    ] = None,
    link_loss_at: Annotated[
        float | None, typer.Option("--link-loss-at", help="Lose the link at T, s.")
    ] = None,
    link_loss_for: Annotated[
        float | None,
        typer.Option(
            "--link-loss-for",
            min=0.0,
            help="Link loss duration, s (default: for good). "
            "SIGUSR1 to the mock starts a link loss of this length at once.",
        ),
    ] = None,
    gust: Annotated[
        str | None, typer.Option("--gust", help="Wind gust START:DURATION:VN:VE (s, s, m/s, m/s).")
    ] = None,
    stats_out: Annotated[
        Path | None, typer.Option("--stats-out", help="Write setpoint arrivals etc. (JSON).")
    ] = None,
    clock_rate: Annotated[
        float,
        typer.Option(
            "--clock-rate",
            min=0.1,
            max=10.0,
            help="Vehicle seconds per wall second, like a simulator under load (e.g. 0.9).",
        ),
    ] = 1.0,
    drift: Annotated[
        str | None,
        typer.Option(
            "--drift",
            help="Estimator drift T:D:VN:VE:VD: from T s after arming, for D s (inf: for good), "
            "the estimated position walks away at (VN, VE, VD) m/s.",
        ),
    ] = None,
    divergence: Annotated[
        str | None,
        typer.Option(
            "--divergence",
            help="Estimator divergence T:D:AN:AE:AD: from T s after arming, for D s, the "
            "estimated position runs away as a t^2/2 with a = (AN, AE, AD) m/s^2.",
        ),
    ] = None,
    jump: Annotated[
        str | None,
        typer.Option(
            "--jump",
            help="Estimator jump T:DN:DE:DD: T s after arming the estimated position steps by "
            "(DN, DE, DD) m.",
        ),
    ] = None,
    mocap: Annotated[
        bool,
        typer.Option(
            "--mocap",
            help="Also serve the vehicle's true pose as a mock OptiTrack Motive (NatNet) and "
            "print 'MOCAP <url>' before READY.",
        ),
    ] = False,
    mocap_rate: Annotated[
        float, typer.Option("--mocap-rate", min=50.0, max=360.0, help="Mocap frame rate, Hz.")
    ] = 120.0,
    mocap_noise_mm: Annotated[
        float, typer.Option("--mocap-noise-mm", min=0.0, help="Marker noise, mm (1 sigma).")
    ] = 0.2,
    mocap_room: Annotated[
        str, typer.Option("--mocap-room", help="Axes of the room's mocap (optitrack: Y up).")
    ] = "optitrack",
    mocap_yaw_offset_deg: Annotated[
        float, typer.Option("--mocap-yaw-offset-deg", help="Heading of the room's north axis.")
    ] = 0.0,
    mocap_body: Annotated[str, typer.Option("--mocap-body", help="Rigid body name.")] = "drone",
    mocap_occlusion: Annotated[
        list[str] | None,
        typer.Option(
            "--mocap-occlusion",
            help="Body not tracked START:DURATION (s after the first OFFBOARD; repeatable).",
        ),
    ] = None,  # fmt: skip
    mocap_dropout: Annotated[
        list[str] | None, typer.Option("--mocap-dropout", help="No frames START:DURATION, s.")
    ] = None,
    mocap_freeze: Annotated[
        list[str] | None,
        typer.Option("--mocap-freeze", help="The same frame repeated START:DURATION, s."),
    ] = None,
    mocap_jump: Annotated[
        list[str] | None,
        typer.Option(
            "--mocap-jump", help="Solved pose offset START:DURATION:DX:DY:DZ (room axes)."
        ),
    ] = None,
) -> None:
    """Run a mock PX4 quadrotor that MAVSDK cannot tell from the real one.

    The mock binds a UDP socket on 127.0.0.1 (``--port``, default any free port) and prints
    exactly one line ``READY udpout://127.0.0.1:<port>`` on stdout; connect MAVSDK (or
    ``gcs fly``) with that URL. It speaks MAVLink 2 as PX4 v1.16 does: heartbeats with PX4
    modes, arming, take-off, hold, land with auto-disarm, offboard with PX4's rules
    (refused without a setpoint stream, falls back to Hold after COM_OF_LOSS_T without
    setpoints), PX4 parameters, and telemetry at PX4-like rates (position and odometry at
    50 Hz; SET_MESSAGE_INTERVAL is honoured). The simulated vehicle follows a PX4-like
    cascaded controller whose x and y closed loops resemble eq. (11) of the paper, with a
    repeatable position-dependent disturbance, random gusts and millimetre mocap noise.
    ``--config profiles/mock-gps.yaml`` is instead a vehicle like PX4 SITL on GPS + EKF2:
    it flies on an estimate that wanders by decimetres (the truth goes to ``--stats-out``).

    Indoor arena: ``--mocap`` serves the vehicle's true pose as a mock OptiTrack Motive over
    NatNet (multicast on loopback; URL on a 'MOCAP' line before READY) at ``--mocap-rate``
    with marker noise and faults (``--mocap-occlusion``, ``--mocap-dropout``,
    ``--mocap-freeze``, ``--mocap-jump``, timed from the first OFFBOARD). With ``--config
    profiles/mock-mocap.yaml`` the vehicle has no GPS and a position only while external
    vision arrives (``gcs fly --mocap`` forwards it), as EKF2 on vision alone.

    Faults: ``--loss`` and ``--latency-ms`` apply from the start and to both directions. The
    times of ``--dropout``, ``--link-loss-at`` and ``--gust`` count in seconds from the
    moment the vehicle first enters OFFBOARD. A dropout silences the telemetry streams
    (heartbeats and command replies go on); a link loss silences everything, for good or for
    ``--link-loss-for`` seconds; a gust blows the given north/east wind through the drag.

    ``--clock-rate R`` runs the vehicle's clock at R times the wall clock, as a simulator
    that cannot keep up (PX4 SITL in lockstep on a loaded machine: 0.72-0.9): physics, PX4
    timeouts, stream rates and every time stamp the mock sends follow it; fault times count
    on it.

    Estimator faults count from the vehicle's first **arming** (so that one can strike during
    take-off): ``--drift``, ``--divergence`` and ``--jump`` move the estimated position (what
    the mock reports and flies on) away from the truth; the estimated velocity stays right.
    The mock honours a geofence uploaded with MAVSDK's Geofence plugin (the MAVLink mission
    protocol) as PX4 does, with ``GF_ACTION``, ``GF_MAX_HOR_DIST`` and ``GF_MAX_VER_DIST``.

    SIGTERM or Ctrl-C stops it; with ``--stats-out`` it then writes, atomically, a JSON file
    with the arrival time (monotonic clock and vehicle time) and value of every position
    setpoint, the mode changes and packet counters, and with an estimator the true position
    and the estimator's error every 0.02 s.

    Examples:

        gcs mock --seed 3

        gcs mock --config profiles/mock.yaml --gust 5:2:0:3 --stats-out /tmp/mock.json

        gcs mock --config profiles/mock-gps.yaml --seed 1 --stats-out /tmp/mock-gps.json

        gcs mock --clock-rate 0.8

        gcs mock --divergence 1.0:30:0:0:1.5 --stats-out /tmp/incident.json
    """
    arena = None
    if mocap:
        arena = arena_options(
            mocap_rate, mocap_noise_mm, mocap_room, mocap_yaw_offset_deg, mocap_body, seed,
            {"occlusion": mocap_occlusion, "dropout": mocap_dropout, "freeze": mocap_freeze,
             "jump": mocap_jump},
        )  # fmt: skip
    try:
        faults = Faults(
            loss_fraction=loss,
            latency_ms=latency_ms,
            dropout_start_s=parse_dropout(dropout)[0] if dropout else None,
            dropout_duration_s=parse_dropout(dropout)[1] if dropout else None,
            link_loss_at_s=link_loss_at,
            link_loss_duration_s=link_loss_for,
            gust_start_s=parse_gust(gust)[0] if gust else None,
            gust_duration_s=parse_gust(gust)[1] if gust else None,
            gust_vn_m_s=parse_gust(gust)[2] if gust else 0.0,
            gust_ve_m_s=parse_gust(gust)[3] if gust else 0.0,
            clock_rate=clock_rate,
            **estimator_faults(drift, divergence, jump),
        )
    except ValueError as exc:
        if isinstance(exc, GcsError):
            raise
        raise typer.BadParameter(str(exc)) from exc
    run_mock(
        config, faults, seed=seed, port=port, gcs_port=gcs_port, stats_out=stats_out,
        arena=arena,
    )  # fmt: skip


def arena_options(
    rate_hz: float,
    noise_mm: float,
    room: str,
    yaw_offset_deg: float,
    body: str,
    seed: int,
    faults: dict[str, list[str] | None],
) -> ArenaOptions:
    """The arena options of ``gcs mock --mocap ...`` (a bad value is a usage error).

    ``rate_hz``: frame rate [Hz]. ``noise_mm``: marker noise [mm]. ``room``: named convention of the
    room's axes. ``yaw_offset_deg``: heading of the room's north axis [deg].
    """
    try:
        windows = tuple(
            parse_arena_fault(kind, text) for kind, texts in faults.items() for text in texts or []
        )
        return ArenaOptions(
            rate_hz=rate_hz, noise_m=noise_mm / 1000.0, room=room, yaw_offset_deg=yaw_offset_deg,
            body=body, faults=windows, seed=seed,
        )  # fmt: skip
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def estimator_faults(
    drift: str | None, divergence: str | None, jump: str | None
) -> dict[str, object]:
    """The ``Faults`` fields of the estimator options (a duration of ``inf``: for good)."""
    fields: dict[str, object] = {}
    for option, text, prefix, unit in (
        ("--drift", drift, "drift", "ned_m_s"),
        ("--divergence", divergence, "divergence", "ned_m_s2"),
    ):
        if text is not None:
            start, duration, vector = parse_estimator_fault(text, option)
            fields[f"{prefix}_start_s"] = start
            fields[f"{prefix}_duration_s"] = None if duration == math.inf else duration
            fields[f"{prefix}_{unit}"] = vector
    if jump is not None:
        start, _, vector = parse_estimator_fault(jump, "--jump", timed=False)
        fields["jump_at_s"], fields["jump_ned_m"] = start, vector
    return fields
