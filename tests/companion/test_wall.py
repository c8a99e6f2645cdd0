"""companion.wall.WallTrack: what one look knows of the wall ahead, from its readings and an earlier look's bound."""

from __future__ import annotations

import math

import pytest

from companion.wall import WallTrack, wall_ahead_words


def test_the_distance_is_the_readings_median_once_there_are_enough_and_follows_the_vehicle():
    wall = WallTrack()
    assert wall.add(0.0, 0.0, 3.0, None, None) == 3.0
    wall.add(0.2, 0.0, 2.9, None, None)                 # the wall 3.1 m along the heading
    assert wall.view(0.2, 0.0)[:2] == (None, None)      # two readings: no distance yet, nor a rough bound
    assert wall.fallback_distance(0.2) == pytest.approx(2.85)
    wall.add(0.4, 0.0, 2.6, None, None)
    distance, ahead, _ = wall.view(1.0, 0.0)            # the median place, 3.0, from 1 m along
    assert distance == pytest.approx(2.0) and ahead == distance


def test_readings_out_of_range_are_dropped_and_rough_ones_bound_the_wall_ahead_only():
    wall = WallTrack()
    assert wall.add(0.0, 0.0, 12.0, None, None) is None and wall.readings == []
    for here in (0.0, 0.2, 0.4):
        wall.add(here, 0.0, None, 2.4 - here, None)     # without a gap: rough readings only, the wall at 2.4
    assert wall.view(0.4, 0.0)[:2] == (None, pytest.approx(2.0))


def test_a_turned_walls_turn_is_the_median_of_the_latest_and_carries_the_readings():
    wall = WallTrack()
    turn = math.radians(15.0)
    for across in (-1.0, -0.5, 0.0):
        wall.add(0.0, across, 3.0 + across * math.tan(turn), None, turn)
    assert wall.turn == pytest.approx(turn)
    assert wall.view(0.0, 0.0)[0] == pytest.approx(3.0)


def test_a_looks_readings_beyond_its_prior_are_not_believed_unless_they_agree():
    # earlier looks allow the wall as near as 2.0 m; the look reads 3.0 m, steadily: it is the wall
    steady = WallTrack(prior=2.0)
    for here in (0.0, 0.2, 0.4):
        steady.add(here, 0.0, 3.0 - here, None, None)
    assert steady.own(0.4, 0.0)
    assert steady.view(0.4, 0.0)[:2] == (pytest.approx(2.6), pytest.approx(2.6))
    # readings that jump (as past a wall's end) are held to the prior: the distance at the prior, not beyond
    jumping = WallTrack(prior=2.0)
    for here, reading in ((0.0, 3.0), (0.2, 4.3), (0.4, 2.6)):
        jumping.add(here, 0.0, reading, None, None)
    assert not jumping.own(0.4, 0.0)
    assert jumping.view(0.4, 0.0)[:2] == (pytest.approx(1.6), pytest.approx(1.6))
    # within the prior plus the slack a reading stands; the wall ahead is still taken no further than the prior
    near = WallTrack(prior=2.9, agree_m=0.0, agree_per_m=0.0)
    for here, reading in ((0.0, 3.0), (0.2, 3.0), (0.4, 2.8)):
        near.add(here, 0.0, reading, None, None)
    distance, ahead, _ = near.view(0.4, 0.0)
    assert distance == pytest.approx(2.8) and ahead == pytest.approx(2.5)
    assert WallTrack().own(0.0, 0.0) is False           # the first look has no prior to overrule


def test_a_looks_own_rough_readings_lift_its_prior_when_they_agree_within_the_ceiling():
    """hard world seeds 67 and 68: bounds allowing for a 25° turn held blind looks 1.5 m across short of the
    wall, where they saw nothing and refused."""
    def blind(readings, ceiling=3.4, prior=2.0):
        wall = WallTrack(prior=prior, ceiling=ceiling)
        for here, reading in zip((0.0, 0.2, 0.4), readings, strict=True):
            wall.add(here, 0.0, None, reading, None)     # no gap in view: rough readings only
        return wall
    # the wall steadily 3.0 m along: ahead is it, beyond the prior (2.0), within the ceiling
    steady = blind((3.0, 2.8, 2.6))
    assert steady.rough_own(0.4, 0.0) == pytest.approx(3.0)
    assert steady.view(0.4, 0.0)[:2] == (None, pytest.approx(2.6))
    # readings that jump are not the wall: held to the prior
    assert blind((3.0, 3.6, 2.6)).view(0.4, 0.0)[:2] == (None, pytest.approx(1.6))
    # steady, but beyond the ceiling plus the slack (what lies behind a wall's end): held to the prior
    assert blind((3.0, 2.8, 2.6), ceiling=2.6).rough_own(0.4, 0.0) is None
    assert blind((3.0, 2.8, 2.6), ceiling=2.6).view(0.4, 0.0)[:2] == (None, pytest.approx(1.6))
    assert blind((3.0, 2.8, 2.6), ceiling=2.7).view(0.4, 0.0)[:2] == (None, pytest.approx(2.6))   # within the slack
    # nearer than the prior: the readings stand (the bound never lifts the wall further than they say)
    assert blind((2.0, 1.8, 1.6), prior=2.5).view(0.4, 0.0)[:2] == (None, pytest.approx(1.6))
    # without a ceiling (the first look, or no earlier sight) nothing changes
    assert blind((3.0, 2.8, 2.6), ceiling=None).view(0.4, 0.0)[:2] == (None, pytest.approx(1.6))


def test_the_far_surface_counts_only_beyond_the_pairs_own_wall_reading():
    wall = WallTrack()
    wall.add_far(0.0, 4.0, 2.0)
    wall.add_far(0.0, 1.5, 2.0)                         # nearer than the wall: not the far surface
    wall.add_far(0.0, 25.0, None)                       # beyond any room
    wall.add_far(0.5, 3.4, None)
    assert wall.far == [4.0, 3.9] and wall.far_distance(1.0) == pytest.approx(2.95)
    assert WallTrack().far_distance(0.0) is None


def test_what_the_wall_ahead_rests_on_is_said_with_it():
    """hard world seed 89: a search look refused "with the wall 0.13 m ahead" from 1.09 m before it; the 0.13 m
    was the bound earlier looks put on the wall, not a measurement."""
    measured = WallTrack()
    for here in (0.0, 0.2, 0.4):
        measured.add(here, 0.0, 3.0 - here, None, None)
    assert measured.view(0.4, 0.0) == (pytest.approx(2.6), pytest.approx(2.6), "measured")
    rough = WallTrack()
    for here in (0.0, 0.2, 0.4):
        rough.add(here, 0.0, None, 2.4 - here, None)
    assert rough.view(0.4, 0.0) == (None, pytest.approx(2.0), "rough")
    bounded = WallTrack(prior=0.55)                      # earlier looks allow the wall 0.55 m along: nothing read
    assert bounded.view(0.4, 0.0) == (None, pytest.approx(0.15), "bound")
    for here in (0.0, 0.2, 0.4):                         # readings that jump are held to the bound
        bounded.add(here, 0.0, (1.5, 2.9, 1.2)[int(here / 0.2 + 0.5)], None, None)
    assert bounded.view(0.4, 0.0) == (pytest.approx(0.15), pytest.approx(0.15), "bound")
    assert WallTrack().view(0.0, 0.0) == (None, None, None)
    assert wall_ahead_words(0.13, "bound").startswith("possibly as near as 0.13 m ahead")
    assert wall_ahead_words(0.9, "rough") == "about 0.90 m ahead (read without an opening in view)"
    assert wall_ahead_words(0.9, "measured") == "0.90 m ahead"
