"""The servo law: the corrected lateral sign, clamps, push conditions, and convergence from both sides."""

from __future__ import annotations

import math

import pytest

from companion.servo import ServoConfig, heading_to_ned, normalised_error, push_length, push_waypoints, servo_step

W, H = 320, 240
F = 156.4  # px: the default camera, vertical FOV 75° over 240 px


def test_normalised_error_is_zero_at_the_centre_and_one_at_the_edges():
    assert normalised_error((160, 120), W, H) == (0.0, 0.0)
    assert normalised_error((320, 0), W, H) == (1.0, -1.0)


@pytest.mark.parametrize("u, sign", [(240, +1), (80, -1)])
def test_gap_right_of_centre_moves_right(u, sign):
    # DESIGN.md step 5: Δy = +κ_y·e_u (the paper's printed minus sign flies away from the gap).
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


def test_heading_rotation():
    assert heading_to_ned((1.0, 0.0, 0.2), math.pi / 2) == pytest.approx((0.0, 1.0, 0.2))


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
