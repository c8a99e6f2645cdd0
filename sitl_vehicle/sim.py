"""The pure vehicle core: dynamics + sensors + estimator + PX4-shaped control cascade + planner.

No MAVLink, sockets or clocks: the caller owns time and calls :meth:`VehicleSim.step` (one physics
step) or :meth:`VehicleSim.run`. Loop rates follow PX4: the rate loop runs every physics step
(500 Hz default), the attitude loop at ``ControlConfig.attitude_hz`` (250 Hz), position/velocity at
``ControlConfig.position_hz`` (100 Hz) together with the estimator's prediction (EKF2-like 100 Hz
with IMU averaging).

Setpoints (:class:`Setpoint`, NaN = axis not controlled):

* all three position components finite -> :class:`~sitl_vehicle.trajectory.TrapezoidPlanner` (a new
  target replans from the current reference; the identical target re-sent does nothing); the
  setpoint's velocity/acceleration are then ignored (the planner supplies the feed-forward);
* some position components NaN (e.g. x, y set and z NaN with velocity z set: land-style) -> the
  finite position axes are planned, the others follow the velocity setpoint;
* position all NaN, velocity set -> acceleration-limited velocity reference (no planner);
* acceleration components are passed through where neither position nor velocity is set.
* yaw: finite ``yaw`` is tracked (with a finite ``yaw_rate`` as its feed-forward); else a finite ``yaw_rate`` is
  integrated; else the heading is held.

:class:`AttitudeSetpoint` (Stabilized flight from the sticks) bypasses position and velocity control: roll
and pitch angles, a yaw rate, and a throttle mapped to collective thrust as PX4 does (stick centre = hover
thrust). :class:`RateSetpoint` (Acro) bypasses the attitude loop too: body rates straight to the rate loop and
the collective thrust as it is.

Crash (collision or hard ground impact): motors stop, the vehicle disarms, ``crashed`` latches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sitl_vehicle.airframes import AIRFRAMES, GRAVITY, Airframe
from sitl_vehicle.collision import CollisionMonitor, CollisionWorld, GroundOnly
from sitl_vehicle.control.attitude import AttitudeControl
from sitl_vehicle.control.config import ControlConfig
from sitl_vehicle.control.mixer import Mixer
from sitl_vehicle.control.position import PositionControl, PositionControlStates, TrajectorySetpoint
from sitl_vehicle.control.qmath import (
    bodyz_to_attitude,
    euler_from_quat,
    qrotate_inv,
    quat_from_euler,
    wrap_pi,
    yaw_from_quat,
)
from sitl_vehicle.control.rate import RateControl
from sitl_vehicle.dynamics import QuadDynamics
from sitl_vehicle.estimator import Estimator
from sitl_vehicle.sensors import Imu, PoseSensor, SensorNoise
from sitl_vehicle.setpoints import (
    AttitudeSetpoint,
    ManualSetpoint,
    RateSetpoint,
    Setpoint,
    throttle_to_thrust,
)
from sitl_vehicle.trajectory import PlannerConfig, TrapezoidPlanner, VelocitySlew
from sitl_vehicle.wind import WindConfig, WindModel

__all__ = [
    "AIRFRAMES", "Airframe", "AttitudeSetpoint", "ControlConfig", "ManualSetpoint", "PlannerConfig", "RateSetpoint",
    "SensorNoise", "Setpoint", "throttle_to_thrust",
    "VehicleConfig", "VehicleSim", "VehicleState", "CollisionWorld", "GroundOnly", "GRAVITY",
]

NAN = float("nan")
NAN3 = (NAN, NAN, NAN)


_fin = math.isfinite  # C builtin: much cheaper than a Python-level helper in the control loops


@dataclass(frozen=True)
class VehicleState:
    position: tuple[float, float, float]  # m, NED
    velocity: tuple[float, float, float]  # m/s, NED
    attitude: tuple[float, float, float, float]  # -, quaternion (w, x, y, z) body FRD -> world NED
    angular_velocity: tuple[float, float, float]  # rad/s, body FRD

    def euler(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in rad, ZYX convention."""
        return euler_from_quat(self.attitude)


@dataclass(frozen=True)
class VehicleConfig:
    airframe: Airframe = AIRFRAMES["quad250"]  # vehicle parameters (see airframes.py)
    physics_hz: float = 500.0  # Hz, RK4 step rate (= rate-loop rate)
    control: ControlConfig = field(default_factory=ControlConfig)  # gains and limits
    planner: PlannerConfig = field(default_factory=PlannerConfig)  # trajectory limits
    noise: SensorNoise | None = field(default_factory=SensorNoise)  # None = estimate is exact truth
    crash_speed_mps: float = 2.0  # m/s, vertical touchdown speed above which a landing is a crash
    wind: WindConfig | None = None  # steady wind and gusts on the vehicle (None or calm: still air)


class VehicleSim:
    """One simulated multicopter; see the module docstring."""

    def __init__(self, config: VehicleConfig = VehicleConfig(), rng: np.random.Generator | None = None,
                 world: CollisionWorld | None = None, initial_position=(0.0, 0.0, 0.0), initial_yaw: float = 0.0):
        self.config = config
        af = config.airframe
        self.airframe = af
        self.dt = 1.0 / config.physics_hz
        self.time_s = 0.0
        self._k = 0
        self.dyn = QuadDynamics(af, self.dt, initial_position, initial_yaw)
        self.mixer = Mixer(af)
        self.collision = CollisionMonitor(world if world is not None else GroundOnly(), af.body_radius_m,
                                          config.crash_speed_mps)
        self._inertia = af.inertia_kgm2
        self._thrust_full = 4.0 * af.thrust_max_n
        self._rng = rng if rng is not None else np.random.default_rng(0)
        # Wind draws from a child of the seed, so that still air leaves every other draw as it was.
        self.wind = (WindModel(config.wind, self._rng.spawn(1)[0])
                     if config.wind is not None and not config.wind.calm else None)
        self.noise = config.noise
        self.pos_ctl = PositionControl()
        self.att_ctl = AttitudeControl()
        self.rate_ctl = RateControl(dt=self.dt)
        self.planner = TrapezoidPlanner(config.planner)
        self.slew = VelocitySlew(config.planner)
        self._apply_control_config(config.control)
        self.armed = False
        self.motor_command = (0.0, 0.0, 0.0, 0.0)
        self._setpoint: Setpoint | ManualSetpoint | None = None
        self._yaw_sp = float(initial_yaw)
        self._q_sp = self.dyn.attitude
        self._thrust_sp = 0.0
        self._rate_sp = (0.0, 0.0, 0.0)
        self._yaw_rate_ff = NAN
        self._ref = (NAN3, NAN3, NAN3)
        self.last_position_output = None
        # estimator
        if self.noise is not None:
            self.imu = Imu(self.noise, self._rng)
            self.pose_sensor = PoseSensor(self.noise, self._rng)
            self.estimator = Estimator(self.noise, 1.0 / self._pos_dt, self.dt,
                                       self.dyn.position, self.dyn.attitude)
            self._est_div = self._pos_div
            self._pose_div = max(int(round(config.physics_hz / self.noise.pose_rate_hz)), 1)
            self._v_mark = self.dyn.velocity
            self._mark_k = 0
        else:
            self.imu = self.pose_sensor = self.estimator = None
        self._accel_sample: tuple[float, float, float] | None = None   # the IMU's latest (imu_reading)
        self._gyro_sample: tuple[float, float, float] | None = None

    # ------------------------------------------------------------------ configuration
    def _apply_control_config(self, c: ControlConfig) -> None:
        self.control_config = c
        self._pos_div = max(int(round(self.config.physics_hz / c.position_hz)), 1)
        self._att_div = max(int(round(self.config.physics_hz / c.attitude_hz)), 1)
        self._pos_dt = self._pos_div * self.dt
        est = getattr(self, "estimator", None)
        if est is not None:
            # the estimator predicts at the position-loop rate (EKF2-like, IMU averaged over the interval)
            est.set_rate(1.0 / self._pos_dt)
            self._est_div = self._pos_div
        pc = self.pos_ctl
        pc.set_position_gains((c.pos_p_xy, c.pos_p_xy, c.pos_p_z))
        pc.set_velocity_gains((c.vel_p_xy, c.vel_p_xy, c.vel_p_z), (c.vel_i_xy, c.vel_i_xy, c.vel_i_z),
                              (c.vel_d_xy, c.vel_d_xy, c.vel_d_z))
        pc.set_velocity_limits(c.vel_max_xy, c.vel_max_up, c.vel_max_down)
        pc.set_thrust_limits(c.thrust_min, c.thrust_max)
        pc.set_tilt_limit(c.tilt_max_rad)
        pc.set_hover_thrust(c.hover_thrust if c.hover_thrust is not None else self.airframe.hover_thrust)
        self.att_ctl.set_proportional_gain(c.att_p, c.yaw_weight)
        self.att_ctl.set_rate_limit(c.rate_max)
        self.rate_ctl.set_gains(c.rate_p, c.rate_i, c.rate_d, c.rate_ff, c.rate_int_lim)
        self.rate_ctl.set_d_lpf(c.rate_d_lpf_hz, self.dt)

    def reconfigure(self, *, control: ControlConfig | None = None, planner: PlannerConfig | None = None) -> None:
        """Swap gains/limits at runtime without resetting state (integrators, plan, estimate are kept)."""
        if control is not None:
            self._apply_control_config(control)
            self.config = _replace(self.config, control=control)
        if planner is not None:
            self.planner.set_config(planner)
            self.slew.config = planner
            self.config = _replace(self.config, planner=planner)

    # ------------------------------------------------------------------ state access
    @property
    def truth(self) -> VehicleState:
        d = self.dyn
        return VehicleState(d.position, d.velocity, d.attitude, d.angular_velocity)

    @property
    def estimate(self) -> VehicleState:
        e = self.estimator
        if e is None:
            return self.truth
        return VehicleState(e.position, e.velocity, e.attitude_now(), e.omega)

    @property
    def imu_reading(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """The IMU's latest specific force (m/s², body FRD: about (0, 0, -9.81) at rest) and rates (rad/s), with
        its noise and biases; without sensor noise, the true ones."""
        if self.estimator is not None and self._accel_sample is not None:
            return self._accel_sample, self._gyro_sample
        return self.true_specific_force, tuple(self.dyn.angular_velocity)

    @property
    def true_specific_force(self) -> tuple[float, float, float]:
        """The specific force (m/s², body FRD) over the last physics step: what a perfect accelerometer reads."""
        a = self.dyn.accel_world
        return qrotate_inv(self.dyn.attitude, (a[0], a[1], a[2] - GRAVITY))

    @property
    def estimate_valid(self) -> bool:
        """Whether :attr:`estimate` may be used for control/telemetry (always, once constructed)."""
        return True

    @property
    def landed(self) -> bool:
        """On the ground and not climbing (truth ground contact, PX4 land-detector semantics)."""
        return self.dyn.on_ground

    @property
    def crashed(self) -> bool:
        return self.collision.crashed

    @property
    def crash_reason(self) -> str | None:
        return self.collision.crash_reason

    @property
    def min_clearance_m(self) -> float:
        return self.collision.min_clearance_m

    @property
    def crossed_wall(self) -> bool:
        return self.collision.crossed_wall

    @property
    def passed(self) -> bool:
        """Through the opening: the gate's rectangle crossed where the world has a gate, else the wall crossed."""
        c = self.collision
        return c.gate_crossed if c.gate is not None else c.crossed_wall

    @property
    def motor_outputs(self) -> tuple[float, float, float, float]:
        """Normalised motor states (0..1) after the motor lag."""
        m = self.dyn.motor
        return (m[0], m[1], m[2], m[3])

    @property
    def reference(self):
        """``(p_ref, v_ref, a_ref)`` fed to the position controller at its last update (NaN = unset)."""
        return self._ref

    @property
    def setpoint(self) -> Setpoint | ManualSetpoint | None:
        return self._setpoint

    # ------------------------------------------------------------------ commands
    def set_armed(self, armed: bool) -> None:
        armed = bool(armed)
        if armed and self.crashed:
            return
        if armed and not self.armed:
            self._reset_controllers()
            self.armed = True
            if isinstance(self._setpoint, Setpoint):
                self._apply_setpoint(self._setpoint, fresh=True)
        elif not armed:
            self.armed = False

    def set_setpoint(self, sp: Setpoint | ManualSetpoint) -> None:
        if isinstance(sp, ManualSetpoint):
            if type(self._setpoint) is not type(sp):
                self.planner.clear()
                self.slew.reset()
                if isinstance(self._setpoint, RateSetpoint):  # out of Acro: hold the heading it left the vehicle at
                    self._yaw_sp = yaw_from_quat(self.estimate.attitude)
            self._setpoint = sp
            return
        if isinstance(self._setpoint, ManualSetpoint):
            self._setpoint = None  # back to position control: plan from the state, not from a stale reference
            self._yaw_sp = yaw_from_quat(self.estimate.attitude)
        self._apply_setpoint(sp, fresh=False)

    def clear_setpoint(self) -> None:
        """No setpoint: an armed vehicle idles its motors."""
        self._setpoint = None
        self.planner.clear()
        self.slew.reset()

    def _reset_controllers(self) -> None:
        self.pos_ctl.reset_integral()
        self.rate_ctl.reset()
        self.planner.clear()
        self.slew.reset()
        est = self.estimate
        self._yaw_sp = yaw_from_quat(est.attitude)
        self._q_sp = est.attitude
        self._thrust_sp = 0.0
        self._rate_sp = (0.0, 0.0, 0.0)

    def _apply_setpoint(self, sp: Setpoint, fresh: bool) -> None:
        self._setpoint = sp
        if not self.armed:
            return
        est = self.estimate
        pos = sp.position
        pmask = (_fin(pos[0]), _fin(pos[1]), _fin(pos[2]))
        if any(pmask):
            speed_changed = self._plan_at_speed(sp.cruise_speed)
            if not self.planner.active or fresh:
                vr = self.slew.v_ref
                v_now = tuple(vr[i] if _fin(vr[i]) else est.velocity[i] for i in range(3))
                self.planner.clear()
                self.planner.set_target(pos, self.time_s, est.position, v_now)
            elif not self.planner.set_target(pos, self.time_s, est.position, est.velocity) and speed_changed:
                # as PX4 does, a new cruise speed (DO_CHANGE_SPEED) applies to the move under way
                self.planner.replan(self.time_s)
            if all(pmask):
                self.slew.reset()
        else:
            if self.planner.active:
                # leaving position control: the velocity reference continues from the plan's
                _, v, _ = self.planner.sample(self.time_s)
                self.slew.reset(v)
                self.planner.clear()
        if _fin(sp.yaw):
            self._yaw_sp = sp.yaw

    def _plan_at_speed(self, cruise_speed: float) -> bool:
        """The planner's limits: the configured ones, with a setpoint's cruise speed (capped at the horizontal
        velocity limit) in place of MPC_XY_CRUISE. Returns whether they changed."""
        limits = self.config.planner
        if _fin(cruise_speed):
            limits = _replace(limits, v_max_xy=min(cruise_speed, self.config.control.vel_max_xy))
        if self.planner.config == limits:
            return False
        self.planner.set_config(limits)
        return True

    # ------------------------------------------------------------------ stepping
    def run(self, duration_s: float) -> None:
        n = int(round(duration_s / self.dt))
        step = self.step
        for _ in range(n):
            step()

    def step(self) -> None:
        """One physics step: sensors/estimator, due control loops, mixer, RK4, collision check."""
        k = self._k
        dyn = self.dyn
        est = self.estimator
        if est is not None:
            gyro = self.imu.gyro(dyn.x[10:13])
            self._gyro_sample = gyro
            est.add_gyro(gyro, self.dt)
            if k % self._est_div == 0:
                v = dyn.velocity
                vm = self._v_mark
                n = k - self._mark_k
                self._v_mark = v
                self._mark_k = k
                if n > 0:
                    f = self.imu.accel_mean(dyn.attitude, (v[0] - vm[0], v[1] - vm[1], v[2] - vm[2]),
                                            n * self.dt, n)
                    self._accel_sample = f
                    est.predict(f)
            if k % self._pose_div == 0:
                p, q = self.pose_sensor.measure(dyn.position, dyn.attitude)
                est.update_position(p)
                est.correct_attitude(q, self._pose_div * self.dt)

        if self.armed and self._setpoint is not None:
            if k % self._pos_div == 0:
                self._position_loop()
            if k % self._att_div == 0:
                if est is not None:
                    est.propagate()
                    q = est.q
                else:
                    q = dyn.attitude
                sp = self._setpoint
                if isinstance(sp, RateSetpoint):    # Acro: the sticks' rates go to the rate loop as they are
                    self._rate_sp = (sp.roll_rate, sp.pitch_rate, sp.yaw_rate)
                else:
                    self._rate_sp = self.att_ctl.update(q, self._q_sp, self._yaw_rate_ff)
            omega = est.omega if est is not None else dyn.angular_velocity
            landed = dyn.on_ground
            if landed:
                self.rate_ctl.reset_integral()
            alpha = self.rate_ctl.update(omega, self._rate_sp, update_integral=not landed)
            ix, iy, iz = self._inertia
            u = self.mixer.mix(self._thrust_sp * self._thrust_full, (alpha[0] * ix, alpha[1] * iy, alpha[2] * iz))
            self.rate_ctl.set_saturation_status(self.mixer.saturation_positive, self.mixer.saturation_negative)
            if landed and self._thrust_sp < self.airframe.hover_thrust * 0.9:
                idle = self.airframe.idle_command
                u = [max(x, idle) for x in u]
            self.motor_command = (u[0], u[1], u[2], u[3])
        elif self.armed:
            idle = self.airframe.idle_command
            self.motor_command = (idle, idle, idle, idle)
        else:
            self.motor_command = (0.0, 0.0, 0.0, 0.0)

        if self.wind is not None:
            dyn.wind = self.wind.velocity(self.time_s)
        dyn.step(self.motor_command)
        self._k = k + 1
        self.time_s = self._k * self.dt
        x = dyn.x
        if self.collision.check((x[0], x[1], x[2]), self.time_s, dyn.touchdown_speed_mps if dyn.touchdown else None):
            self.armed = False
            self.motor_command = (0.0, 0.0, 0.0, 0.0)

    def _position_loop(self) -> None:
        sp = self._setpoint
        t = self.time_s
        dtp = self._pos_dt
        if isinstance(sp, AttitudeSetpoint):
            self._stabilized(sp, dtp)
            return
        if isinstance(sp, RateSetpoint):
            self._thrust_sp = min(max(sp.thrust, 0.0), 1.0)
            self._ref = (NAN3, NAN3, NAN3)
            return
        est = self.estimator
        dyn = self.dyn
        if est is not None:
            pos, vel, acc, q = est.position, est.velocity, est.acceleration, est.q
        else:
            pos, vel, acc, q = dyn.position, dyn.velocity, dyn.accel_world, dyn.attitude
        # ---- reference
        if self.planner.active:
            p_ref, v_ref, a_ref = self.planner.sample(t)
            lead = self.control_config.acc_ff_lead_s
            if lead > 0.0:
                # the acceleration feed-forward leads by the inner loops' lag (attitude/thrust response)
                a_ref = self.planner.sample(t + lead)[2]
        else:
            p_ref, v_ref, a_ref = NAN3, NAN3, NAN3
        if not all(_fin(c) for c in p_ref):
            vsp = sp.velocity
            vmask = [not _fin(p_ref[i]) and _fin(vsp[i]) for i in range(3)]
            if any(vmask):
                vin = tuple(vsp[i] if vmask[i] else NAN for i in range(3))
                sv, sa = self.slew.update(vin, dtp, vel)
                v_ref = tuple(sv[i] if vmask[i] else v_ref[i] for i in range(3))
                a_ref = tuple(sa[i] if vmask[i] else a_ref[i] for i in range(3))
            else:
                self.slew.reset()
            asp = sp.acceleration
            a_ref = tuple(asp[i] if (not _fin(p_ref[i]) and not _fin(v_ref[i]) and _fin(asp[i])) else a_ref[i]
                          for i in range(3))
        self._ref = (p_ref, v_ref, a_ref)
        # ---- yaw
        yaw_rate = sp.yaw_rate
        if _fin(sp.yaw):
            self._yaw_sp = sp.yaw
            yaw_ff = yaw_rate if _fin(yaw_rate) else NAN     # both: the rate is the feed-forward, as on PX4
        elif _fin(yaw_rate):
            self._yaw_sp = wrap_pi(self._yaw_sp + yaw_rate * dtp)
            yaw_ff = yaw_rate
        else:
            yaw_ff = NAN
        self._yaw_rate_ff = yaw_ff
        # ---- position/velocity control
        pc = self.pos_ctl
        if dyn.on_ground:
            pc.reset_integral_xy()
        pc.set_state(PositionControlStates(pos, vel, acc, yaw_from_quat(q)))
        pc.set_input_setpoint(TrajectorySetpoint(p_ref, v_ref, a_ref, self._yaw_sp, yaw_ff))
        out = pc.update(dtp)
        self.last_position_output = out
        if not out.valid:
            # incomplete setpoint: level attitude, hover thrust (PX4 would fail over to a safe mode)
            self._q_sp = bodyz_to_attitude((0.0, 0.0, 1.0), self._yaw_sp)
            self._thrust_sp = self.pos_ctl._hover_thrust
            return
        tx, ty, tz = out.thrust
        n = math.sqrt(tx * tx + ty * ty + tz * tz)
        self._thrust_sp = n
        self._q_sp = bodyz_to_attitude((-tx, -ty, -tz) if n > 1e-9 else (0.0, 0.0, 1.0), self._yaw_sp)


    def _stabilized(self, sp: AttitudeSetpoint, dtp: float) -> None:
        """Stabilized flight: attitude from the sticks (yaw integrated from the rate), thrust from the throttle."""
        c = self.control_config
        tilt = min(math.hypot(sp.roll, sp.pitch), c.tilt_max_rad)
        scale = tilt / math.hypot(sp.roll, sp.pitch) if tilt > 0 else 0.0
        self._yaw_sp = wrap_pi(self._yaw_sp + sp.yaw_rate * dtp)
        self._yaw_rate_ff = sp.yaw_rate
        self._q_sp = quat_from_euler(sp.roll * scale, sp.pitch * scale, self._yaw_sp)
        self._thrust_sp = throttle_to_thrust(sp.throttle, self.pos_ctl._hover_thrust, c.thrust_min, c.thrust_max)
        self._ref = (NAN3, NAN3, NAN3)


def _replace(cfg, **kw):
    from dataclasses import replace

    return replace(cfg, **kw)

