"""Rigid-body + motor dynamics: analytic checks on plain-float RK4."""

import math

import pytest

from sitl_vehicle.airframes import AIRFRAMES, GRAVITY, QUAD250, TELLO
from sitl_vehicle.control.qmath import qrotate, quat_from_euler
from sitl_vehicle.dynamics import QuadDynamics

DT = 0.002


def test_airframes_have_expected_mass_and_thrust_to_weight():
    assert abs(QUAD250.mass_kg - 1.0) < 0.2 and abs(QUAD250.thrust_to_weight - 2.0) < 0.2
    assert abs(TELLO.mass_kg - 0.080) < 1e-9 and 1.5 < TELLO.thrust_to_weight < 2.5
    assert set(AIRFRAMES) >= {"quad250", "tello"}


def test_free_fall_with_linear_drag_matches_closed_form():
    d = QuadDynamics(QUAD250, DT, position=(0.0, 0.0, -100.0))
    k = QUAD250.drag_coeff_ns_per_m[2] / QUAD250.mass_kg
    n = 500
    for _ in range(n):
        d.step((0.0, 0.0, 0.0, 0.0))
    t = n * DT
    vz = GRAVITY / k * (1.0 - math.exp(-k * t))
    z = -100.0 + GRAVITY / k * t - GRAVITY / k ** 2 * (1.0 - math.exp(-k * t))
    assert abs(d.velocity[2] - vz) < 1e-9
    assert abs(d.position[2] - z) < 1e-9


def test_motor_lag_time_constant_is_visible_in_a_step():
    d = QuadDynamics(QUAD250, DT)
    tau = QUAD250.motor_tau_s
    n = int(round(tau / DT))
    for _ in range(n):
        d.step((0.8, 0.8, 0.8, 0.8))
    # first-order lag: 63.2 % of the step after one time constant
    assert all(abs(m - 0.8 * (1.0 - math.exp(-1.0))) < 1e-12 for m in d.motor)
    # and the thrust lags accordingly (mean over the last step, slightly below the end value)
    assert 0.55 * 0.8 * 4 * QUAD250.thrust_max_n < d.thrust_n < 0.64 * 0.8 * 4 * QUAD250.thrust_max_n


def test_hover_command_is_an_equilibrium():
    d = QuadDynamics(QUAD250, DT, position=(0.0, 0.0, -2.0))
    h = QUAD250.hover_thrust
    d.motor = [h, h, h, h]
    for _ in range(1000):
        d.step((h, h, h, h))
    assert max(abs(c) for c in d.velocity) < 1e-9
    assert abs(d.position[2] + 2.0) < 1e-9


@pytest.mark.parametrize(
    "motor,expect",
    [
        (0, (-1, +1, +1)),  # front-right CCW: roll left (-), pitch up (+), yaw right (+)
        (1, (+1, -1, +1)),  # rear-left CCW
        (2, (+1, +1, -1)),  # front-left CW
        (3, (-1, -1, -1)),  # rear-right CW
    ],
)
def test_rotor_torque_signs_follow_px4_quad_x(motor, expect):
    d = QuadDynamics(QUAD250, DT)
    u = [0.5] * 4
    u[motor] = 0.7
    f, tx, ty, tz = d.forces(u)
    assert (math.copysign(1, tx), math.copysign(1, ty), math.copysign(1, tz)) == expect
    # the fast path used inside step() agrees
    assert d._forces4(*u) == pytest.approx((f, tx, ty, tz), abs=1e-12)


def test_torque_free_spin_keeps_unit_quaternion_and_angular_momentum():
    d = QuadDynamics(QUAD250, DT, position=(0.0, 0.0, -1000.0))
    d.x[10:13] = [1.0, 0.5, 2.0]
    ixx, iyy, izz = QUAD250.inertia_kgm2

    def momentum_world():
        w = d.angular_velocity
        return qrotate(d.attitude, (ixx * w[0], iyy * w[1], izz * w[2]))

    h0 = momentum_world()
    for _ in range(2000):
        d.step((0.0, 0.0, 0.0, 0.0))
    q = d.attitude
    assert abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-12
    h1 = momentum_world()
    assert max(abs(a - b) for a, b in zip(h0, h1, strict=True)) < 1e-6


def test_ground_holds_vehicle_no_sinking_no_sliding():
    d = QuadDynamics(QUAD250, DT)
    d.x[3] = 3.0  # sliding north on the ground
    idle = QUAD250.idle_command
    for _ in range(100):
        d.step((idle,) * 4)
        assert d.position[2] == 0.0
    assert d.velocity == (0.0, 0.0, 0.0) and d.on_ground
    assert abs(d.position[0]) < 3.0 * DT + 1e-12  # stopped within the first step


def test_ground_levels_a_tilted_touchdown_and_keeps_heading():
    q = quat_from_euler(0.2, -0.1, 1.0)
    d = QuadDynamics(QUAD250, DT, position=(0.0, 0.0, -0.001))
    d.x[6:10] = list(q)
    d.x[5] = 1.0
    d.step((0.0,) * 4)
    assert d.on_ground and d.touchdown and d.touchdown_speed_mps > 0.99
    w, x, y, z = d.attitude
    assert x == 0.0 and y == 0.0
    assert abs(2.0 * math.atan2(z, w) - 1.0) < 1e-9


def test_enough_thrust_lifts_off():
    d = QuadDynamics(QUAD250, DT)
    d.motor = [0.7] * 4
    for _ in range(50):
        d.step((0.7,) * 4)
    assert not d.on_ground and d.position[2] < 0.0 and d.velocity[2] < 0.0


def _reference_rhs(af):
    """Slow, independent twin of the dynamics (numpy, motor states inside the ODE) for solve_ivp."""
    import numpy as np

    geom = af.rotor_geometry()
    inertia = np.array(af.inertia_kgm2)
    drag = np.array(af.drag_coeff_ns_per_m)

    def rhs(_t, y, u):
        v, q, w, m = y[3:6], y[6:10], y[10:13], y[13:17]
        thrusts = af.thrust_max_n * m
        torque = np.zeros(3)
        for (rx, ry, s), t in zip(geom, thrusts, strict=True):
            torque += np.cross([rx, ry, 0.0], [0.0, 0.0, -t]) + [0.0, 0.0, s * af.torque_coeff_m * t]
        qw, qx, qy, qz = q
        rot = np.array([
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
            [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
            [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)],
        ])
        acc = np.array([0.0, 0.0, GRAVITY]) + rot @ [0.0, 0.0, -thrusts.sum() / af.mass_kg] - drag * v / af.mass_kg
        omega_q = np.array([0.0, *w])
        qdot = 0.5 * np.array([
            qw * omega_q[0] - qx * omega_q[1] - qy * omega_q[2] - qz * omega_q[3],
            qw * omega_q[1] + qx * omega_q[0] + qy * omega_q[3] - qz * omega_q[2],
            qw * omega_q[2] - qx * omega_q[3] + qy * omega_q[0] + qz * omega_q[1],
            qw * omega_q[3] + qx * omega_q[2] - qy * omega_q[1] + qz * omega_q[0],
        ])
        wdot = (torque - np.cross(w, inertia * w)) / inertia
        mdot = (np.asarray(u) - m) / af.motor_tau_s
        return np.concatenate([v, acc, qdot, wdot, mdot])

    return rhs


@pytest.mark.parametrize("airframe", [QUAD250, TELLO])
def test_rk4_matches_a_slow_reference_twin(airframe):
    """Fast float RK4 (exact motor lag, mean rotor force per step) vs scipy on the full 17-state ODE."""
    import numpy as np
    from scipy.integrate import solve_ivp

    d = QuadDynamics(airframe, DT, position=(0.0, 0.0, -50.0), yaw=0.3)
    d.x[10:13] = [0.4, -0.3, 0.2]
    h = airframe.hover_thrust
    d.motor = [h] * 4
    y = np.array(d.x + d.motor)
    rhs = _reference_rhs(airframe)
    commands = [(h + 0.02, h - 0.01, h, h + 0.01), (h - 0.02, h + 0.03, h + 0.01, h - 0.01)]  # 2nd: net yaw
    for u in commands:  # two 0.25 s segments with different constant commands
        for _ in range(125):
            d.step(u)
        y = solve_ivp(rhs, (0.0, 0.25), y, args=(u,), rtol=1e-10, atol=1e-12).y[:, -1]
    assert np.allclose(d.x[:6], y[:6], atol=1e-5)
    assert np.allclose(d.x[6:10], y[6:10] / np.linalg.norm(y[6:10]), atol=1e-5)
    assert np.allclose(d.x[10:13], y[10:13], atol=1e-4)
    assert np.allclose(d.motor, y[13:17], atol=1e-12)
