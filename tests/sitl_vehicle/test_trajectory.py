"""Trapezoid planner and velocity slew: shapes, continuity, no restart on identical targets."""

import math

import numpy as np
import pytest

from sitl_vehicle.trajectory import PlannerConfig, TrapezoidPlanner, VelocitySlew, plan_1d, sample_1d

NAN = float("nan")
CFG = PlannerConfig(v_max_xy=2.0, v_max_up=1.0, v_max_down=0.7, a_max_xy=3.0, a_max_z=2.0)


def profile(planner, t0, t1, dt=0.001):
    ts = np.arange(t0, t1, dt)
    out = [planner.sample(t) for t in ts]
    p = np.array([o[0] for o in out])
    v = np.array([o[1] for o in out])
    a = np.array([o[2] for o in out])
    return ts, p, v, a


def test_long_move_is_trapezoid_reaching_vmax():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((4.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0), (0.0, 0.0, 0.0))
    # accelerate 2/3 s, cruise (4 - 4/3)/2 s, decelerate 2/3 s
    assert pl.duration == pytest.approx(2 / 3 + (4 - 4 / 3) / 2 + 2 / 3)
    ts, p, v, a = profile(pl, 0.0, pl.duration + 0.5)
    speed = np.linalg.norm(v, axis=1)
    assert speed.max() == pytest.approx(2.0)
    cruise = speed > 2.0 - 1e-9
    assert cruise.sum() * 0.001 == pytest.approx((4 - 4 / 3) / 2, abs=0.003)
    assert np.max(np.abs(a[:, 0])) == pytest.approx(3.0)
    assert p[-1] == pytest.approx((4.0, 0.0, -1.0))
    assert np.all(np.abs(p[:, 1]) < 1e-12) and np.all(p[:, 2] == -1.0)


def test_short_move_is_triangular():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((0.5, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0))
    ts, p, v, a = profile(pl, 0.0, pl.duration + 0.2)
    vp = math.sqrt(3.0 * 0.5)  # peak of a triangle: v^2 = a * d
    assert v[:, 0].max() == pytest.approx(vp, rel=1e-3) and vp < 2.0
    assert pl.duration == pytest.approx(2 * vp / 3.0)
    assert p[-1, 0] == 0.5


def test_diagonal_and_vertical_limits_respect_axis_limits():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((3.0, 4.0, -6.0), 0.0, (0.0, 0.0, 0.0))  # climbing diagonal
    _, p, v, a = profile(pl, 0.0, pl.duration + 0.1, dt=0.005)
    assert np.max(np.hypot(v[:, 0], v[:, 1])) <= 2.0 + 1e-9
    assert np.max(-v[:, 2]) <= 1.0 + 1e-9 and np.max(v[:, 2]) <= 1e-9
    assert np.max(np.abs(a[:, 2])) <= 2.0 + 1e-9
    # straight line: every point on the segment
    d = np.array([3.0, 4.0, -6.0]) / np.linalg.norm([3.0, 4.0, -6.0])
    off = p - np.outer(p @ d, d)
    assert np.max(np.linalg.norm(off, axis=1)) < 1e-9


def test_identical_target_never_restarts():
    pl = TrapezoidPlanner(CFG)
    assert pl.set_target((2.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0))
    before = pl.sample(0.7)
    for k in range(1, 40):  # re-sent at 20 Hz
        assert not pl.set_target((2.0, 0.0, -1.0), k * 0.05, (9.0, 9.0, 9.0), (1.0, 1.0, 1.0))
    assert pl.restarts == 1
    assert pl.sample(0.7) == before


@pytest.mark.parametrize("new_target", [(2.0, 2.0, -1.0), (-1.0, 0.5, -1.5), (1.2, 0.0, -1.0), (4.0, 0.0, -1.0)])
def test_target_change_mid_flight_is_continuous(new_target):
    pl = TrapezoidPlanner(CFG)
    pl.set_target((2.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0))
    t_switch = 0.8  # cruising at 2 m/s
    p_before, v_before, _ = pl.sample(t_switch)
    assert pl.set_target(new_target, t_switch, (5.0, 5.0, 5.0), (0.0, 0.0, 0.0))  # state ignored: ref continues
    p_after, v_after, _ = pl.sample(t_switch)
    assert p_after == pytest.approx(p_before, abs=1e-12)
    assert v_after == pytest.approx(v_before, abs=1e-12)
    ts, p, v, a = profile(pl, t_switch, t_switch + pl.duration + 0.2, dt=0.0005)
    # no jumps: the reference is the sum of the on-line and the off-line (brake-and-return) profiles,
    # each within the per-axis limits, so per step |dv_xy| <= 2*a_max_xy*dt and |dv_z| <= 2*a_max_z*dt
    dt = 0.0005
    assert np.max(np.linalg.norm(np.diff(p, axis=0), axis=1)) < 2 * math.hypot(2.0, 1.0) * dt
    dv = np.diff(v, axis=0)
    assert np.max(np.hypot(dv[:, 0], dv[:, 1])) <= 2 * 3.0 * dt + 1e-9
    assert np.max(np.abs(dv[:, 2])) <= 2 * 2.0 * dt + 1e-9
    assert p[-1] == pytest.approx(new_target, abs=1e-9) and np.all(np.abs(v[-1]) < 1e-9)


def test_overshoot_when_target_is_closer_than_stopping_distance():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((4.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0))
    x_sw = pl.sample(1.0)[0][0]
    pl.set_target((x_sw + 0.1, 0.0, -1.0), 1.0)  # at 2 m/s the stop takes 0.67 m
    _, p, v, _ = profile(pl, 1.0, 1.0 + pl.duration + 0.1)
    assert p[:, 0].max() == pytest.approx(x_sw + 2.0 ** 2 / (2 * 3.0), abs=1e-3)
    assert p[-1, 0] == pytest.approx(x_sw + 0.1)


def test_nan_axes_are_not_planned():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1.0, 1.0, NAN), 0.0, (0.0, 0.0, -2.0), (0.0, 0.0, 0.5))
    p, v, a = pl.sample(0.3)
    assert math.isnan(p[2]) and math.isnan(v[2]) and math.isnan(a[2])
    assert p[0] > 0.0 and p[0] == pytest.approx(p[1])


def test_plan_1d_starts_with_given_velocity():
    for v0 in (-1.0, 0.0, 1.0, 3.0):
        segs, total = plan_1d(2.0, v0, 2.0, 3.0)
        x, v, _ = sample_1d(segs, total, 2.0, 0.0)
        assert x == 0.0 and v == v0
        assert sample_1d(segs, total, 2.0, total + 1.0) == (2.0, 0.0, 0.0)


def test_velocity_slew_is_acceleration_limited():
    s = VelocitySlew(CFG)
    dt = 0.01
    vs = []
    for _ in range(150):
        v, a = s.update((1.5, 1.5, -0.8), dt, (0.0, 0.0, 0.0))
        vs.append(v)
    vs = np.array(vs)
    dv = np.diff(np.vstack([[0.0, 0.0, 0.0], vs]), axis=0)
    assert np.max(np.hypot(dv[:, 0], dv[:, 1])) <= 3.0 * dt + 1e-12
    assert np.max(np.abs(dv[:, 2])) <= 2.0 * dt + 1e-12
    # the horizontal setpoint is clipped to v_max_xy, the climb to v_max_up
    assert np.hypot(*vs[-1, :2]) == pytest.approx(2.0) and vs[-1, 2] == pytest.approx(-0.8)
    v, _ = s.update((NAN, NAN, 0.0), dt)
    assert math.isnan(v[0]) and math.isnan(v[1])
