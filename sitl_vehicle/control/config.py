"""All controller gains and limits as one frozen dataclass (PX4 parameter names in the comments).

Units are physical so one set of gains suits every airframe: the velocity loop outputs an
acceleration (m/s^2), the rate loop an angular acceleration (rad/s^2) that the allocator turns into
torque through the airframe's inertia.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_D = math.pi / 180.0


@dataclass(frozen=True)
class ControlConfig:
    # --- loop rates (PX4: rate loop at gyro rate, attitude ~250 Hz, position ~50-100 Hz)
    attitude_hz: float = 250.0  # Hz, attitude loop rate (rate loop runs every physics step)
    position_hz: float = 100.0  # Hz, position/velocity loop rate
    # --- position P (MPC_XY_P, MPC_Z_P)
    pos_p_xy: float = 2.0  # 1/s, MPC_XY_P
    pos_p_z: float = 1.8  # 1/s, MPC_Z_P
    # --- velocity PID -> acceleration (MPC_*_VEL_*_ACC)
    vel_p_xy: float = 4.0  # 1/s, MPC_XY_VEL_P_ACC
    vel_i_xy: float = 0.5  # 1/s^2, MPC_XY_VEL_I_ACC
    vel_d_xy: float = 0.1  # -, MPC_XY_VEL_D_ACC
    vel_p_z: float = 5.0  # 1/s, MPC_Z_VEL_P_ACC
    vel_i_z: float = 4.0  # 1/s^2, MPC_Z_VEL_I_ACC
    vel_d_z: float = 0.0  # -, MPC_Z_VEL_D_ACC
    acc_ff_lead_s: float = 0.06  # s, planner acceleration feed-forward is taken this far ahead (inner-loop lag)
    vel_max_xy: float = 12.0  # m/s, MPC_XY_VEL_MAX (controller limit; the planner has its own)
    vel_max_up: float = 3.0  # m/s, MPC_Z_VEL_MAX_UP
    vel_max_down: float = 1.5  # m/s, MPC_Z_VEL_MAX_DN
    # --- thrust / tilt
    tilt_max_rad: float = 45.0 * _D  # rad, MPC_TILTMAX_AIR
    thrust_min: float = 0.12  # -, MPC_THR_MIN (normalised collective thrust)
    thrust_max: float = 1.0  # -, MPC_THR_MAX
    hover_thrust: float | None = None  # -, MPC_THR_HOVER; None = exact value from the airframe
    # --- attitude P (MC_ROLL_P, MC_PITCH_P, MC_YAW_P, MC_YAW_WEIGHT)
    att_p: tuple[float, float, float] = (15.0, 15.0, 4.0)  # 1/s, roll, pitch, yaw
    yaw_weight: float = 0.4  # -, MC_YAW_WEIGHT
    rate_max: tuple[float, float, float] = (220.0 * _D, 220.0 * _D, 200.0 * _D)  # rad/s, MC_*RATE_MAX
    # --- body-rate PID -> angular acceleration (MC_*RATE_P/I/D/FF, MC_*R_INT_LIM)
    rate_p: tuple[float, float, float] = (50.0, 50.0, 15.0)  # 1/s, roll, pitch, yaw
    rate_i: tuple[float, float, float] = (40.0, 40.0, 10.0)  # 1/s^2
    rate_d: tuple[float, float, float] = (0.9, 0.9, 0.0)  # -
    rate_ff: tuple[float, float, float] = (0.0, 0.0, 0.0)  # 1/s
    rate_int_lim: tuple[float, float, float] = (30.0, 30.0, 10.0)  # rad/s^2, integrator limit
    rate_d_lpf_hz: float = 40.0  # Hz, IMU_DGYRO_CUTOFF (D-term low-pass)
