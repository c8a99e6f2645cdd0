"""PX4-shaped control cascade: position/velocity -> attitude -> body rate -> mixer (one module each)."""

from sitl_vehicle.control.attitude import AttitudeControl
from sitl_vehicle.control.config import ControlConfig
from sitl_vehicle.control.mixer import Mixer
from sitl_vehicle.control.position import (
    PositionControl,
    PositionControlOutput,
    PositionControlStates,
    TrajectorySetpoint,
)
from sitl_vehicle.control.rate import RateControl

__all__ = [
    "AttitudeControl", "ControlConfig", "Mixer", "PositionControl", "PositionControlOutput",
    "PositionControlStates", "RateControl", "TrajectorySetpoint",
]
