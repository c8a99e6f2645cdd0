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


# --- plan_1d / sample_1d: exact segments from the textbook formulas ---------------------------------------

def assert_segments(segs, expected):
    assert len(segs) == len(expected), segs
    for got, want in zip(segs, expected, strict=True):
        assert got == pytest.approx(want, abs=1e-12), (segs, expected)


def test_plan_1d_trapezoid_segments():
    # 0 -> 4 m, v_max 2, a_max 3: accelerate 2/3 s over 2/3 m, cruise 4/3 s, brake 2/3 s
    segs, total = plan_1d(4.0, 0.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 0.0, 3.0), (2 / 3, 2 / 3, 2.0, 0.0), (2.0, 4.0 - 2 / 3, 2.0, -3.0)])
    assert total == pytest.approx(2.0 + 2 / 3, abs=1e-12)
    # mirrored for a negative distance (and a negative start velocity)
    segs, total = plan_1d(-4.0, 0.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 0.0, -3.0), (2 / 3, -2 / 3, -2.0, 0.0), (2.0, -4.0 + 2 / 3, -2.0, 3.0)])
    assert total == pytest.approx(2.0 + 2 / 3, abs=1e-12)
    # starting at v_max: no acceleration segment
    segs, total = plan_1d(4.0, 2.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 2.0, 0.0), (5 / 3, 4.0 - 2 / 3, 2.0, -3.0)])
    assert total == pytest.approx(5 / 3 + 2 / 3, abs=1e-12)
    # mirrored with a start velocity: 1 -> 2 m/s in 1/3 s (0.5 m), cruise, brake 2/3 s (2/3 m)
    segs, total = plan_1d(-4.0, -1.0, 2.0, 3.0)
    cruise = (4.0 - 0.5 - 2 / 3) / 2.0
    assert_segments(segs, [(0.0, 0.0, -1.0, -3.0), (1 / 3, -0.5, -2.0, 0.0), (1 / 3 + cruise, -4.0 + 2 / 3, -2.0, 3.0)])
    assert total == pytest.approx(1 / 3 + cruise + 2 / 3, abs=1e-12)
    # a triangle from a start velocity: v_p^2 = a d + v0^2 / 2 (1 m at 1 m/s: v_p = sqrt(3.5) < 2)
    segs, total = plan_1d(1.0, 1.0, 2.0, 3.0)
    vp = math.sqrt(3.5)
    assert_segments(segs, [(0.0, 0.0, 1.0, 3.0), ((vp - 1.0) / 3, (vp * vp - 1.0) / 6, vp, -3.0)])
    assert total == pytest.approx((2 * vp - 1.0) / 3, abs=1e-12)
    # a triangle: d = 0.75 at a = 3 peaks at sqrt(a d) = 1.5 after 0.5 s
    segs, total = plan_1d(0.75, 0.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 0.0, 3.0), (0.5, 0.375, 1.5, -3.0)])
    assert total == pytest.approx(1.0, abs=1e-12)
    # exactly long enough to touch v_max (d = v^2 / a = 4/3): no cruise segment
    segs, total = plan_1d(4 / 3, 0.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 0.0, 3.0), (2 / 3, 2 / 3, 2.0, -3.0)])
    assert total == pytest.approx(4 / 3, abs=1e-12)


def test_plan_1d_brakes_an_opposite_or_excess_start_velocity():
    # moving away at 1 m/s: brake 1/3 s (to x = -1/6), then a triangle over 7/6 m: peak sqrt(3 * 7/6)
    segs, total = plan_1d(1.0, -1.0, 2.0, 3.0)
    vp = math.sqrt(3.5)
    assert_segments(segs, [(0.0, 0.0, -1.0, 3.0), (1 / 3, -1 / 6, 0.0, 3.0),
                           (1 / 3 + vp / 3, -1 / 6 + vp * vp / 6, vp, -3.0)])
    assert total == pytest.approx(1 / 3 + 2 * vp / 3, abs=1e-12)
    # too fast (3 m/s > v_max 2): slow down first (1/3 s over 5/6 m), then cruise and brake
    segs, total = plan_1d(10.0, 3.0, 2.0, 3.0)
    cruise = (10.0 - 5 / 6 - 2 / 3) / 2.0
    assert_segments(segs, [(0.0, 0.0, 3.0, -3.0), (1 / 3, 5 / 6, 2.0, 0.0),
                           (1 / 3 + cruise, 10.0 - 2 / 3, 2.0, -3.0)])
    assert total == pytest.approx(1 / 3 + cruise + 2 / 3, abs=1e-12)


def test_plan_1d_overshoots_when_it_cannot_stop_in_time():
    # 2 m/s with 0.1 m to go: brake 2/3 s to x = 2/3, then come back 0.5667 m (a triangle, peak sqrt(3 * 17/30))
    segs, total = plan_1d(0.1, 2.0, 2.0, 3.0)
    back = 2 / 3 - 0.1
    vp = math.sqrt(3.0 * back)
    assert_segments(segs, [(0.0, 0.0, 2.0, -3.0), (2 / 3, 2 / 3, 0.0, -3.0),
                           (2 / 3 + vp / 3, 2 / 3 - back / 2, -vp, 3.0)])
    assert total == pytest.approx(2 / 3 + 2 * vp / 3, abs=1e-12)
    # the stopping distance exactly the distance: no overshoot (a plain brake)
    segs, total = plan_1d(2 / 3, 2.0, 2.0, 3.0)
    assert_segments(segs, [(0.0, 0.0, 2.0, -3.0)])
    assert total == pytest.approx(2 / 3, abs=1e-12)
    # brake-and-return from a standing start at the goal: a velocity and no distance
    segs, total = plan_1d(0.0, 1.5, 2.0, 3.0)
    vp = math.sqrt(3.0 * 0.375)
    assert_segments(segs, [(0.0, 0.0, 1.5, -3.0), (0.5, 0.375, 0.0, -3.0), (0.5 + vp / 3, 0.375 / 2, -vp, 3.0)])
    assert total == pytest.approx(0.5 + 2 * vp / 3, abs=1e-12)
    # nothing to do
    assert plan_1d(0.0, 0.0, 2.0, 3.0) == ([], 0.0)


def test_plan_1d_profiles_end_at_rest_on_the_target():
    for dist, v0 in ((4.0, 0.0), (0.3, 0.0), (0.1, 2.0), (0.5, 2.0), (1.0, 1.0), (-4.0, -1.0), (1.0, -1.0),
                     (10.0, 3.0), (-2.0, 1.0), (0.0, -1.2), (5e-7, 0.0), (2.0, 2.5)):
        segs, total = plan_1d(dist, v0, 2.0, 3.0)
        t, x, v, a = segs[-1]
        dur = total - t
        assert x + v * dur + 0.5 * a * dur * dur == pytest.approx(dist, abs=1e-9)
        assert v + a * dur == pytest.approx(0.0, abs=1e-9)
        for (t0, x0, v0_, a0), (t1, x1, v1, _) in zip(segs, segs[1:], strict=False):  # continuous
            d = t1 - t0
            assert d > 0.0 and abs(a0) in (0.0, 3.0)
            assert x0 + v0_ * d + 0.5 * a0 * d * d == pytest.approx(x1, abs=1e-12)
            assert v0_ + a0 * d == pytest.approx(v1, abs=1e-12)
            assert abs(v1) <= 2.0 + 1e-12 or abs(v0_) > 2.0


def test_sample_1d_piecewise():
    segs = [(0.0, 0.0, 1.0, 0.0), (2.0, 2.0, 1.0, -0.5), (3.0, 2.75, 0.5, 0.25)]
    assert sample_1d(segs, 5.0, 9.0, 5.0) == (9.0, 0.0, 0.0)  # at the end time: the end, at rest
    assert sample_1d(segs, 5.0, 9.0, 7.0) == (9.0, 0.0, 0.0)
    assert sample_1d(segs, 5.0, 9.0, -1.0) == (0.0, 1.0, 0.0)  # before the start: the start
    assert sample_1d(segs, 5.0, 9.0, 0.0) == (0.0, 1.0, 0.0)
    assert sample_1d(segs, 5.0, 9.0, 1.5) == (1.5, 1.0, 0.0)
    assert sample_1d(segs, 5.0, 9.0, 2.0) == (2.0, 1.0, -0.5)  # a segment starts at its own time
    assert sample_1d(segs, 5.0, 9.0, 2.5) == (2.0 + 0.5 - 0.0625, 0.75, -0.5)
    assert sample_1d(segs, 5.0, 9.0, 4.0) == (2.75 + 0.5 + 0.125, 0.75, 0.25)
    assert sample_1d([], 0.0, 3.0, 0.0) == (3.0, 0.0, 0.0)
    assert sample_1d([], 1.0, 3.0, 0.5) == (3.0, 0.0, 0.0)  # no segments: already there
    # a profile whose first segment starts later than 0 (the later segments are picked by their start)
    late = [(1.0, 0.0, 2.0, 0.0), (2.0, 2.0, 2.0, -1.0)]
    single = [(0.0, 0.0, 2.0, -3.0)]  # one segment (a plain brake)
    assert sample_1d(single, 2 / 3, 2 / 3, 1 / 3) == (2 / 3 - 1 / 6, 1.0, -3.0)
    assert sample_1d(late, 4.0, 4.0, 3.0) == (2.0 + 2.0 - 0.5, 1.0, -1.0)


# --- TrapezoidPlanner: defaults, limits per direction, retargeting, brake-and-return -------------------------

def test_defaults_and_idle_state():
    c = PlannerConfig()
    assert (c.v_max_xy, c.v_max_up, c.v_max_down, c.a_max_xy, c.a_max_z, c.retarget_tolerance_m) == \
        (2.0, 1.0, 0.7, 3.0, 2.0, 1e-3)
    pl = TrapezoidPlanner()
    assert pl.config == PlannerConfig()
    assert pl.target is None and not pl.active and pl.duration == 0.0 and pl.restarts == 0
    assert not pl.is_same_target((0.0, 0.0, 0.0))
    for vec in pl.sample(1.0):
        assert len(vec) == 3 and all(math.isnan(c) for c in vec)
    s = VelocitySlew()
    assert s.config == PlannerConfig()
    assert all(math.isnan(c) for c in s.v_ref) and s.a_ref == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="^the first target needs the current position p_now$"):
        pl.set_target((1.0, 0.0, 0.0), 0.0)


def test_clear_forgets_the_target():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0))
    assert pl.active and pl.target == (1.0, 0.0, -1.0)
    pl.clear()
    assert not pl.active and pl.target is None
    assert all(math.isnan(c) for c in pl.sample(0.5)[0])
    with pytest.raises(ValueError, match="p_now"):  # the next target starts from the state again
        pl.set_target((1.0, 0.0, -1.0), 1.0)
    assert pl.set_target((1.0, 0.0, -1.0), 1.0, (0.0, 0.0, -1.0))  # the same target after clear: replanned
    assert pl.restarts == 2


def test_set_config_applies_to_the_next_plan_only():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((4.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    d0 = pl.duration
    slow = PlannerConfig(v_max_xy=1.0, a_max_xy=1.0)
    pl.set_config(slow)
    assert pl.config == slow and pl.duration == d0 and pl.sample(1.0)[1][0] == pytest.approx(2.0)
    pl.set_target((0.0, 0.0, 0.0), d0, (0.0, 0.0, 0.0))  # at rest on (4, 0, 0): back at 1 m/s, 1 m/s^2
    assert pl.duration == pytest.approx(1.0 + 3.0 + 1.0)
    assert pl.sample(d0 + 2.0)[1][0] == pytest.approx(-1.0)


def test_replan_takes_the_move_under_way_to_new_limits_without_a_jump():
    pl = TrapezoidPlanner(CFG)
    assert not pl.replan(0.0)                                           # idle: nothing to plan again
    pl.set_target((20.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    p1, v1, _ = pl.sample(3.0)
    assert v1[0] == pytest.approx(2.0)                                  # cruising at MPC_XY_CRUISE
    pl.set_config(PlannerConfig(v_max_xy=0.5, a_max_xy=3.0))
    assert pl.replan(3.0) and pl.target == (20.0, 0.0, 0.0) and pl.restarts == 2
    p2, v2, _ = pl.sample(3.0)
    assert p2 == pytest.approx(p1) and v2 == pytest.approx(v1)         # the reference continues from where it was
    assert pl.sample(3.0 + 1.5 / 3.0)[1][0] == pytest.approx(0.5)      # braked to the new speed at a_max
    assert pl.sample(3.0 + pl.duration)[0] == pytest.approx((20.0, 0.0, 0.0))


def test_the_retarget_tolerance_is_per_axis_and_nan_aware():
    pl = TrapezoidPlanner(PlannerConfig(retarget_tolerance_m=0.5))
    pl.set_target((1.0, 2.0, -1.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.is_same_target((1.5, 1.5, -1.5))  # 0.5 off on every axis: still the same
    assert not pl.is_same_target((1.5000001, 2.0, -1.0))
    assert not pl.is_same_target((1.0, 2.0, -0.4999999))
    assert not pl.is_same_target((1.0, 2.0, NAN))
    assert not pl.set_target((1.25, 2.25, -1.25), 0.5)
    assert pl.set_target((1.0, 2.0, NAN), 0.5) and pl.restarts == 2
    assert pl.is_same_target((1.0, 2.0, NAN)) and pl.is_same_target((1.4, 2.0, NAN))
    assert not pl.is_same_target((1.0, 2.0, -1.0))


def test_vertical_limits_depend_on_the_direction():
    # descend 2 m: v_max_down 0.7, a_max_z 2: accelerate 0.35 s over 0.1225 m each way, cruise the rest
    pl = TrapezoidPlanner(CFG)
    pl.set_target((0.0, 0.0, 0.0), 0.0, (0.0, 0.0, -2.0))
    assert pl.duration == pytest.approx(0.7 + (2.0 - 0.245) / 0.7)
    assert pl.sample(1.0)[1] == pytest.approx((0.0, 0.0, 0.7)) and pl.sample(0.1)[2] == pytest.approx((0, 0, 2.0))
    # climb 2 m: v_max_up 1.0: accelerate 0.5 s over 0.25 m each way
    pl = TrapezoidPlanner(CFG)
    pl.set_target((0.0, 0.0, -2.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.duration == pytest.approx(1.0 + 1.5 / 1.0)
    assert pl.sample(1.0)[1] == pytest.approx((0.0, 0.0, -1.0)) and pl.sample(0.1)[2] == pytest.approx((0, 0, -2.0))
    # a descending diagonal (0.6, 0, 0.8): speed along it limited by the descent, 0.7 / 0.8 = 0.875 m/s,
    # acceleration by the vertical a_max 2 / 0.8 = 2.5 (the horizontal allows 3 / 0.6 = 5)
    pl = TrapezoidPlanner(CFG)
    pl.set_target((3.0, 0.0, 4.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.sample(0.1)[2] == pytest.approx((2.5 * 0.6, 0.0, 2.5 * 0.8))
    assert pl.sample(3.0)[1] == pytest.approx((0.875 * 0.6, 0.0, 0.875 * 0.8))
    assert pl.duration == pytest.approx(0.875 / 2.5 + 5.0 / 0.875)
    # the same climbing: 1.0 / 0.8 = 1.25 m/s
    pl = TrapezoidPlanner(CFG)
    pl.set_target((3.0, 0.0, -4.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.sample(3.0)[1] == pytest.approx((1.25 * 0.6, 0.0, -1.25 * 0.8))
    # horizontal (0.6, 0.8, 0): the horizontal limits along the line
    pl = TrapezoidPlanner(CFG)
    pl.set_target((3.0, 4.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.sample(1.0)[1] == pytest.approx((1.2, 1.6, 0.0)) and pl.sample(0.1)[2] == pytest.approx((1.8, 2.4, 0))
    assert pl.duration == pytest.approx(2 / 3 + (5.0 - 4 / 3) / 2.0 + 2 / 3)


def test_brake_and_return_of_the_sideways_start_velocity():
    """A start velocity across the line is braked with a_max and its offset brought back to zero."""
    pl = TrapezoidPlanner(CFG)
    # line along x (4 m), start moving 1.5 m/s along +y: brake 0.5 s (offset 0.375 m), return as a triangle
    pl.set_target((4.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0), (0.0, 1.5, 0.0))
    _, p, v, a = profile(pl, 0.0, pl.duration + 0.01, dt=0.0025)
    assert v[0] == pytest.approx((0.0, 1.5, 0.0)) and a[0] == pytest.approx((3.0, -3.0, 0.0))
    assert p[:, 1].max() == pytest.approx(0.375, abs=1e-5)
    assert pl.sample(0.5)[0][1] == pytest.approx(0.375)
    vp = math.sqrt(3.0 * 0.375)
    assert np.min(v[:, 1]) >= -vp - 1e-12
    assert pl.sample(0.5 + vp / 3.0)[1][1] == pytest.approx(-vp, abs=1e-12)  # the return's peak speed
    assert pl.duration == pytest.approx(2 / 3 + (4 - 4 / 3) / 2 + 2 / 3)  # the line takes longer
    assert p[-1] == pytest.approx((4.0, 0.0, -1.0), abs=1e-12)
    # a short line with a fast sideways start: the return takes longer than the line
    pl = TrapezoidPlanner(CFG)
    pl.set_target((0.01, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0), (0.0, 2.0, 0.0))
    off = 4.0 / 6.0
    assert pl.duration == pytest.approx(2 / 3 + 2 * math.sqrt(3.0 * off) / 3.0)
    assert pl.sample(2 / 3)[0] == pytest.approx((0.01, off, -1.0), abs=1e-9)
    # vertical sideways velocity (line along x, moving down at 2 m/s): braked with a_max_z and returned at
    # the smaller vertical speed limit, min(v_max_up, v_max_down) = 0.7 m/s (1 m back up)
    pl = TrapezoidPlanner(CFG)
    pl.set_target((0.01, 0.0, -5.0), 0.0, (0.0, 0.0, -5.0), (0.0, 0.0, 2.0))
    _, p, v, a = profile(pl, 0.0, pl.duration + 0.01, dt=0.0025)
    assert a[0] == pytest.approx((3.0, 0.0, -2.0))
    assert p[:, 2].max() == pytest.approx(-4.0, abs=1e-5)  # 2^2 / (2 * 2) = 1 m down
    assert np.min(v[:, 2]) == pytest.approx(-0.7, abs=1e-9)
    assert pl.duration == pytest.approx(1.0 + 0.35 + (1.0 - 0.245) / 0.7 + 0.35)
    # a horizontal-and-vertical sideways velocity: the same limits, scaled to its direction
    pl = TrapezoidPlanner(CFG)
    pl.set_target((5.0, 0.0, -5.0), 0.0, (0.0, 0.0, -5.0), (0.0, 0.3, 0.4))
    ep = np.array([0.0, 0.6, 0.8])
    assert pl.sample(0.0)[2] == pytest.approx(tuple(3.0 * np.array([1, 0, 0]) - 2.5 * ep))  # a_max_z / 0.8


def test_sample_snaps_to_the_target_at_the_end_and_holds():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1.0 / 3.0, 0.1, -1.7), 2.0, (0.0, 0.0, -1.0))
    end = 2.0 + pl.duration
    for t in (end, end + 5.0):
        p, v, a = pl.sample(t)
        assert p == (1.0 / 3.0, 0.1, -1.7) and v == (0.0, 0.0, 0.0) and a == (0.0, 0.0, 0.0)
    p, v, _ = pl.sample(2.0)  # the plan starts at the time given
    assert p == pytest.approx((0.0, 0.0, -1.0)) and v == (0.0, 0.0, 0.0)
    assert pl.sample(1.0)[0] == pytest.approx((0.0, 0.0, -1.0))


def test_unplanned_axes_continue_from_the_state_when_they_become_planned():
    pl = TrapezoidPlanner(CFG)
    assert pl.set_target((1.0, 0.0, NAN), 0.0, (0.0, 0.0, -2.0), (0.0, 0.0, 0.4))
    p, v, a = pl.sample(0.2)
    assert math.isnan(p[2]) and math.isnan(v[2]) and math.isnan(a[2])
    assert p[1] == 0.0 and v[1] == 0.0  # the planned axes: no sideways motion (z's velocity is not planned)
    assert pl.duration == pytest.approx(2 * math.sqrt(1.0 / 3.0))
    # now z gets a target: it starts from the state's z and vertical velocity given now
    p_sw, v_sw, _ = pl.sample(0.3)
    assert pl.set_target((1.0, 0.0, -3.0), 0.3, (9.0, 9.0, -2.5), (9.0, 9.0, 0.0))
    p, v, _ = pl.sample(0.3)
    assert p == pytest.approx((p_sw[0], p_sw[1], -2.5), abs=1e-12)
    assert v == pytest.approx((v_sw[0], v_sw[1], 0.0), abs=1e-12)
    pl2 = TrapezoidPlanner(CFG)
    pl2.set_target((1.0, 0.0, NAN), 0.0, (0.0, 0.0, -2.0))
    pl2.set_target((1.0, 0.0, -3.0), 0.3, (9.0, 9.0, -2.5), (9.0, 9.0, -0.6))
    assert pl2.sample(0.3)[1][2] == pytest.approx(-0.6, abs=1e-12)
    # without a state the newly planned axis starts at 0
    pl3 = TrapezoidPlanner(CFG)
    pl3.set_target((1.0, 0.0, NAN), 0.0, (0.0, 0.0, -2.0))
    pl3.set_target((1.0, 0.0, -3.0), 0.3)
    assert pl3.sample(0.3)[0][2] == 0.0 and pl3.sample(0.3)[1][2] == 0.0
    # a NaN in the start velocity counts as 0, and an unplanned axis's velocity is dropped from the plan
    pl4 = TrapezoidPlanner(CFG)
    pl4.set_target((2.0, 0.0, -1.0), 0.0, (0.0, 0.0, -1.0), (NAN, 1.0, NAN))
    assert pl4.sample(0.0)[1] == pytest.approx((0.0, 1.0, 0.0))
    pl5 = TrapezoidPlanner(CFG)
    pl5.set_target((2.0, 0.0, NAN), 0.0, (0.0, 0.0, -1.0), (0.5, 0.0, 3.0))  # z's 3 m/s: not braked in the plan
    assert pl5.sample(0.0)[1][:2] == pytest.approx((0.5, 0.0))
    assert pl5.duration == pytest.approx(plan_1d(2.0, 0.5, 2.0, 3.0)[1])
    assert pl5.target == (2.0, 0.0, NAN) or math.isnan(pl5.target[2])


def test_targets_accept_any_number_types():
    pl = TrapezoidPlanner(CFG)
    assert pl.set_target(np.array([1, 0, -1]), 0, [0, 0, -1], np.zeros(3))
    assert pl.target == (1.0, 0.0, -1.0) and all(type(c) is float for c in pl.target)
    p, _, _ = pl.sample(pl.duration)
    assert p == (1.0, 0.0, -1.0)


def test_a_zero_length_move_is_immediately_done():
    pl = TrapezoidPlanner(CFG)
    assert pl.set_target((1.0, 2.0, -1.0), 0.0, (1.0, 2.0, -1.0))
    assert pl.duration == 0.0
    assert pl.sample(0.0) == ((1.0, 2.0, -1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


# --- VelocitySlew ----------------------------------------------------------------------------------------------

def test_velocity_slew_steps_exactly():
    s = VelocitySlew(CFG)
    dt = 0.1
    # within one step's reach (a_max_xy dt = 0.3 as a vector, a_max_z dt = 0.2): reached at once
    v, a = s.update((0.1, 0.2, 0.1), dt, (0.0, 0.0, 0.0))
    assert v == pytest.approx((0.1, 0.2, 0.1)) and a == pytest.approx((1.0, 2.0, 1.0))
    assert s.v_ref == v and s.a_ref == a
    # beyond it: a step of 0.3 along the horizontal change, 0.2 vertically
    s = VelocitySlew(CFG)
    v, a = s.update((1.2, 1.6, 0.5), dt, (0.0, 0.0, 0.0))
    assert v == pytest.approx((0.18, 0.24, 0.2)) and a == pytest.approx((1.8, 2.4, 2.0))
    v, a = s.update((0.18, 0.24, -0.5), dt)  # back down: -0.2 per step
    assert v == pytest.approx((0.18, 0.24, 0.0)) and a == pytest.approx((0.0, 0.0, -2.0))
    # starts from the current velocity when nothing was controlled before
    s = VelocitySlew(CFG)
    v, _ = s.update((1.0, 0.0, 0.0), dt, (0.9, -0.1, 0.05))
    assert v == pytest.approx((1.0, 0.0, 0.0))
    # the horizontal setpoint scaled to v_max_xy as a vector, the vertical clipped to up / down limits
    s = VelocitySlew(CFG)
    v, _ = s.update((3.0, 4.0, -5.0), 10.0, (0.0, 0.0, 0.0))
    assert v == pytest.approx((1.2, 1.6, -1.0))
    v, _ = s.update((0.0, -1.0, 5.0), 10.0)
    assert v == pytest.approx((0.0, -1.0, 0.7))
    v, _ = s.update((1.0, 1.0, 0.7), 10.0)  # |(1, 1)| = 1.41 < 2: not scaled
    assert v == pytest.approx((1.0, 1.0, 0.7))


def test_velocity_slew_nan_axes_and_reset():
    s = VelocitySlew(CFG)
    v, a = s.update((1.0, NAN, 0.3), 0.1, (0.0, 0.0, 0.2))  # x without y is not a horizontal setpoint
    assert math.isnan(v[0]) and math.isnan(v[1]) and math.isnan(a[0]) and math.isnan(a[1])
    assert v[2] == pytest.approx(0.3) and a[2] == pytest.approx(1.0)
    v, a = s.update((NAN, 1.0, NAN), 0.1, (0.0, 0.0, 0.2))
    assert all(math.isnan(c) for c in v + a)
    # an axis that becomes controlled starts from the current velocity
    v, _ = s.update((0.5, 0.5, 0.0), 0.1, (0.4, 0.45, -0.1))
    assert v == pytest.approx((0.5, 0.5, 0.0))
    s.reset((0.1, 0.2, 0.3))
    assert s.v_ref == (0.1, 0.2, 0.3) and s.a_ref == (0.0, 0.0, 0.0)
    v, _ = s.update((0.1, 0.2, 0.3), 0.1, (5.0, 5.0, 5.0))  # continues from the reset value, not the state
    assert v == pytest.approx((0.1, 0.2, 0.3))
    s.reset(np.array([1, 2, 3]))
    assert s.v_ref == (1.0, 2.0, 3.0) and all(type(c) is float for c in s.v_ref)
    s.reset()
    assert all(math.isnan(c) for c in s.v_ref) and s.a_ref == (0.0, 0.0, 0.0)
    v, _ = s.update((0.0, 0.0, 0.0), 0.1, (0.05, 0.0, -0.1))
    assert v == pytest.approx((0.0, 0.0, 0.0))


def test_a_3d_diagonal_move_and_start_velocities_along_and_across_it():
    # (2, 1, -2): 3 m along e = (2, 1, -2) / 3; speed limited by the climb (1.0 / (2/3) = 1.5), acceleration by
    # the vertical a_max (2 / (2/3) = 3): accelerate 0.5 s over 0.375 m each way, cruise 2.25 m in 1.5 s
    e = np.array([2.0, 1.0, -2.0]) / 3.0
    pl = TrapezoidPlanner(CFG)
    pl.set_target((2.0, 1.0, -3.0), 0.0, (0.0, 0.0, -1.0))
    assert pl.duration == pytest.approx(2.5, abs=1e-12)
    assert pl.sample(1.0)[1] == pytest.approx(tuple(1.5 * e), abs=1e-12)
    assert pl.sample(0.25)[2] == pytest.approx(tuple(3.0 * e), abs=1e-12)
    # starting at cruise speed along the line: no acceleration phase, nothing across it
    pl = TrapezoidPlanner(CFG)
    pl.set_target((2.0, 1.0, -3.0), 0.0, (0.0, 0.0, -1.0), tuple(1.5 * e))
    assert pl.duration == pytest.approx((3.0 - 0.375) / 1.5 + 0.5, abs=1e-12)  # cruise, then brake
    assert pl.sample(0.0)[2] == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # moving across the line, ep = (1, 2, 2) / 3 at 0.9 m/s: braked with min(3 / |ep_xy|, 2 / (2/3)) = 3 m/s^2
    # in 0.3 s over 0.135 m while the line accelerates at 3 m/s^2
    ep = np.array([1.0, 2.0, 2.0]) / 3.0
    pl = TrapezoidPlanner(CFG)
    pl.set_target((2.0, 1.0, -3.0), 0.0, (0.0, 0.0, -1.0), tuple(0.9 * ep))
    assert pl.sample(0.0)[1] == pytest.approx(tuple(0.9 * ep), abs=1e-12)
    assert pl.sample(0.0)[2] == pytest.approx(tuple(3.0 * e - 3.0 * ep), abs=1e-12)
    p = np.array(pl.sample(0.3)[0])
    assert p == pytest.approx(tuple(np.array([0.0, 0.0, -1.0]) + 0.135 * e + 0.135 * ep), abs=1e-12)
    assert pl.duration == pytest.approx(2.5, abs=1e-12)


def test_a_zero_length_move_brakes_and_returns_every_velocity_component():
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1.0, 2.0, -1.0), 0.0, (1.0, 2.0, -1.0), (0.3, -0.4, 0.2))
    assert pl.sample(0.0)[1] == pytest.approx((0.3, -0.4, 0.2), abs=1e-12)
    assert pl.duration > 0.0
    assert pl.sample(pl.duration)[0] == (1.0, 2.0, -1.0)


def test_the_thresholds_for_no_move_and_no_sideways_velocity_are_exclusive():
    # a move of exactly 1e-9 m counts as none (no line profile) ...
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1e-9, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    assert pl.duration == 0.0
    # ... and a sideways velocity of exactly 1e-9 m/s is dropped
    pl = TrapezoidPlanner(CFG)
    pl.set_target((1.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), (0.0, 1e-9, 0.0))
    assert pl.sample(0.0)[1] == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_sideways_velocity_against_an_axis_is_braked_and_returned(axis):
    """A start velocity of -0.8 m/s across the line, along each axis in turn (the line along another axis):
    braked with that axis's a_max, it peaks at v^2 / (2 a) on the negative side and returns to 0."""
    line = [0.0, 0.0, 0.0]
    line[(axis + 1) % 3] = 2.0
    v0 = [0.0, 0.0, 0.0]
    v0[axis] = -0.8
    amax = 2.0 if axis == 2 else 3.0
    pl = TrapezoidPlanner(CFG)
    pl.set_target(tuple(np.array([0.0, 0.0, -5.0]) + line), 0.0, (0.0, 0.0, -5.0), tuple(v0))
    assert pl.sample(0.0)[1][axis] == pytest.approx(-0.8, abs=1e-12)
    assert pl.sample(0.0)[2][axis] == pytest.approx(amax, abs=1e-12)
    p = pl.sample(0.8 / amax)[0]  # at rest across the line: the furthest out
    assert p[axis] - (-5.0 if axis == 2 else 0.0) == pytest.approx(-0.64 / (2 * amax), abs=1e-12)
