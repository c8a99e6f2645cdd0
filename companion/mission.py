"""The companion's mission: CONNECT → PREFLIGHT → ARM → TAKEOFF → OFFBOARD → SERVO → TRAVERSE → HOLD|LAND → DONE.

Each servo step (docs/design.md steps 1–8): move to the waypoint and wait for arrival, take a frame, compute
flow against the previous frame, detect the gap, filter the centroid (τ_c), and derive the next waypoint.
When centred and close, or when the step budget is spent, push through in 0.05 m increments (step 7).
Every way out of the loop is a state: a lost link or a refused command ends in FAILED with the reason, after
asking the vehicle to hold (or land) where it can; declining to fly through (an opening too small, one it cannot
centre on, or none seen in N frames) ends in REFUSED, holding where it is, once a search has looked again from
either side of the start (MissionConfig.search_shift_m) and found nothing it can pass.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import time

import numpy as np

from companion.camera import CameraError, FrameSource
from companion.edges import DEFAULT_EDGES, EdgeConfig
from companion.flightrecord import FlightRecord
from companion.link.base import AutopilotLink, LinkError, LinkLost
from companion.look import across_heading, along_heading, next_look_step, see_frame
from companion.mission_config import MissionConfig, MissionResult, State
from companion.motion import off_heading, tilted_pixel
from companion.opening import OpeningConfig, OpeningTracker
from companion.perception import perceive
from companion.push import push_length, push_path
from companion.runlog import RunLog
from companion.search import look_places, search_wall_bound, search_wall_ceiling
from companion.servo import (
    ServoConfig,
    ServoStep,
    heading_to_ned,
    probe_aside_m,
    servo_step,
)
from companion.thickness import ThicknessLookConfig
from companion.thickness_flight import ThicknessLook
from companion.tracking import CentroidFilter, ConfirmingCentroidFilter
from companion.wall import WallTrack, wall_ahead_words

log = logging.getLogger(__name__)


class Mission(ThicknessLook):
    def __init__(self, link: AutopilotLink, camera: FrameSource, flow, detector, runlog: RunLog,
                 servo: ServoConfig | None = None, config: MissionConfig | None = None,
                 tracker: CentroidFilter | None = None, derotate_flow: bool = True,
                 openings: OpeningConfig | None = None, recording=None, blind_detector=None,
                 edges: EdgeConfig | None = DEFAULT_EDGES, thickness: ThicknessLookConfig | None = None):
        self.link = link
        self.camera = camera
        self.flow = flow
        self.detector = detector
        self.blind_detector = blind_detector or detector   # after config.blind_frames frames that saw nothing
        self.edges = edges    # openings' edges read again from the frames (companion.edges); None: as flow shows
        self.record = FlightRecord(runlog, recording)   # what it saw and decided, written as it flies
        self.servo = servo or ServoConfig()
        self.config = config or MissionConfig()
        self.tracker = tracker or ConfirmingCentroidFilter()
        self._fresh_tracker = copy.deepcopy(self.tracker)  # each look of a search starts from it
        self._frame_base = 0      # step number of the current look's first frame (looks number on from the last)
        self._steps_before = 0    # servo steps of the looks before this one
        self._home_z = 0.0        # home's down coordinate (NED), taken on the ground at arming
        self._wall_seen = None    # (forward, right, turn) of the wall's face as last measured (m, m, rad or None)
        self._wall_sights = []    # every such sight of the current look taken with the wall's turn measured
        # Once the wall's distance is known, the opening's clear centre is tracked where it is in the world
        # (companion.opening): a frame without a detection then steers by the vehicle's own motion instead of
        # repeating the last step (measured: re-applied 0.25 m steps towards a stale image position ran a
        # vehicle 2 m sideways).
        self.openings = openings or OpeningConfig()
        self.thickness = thickness or ThicknessLookConfig()
        self._thickness_looked = False   # the wall's thickness is looked at once a flight (one wall)
        self.derotate = derotate_flow
        self.result = MissionResult(State.CONNECT)
        self.clock = link.clock     # every wait and timeout on the link's clock (wall, or lockstep)
        self._t0 = time.monotonic()
        self._t0_clock = self.clock.now()

    # ----------------------------------------------------------------------------------- run
    def run(self) -> MissionResult:
        try:
            self._enter(State.CONNECT)
            self.link.connect(self.config.connect_timeout_s)
            self._enter(State.PREFLIGHT)
            self.link.wait_for(lambda t: t.position is not None and t.landed is not None,
                               self.config.preflight_timeout_s, "position estimate and landed state")
            self.link.set_takeoff_altitude(self.config.altitude_m)
            home_z = self._home_z = self._arm_and_take_off()
            self.link.wait_for(lambda t: t.position is not None
                               and abs(t.position[2] - (home_z - self.config.altitude_m)) < 0.1
                               and math.hypot(*t.velocity) < 0.2,
                               self.config.takeoff_timeout_s, "takeoff altitude")
            self._enter(State.OFFBOARD)
            start = self.link.telemetry.position
            self.yaw = self.result.heading_rad = self.link.telemetry.attitude_euler[2]
            self.link.start_offboard(start, self.yaw)
            self.record.setpoint(start)
            self._enter(State.SERVO)
            waypoint, bias, wall_distance, turn = self._servo_searching(start)
            self._enter(State.TRAVERSE)
            self._traverse(waypoint, bias, wall_distance, self.result.far_distance_m, turn)
            if self.config.finish == "land":
                self._enter(State.LAND)
                self.link.land()
                self.link.wait_for(lambda t: not t.armed, 60, "landing")
            else:
                self._enter(State.HOLD)
                self.link.hold()
            self._enter(State.DONE)
        except Refusal as exc:
            self._refuse(str(exc))
        except LinkLost as exc:
            self._fail(f"link lost: {exc}", safe=False)
        except (LinkError, CameraError) as exc:
            self._fail(str(exc), safe=True)
        return self.result

    def _arm_and_take_off(self) -> float:
        """Arm, then command the takeoff; returns home's down coordinate. PX4 disarms a vehicle left armed on
        the ground (COM_DISARM_PRFLT, 10 s): when a slow, lossy link lets that happen before the takeoff command
        gets through, the refusal is followed by a disarmed heartbeat, and the vehicle is armed again (on the
        ground, disarmed: nothing to lose), up to ``takeoff_attempts`` times."""
        attempts, attempt = self.config.takeoff_attempts, 1
        while True:
            self._enter(State.ARM)
            self.link.arm()
            self._enter(State.TAKEOFF)
            home_z = self.link.telemetry.position[2]     # on the ground: a retried takeoff may ack in the climb
            try:
                self.link.takeoff(self.config.altitude_m)
                return home_z
            except LinkLost:
                raise
            except LinkError as exc:
                if attempt >= attempts or not self.link.try_wait_for(
                        lambda t: t.armed is False and t.landed, 2.0, "a disarmed heartbeat"):
                    raise
                log.warning("takeoff attempt %d of %d: %s; the vehicle disarmed on the ground: arming again",
                            attempt, attempts, exc)
                self.record.event(f"takeoff refused, the vehicle disarmed on the ground: arming again ({exc})", "WARN")
                attempt += 1

    # --------------------------------------------------------------------------------- servo
    def _servo_searching(self, start):
        """Servo on an opening; refused, look again from either side of the start's axis (``search_shift_m``,
        the refused opening's side first), the refused ones set aside; returns what :meth:`_servo` returns, or
        raises the combined refusal.  With another opening seen on the way (``Refusal.alternative``), the first
        look is in front of it instead, then the sides of the axis, the one further from it first
        (:func:`companion.search.look_places`)."""
        try:
            return self._servo(start)
        except Refusal as exc:
            first = exc
        shift = self.config.search_shift_m
        if shift <= 0:
            raise first
        walls = [self._wall_seen] if self._wall_seen is not None else []   # each look's last sight of the wall
        # ... and, for the nearest the wall can be, every sight of it with its turn measured: a look that read the
        # wall, then followed blobs past its end, last read what lies behind the end, up to 4 m further (measured,
        # hard world seed 105, hard_1719364450: the second look began beside the wall's end, past its face, and
        # backed into its corner).  Not the sights before the turn was measured: allowed a 25° turn either way across
        # 3 m, they held later looks up to 1.7 m further back (hard world seeds 99 and 101: four passable flights lost)
        sights = list(self._wall_sights)
        ahead, axis = self._forward(start), self._across(start)[0]
        seen = first.place[0] if first.place is not None else self._across(self.link.telemetry.position)[0]
        side = 1.0 if seen >= axis else -1.0
        avoid = [first.place] if first.place is not None else []
        looks = []
        for right, where in look_places(axis, shift, side,
                                        first.alternative[0] if first.alternative is not None else None):
            prior = search_wall_bound(walls + sights, right, self.config.search_wall_turn_rad,
                                      self.config.search_yaw_margin_rad)
            ceiling = search_wall_ceiling(walls, right, self.config.search_wall_turn_rad,
                                          self.config.search_yaw_margin_rad)
            forward = ahead if prior is None else prior - self.servo.hold_distance_m - self.config.search_walk_m
            note = f"refused ({first}); looking again from {where}" + (
                "" if prior is None else f", {prior - forward:.2f} m before the nearest the wall can be there")
            log.info("%s", note)
            self.record.event(note, "WARN")
            # back first (away from the wall, the way it came, behind the start if need be), then across
            self._move_to(self._from_heading(min(forward, self._forward(self.link.telemetry.position)),
                                             self._across(self.link.telemetry.position)[0], start[2]))
            look = self._from_heading(forward, right, start[2])
            self._move_to(look)
            self.tracker = copy.deepcopy(self._fresh_tracker)
            self._steps_before = self.result.servo_steps
            self._wall_seen = None
            self._wall_sights = []
            try:
                return self._servo(look, tuple(avoid), prior, (right, self.config.search_reach_m), ceiling)
            except Refusal as exc:
                looks.append(f"from {where}: {exc}")
                if self._wall_seen is not None:
                    walls.append(self._wall_seen)
                sights += self._wall_sights
                if exc.place is not None:
                    avoid.append(exc.place)
        raise Refusal(f"{first}; looked again " + "; ".join(looks))

    def _move_to(self, point) -> None:
        self._send(point)
        self.link.wait_position(point, self.config.arrival_tolerance_m, self.config.search_move_timeout_s,
                                self.config.arrival_speed_mps)

    def _from_heading(self, forward: float, right: float, down: float) -> tuple[float, float, float]:
        """NED from coordinates along and across the initial heading (the inverse of _forward and _across)."""
        return heading_to_ned((forward, right, down), self.yaw)

    def _servo(self, start, avoid: tuple = (), wall_prior: float | None = None, reach=None,
               wall_ceiling: float | None = None):
        """Servo steps until push; returns (where the push starts, lateral/vertical bias, wall distance, the wall's
        turn against the heading or None).
        ``avoid``: places of openings refused before; ``wall_prior``: the nearest the wall's face can be (forward
        coordinate), from earlier looks: no blind step goes nearer than the hold distance to it; ``reach``: (right,
        metres), a look's bound on the openings it takes (companion.opening), and then no push without a clear
        sighting; ``wall_ceiling``: the furthest the wall's face can be, from earlier looks (companion.wall)."""
        cfg = self.servo if reach is None else dataclasses.replace(self.servo, roomy_tolerance_m=math.inf)
        width, height = self.camera.width, self.camera.height
        prev = self.camera.capture()
        # The autopilot's estimates at each frame's time stamp, as a real companion has them (the frame's own
        # pose is the simulator's truth, used only to render and to log).
        prev_position, prev_attitude = self._estimates_at(prev.time_s)
        base = self._frame_base
        self.record.first_frame(base, prev, prev_position, prev_attitude)
        waypoint = start
        step = servo_step(None, 0.0, 0, width, height, cfg)
        wall_distance = None
        wall = WallTrack(wall_prior, self.config.min_wall_measurements, self.config.search_wall_slack_m,
                         self.config.search_wall_agree_m, self.config.search_wall_agree_per_m, wall_ceiling)
        openings = OpeningTracker(cfg, self.openings, self.tracker, avoid, reach)
        ever_seen = False
        unseen_in_front, stepped_back = 0, False
        # no step lower than min_altitude_m above home (or the flight's own height, if lower), whatever the image
        floor = self._home_z - min(self.config.min_altitude_m, self.config.altitude_m)
        for k in range(cfg.step_budget):
            n = base + k + 1      # the step's number in the flight's logs
            self._frame_base = n + 1
            t_step = self.clock.now()
            delta = heading_to_ned(step.delta_heading, self.yaw)
            waypoint = (waypoint[0] + delta[0], waypoint[1] + delta[1], min(waypoint[2] + delta[2], floor))
            self._send(waypoint)
            arrived = self.link.wait_position(waypoint, self._arrival_tolerance(delta), self.config.step_timeout_s,
                                              self.config.arrival_speed_mps)
            self._settle()
            move_s = self.clock.now() - t_step
            if not self.link.telemetry.armed:
                raise LinkError("the vehicle disarmed during the servo phase (crash or failsafe)")
            t_frame = self.clock.now()
            frame = self.camera.capture()
            position, attitude = self._estimates_at(frame.time_s)
            moved = math.dist(prev_position, position)
            # measured (hard world, seed 43): a step shorter than the arrival tolerance "arrived" at once, and a
            # pair 0.01 m apart showed a 61 % "opening" 0.97 m away; the vehicle pushed into the wall
            still = moved < self.config.min_baseline_m
            detector = self.detector if ever_seen or k < self.config.blind_frames else self.blind_detector
            seen = perceive(prev.rgb, frame.rgb, prev_attitude, attitude, self.camera.K, self.flow, detector,
                            self.derotate, moved, self.config.min_baseline_m, self.edges)
            self.record.frame_poses(n, frame, position, attitude)
            view = see_frame(seen, prev.rgb, prev_position, position, prev_attitude, moved, still, self.camera.K,
                             self.yaw, openings, wall)
            sight, found, ahead = view.sight, view.found, view.ahead
            wall_distance, detection, used = view.wall_distance, view.detection, view.sight.target_px
            if view.wall_patches:
                note = (f"set aside {len(view.wall_patches)} of {len(found) + len(view.wall_patches)} openings as "
                        f"patches of the wall (inverse depth {', '.join(f'{r:.2f}' for r in view.wall_patches)} of "
                        "the wall's there)")
                log.info("%s", note)
                self.record.event(note)
            if sight.note:
                log.info("%s", sight.note)
                self.record.event(sight.note)
            shown = None if used is None else tilted_pixel(used, self.camera.K, prev_attitude[0], prev_attitude[1],
                                                             off_heading(prev_attitude[2], self.yaw))
            observed = {   # the frame and what was made of it; then the step it decided, or the refusal
                "step": n, "frame_time_s": frame.time_s,
                "position_true": frame.position, "position_est": position, "waypoint": waypoint, "arrived": arrived,
                "centroid_raw": detection.centroid, "openings": len(found), "centroid_used": used,
                "clear_radius_m": sight.clear_radius_m, "clearance_here_m": sight.clearance_here_m,
                "judged_estimates": sight.judged_estimates, "estimate_m": sight.estimate_m,
                "estimate_px": sight.estimate_px, "judged": sight.judged, "note": sight.note,
                "attitude_est": attitude, "accepted": self.tracker.last_accepted,
                "no_gap_reason": detection.reason, "past_the_end": detector is not self.detector,
                "area_frac": view.area_frac, "wall_distance_m": view.measured,
                "far_distance_m": view.far, "wall_patches": [round(r, 3) for r in view.wall_patches],
                "wall_turn_rad": view.wall_yaw,
                "timing": {"move_s": move_s, "capture_ms": frame.capture_ms, "flow_ms": seen.flow_ms,
                           "detect_ms": seen.detect_ms}}

            # a refusal's own frame is logged too, holding: the estimate that decided it is in the decision log
            hold = ServoStep((0.0, 0.0, 0.0), None, False, False)
            lag = tuple(w - q for w, q in zip(self._across(waypoint), self._across(position), strict=True))
            if self._thickness_due(sight, view):
                # judged too near the need to tell by the depth assumed: read the wall's, judge again by it, and go
                # on from here with the step this frame gives (no push on it: the next frame decides)
                resume = dataclasses.replace(next_look_step(view, k, width, height, cfg, wall_prior,
                                                            openings.last_accepted, lag), push=False)
                observed["note"] = "; ".join(filter(None, [observed["note"], "the wall's thickness read next"]))
                self._record_step(frame, seen.flow, detection, shown, hold, wall_distance, observed)
                thickness = self._thickness_look(sight, view, position, openings)
                if thickness is not None:
                    cfg = dataclasses.replace(cfg, wall_thickness_m=thickness)
                prev, prev_position, prev_attitude = self._back_from_the_look(waypoint, n + 1)
                base += 1           # the look's frames are not the servo's: a new first frame
                self._frame_base = n + 2
                self.result.servo_steps = self._steps_before + k + 1
                step = resume
                continue
            if sight.refusal:
                self._record_step(frame, seen.flow, detection, shown, hold, wall_distance, observed, sight.refusal)
                raise Refusal(sight.refusal, openings.world.used, openings.alternative())
            ever_seen |= bool(found)
            if ahead is not None and view.ahead_basis != "bound":
                # bounded as the look's own steps are: a look's reading beyond its bound (measured: by a wall's
                # end, rough readings of what lies behind it) would start the next look too near the wall.  Not
                # the bound alone: carried to the next look as a sight of its own, it was allowed a 25° turn
                # once more across the 3 m between the side looks (measured, hard world seed 96, hard_0888527560:
                # the third look began 3 m from the wall, held short of it as if it were within 1.6 m, and saw
                # the opening in 6 of 24 frames from there)
                self._wall_seen = (view.here + ahead, view.across, view.wall_yaw)
                if view.wall_yaw is not None:
                    self._wall_sights.append(self._wall_seen)
            if used is None and ahead is not None and ahead <= cfg.hold_distance_m:
                why = f"no opening in sight with the wall {wall_ahead_words(ahead, view.ahead_basis)}: not flying on"
                self._record_step(frame, seen.flow, detection, shown, hold, wall_distance, observed, why)
                raise Refusal(why, None, openings.alternative())
            next_step = next_look_step(view, k, width, height, cfg, wall_prior, openings.last_accepted, lag)
            near = wall_distance is not None and wall_distance <= self.openings.decide_within_m
            unseen_in_front = unseen_in_front + 1 if near and not found and sight.offset_m is not None else 0
            if unseen_in_front >= self.config.unseen_step_back_after and not stepped_back and not next_step.push:
                note = (f"no opening seen in {unseen_in_front} frames in front of the one placed "
                        f"{math.hypot(*sight.offset_m):.2f} m off: a step {self.config.unseen_step_back_m:.1f} m "
                        "back, to see it again")
                log.info("%s", note)
                self.record.event(note)
                next_step = dataclasses.replace(next_step, delta_heading=(-self.config.unseen_step_back_m, 0.0, 0.0))
                stepped_back, unseen_in_front = True, 0
            if next_step.push and openings.doubted_on_approach(sight.clear_radius_m):
                # one near estimate says it shrank: no push on it, a step aside for another frame pair to judge by
                next_step = dataclasses.replace(next_step, push=False, delta_heading=(0.0, probe_aside_m(k, cfg), 0.0))
            shrunk = openings.shrunk_on_approach(sight.clear_radius_m) if next_step.push else None
            if shrunk:
                self._record_step(frame, seen.flow, detection, shown, hold, wall_distance, observed, shrunk)
                raise Refusal(shrunk, openings.world.used, openings.alternative())
            self.clock.sleep_until(t_frame + self.config.perception_latency_s)
            self.result.servo_steps = self._steps_before + k + 1
            self._record_step(frame, seen.flow, detection, shown, next_step, wall_distance, observed)
            log.info("step %d: centroid %s used %s area %.3f error %s wall %.2f m%s", n,
                     _fmt(detection.centroid), _fmt(used), view.area_frac, _fmt(next_step.error),
                     view.measured if view.measured is not None else math.nan, " → push" if next_step.push else "")
            if not ever_seen and k + 1 >= self.config.no_gap_limit:
                # nothing seen to fly through: the vehicle has touched nothing and holds, as for an opening
                # judged too small (an opening too small for the detector is the same decision, earlier)
                raise Refusal(f"no opening found in {k + 1} frames: nothing seen to fly through")
            prev, prev_attitude, prev_position, step = frame, attitude, position, next_step
            if next_step.push:
                break
        else:
            if step.offset_m is None:   # a look pushes only what it has placed (companion.look.next_look_step)
                raise Refusal(f"no opening placed within {cfg.step_budget} steps: not flying through",
                              openings.world.used, openings.alternative())
            # the metric law pushes only a sphere it has seen clear the edges
            why = ("" if step.aligned is False else ", its size not judged from in front of it"
                   if step.judged is False else ", not seen clear in the last frame")
            raise Refusal(f"could not centre on the opening within {cfg.step_budget} steps (still "
                          f"{math.hypot(*step.offset_m):.2f} m off, {step.tolerance_m:.2f} m allowed{why}): "
                          "not flying through", openings.world.used, openings.alternative())
        self.result.wall_distance_m = wall_distance
        here = self._forward(prev_position)
        if wall_distance is None:  # fewer readings than the minimum: still better than nothing
            wall_distance = wall.fallback_distance(here)
        far = wall.far_distance(here)
        if far is not None:
            self.result.far_distance_m = far
        # The push starts from where the vehicle was at the last frame, not from the waypoint it was still on
        # its way to (within the arrival tolerance): its last correction, the wall's and the far surface's
        # distances were all measured from there (measured, hard world seed 44: started from the waypoint
        # 0.04 m aside, a push through a polygon 0.26 m clear touched its edge).
        self.result.wall_turn_rad = wall.turn
        return tuple(prev_position), step.delta_heading[1:], wall_distance, wall.turn

    def _send(self, waypoint) -> None:
        self.link.set_position_target(waypoint, self.yaw)
        self.record.setpoint(waypoint)

    def _record_step(self, frame, flow, detection, shown_px, decided: ServoStep, wall_distance, observed: dict,
                     refusal: str | None = None) -> None:
        """A servo step's images and decision line: ``observed`` (what the frame showed and was made of) and the
        step ``decided``, or, with ``refusal``, the hold the flight ends in and why."""
        self.record.step(observed["step"], frame, flow, detection, shown_px, decided, wall_distance,
                         refusal or observed["note"], {
                             "step": observed["step"], "t_wall_s": time.monotonic() - self._t0,
                             "t_clock_s": self.clock.now() - self._t0_clock, **observed, "refusal": refusal,
                             "error": decided.error,
                             "next_delta_heading": decided.delta_heading, "close": decided.close, "push": decided.push,
                             "offset_m": decided.offset_m, "tolerance_m": decided.tolerance_m,
                             "aligned": decided.aligned})

    def _estimates_at(self, time_s: float):
        """(position, attitude) estimates at a frame's time stamp.  Over a slow link they arrive after the frame:
        wait (at most ``estimate_wait_s``) until telemetry has come within ``estimate_max_age_s`` of that moment
        (a stream period: on a prompt link it already has), then interpolate, or take the nearest sample; the
        latest ones if it never does."""
        t = self.link.telemetry
        since = time_s - self.config.estimate_max_age_s
        if not self.link.try_wait_for(lambda tel: tel.covers(since), self.config.estimate_wait_s,
                                      "telemetry at the frame's time"):
            log.debug("telemetry did not reach t=%.3f s within %.1f s; using the latest", time_s,
                      self.config.estimate_wait_s)
        return t.position_at(time_s), t.attitude_at(time_s)

    def _arrival_tolerance(self, step) -> float:
        """How near a servo step's waypoint counts as reached: a share of the step, within bounds.  With a fixed
        0.06 m, a shorter step "arrived" at once and its frame was taken where the last one was (no parallax),
        and a longer one was caught on its overshoot, up to 0.06 m past (measured, hard world seeds 76 and 77:
        the frame's place across 0.024 m from the waypoint at the median of 3,161 metric steps, over 0.03 m in
        42 % of them; vehicles swung about openings they were nearly centred on until the steps ran out)."""
        c = self.config
        return min(c.arrival_tolerance_m, max(c.min_arrival_tolerance_m, c.arrival_step_frac * math.hypot(*step)))

    def _settle(self) -> None:
        """Wait for a level attitude before the next frame (bounded: a windy or tilted vehicle still flies)."""
        tilt = self.config.capture_tilt_rad
        if not self.link.try_wait_for(lambda t: abs(t.attitude_euler[0]) < tilt and abs(t.attitude_euler[1]) < tilt,
                                      self.config.settle_timeout_s, "a level attitude"):
            log.debug("still tilted after %.1f s; taking the frame anyway", self.config.settle_timeout_s)

    def _forward(self, position) -> float:
        return along_heading(position, self.yaw)

    def _across(self, position) -> tuple[float, float]:
        return across_heading(position, self.yaw)

    def _traverse(self, start, bias, wall_distance, far_distance=None, turn=None) -> None:
        length = push_length(wall_distance, self.servo, far_distance)
        self.result.push_length_m = length
        points, square = push_path(start, self.yaw, length, bias, self.servo, wall_distance, turn)
        # the square path's length along the heading is the straight push's; it flies a little further
        flown = sum(math.dist(a, b) for a, b in zip([start, *points[:-1]], points, strict=True))
        log.info("traversal: %.2f m ahead along the heading%s in %.2f m increments (wall measured at %s m%s, beyond "
                 "it %s m)", length, f", {flown:.2f} m flown square to the wall" if square else "",
                 self.servo.push_increment_m, _fmt(wall_distance),
                 "" if turn is None else f", turned {math.degrees(turn):.1f}°", _fmt(far_distance))
        period = 1.0 / 20.0  # one increment per setpoint period: ~1 m/s, level
        for p in points:
            self._send(p)
            self.link.check_alive()
            self.clock.sleep(period)
        self.link.wait_position(points[-1], 0.1, self.config.step_timeout_s, 0.3)

    # ------------------------------------------------------------------------------- states
    def _enter(self, state: State) -> None:
        self.result.state = state
        self.result.states.append((round(self.clock.now() - self._t0_clock, 3), state.value))
        log.info("state: %s", state.value.upper())
        self.record.event(f"state: {state.value.upper()}")

    def _refuse(self, reason: str) -> None:
        """Decline the opening: hold where the vehicle is, and say why (a refused flight touches nothing)."""
        log.warning("refused in %s: %s", self.result.state.value.upper(), reason)
        self.record.event(f"refused: {reason}", "WARN")
        self.result.reason = reason
        self._enter(State.REFUSED)
        try:
            self.link.hold()
        except LinkError as exc:
            log.error("could not command Hold after refusing: %s", exc)

    def _fail(self, reason: str, safe: bool) -> None:
        log.error("mission failed in %s: %s", self.result.state.value.upper(), reason)
        self.record.event(f"failed: {reason}", "ERROR")
        failed_in = self.result.state
        self.result.reason = f"{failed_in.value}: {reason}"
        self._enter(State.FAILED)
        if safe and failed_in not in (State.CONNECT, State.PREFLIGHT, State.ARM):
            try:
                self.link.hold()
            except LinkError as exc:
                log.error("could not command Hold after the failure: %s", exc)


class Refusal(RuntimeError):
    """The companion declines to fly through (an opening too small, one it cannot centre on, or none seen); the
    reason names the numbers behind the decision, and ``place`` where the refused opening is on the wall (right,
    down across the heading, metres; None when none was placed); ``alternative``, where another opening seen on
    the way is (:meth:`companion.opening.OpeningTracker.alternative`; None: none)."""

    def __init__(self, reason: str, place=None, alternative=None):
        super().__init__(reason)
        self.place = place
        self.alternative = alternative


def _fmt(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, (tuple, list, np.ndarray)):
        return "(" + ", ".join(f"{v:.2f}" for v in value) + ")"
    return f"{value:.2f}"
