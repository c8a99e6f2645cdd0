"""Rate, attitude, mixer and position control against their documented laws, axis by axis (gains differ per
axis so that a swapped index shows); expected values come from the modules' formulas and hand-worked cases."""

import math

import numpy as np
import pytest

from sitl_vehicle.airframes import GRAVITY, QUAD250
from sitl_vehicle.control.attitude import AttitudeControl
from sitl_vehicle.control.mixer import Mixer, _desat_gain, _desaturate
from sitl_vehicle.control.position import PositionControl, PositionControlStates, TrajectorySetpoint
from sitl_vehicle.control.qmath import quat_from_euler
from sitl_vehicle.control.rate import RateControl

P, I, D, FF, LIM = (2.0, 3.0, 4.0), (5.0, 6.0, 7.0), (0.1, 0.2, 0.3), (0.5, 0.6, 0.7), (0.3, 0.4, 0.5)


def reference_rate_pid(rates, sps, sat_pos, sat_neg, dt, cutoff_hz):
    """alpha = P·e + I − D·ḋω (low-passed, on the measurement) + FF·ω_sp; I += Ki·e·dt clamped to ±lim, frozen on
    an axis saturated in the direction e would grow it."""
    a = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt) if cutoff_hz > 0 else 1.0
    p, i, d, ff, lim = map(np.array, (P, I, D, FF, LIM))
    integ, dfilt, prev, outs, integs = np.zeros(3), np.zeros(3), None, [], []
    for rate, sp, spos, sneg in zip(rates, sps, sat_pos, sat_neg, strict=True):
        if prev is not None:
            dfilt = dfilt + a * ((rate - prev) / dt - dfilt)
        prev = rate
        e = sp - rate
        outs.append(p * e + integ - d * dfilt + ff * sp)
        frozen = (e > 0) & spos | (e < 0) & sneg
        integ = np.where(frozen, integ, np.clip(integ + i * e * dt, -lim, lim))
        integs.append(integ)
    return np.array(outs), np.array(integs)


@pytest.mark.parametrize("cutoff_hz", [0.0, 0.5, 30.0])
def test_rate_pid_follows_its_law_on_every_axis(cutoff_hz):
    rng = np.random.default_rng(7)
    n, dt = 120, 0.004
    rates = rng.normal(0.0, 1.0, (n, 3))
    sps = rng.normal(0.0, 1.0, (n, 3)) + np.where(np.arange(n) < n // 2, 1.5, -1.5)[:, None]  # up, then down
    sat_pos = rng.random((n, 3)) < 0.3
    sat_neg = rng.random((n, 3)) < 0.3
    want_out, want_int = reference_rate_pid(rates, sps, sat_pos, sat_neg, dt, cutoff_hz)
    rc = RateControl(p=P, i=I, d=D, ff=FF, int_lim=LIM, d_lpf_hz=cutoff_hz, dt=dt)
    for k in range(n):
        rc.set_saturation_status(sat_pos[k], sat_neg[k])
        assert rc.update(tuple(rates[k]), tuple(sps[k])) == pytest.approx(tuple(want_out[k]), abs=1e-12)
        assert rc.integral == pytest.approx(tuple(want_int[k]), abs=1e-12)
    # the clamp was reached both ways on every axis
    assert want_int.max(axis=0) == pytest.approx(LIM) and want_int.min(axis=0) == pytest.approx(-np.array(LIM))


def test_rate_pid_defaults_are_a_500_hz_loop_with_a_40_hz_d_filter():
    rc = RateControl(p=(0.0,) * 3, i=(0.0,) * 3, d=(1.0, 1.0, 1.0))
    rc.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = rc.update((0.01, 0.02, 0.03), (0.0, 0.0, 0.0))
    alpha = 1.0 - math.exp(-2.0 * math.pi * 40.0 * 0.002)
    assert out == pytest.approx(tuple(-alpha * r / 0.002 for r in (0.01, 0.02, 0.03)), rel=1e-12)


def test_rate_pid_reset_clears_filter_integral_and_saturation():
    rc = RateControl(p=P, i=I, d=D, ff=(0.0,) * 3, int_lim=LIM, d_lpf_hz=0.0, dt=0.01)
    rc.set_saturation_status((True,) * 3, (True,) * 3)
    for k in range(5):
        rc.update((0.1 * k, -0.2 * k, 0.3 * k), (1.0, 1.0, 1.0))
    rc.reset()
    # first step after a reset: no derivative (no previous sample), no integral
    assert rc.update((0.5, 0.5, 0.5), (0.0, 0.0, 0.0)) == pytest.approx(tuple(-0.5 * p for p in P))
    # and the saturation flags are gone: the integrator moves both ways on every axis
    assert rc.integral == pytest.approx(tuple(-0.5 * i * 0.01 for i in I))
    rc.update((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    assert rc.integral == pytest.approx(tuple(0.5 * i * 0.01 for i in I))
    rc.reset_integral()
    assert rc.integral == (0.0, 0.0, 0.0)


def test_attitude_yaw_weight_above_one_is_one():
    q = quat_from_euler(0.0, 0.0, 0.0)
    qd = quat_from_euler(0.0, 0.0, 0.1)
    big = dict(rate_limit=(100.0,) * 3)
    assert AttitudeControl(yaw_weight=1.5, **big).update(q, qd) == pytest.approx(
        AttitudeControl(yaw_weight=1.0, **big).update(q, qd))


@pytest.mark.parametrize("axis", [0, 1])
def test_attitude_upside_down_setpoint_uses_full_attitude_control(axis):
    """Setpoint turned 180° about x (or y): the error quaternion is (0, 1, 0, 0) (or (0, 0, 1, 0)), so the rate
    set-point is 2·gain about that axis, limited."""
    gain, limit = (6.5, 6.0, 2.8), (20.0, 20.0, 20.0)
    ac = AttitudeControl(p=gain, yaw_weight=0.4, rate_limit=limit)
    qd = quat_from_euler(math.pi, 0.0, 0.0) if axis == 0 else quat_from_euler(0.0, math.pi, 0.0)
    want = [0.0, 0.0, 0.0]
    want[axis] = 2.0 * gain[axis]
    assert ac.update((1.0, 0.0, 0.0, 0.0), qd) == pytest.approx(tuple(want), abs=1e-9)


def test_attitude_yaw_rate_feed_forward_is_the_world_z_axis_in_body_axes():
    roll, pitch, r_sp = 0.3, 0.2, 0.7
    q = quat_from_euler(roll, pitch, 0.1)
    # R^T e_z for ZYX angles: the third row of R = (−sin θ, sin φ cos θ, cos φ cos θ)
    zb = (-math.sin(pitch), math.sin(roll) * math.cos(pitch), math.cos(roll) * math.cos(pitch))
    ac = AttitudeControl(rate_limit=(10.0,) * 3)
    assert ac.update(q, q, r_sp) == pytest.approx(tuple(r_sp * z for z in zb), abs=1e-12)


# ---------------------------------------------------------------- mixer: hand-worked geometry and desaturation


def test_each_motor_gives_thrust_and_the_torques_of_its_place():
    """Rotor i at (x, y) in FRD, thrust T·u up (−z): τ = r × F gives roll −y·T, pitch +x·T; yaw s·k_m·T."""
    m = Mixer(QUAD250)
    t, km = QUAD250.thrust_max_n, QUAD250.torque_coeff_m
    d = QUAD250.arm_length_m * math.sqrt(0.5)
    places = [(d, d, 1.0), (-d, -d, 1.0), (d, -d, -1.0), (-d, d, -1.0)]    # PX4 quad_x: front-right first
    for i, (x, y, s) in enumerate(places):
        u = [0.0] * 4
        u[i] = 0.5
        assert m.effectiveness(u) == pytest.approx((0.5 * t, -0.5 * y * t, 0.5 * x * t, 0.5 * s * km * t), abs=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_an_unreachable_torque_saturates_its_own_axis_and_direction_only(axis, sign):
    m = Mixer(QUAD250)
    hover = QUAD250.mass_kg * 9.81
    torque = [0.0, 0.0, 0.0]
    torque[axis] = sign * 5.0                        # far beyond what the motors can give
    u = m.mix(hover, tuple(torque))
    got = m.effectiveness(u)
    assert all(0.0 <= x <= 1.0 for x in u)
    assert 0.0 < sign * got[1 + axis] < 5.0           # reduced, never reversed
    assert got[0] <= hover + 1e-9                     # thrust never added
    want_pos = tuple(sign > 0 and k == axis for k in range(3))
    want_neg = tuple(sign < 0 and k == axis for k in range(3))
    assert m.saturation_positive == want_pos and m.saturation_negative == want_neg


@pytest.mark.parametrize("torque", [(0.2, -0.15, 0.02), (-0.25, 0.2, -0.03), (0.0, 0.3, 0.0)])
def test_reachable_demands_are_met_exactly(torque):
    m = Mixer(QUAD250)
    m.mix(9.81, (5.0, 0.0, 0.0))                      # saturated first: the flags must clear again
    u = m.mix(9.81, torque)
    assert m.effectiveness(u) == pytest.approx((9.81, *torque), abs=1e-9)
    assert m.saturation_positive == (False,) * 3 and m.saturation_negative == (False,) * 3


def test_thrust_alone_too_high_is_clipped_to_full_and_too_low_to_zero():
    m = Mixer(QUAD250)
    assert m.mix(4 * QUAD250.thrust_max_n * 1.5, (0.0, 0.0, 0.0)) == pytest.approx([1.0] * 4)
    assert m.mix(-3.0, (0.0, 0.0, 0.0)) == pytest.approx([0.0] * 4)


def test_desaturation_gain_hand_worked():
    ones = (1.0, 1.0, 1.0, 1.0)
    assert _desat_gain(ones, [1.2, 0.5, 0.5, 0.5]) == pytest.approx(-0.2)      # shift down by the overshoot
    assert _desat_gain(ones, [-0.1, 0.5, 0.5, 0.5]) == pytest.approx(0.1)      # up by the undershoot
    # both: the largest needed up-shift plus the largest down-shift (PX4: k_min + k_max)
    assert _desat_gain(ones, [1.3, -0.1, 0.5, 0.5]) == pytest.approx(-0.3 + 0.1)
    # along a direction of −1 on the saturated motor: the shift has the other sign
    assert _desat_gain((-1.0, 1.0, 1.0, 1.0), [1.25, 0.5, 0.5, 0.5]) == pytest.approx(0.25)
    assert _desat_gain((-0.5, 1.0, 1.0, 1.0), [-0.25, 0.5, 0.5, 0.5]) == pytest.approx(-0.5)
    # components under 0.2 of the direction cannot help and are skipped; 0.2 itself counts
    assert _desat_gain((0.1, 1.0, 1.0, 1.0), [2.0, 0.5, 0.5, 0.5]) == 0.0
    assert _desat_gain((0.2, 1.0, 1.0, 1.0), [1.1, 0.5, 0.5, 0.5]) == pytest.approx(-0.5)
    # other bounds
    assert _desat_gain(ones, [0.5, 0.5, 0.5, 0.5], lo=0.6, hi=0.9) == pytest.approx(0.1)
    assert _desat_gain(ones, [0.5, 0.5, 0.5, 0.95], lo=0.0, hi=0.9) == pytest.approx(-0.05)


def test_desaturate_shifts_once_then_by_half_of_what_is_left():
    ones = (1.0, 1.0, 1.0, 1.0)
    u = [1.2, -0.1, 0.5, 0.5]
    # first gain −0.2 + 0.1 = −0.1: (1.1, −0.2, 0.4, 0.4); then −0.1 + 0.2 = 0.1, half of it: +0.05
    _desaturate(u, ones)
    assert u == pytest.approx([1.15, -0.15, 0.45, 0.45])
    # by default (airmode) a shift that raises u is taken too
    y = [-0.1, 0.5, 0.5, 0.5]
    _desaturate(y, ones)
    assert y == pytest.approx([0.0, 0.6, 0.6, 0.6])
    # reduce-only: a positive shift is refused, a negative one taken
    v = [-0.1, 0.5, 0.5, 0.5]
    _desaturate(v, ones, reduce_only=True)
    assert v == [-0.1, 0.5, 0.5, 0.5]
    w = [1.2, 0.5, 0.5, 0.5]
    _desaturate(w, ones, reduce_only=True)
    assert w == pytest.approx([1.0, 0.3, 0.3, 0.3])
    # saturated at both ends: −0.1 taken, then half of what is left (+0.05) as PX4 does, whatever its sign; the
    # net shift (−0.05) centres the excess and is still a reduction
    x = [1.2, -0.1, 0.5, 0.5]
    _desaturate(x, ones, reduce_only=True)
    assert x == pytest.approx([1.15, -0.15, 0.45, 0.45])


# ---------------------------------------------------------------- position control: validity, tilt, thrust

NAN = float("nan")
LEVEL = PositionControlStates(position=(0.0, 0.0, -1.0), velocity=(0.0, 0.0, 0.0), acceleration=(0.0, 0.0, 0.0),
                              yaw=0.0)


def _pc(hover=0.5, tilt=math.pi / 4):
    pc = PositionControl()
    pc.set_position_gains((1.0, 1.0, 1.0))
    pc.set_velocity_gains((2.0, 2.0, 4.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    pc.set_velocity_limits(10.0, 5.0, 5.0)
    pc.set_thrust_limits(0.05, 1.0)
    pc.set_tilt_limit(tilt)
    pc.set_hover_thrust(hover)
    return pc


def _valid(sp, state=LEVEL):
    pc = _pc()
    pc.set_state(state)
    pc.set_input_setpoint(sp)
    return pc.update(0.01).valid


def test_validity_each_level_needs_its_xy_pair_and_every_axis_a_setpoint():
    v, a = (0.1, 0.2, 0.0), (0.3, -0.1, 0.0)
    assert _valid(TrajectorySetpoint(velocity=v, acceleration=a))
    assert not _valid(TrajectorySetpoint(velocity=(0.1, 0.2, NAN)))                       # z: nothing
    assert not _valid(TrajectorySetpoint(velocity=v, acceleration=(0.3, NAN, 0.0)))        # acc pair broken
    assert not _valid(TrajectorySetpoint(velocity=(NAN, 0.2, 0.0), acceleration=a))        # vel pair broken
    assert not _valid(TrajectorySetpoint(position=(NAN, 1.0, -1.0), velocity=v))           # pos pair broken
    assert not _valid(TrajectorySetpoint(position=(0.0, 0.0, -1.0)),
                      PositionControlStates((0.0, 0.0, NAN), (0.0,) * 3, (0.0,) * 3, 0.0))  # z position unknown
    for vel, acc in [((0.0, 0.0, NAN), (0.0,) * 3), ((0.0,) * 3, (0.0, 0.0, NAN))]:       # z velocity or its rate
        state = PositionControlStates((0.0,) * 3, vel, acc, 0.0)
        assert not _valid(TrajectorySetpoint(velocity=(0.0, 0.0, 0.0)), state)


def test_integral_resets():
    pc = _pc()
    pc.set_velocity_gains((2.0, 2.0, 4.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0))
    pc.set_state(LEVEL)
    pc.set_input_setpoint(TrajectorySetpoint(velocity=(0.5, -0.5, -0.3)))
    for _ in range(3):
        pc.update(0.1)
    before = pc.integral
    assert all(abs(c) > 0 for c in before)
    pc.reset_integral_xy()
    assert pc.integral == (0.0, 0.0, before[2])
    pc.reset_integral()
    assert pc.integral == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("ax, ay", [(2.0, 0.0), (0.0, -3.0), (1.5, 2.5)])
def test_horizontal_acceleration_within_the_tilt_limit_is_hover_thrust_tilted(ax, ay):
    """Level flight: vertical thrust balances gravity (−hover), the horizontal part gives a = T_xy·g/hover."""
    pc = _pc(hover=0.4)
    pc.set_state(LEVEL)
    pc.set_input_setpoint(TrajectorySetpoint(acceleration=(ax, ay, 0.0)))
    out = pc.update(0.01)
    assert out.thrust == pytest.approx((ax * 0.4 / GRAVITY, ay * 0.4 / GRAVITY, -0.4), abs=1e-12)


@pytest.mark.parametrize("direction", [(1.0, 0.0), (0.0, 1.0), (-0.6, 0.8)])
def test_beyond_the_tilt_limit_the_thrust_leans_exactly_the_limit_in_the_demanded_direction(direction):
    tilt = math.radians(30)
    pc = _pc(hover=0.5, tilt=tilt)
    pc.set_state(LEVEL)
    a = 1.5 * GRAVITY                                  # far more than 30° of tilt can give
    pc.set_input_setpoint(TrajectorySetpoint(acceleration=(a * direction[0], a * direction[1], 0.0)))
    thr = pc.update(0.01).thrust
    lean = 0.5 * math.tan(tilt)                       # vertical −hover, horizontal hover·tan(tilt)
    assert thr == pytest.approx((lean * direction[0], lean * direction[1], -0.5), abs=1e-12)


def test_limit_tilt_hand_worked():
    t = math.radians(45)
    s, c = math.sin(t), math.cos(t)
    b = (0.6 * math.sin(math.radians(60)), 0.8 * math.sin(math.radians(60)), math.cos(math.radians(60)))
    assert PositionControl._limit_tilt(*b, t) == pytest.approx((0.6 * s, 0.8 * s, c), abs=1e-12)
    assert PositionControl._limit_tilt(0.0, 0.0, -1.0, t) == pytest.approx((s, 0.0, c))       # straight down
    # unit vectors rounded just past ±1 in z stay usable
    assert PositionControl._limit_tilt(0.0, 0.0, 1.0000000000000002, t) == (0.0, 0.0, 1.0000000000000002)
    assert PositionControl._limit_tilt(0.0, 0.0, -1.0000000000000002, t) == pytest.approx((s, 0.0, c))


def test_near_free_fall_the_thrust_still_leans_toward_a_small_horizontal_demand():
    pc = _pc(hover=0.5)
    pc.set_state(LEVEL)
    pc.set_input_setpoint(TrajectorySetpoint(acceleration=(0.1, -0.05, GRAVITY - 0.5)))
    thr = pc.update(0.01).thrust
    assert thr[0] > 0.0 and thr[1] < 0.0
    # beyond free fall the axis is kept pointing up: a small horizontal demand tilts it little
    pc.set_input_setpoint(TrajectorySetpoint(acceleration=(0.05, 0.0, 1.5 * GRAVITY)))
    thr = pc.update(0.01).thrust
    assert 0.0 < math.atan2(math.hypot(thr[0], thr[1]), -thr[2]) < math.radians(10)


def test_constrain_xy_hand_worked():
    cxy = PositionControl._constrain_xy
    assert cxy((1.0, 0.0), (0.0, 2.0), 5.0) == (1.0, 2.0)                      # fits: the sum
    assert cxy((6.0, 8.0), (1.0, 1.0), 5.0) == pytest.approx((3.0, 4.0))       # v0 alone too long: v0 scaled
    assert cxy((3.0, 0.0), (0.0, 10.0), 5.0) == pytest.approx((3.0, 4.0))      # 3-4-5: v0 kept, v1 what fits
    assert cxy((0.0, -3.0), (-10.0, 0.0), 5.0) == pytest.approx((-4.0, -3.0))
    assert cxy((3.0, 4.0), (1e-7, 0.0), 5.0) == pytest.approx((3.0, 4.0))      # nothing of v1 to add
    # v1 partly against v0: s solves |v0 + s·u1| = vmax with s ≥ 0
    out = cxy((3.0, 0.0), (-6.0, 8.0), 5.0)
    assert math.hypot(*out) == pytest.approx(5.0)
    assert (out[0] - 3.0) * 8.0 - out[1] * -6.0 == pytest.approx(0.0, abs=1e-12) and out[1] > 0
    sx, sy = cxy((1.0, NAN), (0.0, 0.0), 5.0)
    assert sx == 1.0 and math.isnan(sy)


def test_attitude_yaw_rate_feed_forward_adds_to_the_attitude_error_term():
    q, qd = quat_from_euler(0.2, -0.1, 0.3), quat_from_euler(0.25, -0.05, 0.4)
    zb = (-math.sin(-0.1), math.sin(0.2) * math.cos(-0.1), math.cos(0.2) * math.cos(-0.1))
    ac = AttitudeControl(rate_limit=(10.0,) * 3)
    base = ac.update(q, qd)
    assert all(abs(c) > 0.05 for c in base)
    assert ac.update(q, qd, 0.5) == pytest.approx(tuple(b + 0.5 * z for b, z in zip(base, zb, strict=True)), abs=1e-12)


def test_a_new_mixer_reports_no_saturation():
    m = Mixer(QUAD250)
    assert m.saturation_positive == (False, False, False) and m.saturation_negative == (False, False, False)


def _hand_allocation():
    """Motor commands for (thrust, roll, pitch, yaw) from the hand-built effectiveness of the X layout."""
    t, km = QUAD250.thrust_max_n, QUAD250.torque_coeff_m
    d = QUAD250.arm_length_m * math.sqrt(0.5)
    places = [(d, d, 1.0), (-d, -d, 1.0), (d, -d, -1.0), (-d, d, -1.0)]
    b = np.array([[t] * 4, [-y * t for _, y, _ in places], [x * t for x, _, _ in places],
                  [s * km * t for _, _, s in places]])
    return b, np.linalg.inv(b)


@pytest.mark.parametrize("motor", [0, 1, 2, 3])
def test_one_motor_pushed_past_full_gives_way_by_thrust_keeping_the_torques(motor):
    """Roll and pitch that ask one motor alone for more than full: thrust is reduced (never the torques) and no
    command leaves [0, 1]."""
    b, inv = _hand_allocation()
    m = Mixer(QUAD250)
    want = np.zeros(4)
    want[motor] = 0.5              # of which roll and pitch alone give that motor +0.25 (its diagonal −0.25)
    torque = b @ want
    thrust = 0.8 * b[0].sum()                         # 0.8 on every motor
    u = m.mix(thrust, (torque[1], torque[2], 0.0))
    assert (inv @ np.array([thrust, torque[1], torque[2], 0.0]))[motor] > 1.0     # it would saturate
    assert all(0.0 <= x <= 1.0 for x in u) and max(u) == pytest.approx(1.0)
    got = m.effectiveness(u)
    assert got[1:3] == pytest.approx((torque[1], torque[2]), abs=1e-9) and got[0] < thrust


def test_yaw_that_brings_roll_and_pitch_back_in_range_is_met_exactly():
    """Roll and pitch alone would ask motor 0 for more than full; the yaw asked at the same time lowers it:
    the whole demand is reachable and met exactly."""
    b, inv = _hand_allocation()
    m = Mixer(QUAD250)
    hover = 0.7 * b[0].sum()
    rp = b @ np.array([0.35, -0.35, 0.0, 0.0])         # roll and pitch only: motor 0 to 1.05, motor 1 to 0.35
    yaw = b[3] @ np.array([-0.1, -0.1, 0.1, 0.1])       # motors 0, 1 down
    assert (inv @ np.array([hover, rp[1], rp[2], 0.0]))[0] > 1.0
    demand = (hover, rp[1], rp[2], yaw)
    assert all(0.0 <= x <= 1.0 for x in inv @ np.array(demand))
    u = m.mix(hover, demand[1:])
    assert m.effectiveness(u) == pytest.approx(demand, abs=1e-9)


def test_low_thrust_roll_is_not_helped_by_adding_thrust():
    m = Mixer(QUAD250)
    u = m.mix(2.0, (0.3, 0.0, 0.0))                   # 0.1 per motor, the roll asks ±0.17: undershoot only
    f, tx, _, _ = m.effectiveness(u)
    assert f <= 2.0 + 1e-9 and 0.0 < tx < 0.3 and min(u) >= 0.0


def test_a_torque_just_beyond_reach_is_flagged():
    """At hover (0.5 on every motor) the most roll is 4·d·T·0.5; ask for 15 % more."""
    d = QUAD250.arm_length_m * math.sqrt(0.5)
    most = 4 * d * QUAD250.thrust_max_n * 0.5
    m = Mixer(QUAD250)
    m.mix(2 * QUAD250.thrust_max_n, (1.15 * most, 0.0, 0.0))
    assert m.saturation_positive == (True, False, False)


def test_desaturation_skips_small_components_wherever_they_are_and_scales_by_the_direction():
    assert _desat_gain((0.1, 1.0, 1.0, 1.0), [0.5, 1.2, 0.5, 0.5]) == pytest.approx(-0.2)
    u = [1.2, 0.5, 0.5, 0.5]
    _desaturate(u, (1.0, 0.5, 0.5, 0.5))             # shift −0.2 along the direction: the others by −0.1
    assert u == pytest.approx([1.0, 0.4, 0.4, 0.4])


def _run(pc, sp, state=LEVEL, dt=0.1):
    pc.set_state(state)
    pc.set_input_setpoint(sp)
    return pc.update(dt)


@pytest.mark.parametrize("sp, state", [
    (TrajectorySetpoint(velocity=(0.1, NAN, 0.0)), LEVEL),                                      # broken pair
    (TrajectorySetpoint(position=(0.0, 0.0, -1.0), yaw=0.2), PositionControlStates((0.0, 0.0, NAN), (0.0,) * 3,
                                                                                   (0.0,) * 3, 0.0)),
    (TrajectorySetpoint(velocity=(0.0, 0.0, 0.0), yaw=0.2), PositionControlStates((0.0,) * 3, (0.0, NAN, 0.0),
                                                                                  (0.0,) * 3, 0.0)),
    (TrajectorySetpoint(velocity=(0.0, 0.0, 0.0), yaw=0.2), PositionControlStates((0.0,) * 3, (0.0,) * 3,
                                                                                  (NAN, 0.0, 0.0), 0.0)),
])
def test_invalid_input_gives_nothing_usable(sp, state):
    out = _run(_pc(), sp, state)
    assert out.valid is False
    assert all(math.isnan(c) for c in (*out.thrust, *out.acceleration, *out.velocity, out.yaw, out.yaw_rate))


def test_valid_input_passes_yaw_through():
    out = _run(_pc(), TrajectorySetpoint(velocity=(0.0, 0.0, 0.0), yaw=1.2, yaw_rate=0.3))
    assert out.valid is True and out.yaw == 1.2 and out.yaw_rate == 0.3
    state = PositionControlStates((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, -0.7)
    out = _run(_pc(), TrajectorySetpoint(velocity=(0.0, 0.0, 0.0)), state)
    assert out.yaw == -0.7 and out.yaw_rate == 0.0       # no yaw set-point: hold the heading, no rate


def test_position_loop_velocity_setpoint_per_axis_and_the_horizontal_limit():
    pc = _pc()
    pc.set_position_gains((0.5, 1.5, 2.0))
    out = _run(pc, TrajectorySetpoint(position=(0.2, -0.4, -1.3)))
    assert out.velocity == pytest.approx((0.5 * 0.2, 1.5 * -0.4, 2.0 * -0.3))
    # limit 1 m/s: the position part (0, 0.8) is kept, the feed-forward (0.9, 0) adds what fits: 0.6
    pc = _pc()
    pc.set_position_gains((1.0, 1.0, 1.0))
    pc.set_velocity_limits(1.0, 5.0, 5.0)
    out = _run(pc, TrajectorySetpoint(position=(0.0, 0.8, -1.0), velocity=(0.9, 0.0, 0.0)))
    assert out.velocity[:2] == pytest.approx((0.6, 0.8))
    # a velocity set-point alone beyond the limit is scaled to it
    out = _run(pc, TrajectorySetpoint(velocity=(0.0, 1.5, 0.0)))
    assert out.velocity == pytest.approx((0.0, 1.0, 0.0))
    out = _run(pc, TrajectorySetpoint(velocity=(-1.2, 0.9, 0.0)))
    assert out.velocity == pytest.approx((-0.8, 0.6, 0.0))


def test_velocity_pid_law_with_integral_and_derivative():
    """a = Kp·e + I − Kd·dv/dt per axis, I += Ki·e·dt after each step (nothing saturated)."""
    pc = _pc(hover=0.5)
    kp, ki, kd = (2.0, 3.0, 4.0), (0.5, 0.7, 0.9), (0.1, 0.2, 0.3)
    pc.set_velocity_gains(kp, ki, kd)
    vsp = (0.3, -0.2, 0.1)
    state = PositionControlStates((0.0,) * 3, (0.1, 0.1, -0.1), (0.2, -0.3, 0.4), 0.0)
    e = [s - v for s, v in zip(vsp, state.velocity, strict=True)]
    dt = 0.05
    first = _run(pc, TrajectorySetpoint(velocity=vsp), state, dt)
    assert first.acceleration == pytest.approx(tuple(kp[i] * e[i] - kd[i] * state.acceleration[i]
                                                      for i in range(3)))
    integ = tuple(ki[i] * e[i] * dt for i in range(3))
    assert pc.integral == pytest.approx(integ)
    second = _run(pc, TrajectorySetpoint(velocity=vsp), state, dt)
    assert second.acceleration == pytest.approx(tuple(kp[i] * e[i] + integ[i] - kd[i] * state.acceleration[i]
                                                       for i in range(3)))
    assert pc.integral == pytest.approx(tuple(2 * c for c in integ))


@pytest.mark.parametrize("vz_sp, acc_ff, frozen", [
    (3.0, 0.0, True),            # diving: thrust at its minimum, the error asks for less still
    (0.5, 0.0, True),            # ... a small error too (a strong gain saturates it)
    (-3.0, 0.0, True),           # climbing: thrust past its maximum, the error asks for more
    (0.5, -30.0, False),         # thrust at its maximum but the error asks for less: integrate
    (0.02, 0.0, False),          # nothing saturated
])
def test_vertical_integrator_freezes_only_against_a_saturated_thrust(vz_sp, acc_ff, frozen):
    pc = _pc(hover=0.5)
    pc.set_thrust_limits(0.1, 0.9)
    pc.set_velocity_gains((2.0, 2.0, 40.0), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    out = _run(pc, TrajectorySetpoint(velocity=(0.0, 0.0, vz_sp), acceleration=(0.0, 0.0, acc_ff)), dt=0.1)
    assert pc.integral[2] == pytest.approx(0.0 if frozen else vz_sp * 0.1)
    assert (out.thrust[2] >= -0.1 or out.thrust[2] <= -0.9) is (abs(vz_sp) > 0.1 or acc_ff != 0.0)


@pytest.mark.parametrize("direction", [(1.0, 0.0), (-0.6, 0.8)])
def test_vertical_thrust_has_priority_over_horizontal(direction):
    """Thrust at most 0.8 with 0.5 vertical: the horizontal part is cut to √(0.8² − 0.5²) in its direction."""
    pc = _pc(hover=0.5, tilt=math.radians(80))
    pc.set_thrust_limits(0.05, 0.8)
    a = 1.5 * GRAVITY                                 # asks 0.75 sideways
    out = _run(pc, TrajectorySetpoint(acceleration=(a * direction[0], a * direction[1], 0.0)))
    xy = math.sqrt(0.8 ** 2 - 0.5 ** 2)
    assert out.thrust == pytest.approx((xy * direction[0], xy * direction[1], -0.5), abs=1e-12)
    # vertical demand past the maximum: nothing left for horizontal
    out = _run(pc, TrajectorySetpoint(acceleration=(2.0, 1.0, -1.0 * GRAVITY)))
    assert out.thrust[:2] == (0.0, 0.0) and out.thrust[2] == pytest.approx(-1.0)


@pytest.mark.parametrize("kp", [(2.0, 2.5), (0.5, 0.0)])
def test_horizontal_integrator_tracks_the_thrust_it_got(kp):
    """Tracking anti-reset windup: I_xy += (e − (2/Kp_x)·(a_sp − a_produced))·Ki·dt, a_produced = T_xy·g/hover;
    without saturation a_produced = a_sp and it is the plain I += e·Ki·dt."""
    pc = _pc(hover=0.5, tilt=math.radians(80))
    pc.set_thrust_limits(0.05, 0.8)
    pc.set_velocity_gains((*kp, 4.0), (0.5, 0.5, 0.0), (0.0, 0.0, 0.0))
    vsp = (0.2, -0.1, 0.0)
    ff = (1.2 * GRAVITY, 0.9 * GRAVITY, 0.0)         # past what 0.8 of thrust gives sideways
    out = _run(pc, TrajectorySetpoint(velocity=vsp, acceleration=ff), dt=0.1)
    produced = [t * GRAVITY / 0.5 for t in out.thrust[:2]]
    want = [(vsp[i] - 2.0 / kp[0] * (out.acceleration[i] - produced[i])) * 0.5 * 0.1 for i in range(2)]
    assert pc.integral[:2] == pytest.approx(want, abs=1e-12)
    assert all(abs(w - vsp[i] * 0.05) > 0.01 for i, w in enumerate(want))      # the windup term mattered
    pc.reset_integral()
    _run(pc, TrajectorySetpoint(velocity=vsp, acceleration=(0.1, 0.0, 0.0)), dt=0.1)
    assert pc.integral[:2] == pytest.approx((vsp[0] * 0.05, vsp[1] * 0.05))


def test_desaturate_second_pass_along_a_non_unit_direction():
    u = [1.3, -0.05, 0.5, 0.5]
    # first: k = −0.3 + 0.05/0.5 = −0.2 → (1.1, −0.15, 0.4, 0.4); then k = −0.1 + 0.15/0.5 = 0.2, half of it
    _desaturate(u, (1.0, 0.5, 0.5, 0.5))
    assert u == pytest.approx([1.2, -0.1, 0.45, 0.45])


def test_no_windup_correction_without_a_proportional_gain_or_when_thrust_gives_more_than_asked():
    vsp = (0.2, -0.1, 0.0)
    # no P gain on x: the tracking gain 2/Kp is taken as 0, the integrator is plain even in saturation
    pc = _pc(hover=0.5, tilt=math.radians(80))
    pc.set_thrust_limits(0.05, 0.8)
    pc.set_velocity_gains((0.0, 2.0, 4.0), (0.5, 0.5, 0.0), (0.0, 0.0, 0.0))
    _run(pc, TrajectorySetpoint(velocity=vsp, acceleration=(1.2 * GRAVITY, 0.9 * GRAVITY, 0.0)), dt=0.1)
    assert pc.integral[:2] == pytest.approx((vsp[0] * 0.05, vsp[1] * 0.05))
    # falling faster than gravity, the thrust held at its minimum gives more sideways than asked: not a windup
    pc = _pc(hover=0.5)
    pc.set_thrust_limits(0.3, 0.9)
    pc.set_velocity_gains((2.0, 2.0, 4.0), (0.5, 0.5, 0.0), (0.0, 0.0, 0.0))
    out = _run(pc, TrajectorySetpoint(velocity=vsp, acceleration=(0.0, 0.0, 1.5 * GRAVITY)), dt=0.1)
    produced = [t * GRAVITY / 0.5 for t in out.thrust[:2]]
    assert math.hypot(*produced) > math.hypot(*out.acceleration[:2])
    assert pc.integral[:2] == pytest.approx((vsp[0] * 0.05, vsp[1] * 0.05))


def test_constrain_xy_more_hand_worked_cases():
    cxy = PositionControl._constrain_xy
    # v0 at the limit, v1 pointing back across: v0 is kept as it is (not mirrored to the circle's far side)
    assert cxy((3.0, 4.0), (-30.0, 0.0), 5.0) == pytest.approx((3.0, 4.0))
    # the sum exactly at the limit is taken as it is, even with v0 alone at the limit
    assert cxy((5.0, 0.0), (-1.0, 3.0), 5.0) == pytest.approx((4.0, 3.0))
    # v0 with both components: v1 along y adds until the circle, x stays 2.4
    assert cxy((2.4, 1.8), (0.0, 10.0), 5.0) == pytest.approx((2.4, math.sqrt(25.0 - 2.4 ** 2)))
    # a non-finite sum component is passed through at once
    sx, sy = cxy((1.0, NAN), (0.5, 0.0), 5.0)
    assert sx == 1.5 and math.isnan(sy)
