"""What one look makes of each frame pair, and where it steps next (pure: no clock, no I/O).

A look is one servo towards the wall: the first from the start, then those of the search.  Each frame pair gives
:func:`see_frame` the flow and the detection; it reads the wall (:class:`companion.wall.WallTrack`), sets aside
patches of the wall taken for openings, places and judges the openings (:class:`companion.opening.OpeningTracker`)
and measures the far surface seen through the tracked one.  :func:`next_look_step` then chooses the step: the
metric law once the tracked opening is placed, the paper's image law before, and no blind step nearer the wall
than the hold distance.  The mission (``companion.mission``) flies the steps, keeps the logs and raises the
refusals.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from companion.motion import off_heading, tilted_pixel, translation_in_camera
from companion.opening import OpeningTracker, Sight, candidates_in
from companion.servo import (
    ServoConfig,
    ServoStep,
    far_distance_from_flow,
    metric_step,
    normalised_error,
    servo_step,
    wall_and_openings,
    wall_distance_from_flow,
    wall_slope,
)
from companion.wall import WallTrack


def along_heading(position, yaw: float) -> float:
    """Coordinate along the initial heading ``yaw`` (the direction of travel toward the wall)."""
    return position[0] * math.cos(yaw) + position[1] * math.sin(yaw)


def across_heading(position, yaw: float) -> tuple[float, float]:
    """Coordinates across the initial heading ``yaw``: (right of it, down), metres."""
    return -position[0] * math.sin(yaw) + position[1] * math.cos(yaw), position[2]


def along_heading_axis(reading: float | None, turn: float | None, looks_off: float
                      ) -> tuple[float | None, float | None]:
    """A frame pair's wall reading and turn, taken along and against the axis of a camera that looks
    ``looks_off`` (rad, positive: right) off the heading, as they are along and against the heading: the turn
    less that, and the distance to where the heading's axis meets the wall (the plane's inverse depth there,
    ``tan(turn) · tan(looks_off)`` of the reading's more, along a ray ``1/cos(looks_off)`` longer).  Without a
    turn (no plane fitted) the reading is kept as it is."""
    if turn is None:
        return reading, None
    if reading is not None:
        reading = reading / ((1.0 + math.tan(turn) * math.tan(looks_off)) * math.cos(looks_off))
    return reading, turn - looks_off


@dataclass(frozen=True)
class FrameView:
    """What a look makes of one frame pair."""

    sight: Sight                    # the tracked opening as this pair shows it (companion.opening)
    detection: object               # the detection to show and log: the tracked one, else the detector's top
    found: list                     # the openings kept (patches of the wall set aside)
    wall_patches: list[float]       # the set-aside ones' inverse depth, as a fraction of the wall's there
    measured: float | None          # this pair's wall reading (m, straight ahead of where the vehicle is)
    wall_distance: float | None     # the look's wall distance (the readings' median), None before enough
    ahead: float | None             # the nearest the wall can be straight ahead (m)
    wall_yaw: float | None          # the wall's turn against the heading (rad), once measured
    here: float                     # where the vehicle is along the heading ...
    across: float                   # ... and across it (right), metres
    far: float | None               # the far surface through the tracked opening (m), when seen
    area_frac: float                # the shown detection's share of the frame
    ahead_basis: str | None = None  # what ``ahead`` rests on (companion.wall.WallTrack.view)


def see_frame(seen, prev_rgb, prev_position, position, prev_attitude, moved: float, still: bool, K,
              yaw: float, openings: OpeningTracker, wall: WallTrack) -> FrameView:
    """One frame pair of a look: ``seen`` (companion.perception's flow, detection and textured pixels, on the first
    frame's pixels), the first frame's image, the autopilot's position estimates at both frames and its attitude at the
    first, how far the camera moved between them (``still``: too little for parallax), the camera matrix and the
    initial heading.  Updates ``openings`` and ``wall``."""
    flow, top = seen.flow, seen.detection
    height, width = prev_rgb.shape[:2]
    focal = float(K[0, 0])
    # Forward flow lives on the first frame's pixels: so do the masks, which are placed and measured from where
    # that frame was taken (measured: scaled from the second frame's distance, every opening came out 10 % small
    # at a 0.18 m step from 1.6 m, and a sideways step misplaced it by the step).
    # ... and placed as a level camera looking along the heading sees them: the vehicle's yaw wanders off it by
    # a degree or more while it moves (see companion.motion.level_pixel)
    looks_off = off_heading(prev_attitude[2], yaw)
    candidates = candidates_in(top, K, prev_attitude, yaw)
    # The wall is read where the first frame has texture, along the move the autopilot's estimates say (the
    # flow's own focus of expansion is pulled off by the empty space beyond a wall's end: measured, hard world
    # seed 60, readings 5-28 % long there, and a vehicle walked into the wall)
    direction = translation_in_camera(prev_position, position, prev_attitude)
    textured = seen.textured if not still else None
    # A detection whose depth is the wall's is a patch of it, not an opening (OpeningConfig.max_depth_ratio:
    # measured, hard world seed 64, a sideways step past a turned wall showed its farther half as a "gap" 42 % of
    # the frame, pushed at once from 2.2 m into the wall; on seed 60, blobs on a wall followed to it).  Only with
    # a detected gap is the wall read: the openings' masks keep the far pixels out of its depth statistic
    # (measured: without one, readings of 0.7–0.9 m for a wall 2.8 m away pushed far too early).
    kept, patches, reading, turn = wall_and_openings(flow, [c.detection.mask for c in candidates], moved, focal,
                                                     openings.config.max_depth_ratio, direction, textured)
    candidates = [candidates[i] for i in kept]
    reading, turn = along_heading_axis(reading, turn, looks_off)
    found = [c.detection for c in candidates]
    here, place = along_heading(position, yaw), across_heading(position, yaw)   # place: (right, down) now
    across = place[0]
    # the wall where it is read: ahead of the first frame (the flow's pixels), as far as its depth from the second
    # (forward flow is the second frame's inverse depth times the move); a reading put ahead of the second frame,
    # after a move across a turned wall, was the move's length times the turn's tangent long or short (the decision
    # logs of hard world seeds 76 and 77 read again, carried along by the true turn: within 1.6 m of the wall the
    # track's distance came out 0.029 m long or more at one step in ten, 0.012 m read ahead of the first frame;
    # 0.034 and 0.014 m on walls turned over 10°)
    seen_from, seen_place = along_heading(prev_position, yaw), across_heading(prev_position, yaw)
    measured = wall.add(
        here, seen_place[0], reading,
        # without a gap the wall is still measured, for one purpose only: not to walk into it blind
        None if found or still else wall_distance_from_flow(flow, None, moved, direction, focal, textured),
        turn if moved >= 0.08 else None)
    wall_yaw = wall.turn
    # A distance enters the push decision only once three measurements agree on a median; a look's is bounded by
    # where earlier looks put the wall, unless its own readings agree (measured, hard world seeds 46-48: bounds
    # from sights taken 1.4-3 m across put the wall up to 1.4 m too near; looks stopped 1.3-2.3 m from it "with
    # the wall 1.09 m ahead", or stalled 2.5 m out, their openings scaled by that wrong distance to half their
    # size).
    wall_distance, ahead, ahead_basis = wall.view(here, across)
    axis = tilted_pixel(((width - 1) / 2.0, (height - 1) / 2.0), K, prev_attitude[0], prev_attitude[1], looks_off)
    # the wall straight ahead of where the first frame (whose pixels the masks live in) was taken
    seen_distance = (wall_distance + (here - seen_from) + (seen_place[0] - across) * wall_slope(wall_yaw)
                     if wall_distance is not None else None)
    sight = openings.observe(candidates, seen_place, seen_distance, focal, width, height, axis, moved, wall_yaw,
                             viewer_m=place)
    detection = sight.detection if sight.detection is not None else top
    area_frac = detection.area / float(width * height) if detection.found else 0.0
    far = (far_distance_from_flow(flow, detection.mask, moved)
           if sight.detection is not None and openings.last_accepted else None)
    if far is not None:
        wall.add_far(here, far, measured)
    return FrameView(sight, detection, found, list(patches), measured, wall_distance, ahead,
                     wall_yaw, here, across, far, area_frac, ahead_basis)


def next_look_step(view: FrameView, index: int, width: int, height: int, config: ServoConfig,
                   wall_prior: float | None, accepted: bool, lag_m: tuple[float, float] = (0.0, 0.0)) -> ServoStep:
    """The step after frame pair ``index`` (0-based) of a look: the metric law once the tracked opening is
    placed; before, the paper's image law without its push, never nearer the wall than the hold distance while it
    sees nothing, or (a look of the search, ``wall_prior`` given) while its own wall is not measured yet;
    ``accepted``: whether the tracker took this frame's sighting; ``lag_m``: the waypoint's place (right, down)
    less the frame's (see :func:`companion.servo.metric_step`)."""
    sight, used = view.sight, view.sight.target_px
    if sight.offset_m is not None:
        return metric_step(sight.offset_m, sight.clear_radius_m, view.wall_distance, view.area_frac, index + 1, config,
                           normalised_error(used, width, height), sight.clearance_here_m, sight.sightings,
                           sight.close_sightings, sight.judged_estimates, lag_m)
    step = servo_step(used, view.area_frac if used is not None else 0.0, index + 1, width, height, config,
                      view.wall_distance)
    if used is None:     # blind: a new parallax baseline, but no push, nor closer than the hold
        forward = step.delta_heading[0]
        if view.ahead is not None:
            forward = min(forward, max(0.0, view.ahead - config.hold_distance_m))
        return dataclasses.replace(step, delta_heading=(forward, 0.0, 0.0), push=False)
    if wall_prior is not None and view.wall_distance is None:
        # a look steering by the image alone, its wall not measured yet, is as blind to the wall as one seeing
        # nothing: no nearer than the hold distance to where earlier looks put it, and no push (measured, hard
        # world seed 46: a look whose target was a stale image position walked 2 m on and into the wall)
        forward = min(step.delta_heading[0], max(0.0, view.ahead - config.hold_distance_m))
        # ... and steps across only towards a target seen in this frame: a held one re-applied its last
        # correction at every step (measured, hard world seed 49: held at the hold distance, no baseline, no new
        # sighting; 0.05 m down per step for 20 steps, to the ground)
        sideways = step.delta_heading[1:] if accepted else (0.0, 0.0)
        return dataclasses.replace(step, delta_heading=(forward, *sideways), push=False)
    # No look pushes what it never placed (the paper's law pushes once its step budget is spent: measured, hard
    # world seed 67, hard_0252556946, a first look that saw a 0.37 m high opening in one frame from 2 m followed
    # that stale image position for 19 steps, 1.3 m aside and 1.2 m down, and pushed into the wall at the 30th)
    return dataclasses.replace(step, push=False)
