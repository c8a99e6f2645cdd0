"""The MAVSDK backend (the ``mavsdk`` 4.x native API: C++ MAVSDK through ctypes, no gRPC server).

Same interface as the pymavlink backend. MAVSDK streams offboard setpoints at 20 Hz itself and retries
commands; telemetry arrives through subscriptions into the shared cache. MAVSDK does not expose the raw
packets, so this backend writes no .tlog (the pymavlink backend does).
"""

from __future__ import annotations

import logging
import math
import threading

from companion.link.base import AutopilotLink, LinkError, parse_endpoint

log = logging.getLogger(__name__)
sdk_log = logging.getLogger("mavsdk")
_routed = False


def route_mavsdk_log() -> None:
    """Send the C++ MAVSDK's own log lines to the ``mavsdk`` Python logger instead of stdout (once per process)."""
    global _routed
    if _routed:
        return
    import mavsdk

    levels = {mavsdk.LogLevel.DEBUG: logging.DEBUG, mavsdk.LogLevel.INFO: logging.INFO,
              mavsdk.LogLevel.WARN: logging.WARNING, mavsdk.LogLevel.ERROR: logging.ERROR}

    def forward(level, message, file, line) -> bool:
        sdk_log.log(levels.get(level, logging.INFO), "%s", message)
        return True                                   # handled: MAVSDK does not print it too

    mavsdk.log_subscribe(forward)
    _routed = True


class MavsdkLink(AutopilotLink):
    name = "mavsdk"

    def __init__(self, url: str):
        super().__init__()
        self.endpoint = parse_endpoint(url)
        self._sdk = None
        self._system = None
        self._stop = threading.Event()
        self._watch: threading.Thread | None = None
        self.setpoint_times: list[float] = []  # MAVSDK streams internally; not observable here

    def _url(self) -> str:
        ep = self.endpoint
        if ep.scheme == "serial":
            return f"serial://{ep.host}:{ep.port}"
        if ep.scheme == "tcp":
            return f"tcpout://{ep.host}:{ep.port}"
        return f"{ep.scheme}://{ep.host}:{ep.port}"

    def connect(self, timeout_s: float = 30.0) -> None:
        import mavsdk
        from mavsdk.plugins.action import Action
        from mavsdk.plugins.offboard import Offboard
        from mavsdk.plugins.telemetry import Telemetry

        route_mavsdk_log()
        self._sdk = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(
            mavsdk.ComponentType.COMPANION_COMPUTER))
        result = self._sdk.add_any_connection(self._url())
        if result != mavsdk.ConnectionResult.SUCCESS:
            raise LinkError(f"MAVSDK cannot open {self._url()}: {result.name}")
        self._system = self._sdk.first_autopilot(timeout_s)
        if self._system is None:
            raise LinkError(f"no autopilot found on {self._url()} within {timeout_s:.0f} s: is the vehicle "
                            f"running and sending to this address?")
        self._telemetry, self._action, self._offboard = (Telemetry(self._system), Action(self._system),
                                                        Offboard(self._system))
        t = self.telemetry
        with t.lock:
            t.last_heartbeat = self.clock.now()
            t.autopilot = {"PX4": "px4", "ARDUPILOT": "ardupilot"}.get(self._system.autopilot_type().name, "other")
        self._subscribe()
        self._watch = threading.Thread(target=self._watch_connection, name="mavsdk-watch", daemon=True)
        self._watch.start()
        try:
            self._telemetry.set_rate_attitude_euler(50.0)  # derotation needs attitude at each frame
        except Exception as exc:  # noqa: BLE001 — not every autopilot accepts a rate change
            log.warning("could not raise the attitude rate: %s", exc)
        log.info("connected to %s autopilot via MAVSDK on %s", t.autopilot, self._url())

    def _subscribe(self) -> None:
        t, tel = self.telemetry, self._telemetry

        def position(pv, _):
            with t.lock:
                t.position = (pv.position.north_m, pv.position.east_m, pv.position.down_m)
                t.velocity = (pv.velocity.north_m_s, pv.velocity.east_m_s, pv.velocity.down_m_s)
                t.position_time = self.clock.now()
                # MAVSDK's position carries no time stamp: the latest attitude's stands in for it
                stamp = t.attitude_history[-1][0] if t.attitude_history else 0.0
                t.position_history.append((stamp, *t.position))
            t.notify(stamp, position=t.position)

        def attitude(e, _):
            rpy = (math.radians(e.roll_deg), math.radians(e.pitch_deg), math.radians(e.yaw_deg))
            with t.lock:
                t.attitude_euler = rpy
                t.attitude_history.append((e.timestamp_us * 1e-6, *rpy))
            t.notify(e.timestamp_us * 1e-6, attitude=rpy)

        def armed(value, _):
            with t.lock:
                t.armed = bool(value)

        def flight_mode(mode, _):
            with t.lock:
                t.mode = {"HOLD": "LOITER", "RETURN_TO_LAUNCH": "RTL"}.get(mode.name, mode.name)

        def landed_state(state, _):
            with t.lock:
                if state.name != "UNKNOWN":
                    t.landed = state.name == "ON_GROUND"

        def home(p, _):
            with t.lock:
                t.home = (p.latitude_deg, p.longitude_deg, p.absolute_altitude_m)

        def status_text(s, _):
            log.info("autopilot: %s", s.text)
            with t.lock:
                t.statustexts.append((int(s.type), s.text))

        tel.subscribe_position_velocity_ned(position)
        tel.subscribe_attitude_euler(attitude)
        tel.subscribe_armed(armed)
        tel.subscribe_flight_mode(flight_mode)
        tel.subscribe_landed_state(landed_state)
        tel.subscribe_home(home)
        tel.subscribe_status_text(status_text)

    def _watch_connection(self) -> None:
        while not self._stop.wait(0.1):
            if self._system is not None and self._system.is_connected():
                with self.telemetry.lock:
                    self.telemetry.last_heartbeat = self.clock.now()

    def close(self) -> None:
        self._stop.set()
        if self._watch is not None:
            self._watch.join(timeout=2)
        if self._sdk is not None:
            self._sdk.destroy()
            self._sdk = None

    def _call(self, what: str, fn, *args) -> None:
        from mavsdk import MavsdkError

        try:
            fn(*args)
        except MavsdkError as exc:
            with self.telemetry.lock:
                reason = self.telemetry.statustexts[-1][1] if self.telemetry.statustexts else ""
            raise LinkError(f"{what} refused: {exc}{': ' + reason if reason else ''}") from None

    def arm(self) -> None:
        self._call("arm", self._action.arm)

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        self._call("set takeoff altitude", self._action.set_takeoff_altitude, float(altitude_m))

    def takeoff(self, altitude_m: float) -> None:
        self._call("takeoff", self._action.takeoff)

    def start_offboard(self, position, yaw: float) -> None:
        self.set_position_target(position, yaw)
        self._call("offboard start", self._offboard.start)

    def set_position_target(self, position, yaw: float) -> None:
        from mavsdk.plugins.offboard import PositionNedYaw

        if not all(math.isfinite(v) for v in (*position, yaw)):
            raise ValueError(f"setpoint {position}, yaw {yaw} is not finite")
        self._call("offboard setpoint", self._offboard.set_position_ned,
                   PositionNedYaw(float(position[0]), float(position[1]), float(position[2]), math.degrees(yaw)))

    def hold(self) -> None:
        self._call("hold", self._action.hold)

    def land(self) -> None:
        self._call("land", self._action.land)
