"""Rigid-body quadrotor dynamics on plain Python floats (pure: no clock, no I/O).

State ``X = [p, v, q, w]`` (13 floats): NED position (m), NED velocity (m/s), attitude quaternion
(w, x, y, z) body(FRD) -> world(NED), body angular velocity (rad/s, FRD). Four motor states
(normalised 0..1, see :mod:`sitl_vehicle.airframes`) follow their commands with a first-order lag.

Integration: one fixed step ``dt`` of classical RK4 for ``[p, v, q, w]``. The motor lag is
integrated exactly (``m += (u - m)(1 - e^{-dt/tau})``) and the rotor forces are held at their exact
mean over the step while the rigid body is integrated, so the RK4 stages share one force/torque
evaluation. The quaternion is renormalised after every step.

Forces: gravity ``+g`` on NED z, rotor thrust along body ``-z``, linear drag ``-c * (v - wind)`` (world axes;
``wind`` is the air's NED velocity, zero unless set, see :mod:`sitl_vehicle.wind`).

Ground contact (ground is the plane z = 0, flying is z < 0): the vehicle centre never goes below
z = 0. While in contact and the thrust cannot lift it (``g - T*R33/m >= 0``) the ground holds it:
velocity and angular velocity are zeroed (static friction, no sliding, no tipping) and the attitude
is levelled keeping the heading. ``touchdown_speed_mps`` records the downward speed at the instant of
each new contact (the collision monitor turns a hard one into a crash).
"""

from __future__ import annotations

import math

from sitl_vehicle.airframes import GRAVITY, Airframe

__all__ = ["QuadDynamics"]


class QuadDynamics:
    """Quadrotor rigid body + motors, stepped with fixed-step RK4 at ``1/dt``."""

    def __init__(self, airframe: Airframe, dt: float, position=(0.0, 0.0, 0.0), yaw: float = 0.0):
        self.airframe = airframe
        self.dt = float(dt)
        self._mass = airframe.mass_kg
        self._inv_mass = 1.0 / airframe.mass_kg
        ixx, iyy, izz = airframe.inertia_kgm2
        self._ixx, self._iyy, self._izz = ixx, iyy, izz
        self._kx = (izz - iyy) / ixx
        self._ky = (ixx - izz) / iyy
        self._kz = (iyy - ixx) / izz
        self._drag = tuple(c / airframe.mass_kg for c in airframe.drag_coeff_ns_per_m)
        self._tmax = airframe.thrust_max_n
        self._km = airframe.torque_coeff_m
        self._geom = airframe.rotor_geometry()
        tau = airframe.motor_tau_s
        self._lag_decay = math.exp(-self.dt / tau)  # m_new - u = (m - u) * decay
        self._lag_mean = tau / self.dt * (1.0 - self._lag_decay)  # mean of (m - u) over the step / (m0 - u)
        self.reset(position, yaw)

    # ------------------------------------------------------------------ state
    def reset(self, position=(0.0, 0.0, 0.0), yaw: float = 0.0) -> None:
        px, py, pz = (float(c) for c in position)
        pz = min(pz, 0.0)
        h = 0.5 * float(yaw)
        self.x = [px, py, pz, 0.0, 0.0, 0.0, math.cos(h), 0.0, 0.0, math.sin(h), 0.0, 0.0, 0.0]
        self.motor = [0.0, 0.0, 0.0, 0.0]
        self.on_ground = pz >= 0.0
        self.touchdown_speed_mps = 0.0
        self.wind = (0.0, 0.0, 0.0)
        self.touchdown = False  # True in the step where a new ground contact began
        self.thrust_n = 0.0
        self.torque_nm = (0.0, 0.0, 0.0)
        self.accel_world = (0.0, 0.0, 0.0)  # m/s^2, mean NED acceleration over the last step

    @property
    def position(self) -> tuple[float, float, float]:
        x = self.x
        return (x[0], x[1], x[2])

    @property
    def velocity(self) -> tuple[float, float, float]:
        x = self.x
        return (x[3], x[4], x[5])

    @property
    def attitude(self) -> tuple[float, float, float, float]:
        x = self.x
        return (x[6], x[7], x[8], x[9])

    @property
    def angular_velocity(self) -> tuple[float, float, float]:
        x = self.x
        return (x[10], x[11], x[12])

    # ------------------------------------------------------------------ physics
    def forces(self, motor_mean) -> tuple[float, float, float, float]:
        """Collective thrust (N) and body torques (N*m) for normalised motor states."""
        tmax = self._tmax
        km = self._km
        f = tx = ty = tz = 0.0
        for (rx, ry, ys), m in zip(self._geom, motor_mean, strict=False):
            t = tmax * m
            f += t
            tx -= ry * t
            ty += rx * t
            tz += ys * km * t
        return f, tx, ty, tz

    def _forces4(self, a0: float, a1: float, a2: float, a3: float) -> tuple[float, float, float, float]:
        # quad_x rotors 1..4 at (d, d), (-d, -d), (d, -d), (-d, d); CCW, CCW, CW, CW
        tm = self._tmax
        t0, t1, t2, t3 = tm * a0, tm * a1, tm * a2, tm * a3
        dx = self._geom[0][0]
        km = self._km
        return (t0 + t1 + t2 + t3, dx * (-t0 + t1 + t2 - t3), dx * (t0 - t1 + t2 - t3), km * (t0 + t1 - t2 - t3))

    def step(self, command) -> None:
        """Advance one step ``dt`` with normalised motor commands ``command`` (4 floats, clipped 0..1)."""
        dt = self.dt
        self.touchdown = False
        decay = self._lag_decay
        mean = self._lag_mean
        mot = self.motor
        u0, u1, u2, u3 = command
        u0 = 0.0 if u0 < 0.0 else (1.0 if u0 > 1.0 else u0)
        u1 = 0.0 if u1 < 0.0 else (1.0 if u1 > 1.0 else u1)
        u2 = 0.0 if u2 < 0.0 else (1.0 if u2 > 1.0 else u2)
        u3 = 0.0 if u3 < 0.0 else (1.0 if u3 > 1.0 else u3)
        m0, m1, m2, m3 = mot
        # exact mean thrust of each motor over the step, then exact end state
        a0 = u0 + (m0 - u0) * mean
        a1 = u1 + (m1 - u1) * mean
        a2 = u2 + (m2 - u2) * mean
        a3 = u3 + (m3 - u3) * mean
        self.motor = [u0 + (m0 - u0) * decay, u1 + (m1 - u1) * decay,
                      u2 + (m2 - u2) * decay, u3 + (m3 - u3) * decay]
        f, tx, ty, tz = self._forces4(a0, a1, a2, a3)
        self.thrust_n = f
        self.torque_nm = (tx, ty, tz)

        fm = f * self._inv_mass
        cx, cy, cz = self._drag
        ixx, iyy, izz = self._ixx, self._iyy, self._izz
        kx, ky, kz = self._kx, self._ky, self._kz
        ax_t, ay_t, az_t = tx / ixx, ty / iyy, tz / izz
        g = GRAVITY

        px, py, pz, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz = self.x
        ax, ay, az = self.wind

        def deriv(vx, vy, vz, qw, qx, qy, qz, wx, wy, wz):
            r13 = 2.0 * (qx * qz + qw * qy)
            r23 = 2.0 * (qy * qz - qw * qx)
            r33 = 1.0 - 2.0 * (qx * qx + qy * qy)
            return (
                -fm * r13 - cx * (vx - ax),
                -fm * r23 - cy * (vy - ay),
                g - fm * r33 - cz * (vz - az),
                0.5 * (-qx * wx - qy * wy - qz * wz),
                0.5 * (qw * wx + qy * wz - qz * wy),
                0.5 * (qw * wy - qx * wz + qz * wx),
                0.5 * (qw * wz + qx * wy - qy * wx),
                ax_t - kx * wy * wz,
                ay_t - ky * wz * wx,
                az_t - kz * wx * wy,
            )

        h2 = 0.5 * dt
        k1 = deriv(vx, vy, vz, qw, qx, qy, qz, wx, wy, wz)
        v2x, v2y, v2z = vx + h2 * k1[0], vy + h2 * k1[1], vz + h2 * k1[2]
        k2 = deriv(v2x, v2y, v2z,
                   qw + h2 * k1[3], qx + h2 * k1[4], qy + h2 * k1[5], qz + h2 * k1[6],
                   wx + h2 * k1[7], wy + h2 * k1[8], wz + h2 * k1[9])
        v3x, v3y, v3z = vx + h2 * k2[0], vy + h2 * k2[1], vz + h2 * k2[2]
        k3 = deriv(v3x, v3y, v3z,
                   qw + h2 * k2[3], qx + h2 * k2[4], qy + h2 * k2[5], qz + h2 * k2[6],
                   wx + h2 * k2[7], wy + h2 * k2[8], wz + h2 * k2[9])
        v4x, v4y, v4z = vx + dt * k3[0], vy + dt * k3[1], vz + dt * k3[2]
        k4 = deriv(v4x, v4y, v4z,
                   qw + dt * k3[3], qx + dt * k3[4], qy + dt * k3[5], qz + dt * k3[6],
                   wx + dt * k3[7], wy + dt * k3[8], wz + dt * k3[9])
        s = dt / 6.0
        npx = px + s * (vx + 2.0 * (v2x + v3x) + v4x)
        npy = py + s * (vy + 2.0 * (v2y + v3y) + v4y)
        npz = pz + s * (vz + 2.0 * (v2z + v3z) + v4z)
        nvx = vx + s * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0])
        nvy = vy + s * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1])
        nvz = vz + s * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2])
        nqw = qw + s * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3])
        nqx = qx + s * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4])
        nqy = qy + s * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5])
        nqz = qz + s * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6])
        nwx = wx + s * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7])
        nwy = wy + s * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8])
        nwz = wz + s * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9])
        n = 1.0 / math.sqrt(nqw * nqw + nqx * nqx + nqy * nqy + nqz * nqz)
        nqw *= n
        nqx *= n
        nqy *= n
        nqz *= n

        if npz >= 0.0:
            npz = 0.0
            if not self.on_ground:
                self.touchdown_speed_mps = max(nvz, 0.0)
                self.touchdown = True
            r33 = 1.0 - 2.0 * (nqx * nqx + nqy * nqy)
            if g - fm * r33 >= 0.0:
                # held by the ground: no sliding, no tipping, level with the heading kept
                nvx = nvy = nvz = 0.0
                nwx = nwy = nwz = 0.0
                yaw = math.atan2(2.0 * (nqw * nqz + nqx * nqy), 1.0 - 2.0 * (nqy * nqy + nqz * nqz))
                nqw, nqx, nqy, nqz = math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)
                self.on_ground = True
            else:
                if nvz > 0.0:
                    nvz = 0.0
                self.on_ground = False
        else:
            self.on_ground = False

        inv_dt = 1.0 / dt
        self.accel_world = ((nvx - vx) * inv_dt, (nvy - vy) * inv_dt, (nvz - vz) * inv_dt)
        self.x = [npx, npy, npz, nvx, nvy, nvz, nqw, nqx, nqy, nqz, nwx, nwy, nwz]
