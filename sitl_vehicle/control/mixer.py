"""Control allocation for a quad X with PX4's sequential desaturation, airmode disabled.

Priorities (PX4 ``ControlAllocationSequentialDesaturation::mixAirmodeDisabled``):

1. mix collective thrust + roll + pitch;
2. desaturate with the thrust direction, but only by *reducing* thrust (never add thrust to unsaturate);
3. desaturate with the roll direction, then the pitch direction (they give way next);
4. add yaw, desaturate with the yaw direction only (yaw gives way first of the torques), then once more
   reduce thrust only; clip to [0, 1].

Inputs are physical (collective thrust N, body torques N*m), outputs normalised motor commands.
``saturation_positive/negative`` per torque axis tell the rate controller where to freeze its integrator.
"""

from __future__ import annotations

import numpy as np

from sitl_vehicle.airframes import Airframe


def _desat_gain(vec, u, lo: float = 0.0, hi: float = 1.0) -> float:
    """PX4 computeDesaturationGain: the shift along ``vec`` that removes as much saturation as possible."""
    k_min = 0.0
    k_max = 0.0
    for d, x in zip(vec, u, strict=False):
        if abs(d) < 0.2:
            continue
        if x < lo:
            k = (lo - x) / d
            if k < k_min:
                k_min = k
            if k > k_max:
                k_max = k
        if x > hi:
            k = (hi - x) / d
            if k < k_min:
                k_min = k
            if k > k_max:
                k_max = k
    return k_min + k_max


def _desaturate(u: list[float], vec, reduce_only: bool = False) -> None:
    """Shift ``u`` along ``vec`` in place (twice, the second time by half, as PX4's ``desaturateActuators``).

    ``reduce_only`` refuses a first shift that would raise ``u`` along ``vec`` (airmode disabled: thrust is
    never added to unsaturate). The second, half shift always runs, as in PX4: when motors are saturated at
    both ends, the first shift (``k_min + k_max``) overshoots and the half shift back centres the excess
    between the bounds, so the net change is half the first shift (still a reduction, never an increase).
    Skipping it would take the whole first shift off the thrust: with a large roll+pitch demand that is all
    of it, and the roll/pitch desaturation that follows then zeroes every motor (no thrust, no torque).
    """
    k = _desat_gain(vec, u)
    if reduce_only and k > 0.0:
        return
    for i in range(4):
        u[i] += k * vec[i]
    k = 0.5 * _desat_gain(vec, u)
    for i in range(4):
        u[i] += k * vec[i]


class Mixer:
    """Quad-X allocator built from an :class:`Airframe` (inverse of its effectiveness matrix)."""

    def __init__(self, airframe: Airframe):
        tmax, km = airframe.thrust_max_n, airframe.torque_coeff_m
        geom = airframe.rotor_geometry()
        # effectiveness: [F, tx, ty, tz] = B @ u, u = normalised motor command
        b = np.array([[tmax] * 4,
                      [-ry * tmax for _, ry, _ in geom],
                      [rx * tmax for rx, _, _ in geom],
                      [s * km * tmax for _, _, s in geom]], dtype=float)
        mix = np.linalg.inv(b)
        self._b = [tuple(float(v) for v in row) for row in b]
        self._mix = [tuple(float(v) for v in mix[:, j]) for j in range(4)]  # columns: thrust, roll, pitch, yaw
        self._dirs = [tuple(float(v) / float(np.max(np.abs(mix[:, j]))) for v in mix[:, j]) for j in range(4)]
        self.saturation_positive = (False, False, False)
        self.saturation_negative = (False, False, False)

    def effectiveness(self, u) -> tuple[float, float, float, float]:
        """Collective thrust (N) and torques (N*m) produced by motor commands ``u``."""
        return tuple(sum(r * x for r, x in zip(row, u, strict=False)) for row in self._b)

    def mix(self, thrust_n: float, torque) -> list[float]:
        """Motor commands in [0, 1] for collective thrust (N) and body torques (N*m)."""
        mt, mr, mp, my = self._mix
        tx, ty, tz = torque
        u0 = mt[0] * thrust_n + mr[0] * tx + mp[0] * ty
        u1 = mt[1] * thrust_n + mr[1] * tx + mp[1] * ty
        u2 = mt[2] * thrust_n + mr[2] * tx + mp[2] * ty
        u3 = mt[3] * thrust_n + mr[3] * tx + mp[3] * ty
        y0, y1, y2, y3 = u0 + my[0] * tz, u1 + my[1] * tz, u2 + my[2] * tz, u3 + my[3] * tz
        if (0.0 <= y0 <= 1.0 and 0.0 <= y1 <= 1.0 and 0.0 <= y2 <= 1.0 and 0.0 <= y3 <= 1.0):
            # nothing saturates: every desaturation gain below would be zero
            self.saturation_positive = self.saturation_negative = (False, False, False)
            return [y0, y1, y2, y3]
        u = [u0, u1, u2, u3]
        dt_, dr, dp, dy = self._dirs
        _desaturate(u, dt_, reduce_only=True)
        _desaturate(u, dr)
        _desaturate(u, dp)
        for i in range(4):
            u[i] += my[i] * tz
        _desaturate(u, dy)
        _desaturate(u, dt_, reduce_only=True)
        u = [0.0 if x < 0.0 else (1.0 if x > 1.0 else x) for x in u]
        # saturation flags: compare produced with requested torque
        b = self._b
        pos = []
        neg = []
        for ax, req in ((1, tx), (2, ty), (3, tz)):
            row = b[ax]
            got = row[0] * u[0] + row[1] * u[1] + row[2] * u[2] + row[3] * u[3]
            tol = 1e-6 + 1e-3 * abs(req)
            pos.append(got < req - tol)
            neg.append(got > req + tol)
        self.saturation_positive = (pos[0], pos[1], pos[2])
        self.saturation_negative = (neg[0], neg[1], neg[2])
        return u
