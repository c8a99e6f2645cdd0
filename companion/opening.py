"""Which opening to fly through, where it is, and whether the vehicle fits (pure: no clock, no I/O).

The gap detector may see several openings in one frame (:attr:`companion.gap.GapDetection.candidates`).
:class:`OpeningTracker` keeps to one of them from frame to frame, so that the vehicle never servos between
two:

- before the wall's distance is measured, in the image: the candidate nearest the tracked centre (within
  τ_c, and within half the distance at which two openings were once seen together) is the one; with none
  tracked yet, the one with the largest clear circle (the one a body fits best);
- once the distance is measured, also in the world: the image tracker's opening is placed across the heading
  (right, down, metres) at the wall's distance, a place that jumps by more than ``world_gate_m`` is taken only
  once a second one agrees, and the tracked place is the median of the latest.  A frame without a sighting
  steers by the vehicle's own motion, not by a stale image position.
- its clear radius in metres is the upper quartile of its latest estimates taken from nearly in front of it
  (within ``judge_offset_m``: seen from the side, a thick wall's inner faces hide part of the opening; and a
  mask misses part of an opening far more often than it takes in wall: on hard-world views a single estimate
  was at most 0.009 m over the truth in nine cases of ten, but down to 0.042 m under it); once the wall is within
  ``decide_within_m`` and ``min_estimates`` such estimates say that the body sphere and its margin do not fit
  (with the estimate's allowance, ``ServoConfig.size_allowance_m``),
  another candidate that fits is taken instead (once, and said so), or the opening is refused with the numbers;
  what the vehicle steers and pushes by is the smaller of that radius after the latest estimate and after the
  one before (none before two): one view does not decide a push;
- openings refused before (``avoid``: their places on the wall) are no candidates once the wall's distance places
  what is seen (the mission's search for another opening);
- the other openings it places are remembered (:class:`SeenElsewhere`), so that, the tracked one refused, the
  search can look again in front of the widest of them (:meth:`OpeningTracker.alternative`).

The clear radius of what is seen through an opening in a wall of thickness t is bounded by the opening's far
edge, t beyond the wall's face (the tunnel's inner faces count as wall), so it is scaled by that depth.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from companion.opening_geometry import edge_distance_px, in_wall, turned_wall_stretch
from companion.servo import (
    TURN_NEGLIGIBLE_RAD,
    ServoConfig,
    alignment_tolerance,
    judged_tolerance,
    metric_offset,
    normalised_error,
    wall_slope,
)
from companion.tracking import ConfirmingCentroidFilter, TrackingConfig

Point = tuple[float, float]


@dataclass(frozen=True)
class OpeningConfig:
    tau_c_px: float = 80.0          # the paper's τ_c, in the image before the wall's distance is known
    world_gate_m: float = 0.35      # a detection farther than this from the tracked place is another opening
    radius_window: int = 5          # the clear radius is the upper quartile of this many latest estimates ...
    judge_offset_m: float = 0.15    # ... taken from within this of the opening's clear centre
    judge_step_m: float = 0.08      # ... between frames this far apart at least
    min_estimates: int = 3          # ... and judged (fits or not) only once there are this many
    decide_within_m: float = 1.6    # ... and the wall is this close (a pixel is then about 1 cm there, and the
                                    # whole opening in view: judged from 2.2 m, partial masks refused a 0.75 m one)
    min_opening_px: float = 6.0     # two openings seen together count only when each is this wide a circle
    min_gate_px: float = 20.0       # ... and their half separation gates no tighter than this
    lost_after: int = 4             # frames in a row with openings in view but none matched to the tracked one:
                                    # then one placed where the tracked one is on the wall is taken for it
    mask_inset_px: float = 1.0      # the mask's clear circle lies this far inside that of what is seen through
                                    # the opening (see clear_radius_m; 2 px for the detector's masks as flow
                                    # shows them, before companion.edges)
    alternative_sightings: int = 3  # another opening is worth a look of the search once this many frames placed it
    near_size_ratio: float = 0.7    # no push on an opening whose size estimates from within decide_within_m are
                                    # all under this fraction of the clear radius it is steered by: what shrinks
                                    # as it is approached is a pattern on the wall (measured, 644 pushes of hard
                                    # seeds 88, 89 and 92-96, the suite and standard seed 40: the largest near
                                    # estimate was at least 0.91 of it on every push that went through, and 0.35
                                    # on the one that hit a wall, blobs judged 0.44 m from 3.4 m and 0.16 m at 1.4 m)
    near_estimates: int = 2         # ... once this many near estimates say so; with fewer, one more frame first
                                    # (measured, the suite, window2_newspaper: one notched mask, 14 px for 28-32 px
                                    # in the frames before, refused an opening 0.79 m clear; 2026-12-06, AVX512-BF16)
    max_depth_ratio: float = 0.85   # an opening's inverse depth is at most this fraction of the wall plane's
                                    # there (servo.depth_against_wall); above it, a patch of the wall (the
                                    # frame pairs of 40 hard-world flights, seed 60, re-rendered: at most 0.75
                                    # over 221 detections of openings, and 21 of 52 detections of no opening
                                    # above 0.85, up to 1.03)


@dataclass(frozen=True)
class Candidate:
    """One detected opening as the tracker sees it: the detection and its clear centre in the level image."""

    detection: object               # companion.gap.GapDetection
    target_px: Point                # its clear centre (or centroid), as a level camera would see it


@dataclass(frozen=True)
class Sight:
    """What the tracker makes of one frame."""

    detection: object | None        # the tracked opening's detection in this frame (None: not seen)
    target_px: Point | None         # its tracked image position (the paper's law steers by it)
    offset_m: Point | None = None   # metric phase: (right, down) from the vehicle to its clear centre
    clear_radius_m: float | None = None
    clearance_here_m: float | None = None  # from the heading's axis to the opening's nearest edge (this frame)
    sightings: int = 0              # how many frames placed the tracked opening where it is tracked ...
    close_sightings: int = 0        # ... of them with the wall within decide_within_m
    judged_estimates: int = 0       # its size estimates taken in front of it, near (what judges it: see observe)
    note: str | None = None         # a choice or a switch, said once
    refusal: str | None = None      # why the vehicle will not fly through (then it must not)
    estimate_m: float | None = None  # this frame's own clear-radius estimate of it (None: this frame gave none)
    estimate_px: float | None = None  # ... from this clear radius of its mask, in the wall's plane (pixels)
    judged: bool = False            # ... and it counts among those that judge the opening (see observe)
    judged_m: float | None = None   # the clear radius the fit is judged by (None: not judged yet)


def candidates_in(detection, K: np.ndarray, attitude, heading: float | None = None) -> list[Candidate]:
    """The openings of one detection (all its candidates), each with its clear centre as a level camera looking
    along ``heading`` would see it, given the (roll, pitch, yaw) ``attitude`` at the frame (None: along the
    camera's own yaw, for the image phase of a replay)."""
    from companion.motion import level_pixel, off_heading

    yaw = 0.0 if heading is None else off_heading(attitude[2], heading)
    found = [d for d in (detection.candidates or (detection,)) if d.found]
    return [Candidate(d, level_pixel(d.clear_centre or d.centroid, K, attitude[0], attitude[1], yaw))
            for d in found]


def upper_quartile(estimates: list[float], window: int) -> float:
    """The clear radius (m) a tracked opening is steered and judged by: the upper quartile of its latest ``window``
    size estimates (see the module docstring); 0 without any."""
    return float(np.percentile(estimates[-window:], 75)) if estimates else 0.0


def median_place(places: list[Point]) -> Point:
    """The per-axis median of places (right, down): an opening does not move, its sightings jitter."""
    return float(np.median([p[0] for p in places])), float(np.median([p[1] for p in places]))


@dataclass
class SeenElsewhere:
    """An opening other than the tracked one, as the frames that placed it saw it."""

    places: list[Point]             # (right, down), metres, one per sighting
    radii: list[float]              # its clear radius (m) from each sighting

    def place(self, window: int) -> Point:
        """The median of the latest ``window`` places (the nearer views place it better)."""
        return median_place(self.places[-window:])


class OpeningTracker:
    def __init__(self, servo: ServoConfig | None = None, config: OpeningConfig | None = None,
                 pixel_tracker=None, avoid: tuple[Point, ...] = (), reach: tuple[float, float] | None = None
                 ) -> None:
        self.servo = servo or ServoConfig()
        # places (right, down, metres) of openings already judged too small: a sighting placed within the world
        # gate of one is not a candidate (a search looks for another opening, not the refused one again); and
        # with ``reach`` (right, metres), none placed further across than that from there (a search looks ahead
        # of where it looks from, not along the wall towards its end, where the void beside it showed "openings")
        self.avoid = tuple(avoid)
        self.reach = reach
        self.config = config = config or OpeningConfig()
        self.pixels = pixel_tracker if pixel_tracker is not None else ConfirmingCentroidFilter(
            TrackingConfig(config.tau_c_px))
        self.world = ConfirmingCentroidFilter(TrackingConfig(config.world_gate_m))
        self.radii: list[float] = []        # the tracked opening's clear radius (m), one per sighting ...
        self.close_radii: list[float] = []  # ... and those from within decide_within_m, in front of it
        self.near_radii: list[float] = []   # ... and those from within decide_within_m, from anywhere
        self.places: list[Point] = []       # the tracked clear centre's accepted places (right, down), metres
        self.close_places = 0               # ... how many of them with the wall within decide_within_m
        self.radius_trail: list[float] = []  # the clear radius (upper quartile) after each of its estimates
        # where each estimate of radii, close_radii and near_radii was taken: (depth scaled by, the wall's turn), to
        # take it to another wall thickness (set_wall_thickness)
        self.radii_at: list[tuple[float, float | None]] = []
        self.close_at: list[tuple[float, float | None]] = []
        self.near_at: list[tuple[float, float | None]] = []
        self.switched = False
        self._announced = False
        self.separation_px = math.inf       # the closest two openings have been to each other in one frame
        self.elsewhere: list[SeenElsewhere] = []  # the other openings placed (see alternative)
        self._unmatched = 0                 # frames in a row with openings in view, none matched to the tracked one

    @property
    def last_accepted(self) -> bool:
        return self.pixels.last_accepted

    def clear_radius_m(self, radius_px: float, wall_distance_m: float, focal_px: float) -> float:
        """Metres, from a detection's clear radius in pixels (see the module docstring).  The inset: on the close
        frame pairs (1.6 m or nearer) of 44 hard-world flights (seeds 60 and 61, openings 0.40-0.60 m clear, RAFT,
        re-rendered at the flown poses and scaled by the true distance), the upper quartile of a flight's
        last five estimates came out 0.018 m over the true clear diameter at the median with 2.5 px, and 0.001 m
        with 1.5 px: the estimate the refusal is judged by is the upper quartile, so the inset that makes it right
        is smaller than the one that makes a single estimate right (a mask's clear radius is 0.4 px short of the
        ground truth's at the median, but now and then several pixels short where its edge has a notch).  In flight
        the 2.5 px were right only while the wall's readings came out 3 % short (before the plane fit of
        :func:`companion.servo.wall_distance_from_flow`).  With :func:`turned_wall_stretch` in place of 1/cos(turn),
        which takes a few per cent off openings in turned walls, 2 px: on the close views of 114 flights of
        hard-world seeds 60 and 64-68 whose opening was 0.38-0.62 m clear (each flight's first three estimates at the
        true distance, upper quartile over truth), 1/cos(turn) and 1.5 px gave 1.008 at the median, 0.940-1.127
        from the 10th to the 90th percentile, and of the 93 openings 0.40-0.56 m clear, 8 of 47 passable ones judged
        too small and 11 of 46 impassable ones judged to fit; the stretch and 2 px give 1.016, 0.950-1.091, 7 and 9
        (1.75 px: 1.006, 8 and 8; flown on hard seeds 67 and 68, 1.75 px lost two passable flights more than 2 px).
        With the edges read again from the frames (:mod:`companion.edges`), 1 px: on renders drawn as ``python -m
        tools.size_error`` draws them (80 scenes of five pairs each, seeds 9100 and 9200, openings within 0.05 m of
        the need, the 0.007 m allowance), the judgement over the truth has a spread (sd of its log) of 0.044 and
        0.049 against 0.088 and 0.084 for the detector's masks at 2 px, with the median level (0.974 and 0.972
        against 0.974 and 0.984); 1 of 72 impassable openings was judged to fit and 25 of 83 passable ones too
        small, against 3 and 28."""
        return (radius_px + self.config.mask_inset_px) * (wall_distance_m + self.servo.wall_thickness_m) / focal_px

    def observe(self, candidates: list[Candidate], across_m: Point, wall_distance_m: float | None,
                focal_px: float, width: int, height: int, axis_px: Point | None = None,
                moved_m: float = math.inf, wall_yaw_rad: float | None = None,
                viewer_m: Point | None = None) -> Sight:
        """One frame pair: ``candidates`` seen in it, and where that view was taken from: the place across the
        heading (right, down, metres) and the wall's distance (None until measured) of the frame whose pixels
        the detection lives in (forward flow's: the first of the two), and where the heading's axis is in that
        (tilted) frame; ``viewer_m``, the vehicle's place now (default: the same), for the offset to steer by and
        the clearance the body would have flying straight on from here; how far the vehicle moved between the
        two frames (a small step gives little parallax and a poor mask, not one to judge by); and how far
        the wall is turned against the camera's axis, when measured (an opening seen at an angle looks narrower
        than it is in the wall, where the body crosses it)."""
        viewer = across_m if viewer_m is None else viewer_m
        stretch = 1.0          # used only once the wall's distance is known (see the return below without it)
        if wall_distance_m is not None and wall_yaw_rad is not None and abs(wall_yaw_rad) > TURN_NEGLIGIBLE_RAD:
            stretch = turned_wall_stretch(self.servo.body_radius_m + self.servo.clearance_margin_m, wall_distance_m,
                                          wall_yaw_rad, self.servo.wall_thickness_m)

        walled: dict[int, tuple[np.ndarray, float]] = {}

        def wall_view(det) -> tuple[np.ndarray, float]:
            """The detection's mask and clear radius (px) as the wall's own plane shows them (once each)."""
            if stretch == 1.0:
                return det.mask, det.clear_radius_px
            if id(det) not in walled:
                walled[id(det)] = in_wall(det.mask, stretch)
            return walled[id(det)]

        def radius_px(det) -> float:
            return wall_view(det)[1]

        slope = wall_slope(wall_yaw_rad)

        def depth(target_px: Point) -> float:
            """The wall's depth along the heading at a level pixel: a turned wall is nearer on one side.  Scaled
            by the depth on the axis, an opening 0.5 m aside of it at 1.5 m from a wall turned 15° came out
            0.06 m further aside than it is and 9 % larger seen from its near side (window1_brick, DIS fine)."""
            lateral = (target_px[0] - width / 2) / focal_px
            return wall_distance_m / max(1.0 - lateral * slope, 0.5)

        def radius_m(c: Candidate) -> float:
            return self.clear_radius_m(radius_px(c.detection), depth(c.target_px), focal_px)

        def place(target_px: Point) -> Point:
            off = metric_offset(normalised_error(target_px, width, height), width, height, focal_px, depth(target_px))
            return across_m[0] + off[0], across_m[1] + off[1]
        if wall_distance_m is not None:
            if self.avoid:
                candidates = [c for c in candidates
                              if all(math.dist(place(c.target_px), a) > self.config.world_gate_m for a in self.avoid)]
                # Followed in the image before the wall's distance could place it, a refused opening is let go
                # (measured, hard world seeds 67, 77 and 78: looks of the search centred on the opening they had been
                # sent away from, never judged again, until their 30 steps ran out)
                if self.world.used is None and self.pixels.used is not None and any(
                        math.dist(place(self.pixels.used), a) <= self.config.world_gate_m for a in self.avoid):
                    self.pixels.reset()
            if self.reach is not None:
                candidates = [c for c in candidates if abs(place(c.target_px)[0] - self.reach[0]) <= self.reach[1]]
        note = None
        if self.pixels.used is None and len(candidates) > 1 and not self._announced:
            best = max(candidates, key=lambda c: c.detection.clear_radius_px)
            note = (f"{len(candidates)} openings in view; following the one at ({best.target_px[0]:.0f}, "
                    f"{best.target_px[1]:.0f}) px, the widest (clear circle {2 * best.detection.clear_radius_px:.0f}"
                    " px across)")
            self._announced = True
        # Two openings seen in one frame this far apart in the image: a sighting further than half that from
        # the tracked one is the other opening, even within τ_c (a frame may see only one of them).
        real = [c for c in candidates if c.detection.clear_radius_px >= self.config.min_opening_px]
        for i, a in enumerate(real):
            for b in real[i + 1:]:
                self.separation_px = min(self.separation_px, math.dist(a.target_px, b.target_px))
        gate = min(self.config.tau_c_px, max(self.config.min_gate_px, 0.5 * self.separation_px))
        before = self.pixels.used
        pick = _nearest(candidates, before, gate, lambda c: c.target_px)
        widest = max(candidates, key=lambda c: c.detection.clear_radius_px) if candidates else None
        self._unmatched = self._unmatched + 1 if pick is None and widest is not None and before is not None else 0
        if self._unmatched >= self.config.lost_after and wall_distance_m is not None and self.world.used is not None:
            # Measured: fragments of one opening, taken for two, shrank the image gate so that the tracked one
            # was never matched again, and the vehicle probed in front of it until its step budget ran out.  The
            # world place still says which one it is: a sighting placed within the world gate of it is it.
            near = [c for c in candidates if math.dist(place(c.target_px), self.world.used) <= self.config.world_gate_m]
            if near:
                pick = min(near, key=lambda c: math.dist(place(c.target_px), self.world.used))
                self.pixels.config = dataclasses.replace(self.pixels.config, tau_c_px=self.config.tau_c_px)
                self.pixels.seed(pick.target_px)
                self.separation_px, self._unmatched = math.inf, 0
                before = pick.target_px
                note = (f"the tracked opening, unmatched in the image for {self.config.lost_after} frames, found "
                        f"again where it is on the wall, at ({pick.target_px[0]:.0f}, {pick.target_px[1]:.0f}) px")
        # Not the tracked one: offer the widest to the image tracker, which takes it only once two frames in a
        # row agree on it (three with several openings about: the tracked one is gone, say out of view); then
        # it is the one, from scratch.
        if self.separation_px < math.inf:    # with several openings about, a switch needs one more frame
            self.pixels.reacquire_after = 3
            self.pixels.config = dataclasses.replace(self.pixels.config, tau_c_px=gate)
        used = self.pixels.update((pick or widest).target_px if (pick or widest) is not None else None)
        if pick is None and before is None:
            pick = widest                        # the first one, being confirmed
        elif pick is None and self.pixels.last_accepted:
            pick = widest
            self.world.reset()
            self._forget_history()
            note = (f"lost the tracked opening; following the one at ({used[0]:.0f}, {used[1]:.0f}) px, "
                    f"seen in {self.pixels.reacquire_after} frames in a row")
        if wall_distance_m is None or used is None:
            return Sight(pick.detection if pick is not None else None, used, note=note)

        if self.world.used is None:          # the image-tracked centre, placed in the world once
            self.world.seed(place(used))
        placed = [(c, place(c.target_px)) for c in candidates]
        # which opening it is, the image tracker decides (τ_c, confirmation); the world tracker, fed with
        # that one's place, rejects a place that jumps and takes it after two that agree
        chosen = next((cp for cp in placed if cp[0] is pick), None) if self.pixels.last_accepted else None
        before_m = self.world.used
        self.world.update(chosen[1] if chosen is not None else None)
        if (self.world.last_accepted and before_m is not None
                and math.dist(self.world.used, before_m) > self.config.world_gate_m):
            # A jump two sightings confirmed: what was placed before is another thing (or a worse estimate of this
            # one), and the median of both kinds of place lies on neither (measured, hard world seed 80,
            # hard_1468430193: a blob on the wall placed first, then the opening 1.2 m from it; the vehicle
            # centred on the wall halfway between, blobs there confirmed that place, the push met the opening's edge)
            self._forget_history()
        self._remember([cp for cp in placed if chosen is None or cp[0] is not chosen[0]], radius_m)
        estimated = chosen is not None and self.world.last_accepted
        estimate = estimate_px = None
        judged_here = False
        if estimated:
            estimate, estimate_px = radius_m(chosen[0]), radius_px(chosen[0].detection)
            at = (depth(chosen[0].target_px), wall_yaw_rad)
            self.radii.append(estimate)
            self.radii_at.append(at)
            judged_here = (math.dist(chosen[1], across_m) <= self.config.judge_offset_m
                           and wall_distance_m <= self.config.decide_within_m and moved_m >= self.config.judge_step_m)
            if judged_here:
                self.close_radii.append(estimate)
                self.close_at.append(at)
            if wall_distance_m <= self.config.decide_within_m:
                self.near_radii.append(estimate)
                self.near_at.append(at)
            self.places.append(chosen[1])
            self.close_places += wall_distance_m <= self.config.decide_within_m
        # the opening does not move: its place is the median of the latest sightings (each jitters by a few px)
        target = median_place(self.places[-self.config.radius_window:] or [self.world.used])
        # steered by every estimate until close ones, taken in front of the opening, are there to judge it by
        best = self.close_radii or self.radii
        radius = upper_quartile(best, self.config.radius_window)
        if estimated:
            self.radius_trail.append(radius)
        refusal = None
        judged = len(self.close_radii) >= self.config.min_estimates
        if judged and judged_tolerance(radius, self.servo) < 0:
            fits = [(c, p, radius_m(c)) for c, p in placed if chosen is None or c is not chosen[0]]
            fits = [f for f in fits if judged_tolerance(f[2], self.servo) >= 0]
            too_small = self.describe_too_small(chosen[0].detection if chosen is not None else None, radius,
                                                depth(chosen[0].target_px) if chosen is not None else wall_distance_m,
                                                focal_px)
            if fits and not self.switched:
                c, p, r = max(fits, key=lambda f: f[2])
                self.pixels.seed(c.target_px)
                self.world.seed(p)
                self.radii, self.close_radii, self.places, self.radius_trail = [r], [r], [p], [r]
                self.near_radii = [r]
                at = (depth(c.target_px), wall_yaw_rad)
                self.radii_at, self.close_at, self.near_at = [at], [at], [at]
                self.close_places = 1        # judged from within decide_within_m, as every switch is
                self.switched = True
                target, radius, chosen = p, r, (c, p)
                note = f"{too_small}; taking the one {math.dist(p, viewer):.2f} m away, {2 * r:.2f} m clear"
            else:
                refusal = f"{too_small}: not flying through"
        # What the vehicle steers and pushes by holds after two estimates in a row: one view's estimate, the first
        # or one that jumps (measured, hard world seeds 41, 44 and 45: 0.16 -> 0.38 m, 0.23 -> 0.50 m, 0.29 ->
        # 0.35 m and a first 0.83 m, on openings 0.22-0.27 m clear, each pushed at once and touched), does not
        # decide a push on its own.
        steady = min(self.radius_trail[-2:]) if len(self.radius_trail) >= 2 else 0.0
        offset = (target[0] - viewer[0], target[1] - viewer[1])
        here = None
        if chosen is not None and axis_px is not None and self.world.last_accepted:
            # the heading's axis from where the vehicle is now, as that view saw the wall
            shift = focal_px / wall_distance_m
            axis = (axis_px[0] + (viewer[0] - across_m[0]) * shift, axis_px[1] + (viewer[1] - across_m[1]) * shift)
            mask = wall_view(chosen[0].detection)[0]
            here = self.clear_radius_m(edge_distance_px(mask, (axis[0] * stretch, axis[1])), depth(axis),
                                       focal_px) if chosen[0].detection.mask.any() else 0.0
        return Sight(chosen[0].detection if chosen is not None else None, used, offset, steady, here,
                     len(self.places), self.close_places, len(self.close_radii), note, refusal, estimate, estimate_px,
                     judged_here, radius if judged else None)

    def _forget_history(self) -> None:
        """Drop what was kept of the tracked opening (its places, size estimates and sighting counts): what comes
        next is another opening, or a better placed one."""
        self.radii, self.close_radii, self.places, self.radius_trail = [], [], [], []
        self.near_radii = []
        self.radii_at, self.close_at, self.near_at = [], [], []
        self.close_places = 0

    def set_wall_thickness(self, thickness_m: float) -> None:
        """Judge by a wall ``thickness_m`` deep from now on (companion.thickness measured it), and take the tracked
        opening's estimates so far to it: each was scaled by its depth plus the thickness assumed, and, in a turned
        wall, stretched to the wall's plane by a factor that depends on the thickness (:func:`turned_wall_stretch`).
        The trail the vehicle steers by goes with the latest estimate's factor."""
        old = self.servo.wall_thickness_m
        need = self.servo.body_radius_m + self.servo.clearance_margin_m

        def factor(at: tuple[float, float | None]) -> float:
            depth, turn = at
            f = (depth + thickness_m) / (depth + old)
            if turn is not None and abs(turn) > TURN_NEGLIGIBLE_RAD:
                f *= (turned_wall_stretch(need, depth, turn, thickness_m)
                      / turned_wall_stretch(need, depth, turn, old))
            return f

        for values, ats in ((self.radii, self.radii_at), (self.close_radii, self.close_at),
                            (self.near_radii, self.near_at)):
            values[:] = [r * factor(at) for r, at in zip(values, ats, strict=True)]
        if self.radii_at:
            latest = factor(self.radii_at[-1])
            self.radius_trail = [r * latest for r in self.radius_trail]
        self.servo = dataclasses.replace(self.servo, wall_thickness_m=thickness_m)

    def _shrunk(self, steered_m: float | None) -> bool:
        """Whether every size estimate from within ``decide_within_m`` is under ``near_size_ratio`` of
        ``steered_m``; False with none."""
        return bool(self.near_radii) and bool(steered_m) and (
            max(self.near_radii) < self.config.near_size_ratio * steered_m)

    def shrunk_on_approach(self, steered_m: float | None) -> str | None:
        """Why the tracked opening is not one to push through, when its size estimates from within
        ``decide_within_m``, ``near_estimates`` of them at least, are all under ``near_size_ratio`` of ``steered_m``
        (the clear radius it is steered and pushed by, set by views from farther): a real opening's estimates agree
        from any distance, a pattern on the wall taken for one shrinks as the vehicle nears it.  None where they
        agree, or fewer are there (see :meth:`doubted_on_approach`)."""
        if not self._shrunk(steered_m) or len(self.near_radii) < self.config.near_estimates:
            return None
        near = max(self.near_radii)
        return (f"the opening judged {2 * steered_m:.2f} m clear from farther looks {2 * near:.2f} m clear from "
                f"within {self.config.decide_within_m:g} m of the wall: what shrinks as it is approached is no "
                "opening (a pattern on the wall?): not flying through")

    def doubted_on_approach(self, steered_m: float | None) -> bool:
        """Whether the near estimates say it shrank but are too few to refuse it by: no push yet, one more frame
        (a single notched mask is not a pattern on the wall)."""
        return self._shrunk(steered_m) and len(self.near_radii) < self.config.near_estimates

    def _remember(self, placed: list[tuple[Candidate, Point]], radius_m) -> None:
        """Keep the places and clear radii (``radius_m`` of a candidate) of openings other than the tracked one (each
        sighting joins the remembered opening whose place is within the world gate of it, or starts one)."""
        gate, window = self.config.world_gate_m, self.config.radius_window
        for c, p in placed:
            if c.detection.clear_radius_px < self.config.min_opening_px:
                continue
            if self.world.used is not None and math.dist(p, self.world.used) <= gate:
                continue                       # the tracked one, seen but not matched in the image
            radius = radius_m(c)
            near = _nearest(self.elsewhere, p, gate, lambda e: e.place(window))
            if near is None:
                self.elsewhere.append(SeenElsewhere([p], [radius]))
            else:
                near.places.append(p)
                near.radii.append(radius)

    def alternative(self) -> Point | None:
        """Where (right, down) the widest other opening is, among those placed in ``alternative_sightings``
        frames or more, away from the tracked one and from those refused before, and as wide as the body at
        least in one view (seen at an angle or at the frame's edge, an opening shows less than it has); None
        without one.  A refused opening's search looks again in front of it first (measured, hard world seeds
        64-66: the search's looks from either side of the start's axis take no opening near the axis, and a
        first look that followed another opening never came back to a passable one there).  Away from the tracked
        one means from every place it was accepted at, not only the latest: as the wall's distance settles, an
        opening's place moves, and a part of it placed beside it early on is it (hard world seed 66,
        hard_0760398658: the look in front of the one other opening remembered found only the refused one; not
        flown again with this rule)."""
        gate, window = self.config.world_gate_m, self.config.radius_window
        taken = [*self.avoid, *self.places, *([self.world.used] if self.world.used is not None else [])]
        ones = [e for e in self.elsewhere
                if len(e.places) >= self.config.alternative_sightings
                and max(e.radii) >= self.servo.body_radius_m
                and all(math.dist(e.place(window), t) > gate for t in taken)]
        if not ones:
            return None
        return max(ones, key=lambda e: max(e.radii)).place(window)

    def describe_too_small(self, detection, radius_m: float, wall_distance_m: float, focal_px: float) -> str:
        """'opening 0.31 × 0.42 m (0.30 m clear) is narrower than the vehicle's 0.38 m plus 0.10 m margin'; one
        judged no narrower than that, but within the estimate's allowance of it, is called too close to tell."""
        s = self.servo
        size = ""
        if detection is not None and detection.mask.any():
            ys, xs = np.nonzero(detection.mask)
            scale = (wall_distance_m + s.wall_thickness_m) / focal_px
            size = f"{(xs.max() - xs.min() + 1) * scale:.2f} × {(ys.max() - ys.min() + 1) * scale:.2f} m "
        if alignment_tolerance(radius_m, s) >= 0:
            return (f"opening {size}({2 * radius_m:.3f} m clear) is too near the vehicle's {2 * s.body_radius_m:.2f} m "
                    f"plus {2 * s.clearance_margin_m:.2f} m margin to tell, within the size estimate's "
                    f"{2 * s.size_allowance_m:.3f} m allowance")
        return (f"opening {size}({2 * radius_m:.2f} m clear) is narrower than the vehicle's "
                f"{2 * s.body_radius_m:.2f} m plus {2 * s.clearance_margin_m:.2f} m margin")


# the words of describe_too_small's two refusals, for tools that sort a flight's refusal by its reason
_TOO_SMALL_WORDS = ("is narrower than", "to tell, within")


def is_size_refusal(reason: str | None) -> bool:
    """Whether a refusal's reason is one of :meth:`OpeningTracker.describe_too_small`'s: judged too small, or too
    near the need to tell."""
    return reason is not None and any(words in reason for words in _TOO_SMALL_WORDS)


def _nearest(items, reference: Point | None, gate: float, key):
    """The item whose ``key`` is nearest ``reference`` within ``gate``, or None."""
    if reference is None or not items:
        return None
    best = min(items, key=lambda item: math.dist(key(item), reference))
    return best if math.dist(key(best), reference) <= gate else None

