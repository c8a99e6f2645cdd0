"""What a mission is configured with and what it ends in: its states, :class:`MissionConfig` (the constants of
:class:`companion.mission.Mission`) and :class:`MissionResult`.  Pure data: no clock, no I/O."""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass, field


class State(enum.Enum):
    CONNECT = "connect"
    PREFLIGHT = "preflight"
    ARM = "arm"
    TAKEOFF = "takeoff"
    OFFBOARD = "offboard"
    SERVO = "servo"
    TRAVERSE = "traverse"
    HOLD = "hold"
    LAND = "land"
    DONE = "done"
    REFUSED = "refused"
    FAILED = "failed"


@dataclass(frozen=True)
class MissionConfig:
    altitude_m: float = 1.5  # takeoff altitude above home
    connect_timeout_s: float = 30.0
    preflight_timeout_s: float = 20.0
    takeoff_timeout_s: float = 30.0
    arrival_tolerance_m: float = 0.06  # a waypoint is reached within this distance ...
    arrival_speed_mps: float = 0.15  # ... and below this speed (a steady view for the next frame)
    arrival_step_frac: float = 0.4   # a servo step is reached within this share of its length, when that is less
    min_arrival_tolerance_m: float = 0.02  # ... but never less than this (the vehicle holds in gusts)
    step_timeout_s: float = 8.0  # wall seconds to reach one servo waypoint
    capture_tilt_rad: float = 0.05  # then wait (≤ settle_timeout_s) until roll and pitch are below this: a
    settle_timeout_s: float = 1.5   # vehicle still braking is pitched 10°+ (measured), which blurs parallax
    estimate_wait_s: float = 0.5    # for the telemetry of a frame's moment to arrive (a slow link delays it)
    estimate_max_age_s: float = 0.04  # ... to within this (position streams at 30 Hz, attitude at 50 Hz)
    min_altitude_m: float = 0.5  # no servo step goes lower than this above home, nor than altitude_m if that is
                                 # lower (the random worlds' openings start 0.35 m up, their centres 1 m or more)
    takeoff_attempts: int = 3  # arm + takeoff rounds when the vehicle disarms on the ground in between
    no_gap_limit: int = 8  # servo steps without any gap ever seen before giving up
    blind_frames: int = 3  # ... and after this many the look's detector also looks past the wall's end (the
                           # Mission's blind_detector): seen from beside a wall's end, the space beyond it is the
                           # sharpest depth step and the opening lies in its near class (measured: the first looks
                           # of four passable hard-world flights, seeds 88-90, that saw nothing in 8 frames; it
                           # found the opening in 2-4 of their frames 4-8, and nothing off it)
    unseen_step_back_after: int = 4  # frames in a row that see no opening at all, with the tracked one placed and
    unseen_step_back_m: float = 0.5  # the wall within decide_within_m: then one step back this far, once a look
                                     # (a new forward baseline and a wider view; it dithered beside the place
                                     # instead until its steps ran out: 21 of 400 flights of hard seeds 96, 98, 99
                                     # and 101 did, for 6-27 frames; 7 of them failed)
    min_wall_measurements: int = 3  # flow-based wall distances needed before they steer the push
    min_baseline_m: float = 0.02  # a frame pair whose camera moved less than this is not looked at (no parallax:
                                  # at 1 m from a wall 1 m before its background, about 3 px of contrast)
    finish: str = "hold"  # after the traversal: "hold" or "land"
    # Camera-to-setpoint latency: the next waypoint is sent this long after its frame was taken, or once
    # perception is done if that takes longer.  In lockstep perception costs no simulated time, so this is
    # what it costs; 0 suits the stop-and-go servo, which waits for a still vehicle before each frame.
    perception_latency_s: float = 0.0
    # Refused (an opening too small, none seen, none centred on): look again before holding for good, from this
    # far to one side of the start's axis (the refused opening's side first), then to the other, the refused ones
    # set aside (companion.opening: avoid).  An opening out of the camera's view from the start is found this way
    # (hard world, seed 41: five passable openings 41-53° off the start heading, 2.2-2.6 m to its side).  0: none.
    search_shift_m: float = 1.5
    search_move_timeout_s: float = 20.0  # wall (or lockstep) seconds to reach each point of the search
    search_wall_turn_rad: float = math.radians(25.0)  # a look allows for a wall turned this far (the hard world: 20°)
    search_yaw_margin_rad: float = math.radians(8.0)  # ... or, its turn measured, for that give or take this
    search_reach_m: float = 1.6  # a look takes only openings this far across from where it looks from, and only
                                 # seen clear in the frame it pushes on (no push on a tracked place alone); 1.2
                                 # left openings 2.7-3.0 m across the start's axis to no look (hard world seeds
                                 # 67 and 71: with 1.6, hard_1412974212 and hard_1694391472 through)
    search_walk_m: float = 1.0   # ... and starts this much further than the hold distance from it (room to walk
                                 # for parallax before the hold)
    search_wall_slack_m: float = 0.3  # ... and takes the wall no further than that bound plus this, ...
    search_wall_agree_m: float = 0.05      # ... unless its own latest min_wall_measurements readings agree within
    search_wall_agree_per_m: float = 0.05  # this plus this per metre of its distance: then they are the wall


@dataclass
class MissionResult:
    state: State
    reason: str | None = None
    servo_steps: int = 0
    states: list[tuple[float, str]] = field(default_factory=list)
    wall_distance_m: float | None = None
    far_distance_m: float | None = None
    push_length_m: float | None = None
    heading_rad: float | None = None    # the heading flown along (NED yaw): the yaw at the offboard start
    wall_turn_rad: float | None = None  # the wall's turn against the heading at the push, as measured
    wall_thickness_m: float | None = None  # the wall's depth, read by the thickness look (None: assumed)
    thickness_look: dict | None = None     # what that look saw and made of it (None: no look)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["state"] = self.state.value
        return d
