"""Link-loss and geofence failsafes and the pilot's stick takeover, as PX4's commander acts on them.

:class:`Failsafes` is a mixin of :class:`sitl_vehicle.commander.Commander` (it reads and sets the commander's
state and calls its ``_enter``, ``_disarm`` and ``_say``): what the loss of the offboard stream, of manual
control or of the ground station's link does (COM_OBL_RC_ACT, NAV_RCL_ACT, NAV_DLL_ACT, their exceptions and
COM_FAIL_ACT_T's delay in Hold), what leaving the geofence does (GF_ACTION), and when moving the sticks takes over
(COM_RC_OVERRIDE). Apart from the commander because it is the part that acts on what went wrong rather than on what
was asked.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.geofence import Geofence, RallyItem
from sitl_vehicle.manual import Sticks
from sitl_vehicle.modes import FlightMode

if TYPE_CHECKING:
    from sitl_vehicle.commander import VehicleStatus

# COM_OBL_RC_ACT values for Return and Land; the others (PX4: Position, Altitude, Manual, which need a pilot
# on the sticks) hold position
OBL_ACTION_RETURN = 3
OBL_ACTION_LAND = 4
# NAV_DLL_ACT (ground-station link loss) and NAV_RCL_ACT (manual control loss) values: 0 none, 1 Hold,
# 2 Return, 3 Land, 5 terminate, 6 disarm
DLL_ACTIONS = {1: FlightMode.AUTO_LOITER, 2: FlightMode.AUTO_RTL, 3: FlightMode.AUTO_LAND}
DLL_STOP_MOTORS = (5, 6)
# COM_RCL_EXCEPT / COM_DLL_EXCEPT bits (PX4's link-loss exceptions): 1 Mission, 2 the other auto modes (Hold,
# Takeoff, Land, Return), 4 Offboard; a loss in an excepted mode is only reported. The stick modes need the
# sticks and are never excepted.
LOSS_EXCEPTION_BIT = {FlightMode.AUTO_MISSION: 1, FlightMode.AUTO_LOITER: 2, FlightMode.AUTO_TAKEOFF: 2,
                      FlightMode.AUTO_LAND: 2, FlightMode.AUTO_RTL: 2, FlightMode.OFFBOARD: 4}
# PX4 ranks failsafe actions so that of two at once the worse wins: Hold < Return < Land
FAILSAFE_SEVERITY = {FlightMode.AUTO_LOITER: 0, FlightMode.AUTO_RTL: 1, FlightMode.AUTO_LAND: 2}
# GF_ACTION (PX4): 0 none, 1 warning, 2 Hold, 3 Return, 4 terminate (here: the motors stopped), 5 Land
GF_ACTIONS = {2: FlightMode.AUTO_LOITER, 3: FlightMode.AUTO_RTL, 5: FlightMode.AUTO_LAND}
GF_NONE, GF_WARNING, GF_TERMINATE = 0, 1, 4
# COM_FAIL_ACT_T at or below this acts at once, as PX4 does
FAIL_ACT_T_MIN = 0.1
# COM_RC_OVERRIDE bits: moving the sticks takes over (switches to Position) in the auto modes, in Offboard
RC_OVERRIDE_AUTO, RC_OVERRIDE_OFFBOARD = 1, 2
AUTO_MODES = (FlightMode.AUTO_MISSION, FlightMode.AUTO_LOITER, FlightMode.AUTO_TAKEOFF, FlightMode.AUTO_LAND,
              FlightMode.AUTO_RTL)
# the sticks "move" when an axis (throttle counted double: its range is half) changed by COM_RC_STICK_OV
# within this window: a quick push, not a slow drift or jitter (PX4 thresholds a smoothed stick rate)
STICK_MOVE_WINDOW_S = 1.0


class Failsafes:
    """The commander's failsafe and takeover logic, mixed into ``Commander``."""

    def _offboard_lost(self, status: VehicleStatus) -> None:
        action = int(self.params["COM_OBL_RC_ACT"])
        target = {OBL_ACTION_LAND: FlightMode.AUTO_LAND, OBL_ACTION_RETURN: FlightMode.AUTO_RTL}.get(
            action, FlightMode.AUTO_LOITER)
        self._fail_safe("offboard", target, status)

    def _note_stick_movement(self, sticks: Sticks, time_s: float) -> None:
        """Flag a takeover request when an axis moved by COM_RC_STICK_OV (percent of its range) within
        STICK_MOVE_WINDOW_S."""
        recent = self._recent_sticks
        while recent and time_s - recent[0][0] > STICK_MOVE_WINDOW_S:
            recent.popleft()
        threshold = 0.01 * self.params["COM_RC_STICK_OV"]
        for _, old in recent:
            if max(abs(sticks.pitch - old.pitch), abs(sticks.roll - old.roll), abs(sticks.yaw - old.yaw),
                   2.0 * abs(sticks.throttle - old.throttle)) > threshold:
                self._sticks_moved = True
                recent.clear()  # one push, one request
                break
        recent.append((time_s, sticks))

    def _stick_takeover_allowed(self) -> bool:
        """PX4's stick takeover: in the auto modes or Offboard as COM_RC_OVERRIDE allows, and from a failsafe's
        Hold, Return or Land: offboard loss's at once, a link loss's once its COM_FAIL_ACT_T delay is over
        (during it, only a mode choice takes over; with no delay configured, never)."""
        if self.failsafe and self.mode in (FlightMode.AUTO_LOITER, FlightMode.AUTO_RTL, FlightMode.AUTO_LAND):
            return self._delayed_failsafe is None and self._failsafe_stick_takeover
        bits = int(self.params["COM_RC_OVERRIDE"])
        return bool((bits & RC_OVERRIDE_AUTO and self.mode in AUTO_MODES)
                    or (bits & RC_OVERRIDE_OFFBOARD and self.mode is FlightMode.OFFBOARD))

    def _loss_excepted(self, param: str) -> bool:
        """Whether the link-loss exception mask ``param`` (COM_RCL_EXCEPT, COM_DLL_EXCEPT) covers this mode."""
        return bool(int(self.params[param]) & LOSS_EXCEPTION_BIT.get(self.mode, 0))

    def _manual_control_failsafe(self, status: VehicleStatus) -> None:
        """PX4's manual-control-loss failsafe (NAV_RCL_ACT): once per loss, in any mode COM_RCL_EXCEPT does not
        except, and not when the vehicle was armed without sticks."""
        self._manual_failsafe_done = True
        action = int(self.params["NAV_RCL_ACT"])
        self._fail_safe("manual control", None if action in DLL_STOP_MOTORS
                        else DLL_ACTIONS.get(action, FlightMode.AUTO_LOITER), status, delayed=True)

    def _data_link_failsafe(self, status: VehicleStatus) -> None:
        """PX4's data-link-loss failsafe (NAV_DLL_ACT): once a ground station had connected, once per loss, in
        the air, in any mode but Land that COM_DLL_EXCEPT does not except."""
        self._gcs_failsafe_done = True
        action = int(self.params["NAV_DLL_ACT"])
        if action in DLL_ACTIONS or action in DLL_STOP_MOTORS:
            self._fail_safe("data link", None if action in DLL_STOP_MOTORS else DLL_ACTIONS[action], status,
                            delayed=True)

    def _fail_safe(self, lost: str, target: FlightMode | None, status: VehicleStatus,
                   delayed: bool = False) -> None:
        """Act on the loss of ``lost``: switch to ``target`` (Hold instead of Return on the ground), or stop
        the motors when ``target`` is None. Already in ``target``, or landing when ``target`` is Return, the
        vehicle carries on (PX4 does not restart a Return, nor turn a landing into one).

        ``delayed`` (the link losses): as PX4 does, the vehicle first holds for COM_FAIL_ACT_T, so that the
        pilot can choose a mode instead, then switches; a loss during that delay keeps its deadline and the
        worse action. Stopping the motors never waits."""
        self.failsafe = True
        self._failsafe_stick_takeover = not delayed or self.params["COM_FAIL_ACT_T"] > FAIL_ACT_T_MIN
        if target is None:
            self._delayed_failsafe = None
            self._disarm(f"Failsafe: {lost} lost, motors stopped")
            return
        target = _hold_if_landed(target, status)
        pending = self._delayed_failsafe
        if pending is not None:
            worse = max(target, pending[0], key=FAILSAFE_SEVERITY.__getitem__)
            self._delayed_failsafe = (worse, pending[1])
            self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe: {lost} lost, switching to {worse.label} in "
                                                     f"{max(pending[1] - status.time_s, 0.0):.0f} s")
            return
        if target is self.mode or (target is FlightMode.AUTO_RTL and self.mode is FlightMode.AUTO_LAND):
            self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe: {lost} lost, continuing {self.mode.label}")
            return
        wait = self.params["COM_FAIL_ACT_T"] if delayed else 0.0
        if wait > FAIL_ACT_T_MIN and target is not FlightMode.AUTO_LOITER:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe: {lost} lost, switching to {target.label} in "
                                                     f"{wait:.0f} s (Hold until then)")
            self._delayed_failsafe = (target, status.time_s + wait)
            if self.mode is not FlightMode.AUTO_LOITER:
                self._enter(FlightMode.AUTO_LOITER, status)
            return
        self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe: {lost} lost, switching to {target.label}")
        self._enter(target, status)

    def set_rally_points(self, points: list[RallyItem]) -> None:
        """New rally points (uploaded whole; none clears them): a Return started from now on may fly to one."""
        self.rally_points = tuple(points)

    def set_geofence(self, geofence: Geofence) -> None:
        """A new fence (uploaded whole; an empty one clears it)."""
        self.geofence = geofence
        self._geofence_breached = False

    def _geofence_breach(self, status: VehicleStatus, home: tuple[float, float, float] | None = None) -> str | None:
        """Why the vehicle is outside the fence and its limits from ``home`` (default: the commander's), or None."""
        return self.geofence.breach(status.position, self.home if home is None else home,
                                    self.params["GF_MAX_HOR_DIST"], self.params["GF_MAX_VER_DIST"])

    def _check_geofence(self, status: VehicleStatus) -> None:
        """PX4's geofence failsafe: leaving the fence in the air does what GF_ACTION says, once, until the vehicle
        is back inside (a Hold holds where it stopped; the pilot may choose a mode or take over with the sticks)."""
        why = self._geofence_breach(status) if self.armed and not status.landed else None
        if why is None or self._geofence_breached:
            self._geofence_breached = why is not None
            return
        self._geofence_breached = True
        action = int(self.params["GF_ACTION"])
        text = f"Geofence breached: {why}"
        if action == GF_TERMINATE:
            self._disarm(f"{text}: flight terminated, motors stopped")
        elif action in GF_ACTIONS:
            self.failsafe = True
            self._failsafe_stick_takeover = True
            target = _hold_if_landed(GF_ACTIONS[action], status)
            if target is self.mode or (target is FlightMode.AUTO_RTL and self.mode is FlightMode.AUTO_LAND):
                self._say(mavlink.MAV_SEVERITY_CRITICAL, f"{text}, continuing {self.mode.label}")
            else:
                self._say(mavlink.MAV_SEVERITY_CRITICAL, f"{text}, switching to {target.label}")
                self._enter(target, status)
        elif action == GF_WARNING:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, text)

    def _delayed_failsafe_due(self, status: VehicleStatus) -> None:
        """COM_FAIL_ACT_T is over and no mode was chosen meanwhile: the failsafe's action, even if the link
        came back meanwhile (PX4 clears a Return or a Land only on a mode change)."""
        target = _hold_if_landed(self._delayed_failsafe[0], status)
        self._delayed_failsafe = None
        if target is not self.mode:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Failsafe: switching to {target.label}")
            self._enter(target, status)


def _hold_if_landed(target: FlightMode, status: VehicleStatus) -> FlightMode:
    """A failsafe's mode: Hold instead of Return on the ground (there is nothing to return from)."""
    return FlightMode.AUTO_LOITER if target is FlightMode.AUTO_RTL and status.landed else target
