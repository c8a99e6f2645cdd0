"""Image-based visual servoing toward the gap (docs/design.md steps 5–8), as pure functions.

Sign convention (docs/design.md step 5, correcting the paper): with a forward camera in FRD, a gap seen to
the right of the image centre (e_u > 0) is to the vehicle's right (+y in NED when heading north), so the
lateral step is Δy = +κ_y·e_u; likewise a gap below the centre (e_v > 0) is lower, Δz = +κ_z·e_v (NED z
is down). Steps are taken in the heading frame and rotated into NED by the current yaw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ServoConfig:
    """Constants of the servo law; the paper's values where it gives them, ours (measured) elsewhere."""

    kappa_y: float = 0.30  # m per unit normalised error (paper)
    align_error: float = 0.6  # forward step shrinks linearly as max(|e_u|, |e_v|) grows toward this (ours) ...
    min_forward_frac: float = 0.35  # ... down to this fraction of δ_f: align first when far off-axis (ours)
    kappa_z: float = 0.30  # m per unit normalised error (paper)
    forward_step_m: float = 0.20  # δ_f in the servo phase (paper silent; ours: steps scaled with the measured
                                  # wall distance flew worse, the flow-based distance is poor on short steps)
    lateral_clamp_far_m: float = 0.06  # |Δy|, |Δz| limit during early steps (paper)
    lateral_clamp_close_m: float = 0.12  # ... when close to the window (paper)
    close_area_frac: float = 0.10  # mask area / image area from which the vehicle counts as "close" (ours)
    close_distance_m: float = 1.6  # ... or measured wall distance below this (ours)
    push_area_frac: float = 0.20  # centred and at least this large: push through now (ours)
    push_distance_m: float = 1.4  # centred and the wall at most this far: push through now (ours; measured:
                                  # detection degrades inside ~1 m, where the opening fills the view)
    last_call_distance_m: float = 1.1  # the wall this close: push through whatever the centring (ours)
    centred_tol: float = 0.12  # |e_u|, |e_v| below this counts as centred (ours)
    step_budget: int = 30  # servo steps before pushing through regardless (paper: 16, standing in for "close"
                           # with fixed steps; ours shrink while misaligned and closeness is measured, so
                           # the budget is only a cap: at 16, 12 of 13 failed flights pushed blind from 1–2.6 m)
    push_increment_m: float = 0.05  # forward increment of the final traversal (paper)
    push_margin_m: float = 0.55  # how far past the wall's back face the push ends (ours)
    push_default_m: float = 2.0  # traversal length when the wall distance could not be measured (ours)
    push_max_beyond_wall_m: float = 1.2  # never push further than this past the wall (scenes put a background
                                         # surface 2 m behind it; a real room has one too)
    wall_thickness_m: float = 0.15  # assumed wall depth for the push length (suite walls are 0.15 m)
    # Metric alignment (ours), once the wall's distance Z is measured: the target's pixel offset times Z/f is
    # the body's lateral and vertical offset from the opening's clear centre in metres; the paper's κ·e is a
    # fixed fraction of it whatever the distance, too slow close to the wall (an opening 0.9 m to the side
    # was still 0.27 m off when the wall came within reach, and the push met its edge).
    body_radius_m: float = 0.19  # the vehicle's collision sphere (quad250's: 0.38 m across, props included)
    clearance_margin_m: float = 0.05  # kept free between the sphere and the opening's edge, each side
    size_allowance_m: float = 0.007  # a judged clear radius must beat the sphere and its margin by this too: its
                                     # error near the need (measured, hard world seeds 87-91: the four impassable
                                     # openings flown through, 0.224-0.238 m clear, none touched, had been judged
                                     # 0.0007-0.0066 m over the 0.24 m needed; flown again with it, seeds 88-91
                                     # refused every impassable one and lost 1-3 passable flights each)
    metric_gain: float = 0.7  # fraction of the metric offset removed per step
    metric_max_step_m: float = 0.25  # |Δy|, |Δz| limit of a metric step
    metric_slowdown_m: float = 0.5  # the forward step shrinks as the offset grows toward this (to the minimum
                                    # fraction above)
    hold_distance_m: float = 1.1  # misaligned, the vehicle moves no closer than this to the wall; it centres
                                  # first, then pushes (the paper pushes whatever the centring)
    far_margin_m: float = 0.35  # the push stops this short of the far surface seen through the opening (ours;
                                # measured: the vehicle runs on 0.1-0.2 m past the push's last setpoint)
    probe_step_m: float = 0.08  # aligned on the tracked place but not seen this frame: creep this far on ...
    probe_floor_m: float = 0.9  # ... while the wall is further than this; held still, step this far sideways
    roomy_tolerance_m: float = 0.1  # an opening this much wider than needed may be pushed through unseen in
                                    # the last frame (the push's own correction is 0.06 m at most) ...
    roomy_sightings: int = 3        # ... once this many frames placed it (measured: two sightings at the frame's
                                    # edge placed one 0.3 m off, and the push met its edge) ...
    roomy_close_sightings: int = 1  # ... this many of them with the wall within OpeningConfig.decide_within_m
                                    # (measured, hard world seed 60: a place tracked from 2-4 m, last seen 1.85 m
                                    # out, was a blob on the wall; pushed on from 1.2 m, the vehicle hit it)
    judged_tight: int = 1           # an opening less than roomy_tolerance_m wider than needed (any, in a search
                                    # look) is pushed only once this many of its size estimates were taken in front
                                    # of it near the wall (OpeningConfig.judge_offset_m, decide_within_m): from the
                                    # side a mask took in more than the opening (measured, hard world seeds 74 and 76:
                                    # openings 0.44 and 0.41 m clear judged 0.54 and 0.61 m from 0.3-0.7 m to their
                                    # side, pushed at once; the second touched)
    push_sightings: int = 3         # no push on an opening fewer frames than this placed, the tracked one's since
                                    # any switch (measured, hard world seed 69: lost at 1.0 m from the wall, the
                                    # tracker took another opening and pushed on its second sighting, which put
                                    # a 0.40 m wide ellipse at 0.82 m; the vehicle hit it)


@dataclass(frozen=True)
class ServoStep:
    """One decision: the step to take and why."""

    delta_heading: tuple[float, float, float]  # forward, right, down in the heading frame, metres
    error: tuple[float, float] | None  # (e_u, e_v), None without a centroid
    close: bool
    push: bool  # time to stop servoing and traverse
    offset_m: tuple[float, float] | None = None  # metric (right, down) offset of the target, when measured
    tolerance_m: float | None = None  # how far off the target the sphere still clears the edges (< 0: cannot)
    aligned: bool | None = None  # metric law: the sphere would clear the edges now (None: not measured)
    judged: bool | None = None   # metric law: its size judged as a push needs (ServoConfig.judged_tight)


def metric_offset(error: tuple[float, float], width: int, height: int, focal_px: float,
                  distance_m: float) -> tuple[float, float]:
    """Metres right and down from the camera axis to the target at depth ``distance_m``: pixel offset · Z/f."""
    e_u, e_v = error
    return e_u * (width / 2) * distance_m / focal_px, e_v * (height / 2) * distance_m / focal_px


def alignment_tolerance(clear_radius_m: float, config: ServoConfig) -> float:
    """How far (m) the body's centre may be from the clear centre with the sphere still clearing every edge by
    the margin: the opening's clear radius less the body radius and the margin (negative: it cannot pass)."""
    return clear_radius_m - config.body_radius_m - config.clearance_margin_m


def judged_tolerance(judged_radius_m: float, config: ServoConfig) -> float:
    """:func:`alignment_tolerance` of an opening's judged clear radius (its size estimates'), less the estimate's
    allowance (``size_allowance_m``): what fit and refusal decide by."""
    return alignment_tolerance(judged_radius_m - config.size_allowance_m, config)


def normalised_error(centroid: tuple[float, float], width: int, height: int) -> tuple[float, float]:
    """docs/design.md step 5: e_u = (u − W/2)/(W/2), e_v = (v − H/2)/(H/2)."""
    u, v = centroid
    return (u - width / 2) / (width / 2), (v - height / 2) / (height / 2)


def servo_step(centroid: tuple[float, float] | None, area_frac: float, step_index: int, width: int,
               height: int, config: ServoConfig = ServoConfig(), wall_distance_m: float | None = None) -> ServoStep:
    """The paper's law with our corrected sign: Δp = [δ_f, κ_y·e_u, κ_z·e_v], clamped; forward only without
    a centroid (new parallax baseline). ``step_index`` counts the steps already taken.  Once the wall's
    distance is measured the mission flies :func:`metric_step` instead."""
    budget_spent = step_index + 1 >= config.step_budget
    near = wall_distance_m is not None and wall_distance_m <= config.last_call_distance_m
    forward = config.forward_step_m
    if centroid is None:
        return ServoStep((forward, 0.0, 0.0), None, False, budget_spent or near)
    e_u, e_v = normalised_error(centroid, width, height)
    close = area_frac >= config.close_area_frac or (
        wall_distance_m is not None and wall_distance_m <= config.close_distance_m)
    clamp = config.lateral_clamp_close_m if close else config.lateral_clamp_far_m
    dy = float(np.clip(config.kappa_y * e_u, -clamp, clamp))
    dz = float(np.clip(config.kappa_z * e_v, -clamp, clamp))
    # The lateral step is clamped, so a gap far off-axis is reached only if the forward step waits for it.
    misalign = max(abs(e_u), abs(e_v))
    forward *= float(np.clip(1.0 - misalign / config.align_error, config.min_forward_frac, 1.0))
    centred = abs(e_u) <= config.centred_tol and abs(e_v) <= config.centred_tol
    large = area_frac >= config.push_area_frac or (
        wall_distance_m is not None and wall_distance_m <= config.push_distance_m)
    push = (centred and large) or budget_spent or near
    return ServoStep((forward, dy, dz), (e_u, e_v), close, push)


def probe_aside_m(step_index: int, config: ServoConfig = ServoConfig()) -> float:
    """A step sideways (right, metres) for a frame pair with parallax where the vehicle would stay in place: right
    and left in turn by ``step_index``, so that the next step returns."""
    return config.probe_step_m if step_index % 2 == 0 else -config.probe_step_m


def metric_step(offset_m: tuple[float, float], clear_radius_m: float, distance_m: float, area_frac: float,
                step_index: int, config: ServoConfig = ServoConfig(),
                error: tuple[float, float] | None = None, clearance_here_m: float | None = None,
                sightings: int = 0, close_sightings: int = 0, judged_estimates: int | None = None,
                lag_m: tuple[float, float] = (0.0, 0.0)) -> ServoStep:
    """One step of the metric law, from the body's (right, down) offset to the opening's clear centre in
    metres and the opening's clear radius (judged, less its ``size_allowance_m``): remove ``metric_gain`` of the
    offset (clamped), move forward less the further off it is, never closer than ``hold_distance_m`` while the
    sphere would not clear the edges, and push once it would (and the wall is close, or the opening large, or the
    step budget spent; never while it would not: ``aligned`` tells the caller).  Whether it would: from
    ``clearance_here_m``, the distance from the heading's axis to the opening's nearest edge seen in this frame,
    when there is one (an elongated opening leaves room along its length), else from the offset and the clear
    radius.  Not seen in this frame, it pushes only with room to spare, on a place ``sightings`` frames placed,
    ``close_sightings`` of them from near the wall; never on one fewer than ``push_sightings`` frames placed
    (after a switch, the new one's), where it creeps on as for an unseen place; and on one with little room to
    spare only once ``judged_estimates`` of its size estimates (``judged_tight`` at least) were taken in front of
    it (None: not counted).  ``error``: the image error, for the record.  ``lag_m``: how far (right, down) the
    waypoint the vehicle is on its way to lies from where the frame was taken; a centring step goes from the
    waypoint, the push from where the vehicle is."""
    budget_spent = step_index + 1 >= config.step_budget
    tolerance = judged_tolerance(clear_radius_m, config)
    fresh = clearance_here_m is not None
    limit = config.metric_max_step_m

    def correction(offset: tuple[float, float]) -> tuple[float, float]:
        return (float(np.clip(config.metric_gain * offset[0], -limit, limit)),
                float(np.clip(config.metric_gain * offset[1], -limit, limit)))

    # The waypoint is the last one plus the step.  Taken from the frame's place, the step counted the part of the
    # last one the vehicle had yet to fly (or had overshot) twice: the frame is taken within the arrival tolerance
    # (up to 0.06 m, companion.mission), and the next waypoint went that far past the opening's
    # centre (measured, hard world seed 77, hard_0602231812: 1.0 m from the wall, 0.10-0.16 m swings across a
    # 0.05 m wide centre for 17 steps, then "could not centre"; in seeds 76 and 77, the frame's place across was
    # 0.024 m from the waypoint at the median of 3,161 metric steps, over 0.03 m in 42 % of them).
    dy, dz = correction((offset_m[0] - lag_m[0], offset_m[1] - lag_m[1]))
    off = math.hypot(*offset_m)
    if fresh:
        aligned = 0.0 <= tolerance and alignment_tolerance(clearance_here_m, config) >= 0.0
    else:
        aligned = 0.0 <= tolerance and off <= tolerance
    forward = config.forward_step_m * float(np.clip(1.0 - off / config.metric_slowdown_m,
                                                    config.min_forward_frac, 1.0))
    close = area_frac >= config.close_area_frac or distance_m <= config.close_distance_m
    large = area_frac >= config.push_area_frac or distance_m <= config.push_distance_m
    # A sphere with room to spare may push on the tracked place alone, once several sightings placed it, one of
    # them close; one that only just fits must have been seen clear in this very frame.
    roomy = (aligned and tolerance >= config.roomy_tolerance_m and sightings >= config.roomy_sightings
             and close_sightings >= config.roomy_close_sightings)
    # ... and one that only just fits must have been judged from in front of it (judged_tight)
    judged = (judged_estimates is None or tolerance >= config.roomy_tolerance_m
              or judged_estimates >= config.judged_tight)
    placed = sightings >= config.push_sightings and judged
    if not aligned:
        forward = min(forward, max(0.0, distance_m - config.hold_distance_m))
    elif not ((fresh or roomy) and placed) and large:
        forward = min(forward, config.probe_step_m) if distance_m > config.probe_floor_m else 0.0
    if forward < 0.02 and abs(dy) < 0.02 and abs(dz) < 0.02:
        # held in place a frame pair has no parallax to see the opening by: step sideways, right and left in
        # turn, and the next step returns.  Not back: moving along the axis puts a centred opening at the focus
        # of expansion, where the flow shows no depth (measured, hard world seed 43: probing back and forth 0.9 m
        # from a turned wall, a vehicle centred on an opening never saw it clear again)
        dy = probe_aside_m(step_index, config)
    push = aligned and (fresh or roomy) and placed and (large or budget_spent)
    if push:        # the push starts from where the frame was taken (companion.mission), its bias from there
        dy, dz = correction(offset_m)
    return ServoStep((forward, dy, dz), error, close, push, (float(offset_m[0]), float(offset_m[1])), tolerance,
                     aligned, judged)


def heading_to_ned(delta: tuple[float, float, float], yaw: float) -> tuple[float, float, float]:
    f, r, d = delta
    c, s = math.cos(yaw), math.sin(yaw)
    return (c * f - s * r, s * f + c * r, d)


def far_distance_from_flow(flow: np.ndarray, gap_mask: np.ndarray, translation_m: float,
                           erode_px: int = 4) -> float | None:
    """Metric distance to the far surface seen through the opening, by the same parallax as the wall's:
    Z = |T|/ρ with ρ the median relative inverse depth inside the gap mask (shrunk by ``erode_px`` so that
    the wall's flow at its edge stays out).  None when too little of the mask is measurable."""
    import cv2

    from companion.gap import inverse_depth_from_flow

    if translation_m <= 1e-3 or gap_mask is None:
        return None
    inner = cv2.erode(gap_mask.astype(np.uint8), np.ones((2 * erode_px + 1,) * 2, np.uint8)).astype(bool)
    rho, valid = inverse_depth_from_flow(flow)
    keep = inner & valid & np.isfinite(rho) & (rho > 0)
    if keep.sum() < 30:
        return None
    rho_far = float(np.median(rho[keep]))
    return translation_m / rho_far if rho_far > 0 else None


def wall_distance_from_flow(flow: np.ndarray, gap_mask: np.ndarray | None, translation_m: float,
                            motion_direction_cam: tuple[float, float, float] | None = None,
                            focal_px: float | None = None, textured: np.ndarray | None = None) -> float | None:
    """Metric distance to the nearer surface (the wall) straight ahead, from flow and the known length of the
    camera's translation between the frames: for a translating camera the flow is (|T|/Z)·g, so Z = |T|/ρ with ρ
    the relative inverse depth.  With ``focal_px``, ρ is that of the plane fitted through the wall's inverse
    depth (:func:`_wall_plane`) at the image's centre; without it, or with too little wall for a plane,
    the 60th percentile of ρ over measurable pixels outside the gap (it leans toward the wall and away from far
    pixels a gap mask missed, but also toward a turned wall's near side: measured on 201 close frame pairs of
    hard-world flights, seeds 60 and 61, the percentile read 0.966 of the true distance at the median, 0.961
    with the wall turned 10-21°; the plane 0.996, and 0.993-1.002 whatever the turn).  ``motion_direction_cam``:
    the translation's direction in the first camera's axes when known (else estimated from the flow);
    ``textured``: the pixels whose flow is read (:func:`companion.gap.textured_pixels`; None: all)."""
    from companion.gap import CameraMotion, inverse_depth_from_flow

    if translation_m <= 1e-3:
        return None
    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=motion_direction_cam))
    left_out = _left_out(gap_mask, textured)
    plane = _wall_plane(rho, valid, left_out, focal_px) if focal_px is not None else None
    return _distance(rho, valid, left_out, translation_m, plane)


def wall_from_flow(flow: np.ndarray, gap_mask: np.ndarray | None, translation_m: float, focal_px: float,
                   motion_direction_cam: tuple[float, float, float] | None = None,
                   textured: np.ndarray | None = None) -> tuple[float | None, float | None]:
    """(:func:`wall_distance_from_flow`, :func:`wall_yaw_from_flow`) of one frame pair, from one inverse depth and
    one plane fit (the two read the same plane).  The move's direction known (from the autopilot's estimates)
    and the pixels without texture left out, the readings of the frame pairs within 2.6 m of the wall in 47
    hard-world flights (seeds 60 and 61, re-rendered at the flown poses and re-perceived) came out within 5.5 %
    of the truth in nine cases of ten where part of the view had no texture (91 pairs: the empty space beyond a
    wall's end), against 25 % with the direction estimated from the flow, and as before elsewhere (1,222 pairs:
    6.0 % against 5.9 %)."""
    from companion.gap import CameraMotion, inverse_depth_from_flow

    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=motion_direction_cam))
    left_out = _left_out(gap_mask, textured)
    plane = _wall_plane(rho, valid, left_out, focal_px)
    distance = _distance(rho, valid, left_out, translation_m, plane) if translation_m > 1e-3 else None
    return distance, _yaw(plane)


def depth_against_wall(flow: np.ndarray, masks: list[np.ndarray], focal_px: float,
                       motion_direction_cam: tuple[float, float, float] | None = None,
                       textured: np.ndarray | None = None) -> list[float | None]:
    """For each of ``masks`` (the openings seen in one frame pair), the median inverse depth inside it as a
    fraction of the wall plane's there (:func:`_wall_plane`, fitted outside every mask): well under 1 for what is
    seen through an opening, about 1 for a patch of the wall itself that the detector took for one; None for all
    when there is too little wall for a plane, or for a mask with too little measurable flow."""
    from companion.gap import CameraMotion, inverse_depth_from_flow

    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=motion_direction_cam))
    return _depth_ratios(rho, valid, masks, focal_px, textured)[0]


def wall_and_openings(flow: np.ndarray, masks: list[np.ndarray], translation_m: float, focal_px: float,
                      max_depth_ratio: float, motion_direction_cam: tuple[float, float, float] | None = None,
                      textured: np.ndarray | None = None
                      ) -> tuple[list[int], list[float], float | None, float | None]:
    """One frame pair's openings and wall from one inverse depth: the indices of the ``masks`` kept as openings
    (:func:`depth_against_wall` at most ``max_depth_ratio``; all of them without ``textured``, as for a pair
    that moved too little to judge), the ratios of those set aside, and the wall's distance and turn read
    outside the kept ones (:func:`wall_from_flow`; None, None when none is kept).  The plane the ratios were
    judged by is the wall's when nothing is set aside."""
    from companion.gap import CameraMotion, inverse_depth_from_flow

    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=motion_direction_cam))
    ratios, plane = (_depth_ratios(rho, valid, masks, focal_px, textured) if masks and textured is not None
                     else ([None] * len(masks), None))
    kept = [i for i, r in enumerate(ratios) if r is None or r <= max_depth_ratio]
    patches = [r for r in ratios if r is not None and r > max_depth_ratio]
    if not kept:
        return kept, patches, None, None
    left_out = _left_out(np.logical_or.reduce([masks[i] for i in kept]), textured)
    if plane is None or patches:
        plane = _wall_plane(rho, valid, left_out, focal_px)
    distance = _distance(rho, valid, left_out, translation_m, plane) if translation_m > 1e-3 else None
    return kept, patches, distance, _yaw(plane)


def _depth_ratios(rho: np.ndarray, valid: np.ndarray, masks: list[np.ndarray], focal_px: float,
                  textured: np.ndarray | None) -> tuple[list[float | None], np.ndarray | None]:
    """:func:`depth_against_wall` from an inverse depth, and the plane fitted outside every mask (or None)."""
    gaps = np.logical_or.reduce(masks) if masks else None
    plane = _wall_plane(rho, valid, _left_out(gaps, textured), focal_px)
    if plane is None:
        return [None] * len(masks), None
    h, w = rho.shape
    ratios = []
    for mask in masks:
        inside = mask & valid & np.isfinite(rho)
        if inside.sum() < 10:
            ratios.append(None)
            continue
        ys, xs = np.nonzero(inside)
        wall_rho = plane[0] * (xs - (w - 1) / 2) / focal_px + plane[1] * (ys - (h - 1) / 2) / focal_px + plane[2]
        ratios.append(float(np.median(rho[inside]) / np.median(wall_rho)))
    return ratios, plane


def _left_out(gap_mask: np.ndarray | None, textured: np.ndarray | None) -> np.ndarray | None:
    """The pixels a wall reading leaves out: the gaps', and those without texture."""
    if textured is None:
        return gap_mask
    untextured = ~textured.astype(bool)
    return untextured if gap_mask is None else gap_mask.astype(bool) | untextured


def _distance(rho: np.ndarray, valid: np.ndarray, gap_mask: np.ndarray | None, translation_m: float,
              plane: np.ndarray | None) -> float | None:
    """The wall's distance straight ahead: from ``plane`` (:func:`_wall_plane`) when there is one, else from the
    60th percentile of ρ (see :func:`wall_distance_from_flow`)."""
    if plane is not None:
        return translation_m / plane[2]
    keep = valid & np.isfinite(rho) & (rho > 0)
    if gap_mask is not None:
        keep &= ~gap_mask.astype(bool)
    h, w = keep.shape
    core = np.zeros_like(keep)
    core[h // 6: h - h // 6, w // 6: w - w // 6] = True  # the wall around the gap, not the floor at the edges
    keep &= core
    if keep.sum() < 0.02 * h * w:
        return None
    rho_wall = float(np.percentile(rho[keep], 60))
    return translation_m / rho_wall if rho_wall > 0 else None


TURN_NEGLIGIBLE_RAD = 0.05  # a wall measured as turned less than this (about 3°) is taken to face the camera


def wall_forward_at(readings: list[tuple[float, float]], across_m: float, turn_rad: float | None) -> float:
    """The wall's forward coordinate straight ahead of ``across_m`` (metres right of the initial heading), from
    ``readings``: (the wall's forward coordinate as measured straight ahead, the across coordinate it was measured
    from).  A wall turned by ``turn_rad`` (:func:`wall_yaw_from_flow`'s sign: positive, its right side further
    away) is ``tan(turn)`` metres further per metre to the right, so each reading is carried along the wall to
    ``across_m`` before the median (measured, hard world seed 47: a wall turned 16.5° and readings taken over 1.4 m
    of sideways flight put it about 0.2 m too far, and the opening's clear radius, scaled by that distance, came
    out 0.275 m for 0.205 m; the vehicle pushed into an opening it could not pass).  Without a measured turn, or
    a negligible one, the plain median."""
    return float(np.median(carried_along_wall(readings, across_m, turn_rad)))


def carried_along_wall(readings: list[tuple[float, float]], across_m: float, turn_rad: float | None) -> list[float]:
    """Each reading's forward coordinate carried along a wall turned by ``turn_rad`` to ``across_m``."""
    slope = wall_slope(turn_rad)
    return [forward + (across_m - across) * slope for forward, across in readings]


def wall_readings_agree(readings: list[tuple[float, float]], across_m: float, turn_rad: float | None,
                        here_m: float, count: int, tolerance_m: float, per_metre: float) -> bool:
    """Whether the latest ``count`` wall readings ((forward, across) as for :func:`wall_forward_at`), carried
    along the wall to ``across_m``, lie within ``tolerance_m`` plus ``per_metre`` of the distance from
    ``here_m`` (the forward coordinate the vehicle is at) of each other: the wall, seen steadily, not what lies
    behind a wall's end, whose readings jump (measured over the flights of hard world seeds 46-48: of 5,634 runs of
    three readings, the 3,766 that agreed so had their median at most 0.16 m beyond the true wall within 1.3 m of
    it, and 0.19 m within 1.8 m)."""
    if len(readings) < count:
        return False
    carried = carried_along_wall(readings[-count:], across_m, turn_rad)
    distance = max(0.0, float(np.median(carried)) - here_m)
    return max(carried) - min(carried) <= tolerance_m + per_metre * distance


def wall_slope(turn_rad: float | None) -> float:
    """How much further (m) the wall is per metre to the right: tan(turn), 0 without a measured turn or with a
    negligible one."""
    return 0.0 if turn_rad is None or abs(turn_rad) <= TURN_NEGLIGIBLE_RAD else math.tan(turn_rad)


def wall_yaw_from_flow(flow: np.ndarray, gap_mask: np.ndarray | None, focal_px: float) -> float | None:
    """How far the wall is turned against the camera's axis (radians, positive: its right side further away),
    from the plane of its inverse depth (:func:`_wall_plane`): its normal's direction.  None when too
    little wall is measurable."""
    from companion.gap import inverse_depth_from_flow

    return _yaw(_wall_plane(*inverse_depth_from_flow(flow), gap_mask, focal_px))


def _yaw(plane: np.ndarray | None) -> float | None:
    """The wall's turn from its plane (:func:`_wall_plane`), None without one."""
    return None if plane is None else float(math.atan2(-plane[0], plane[2]))


def _wall_plane(rho: np.ndarray, valid: np.ndarray, gap_mask: np.ndarray | None,
                focal_px: float) -> np.ndarray | None:
    """The wall's plane in inverse depth: on a plane, ρ is linear in the normalised image coordinates, ρ = a·x/f
    + b·y/f + c, with (a, b, c) ∝ its normal; a least-squares fit through the wall's ρ (outside the gaps, away
    from the frame's edges and from far pixels a mask missed).  (a, b, c), c > 0 (ρ straight ahead); None when
    too little wall is measurable or the fit puts the plane behind the camera."""
    keep = valid & np.isfinite(rho) & (rho > 0)
    if gap_mask is not None:
        keep &= ~gap_mask.astype(bool)
    h, w = keep.shape
    core = np.zeros_like(keep)
    core[h // 8: h - h // 4, w // 10: w - w // 10] = True      # not the floor at the bottom, nor the edges
    keep &= core
    if keep.sum() < 0.05 * h * w:
        return None
    values = rho[keep]
    lo, hi = np.percentile(values, (20, 95))                    # the wall, not what lies beyond it
    keep &= (rho >= lo) & (rho <= hi)
    ys, xs = np.nonzero(keep)
    a = np.stack([(xs - (w - 1) / 2) / focal_px, (ys - (h - 1) / 2) / focal_px, np.ones(len(xs))], axis=1)
    coef, *_ = np.linalg.lstsq(a, rho[keep], rcond=None)
    return coef if coef[2] > 0 else None
