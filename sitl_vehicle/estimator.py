"""State estimator: filterpy Kalman filter for position/velocity, complementary filter for attitude.

Design (documented choice):

* **Attitude**: the bias-corrected gyro is accumulated every physics step into a delta angle (the rate
  estimate for the rate loop is the per-step ``gyro - bias``) and the quaternion is rotated by the
  accumulated delta angle whenever the attitude is consumed (attitude loop, KF prediction, correction);
  telemetry reads it turned without storing it (:meth:`Estimator.attitude_now`), so that only simulated time
  groups the sums.
  At each pose measurement (``pose_rate_hz``, mocap-like) a Mahony-style complementary correction
  pulls the estimate towards the measured attitude by a fraction ``att_gain`` of the small-angle
  error and integrates the same error into a gyro-bias estimate (``gyro_bias_gain``).
* **Position/velocity**: ``filterpy.kalman.KalmanFilter`` with state ``[p(3), v(3), b_a(3)]`` (NED,
  ``b_a`` an accelerometer bias expressed in NED, a random walk). Prediction runs at the estimator
  rate (``rate_hz``, 100 Hz like PX4 EKF2) with the interval-averaged accelerometer rotated to NED by
  the attitude estimate plus gravity as the control input; the update uses the position measurement.
  F, B, Q, H, R are precomputed once and ``predict``/``update`` are called with no extra arguments.

The telemetry estimate is this filter's output; the controllers fly on it.
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import KalmanFilter

from sitl_vehicle.airframes import GRAVITY
from sitl_vehicle.control.qmath import qconj, qmul, qrotate
from sitl_vehicle.sensors import SensorNoise


def _rotated(q, da) -> tuple[float, float, float, float]:
    """``q`` rotated by the body delta angle ``da`` (exact exponential map), normalised."""
    ax, ay, az = da
    ang = math.sqrt(ax * ax + ay * ay + az * az)
    h = 0.5 * ang
    k = math.sin(h) / ang
    qw, qx, qy, qz = qmul(q, (math.cos(h), ax * k, ay * k, az * k))
    n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return (qw * n, qx * n, qy * n, qz * n)


class Estimator:
    """Pose estimator fed by :mod:`sitl_vehicle.sensors`; pure (times come from the caller)."""

    def __init__(self, noise: SensorNoise, rate_hz: float, physics_dt: float, position=(0.0, 0.0, 0.0),
                 attitude=(1.0, 0.0, 0.0, 0.0), att_gain: float = 0.05, gyro_bias_gain: float = 0.5,
                 accel_bias_walk: float = 0.01):
        self.noise = noise
        self._physics_dt = physics_dt
        self._accel_bias_walk = accel_bias_walk
        self.att_gain = att_gain
        self.gyro_bias_gain = gyro_bias_gain
        kf = KalmanFilter(dim_x=9, dim_z=3, dim_u=3)
        i3 = np.eye(3)
        kf.H = np.hstack([i3, np.zeros((3, 3)), np.zeros((3, 3))])
        kf.R = noise.pos_noise_m ** 2 * i3 if noise.pos_noise_m > 0 else 1e-8 * i3
        self.kf = kf
        self.set_rate(rate_hz)
        kf.x = np.array([*position, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=float)
        kf.P = np.diag([0.05 ** 2] * 3 + [0.1 ** 2] * 3 + [max(noise.accel_bias_m_s2, 1e-3) ** 2] * 3)
        self.kf = kf
        self._u = np.zeros(3)
        self._z = np.zeros(3)
        self.q = tuple(float(c) for c in attitude)
        self.gyro_bias = (0.0, 0.0, 0.0)
        self.omega = (0.0, 0.0, 0.0)
        self._dangle = [0.0, 0.0, 0.0]
        self.position = tuple(float(c) for c in position)
        self.velocity = (0.0, 0.0, 0.0)
        self.acceleration = (0.0, 0.0, 0.0)

    def set_rate(self, rate_hz: float) -> None:
        """(Re)build the constant F, B, Q for a prediction interval of ``1/rate_hz``; state and P are kept."""
        self.dt = dt = 1.0 / rate_hz
        noise = self.noise
        kf = self.kf
        i3 = np.eye(3)
        z3 = np.zeros((3, 3))
        kf.F = np.block([[i3, dt * i3, -0.5 * dt * dt * i3], [z3, i3, -dt * i3], [z3, z3, i3]])
        kf.B = np.vstack([0.5 * dt * dt * i3, dt * i3, z3])
        samples = max(int(round(dt / self._physics_dt)), 1)
        sa = max(noise.accel_noise_m_s2 / math.sqrt(samples), 1e-3) * 2.0  # x2: unmodelled attitude error
        g = np.vstack([0.5 * dt * dt * i3, dt * i3, z3])
        q = sa ** 2 * (g @ g.T)
        q[6:, 6:] = (self._accel_bias_walk ** 2) * dt * i3
        kf.Q = q

    # ------------------------------------------------------------------ attitude
    def add_gyro(self, gyro, dt: float) -> None:
        """Physics-rate gyro sample: sets the rate estimate and accumulates the delta angle (PX4-style
        IMU integration); the attitude itself is propagated by :meth:`propagate` when it is needed."""
        b = self.gyro_bias
        wx, wy, wz = gyro[0] - b[0], gyro[1] - b[1], gyro[2] - b[2]
        self.omega = (wx, wy, wz)
        da = self._dangle
        da[0] += wx * dt
        da[1] += wy * dt
        da[2] += wz * dt

    def propagate(self) -> None:
        """Rotate the attitude estimate by the accumulated delta angle (exact exponential map)."""
        self.q = self.attitude_now()
        da = self._dangle
        da[0] = da[1] = da[2] = 0.0

    def attitude_now(self) -> tuple[float, float, float, float]:
        """The attitude with the accumulated delta angle applied, the estimator left as it is.  Reading the
        estimate (telemetry, a heartbeat) must not regroup the gyro integration: when it did, a lockstep flight
        depended on when the wall clock sent a ground station's heartbeat (measured: the same hard-world
        flight twice, its attitude 5e-8 rad apart after 32 s, then different frames)."""
        da = self._dangle
        if da[0] == 0.0 and da[1] == 0.0 and da[2] == 0.0:
            return self.q
        return _rotated(self.q, da)

    def integrate_gyro(self, gyro, dt: float) -> None:
        """Gyro sample + immediate attitude propagation."""
        self.add_gyro(gyro, dt)
        self.propagate()

    def correct_attitude(self, q_meas, dt_meas: float) -> None:
        """Complementary correction towards a measured attitude (Mahony-style, with gyro-bias learning)."""
        self.propagate()
        e = qmul(qconj(self.q), q_meas)
        if e[0] < 0.0:
            e = (-e[0], -e[1], -e[2], -e[3])
        ex, ey, ez = 2.0 * e[1], 2.0 * e[2], 2.0 * e[3]  # small-angle error, body frame (rad)
        k = self.att_gain
        qw, qx, qy, qz = qmul(self.q, (1.0, 0.5 * k * ex, 0.5 * k * ey, 0.5 * k * ez))
        n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self.q = (qw * n, qx * n, qy * n, qz * n)
        kb = self.gyro_bias_gain * dt_meas
        b = self.gyro_bias
        self.gyro_bias = (b[0] - kb * ex, b[1] - kb * ey, b[2] - kb * ez)

    # ------------------------------------------------------------------ position / velocity
    def predict(self, accel_body) -> None:
        """KF prediction over one estimator interval with the mean body specific force (m/s^2)."""
        self.propagate()
        f = qrotate(self.q, accel_body)
        u = self._u
        u[0] = f[0]
        u[1] = f[1]
        u[2] = f[2] + GRAVITY
        self.kf.predict(u=u)
        self._publish(u)

    def update_position(self, p_meas) -> None:
        z = self._z
        z[0], z[1], z[2] = p_meas
        self.kf.update(z)
        self._publish(self._u)

    def _publish(self, u) -> None:
        x = self.kf.x.tolist()
        self.position = (x[0], x[1], x[2])
        self.velocity = (x[3], x[4], x[5])
        self.acceleration = (float(u[0]) - x[6], float(u[1]) - x[7], float(u[2]) - x[8])

    @property
    def accel_bias(self) -> tuple[float, float, float]:
        x = self.kf.x
        return float(x[6]), float(x[7]), float(x[8])
