"""``flowgap-tlog replay RUN_DIR``: re-run a logged flight's perception with other settings.

The companion logs each frame's true pose (``frames.jsonl``) and each decision (``decisions.jsonl``).
Replay re-renders the camera at those poses, runs flow → derotation → detector → τ_c filter with the
chosen backend and detector, and lists the steps where the used centroid differs from the one flown.
The vehicle's motion is not re-simulated: the replay answers "what would this perception have seen on the
same path", step by step.  With a recording (``--rerun``) the replayed frames, flow and masks go into a Rerun
recording beside what the flight's ``link.tlog`` holds: the estimated trajectory, the attitude and every
setpoint sent.
"""

from __future__ import annotations

import json
import math
from pathlib import Path


class ReplayError(ValueError):
    """The run directory cannot be replayed; the message says why."""


def read_jsonl(path: Path) -> list[dict]:
    """The records of a run log's ``.jsonl`` file; :class:`ReplayError` naming the file (and line) when it is
    missing or not JSON."""
    if not path.exists():
        raise ReplayError(f"{path} is missing: is this a flowgap-companion run directory?")
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                raise ReplayError(f"{path}:{n} is not valid JSON (truncated run log?)") from None
    return rows


def replay(run_dir: Path, flow: str | None = None, detector: str | None = None, differ_px: float = 10.0,
           recording=None, edges: str | None = None) -> dict:
    """Replay ``run_dir``; ``flow``/``detector``/``edges`` (an ``--edges`` mode) default to what the flight used;
    ``recording``: a :class:`companion.recording.FlightRecording` to log the replay into."""
    from companion.edges import edges_for
    from companion.flow.colour import flow_to_colour
    from companion.flow.registry import make_flow_backend, parse_backend
    from companion.gap import blind_detector, get_detector
    from companion.mission_config import MissionConfig
    from companion.opening import OpeningTracker, candidates_in
    from companion.perception import perceive
    from scenes import PinholeCamera, Pose, load_scene, render_splats

    summary_path = run_dir / "summary.json"
    if not summary_path.exists():
        raise ReplayError(f"{summary_path} is missing: is {run_dir} a flowgap-companion run directory?")
    summary = json.loads(summary_path.read_text())
    frames = {f["step"]: f for f in read_jsonl(run_dir / "frames.jsonl")}
    decisions = {d["step"]: d for d in read_jsonl(run_dir / "decisions.jsonl")}
    if 0 not in frames or len(frames) < 2:
        raise ReplayError(f"{run_dir / 'frames.jsonl'} holds {len(frames)} frames: nothing to replay")
    flow_spec = flow or summary["flow"]
    detector_name = detector or summary["detector"]
    name, options = parse_backend(flow_spec)
    backend = make_flow_backend(name, **options)
    detect = get_detector(detector_name)
    # the frames a blind look saw past the wall's end with (decisions.jsonl's past_the_end), replayed so too
    detect_blind = blind_detector(detector_name) or detect
    spec, cloud = load_scene(summary["scene"])
    camera = PinholeCamera()
    openings = OpeningTracker()   # the image phase of the mission's tracking: its centroid_used
    # openings' edges read as the flight read them (flights before 2026-12-06 kept the detector's masks)
    flown_edges = summary.get("edges") or "flow"
    edges_mode = edges or flown_edges
    edge_config = edges_for(edges_mode)
    heading = summary.get("heading_rad")   # absent from runs before 2026-12-05: placed along the camera's yaw
    if recording is not None:
        recording.scene(spec, cloud)
        recording.camera(camera.K, camera.width, camera.height)
        record_tlog(recording, run_dir / "link.tlog")

    def render(step):
        f = frames[step]
        return render_splats(cloud, camera, Pose(tuple(f["position_true"]), tuple(f["attitude_true"]))).rgb

    rows, prev = [], render(0)
    for step in sorted(s for s in frames if s > 0):
        rgb = render(step)
        if step not in decisions:
            # a look's first frame (a search's, or the servo's again after the thickness look): no pair ends on it
            prev = rgb
            continue
        decision = decisions[step]
        before, now = frames[step - 1].get("position_est"), frames[step].get("position_est")
        moved = math.dist(before, now) if before is not None and now is not None else None
        blind = decision.get("past_the_end", False)
        p = perceive(prev, rgb, frames[step - 1]["attitude_est"], frames[step]["attitude_est"], camera.K,
                     backend, detect_blind if blind else detect, baseline_m=moved,
                     min_baseline_m=MissionConfig().min_baseline_m, edges=edge_config)
        seen = candidates_in(p.detection, camera.K, frames[step]["attitude_est"], heading)
        used = openings.observe(seen, (0.0, 0.0), None, float(camera.K[0, 0]), camera.width,
                                camera.height).target_px
        flown = decision.get("centroid_used")
        if used is None or flown is None:
            distance = None if used is None and flown is None else math.inf
        else:
            distance = math.dist(used, flown)
        differs = distance is not None and distance > differ_px
        if recording is not None:
            f = frames[step]
            recording.frame(step, f["time_s"], rgb, flow_to_colour(p.flow), p.detection.mask, p.detection.centroid,
                            used, f["position_true"], f["attitude_true"],
                            text=f"step {step}: replayed {used}, flown {flown}")
        rows.append({"step": step, "flown_centroid": flown, "replay_centroid": used,
                     "replay_raw": p.detection.centroid, "distance_px": distance, "differs": differs,
                     "replay_clear_radius_px": p.detection.clear_radius_px if p.detection.found else None})
        prev = rgb
    return {"run_dir": str(run_dir), "scene": summary["scene"], "flown": {"flow": summary["flow"],
            "detector": summary["detector"], "edges": flown_edges},
            "replay": {"flow": flow_spec, "detector": detector_name, "edges": edges_mode},
            "differ_px": differ_px, "steps": len(rows), "differing_steps": [r["step"] for r in rows if r["differs"]],
            "rows": rows}


def record_tlog(recording, tlog: Path) -> int:
    """Log what a companion's ``link.tlog`` holds into ``recording``: the autopilot's LOCAL_POSITION_NED and
    ATTITUDE on its own time stamps, and the SET_POSITION_TARGET_LOCAL_NED setpoints sent (at the latest
    autopilot time before each).  Returns the number of messages used; a missing tlog logs nothing."""
    from pymavlink import mavutil

    if not tlog.exists():
        return 0
    conn = mavutil.mavlink_connection(str(tlog), notimestamps=False)
    used = 0
    try:
        while True:
            msg = conn.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE", "SET_POSITION_TARGET_LOCAL_NED"])
            if msg is None:
                return used
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                recording.telemetry(msg.time_boot_ms * 1e-3, position=(msg.x, msg.y, msg.z))
            elif kind == "ATTITUDE":
                recording.telemetry(msg.time_boot_ms * 1e-3, attitude=(msg.roll, msg.pitch, msg.yaw))
            elif math.isfinite(msg.x) and math.isfinite(msg.y) and math.isfinite(msg.z):
                recording.setpoint((msg.x, msg.y, msg.z))
            used += 1
    finally:
        conn.close()


def describe(result: dict) -> str:
    def settings(which: dict) -> str:
        return f"{which['flow']} + {which['detector']} (edges {which.get('edges', 'flow')})"

    lines = [f"replay of {result['run_dir']} ({result['scene']}): flown with {settings(result['flown'])}, "
             f"replayed with {settings(result['replay'])}",
             f"{'step':>4}  {'flown centroid':>16}  {'replayed':>16}  {'Δ px':>6}  {'clear r px':>10}"]

    def fmt(c):
        return "none" if c is None else f"({c[0]:.0f}, {c[1]:.0f})"

    for r in result["rows"]:
        d = r["distance_px"]
        mark = "  <- differs" if r["differs"] else ""
        dist = "-" if d is None else ("∞" if math.isinf(d) else f"{d:.1f}")
        radius = r.get("replay_clear_radius_px")
        radius_text = "-" if radius is None else f"{radius:.1f}"
        lines.append(f"{r['step']:>4}  {fmt(r['flown_centroid']):>16}  {fmt(r['replay_centroid']):>16}  "
                     f"{dist:>6}  {radius_text:>10}{mark}")
    lines.append(f"{len(result['differing_steps'])} of {result['steps']} steps differ by more than "
                 f"{result['differ_px']:g} px")
    return "\n".join(lines)
