"""The servo law: the corrected lateral sign, clamps, push conditions, and convergence from both sides."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.servo import ServoConfig, heading_to_ned, normalised_error, push_length, push_waypoints, servo_step

W, H = 320, 240
F = 156.4  # px: the default camera, vertical FOV 75° over 240 px


def test_normalised_error_is_zero_at_the_centre_and_one_at_the_edges():
    assert normalised_error((160, 120), W, H) == (0.0, 0.0)
    assert normalised_error((320, 0), W, H) == (1.0, -1.0)


@pytest.mark.parametrize("u, sign", [(240, +1), (80, -1)])
def test_gap_right_of_centre_moves_right(u, sign):
    # docs/design.md step 5: Δy = +κ_y·e_u (the paper's printed minus sign flies away from the gap).
    step = servo_step((u, 120), 0.02, 0, W, H)
    assert math.copysign(1, step.delta_heading[1]) == sign and step.delta_heading[2] == 0.0


def test_gap_below_centre_moves_down_in_ned():
    assert servo_step((160, 200), 0.02, 0, W, H).delta_heading[2] > 0


def test_lateral_step_is_clamped_far_and_close():
    cfg = ServoConfig()
    far = servo_step((320, 0), 0.01, 0, W, H, cfg)
    close = servo_step((320, 0), 0.5, 0, W, H, cfg)
    assert far.delta_heading[1:] == (cfg.lateral_clamp_far_m, -cfg.lateral_clamp_far_m)
    assert close.delta_heading[1:] == (cfg.lateral_clamp_close_m, -cfg.lateral_clamp_close_m) and close.close
    # Far off-axis (|e| = 1): the forward step shrinks so the clamped lateral step can catch up.
    assert far.delta_heading[0] == pytest.approx(cfg.forward_step_m * cfg.min_forward_frac)
    assert servo_step((160, 120), 0.01, 0, W, H, cfg).delta_heading[0] == cfg.forward_step_m


def test_no_centroid_moves_straight_forward():
    step = servo_step(None, 0.0, 0, W, H)
    assert step.delta_heading == (ServoConfig().forward_step_m, 0.0, 0.0) and step.error is None and not step.push


@pytest.mark.parametrize("centroid, area, index, wall, push", [
    ((160, 120), 0.25, 3, None, True),  # centred and large
    ((250, 120), 0.25, 3, None, False),  # large but not centred
    ((160, 120), 0.05, 3, None, False),  # centred but small and far
    ((160, 120), 0.05, 3, 1.3, True),  # centred, wall measured close
    ((160, 120), 0.05, 3, 1.6, False),  # centred, wall not yet close
    ((250, 120), 0.05, 3, 1.0, True),  # the wall this close: push whatever the centring
    ((250, 120), 0.05, 29, None, True),  # step budget (30) spent
    ((250, 120), 0.05, 15, None, False),  # the paper's 16 is not a push any more: closeness decides
])
def test_push_conditions(centroid, area, index, wall, push):
    assert servo_step(centroid, area, index, W, H, wall_distance_m=wall).push is push


@pytest.mark.parametrize("yaw_deg, forward_ned, right_ned", [
    (0.0, (1.0, 0.0), (0.0, 1.0)),        # facing north, the right hand points east
    (90.0, (0.0, 1.0), (-1.0, 0.0)),      # facing east, south
    (180.0, (-1.0, 0.0), (0.0, -1.0)),    # facing south, west
    (-90.0, (0.0, -1.0), (1.0, 0.0)),     # facing west, north
])
def test_heading_steps_turn_into_ned_by_the_compass(yaw_deg, forward_ned, right_ned):
    yaw = math.radians(yaw_deg)
    assert heading_to_ned((1.0, 0.0, 0.2), yaw) == pytest.approx((*forward_ned, 0.2), abs=1e-12)
    assert heading_to_ned((0.0, 1.0, -0.1), yaw) == pytest.approx((*right_ned, -0.1), abs=1e-12)


def test_a_heading_step_at_any_yaw_keeps_its_length_and_puts_right_90_degrees_clockwise_of_forward():
    for yaw in np.linspace(-math.pi, math.pi, 13):
        f, r = 0.3, -0.2
        n, e, d = heading_to_ned((f, r, 0.05), yaw)
        assert math.hypot(n, e) == pytest.approx(math.hypot(f, r)) and d == 0.05
        # the forward and right parts, each on its own, seen as compass bearings (clockwise from north)
        fn, fe, _ = heading_to_ned((1.0, 0.0, 0.0), yaw)
        rn, re, _ = heading_to_ned((0.0, 1.0, 0.0), yaw)
        assert math.remainder(math.atan2(fe, fn) - yaw, math.tau) == pytest.approx(0.0, abs=1e-12)
        assert math.remainder(math.atan2(re, rn) - (yaw + math.pi / 2), math.tau) == pytest.approx(0.0, abs=1e-12)
        assert (n, e) == pytest.approx((f * fn + r * rn, f * fe + r * re))


def test_push_waypoints_are_005_m_increments_with_the_bias_spread_over_the_first_half():
    points = push_waypoints((0.0, 0.0, -1.5), 0.0, 1.0, (0.1, -0.05))  # 0.1 is clamped to 0.06
    assert len(points) == 20
    steps = [math.dist(a, b) for a, b in zip([(0.0, 0.0, -1.5)] + points[:-1], points, strict=True)]
    assert points[-1] == pytest.approx((1.0, 0.06, -1.55))
    assert all(s >= 0.05 - 1e-9 for s in steps) and points[10][1:] == pytest.approx(points[-1][1:])


def test_push_length_passes_the_wall_but_stops_short_of_what_is_behind():
    cfg = ServoConfig()
    assert push_length(1.0, cfg) == pytest.approx(1.0 + cfg.wall_thickness_m + cfg.push_margin_m)
    assert push_length(None, cfg) == cfg.push_default_m and push_length(-1.0, cfg) == cfg.push_default_m


@pytest.mark.parametrize("y0, z0", [(-0.5, 0.0), (0.5, 0.0), (0.3, -0.3), (-0.4, 0.25)])
def test_closed_loop_converges_from_either_side(y0, z0):
    """A pinhole camera looking at a gap centre 3 m ahead: the law drives the offset toward zero."""
    gap = (3.0, 0.0, -1.5)
    p = [0.0, y0, -1.5 + z0]
    for k in range(30):
        dx = gap[0] - p[0]
        u = W / 2 + F * (gap[1] - p[1]) / dx
        v = H / 2 + F * (gap[2] - p[2]) / dx
        area = min(0.9, (F * 0.9 / dx) ** 2 / (W * H))  # a 0.9 m window
        step = servo_step((u, v), area, k, W, H)
        d = heading_to_ned(step.delta_heading, 0.0)
        p = [p[0] + d[0], p[1] + d[1], p[2] + d[2]]
        if step.push:
            break
    assert abs(p[1] - gap[1]) < 0.1 and abs(p[2] - gap[2]) < 0.1, f"ended at {p}"
    assert abs(p[1] - gap[1]) < abs(y0) or y0 == 0


# --- the metric law: offsets in metres once the wall's distance is measured ---------------------------------

def test_metric_offset_is_the_pixel_offset_at_the_wall_distance():
    from companion.servo import metric_offset

    # 80 px right of centre at 2 m with a 160 px focal length: 1 m right; 60 px up: 0.75 m up
    assert metric_offset((0.5, -0.5), W, H, 160.0, 2.0) == pytest.approx((1.0, -0.75))


def test_metric_step_removes_most_of_the_offset_and_holds_off_the_wall_until_the_sphere_clears():
    from companion.servo import alignment_tolerance, metric_step

    cfg = ServoConfig()
    # a 0.9 m opening: clear radius 0.45 m, so the centre may be 0.45 - 0.19 - 0.05 = 0.21 m off
    assert alignment_tolerance(0.45, cfg) == pytest.approx(0.45 - cfg.body_radius_m - cfg.clearance_margin_m)
    far_off = metric_step((0.3, -0.1), 0.45, 1.15, 0.05, 5, cfg)
    assert far_off.delta_heading[1:] == pytest.approx((cfg.metric_gain * 0.3, -cfg.metric_gain * 0.1))
    assert far_off.aligned is False and not far_off.push
    assert far_off.delta_heading[0] == pytest.approx(1.15 - cfg.hold_distance_m)   # no closer than 1.1 m
    held = metric_step((0.3, 0.0), 0.45, 1.05, 0.05, 5, cfg)
    assert held.delta_heading[0] == 0.0 and not held.push
    big = metric_step((2.0, -2.0), 0.45, 2.0, 0.01, 5, cfg)
    assert big.delta_heading[1:] == (cfg.metric_max_step_m, -cfg.metric_max_step_m)
    centred = metric_step((0.05, 0.02), 0.45, 1.3, 0.1, 5, cfg, clearance_here_m=0.45 - math.hypot(0.05, 0.02))
    assert centred.aligned and centred.push and centred.delta_heading[0] > 0
    # aligned by the tracked place alone, not seen in this frame, and only just fitting: no push; creep on to
    # see it again; with room to spare, push on the tracked place
    unseen = metric_step((0.05, 0.02), 0.30, 1.3, 0.1, 5, cfg)
    assert unseen.aligned and not unseen.push and unseen.delta_heading[0] == pytest.approx(cfg.probe_step_m)
    assert metric_step((0.05, 0.02), 0.30, 0.85, 0.1, 5, cfg).delta_heading[0] == 0.0   # not that close
    assert metric_step((0.05, 0.02), 0.45, 1.3, 0.1, 5, cfg, sightings=3).push
    assert not metric_step((0.05, 0.02), 0.45, 1.3, 0.1, 5, cfg, sightings=2).push    # placed too few times
    # held still, a frame pair would show no parallax: step back (the next step comes forward again)
    still = metric_step((0.01, 0.0), 0.30, 0.85, 0.1, 5, cfg)
    assert still.delta_heading[0] == pytest.approx(-cfg.probe_step_m) and not still.push
    # centred but far from a small-looking wall: move on, do not push yet
    approach = metric_step((0.05, 0.02), 0.45, 2.5, 0.05, 5, cfg)
    assert approach.aligned and not approach.push and approach.delta_heading[0] == pytest.approx(
        cfg.forward_step_m * (1 - math.hypot(0.05, 0.02) / cfg.metric_slowdown_m))


def test_the_metric_law_never_pushes_a_sphere_that_would_not_clear():
    from companion.servo import metric_step

    cfg = ServoConfig()
    spent = metric_step((0.3, 0.0), 0.45, 1.1, 0.3, cfg.step_budget - 1, cfg)
    assert not spent.push and spent.aligned is False      # the budget is spent, but pushing would touch
    assert metric_step((0.02, 0.0), 0.45, 1.5, 0.05, cfg.step_budget - 1, cfg, clearance_here_m=0.43).push
    # seen from where it is: the clearance flying straight on decides, not the offset to the clear centre
    slot = metric_step((0.3, 0.0), 0.25, 1.2, 0.3, 5, cfg, clearance_here_m=0.25)
    assert slot.aligned and slot.push        # 0.3 m along a long slot, as much room as at its middle
    narrow = metric_step((0.0, 0.0), 0.2, 1.2, 0.3, 5, cfg)  # 0.4 m across: no offset is good enough
    assert narrow.tolerance_m < 0 and not narrow.push and narrow.aligned is False


def test_metric_servo_converges_on_a_far_off_axis_opening_before_the_wall():
    """The failure it fixes: an opening 0.9 m to the side, reached at 45° by the paper's law (κ·e is too small
    a step close to the wall); the metric law centres first, then pushes."""
    from companion.servo import metric_step

    cfg = ServoConfig()
    gap = (3.0, 0.9, -1.5)
    p = [1.5, 0.0, -1.5]
    for k in range(30):
        distance = gap[0] - p[0]
        off = (gap[1] - p[1], gap[2] - p[2])
        step = metric_step(off, 0.45, distance, 0.05, k, cfg, clearance_here_m=max(0.0, 0.45 - math.hypot(*off)))
        if step.push:
            break
        p = [p[0] + step.delta_heading[0], p[1] + step.delta_heading[1], p[2] + step.delta_heading[2]]
        assert gap[0] - p[0] >= cfg.hold_distance_m - 1e-9 or step.aligned
    assert step.push and abs(p[1] - gap[1]) <= step.tolerance_m


def test_the_push_stops_short_of_the_far_surface_seen_through_the_opening():
    cfg = ServoConfig()
    usual = push_length(1.0, cfg)
    assert push_length(1.0, cfg, far_distance_m=10.0) == pytest.approx(usual)
    near = push_length(1.0, cfg, far_distance_m=1.8)       # background 0.65 m behind a 0.15 m wall
    assert near == pytest.approx(1.8 - cfg.body_radius_m - cfg.far_margin_m) and near < usual
    # never shorter than the crossing needs: the centre past the front face by the body's radius
    assert push_length(1.0, cfg, far_distance_m=1.1) == pytest.approx(1.0 + cfg.body_radius_m)


def test_far_distance_is_read_from_the_parallax_inside_the_gap():
    from companion.servo import far_distance_from_flow, wall_distance_from_flow
    from tests.companion.synthetic import translation_flow

    square = [(120, 80), (200, 80), (200, 160), (120, 160)]
    # camera moving 0.2 m forward; the wall 2 m ahead (ρ = 0.1 per step), the far surface 5 m (ρ = 0.04)
    flow, mask = translation_flow(240, 320, (0.0, 0.0, 1.0), square, rho_near=0.1, rho_far=0.04, scale=1.0)
    assert far_distance_from_flow(flow, mask, 0.2) == pytest.approx(5.0, rel=0.02)
    assert wall_distance_from_flow(flow, mask, 0.2) == pytest.approx(2.0, rel=0.02)
    assert far_distance_from_flow(flow, mask, 0.0) is None
    assert far_distance_from_flow(flow, np.zeros_like(mask), 0.2) is None


def test_the_walls_turn_is_read_from_the_plane_of_its_inverse_depth():
    from companion.servo import wall_yaw_from_flow

    h, w, f = 240, 320, F
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    xn, yn = (xs - (w - 1) / 2) / f, (ys - (h - 1) / 2) / f
    for deg in (0.0, 12.0, -18.0):
        t = math.radians(deg)
        # a plane 2 m ahead turned by t about the vertical: 1/Z = (cos t − sin t·x/f) / (2 cos t)
        rho = 0.15 * (math.cos(t) - math.sin(t) * xn) / (2.0 * math.cos(t))
        flow = np.stack([xn * f * rho, yn * f * rho], -1).astype(np.float32)   # forward translation
        assert wall_yaw_from_flow(flow, None, f) == pytest.approx(t, abs=0.01)


def test_an_opening_seen_at_an_angle_is_judged_at_its_width_in_the_wall():
    from companion.opening import in_wall

    mask = np.zeros((240, 320), bool)
    mask[60:180, 120:180] = True                    # 60 px wide seen at 30°: 69 px in the wall's plane
    wide, radius = in_wall(mask, 1 / math.cos(math.radians(30)))
    assert radius == pytest.approx(30 / math.cos(math.radians(30)), abs=1.0) and wide.shape == (240, 370)
