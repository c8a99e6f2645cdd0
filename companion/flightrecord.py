"""What a flight leaves behind as it flies, the mission's one output edge: each frame's poses for replay
(``frames.jsonl``), the step images, one decision line per servo step (``decisions.jsonl``), the storyboard's rows,
and, with a Rerun recording open, its frames, setpoints and events.

:class:`companion.mission.Mission` decides; this writes what it saw and decided, so that the mission reads as
the flight's steps and not as their bookkeeping.
"""

from __future__ import annotations

from companion.flow.colour import flow_to_colour
from companion.runlog import RunLog
from companion.storyboard import Storyboard, StoryRow, step_text


class FlightRecord:
    def __init__(self, runlog: RunLog, recording=None) -> None:
        self.runlog = runlog
        self.recording = recording          # a Rerun recording of the flight (companion.recording), or None
        self.storyboard = Storyboard()      # what it saw and decided, step by step (companion.storyboard)

    def event(self, text: str, level: str = "INFO") -> None:
        """A state, a choice or a refusal, for the recording's event log."""
        if self.recording is not None:
            self.recording.event(text, level)

    def setpoint(self, waypoint) -> None:
        if self.recording is not None:
            self.recording.setpoint(waypoint)

    def frame_poses(self, step: int, frame, position_est, attitude_est) -> None:
        """What replay needs to re-render and re-perceive this frame (flowgap-tlog replay)."""
        self.runlog.frame({"step": step, "time_s": frame.time_s, "position_true": frame.position,
                           "attitude_true": frame.attitude, "position_est": position_est,
                           "attitude_est": attitude_est})

    def first_frame(self, step: int, frame, position_est, attitude_est) -> None:
        """A look's first frame: no flow yet, only the picture and its poses."""
        self.frame_poses(step, frame, position_est, attitude_est)
        self.runlog.save_images(step, rgb=frame.rgb)
        if self.recording is not None:
            self.recording.frame(step, frame.time_s, frame.rgb, None, None, position_true=frame.position,
                                 attitude_true=frame.attitude, text=f"step {step}: the first frame")

    def step(self, n: int, frame, flow, detection, shown_px, next_step, wall_distance, note: str | None,
             decision: dict) -> None:
        """A servo step: the frame, its flow and the mask the decision used, ``shown_px`` the tracked target as
        the tilted frame shows it (None: none), the step sent next, and the decision's log line."""
        flow_bgr = flow_to_colour(flow, bgr=True)
        self.runlog.save_images(n, rgb=frame.rgb, flow_bgr=flow_bgr, mask=detection.mask)
        state = ("refused" if decision.get("refusal") else "push" if next_step.push else "aligned"
                 if next_step.aligned else "close" if next_step.close else "servo") + (f"; {note}" if note else "")
        row = StoryRow(n, frame.rgb, flow_bgr[:, :, ::-1], detection.mask, detection.centroid, shown_px,
                       step_text(n, next_step.error, next_step.delta_heading, wall_distance, state))
        self.storyboard.add(row)
        if self.recording is not None:
            self.recording.frame(row.step, frame.time_s, row.frame, row.flow_rgb, row.mask, row.raw, row.used,
                                 frame.position, frame.attitude, next_step.error, wall_distance, row.text)
        self.runlog.decision(decision)
