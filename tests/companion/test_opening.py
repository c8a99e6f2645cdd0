"""Choosing, keeping and judging an opening (companion.opening), on synthetic detections."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from companion.gap import _from_contour
from companion.opening import Candidate, OpeningTracker, edge_distance_px
from companion.servo import ServoConfig

W, H, F = 320, 240, 156.4


def rect(u0, v0, u1, v1):
    """A detection of a rectangular opening spanning pixels u0..u1, v0..v1 (with its clear circle)."""
    contour = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], np.int32).reshape(-1, 1, 2)
    return _from_contour((H, W), contour, "test")


def cand(det):
    return Candidate(det, det.clear_centre)


def test_it_follows_the_widest_of_several_and_never_servos_between_two():
    tracker = OpeningTracker()
    small, wide = rect(30, 100, 70, 140), rect(180, 80, 280, 170)
    first = tracker.observe([cand(small), cand(wide)], (0.0, 0.0), None, F, W, H)
    assert first.detection is wide and "2 openings in view" in first.note and "the widest" in first.note
    tracker.observe([cand(small), cand(wide)], (0.0, 0.0), None, F, W, H)       # confirmed
    # the other opening now looks larger (it is nearer the camera's view centre): still the same one
    bigger_small, wide_moved = rect(20, 60, 150, 190), rect(190, 82, 290, 172)
    later = tracker.observe([cand(bigger_small), cand(wide_moved)], (0.0, 0.0), None, F, W, H)
    assert later.detection is wide_moved and later.target_px == pytest.approx(wide_moved.clear_centre)
    # only the other one in view: the tracked centre is kept, the other never taken over
    alone = tracker.observe([cand(bigger_small)], (0.0, 0.0), None, F, W, H)
    assert alone.detection is None and alone.target_px == pytest.approx(wide_moved.clear_centre)


def test_in_the_metric_phase_a_missed_frame_steers_by_the_vehicles_own_motion():
    tracker = OpeningTracker()
    centred = rect(170, 70, 310, 190)                   # clear centre right of the image centre
    for _ in range(2):
        tracker.observe([cand(centred)], (0.0, 0.0), None, F, W, H)
    seen = tracker.observe([cand(centred)], (0.0, 0.0), 1.5, F, W, H)
    u_off = centred.clear_centre[0] - W / 2
    assert seen.offset_m[0] == pytest.approx(u_off * 1.5 / F, rel=0.02)
    missed = tracker.observe([], (0.25, 0.0), 1.5, F, W, H)      # moved 0.25 m right, saw nothing
    assert missed.detection is None and missed.offset_m[0] == pytest.approx(seen.offset_m[0] - 0.25, abs=1e-6)


def test_too_small_an_opening_is_refused_with_its_numbers_and_a_passable_one_taken_instead():
    cfg = ServoConfig()
    slot = rect(140, 60, 180, 180)                       # 41 px wide at 1.2 m: about 0.36 m
    lone = OpeningTracker(cfg)
    for _ in range(2):
        lone.observe([cand(slot)], (0.0, 0.0), None, F, W, H)
    sights = [lone.observe([cand(slot)], (0.0, 0.0), 1.2, F, W, H) for _ in range(3)]
    assert all(s.refusal is None for s in sights[:2])            # judged on three estimates
    refusal = sights[-1].refusal
    assert refusal and refusal.startswith("opening ") and "is narrower than the vehicle's 0.38 m plus 0.10 m margin" \
        in refusal and refusal.endswith("not flying through")
    width = float(refusal.split("opening ")[1].split(" ×")[0])
    assert width == pytest.approx(41 * (1.2 + cfg.wall_thickness_m) / F, abs=0.02)
    # the same with a wide opening in view too: the tracker switches to it, once, and says so
    wide = rect(200, 40, 310, 200)
    other = OpeningTracker(cfg)
    for _ in range(2):
        other.observe([cand(slot)], (0.0, 0.0), None, F, W, H)
    sights = [other.observe([cand(slot), cand(wide)], (0.0, 0.0), 1.2, F, W, H) for _ in range(5)]
    switched = next(s for s in sights if s.note)
    assert "is narrower than" in switched.note and "taking the one" in switched.note
    assert switched.detection is wide and all(s.refusal is None for s in sights)
    assert sights[-1].offset_m[0] == pytest.approx((wide.clear_centre[0] - W / 2) * 1.2 / F, rel=0.05)


def test_the_clearance_flying_straight_on_counts_the_room_along_an_elongated_opening():
    slot = rect(100, 100, 260, 140)                      # long and low: 161 × 41 px
    assert edge_distance_px(slot.mask, (130.0, 120.0)) == pytest.approx(21.0, abs=1.0)   # far from its centre,
    assert edge_distance_px(slot.mask, (180.0, 120.0)) == pytest.approx(21.0, abs=1.0)   # as much room as there
    assert edge_distance_px(slot.mask, (180.0, 60.0)) == 0.0
    mask = np.zeros((H, W), bool)
    cv2.circle(mask.view(np.uint8), (160, 120), 50, 1, -1)
    assert edge_distance_px(mask, (160.0, 120.0)) == pytest.approx(50.0, abs=1.0)
    assert edge_distance_px(mask, (190.0, 120.0)) == pytest.approx(20.0, abs=1.0)


def test_openings_seen_together_are_not_confused_later_when_only_one_of_them_is_in_a_frame():
    left, right = rect(110, 90, 150, 130), rect(180, 85, 230, 135)      # clear centres 75 px apart (< τ_c)
    tracker = OpeningTracker()
    for _ in range(2):
        first = tracker.observe([cand(left), cand(right)], (0.0, 0.0), None, F, W, H)
    assert first.detection is right                                    # the wider one
    # frames that see only the other one: within τ_c of the tracked centre, but it is the other opening
    for _ in range(2):
        only_left = tracker.observe([cand(left)], (0.0, 0.0), None, F, W, H)
        assert only_left.detection is None and only_left.target_px == pytest.approx(right.clear_centre)
    assert tracker.observe([cand(right)], (0.0, 0.0), None, F, W, H).detection is right
    # the tracked one gone for good (out of view): the other is taken after three frames in a row, and said so
    sights = [tracker.observe([cand(left)], (0.0, 0.0), None, F, W, H) for _ in range(3)]
    assert [s.detection is left for s in sights] == [False, False, True]
    assert "lost the tracked opening" in sights[2].note
