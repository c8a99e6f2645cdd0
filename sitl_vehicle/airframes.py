"""Airframes as data: frozen dataclasses with a unit on every field.

Geometry follows PX4's ``quad_x`` (FRD body frame, rotor numbering as in PX4's
``CA_ROTOR*`` parameters)::

        3 (CW)   1 (CCW)        x forward
             \\ /               y right
             / \\               z down
        2 (CCW)  4 (CW)

Rotor ``i`` at body position ``(x_i, y_i, 0)`` makes thrust ``T_i`` along body ``-z``; it
contributes roll torque ``-y_i*T_i``, pitch torque ``x_i*T_i`` and yaw torque
``+k_m*T_i`` for counter-clockwise rotors (the reaction torque turns the body clockwise
seen from above, i.e. positive yaw in FRD) and ``-k_m*T_i`` for clockwise ones.

Motor model: each motor has a normalised command ``u_i`` in [0, 1] and a normalised state
``m_i`` that follows it with a first-order lag ``dm/dt = (u - m)/tau``; rotor thrust is
``T_i = thrust_max_n * m_i`` (thrust linear in the command, i.e. PX4's THR_MDL_FAC = 0)
and rotor drag torque is ``k_m * T_i``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

GRAVITY = 9.80665  # m/s^2, standard gravity (NED +z)


@dataclass(frozen=True)
class Airframe:
    name: str  # -, identifier used on the command line
    mass_kg: float  # kg, total take-off mass
    inertia_kgm2: tuple[float, float, float]  # kg*m^2, principal moments (Ixx, Iyy, Izz) in FRD
    arm_length_m: float  # m, distance from the centre of mass to each rotor axis (X layout, 45 deg)
    thrust_max_n: float  # N, thrust of one rotor at full command (u = 1)
    torque_coeff_m: float  # m, rotor drag torque per unit thrust (k_m: Q = k_m * T)
    motor_tau_s: float  # s, first-order motor time constant
    drag_coeff_ns_per_m: tuple[float, float, float]  # N*s/m, linear drag (x, y, z) in the world frame
    body_radius_m: float  # m, radius of the collision sphere around the centre (props included)
    idle_command: float  # -, normalised motor command when armed and idle on the ground (0..1)

    @property
    def hover_thrust(self) -> float:
        """Normalised collective thrust (0..1 per motor) that balances gravity."""
        return self.mass_kg * GRAVITY / (4.0 * self.thrust_max_n)

    @property
    def thrust_to_weight(self) -> float:
        """Total maximum thrust divided by weight (-)."""
        return 4.0 * self.thrust_max_n / (self.mass_kg * GRAVITY)

    def rotor_geometry(self) -> tuple[tuple[float, float, float], ...]:
        """Per rotor ``(x_m, y_m, yaw_sign)`` in PX4 quad_x order (yaw_sign +1 = CCW rotor)."""
        d = self.arm_length_m * math.sqrt(0.5)
        return ((d, d, 1.0), (-d, -d, 1.0), (d, -d, -1.0), (-d, d, -1.0))


QUAD250 = Airframe(
    name="quad250",
    mass_kg=1.0,
    inertia_kgm2=(0.0065, 0.0065, 0.012),
    arm_length_m=0.125,
    thrust_max_n=2.0 * 1.0 * GRAVITY / 4.0,  # thrust-to-weight 2.0
    torque_coeff_m=0.016,
    motor_tau_s=0.03,
    drag_coeff_ns_per_m=(0.15, 0.15, 0.25),
    body_radius_m=0.19,
    idle_command=0.05,
)

TELLO = Airframe(
    name="tello",
    mass_kg=0.080,
    inertia_kgm2=(9.0e-5, 9.0e-5, 1.6e-4),
    arm_length_m=0.0475,
    thrust_max_n=2.0 * 0.080 * GRAVITY / 4.0,  # thrust-to-weight 2.0
    torque_coeff_m=0.006,
    motor_tau_s=0.02,
    drag_coeff_ns_per_m=(0.02, 0.02, 0.03),
    body_radius_m=0.09,
    idle_command=0.05,
)

AIRFRAMES: dict[str, Airframe] = {a.name: a for a in (QUAD250, TELLO)}
