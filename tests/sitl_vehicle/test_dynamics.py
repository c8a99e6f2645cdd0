"""Rigid-body + motor dynamics: analytic checks on plain-float RK4."""

import math

import pytest

from sitl_vehicle.airframes import AIRFRAMES, GRAVITY, QUAD250, TELLO, Airframe
from sitl_vehicle.control.qmath import qrotate, quat_from_euler
from sitl_vehicle.dynamics import QuadDynamics

DT = 0.002
# every axis different (inertia, drag), so swapped axes show
ODD = Airframe(name="odd", mass_kg=0.8, inertia_kgm2=(0.005, 0.007, 0.011), arm_length_m=0.1, thrust_max_n=4.0,
               torque_coeff_m=0.02, motor_tau_s=0.025, drag_coeff_ns_per_m=(0.1, 0.2, 0.3), body_radius_m=0.15,
               idle_command=0.05)


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


@pytest.mark.parametrize("airframe", [QUAD250, TELLO, ODD])
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


# --- closed forms on an airframe whose every axis differs (so swapped axes show) -------------------------------




def reference_forces(af, motors):
    """Thrust and torque from r x F (F = -T z_body) plus the rotor drag torque (independent of the code)."""
    import numpy as np

    f, tau = 0.0, np.zeros(3)
    for (rx, ry, s), m in zip(af.rotor_geometry(), motors, strict=True):
        t = af.thrust_max_n * m
        f += t
        tau += np.cross([rx, ry, 0.0], [0.0, 0.0, -t]) + [0.0, 0.0, s * af.torque_coeff_m * t]
    return (f, *tau)


def test_reset_state():
    d = QuadDynamics(ODD, DT, position=(1, 2, -3), yaw=0.8)
    assert d.dt == DT and type(d.dt) is float and d.airframe is ODD
    assert d.touchdown is False
    assert d.position == (1.0, 2.0, -3.0) and d.velocity == (0.0, 0.0, 0.0) and d.angular_velocity == (0.0, 0.0, 0.0)
    assert d.attitude == pytest.approx((math.cos(0.4), 0.0, 0.0, math.sin(0.4)), abs=1e-15)
    assert d.motor == [0.0] * 4 and not d.on_ground and not d.touchdown and d.touchdown_speed_mps == 0.0
    assert d.wind == (0.0, 0.0, 0.0) and d.thrust_n == 0.0 and d.torque_nm == (0.0, 0.0, 0.0)
    assert d.accel_world == (0.0, 0.0, 0.0) and len(d.x) == 13
    d.reset((0.0, 0.0, 0.5))  # below the ground: put on it
    assert d.position == (0.0, 0.0, 0.0) and d.on_ground and d.attitude == (1.0, 0.0, 0.0, 0.0)
    d.reset((0.0, 0.0, 0.0))
    assert d.on_ground
    d = QuadDynamics(ODD, DT)
    assert d.position == (0.0, 0.0, 0.0) and d.on_ground and d.attitude == (1.0, 0.0, 0.0, 0.0)


def test_forces_match_r_cross_f_for_every_rotor():
    d = QuadDynamics(ODD, DT)
    for motors in ((0.1, 0.2, 0.3, 0.4), (0.9, 0.0, 0.0, 0.0), (0.0, 0.7, 0.0, 0.0), (0.0, 0.0, 0.5, 0.0),
                   (0.0, 0.0, 0.0, 0.6)):
        ref = reference_forces(ODD, motors)
        assert d.forces(motors) == pytest.approx(ref, abs=1e-12)
        assert d._forces4(*motors) == pytest.approx(ref, abs=1e-12)


def test_commands_are_clipped_and_the_motor_lag_is_exact():
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -10.0))
    d.step((-0.5, 1.5, 0.3, 0.8))
    decay = math.exp(-DT / ODD.motor_tau_s)
    u = (0.0, 1.0, 0.3, 0.8)
    assert d.motor == pytest.approx([c * (1.0 - decay) for c in u], abs=1e-15)
    # the rotor forces over the step are held at their exact mean: u (1 - tau/dt (1 - e^(-dt/tau))) from rest
    mean = [c * (1.0 - ODD.motor_tau_s / DT * (1.0 - decay)) for c in u]
    ref = reference_forces(ODD, mean)
    assert d.thrust_n == pytest.approx(ref[0], rel=1e-12) and d.torque_nm == pytest.approx(ref[1:], rel=1e-12)
    # from a running motor towards a lower command: the same law
    m0 = list(d.motor)
    d.step((0.2, 0.2, 0.2, 0.2))
    assert d.motor == pytest.approx([0.2 + (m - 0.2) * decay for m in m0], abs=1e-15)
    mean = [0.2 + (m - 0.2) * ODD.motor_tau_s / DT * (1.0 - decay) for m in m0]
    assert d.thrust_n == pytest.approx(reference_forces(ODD, mean)[0], rel=1e-12)
    m0 = list(d.motor)
    d.step((1.0000001, 7.0, -1e-9, 0.999))  # clipped to (1, 1, 0, 0.999)
    assert d.motor == pytest.approx([1.0 + (m0[0] - 1.0) * decay, 1.0 + (m0[1] - 1.0) * decay, m0[2] * decay,
                                     0.999 + (m0[3] - 0.999) * decay], abs=1e-15)
    # every motor clipped at both ends
    for cmd, clipped in (((0.5, -3.0, 1.5, -0.2), (0.5, 0.0, 1.0, 0.0)),
                         ((-1.0, 2.0, -0.1, 1.3), (0.0, 1.0, 0.0, 1.0))):
        m0 = list(d.motor)
        d.step(cmd)
        assert d.motor == pytest.approx([c + (m - c) * decay for c, m in zip(clipped, m0, strict=True)], abs=1e-15)


def test_constant_tilted_thrust_with_drag_and_wind_matches_closed_form():
    """No torque (equal motors), no spin: a constant force per axis against linear drag towards the wind,
    v(t) = w + (v0 - w) e^(-kt) + a/k (1 - e^(-kt)) per axis (k = c/m, a the thrust-plus-gravity acceleration)."""
    import numpy as np

    d = QuadDynamics(ODD, DT, position=(1.0, -2.0, -50.0))
    q = quat_from_euler(0.3, -0.2, 0.7)
    d.x[6:10] = list(q)
    d.x[3:6] = [0.5, -1.0, 0.2]
    d.wind = (1.5, -0.5, 0.25)
    u = 0.6
    d.motor = [u] * 4
    n = 400
    for _ in range(n):
        d.step((u,) * 4)
    t = n * DT
    fm = 4 * ODD.thrust_max_n * u / ODD.mass_kg
    acc = np.array(qrotate(q, (0.0, 0.0, -fm))) + (0.0, 0.0, GRAVITY)
    k = np.array(ODD.drag_coeff_ns_per_m) / ODD.mass_kg
    v0, w, p0 = np.array([0.5, -1.0, 0.2]), np.array([1.5, -0.5, 0.25]), np.array([1.0, -2.0, -50.0])
    e = np.exp(-k * t)
    v = w + (v0 - w) * e + acc / k * (1 - e)
    p = p0 + w * t + (v0 - w) / k * (1 - e) + acc / k * t - acc / k ** 2 * (1 - e)
    assert d.velocity == pytest.approx(tuple(v), abs=1e-9)
    assert d.position == pytest.approx(tuple(p), abs=1e-9)
    assert d.attitude == pytest.approx(q, abs=1e-12) and d.angular_velocity == (0.0, 0.0, 0.0)
    # the mean acceleration over the last step is the velocity change over it
    e1 = np.exp(-k * (t - DT))
    v_before = w + (v0 - w) * e1 + acc / k * (1 - e1)
    assert d.accel_world == pytest.approx(tuple((v - v_before) / DT), abs=1e-6)
    assert d.thrust_n == pytest.approx(4 * ODD.thrust_max_n * u, rel=1e-12) and d.torque_nm == pytest.approx(
        (0.0, 0.0, 0.0), abs=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_spin_about_a_principal_axis_is_an_exact_rotation(axis):
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -1000.0))
    w = [0.0, 0.0, 0.0]
    w[axis] = 2.0
    d.x[10:13] = list(w)
    n = 500
    for _ in range(n):
        d.step((0.0,) * 4)
    angle = 2.0 * n * DT
    expect = [math.cos(0.5 * angle), 0.0, 0.0, 0.0]
    expect[1 + axis] = math.sin(0.5 * angle)
    assert d.attitude == pytest.approx(tuple(expect), abs=1e-10)
    assert d.angular_velocity == pytest.approx(tuple(w), abs=1e-12)


@pytest.mark.parametrize("motor", [0, 1, 2, 3])
def test_a_constant_torque_spins_up_linearly(motor):
    """From rest, motors settled: omega' = tau / I on each axis at the start (the gyroscopic coupling is
    second order in the first step)."""
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -1000.0))
    cmd = [0.3] * 4
    cmd[motor] = 0.5
    d.motor = list(cmd)
    d.step(tuple(cmd))
    _, tx, ty, tz = reference_forces(ODD, cmd)
    alpha = (tx / ODD.inertia_kgm2[0], ty / ODD.inertia_kgm2[1], tz / ODD.inertia_kgm2[2])
    assert d.angular_velocity == pytest.approx(tuple(a * DT for a in alpha), rel=1e-4)
    # the attitude turns by the mean rate: half an angular-acceleration step
    qa = d.attitude
    assert qa[1:] == pytest.approx(tuple(0.25 * a * DT * DT for a in alpha), rel=1e-4)


def test_euler_coupling_of_a_spinning_body():
    """Torque-free I w' = -(w x I w): the first step's change of each rate component."""
    import numpy as np

    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -1000.0))
    w0 = np.array([1.0, -2.0, 3.0])
    d.x[10:13] = list(w0)
    d.step((0.0,) * 4)
    inertia = np.array(ODD.inertia_kgm2)
    wdot = -np.cross(w0, inertia * w0) / inertia
    assert np.array(d.angular_velocity) - w0 == pytest.approx(tuple(wdot * DT), rel=2e-2)  # + O(w^3 dt^2)


def test_touchdown_records_the_downward_speed_once_and_lift_off_needs_thrust():
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.001))
    d.x[5] = 2.0  # falling at 2 m/s: reaches the ground in this step
    d.step((0.0,) * 4)
    assert d.touchdown and d.on_ground and d.position[2] == 0.0
    assert d.touchdown_speed_mps == pytest.approx(2.0 + GRAVITY * DT - 0.3 / 0.8 * 2.0 * DT, abs=1e-4)
    assert d.velocity == (0.0, 0.0, 0.0) and d.accel_world == pytest.approx((0.0, 0.0, -2.0 / DT), rel=1e-3)
    speed = d.touchdown_speed_mps
    d.step((0.0,) * 4)  # still on the ground: no new touchdown, the speed of the last one kept
    assert d.touchdown is False and d.on_ground and d.touchdown_speed_mps == speed
    # a fast descent with full thrust reaching the ground: a touchdown, not held (it can climb), no sinking
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.001))
    d.motor = [1.0] * 4
    d.x[5] = 1.0
    d.step((1.0,) * 4)
    assert d.touchdown and d.on_ground is False and d.position[2] == 0.0
    assert d.touchdown_speed_mps > 0.9 and d.velocity[2] == 0.0
    # next step it climbs away
    d.step((1.0,) * 4)
    assert d.position[2] < 0.0 and d.velocity[2] < 0.0 and not d.on_ground and not d.touchdown
    # on the ground with thrust just below the weight: held; just above: lifts off
    w = ODD.mass_kg * GRAVITY / (4 * ODD.thrust_max_n)
    for cmd, held in ((0.99 * w, True), (1.01 * w, False)):
        d = QuadDynamics(ODD, DT)
        d.motor = [cmd] * 4
        d.step((cmd,) * 4)
        assert d.on_ground == held and (d.position[2] < 0.0) == (not held)
    # held while tilted: thrust is enough only when level (g - T R33 / m >= 0 decides)
    d = QuadDynamics(ODD, DT)
    d.x[6:10] = list(quat_from_euler(0.0, 0.5, 0.0))
    cmd = 1.05 * w  # 1.05 * cos(0.5) < 1
    d.motor = [cmd] * 4
    d.step((cmd,) * 4)
    assert d.on_ground and d.attitude == (1.0, 0.0, 0.0, 0.0)


def test_a_touchdown_while_falling_tilted_keeps_the_yaw():
    import numpy as np

    for yaw in (-2.5, -0.4, 0.9, 3.0):
        q = quat_from_euler(0.15, 0.25, yaw)
        d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.0005))
        d.x[6:10] = list(q)
        d.x[5] = 1.0
        d.step((0.0,) * 4)
        w, x, y, z = d.attitude
        assert x == 0.0 and y == 0.0 and d.on_ground
        # the heading of the body x axis projected on the ground
        fwd = qrotate(q, (1.0, 0.0, 0.0))
        yaw_fwd = math.atan2(fwd[1], fwd[0])
        assert math.atan2(math.sin(2 * math.atan2(z, w) - yaw_fwd), math.cos(2 * math.atan2(z, w) - yaw_fwd)) == \
            pytest.approx(0.0, abs=1e-9)
        assert np.hypot(w, z) == pytest.approx(1.0, abs=1e-15)


def test_a_slow_touchdown_records_its_own_speed():
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.0002))
    d.x[5] = 0.3
    d.step((0.0,) * 4)
    assert d.touchdown and d.touchdown_speed_mps == pytest.approx(0.3 + GRAVITY * DT - 0.3 / 0.8 * 0.3 * DT, abs=1e-4)


def test_a_tilted_touchdown_with_thrust_enough_to_climb_is_not_held():
    """Pitched 0.5 rad with 1.18 x the level hover thrust: the vertical part, 1.18 cos(0.5) = 1.036 x the weight,
    can lift, so the ground does not hold it (it only stops the descent)."""
    w = ODD.mass_kg * GRAVITY / (4 * ODD.thrust_max_n)
    q = quat_from_euler(0.0, 0.5, 0.0)
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.001))
    d.x[6:10] = list(q)
    d.x[5] = 1.0
    d.motor = [1.18 * w] * 4
    d.step((1.18 * w,) * 4)
    assert d.touchdown and d.on_ground is False and d.velocity[2] == 0.0
    assert d.attitude == pytest.approx(q, abs=1e-12)  # not levelled
    # with 1.12 x: 1.12 cos(0.5) = 0.983 x the weight: held and levelled
    d = QuadDynamics(ODD, DT, position=(0.0, 0.0, -0.001))
    d.x[6:10] = list(q)
    d.x[5] = 1.0
    d.motor = [1.12 * w] * 4
    d.step((1.12 * w,) * 4)
    assert d.on_ground is True and d.attitude == (1.0, 0.0, 0.0, 0.0)
