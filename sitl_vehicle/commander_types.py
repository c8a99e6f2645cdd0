"""What the commander is given and what it answers: the vehicle's status each tick, a command's reply, and the
armed state, setpoint and mode it asks the vehicle core to fly (pure data, shared by the commander's mixins and the
MAVLink edge)."""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.modes import FlightMode
from sitl_vehicle.sim import ManualSetpoint, Setpoint


@dataclass(frozen=True)
class VehicleStatus:
    """What the commander may know about the vehicle: the estimate, not the truth."""

    time_s: float
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    yaw: float
    armed: bool
    landed: bool
    crashed: bool = False
    position_valid: bool = True


@dataclass(frozen=True)
class Reply:
    result: int  # MAV_RESULT
    text: str | None = None  # reason, also sent as STATUSTEXT when the command is refused
    announced: bool = False  # the commander has queued the STATUSTEXT already (``messages``)

    @property
    def accepted(self) -> bool:
        return self.result == mavlink.MAV_RESULT_ACCEPTED


ACCEPTED = Reply(mavlink.MAV_RESULT_ACCEPTED)


@dataclass(frozen=True)
class CommanderOutput:
    armed: bool
    setpoint: Setpoint | ManualSetpoint
    mode: FlightMode
