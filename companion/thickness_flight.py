"""The thickness look as the mission flies it (:mod:`companion.thickness` plans it and reads the depth): when to look,
the four views square to the wall, and the way back to the servo.  A mixin of :class:`companion.mission.Mission`,
which keeps the link, the camera and the flight record this uses."""

from __future__ import annotations

import dataclasses
import logging
import math

from companion.motion import off_heading
from companion.opening import OpeningTracker, upper_quartile
from companion.perception import derotated_flow, perceive
from companion.servo import judged_tolerance, wall_slope
from companion.thickness import combined_reading, opening_at_centre, plan_look, thickness_reading

log = logging.getLogger("companion.mission")


def deciding_radius(sight) -> float | None:
    """The clear radius a tracked opening's fit turns on: the one judged, or, before that, the one it would be
    pushed by (an opening that fits is pushed on one estimate from in front of it, ServoConfig.judged_tight)."""
    return sight.judged_m if sight.judged_m is not None else sight.clear_radius_m


class ThicknessLook:
    def _thickness_due(self, sight, view) -> bool:
        """Whether to look at the wall's thickness now: not yet this flight, the tracked opening seen from in front
        of it (the wall's distance known, and its turn within the look's bound), its deciding radius within
        ``band_m`` of the need."""
        c = self.thickness
        if (not c.enabled or self._thickness_looked or sight.judged_estimates < 1 or sight.offset_m is None
                or view.wall_distance is None):
            return False
        if view.wall_yaw is not None and abs(view.wall_yaw) > c.max_turn_rad:
            return False
        radius = deciding_radius(sight)
        return radius is not None and abs(judged_tolerance(radius, self.servo)) <= c.band_m

    def _thickness_look(self, sight, view, position, openings: OpeningTracker) -> float | None:
        """Fly the thickness look (:mod:`companion.thickness`) at the tracked opening, seen at ``view`` from
        ``position``; the tracker then judges by the depth read, and so does the push.  Returns it, or None where
        the look could not tell (the depth stays as assumed)."""
        c = self.thickness
        self._thickness_looked = True
        turn = view.wall_yaw or 0.0
        right, down = view.across + sight.offset_m[0], position[2] + sight.offset_m[1]
        face = view.here + view.wall_distance + sight.offset_m[0] * wall_slope(view.wall_yaw)
        floor = self._home_z - min(self.config.min_altitude_m, self.config.altitude_m)
        centre = self._from_heading(face, right, min(down, floor))
        plan = plan_look(centre, self.yaw - turn, c)
        radius = deciding_radius(sight)
        self._say(f"the opening judged {2 * radius:.3f} m clear, within {2 * c.band_m:.2f} m of the need: reading the "
                  f"wall's thickness square to it (turned {math.degrees(turn):.1f}°) from {plan.distance_m:.2f} m")
        side_a = [self._look_frame(point, plan.yaw) for point in plan.a]
        side_b = [self._look_frame(point, plan.yaw) for point in plan.b]
        readings = [self._look_reading(side_a[k:k + 2], side_b[k:k + 2], centre, plan.yaw) for k in range(c.readings)]
        reading = combined_reading(readings, c)
        frames = side_a + side_b
        judged = None
        if reading.thickness_m is None:
            self._say(f"the wall's thickness not read ({reading.why}): judged as assumed")
        else:
            before = openings.servo.wall_thickness_m
            openings.set_wall_thickness(reading.thickness_m)
            self.servo = dataclasses.replace(self.servo, wall_thickness_m=reading.thickness_m)
            judged = upper_quartile(openings.close_radii, openings.config.radius_window)
            self._say(f"the wall {reading.thickness_m:.3f} m deep ({reading.why}), not the {before:.2f} m assumed: "
                      f"the opening judged {2 * judged:.3f} m clear by it")
        self.result.wall_thickness_m = reading.thickness_m
        # with the frames' own poses (the simulator's truth, for the logs only), to tell the look's errors apart
        self.result.thickness_look = {
            "why": reading.why, "readings": [r.thickness_m for r in readings], "distance_m": plan.distance_m,
            "turn_rad": turn, "centre": list(centre), "yaw": plan.yaw,
            "aperture_shift_px": [r.aperture_shift_px for r in readings],
            "wall_shift_px": [r.wall_shift_px for r in readings],
            "judged_before_m": radius, "judged_after_m": judged,
            "views_est": [list(at) for _, at, _ in frames], "attitudes_est": [list(att) for _, _, att in frames],
            "views_true": [list(f.position) if f.position is not None else None for f, _, _ in frames],
            "attitudes_true": [list(f.attitude) if f.attitude is not None else None for f, _, _ in frames]}
        return reading.thickness_m

    def _look_frame(self, point, yaw: float):
        """A frame from ``point`` facing ``yaw``, level and square to within a degree or less (a pair whose tilt
        changed by 2-3° gave masks 10-15 % too wide, and the depth half what it is: measured, a hard-world scene
        scaled near the need, 0.088 m read for 0.237 m); (frame, position, attitude estimates at it)."""
        c = self.thickness
        self.link.set_position_target(point, yaw)
        self.record.setpoint(point)
        self.link.wait_position(point, c.arrival_m, self.config.search_move_timeout_s, self.config.arrival_speed_mps)
        self.link.try_wait_for(lambda t: abs(off_heading(t.attitude_euler[2], yaw)) < c.yaw_tolerance_rad
                               and abs(t.attitude_euler[0]) < c.level_rad and abs(t.attitude_euler[1]) < c.level_rad,
                               c.level_timeout_s, "the look's attitude")
        frame = self.camera.capture()
        return (frame, *self._estimates_at(frame.time_s))

    def _look_reading(self, pair_a, pair_b, centre, yaw: float):
        """One reading from view A's and view B's forward pairs (frame, position, attitude each): their masks, the
        sidestep's flow between their first frames, A's distance from the face along the normal at ``yaw``."""
        masks = [self._look_mask(*pair_a), self._look_mask(*pair_b)]
        (a, a_at, a_att), (b, _, b_att) = pair_a[0], pair_b[0]
        flow, rotational = derotated_flow(a.rgb, b.rgb, a_att, b_att, self.camera.K, self.flow, self.derotate)
        distance = (centre[0] - a_at[0]) * math.cos(yaw) + (centre[1] - a_at[1]) * math.sin(yaw)
        return thickness_reading(masks[0], masks[1], flow, distance, self.thickness, rotational)

    def _look_mask(self, first, second):
        """The opening's mask (the one at the image's centre) from a view's forward pair, in its first frame."""
        (a, a_at, a_att), (b, b_at, b_att) = first, second
        seen = perceive(a.rgb, b.rgb, a_att, b_att, self.camera.K, self.flow, self.detector, self.derotate,
                        math.dist(a_at, b_at), self.config.min_baseline_m, self.edges)
        return opening_at_centre(seen.detection)

    def _say(self, note: str) -> None:
        log.info("%s", note)
        self.record.event(note)

    def _back_from_the_look(self, waypoint, first_step: int):
        """Back to the servo's ``waypoint``, facing the heading again; its first frame (numbered ``first_step`` in
        the logs) and the estimates at it, for the next pair."""
        self._move_to(waypoint)
        self._settle()
        frame = self.camera.capture()
        position, attitude = self._estimates_at(frame.time_s)
        self.record.first_frame(first_step, frame, position, attitude)
        return frame, position, attitude
