"""PX4 flight modes and their MAVLink encoding (HEARTBEAT base_mode / custom_mode).

PX4 packs its mode into HEARTBEAT.custom_mode as main mode in bits 16–23 and sub mode in bits 24–31
(px4_custom_mode.h). Clients such as MAVSDK, QGroundControl and pymavlink's ``interpret_px4_mode`` decode
the mode from these bits alone, so they are the contract; base_mode carries the armed flag and the
generic capability flags PX4 sets for each mode.
"""

from __future__ import annotations

import enum

from pymavlink.dialects.v20 import common as mavlink

# PX4 main modes (px4_custom_mode.h)
MAIN_MANUAL = 1
MAIN_ALTCTL = 2
MAIN_POSCTL = 3
MAIN_AUTO = 4
MAIN_ACRO = 5
MAIN_OFFBOARD = 6
MAIN_STABILIZED = 7

# PX4 AUTO sub modes
SUB_AUTO_READY = 1
SUB_AUTO_TAKEOFF = 2
SUB_AUTO_LOITER = 3
SUB_AUTO_MISSION = 4
SUB_AUTO_RTL = 5
SUB_AUTO_LAND = 6

# PX4 POSCTL sub modes
SUB_POSCTL_ORBIT = 1


class FlightMode(enum.Enum):
    """The modes this vehicle flies; value = (main mode, sub mode, name as PX4 prints it)."""

    AUTO_TAKEOFF = (MAIN_AUTO, SUB_AUTO_TAKEOFF, "Takeoff")
    AUTO_LOITER = (MAIN_AUTO, SUB_AUTO_LOITER, "Hold")
    AUTO_LAND = (MAIN_AUTO, SUB_AUTO_LAND, "Land")
    AUTO_RTL = (MAIN_AUTO, SUB_AUTO_RTL, "Return")
    OFFBOARD = (MAIN_OFFBOARD, 0, "Offboard")
    AUTO_MISSION = (MAIN_AUTO, SUB_AUTO_MISSION, "Mission")
    POSCTL = (MAIN_POSCTL, 0, "Position")
    ORBIT = (MAIN_POSCTL, SUB_POSCTL_ORBIT, "Orbit")  # flown from MAV_CMD_DO_ORBIT's circle, not the sticks
    ALTCTL = (MAIN_ALTCTL, 0, "Altitude")
    STABILIZED = (MAIN_STABILIZED, 0, "Stabilized")
    MANUAL = (MAIN_MANUAL, 0, "Manual")  # a multicopter flies Manual as Stabilized, as PX4's does
    ACRO = (MAIN_ACRO, 0, "Acro")

    @property
    def custom_mode(self) -> int:
        main, sub, _ = self.value
        return (main << 16) | (sub << 24)

    @property
    def label(self) -> str:
        return self.value[2]

    @property
    def manual(self) -> bool:
        """Flown with the sticks (MANUAL_CONTROL): Position, Altitude, Stabilized, Manual and Acro (Orbit, a
        Position sub mode, flies its circle without them)."""
        return self is not FlightMode.ORBIT and self.value[0] in (MAIN_POSCTL, MAIN_ALTCTL, MAIN_STABILIZED,
                                                                  MAIN_MANUAL, MAIN_ACRO)

    @property
    def attitude_from_sticks(self) -> bool:
        """The sticks set the attitude and the throttle the thrust (no altitude or position hold)."""
        return self.value[0] in (MAIN_STABILIZED, MAIN_MANUAL)

    @property
    def rates_from_sticks(self) -> bool:
        """Acro: the sticks set the body rates and the throttle the thrust; centred sticks hold the attitude the
        vehicle has, level or not."""
        return self.value[0] == MAIN_ACRO

    @property
    def thrust_from_throttle(self) -> bool:
        """The throttle stick sets the thrust (Stabilized, Manual and Acro): arming needs it low, and on the
        ground the sticks are flown as they are."""
        return self.attitude_from_sticks or self.rates_from_sticks

    @property
    def base_mode_flags(self) -> int:
        """The generic base_mode flags PX4 reports for this mode (without the armed flag): manual input for
        the stick modes, guided for those that hold position, auto for the autonomous ones; every mode but
        Acro (rates only) stabilizes, as PX4 reports."""
        flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if not self.rates_from_sticks:
            flags |= mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.manual:
            flags |= mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        else:
            flags |= mavlink.MAV_MODE_FLAG_AUTO_ENABLED
        if self is FlightMode.POSCTL or not self.manual:
            flags |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        return flags


class UnsupportedMode(ValueError):
    """A mode request names a PX4 mode this vehicle does not fly."""


def mode_from_custom(main_mode: int, sub_mode: int) -> FlightMode:
    """Map a DO_SET_MODE (custom main, custom sub) pair to a FlightMode.

    PX4 treats AUTO with sub mode 0 as Hold-like ready state; we map it to Hold. Position and Altitude
    and, with the attitude and thrust straight from the sticks, Stabilized and Manual are flown with
    MANUAL_CONTROL sticks (Position's Orbit sub mode is Orbit, any other maps to plain Position), as is Acro,
    with the body rates from the sticks.
    """
    for mode in FlightMode:
        if mode.value[:2] == (main_mode, sub_mode):
            return mode
    for mode in FlightMode:
        main, sub, _ = mode.value
        if main == main_mode and main != MAIN_AUTO and sub == 0:
            return mode
    if main_mode == MAIN_AUTO and sub_mode in (0, SUB_AUTO_READY):
        return FlightMode.AUTO_LOITER
    raise UnsupportedMode(f"PX4 mode main={main_mode} sub={sub_mode} is not supported by this vehicle; it flies "
                          f"{', '.join(m.label for m in FlightMode)}")


def decode_custom_mode(custom_mode: int) -> tuple[int, int]:
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
