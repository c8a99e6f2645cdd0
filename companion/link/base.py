"""The companion's view of an autopilot: one interface, two backends (pymavlink, MAVSDK).

Everything the companion knows about the vehicle arrives through this interface, so the same mission
flies the flowgap SITL vehicle or a real PX4 (or ArduPilot) vehicle. Positions are local NED metres.
"""

from __future__ import annotations

import abc
import bisect
import logging
import math
import threading
from collections import deque
from dataclasses import dataclass, field
from urllib.parse import urlparse

from companion.clock import Clock, WallClock

log = logging.getLogger(__name__)


class LinkError(RuntimeError):
    """The autopilot refused something or stopped answering; the message says what and why."""


class LinkLost(LinkError):
    """No heartbeat from the autopilot within the link timeout."""


class StatusTextAssembler:
    """Joins MAVLink 2 STATUSTEXT chunks back into whole texts.

    A text over 50 bytes arrives as chunks sharing an ``id`` > 0 with rising ``chunk_seq``; the last one is
    shorter than 50 bytes (an empty chunk ends a text that fills its last chunk exactly).  ``add`` returns
    the whole text once it is complete, else None.  A chunk 0 restarts its id (the sender reused it after
    a chunk was lost), and at most ``max_pending`` unfinished texts are kept, oldest dropped first.
    """

    def __init__(self, max_pending: int = 16) -> None:
        self.max_pending = max_pending
        self._pending: dict[int, list[str]] = {}

    def add(self, text_id: int, chunk_seq: int, text: str) -> str | None:
        if not text_id:
            return text
        if chunk_seq == 0:
            self._pending.pop(text_id, None)
        parts = self._pending.setdefault(text_id, [])
        parts.append(text)
        if len(text.encode()) >= 50:
            while len(self._pending) > self.max_pending:
                self._pending.pop(next(iter(self._pending)))
            return None
        return "".join(self._pending.pop(text_id))


@dataclass(frozen=True)
class Endpoint:
    """A parsed MAVLink endpoint URL."""

    scheme: str  # udpin | udpout | tcp | serial
    host: str
    port: int  # serial: baud rate

    @property
    def mavutil(self) -> str:
        """The pymavlink connection string."""
        if self.scheme == "serial":
            return self.host
        return f"{self.scheme}:{self.host}:{self.port}"


def parse_endpoint(url: str) -> Endpoint:
    """``udpin://:14540``, ``udpout://host:port``, ``tcp://host:port``, ``serial:///dev/ttyUSB0:921600``."""
    parsed = urlparse(url)
    scheme = parsed.scheme
    if scheme == "serial":
        device, _, baud = (parsed.netloc + parsed.path).rpartition(":")
        if not device or not baud.isdigit():
            raise ValueError(f"serial URL {url!r} needs a device and a baud rate, e.g. serial:///dev/ttyUSB0:921600")
        return Endpoint("serial", device, int(baud))
    if scheme not in ("udpin", "udpout", "tcp"):
        raise ValueError(f"MAVLink URL {url!r}: scheme must be udpin, udpout, tcp or serial "
                         f"(e.g. udpin://:14540)")
    try:
        port = parsed.port
    except ValueError:
        port = None
    if port is None:
        raise ValueError(f"MAVLink URL {url!r} needs a port, e.g. udpin://:14540")
    host = parsed.hostname or ("0.0.0.0" if scheme == "udpin" else "127.0.0.1")
    return Endpoint(scheme, host, port)


@dataclass
class TelemetryCache:
    """The latest telemetry, updated by the link's receive thread and read by the mission."""

    position: tuple[float, float, float] | None = None  # NED m (LOCAL_POSITION_NED)
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  # NED m/s
    attitude_euler: tuple[float, float, float] = (0.0, 0.0, 0.0)  # roll, pitch, yaw rad
    mode: str = "UNKNOWN"
    armed: bool = False
    landed: bool | None = None  # None until EXTENDED_SYS_STATE says
    home: tuple[float, float, float] | None = None  # lat°, lon°, alt m
    autopilot: str = "unknown"
    last_heartbeat: float = -math.inf  # the link's clock (companion.clock)
    position_time: float = -math.inf
    statustexts: list[tuple[int, str]] = field(default_factory=list)
    # (autopilot time s, roll, pitch, yaw): to read the attitude at a camera frame's time stamp
    attitude_history: deque = field(default_factory=lambda: deque(maxlen=2000), repr=False)  # 40 s at 50 Hz
    # (autopilot time s, north, east, down): the position estimate at a frame's time stamp
    position_history: deque = field(default_factory=lambda: deque(maxlen=2000), repr=False)  # 60 s at 30 Hz
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    # called with (autopilot time s, position=..., attitude=...) on each position or attitude update, on the
    # link's receive thread (a recording of the flight: companion.recording)
    listeners: list = field(default_factory=list, repr=False)

    def notify(self, time_s: float, **values) -> None:
        for listener in list(self.listeners):
            try:
                listener(time_s, **values)
            except Exception:  # noqa: BLE001 — an observer must never stop the link
                log.exception("telemetry listener failed")

    def attitude_at(self, time_s: float) -> tuple[float, float, float]:
        """Attitude (roll, pitch, yaw) at an autopilot time stamp, interpolated between samples (nearest
        sample outside the recorded span; the latest attitude when there is no history)."""
        with self.lock:
            history = list(self.attitude_history)
            latest = self.attitude_euler
        return _interpolate(history, time_s, latest, angle_axis=2)

    def position_at(self, time_s: float) -> tuple[float, float, float] | None:
        """The position estimate at an autopilot time stamp, as :meth:`attitude_at` reads the attitude."""
        with self.lock:
            history = list(self.position_history)
            latest = self.position
        return _interpolate(history, time_s, latest)

    def covers(self, time_s: float) -> bool:
        """Whether position and attitude have both been heard at or after ``time_s`` (autopilot time): over a
        slow link the estimates for a frame's moment arrive after the frame.  Read under ``lock`` (as
        ``AutopilotLink.wait_for`` calls its predicates)."""
        return all(h and h[-1][0] >= time_s for h in (self.position_history, self.attitude_history))


def _interpolate(history: list, time_s: float, latest, angle_axis: int | None = None):
    """Linear interpolation of (time, *values) samples at ``time_s``; ``angle_axis`` interpolates across ±π."""
    if not history:
        return latest
    times = [h[0] for h in history]
    i = bisect.bisect_left(times, time_s)
    if i == 0:
        return tuple(history[0][1:])
    if i == len(history):
        return tuple(history[-1][1:])
    (t0, *a0), (t1, *a1) = history[i - 1], history[i]
    w = (time_s - t0) / (t1 - t0) if t1 > t0 else 0.0
    steps = [b - a for a, b in zip(a0, a1, strict=True)]
    if angle_axis is not None:
        steps[angle_axis] = math.remainder(steps[angle_axis], math.tau)
    return tuple(a + w * d for a, d in zip(a0, steps, strict=True))


class AutopilotLink(abc.ABC):
    """Connect, arm, take off, fly offboard position setpoints, land — for any MAVLink autopilot.

    Every wait, timeout and rate reads ``clock`` (:mod:`companion.clock`): the wall clock, or in lockstep the
    simulated vehicle's."""

    name = "abstract"
    heartbeat_timeout_s = 3.0

    def __init__(self, clock: Clock | None = None) -> None:
        self.telemetry = TelemetryCache()
        self.clock: Clock = clock if clock is not None else WallClock()

    # --- lifecycle
    @abc.abstractmethod
    def connect(self, timeout_s: float = 30.0) -> None: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    # --- commands (raise LinkError with the autopilot's reason on refusal)
    @abc.abstractmethod
    def arm(self) -> None: ...

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        """Tell the autopilot the takeoff altitude before arming (PX4: MIS_TAKEOFF_ALT, as MAVSDK's
        set_takeoff_altitude); links whose takeoff command carries the altitude need nothing."""
        return None

    @abc.abstractmethod
    def takeoff(self, altitude_m: float) -> None: ...

    @abc.abstractmethod
    def start_offboard(self, position: tuple[float, float, float], yaw: float) -> None:
        """Stream ``position`` for ≥ 1 s at ≥ 10 Hz, then switch to the offboard (guided) mode."""

    @abc.abstractmethod
    def set_position_target(self, position: tuple[float, float, float], yaw: float) -> None:
        """Replace the streamed setpoint; the link keeps sending it at 20 Hz from its own thread."""

    @abc.abstractmethod
    def hold(self) -> None: ...

    @abc.abstractmethod
    def land(self) -> None: ...

    # --- shared helpers
    def alive(self) -> bool:
        return self.clock.now() - self.telemetry.last_heartbeat < self.heartbeat_timeout_s

    def check_alive(self) -> None:
        if not self.alive():
            raise LinkLost(f"no heartbeat from the autopilot for {self.heartbeat_timeout_s:.0f} s: link lost")

    def wait_for(self, predicate, timeout_s: float, what: str, period_s: float = 0.02) -> None:
        """Wait until ``predicate(telemetry)``; LinkLost if heartbeats stop, LinkError on timeout."""
        def ready() -> bool:
            self.check_alive()
            with self.telemetry.lock:
                return predicate(self.telemetry)

        if not self.clock.wait_for(ready, timeout_s, period_s):
            raise LinkError(f"timed out after {timeout_s:.0f} s waiting for {what}")

    def try_wait_for(self, predicate, timeout_s: float, what: str) -> bool:
        """``wait_for`` that answers False on a timeout; a lost link still raises LinkLost."""
        try:
            self.wait_for(predicate, timeout_s, what)
            return True
        except LinkLost:
            raise
        except LinkError:
            return False

    def wait_position(self, target, tolerance_m: float, timeout_s: float, speed_mps: float = 0.1) -> bool:
        """Wait until the vehicle is within ``tolerance_m`` of ``target`` and slower than ``speed_mps``."""
        def arrived(t: TelemetryCache) -> bool:
            return (t.position is not None and math.dist(t.position, target) <= tolerance_m
                    and math.hypot(*t.velocity) <= speed_mps)
        return self.try_wait_for(arrived, timeout_s, f"arrival at {target}")
