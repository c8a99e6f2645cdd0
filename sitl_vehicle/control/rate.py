"""Body-rate PID (the shape of PX4's ``RateControl``), output in angular acceleration (rad/s^2).

``alpha = P*e + I - D*d(omega)/dt + FF*omega_sp`` per axis, D on the measurement through a first-order
low-pass (PX4's D-term filter), integrator clamped to ``int_lim`` and frozen on an axis while the
mixer reports that axis saturated in the direction the integrator would grow (PX4's
``setSaturationStatus``). Torque = inertia * alpha is formed by the caller.
"""

from __future__ import annotations

import math


class RateControl:
    def __init__(self, p=(20.0, 20.0, 10.0), i=(10.0, 10.0, 5.0), d=(0.2, 0.2, 0.0), ff=(0.0, 0.0, 0.0),
                 int_lim=(30.0, 30.0, 10.0), d_lpf_hz: float = 40.0, dt: float = 0.002):
        self.set_gains(p, i, d, ff, int_lim)
        self._dt = dt
        self.set_d_lpf(d_lpf_hz, dt)
        self.reset()

    def set_gains(self, p, i, d, ff=(0.0, 0.0, 0.0), int_lim=(30.0, 30.0, 10.0)) -> None:
        self._p, self._i, self._d, self._ff, self._lim = tuple(p), tuple(i), tuple(d), tuple(ff), tuple(int_lim)

    def set_d_lpf(self, cutoff_hz: float, dt: float) -> None:
        self._dt = dt
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt) if cutoff_hz > 0.0 else 1.0

    def reset(self) -> None:
        self._int = [0.0, 0.0, 0.0]
        self._prev = None
        self._dfilt = [0.0, 0.0, 0.0]
        self._sat_pos = (False, False, False)
        self._sat_neg = (False, False, False)

    def reset_integral(self) -> None:
        self._int = [0.0, 0.0, 0.0]

    def set_saturation_status(self, positive, negative) -> None:
        """Per axis: True where the allocator could not deliver more positive/negative torque."""
        self._sat_pos, self._sat_neg = tuple(positive), tuple(negative)

    @property
    def integral(self) -> tuple[float, float, float]:
        return tuple(self._int)

    def update(self, rate, rate_sp, update_integral: bool = True) -> tuple[float, float, float]:
        dt = self._dt
        prev = self._prev
        self._prev = rate
        df = self._dfilt
        a = self._alpha
        if prev is not None:
            inv = 1.0 / dt
            df[0] += a * ((rate[0] - prev[0]) * inv - df[0])
            df[1] += a * ((rate[1] - prev[1]) * inv - df[1])
            df[2] += a * ((rate[2] - prev[2]) * inv - df[2])
        p, ki, d, ff = self._p, self._i, self._d, self._ff
        it = self._int
        e0 = rate_sp[0] - rate[0]
        e1 = rate_sp[1] - rate[1]
        e2 = rate_sp[2] - rate[2]
        out = (p[0] * e0 + it[0] - d[0] * df[0] + ff[0] * rate_sp[0],
               p[1] * e1 + it[1] - d[1] * df[1] + ff[1] * rate_sp[1],
               p[2] * e2 + it[2] - d[2] * df[2] + ff[2] * rate_sp[2])
        if update_integral:
            lim = self._lim
            sp, sn = self._sat_pos, self._sat_neg
            if not ((e0 > 0.0 and sp[0]) or (e0 < 0.0 and sn[0])):
                v = it[0] + ki[0] * e0 * dt
                it[0] = -lim[0] if v < -lim[0] else (lim[0] if v > lim[0] else v)
            if not ((e1 > 0.0 and sp[1]) or (e1 < 0.0 and sn[1])):
                v = it[1] + ki[1] * e1 * dt
                it[1] = -lim[1] if v < -lim[1] else (lim[1] if v > lim[1] else v)
            if not ((e2 > 0.0 and sp[2]) or (e2 < 0.0 and sn[2])):
                v = it[2] + ki[2] * e2 * dt
                it[2] = -lim[2] if v < -lim[2] else (lim[2] if v > lim[2] else v)
        return out
