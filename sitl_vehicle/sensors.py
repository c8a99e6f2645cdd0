"""Sensor noise models: IMU (gyro + accelerometer, white noise + constant turn-on bias) and an
external pose sensor (mocap-like position + attitude at ``pose_rate_hz``).

All randomness comes from the ``numpy.random.Generator`` passed in. Noise is drawn in blocks and
handed out as Python floats, so a per-step gyro sample costs a list index, not a NumPy call.

The accelerometer is read as PX4 EKF2 does, as an *average over the estimator interval*: the true mean
specific force over the interval is ``(v_end - v_start)/T - g`` (exact, from the velocity change) rotated
into the body frame; its white noise is the per-sample noise divided by ``sqrt(samples)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl_vehicle.airframes import GRAVITY
from sitl_vehicle.control.qmath import qmul, qnormalize, qrotate_inv


@dataclass(frozen=True)
class SensorNoise:
    gyro_noise_rad_s: float = 0.005  # rad/s, gyro white noise std of one sample (physics rate)
    gyro_bias_rad_s: float = 0.005  # rad/s, std of the constant gyro turn-on bias per axis
    accel_noise_m_s2: float = 0.08  # m/s^2, accelerometer white noise std of one sample (physics rate)
    accel_bias_m_s2: float = 0.05  # m/s^2, std of the constant accelerometer turn-on bias per axis
    pos_noise_m: float = 0.005  # m, position sensor noise std per axis (mocap-like; GPS would be ~0.5)
    att_noise_rad: float = 0.005  # rad, attitude sensor noise std per axis (small-angle)
    pose_rate_hz: float = 50.0  # Hz, position/attitude sensor rate


class NoiseBlock:
    """Standard-normal samples drawn in blocks from ``rng`` and served as floats."""

    def __init__(self, rng: np.random.Generator, block: int = 4096):
        self._rng = rng
        self._block = block
        self._buf: list[float] = []
        self._i = 0

    def next3(self) -> tuple[float, float, float]:
        i = self._i
        if i + 3 > len(self._buf):
            self._buf = self._rng.standard_normal(self._block).tolist()
            i = 0
        self._i = i + 3
        b = self._buf
        return b[i], b[i + 1], b[i + 2]


class Imu:
    """Gyro per physics step, accelerometer averaged per estimator interval."""

    def __init__(self, noise: SensorNoise, rng: np.random.Generator):
        self.noise = noise
        self._n = NoiseBlock(rng)
        self.gyro_bias = tuple(float(b) for b in rng.normal(0.0, noise.gyro_bias_rad_s, 3))
        self.accel_bias = tuple(float(b) for b in rng.normal(0.0, noise.accel_bias_m_s2, 3))

    def gyro(self, omega) -> tuple[float, float, float]:
        s = self.noise.gyro_noise_rad_s
        n = self._n.next3()
        b = self.gyro_bias
        return omega[0] + b[0] + s * n[0], omega[1] + b[1] + s * n[1], omega[2] + b[2] + s * n[2]

    def accel_mean(self, q_true, dv_world, interval_s: float, samples: int) -> tuple[float, float, float]:
        """Body-frame mean specific force (m/s^2) over an interval with NED velocity change ``dv_world``."""
        inv = 1.0 / interval_s
        f = qrotate_inv(q_true, (dv_world[0] * inv, dv_world[1] * inv, dv_world[2] * inv - GRAVITY))
        s = self.noise.accel_noise_m_s2 / math.sqrt(max(samples, 1))
        n = self._n.next3()
        b = self.accel_bias
        return f[0] + b[0] + s * n[0], f[1] + b[1] + s * n[1], f[2] + b[2] + s * n[2]


class PoseSensor:
    """Mocap/GPS-like position and attitude measurement with white noise."""

    def __init__(self, noise: SensorNoise, rng: np.random.Generator):
        self.noise = noise
        self._n = NoiseBlock(rng, 1024)

    def measure(self, position, q_true):
        sp, sa = self.noise.pos_noise_m, self.noise.att_noise_rad
        n = self._n.next3()
        p = (position[0] + sp * n[0], position[1] + sp * n[1], position[2] + sp * n[2])
        a = self._n.next3()
        dq = (1.0, 0.5 * sa * a[0], 0.5 * sa * a[1], 0.5 * sa * a[2])
        return p, qnormalize(qmul(q_true, dq))
