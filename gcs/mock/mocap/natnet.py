"""NatNet packets as OptiTrack Motive sends them (pure: bytes in, bytes out).

Written from the protocol's documentation: the NatNet SDK's ``NatNetTypes.h`` (packed
``sSender``/``sSender_Server``), its direct-depacketization sample ``PacketClient.cpp`` and
its Python sample ``NatNetClient.py`` (both read, none copied). Every packet is a 4-byte
header, ``uint16 message id`` and ``uint16 payload bytes`` (little-endian), then the payload.
The layout of a frame depends on the NatNet version the server announces in its
``NAT_SERVERINFO``; clients decode with that version. Versions implemented here:

========  ===============  =====================================================================
NatNet    Motive           what changes in the stream (from 3.0)
========  ===============  =====================================================================
3.0, 3.1  2.x              base layout below
4.0       3.0              rigid-body descriptions carry marker names
4.1       3.1 and later    a byte count after every list count (frame) and after every dataset
                           type (model definitions); an asset list; precision timestamps
========  ===============  =====================================================================

Frame of data (``NAT_FRAMEOFDATA``), in order: frame number; marker sets (name, markers);
legacy "other" markers; rigid bodies (id, position, quaternion ``qx qy qz qw``, mean marker
error, ``int16`` params with bit 0 = tracking valid); skeletons; assets (4.1+); labeled
markers (id, position, size, params with bit 0 = occluded, residual); force plates; devices;
timecode and sub-timecode; ``double`` timestamp [s]; three ``uint64`` high-resolution clock
stamps (camera mid-exposure, data received, transmit) in ticks of the server's
``HighResClockFrequency``; precision timestamp seconds and fraction (4.1+); ``int16`` frame
params; a 4-byte end-of-data tag. Lengths are in metres, as Motive streams with scale 1.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

__all__ = [
    "NAT_CONNECT",
    "NAT_SERVERINFO",
    "NAT_REQUEST",
    "NAT_RESPONSE",
    "NAT_REQUEST_MODELDEF",
    "NAT_MODELDEF",
    "NAT_REQUEST_FRAMEOFDATA",
    "NAT_FRAMEOFDATA",
    "NAT_MESSAGESTRING",
    "NAT_DISCONNECT",
    "NAT_KEEPALIVE",
    "NAT_ECHOREQUEST",
    "NAT_ECHORESPONSE",
    "NAT_UNRECOGNIZED_REQUEST",
    "VERSIONS",
    "RigidBodyModel",
    "RigidBodyState",
    "FrameStamps",
    "packet",
    "message_id",
    "server_info",
    "model_definitions",
    "frame_of_data",
]

NAT_CONNECT = 0
NAT_SERVERINFO = 1
NAT_REQUEST = 2
NAT_RESPONSE = 3
NAT_REQUEST_MODELDEF = 4
NAT_MODELDEF = 5
NAT_REQUEST_FRAMEOFDATA = 6
NAT_FRAMEOFDATA = 7
NAT_MESSAGESTRING = 8
NAT_DISCONNECT = 9
NAT_KEEPALIVE = 10
NAT_ECHOREQUEST = 12
NAT_ECHORESPONSE = 13
NAT_UNRECOGNIZED_REQUEST = 100

#: NatNet bitstream versions this module writes.
VERSIONS: tuple[tuple[int, int], ...] = ((3, 0), (3, 1), (4, 0), (4, 1))

_NAME_LEN = 256  # MAX_NAMELENGTH of NatNetTypes.h
_DATASET_RIGID_BODY = 1
_RB_TRACKING_VALID = 0x01
_MARKER_OCCLUDED = 0x01
_MARKER_MODEL_SOLVED = 0x04
_MARKER_HAS_MODEL = 0x08


@dataclass(frozen=True)
class RigidBodyModel:
    """A rigid body as Motive describes it in its model definitions.

    ``name``: asset name; clients find the rigid body by it (frames carry only the id). ``body_id``:
    streaming id (Motive's "Streaming ID", 1 by default for the first asset). ``markers_m``: marker
    positions in the rigid body's own frame, shape (M, 3) [m], M >= 3.
    """

    name: str
    body_id: int
    markers_m: np.ndarray

    def __post_init__(self) -> None:
        markers = np.asarray(self.markers_m, dtype=float)
        if markers.ndim != 2 or markers.shape[1] != 3 or markers.shape[0] < 3:
            raise ValueError(f"markers_m must have shape (M, 3) with M >= 3, got {markers.shape}")
        if not self.name or "\0" in self.name:
            raise ValueError("rigid body name must be non-empty and free of NUL characters")
        object.__setattr__(self, "markers_m", markers)


@dataclass(frozen=True)
class RigidBodyState:
    """The rigid body in one frame, in the motion-capture system's own axes.

    ``tracked``: tracking valid (the solver found the body in this frame). ``pos_m``: position of
    the body's origin, shape (3,) [m]. ``quat_wxyz``: orientation (body to world), unit quaternion
    ``w, x, y, z``, shape (4,). ``error_m``: mean marker error of the solve [m]. ``markers_m``:
    marker positions in world axes as measured, shape (M, 3) [m].
    """

    tracked: bool
    pos_m: np.ndarray
    quat_wxyz: np.ndarray
    error_m: float
    markers_m: np.ndarray


@dataclass(frozen=True)
class FrameStamps:
    """Time stamps of one frame.

    ``timestamp_s``: seconds since the server started streaming (Motive: frame id over the frame
    rate). ``mid_exposure_ticks``: camera mid-exposure, in ticks of the server's high-resolution
    clock. ``data_received_ticks``: when the camera data reached the server [ticks].
    ``transmit_ticks``: when the frame was sent [ticks].
    """

    timestamp_s: float
    mid_exposure_ticks: int
    data_received_ticks: int
    transmit_ticks: int


def _check_version(version: tuple[int, int]) -> None:
    if tuple(version) not in VERSIONS:
        raise ValueError(f"NatNet version {version} not implemented; choose from {VERSIONS}")


def _sized(version: tuple[int, int]) -> bool:
    """NatNet 4.1 and later put a byte count after list counts and dataset types."""
    return tuple(version) >= (4, 1)


def _cstr(text: str) -> bytes:
    return text.encode("utf-8") + b"\0"


def packet(message: int, payload: bytes) -> bytes:
    """Prefix a payload with the NatNet header.

    ``message``: message id (``NAT_*``). ``payload``: payload, at most 65535 bytes.
    """
    if len(payload) > 0xFFFF:
        raise ValueError(f"NatNet payload of {len(payload)} bytes does not fit a uint16 count")
    return struct.pack("<HH", message, len(payload)) + payload


def message_id(datagram: bytes) -> int | None:
    """Message id of a received datagram (None if shorter than a header)."""
    if len(datagram) < 4:
        return None
    return struct.unpack_from("<H", datagram)[0]


def server_info(
    version: tuple[int, int],
    app_version: tuple[int, int, int, int],
    clock_hz: int,
    data_port: int,
    multicast_group: str | None,
    app_name: str = "Motive",
) -> bytes:
    """``NAT_SERVERINFO``: the packed ``sSender_Server`` (279-byte payload).

    ``app_version``: server application version (Motive's), four bytes. ``clock_hz``: ticks per
    second of the high-resolution clock used in frame stamps. ``multicast_group``: dotted IPv4 group
    the frames go to, None for unicast.
    """
    _check_version(version)
    name = app_name.encode("utf-8")[: _NAME_LEN - 1].ljust(_NAME_LEN, b"\0")
    group = bytes(int(p) for p in multicast_group.split(".")) if multicast_group else bytes(4)
    payload = (
        name
        + bytes(app_version)
        + bytes((version[0], version[1], 0, 0))
        + struct.pack("<QH?", clock_hz, data_port, multicast_group is not None)
        + group
    )
    return packet(NAT_SERVERINFO, payload)


def _rigid_body_description(version: tuple[int, int], model: RigidBodyModel) -> bytes:
    m = model.markers_m.shape[0]
    # parent -1 and a zero offset: a top-level rigid body (libmotioncapture adds the offset)
    out = _cstr(model.name) + struct.pack("<ii3f", model.body_id, -1, 0.0, 0.0, 0.0)
    out += struct.pack("<i", m)
    out += model.markers_m.astype("<f4").tobytes()
    out += struct.pack(f"<{m}i", *([0] * m))  # active labels: passive markers
    if version[0] >= 4:
        out += b"".join(_cstr(f"Marker{i + 1}") for i in range(m))
    return out


def model_definitions(version: tuple[int, int], models: list[RigidBodyModel]) -> bytes:
    """``NAT_MODELDEF``: the data descriptions (one rigid body dataset per model)."""
    _check_version(version)
    out = struct.pack("<i", len(models))
    for model in models:
        body = _rigid_body_description(version, model)
        out += struct.pack("<i", _DATASET_RIGID_BODY)
        if _sized(version):
            out += struct.pack("<i", len(body))
        out += body
    return packet(NAT_MODELDEF, out)


def _list(version: tuple[int, int], count: int, items: bytes) -> bytes:
    """A counted list of a frame, with the 4.1+ byte count."""
    head = struct.pack("<i", count)
    if _sized(version):
        head += struct.pack("<i", len(items))
    return head + items


def _marker_id(body_id: int, member: int) -> int:
    """Labeled marker id of a rigid body's marker: asset id (high word), member (low word)."""
    return (body_id << 16) | member


def _frame_lists(
    version: tuple[int, int], models: list[RigidBodyModel], states: list[RigidBodyState]
) -> bytes:
    marker_sets = b""
    bodies = b""
    labeled = b""
    n_sets = 0
    n_labeled = 0
    for model, state in zip(models, states, strict=True):
        q = np.asarray(state.quat_wxyz, dtype=float)
        if state.tracked:
            n_sets += 1
            marker_sets += _cstr(model.name) + struct.pack("<i", len(state.markers_m))
            marker_sets += np.asarray(state.markers_m, "<f4").tobytes()
        pos = np.asarray(state.pos_m, dtype=float)
        bodies += struct.pack(
            "<i3f4ffh",
            model.body_id,
            *pos,
            q[1],
            q[2],
            q[3],
            q[0],
            state.error_m,
            _RB_TRACKING_VALID if state.tracked else 0,
        )
        for i, marker in enumerate(np.asarray(state.markers_m, dtype=float)):
            n_labeled += 1
            params = _MARKER_MODEL_SOLVED | _MARKER_HAS_MODEL
            if not state.tracked:
                params |= _MARKER_OCCLUDED
            labeled += struct.pack(
                "<i3ffhf", _marker_id(model.body_id, i + 1), *marker, 0.014, params, 0.0
            )
    out = _list(version, n_sets, marker_sets)
    out += _list(version, 0, b"")  # legacy "other" (unlabeled) markers
    out += _list(version, len(models), bodies)
    out += _list(version, 0, b"")  # skeletons
    if _sized(version):
        out += _list(version, 0, b"")  # assets
    out += _list(version, n_labeled, labeled)
    out += _list(version, 0, b"")  # force plates
    out += _list(version, 0, b"")  # devices
    return out


def frame_of_data(
    version: tuple[int, int],
    frame_number: int,
    models: list[RigidBodyModel],
    states: list[RigidBodyState],
    stamps: FrameStamps,
) -> bytes:
    """``NAT_FRAMEOFDATA``: one frame with the given rigid bodies.

    ``frame_number``: frame counter (int32). ``models``: the rigid bodies, in the order of the model
    definitions. ``states``: their state in this frame, one per model. ``stamps``: time stamps of
    the frame.
    """
    _check_version(version)
    out = struct.pack("<i", frame_number) + _frame_lists(version, models, states)
    out += struct.pack("<IId", 0, 0, stamps.timestamp_s)  # timecode, sub-timecode, timestamp
    out += struct.pack(
        "<QQQ", stamps.mid_exposure_ticks, stamps.data_received_ticks, stamps.transmit_ticks
    )
    if _sized(version):
        secs = int(stamps.timestamp_s)
        frac = int((stamps.timestamp_s - secs) * 2**32) & 0xFFFFFFFF
        out += struct.pack("<II", secs, frac)
    out += struct.pack("<h", 0)  # frame params: not recording, tracked models unchanged
    out += struct.pack("<i", 0)  # end-of-data tag
    return packet(NAT_FRAMEOFDATA, out)
