"""Real PX4 firmware in software-in-the-loop (SIH quadrotor) for the tests.

:class:`Px4Build` finds a ``px4_sitl_default`` build (``PX4_SITL_DIR``, else
``../shared/px4-v1.16-sitl`` beside the checkout) and makes a runnable copy of its binary once
(the module aliases PX4's start-up scripts call must be symbolic links to ``px4`` in a writable
folder; a copied build may have lost them). :class:`Px4Sitl` starts one vehicle from it: a
fresh working directory, an instance number nobody else on the machine uses (PX4's own lock file
and every UDP port of the instance are probed, and a lock of ours is held for the vehicle's
life, so that ``pytest -n 2``, other developers and CI never collide), parameters set at
start-up through PX4's ``PX4_PARAM_<NAME>`` environment variables or later over MAVLink,
readiness waited for on PX4's own "Ready for takeoff!" line, stopped by its pid (SIGTERM, then
SIGKILL). :class:`Px4Monitor` watches the vehicle on its payload link (PX4 sends there by itself;
the monitor sends no heartbeat, so PX4 never counts it as a ground station and a test can cut
the ground station's link). Every wait is on an event with a bound, never a sleep.

Every vehicle starts with :data:`SITL_PARAMS` (a test's own parameters win): they take away a
fault of PX4 SITL itself, not of anything the tests check.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink import mavutil

from px4.ulog import failure_digest

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_BUILD = ROOT.parent / "shared" / "px4-v1.16-sitl"
ENV_VAR = "PX4_SITL_DIR"
CACHE = ROOT / ".cache" / "px4-sitl"
FAILURES = ROOT / "logs" / "px4-failures"
READY_LINE = "Ready for takeoff!"
#: The start-up script done: what a vehicle set up for motion capture prints before vision
#: arrives (it is not ready for take-off until then).
STARTED_LINE = "Startup script returned successfully"
# instances 0-9 only: from 10 on PX4 sends every vehicle's API link to the same port 14549
INSTANCES = range(10)
START_TIMEOUT_S = 90.0  # boot to "Ready for takeoff!" takes 5-10 s; a loaded machine, more
STOP_TIMEOUT_S = 15.0
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: Set on every vehicle the tests start. ``IMU_GYRO_CAL_EN`` 0 keeps PX4's ``gyro_calibration``
#: module from starting. At every arming and disarming it moves its own interval timer from
#: inside the timer's call (``ScheduleOnInterval`` in its ``Run``; PX4 v1.16,
#: ``src/modules/gyro_calibration/GyroCalibration.cpp``). On SITL the timer is a POSIX
#: emulation whose list of calls is unlocked while a call runs
#: (``platforms/posix/src/px4/common/drv_hrt.cpp``, ``hrt_call_invoke``): should the module's
#: work queue get in before the timer's thread takes the list back, the entry goes into the list
#: twice and every call behind it is lost. That is the one way found in PX4's source for what
#: a few loaded runs met: the barometer, magnetometer, GPS and battery simulators and the
#: CPU-load monitor stopping for good at an arming while the IMU and everything fed by it went
#: on. It was not reproduced (docs/testing.md). On a flight controller the timer is hardware;
#: SIH's gyros carry no offset to calibrate (noise and the earth's rotation only,
#: ``src/modules/simulation/simulator_sih/sih.cpp``), so the module is left out either way.
SITL_PARAMS: dict[str, float] = {"IMU_GYRO_CAL_EN": 0}


class Px4BuildError(RuntimeError):
    """The PX4 build is missing or incomplete."""


def build_dir() -> tuple[Path, bool]:
    """The PX4 build the real-firmware tests use, and whether the user chose it.

    Returns
    -------
    tuple of (Path, bool)
        ``PX4_SITL_DIR`` when set (True), else ``../shared/px4-v1.16-sitl`` beside the
        checkout (False).
    """
    chosen = os.environ.get(ENV_VAR, "").strip()
    return (Path(chosen).expanduser().resolve(), True) if chosen else (DEFAULT_BUILD, False)


@dataclass(frozen=True)
class Px4Build:
    """A ``px4_sitl_default`` build: ``bin/px4`` and ``etc/`` (``build/px4_sitl_default`` of a
    PX4-Autopilot checkout, or a copy of its ``bin`` and ``etc``)."""

    root: Path

    def check(self) -> None:
        """Raise :class:`Px4BuildError` naming what is missing."""
        for part in ("bin/px4", "etc/init.d-posix/rcS"):
            if not (self.root / part).is_file():
                raise Px4BuildError(f"{self.root}: no {part} (not a px4_sitl_default build)")

    def aliases(self) -> list[str]:
        """The module aliases (``px4-<module>``) the start-up scripts call."""
        listed = self.root / "aliases.txt"
        if listed.is_file():
            return [n for n in listed.read_text().split() if n.startswith("px4-")]
        return sorted(
            p.name
            for p in (self.root / "bin").iterdir()
            if p.name.startswith("px4-") and p.name != "px4-alias.sh"
        )

    def runnable(self, cache: Path = CACHE) -> Path:
        """A ``bin`` folder that runs: the binary and ``px4-alias.sh`` copied, every alias a
        symbolic link to ``px4``. Made once per binary file (its device, inode, size and
        modification time name the folder: a rebuilt or replaced binary gets a folder of its
        own) and put in place atomically, so that parallel test workers share it."""
        self.check()
        binary = self.root / "bin" / "px4"
        st = binary.stat()
        key = f"{st.st_dev:x}-{st.st_ino:x}-{st.st_size:x}-{st.st_mtime_ns:x}"
        done = cache / key / "bin"
        if (done / "px4").is_file():
            return done
        cache.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix="staging-", dir=cache))
        bin_dir = staging / "bin"
        bin_dir.mkdir()
        shutil.copy2(binary, bin_dir / "px4")
        (bin_dir / "px4").chmod(0o755)
        alias_script = self.root / "bin" / "px4-alias.sh"
        if alias_script.is_file():
            shutil.copy2(alias_script, bin_dir / "px4-alias.sh")
            (bin_dir / "px4-alias.sh").chmod(0o644)
        for name in self.aliases():
            (bin_dir / name).symlink_to("px4")
        try:
            staging.rename(cache / key)
        except OSError:  # another worker was first: use its copy
            shutil.rmtree(staging, ignore_errors=True)
        return done


def _udp_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


@dataclass(frozen=True)
class Ports:
    """The UDP ports of PX4 instance ``n`` (PX4 listens on the ``*_px4`` ones, sends to the
    others on 127.0.0.1)."""

    n: int

    @property
    def api(self) -> int:
        """Where PX4 sends its offboard/API link (a MAVSDK client listens here)."""
        return 14540 + self.n

    @property
    def api_px4(self) -> int:
        return 14580 + self.n

    @property
    def gcs_px4(self) -> int:
        return 18570 + self.n

    @property
    def payload(self) -> int:
        """Where PX4 sends its onboard payload link (the monitor listens here)."""
        return 14030 + self.n

    @property
    def payload_px4(self) -> int:
        return 14280 + self.n

    @property
    def display(self) -> int:
        """Where PX4 sends the SIH display link (HIL_STATE_QUATERNION: the simulator's truth)."""
        return 19410 + self.n

    @property
    def display_px4(self) -> int:
        return 19450 + self.n

    def all(self) -> list[int]:
        """Every port the instance uses (14550, shared by all instances, excepted)."""
        n = self.n
        return [
            self.api,
            self.api_px4,
            self.gcs_px4,
            self.payload,
            self.payload_px4,
            self.display,
            self.display_px4,
            13030 + n,
            13280 + n,
        ]


def _px4_lock_held(n: int) -> bool:
    """Whether a running PX4 holds ``/tmp/px4_lock-<n>`` (a left-over file alone is free)."""
    path = Path(f"/tmp/px4_lock-{n}")
    if not path.exists():
        return False
    try:
        with path.open("r+") as f:
            try:
                fcntl.lockf(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                return True
            fcntl.lockf(f, fcntl.LOCK_UN)
    except OSError:  # someone else's file we cannot open: count it as taken
        return True
    return False


@contextlib.contextmanager
def reserve_instance(
    candidates: range = INSTANCES, skip: set[int] | frozenset[int] = frozenset()
) -> Iterator[int]:
    """Hold a free PX4 instance number: ours (a lock file of ours, held while the block runs)
    and free (no running PX4 on it, every UDP port of it unbound).

    Parameters
    ----------
    candidates : range
        Instance numbers to try, in order.
    skip : set of int
        Numbers not to try (ones PX4 refused just now).

    Yields
    ------
    int
        The instance number.
    """
    for n in candidates:
        if n in skip:
            continue
        f = open(f"/tmp/gcs-tests-px4-instance-{n}.lock", "a")  # noqa: SIM115 (held below)
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        if _px4_lock_held(n) or not all(_udp_free(p) for p in Ports(n).all()):
            f.close()
            continue
        try:
            yield n
        finally:
            f.close()
        return
    raise RuntimeError(
        f"no free PX4 instance among {candidates.start}..{candidates.stop - 1} "
        "(each is taken by a running PX4 or has a UDP port in use)"
    )


class _Output:
    """PX4's output, read line by line from a thread into a file and a list; waits on lines."""

    def __init__(self, stream, path: Path) -> None:
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._read, args=(stream, path), daemon=True)
        self._thread.start()

    def _read(self, stream, path: Path) -> None:
        with path.open("w") as out:
            for raw in stream:
                line = _ANSI.sub("", raw.rstrip("\n"))
                out.write(line + "\n")
                out.flush()
                with self._cond:
                    self.lines.append(line)
                    self._cond.notify_all()
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def wait_for(self, pattern: str, timeout_s: float, start: int = 0) -> int:
        """Index of the first line from ``start`` on that contains ``pattern``.

        Raises TimeoutError when the bound runs out and EOFError when PX4 exits first.
        """
        deadline = time.monotonic() + timeout_s
        i = start
        with self._cond:
            while True:
                while i < len(self.lines):
                    if pattern in self.lines[i]:
                        return i
                    i += 1
                if self._closed:
                    raise EOFError(f"PX4 exited before printing '{pattern}'")
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError(f"PX4 did not print '{pattern}' within {timeout_s:g} s")
                self._cond.wait(remaining)

    def join(self, timeout_s: float) -> None:
        self._thread.join(timeout_s)

    def text(self) -> str:
        with self._cond:
            return "\n".join(self.lines)


class Px4Sitl:
    """One PX4 SITL vehicle (SIH quadrotor X, airframe 10040), started by :meth:`start`.

    Parameters
    ----------
    build : Px4Build
        The firmware.
    workdir : Path
        A fresh, empty working directory (parameters, mission store, ULog logs, its output).
    params : dict, optional
        Parameters set at start-up (``PX4_PARAM_<NAME>`` environment variables, read by PX4's
        posix rcS before the airframe's defaults apply). Parameters that fail a pre-flight
        check without a ground station (``NAV_DLL_ACT``) would keep PX4 from ever printing
        "Ready for takeoff!" here: set those with :meth:`set_param` once it is ready.
    model : str
        ``PX4_SIM_MODEL``.
    ready : str
        The line of PX4's output that :meth:`start` waits for: "Ready for takeoff!" (its
        pre-flight checks pass); a set-up that cannot pass them before a peer joins (external
        vision only, say) waits for :data:`STARTED_LINE` and then for its own event.
    """

    def __init__(
        self,
        build: Px4Build,
        workdir: Path,
        params: dict[str, float] | None = None,
        model: str = "sihsim_quadx",
        ready: str = READY_LINE,
    ) -> None:
        self.build = build
        self.ready = ready
        self.workdir = workdir
        self.params = {**SITL_PARAMS, **(params or {})}
        self.model = model
        self.instance: int | None = None
        self.proc: subprocess.Popen | None = None
        self.output: _Output | None = None
        self.started_s: float | None = None
        self.ready_after_s: float | None = None
        self._stack = contextlib.ExitStack()

    # --- addresses -------------------------------------------------------------------------
    @property
    def ports(self) -> Ports:
        assert self.instance is not None, "not started"
        return Ports(self.instance)

    @property
    def url(self) -> str:
        """The MAVSDK URL of its API link (what ``gcs --connect`` takes)."""
        return f"udpin://127.0.0.1:{self.ports.api}"

    @property
    def system_id(self) -> int:
        assert self.instance is not None, "not started"
        return self.instance + 1

    # --- life ------------------------------------------------------------------------------
    def start(self, timeout_s: float = START_TIMEOUT_S) -> Px4Sitl:
        """Start PX4 on a free instance and wait for its ``ready`` line ("Ready for takeoff!").

        Parameters
        ----------
        timeout_s : float
            Bound of the wait [s]; on expiry PX4 is stopped and the error shows its last lines.

        Returns
        -------
        Px4Sitl
            Itself, ready.

        Raises
        ------
        RuntimeError
            When its PX4 still runs (a second start would leave the first PX4 running, unseen,
            on its instance until the machine stops).
        """
        if self.alive():
            raise RuntimeError(f"PX4 instance {self.instance} already started: stop() it first")
        bin_dir = self.build.runnable()
        refused: set[int] = set()
        while True:
            stack = contextlib.ExitStack()
            self.instance = stack.enter_context(reserve_instance(skip=refused))
            self._stack = stack
            self._spawn(bin_dir)
            try:
                self.output.wait_for(STARTED_LINE, timeout_s)
            except EOFError:
                # another PX4 took the instance between our probe and its start
                if "already running" in self.output.text():
                    self._reap()
                    stack.close()
                    refused.add(self.instance)
                    continue
                self.stop()
                raise
            except BaseException:
                self.stop()
                raise
            break
        try:
            self.output.wait_for(self.ready, max(1.0, timeout_s - self.elapsed_s()))
        except TimeoutError as exc:
            tail = "\n".join(self.output.lines[-15:])
            self.stop()
            raise TimeoutError(f"{exc} (instance {self.instance}); last lines:\n{tail}") from None
        except BaseException:
            self.stop()
            raise
        self.ready_after_s = self.elapsed_s()
        return self

    def _spawn(self, bin_dir: Path) -> None:
        self.workdir.mkdir(parents=True, exist_ok=True)
        env = {
            **os.environ,
            "PX4_SIM_MODEL": self.model,
            "HEADLESS": "1",
            **{f"PX4_PARAM_{k}": _param_text(v) for k, v in self.params.items()},
        }
        cmd = [
            str(bin_dir / "px4"),
            "-d",
            "-i",
            str(self.instance),
            "-w",
            str(self.workdir),
            str(self.build.root / "etc"),
        ]
        self.started_s = time.monotonic()
        self.proc = subprocess.Popen(
            cmd,
            cwd=self.workdir,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            errors="replace",
            start_new_session=True,  # a Ctrl-C to pytest reaches PX4 only through stop()
        )
        self.output = _Output(self.proc.stdout, self.workdir / "px4-output.txt")

    def elapsed_s(self) -> float:
        """Seconds since PX4 was started."""
        return time.monotonic() - (self.started_s or time.monotonic())

    def alive(self) -> bool:
        """Whether the PX4 process still runs."""
        return self.proc is not None and self.proc.poll() is None

    def _reap(self) -> None:
        if self.proc is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(STOP_TIMEOUT_S)
        if self.output is not None:
            self.output.join(STOP_TIMEOUT_S)

    def stop(self) -> int | None:
        """Stop PX4 by its pid: SIGTERM, SIGKILL if it has not exited within the bound.

        Returns
        -------
        int or None
            Its exit code (None if it was never started).
        """
        code = None
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGTERM)
                try:
                    self.proc.wait(STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(STOP_TIMEOUT_S)
            code = self.proc.returncode
            if self.output is not None:
                self.output.join(STOP_TIMEOUT_S)
        self._stack.close()
        return code

    def __enter__(self) -> Px4Sitl:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- records ---------------------------------------------------------------------------
    def ulogs(self) -> list[Path]:
        """The ULog files PX4 wrote, oldest first."""
        return sorted((self.workdir / "log").glob("**/*.ulg"))

    def keep(self, dest: Path) -> Path:
        """Copy its output and ULog logs to ``dest`` (kept after a failed test)."""
        dest.mkdir(parents=True, exist_ok=True)
        out = self.workdir / "px4-output.txt"
        if out.exists():
            shutil.copy2(out, dest / "px4-output.txt")
        for ulog in self.ulogs():
            shutil.copy2(ulog, dest / ulog.name)
        return dest

    def digest(self) -> str:
        """Its console's last events and its newest log's last seconds (:func:`failure_digest`)."""
        out = self.workdir / "px4-output.txt"
        text = out.read_text(errors="replace") if out.exists() else ""
        return failure_digest(text, self.ulogs())

    # --- MAVLink ---------------------------------------------------------------------------
    def monitor(self) -> Px4Monitor:
        """A :class:`Px4Monitor` on this vehicle's payload link (close it, or use ``with``)."""
        return Px4Monitor(self.ports.payload, self.ports.payload_px4, self.system_id)

    def set_param(self, name: str, value: float, timeout_s: float = 10.0) -> None:
        """Set a parameter over MAVLink (PARAM_SET on the payload link, PX4's echo awaited)."""
        with self.monitor() as mon:
            mon.set_param(name, value, timeout_s)


_MAIN_MODES = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 5: "ACRO", 6: "OFFBOARD", 7: "STABILIZED"}
_AUTO_MODES = {1: "READY", 2: "TAKEOFF", 3: "LOITER", 4: "MISSION", 5: "RTL", 6: "LAND"}


def mode_name(custom_mode: int) -> str:
    """PX4's flight mode from a HEARTBEAT's ``custom_mode`` (main mode << 16 | sub mode << 24)."""
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    if main == 4:
        return f"AUTO.{_AUTO_MODES.get(sub, sub)}"
    return _MAIN_MODES.get(main, f"main {main}")


def _param_text(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else repr(float(value))


@dataclass
class VehicleState:
    """What the monitor last heard (None until heard), with the monotonic time of each change."""

    armed: bool | None = None
    custom_mode: int | None = None
    landed_state: int | None = None
    relative_alt_m: float | None = None
    pos_ned_m: tuple[float, float, float] | None = None
    estimator_flags: int | None = None  # ESTIMATOR_STATUS flags (ESTIMATOR_STATUS_FLAGS)
    statustext: list[tuple[float, str]] = field(default_factory=list)
    changes: list[tuple[float, str, object]] = field(default_factory=list)


class Px4Monitor:
    """Watches PX4 on its onboard payload link (where PX4 sends HEARTBEAT, EXTENDED_SYS_STATE,
    GLOBAL_POSITION_INT, ESTIMATOR_STATUS, STATUSTEXT by itself) from a thread; answers event
    waits.

    It never sends a heartbeat: PX4 does not count it as a ground station, so a test can take
    the ground station away and watch PX4's data-link-loss failsafe. The mission protocol
    (fence read-back) and PARAM_SET go out on the same link.
    """

    def __init__(self, port: int, px4_port: int, system_id: int) -> None:
        self.system_id = system_id
        self._conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=245, source_component=190
        )
        self._px4 = ("127.0.0.1", px4_port)
        self.state = VehicleState()
        self._cond = threading.Condition()
        self._replies: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _send(self, msg) -> None:
        """Send to PX4's payload port (pymavlink's udpin answers only after a packet arrives)."""
        buf = msg.pack(self._conn.mav)
        self._conn.port.sendto(buf, self._px4)

    def _run(self) -> None:
        mav = mavutil.mavlink
        while not self._stop.is_set():
            msg = self._conn.recv_match(blocking=True, timeout=0.2)
            if msg is None or msg.get_srcSystem() != self.system_id:
                continue
            now = time.monotonic()
            kind = msg.get_type()
            with self._cond:
                s = self.state
                if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                    armed = bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
                    if armed != s.armed:
                        s.changes.append((now, "armed", armed))
                    if msg.custom_mode != s.custom_mode:
                        s.changes.append((now, "mode", msg.custom_mode))
                    s.armed, s.custom_mode = armed, msg.custom_mode
                elif kind == "EXTENDED_SYS_STATE":
                    if msg.landed_state != s.landed_state:
                        s.changes.append((now, "landed_state", msg.landed_state))
                    s.landed_state = msg.landed_state
                elif kind == "GLOBAL_POSITION_INT":
                    s.relative_alt_m = msg.relative_alt / 1000.0
                elif kind == "LOCAL_POSITION_NED":
                    s.pos_ned_m = (msg.x, msg.y, msg.z)
                elif kind == "ESTIMATOR_STATUS":
                    s.estimator_flags = msg.flags
                elif kind == "STATUSTEXT":
                    s.statustext.append((now, msg.text))
                elif kind in (
                    "MISSION_COUNT",
                    "MISSION_ITEM_INT",
                    "PARAM_VALUE",
                    "MISSION_ACK",
                    "GPS_GLOBAL_ORIGIN",
                ):
                    self._replies.append(msg)
                self._cond.notify_all()

    def events_since(self, t0: float) -> list[tuple[float, str]]:
        """Changes of armed state, mode and landed state, and PX4's status texts, after the
        monotonic time ``t0``: (seconds after ``t0``, what) in order."""
        landed = {0: "undefined", 1: "on ground", 2: "in air", 3: "taking off", 4: "landing"}
        with self._cond:
            events = [
                (t, "armed" if v else "disarmed")
                if kind == "armed"
                else (t, f"mode {mode_name(v)}")
                if kind == "mode"
                else (t, landed.get(v, str(v)))
                for t, kind, v in self.state.changes
            ]
            events += [(t, f"PX4: {text}") for t, text in self.state.statustext]
        return [(round(t - t0, 1), what) for t, what in sorted(events) if t >= t0]

    def wait(self, what: str, check: Callable[[VehicleState], bool], timeout_s: float) -> float:
        """Wait until ``check(state)`` holds; the monotonic time it first did.

        Raises TimeoutError naming ``what`` and the last state when the bound runs out.
        """
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not check(self.state):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    s = self.state
                    raise TimeoutError(
                        f"{what} did not happen within {timeout_s:g} s (armed {s.armed}, "
                        f"landed_state {s.landed_state}, alt {s.relative_alt_m})"
                    )
                self._cond.wait(min(remaining, 0.5))
            return time.monotonic()

    def _reply(self, match: Callable[[object], bool], timeout_s: float, resend=None):
        """The first reply that ``match`` accepts, sending ``resend()`` every second meanwhile
        (UDP may drop a request)."""
        deadline = time.monotonic() + timeout_s
        next_send = 0.0
        with self._cond:
            while True:
                for i, msg in enumerate(self._replies):
                    if match(msg):
                        return self._replies.pop(i)
                now = time.monotonic()
                if now >= deadline:
                    raise TimeoutError("PX4 did not answer on its payload link")
                if resend is not None and now >= next_send:
                    resend()
                    next_send = now + 1.0
                self._cond.wait(min(deadline, next_send) - now if resend else deadline - now)

    def set_param(self, name: str, value: float, timeout_s: float = 10.0) -> None:
        """PARAM_SET, waiting for PX4's PARAM_VALUE with the new value."""
        mav = self._conn.mav
        kind = mavutil.mavlink.MAV_PARAM_TYPE_INT32
        if not float(value).is_integer():
            kind = mavutil.mavlink.MAV_PARAM_TYPE_REAL32
        if kind == mavutil.mavlink.MAV_PARAM_TYPE_INT32:
            # PX4 carries integers bytewise in the float field
            wire = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        else:
            wire = float(value)
        msg = mav.param_set_encode(self.system_id, 1, name.encode(), wire, kind)
        self._reply(
            lambda m: (
                m.get_type() == "PARAM_VALUE" and m.param_id == name and m.param_value == wire
            ),
            timeout_s,
            resend=lambda: self._send(msg),
        )

    def global_origin(self, timeout_s: float = 10.0) -> tuple[float, float]:
        """PX4's local origin (latitude, longitude) [deg]: GPS_GLOBAL_ORIGIN, requested with
        MAV_CMD_REQUEST_MESSAGE."""
        mav = self._conn.mav
        msg_id = mavutil.mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN
        request = mav.command_long_encode(
            self.system_id, 1, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0
        )
        origin = self._reply(
            lambda m: m.get_type() == "GPS_GLOBAL_ORIGIN",
            timeout_s,
            resend=lambda: self._send(request),
        )
        return origin.latitude * 1e-7, origin.longitude * 1e-7

    def download_fence(self, timeout_s: float = 10.0) -> list:
        """The geofence items PX4 holds (MISSION_REQUEST_LIST, mission_type FENCE)."""
        mav = self._conn.mav
        fence = mavutil.mavlink.MAV_MISSION_TYPE_FENCE
        count = self._reply(
            lambda m: m.get_type() == "MISSION_COUNT" and m.mission_type == fence,
            timeout_s,
            resend=lambda: self._send(mav.mission_request_list_encode(self.system_id, 1, fence)),
        ).count
        items = []
        for seq in range(count):
            items.append(
                self._reply(
                    lambda m, seq=seq: m.get_type() == "MISSION_ITEM_INT" and m.seq == seq,
                    timeout_s,
                    resend=lambda seq=seq: self._send(
                        mav.mission_request_int_encode(self.system_id, 1, seq, fence)
                    ),
                )
            )
        self._send(
            mav.mission_ack_encode(self.system_id, 1, mavutil.mavlink.MAV_MISSION_ACCEPTED, fence)
        )
        return items

    def close(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        self._thread.join(2.0)
        self._conn.close()

    def __enter__(self) -> Px4Monitor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
