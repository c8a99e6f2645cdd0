"""Control cascade units: PositionControl (NaN semantics, PX4-style), attitude, rate, mixer priorities."""

import itertools
import math

import pytest

from sitl_vehicle.airframes import GRAVITY, QUAD250
from sitl_vehicle.control.attitude import AttitudeControl
from sitl_vehicle.control.mixer import Mixer
from sitl_vehicle.control.position import PositionControl, PositionControlStates, TrajectorySetpoint
from sitl_vehicle.control.qmath import (
    bodyz_to_attitude,
    dcm_z,
    euler_from_quat,
    qconj,
    qmul,
    qrotate,
    quat_between,
    quat_from_euler,
)
from sitl_vehicle.control.rate import RateControl

NAN = float("nan")
KP = (1.5, 1.5, 2.0)
KV = (4.0, 4.0, 5.0)
HOVER = 0.5
STATE = PositionControlStates(position=(0.1, -0.2, -1.0), velocity=(0.05, 0.02, -0.03),
                              acceleration=(0.0, 0.0, 0.0), yaw=0.3)
SP_P = (0.2, -0.1, -1.1)
SP_V = (0.1, 0.05, -0.05)
SP_A = (0.3, -0.2, 0.1)


def make_pc():
    pc = PositionControl()
    pc.set_position_gains(KP)
    pc.set_velocity_gains(KV, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    pc.set_velocity_limits(10.0, 5.0, 5.0)
    pc.set_thrust_limits(0.1, 0.9)
    pc.set_tilt_limit(math.radians(45))
    pc.set_hover_thrust(HOVER)
    return pc


def expected_acc(i, p_set, v_set, a_set):
    """Formula for one axis with zero integrator and zero velocity derivative (NaN = no output)."""
    vel_sp = NAN
    if p_set:
        vel_sp = KP[i] * (SP_P[i] - STATE.position[i])
    if v_set:
        vel_sp = SP_V[i] + (vel_sp if p_set else 0.0)
    acc = SP_A[i] if a_set else NAN
    if not math.isnan(vel_sp):
        fb = KV[i] * (vel_sp - STATE.velocity[i])
        acc = fb + (acc if a_set else 0.0)
    return acc


FLAGS = list(itertools.product([False, True], repeat=3))


@pytest.mark.parametrize("xy,z", list(itertools.product(FLAGS, FLAGS)))
def test_every_set_unset_combination(xy, z):
    """PX4 PositionControlTest shape: all 8x8 set/unset combinations of (position, velocity,
    acceleration) for the xy pair and z; validity and output acceleration derived from formulas."""
    def pick(values, flags_xy, flags_z, k):
        return tuple(values[i] if (flags_xy[k] if i < 2 else flags_z[k]) else NAN for i in range(3))

    sp = TrajectorySetpoint(position=pick(SP_P, xy, z, 0), velocity=pick(SP_V, xy, z, 1),
                            acceleration=pick(SP_A, xy, z, 2), yaw=0.5)
    pc = make_pc()
    pc.set_state(STATE)
    pc.set_input_setpoint(sp)
    out = pc.update(0.01)
    should_be_valid = any(xy) and any(z)
    assert out.valid == should_be_valid
    if not should_be_valid:
        return
    for i in range(3):
        flags = xy if i < 2 else z
        assert out.acceleration[i] == pytest.approx(expected_acc(i, *flags), abs=1e-9), i
    # thrust: collinear with the specific-force direction, vertical part = hover scaled (PX4 formula)
    ax, ay, az = out.acceleration
    bz = (-ax, -ay, GRAVITY - az)
    n = math.sqrt(sum(c * c for c in bz))
    tx, ty, tz = out.thrust
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    for t, b in zip((tx, ty, tz), bz, strict=True):
        assert -t / tn == pytest.approx(b / n, abs=1e-9)
    assert tz == pytest.approx(min(az * HOVER / GRAVITY - HOVER, -0.1), abs=1e-9)
    assert out.yaw == 0.5 and out.yaw_rate == 0.0


@pytest.mark.parametrize("field,value", [
    ("position", (1.0, NAN, 0.0)),  # x without y
    ("velocity", (NAN, 1.0, 0.0)),  # y without x
    ("acceleration", (0.0, NAN, 0.0)),
])
def test_xy_setpoints_must_come_in_pairs(field, value):
    pc = make_pc()
    pc.set_state(STATE)
    pc.set_input_setpoint(TrajectorySetpoint(**{field: value}))
    assert not pc.update(0.01).valid


def test_controlled_axis_needs_finite_state():
    pc = make_pc()
    pc.set_state(PositionControlStates((NAN, NAN, -1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    pc.set_input_setpoint(TrajectorySetpoint(position=(0.0, 0.0, -1.0)))
    assert not pc.update(0.01).valid
    # velocity control of xy does not need the position estimate
    pc.set_input_setpoint(TrajectorySetpoint(position=(NAN, NAN, -1.0), velocity=(0.0, 0.0, NAN)))
    assert pc.update(0.01).valid


def test_hover_gives_hover_thrust_and_level_attitude():
    pc = make_pc()
    pc.set_state(PositionControlStates((0.0, 0.0, -1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    pc.set_input_setpoint(TrajectorySetpoint(position=(0.0, 0.0, -1.0)))
    out = pc.update(0.01)
    assert out.valid and out.thrust == pytest.approx((0.0, 0.0, -HOVER), abs=1e-12)


def test_tilt_and_thrust_limits():
    pc = make_pc()
    pc.set_state(PositionControlStates((0.0, 0.0, -1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    pc.set_input_setpoint(TrajectorySetpoint(position=(100.0, 0.0, -1.0)))
    out = pc.update(0.01)
    tx, ty, tz = out.thrust
    assert math.degrees(math.atan2(math.hypot(tx, ty), -tz)) <= 45.0 + 1e-6
    assert math.sqrt(tx * tx + ty * ty + tz * tz) <= 0.9 + 1e-9
    # falling command: thrust never below the minimum
    pc.set_input_setpoint(TrajectorySetpoint(position=(0.0, 0.0, 100.0)))
    tz = pc.update(0.01).thrust[2]
    assert -tz == pytest.approx(0.1)


def test_velocity_integrator_removes_steady_offset_and_freezes_in_saturation():
    pc = make_pc()
    pc.set_velocity_gains(KV, (1.0, 1.0, 2.0), (0.0, 0.0, 0.0))
    pc.set_state(PositionControlStates((0.0, 0.0, -1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0))
    pc.set_input_setpoint(TrajectorySetpoint(velocity=(0.0, 0.0, 3.0)))  # wants to go down fast
    for _ in range(100):
        out = pc.update(0.01)
    # thrust stuck at minimum and the error points further down: integrator frozen at its start (0)
    assert -out.thrust[2] == pytest.approx(0.1) and pc.integral[2] == 0.0
    pc.set_input_setpoint(TrajectorySetpoint(velocity=(0.2, 0.0, 0.0)))
    pc.update(0.01)
    assert pc.integral[0] > 0.0


# ---------------------------------------------------------------- attitude
def test_attitude_zero_error_zero_rate_and_small_roll_error_is_proportional():
    ac = AttitudeControl(p=(6.0, 6.0, 3.0), yaw_weight=0.4, rate_limit=(10.0, 10.0, 10.0))
    q = quat_from_euler(0.0, 0.0, 0.7)
    assert ac.update(q, q) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    qd = quat_from_euler(0.01, 0.0, 0.7)
    r = ac.update(q, qd)
    assert r[0] == pytest.approx(6.0 * 0.01, rel=1e-3) and abs(r[1]) < 1e-6 and abs(r[2]) < 1e-6
    qd = quat_from_euler(0.0, 0.0, 0.71)
    assert ac.update(q, qd)[2] == pytest.approx(3.0 * 0.01, rel=2e-2)  # yaw gain preserved for small errors


def test_attitude_yaw_weighting_prioritises_roll_pitch():
    ac = AttitudeControl(p=(6.0, 6.0, 3.0), yaw_weight=0.4, rate_limit=(100.0, 100.0, 100.0))
    full = AttitudeControl(p=(6.0, 6.0, 3.0), yaw_weight=1.0, rate_limit=(100.0, 100.0, 100.0))
    q = (1.0, 0.0, 0.0, 0.0)
    tilt = quat_from_euler(0.3, 0.0, 0.0)
    tilt_and_yaw = qmul(tilt, (math.cos(0.75), 0.0, 0.0, math.sin(0.75)))  # same thrust axis, +1.5 rad yaw
    assert dcm_z(tilt_and_yaw) == pytest.approx(dcm_z(tilt))
    a = ac.update(q, tilt)
    b = ac.update(q, tilt_and_yaw)
    c = full.update(q, tilt_and_yaw)
    # the roll/pitch demand moves the thrust axis towards its target; a large yaw error turns that
    # direction away from the straight path by the (half) yaw rotation. With yaw weighting 0.4 the
    # deviation is 0.4 * 0.75 rad, with full attitude control (weight 1) the whole 0.75 rad.
    assert a[1] == pytest.approx(0.0, abs=1e-12)
    assert math.atan2(-b[1], b[0]) == pytest.approx(0.4 * 0.75, abs=1e-6)
    assert math.atan2(-c[1], c[0]) == pytest.approx(0.75, abs=1e-6)
    assert math.hypot(b[0], b[1]) == pytest.approx(math.hypot(a[0], a[1]), rel=1e-9)
    assert 0.0 < b[2]


def test_attitude_rate_limit_and_yaw_rate_feed_forward():
    ac = AttitudeControl(p=(6.0, 6.0, 3.0), yaw_weight=0.4, rate_limit=(1.0, 1.0, 0.5))
    q = (1.0, 0.0, 0.0, 0.0)
    r = ac.update(q, quat_from_euler(1.0, 0.0, 0.0))
    assert r[0] == pytest.approx(1.0)
    r = ac.update(q, q, yaw_rate_sp=0.3)
    assert r == pytest.approx((0.0, 0.0, 0.3))


def test_bodyz_to_attitude_and_quat_between():
    q = bodyz_to_attitude((0.0, 0.0, 1.0), 0.8)
    assert euler_from_quat(q) == pytest.approx((0.0, 0.0, 0.8), abs=1e-12)
    q = bodyz_to_attitude((-0.3, 0.0, 1.0), 0.0)  # thrust tilted forward = nose down
    assert euler_from_quat(q)[1] < 0.0
    src, dst = (0.0, 0.0, 1.0), (0.3, -0.2, 0.9)
    n = math.sqrt(sum(c * c for c in dst))
    r = qrotate(quat_between(src, dst), src)
    assert r == pytest.approx(tuple(c / n for c in dst), abs=1e-12)
    e = qmul(qconj(q), q)
    assert e == pytest.approx((1.0, 0.0, 0.0, 0.0))


# ---------------------------------------------------------------- rate
def test_rate_pid_proportional_integral_limit_and_saturation_freeze():
    rc = RateControl(p=(10.0, 10.0, 5.0), i=(100.0, 100.0, 100.0), d=(0.0, 0.0, 0.0),
                     int_lim=(2.0, 2.0, 2.0), dt=0.01)
    out = rc.update((0.0, 0.0, 0.0), (1.0, -1.0, 0.5), update_integral=False)
    assert out == pytest.approx((10.0, -10.0, 2.5))
    for _ in range(100):
        rc.update((0.0, 0.0, 0.0), (1.0, -1.0, 0.5))
    assert rc.integral == pytest.approx((2.0, -2.0, 2.0))
    rc.reset_integral()
    rc.set_saturation_status((True, False, False), (False, False, False))
    rc.update((0.0, 0.0, 0.0), (1.0, -1.0, 0.5))
    assert rc.integral[0] == 0.0 and rc.integral[1] < 0.0


def test_rate_d_term_damps_on_measurement():
    rc = RateControl(p=(0.0, 0.0, 0.0), i=(0.0, 0.0, 0.0), d=(1.0, 1.0, 1.0), d_lpf_hz=0.0, dt=0.01)
    rc.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = rc.update((0.1, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert out[0] == pytest.approx(-10.0)  # -D * d(omega)/dt


# ---------------------------------------------------------------- mixer
@pytest.fixture
def mixer():
    return Mixer(QUAD250)


def test_mixer_unsaturated_is_exact_inverse(mixer):
    req = (9.81, 0.05, -0.04, 0.01)
    u = mixer.mix(req[0], req[1:])
    assert all(0.0 < x < 1.0 for x in u)
    assert mixer.effectiveness(u) == pytest.approx(req, abs=1e-9)
    assert mixer.saturation_positive == (False, False, False)


def test_mixer_yaw_gives_way_first(mixer):
    thrust = 9.81
    roll = 0.3
    u = mixer.mix(thrust, (roll, 0.0, 5.0))  # far more yaw than available
    f, tx, ty, tz = mixer.effectiveness(u)
    assert f == pytest.approx(thrust, rel=1e-6)  # thrust kept
    assert tx == pytest.approx(roll, rel=1e-6)  # roll kept
    assert abs(ty) < 1e-9
    assert 0.0 < tz < 5.0  # yaw reduced, not reversed
    assert mixer.saturation_positive[2] and not mixer.saturation_positive[0]


def test_mixer_high_thrust_reduces_thrust_to_keep_roll(mixer):
    u = mixer.mix(19.0, (0.5, 0.0, 0.0))
    f, tx, ty, tz = mixer.effectiveness(u)
    assert tx == pytest.approx(0.5, rel=1e-6)
    assert f < 19.0 and max(u) == pytest.approx(1.0)


def test_mixer_never_adds_thrust_at_low_thrust_airmode_disabled(mixer):
    u = mixer.mix(1.0, (0.5, 0.0, 0.0))
    f, tx, ty, tz = mixer.effectiveness(u)
    assert f <= 1.0 + 1e-9  # airmode disabled: thrust is never increased to unsaturate
    assert 0.0 < tx < 0.5  # roll gives way instead
    assert min(u) >= 0.0
