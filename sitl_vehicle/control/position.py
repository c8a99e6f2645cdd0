"""Position + velocity control with the shape of PX4's ``PositionControl`` (mc_pos_control).

A pure class: gains and limits come in through setters, the vehicle state through ``set_state``, the
setpoint through ``set_input_setpoint``, and ``update(dt)`` returns a new :class:`PositionControlOutput`
whose ``valid`` says whether the input was complete. NaN components mean "axis not controlled at this
level", exactly as in PX4:

* position P (+ velocity feed-forward): ``v_sp = v_ff + Kp (p_sp - p)`` where finite; a NaN position
  leaves the velocity setpoint as given, a NaN velocity feed-forward takes the position term alone;
* velocity PID (+ acceleration feed-forward): ``a_sp = a_ff + Kp e + I - Kd dv/dt`` where finite;
* acceleration -> normalised thrust vector with tilt limit and hover thrust, vertical thrust has
  priority over horizontal, anti-windup: vertical integrator frozen in saturation, horizontal by
  tracking anti-reset windup (Rundqwist 1990) as PX4 does.

Validity (``_input_valid``): every axis needs a finite position, velocity or acceleration setpoint;
x and y setpoints come in pairs at each level; each controlled state must have a finite estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl_vehicle.airframes import GRAVITY

NAN = float("nan")
NAN3 = (NAN, NAN, NAN)


_fin = math.isfinite  # C builtin: much cheaper than a Python-level helper in the control loops


@dataclass(frozen=True)
class PositionControlStates:
    position: tuple[float, float, float]  # m, NED
    velocity: tuple[float, float, float]  # m/s, NED
    acceleration: tuple[float, float, float]  # m/s^2, NED (velocity derivative for the D term)
    yaw: float  # rad


@dataclass(frozen=True)
class TrajectorySetpoint:
    position: tuple[float, float, float] = NAN3  # m, NED; NaN = not controlled
    velocity: tuple[float, float, float] = NAN3  # m/s, NED (feed-forward when position is set)
    acceleration: tuple[float, float, float] = NAN3  # m/s^2, NED (feed-forward)
    yaw: float = NAN  # rad
    yaw_rate: float = NAN  # rad/s


@dataclass(frozen=True)
class PositionControlOutput:
    valid: bool  # False: incomplete input, the other fields must not be used
    thrust: tuple[float, float, float]  # -, normalised thrust vector in NED (|.| = collective 0..1)
    acceleration: tuple[float, float, float]  # m/s^2, acceleration setpoint that produced it
    velocity: tuple[float, float, float]  # m/s, velocity setpoint after the position loop
    yaw: float  # rad
    yaw_rate: float  # rad/s


class PositionControl:
    """PX4-style position/velocity controller; no clock, no I/O."""

    def __init__(self) -> None:
        self._gain_pos_p = (1.0, 1.0, 1.0)
        self._gain_vel_p = (1.8, 1.8, 4.0)
        self._gain_vel_i = (0.4, 0.4, 2.0)
        self._gain_vel_d = (0.2, 0.2, 0.0)
        self._lim_vel_horizontal = 12.0
        self._lim_vel_up = 3.0
        self._lim_vel_down = 1.5
        self._lim_thr_min = 0.12
        self._lim_thr_max = 1.0
        self._lim_tilt = math.radians(45.0)
        self._hover_thrust = 0.5
        self._vel_int = [0.0, 0.0, 0.0]
        self._state = PositionControlStates(NAN3, NAN3, NAN3, NAN)
        self._sp = TrajectorySetpoint()

    # ------------------------------------------------------------------ setters (PX4 names)
    def set_position_gains(self, p: tuple[float, float, float]) -> None:
        self._gain_pos_p = tuple(p)

    def set_velocity_gains(self, p, i, d) -> None:
        self._gain_vel_p, self._gain_vel_i, self._gain_vel_d = tuple(p), tuple(i), tuple(d)

    def set_velocity_limits(self, horizontal: float, up: float, down: float) -> None:
        self._lim_vel_horizontal, self._lim_vel_up, self._lim_vel_down = horizontal, up, down

    def set_thrust_limits(self, minimum: float, maximum: float) -> None:
        self._lim_thr_min, self._lim_thr_max = max(minimum, 1e-4), maximum

    def set_tilt_limit(self, tilt_rad: float) -> None:
        self._lim_tilt = tilt_rad

    def set_hover_thrust(self, hover_thrust: float) -> None:
        """Normalised collective thrust that balances gravity (MPC_THR_HOVER)."""
        hover_thrust = min(max(hover_thrust, 0.05), 0.9)
        self._hover_thrust = hover_thrust

    def set_state(self, state: PositionControlStates) -> None:
        self._state = state

    def set_input_setpoint(self, sp: TrajectorySetpoint) -> None:
        self._sp = sp

    def reset_integral(self) -> None:
        self._vel_int = [0.0, 0.0, 0.0]

    def reset_integral_xy(self) -> None:
        self._vel_int[0] = 0.0
        self._vel_int[1] = 0.0

    @property
    def integral(self) -> tuple[float, float, float]:
        return tuple(self._vel_int)

    # ------------------------------------------------------------------ update
    def _input_valid(self) -> bool:
        sp, st = self._sp, self._state
        ps, vs, acs = sp.position, sp.velocity, sp.acceleration
        for i in range(3):
            if not (_fin(ps[i]) or _fin(vs[i]) or _fin(acs[i])):
                return False
        if _fin(ps[0]) != _fin(ps[1]) or _fin(vs[0]) != _fin(vs[1]) or _fin(acs[0]) != _fin(acs[1]):
            return False
        for i in range(3):
            if _fin(ps[i]) and not _fin(st.position[i]):
                return False
            if _fin(vs[i]) and not (_fin(st.velocity[i]) and _fin(st.acceleration[i])):
                return False
        return True

    def update(self, dt: float) -> PositionControlOutput:
        """Run one position + velocity control step; ``valid`` False = incomplete input."""
        sp, st = self._sp, self._state
        if not self._input_valid():
            return PositionControlOutput(False, NAN3, NAN3, NAN3, NAN, NAN)

        pos, vel, vel_dot = st.position, st.velocity, st.acceleration
        kp = self._gain_pos_p
        # ---- position P: v_sp = v_ff + Kp*(p_sp - p), NaN-aware (PX4 addIfNotNan)
        vel_sp = list(sp.velocity)
        vsp_pos = [0.0, 0.0, 0.0]
        for i in range(3):
            e = (sp.position[i] - pos[i]) * kp[i]
            if _fin(e):
                vsp_pos[i] = e
                vel_sp[i] = vel_sp[i] + e if _fin(vel_sp[i]) else e
        # horizontal limit prioritising the position component over the feed-forward
        vx, vy = self._constrain_xy((vsp_pos[0], vsp_pos[1]),
                                    (vel_sp[0] - vsp_pos[0], vel_sp[1] - vsp_pos[1]), self._lim_vel_horizontal)
        if _fin(vel_sp[0]):
            vel_sp[0], vel_sp[1] = vx, vy
        if _fin(vel_sp[2]):
            vel_sp[2] = min(max(vel_sp[2], -self._lim_vel_up), self._lim_vel_down)

        # ---- velocity PID -> acceleration
        gp, gi, gd = self._gain_vel_p, self._gain_vel_i, self._gain_vel_d
        vi = self._vel_int
        g = GRAVITY
        vi[2] = min(max(vi[2], -g), g)
        acc_sp = list(sp.acceleration)
        vel_err = [0.0, 0.0, 0.0]
        for i in range(3):
            e = vel_sp[i] - vel[i]
            vel_err[i] = e
            a = e * gp[i] + vi[i] - vel_dot[i] * gd[i]
            if _fin(a):
                acc_sp[i] = acc_sp[i] + a if _fin(acc_sp[i]) else a
        thr = self._acceleration_control(acc_sp)

        # vertical anti-windup: freeze the integrator when the thrust saturates in the error's direction
        if (thr[2] >= -self._lim_thr_min and vel_err[2] >= 0.0) or (
                thr[2] <= -self._lim_thr_max and vel_err[2] <= 0.0):
            vel_err[2] = 0.0
        # vertical priority: horizontal thrust gets what is left of thrust_max
        thr_max_xy_sq = self._lim_thr_max ** 2 - thr[2] ** 2
        thr_max_xy = math.sqrt(thr_max_xy_sq) if thr_max_xy_sq > 0.0 else 0.0
        nxy = math.hypot(thr[0], thr[1])
        if nxy > thr_max_xy:
            s = thr_max_xy / nxy
            thr[0] *= s
            thr[1] *= s
        # horizontal tracking anti-reset windup
        k = g / self._hover_thrust
        prod = (thr[0] * k, thr[1] * k)
        if _fin(acc_sp[0]) and _fin(acc_sp[1]):
            lim = prod if acc_sp[0] ** 2 + acc_sp[1] ** 2 > prod[0] ** 2 + prod[1] ** 2 else (acc_sp[0], acc_sp[1])
            arw = 2.0 / gp[0] if gp[0] > 0.0 else 0.0
            vel_err[0] -= arw * (acc_sp[0] - lim[0])
            vel_err[1] -= arw * (acc_sp[1] - lim[1])
        for i in range(3):
            e = vel_err[i]
            if _fin(e):
                vi[i] += e * gi[i] * dt

        yaw_rate = sp.yaw_rate if _fin(sp.yaw_rate) else 0.0
        yaw = sp.yaw if _fin(sp.yaw) else st.yaw
        thrust = (thr[0], thr[1], thr[2])
        acc = (acc_sp[0], acc_sp[1], acc_sp[2])
        valid = all(_fin(c) for c in thrust) and all(_fin(c) for c in acc)
        return PositionControlOutput(valid, thrust, acc, (vel_sp[0], vel_sp[1], vel_sp[2]), yaw, yaw_rate)

    def _acceleration_control(self, acc_sp) -> list[float]:
        """Acceleration setpoint -> normalised thrust vector (PX4 _accelerationControl)."""
        g = GRAVITY
        zf = -g + acc_sp[2]
        # a downward acceleration beyond ~free fall cannot be produced by thrust: keep the thrust axis
        # pointing up (PX4's limitTilt would otherwise tilt an upside-down axis 45 deg north)
        bx, by, bz = -acc_sp[0], -acc_sp[1], max(-zf, 0.1 * g)
        n = math.sqrt(bx * bx + by * by + bz * bz)
        if not n > 0.0:
            bx, by, bz, n = 0.0, 0.0, 1.0, 1.0
        bx, by, bz = bx / n, by / n, bz / n
        bx, by, bz = self._limit_tilt(bx, by, bz, self._lim_tilt)
        hover = self._hover_thrust
        thrust_ned_z = acc_sp[2] * (hover / g) - hover
        cos_ned_body = bz
        collective = min(thrust_ned_z / cos_ned_body, -self._lim_thr_min) if cos_ned_body > 1e-6 \
            else -self._lim_thr_min
        return [bx * collective, by * collective, bz * collective]

    @staticmethod
    def _limit_tilt(bx: float, by: float, bz: float, tilt_max: float) -> tuple[float, float, float]:
        """Limit the angle between unit ``body_z`` and the world z axis to ``tilt_max`` (PX4 limitTilt)."""
        dot = min(max(bz, -1.0), 1.0)
        angle = math.acos(dot)
        if angle <= tilt_max:
            return bx, by, bz
        # rotate within the plane spanned by world z and body_z
        rx, ry = bx, by
        r = math.hypot(rx, ry)
        if r < 1e-9:
            rx, ry, r = 1.0, 0.0, 1.0
        s, c = math.sin(tilt_max), math.cos(tilt_max)
        return rx / r * s, ry / r * s, c

    @staticmethod
    def _constrain_xy(v0, v1, vmax: float) -> tuple[float, float]:
        """PX4 ControlMath::constrainXY: keep ``v0`` (as far as possible) and add the part of ``v1`` that fits."""
        sx, sy = v0[0] + v1[0], v0[1] + v1[1]
        if not (_fin(sx) and _fin(sy)):
            return sx, sy
        if math.hypot(sx, sy) <= vmax:
            return sx, sy
        n0 = math.hypot(v0[0], v0[1])
        if n0 >= vmax:
            return v0[0] / n0 * vmax, v0[1] / n0 * vmax
        n1 = math.hypot(v1[0], v1[1])
        if n1 < 1e-6:
            return v0
        # find s >= 0 with |v0 + s*u1| = vmax, u1 = v1/|v1|
        ux, uy = v1[0] / n1, v1[1] / n1
        b = v0[0] * ux + v0[1] * uy
        c = n0 * n0 - vmax * vmax
        s = -b + math.sqrt(max(b * b - c, 0.0))
        return v0[0] + s * ux, v0[1] + s * uy
