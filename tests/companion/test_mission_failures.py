"""The mission's ways out, against a scripted autopilot: a refused command or a timeout ends in FAILED with the
reason, and the vehicle is asked to hold whenever it may be in the air (never on the ground before takeoff)."""

from __future__ import annotations

import logging
import math
import threading

import numpy as np
import pytest

from companion.camera import Frame
from companion.clock import _ClockBase
from companion.link.base import AutopilotLink, LinkError
from companion.mission import Mission
from companion.mission_config import MissionConfig, State
from companion.opening import OpeningConfig
from companion.runlog import RunLog


class ScriptedLink(AutopilotLink):
    """An autopilot that answers at once: armed on request, at any setpoint the moment it is sent."""

    name = "scripted"

    def __init__(self, refuse: dict[str, str] | None = None, disarm_on_setpoint: bool = False,
                 climbs: bool = True, disarmed_takeoffs: int = 0):
        super().__init__()
        self.refuse, self.disarm_on_setpoint, self.climbs = refuse or {}, disarm_on_setpoint, climbs
        self.disarmed_takeoffs = disarmed_takeoffs   # takeoffs refused because the vehicle disarmed meanwhile
        self.calls: list[str] = []
        t = self.telemetry
        t.position, t.landed, t.velocity = (0.0, 0.0, 0.0), True, (0.0, 0.0, 0.0)

    def alive(self) -> bool:
        return True

    def _do(self, what: str) -> None:
        self.calls.append(what)
        if what in self.refuse:
            raise LinkError(self.refuse[what])

    def connect(self, timeout_s: float = 30.0) -> None:
        self._do("connect")

    def close(self) -> None:
        self.calls.append("close")

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        self._do("takeoff altitude")

    def arm(self) -> None:
        self._do("arm")
        self.telemetry.armed = True

    def takeoff(self, altitude_m: float) -> None:
        self._do("takeoff")
        if self.disarmed_takeoffs:
            self.disarmed_takeoffs -= 1
            self.telemetry.armed = False         # PX4's COM_DISARM_PRFLT ran out while the command was retried
            raise LinkError("command 22 refused with MAV_RESULT_TEMPORARILY_REJECTED: Takeoff denied: arm first")
        if self.climbs:          # up a moment later, as the mission reads home first
            def climbed():
                self.telemetry.position, self.telemetry.landed = (0.0, 0.0, -altitude_m), False

            threading.Timer(0.05, climbed).start()

    def start_offboard(self, position, yaw) -> None:
        self._do("offboard")

    def set_position_target(self, position, yaw) -> None:
        self._do("setpoint")
        self.telemetry.position = tuple(position)
        if self.disarm_on_setpoint:
            self.telemetry.armed = False

    def hold(self) -> None:
        self._do("hold")

    def land(self) -> None:
        self._do("land")


class RecordingLink(ScriptedLink):
    """A scripted autopilot that also keeps every position setpoint sent (the vehicle is at each at once)."""

    def __init__(self) -> None:
        super().__init__()
        self.setpoints: list[tuple] = []

    def set_position_target(self, position, yaw) -> None:
        super().set_position_target(position, yaw)
        self.setpoints.append(tuple(position))


class StillCamera:
    """The same frame every time: a textured wall (4 px checks: the wall is read only where there is texture)."""

    width, height = 64, 48
    K = np.array([[40.0, 0, 32], [0, 40.0, 24], [0, 0, 1]])
    WALL = np.repeat(((np.indices((48, 64)) // 4).sum(axis=0) % 2 * 200).astype(np.uint8)[..., None], 3, axis=2)

    def capture(self) -> Frame:
        return Frame(self.WALL.copy(), (0.0, 0.0, -1.5), (1.0, 0.0, 0.0, 0.0), 0.0, 0.0)

    def close(self) -> None:
        pass


def _fly(tmp_path, link: ScriptedLink) -> Mission:
    def never(*_):
        raise AssertionError("no frame pair should be perceived")

    mission = Mission(link, StillCamera(), never, never, RunLog(tmp_path, images=False),
                      config=MissionConfig(takeoff_timeout_s=0.3, preflight_timeout_s=0.3))
    mission.run()
    mission.record.runlog.close()
    return mission


def test_a_refused_arm_fails_with_the_autopilots_reason_and_commands_nothing_more(tmp_path):
    link = ScriptedLink(refuse={"arm": "arming denied: Preflight Fail: ekf2 missing data"})
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED and result.reason == "arm: arming denied: Preflight Fail: ekf2 missing data"
    assert link.calls == ["connect", "takeoff altitude", "arm"]   # on the ground: nothing to hold


def test_the_takeoff_altitude_is_set_before_arming_and_its_silence_fails_on_the_ground(tmp_path):
    """PX4 disarms a vehicle left armed on the ground (COM_DISARM_PRFLT): a slow link's parameter retries must
    not run after arming, so the altitude goes first; if it cannot be set, nothing is armed."""
    link = ScriptedLink(refuse={"takeoff altitude": "parameter MIS_TAKEOFF_ALT: no PARAM_VALUE after 10 tries"})
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED
    assert result.reason == "preflight: parameter MIS_TAKEOFF_ALT: no PARAM_VALUE after 10 tries"
    assert link.calls == ["connect", "takeoff altitude"]
    answered = ScriptedLink(climbs=False)
    _fly(tmp_path / "answered", answered)
    assert answered.calls[:4] == ["connect", "takeoff altitude", "arm", "takeoff"]


def test_a_takeoff_that_never_reaches_its_altitude_fails_and_holds(tmp_path):
    link = ScriptedLink(climbs=False)
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED and result.reason.startswith("takeoff: timed out after 0 s waiting for")
    assert link.calls[-1] == "hold" and [s for _, s in result.states][-2:] == ["takeoff", "failed"]


def test_a_vehicle_that_disarms_in_the_servo_phase_fails_there_and_is_asked_to_hold(tmp_path):
    link = ScriptedLink(disarm_on_setpoint=True)
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED
    assert result.reason == "servo: the vehicle disarmed during the servo phase (crash or failsafe)"
    assert link.calls[-1] == "hold" and "setpoint" in link.calls


def test_a_refused_hold_after_a_failure_is_logged_not_raised(tmp_path):
    link = ScriptedLink(climbs=False, refuse={"hold": "command denied"})
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED and link.calls[-1] == "hold"


def test_no_opening_seen_in_eight_frames_is_a_refusal_that_holds(tmp_path):
    """A wall with nothing to fly through (or an opening too small for the detector to see) is declined like an
    opening judged too small: REFUSED with the reason, the vehicle asked to hold, nothing pushed."""
    from companion.flow import make_flow_backend
    from companion.gap import get_detector

    link = ScriptedLink()
    mission = Mission(link, StillCamera(), make_flow_backend("dis", preset="fast"), get_detector("parallax"),
                      RunLog(tmp_path, images=False),
                      config=MissionConfig(takeoff_timeout_s=0.3, preflight_timeout_s=0.3, search_shift_m=0.0))
    result = mission.run()
    mission.record.runlog.close()
    assert result.state is State.REFUSED
    assert result.reason == "no opening found in 8 frames: nothing seen to fly through"
    assert link.calls[-1] == "hold" and link.calls.count("setpoint") >= 8


def test_a_look_that_saw_nothing_for_blind_frames_looks_past_the_walls_end_too(tmp_path):
    """MissionConfig.blind_frames: the detector as given for a look's first frames, then, while nothing has been
    seen, the blind detector (the parallax detector with past_the_end); the decision log says which ran."""
    import json

    from companion.flow import make_flow_backend
    from companion.gap import blind_detector, get_detector

    calls = []

    def counted(name, detector):
        def detect(flow, textured=None):
            calls.append(name)
            return detector(flow, textured=textured)
        return detect

    mission = Mission(ScriptedLink(), StillCamera(), make_flow_backend("dis", preset="fast"),
                      counted("plain", get_detector("parallax")), RunLog(tmp_path, images=False),
                      config=MissionConfig(takeoff_timeout_s=0.3, preflight_timeout_s=0.3, search_shift_m=0.0),
                      blind_detector=counted("blind", blind_detector("parallax")))
    result = mission.run()
    mission.record.runlog.close()
    assert result.reason == "no opening found in 8 frames: nothing seen to fly through"
    flags = [json.loads(line)["past_the_end"] for line in (tmp_path / "decisions.jsonl").read_text().splitlines()]
    assert flags == [False] * 3 + [True] * 5
    assert "plain" in calls and "blind" in calls and calls == sorted(calls, key=lambda c: c == "blind")
    assert blind_detector("paper") is None
    assert blind_detector("parallax").keywords["config"].past_the_end


def test_refused_it_looks_again_from_either_side_of_the_start_before_holding(tmp_path):
    """The search (MissionConfig.search_shift_m): refused from the start, the vehicle looks again from 1.5 m to
    one side of the start's axis and then the other, each a full look of its own, and holds only when all three
    refused; the reason names each look."""
    from companion.flow import make_flow_backend
    from companion.gap import get_detector

    link = RecordingLink()
    mission = Mission(link, StillCamera(), make_flow_backend("dis", preset="fast"), get_detector("parallax"),
                      RunLog(tmp_path, images=False),
                      config=MissionConfig(takeoff_timeout_s=0.3, preflight_timeout_s=0.3,
                                           estimate_wait_s=0.01))   # scripted telemetry has no history to wait for
    result = mission.run()
    mission.record.runlog.close()
    nothing = "no opening found in 8 frames: nothing seen to fly through"
    assert result.state is State.REFUSED and link.calls[-1] == "hold"
    assert result.reason == (f"{nothing}; looked again from 1.5 m right of the start: {nothing}; "
                             f"from 1.5 m left of the start: {nothing}")
    assert result.servo_steps == 3 * 8
    # heading north (yaw 0): right is east.  Each look starts at the start's northing, 1.5 m east, then west
    # (no wall was measured: the start's own distance), and walks north from there
    looks = [p for p in link.setpoints if abs(abs(p[1]) - 1.5) < 1e-9 and abs(p[0]) < 1e-9]
    assert [p[1] for p in looks] == [1.5, 1.5, -1.5]     # east; back there after the walk; then west
    east = [p for p in link.setpoints if p[1] == 1.5]
    assert len(east) >= 8 and max(p[0] for p in east) > 1.0


def test_refused_with_another_opening_seen_it_looks_in_front_of_that_one_first(tmp_path):
    """Refused with another opening seen on the way (Refusal.alternative), the search's first look is in front of
    that one (only openings within search_reach_m of it, the refused one set aside), its second from the side
    of the start's axis further from it, and its third from the other side (1.1 m from the other opening)."""
    from companion.mission import Refusal

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    mission = Mission(link, StillCamera(), None, None, RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01))
    mission.yaw = 0.0                                  # heading north: right is east
    looks = []

    def servo(start, avoid=(), wall_prior=None, reach=None, wall_ceiling=None):
        looks.append((start, avoid, reach))
        if len(looks) == 1:                            # the first look: refused, another opening seen 0.4 m right
            raise Refusal("too small", (-0.7, -0.2), (0.4, -0.3))
        raise Refusal(f"look {len(looks)}", None, (-2.0, 0.0))    # later looks' alternatives are not taken

    mission._servo = servo
    with pytest.raises(Refusal) as refused:
        mission._servo_searching((0.0, 0.0, -1.5))
    assert len(looks) == 4
    reach = MissionConfig().search_reach_m
    assert [r for _, _, r in looks[1:]] == [(0.4, reach), (-1.5, reach), (1.5, reach)]
    assert looks[1][1] == ((-0.7, -0.2),)              # the refused one set aside
    assert looks[1][0][1] == pytest.approx(0.4)        # the look starts in front of it (east 0.4 m)
    assert str(refused.value) == ("too small; looked again from in front of another opening seen on the way, "
                                  "0.4 m right of the start: look 2; from 1.5 m left of the start: look 3; "
                                  "from 1.5 m right of the start: look 4")


def test_a_vehicle_that_disarmed_on_the_ground_before_takeoff_got_through_is_armed_again(tmp_path):
    link = ScriptedLink(climbs=False, disarmed_takeoffs=2)
    _fly(tmp_path, link)
    assert link.calls[:7] == ["connect", "takeoff altitude", "arm", "takeoff", "arm", "takeoff", "arm"]
    assert link.calls[7] == "takeoff"                       # the third round gets through


def test_rearming_is_bounded_and_a_refused_takeoff_while_armed_is_not_retried(tmp_path):
    link = ScriptedLink(disarmed_takeoffs=5)
    result = _fly(tmp_path, link).result
    assert result.state is State.FAILED and result.reason.endswith("Takeoff denied: arm first")
    assert link.calls.count("arm") == 3 and link.calls.count("takeoff") == 3
    armed = ScriptedLink(refuse={"takeoff": "command 22 refused with MAV_RESULT_DENIED: Takeoff denied: no home"})
    result = _fly(tmp_path / "armed", armed).result
    assert result.state is State.FAILED and armed.calls.count("arm") == 1 and armed.calls.count("takeoff") == 1


class StuckLink(ScriptedLink):
    """Setpoints are taken (and kept), the vehicle stays where it is."""

    def __init__(self) -> None:
        super().__init__()
        self.setpoints: list[tuple] = []

    def set_position_target(self, position, yaw) -> None:
        self._do("setpoint")
        self.setpoints.append(tuple(position))


class ZeroFlow:
    def estimate(self, a, b):
        return np.zeros(a.shape[:2] + (2,), np.float32)


def _fly_stuck(folder, detector, **config):
    link = StuckLink()
    mission = Mission(link, StillCamera(), ZeroFlow(), detector, RunLog(folder, images=False),
                      config=MissionConfig(takeoff_timeout_s=0.3, preflight_timeout_s=0.3, estimate_wait_s=0.01,
                                           step_timeout_s=0.01, search_shift_m=0.0, **config))
    result = mission.run()
    mission.record.runlog.close()
    return result, link


class HalfTheFrame:
    """A detector that sees what noise looked like: a big "opening", the frame's right half."""

    def __init__(self) -> None:
        self.looked = 0

    def __call__(self, flow, textured=None):
        from companion.gap import GapDetection

        self.looked += 1
        mask = np.zeros(flow.shape[:2], bool)
        mask[:, 32:] = True
        return GapDetection(mask, (47.5, 23.5), float(mask.sum()), None, None, "fake", (47.5, 23.5), 16.0)


def test_a_frame_pair_taken_without_moving_is_not_looked_at(tmp_path):
    """MissionConfig.min_baseline_m: a camera that did not move between two frames shows no parallax, and the
    detector finds "openings" in its flow's noise (measured, hard world seed 43: a pair 0.01 m apart showed a
    61 % "opening", and the vehicle pushed into the wall).  Such a pair is not looked at: nothing is seen, nothing
    pushed; with no minimum the same pairs reach the detector, and the mission steers by its "opening" until its
    steps run out (before 2026-12-05 it then pushed through it; now no look pushes what it never placed)."""
    detector = HalfTheFrame()
    result, _ = _fly_stuck(tmp_path / "still", detector)
    assert detector.looked == 0 and result.state is State.REFUSED
    assert result.reason == "no opening found in 8 frames: nothing seen to fly through"
    unguarded, _ = _fly_stuck(tmp_path / "no_minimum", detector, min_baseline_m=0.0)
    assert detector.looked >= 3 and "no opening placed" in unguarded.reason    # followed its "opening"


def test_a_look_is_bounded_by_the_nearest_wall_any_earlier_look_allows():
    """companion.search.search_wall_bound: each look's last sight of the wall (forward, right, measured turn)
    bounds where the wall's face can be at another look's place: up to search_wall_turn_rad turned, or its
    measured turn give or take search_yaw_margin_rad; of several looks, the nearest bound counts (measured: a
    look's sight far across with a turn measured wrong started the next look 0.3 m from the wall)."""
    import math

    from companion.search import search_wall_bound

    turn, margin = math.radians(25.0), math.radians(8.0)
    assert search_wall_bound([], 1.0, turn, margin) is None
    unturned = [(3.0, 0.0, None)]
    assert search_wall_bound(unturned, 1.0, turn, margin) == pytest.approx(3.0 - math.tan(turn))
    assert search_wall_bound(unturned, -1.0, turn, margin) == pytest.approx(3.0 - math.tan(turn))
    # turned 10° (further away to the right): the measured turn allows more, on that side only
    turned = [(3.0, 0.0, math.radians(10.0))]
    assert search_wall_bound(turned, 1.0, turn, margin) == pytest.approx(
        3.0 + math.tan(math.radians(10.0)) - math.tan(margin))
    assert search_wall_bound(turned, -1.0, turn, margin) == pytest.approx(
        3.0 - math.tan(math.radians(10.0)) - math.tan(margin))
    # a sight 3 m across, its turn measured 20° the wrong way, says 3.7 m; one 0.5 m across says 2.8 m
    far_wrong = (3.0, -3.0, math.radians(20.0))
    assert search_wall_bound([far_wrong], 0.0, turn, margin) > 3.5
    assert search_wall_bound([far_wrong, (3.0, -0.5, None)], 0.0, turn, margin) == pytest.approx(
        3.0 - 0.5 * math.tan(turn))


def test_a_looks_ceiling_is_the_furthest_the_wall_can_be_by_every_earlier_sight():
    """companion.search.search_wall_ceiling: the bound's other side, turned the other way; of several looks, the
    furthest counts."""
    import math

    from companion.search import search_wall_bound, search_wall_ceiling

    turn, margin = math.radians(25.0), math.radians(8.0)
    assert search_wall_ceiling([], 1.0, turn, margin) is None
    unturned = [(3.0, 0.0, None)]
    for right in (1.0, -1.0):
        assert search_wall_ceiling(unturned, right, turn, margin) == pytest.approx(3.0 + math.tan(turn))
    turned = [(3.0, 0.0, math.radians(10.0))]
    assert search_wall_ceiling(turned, 1.0, turn, margin) == pytest.approx(
        3.0 + math.tan(math.radians(10.0)) + math.tan(margin))
    assert search_wall_ceiling(turned, -1.0, turn, margin) == pytest.approx(
        3.0 - math.tan(math.radians(10.0)) + math.tan(margin))
    # never nearer than the bound, and the same where the look is at the sight's own place
    for walls in (unturned, turned, [(3.0, -3.0, math.radians(20.0)), (3.0, -0.5, None)]):
        for right in (-2.0, 0.0, 1.5):
            assert search_wall_ceiling(walls, right, turn, margin) >= search_wall_bound(walls, right, turn, margin)
    assert search_wall_ceiling(unturned, 0.0, turn, margin) == pytest.approx(3.0)
    assert search_wall_ceiling([(3.0, 0.0, None), (2.5, -0.5, None)], 0.0, turn, margin) == pytest.approx(3.0)


def _look_by_the_image(tmp_path, detector, match: str | None = None, first: bool = False) -> RecordingLink:
    """A look (wall prior 2 m ahead, heading north; ``first``: the first look, with no prior) whose wall is never
    measured (zero flow: no parallax), steering by the image alone, until it refuses (with ``match`` in its
    reason, when given)."""
    from companion.mission import Refusal

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)   # in the air, a look's start
    mission = Mission(link, StillCamera(), ZeroFlow(), detector, RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01, min_baseline_m=0.0))
    mission.yaw = 0.0                                  # heading north: forward is the north coordinate
    with pytest.raises(Refusal, match=match):
        if first:
            mission._servo((0.0, 0.0, -1.5))
        else:
            mission._servo((0.0, 0.0, -1.5), (), 2.0, (0.0, 1.2))
    return link


def test_the_first_look_never_pushes_an_opening_it_never_placed(tmp_path):
    """The paper's law pushes once its step budget is spent; steered by the image alone (the wall never measured)
    the first look refuses instead (measured, hard world seed 67: a first look followed a stale image position
    for 19 steps and pushed into the wall at the 30th)."""
    _look_by_the_image(tmp_path, HalfTheFrame(), match="no opening placed within 30 steps", first=True)


def test_the_looks_are_either_side_of_the_axis_or_in_front_of_another_opening_then_both_sides_further_first():
    """companion.search.look_places: the refused opening's side first, then the other; with another opening seen,
    in front of it first, then whichever side is further from it, then the nearer side unless it lies within
    half the shift of the other opening (that look covered it)."""
    from companion.search import look_places

    assert look_places(0.2, 1.5, -1.0) == [(-1.3, "1.5 m left of the start"), (1.7, "1.5 m right of the start")]
    assert look_places(0.2, 1.5, -1.0, 0.6) == [(0.6, "in front of another opening seen on the way, 0.4 m right of "
                                                      "the start"), (-1.3, "1.5 m left of the start"),
                                                (1.7, "1.5 m right of the start")]
    assert [r for r, _ in look_places(0.0, 1.5, 1.0, -2.4)] == [-2.4, 1.5, -1.5]
    assert [r for r, _ in look_places(0.0, 1.5, 1.0, -1.2)] == [-1.2, 1.5]     # -1.5 is 0.3 m from it
    assert [r for r, _ in look_places(0.0, 1.5, 1.0, -0.7)] == [-0.7, 1.5, -1.5]


def test_a_look_steering_by_the_image_alone_keeps_off_the_wall_earlier_looks_placed(tmp_path):
    """A look (``wall_prior`` from earlier looks) whose detector shows an "opening" but whose wall is never measured
    (zero flow: no parallax) steers by the image alone: it goes no nearer than the hold distance to the prior, and
    at the end of its step budget it refuses instead of pushing what it never placed (measured, hard world seed
    46: such a look walked 2 m on, into the wall)."""
    from companion.servo import ServoConfig

    link = _look_by_the_image(tmp_path, HalfTheFrame(), match="no opening placed within 30 steps")
    prior = 2.0                                        # the nearest the wall's face can be, 2 m ahead
    hold = ServoConfig().hold_distance_m
    assert max(p[0] for p in link.setpoints) <= prior - hold + 1e-9
    assert max(p[0] for p in link.setpoints) > prior - hold - 0.2    # it did walk up to there


class WallFlow:
    """The forward flow of a wall facing the camera at north coordinate ``wall_n``, for the step the vehicle made
    since the last pair (where the link says it is); ``wrong_every``: every that many pairs, the flow of a surface
    1.5 m behind the wall instead (what a look beyond a wall's end sees between readings of the wall)."""

    def __init__(self, link: ScriptedLink, wall_n: float, wrong_every: int = 0) -> None:
        self.link, self.wall_n, self.wrong_every = link, wall_n, wrong_every
        self.before, self.pairs = link.telemetry.position[0], 0

    def estimate(self, a, b):
        here = self.link.telemetry.position[0]
        moved, self.before = here - self.before, here
        self.pairs += 1
        depth = self.wall_n - here + (1.5 if self.wrong_every and self.pairs % self.wrong_every == 0 else 0.0)
        h, w = a.shape[:2]
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        return np.stack([(xs - (w - 1) / 2) * moved / depth, (ys - (h - 1) / 2) * moved / depth], axis=-1)


class SmallHole:
    """A detector that sees an opening straight ahead, 2 px in clear radius: too small to fly through."""

    def __call__(self, flow, textured=None):
        from companion.gap import GapDetection

        h, w = flow.shape[:2]
        ys, xs = np.mgrid[0:h, 0:w]
        mask = (xs - (w - 1) / 2) ** 2 + (ys - (h - 1) / 2) ** 2 <= 4.0
        centre = ((w - 1) / 2, (h - 1) / 2)
        return GapDetection(mask, centre, float(mask.sum()), None, None, "fake", centre, 2.0)


def test_the_frame_that_refuses_an_opening_is_in_the_decision_log_with_the_estimate_that_decided_it(tmp_path):
    """Every refusal is auditable frame by frame: the frame whose size estimate tipped the judgement is logged (it
    was not, before 2026-12-05: the log ended one frame short of the decision), holding, with the reason."""
    import json

    from companion.mission import Refusal

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    mission = Mission(link, StillCamera(), WallFlow(link, 3.0), SmallHole(), RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01))
    mission.yaw = 0.0
    with pytest.raises(Refusal, match="is narrower than the vehicle's") as refused:
        mission._servo((0.0, 0.0, -1.5))
    mission.record.runlog.close()
    decisions = [json.loads(line) for line in open(tmp_path / "decisions.jsonl")]
    last = decisions[-1]
    assert last["refusal"] == str(refused.value) and all(d["refusal"] is None for d in decisions[:-1])
    assert last["judged"] and last["judged_estimates"] >= OpeningConfig().min_estimates
    assert 2 * last["estimate_m"] < 0.30 and last["next_delta_heading"] == [0.0, 0.0, 0.0] and not last["push"]
    assert last["step"] == decisions[-2]["step"] + 1


def _look(tmp_path, wall_n: float, prior: float, wrong_every: int = 0) -> RecordingLink:
    from companion.mission import Refusal

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)   # in the air, a look's start
    mission = Mission(link, StillCamera(), WallFlow(link, wall_n, wrong_every), SmallHole(),
                      RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01))
    mission.yaw = 0.0                                  # heading north: forward is the north coordinate
    with pytest.raises(Refusal):
        mission._servo((0.0, 0.0, -1.5), (), prior, (0.0, 1.2))
    return link


def test_a_looks_own_agreeing_readings_are_the_wall_wherever_earlier_looks_allowed_it(tmp_path):
    """MissionConfig.search_wall_agree_m: a look whose own wall readings agree takes them for the wall, though
    earlier looks allowed it to be 1 m nearer: it walks on past that bound's hold distance, up to its own (measured,
    hard world seeds 46-48: such bounds stopped looks 1.3-2.3 m from the wall, seeing nothing).  Readings that jump
    (every third one 1.5 m beyond, as past a wall's end) are not believed beyond the bound."""
    from companion.servo import ServoConfig

    hold, wall, prior = ServoConfig().hold_distance_m, 3.5, 2.5
    steady = max(p[0] for p in _look(tmp_path / "steady", wall, prior).setpoints)
    assert prior - hold + 0.5 < steady <= wall - hold + 0.05
    jumping = max(p[0] for p in _look(tmp_path / "jumping", wall, prior, wrong_every=3).setpoints)
    assert jumping <= prior - hold + ServoConfig().forward_step_m


def test_a_look_that_never_read_the_wall_leaves_the_next_look_only_the_earlier_looks_bound(tmp_path):
    """What a look saw of the wall bounds the next look (``Mission._wall_seen``); a look that read nothing of it
    (zero flow, nothing detected) and went by the bound earlier looks put on it adds no sight: taken as one, it was
    allowed the search's 25° turn a second time across the next look's way (measured, hard world seed 96: a third
    look held 3 m from the wall).  A look that measured the wall leaves that."""
    from companion.gap import _no_gap
    from companion.mission import Refusal

    def look(flow, detector, prior):
        link = RecordingLink()
        link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
        mission = Mission(link, StillCamera(), flow(link), detector, RunLog(tmp_path / str(prior), images=False),
                          config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01, min_baseline_m=0.0))
        mission.yaw = 0.0
        with pytest.raises(Refusal) as refused:
            mission._servo((0.0, 0.0, -1.5), (), prior, (0.0, 1.2))
        return mission._wall_seen, str(refused.value)

    seen, why = look(lambda link: ZeroFlow(), lambda flow, textured=None: _no_gap(flow.shape[:2], "nothing", "fake"),
                     2.0)
    assert seen is None and "the bound earlier looks put on it" in why
    seen, _ = look(lambda link: WallFlow(link, 3.0), SmallHole(), 2.9)
    assert seen is not None and seen[0] == pytest.approx(3.0, abs=0.15)


class LowHole:
    """A detector that sees an opening low in the frame (about 0.4 of the half-height below the centre) in its
    first ``frames`` calls, and nothing after them (``frames`` None: in every call)."""

    def __init__(self, frames: int | None = None) -> None:
        self.frames, self.calls = frames, 0

    def __call__(self, flow, textured=None):
        from companion.gap import GapDetection, _no_gap

        self.calls += 1
        h, w = flow.shape[:2]
        if self.frames is not None and self.calls > self.frames:
            return _no_gap((h, w), "nothing this frame", "fake")
        mask = np.zeros((h, w), bool)
        mask[30:40, 26:38] = True
        centre = (31.5, 34.5)
        return GapDetection(mask, centre, float(mask.sum()), None, None, "fake", centre, 5.0)


def test_a_look_steers_across_only_towards_a_target_seen_in_that_frame(tmp_path):
    """A look steering by the image alone, its target seen in the first frames only, steps down towards it while it
    is seen and not at all once it is not: the held target's correction is not re-applied at every step (measured,
    hard world seed 49: held at the hold distance, 0.05 m down per step for 20 steps, to the ground)."""
    link = _look_by_the_image(tmp_path, LowHole(frames=4))
    downs = [p[2] for p in link.setpoints]
    assert downs[3] > -1.5 + 0.02                  # it stepped down while the opening was seen ...
    assert downs[-1] == pytest.approx(downs[5])    # ... and not once it was gone
    assert len(downs) >= 20


def test_no_servo_step_goes_below_the_minimum_altitude(tmp_path):
    """MissionConfig.min_altitude_m: an opening seen low in every frame draws each step down, and the steps stop
    at the minimum height above home (home is at 0 here) instead of reaching the ground."""
    link = _look_by_the_image(tmp_path, LowHole())
    downs = [p[2] for p in link.setpoints]
    assert max(downs) == pytest.approx(-MissionConfig().min_altitude_m)
    assert downs.count(max(downs)) >= 3             # it reached the floor and stayed on it


class WallPatch:
    """A detector that takes the left half of the frame for an opening, whatever the flow shows there."""

    def __call__(self, flow, textured=None):
        from companion.gap import GapDetection

        h, w = flow.shape[:2]
        mask = np.zeros((h, w), bool)
        mask[4:h - 4, 2:w // 2] = True
        centre = (w / 4, h / 2)
        return GapDetection(mask, centre, float(mask.sum()), None, None, "fake", centre, 10.0)


def test_an_opening_whose_depth_is_the_walls_is_set_aside_and_never_pushed_through(tmp_path):
    """OpeningConfig.max_depth_ratio: a "gap" whose flow is the wall's own is a patch of the wall (measured, hard
    world seed 64: a turned wall's farther half, 42 % of the frame, pushed at once from 2.2 m into the wall)."""
    import json

    from companion.mission import Refusal
    from companion.servo import ServoConfig

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    mission = Mission(link, StillCamera(), WallFlow(link, 3.0), WallPatch(), RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01))
    mission.yaw = 0.0
    with pytest.raises(Refusal, match="no opening found"):
        mission._servo((0.0, 0.0, -1.5))
    mission.record.runlog.close()
    decisions = [json.loads(line) for line in open(tmp_path / "decisions.jsonl")]
    patches = [d["wall_patches"] for d in decisions if d["wall_patches"]]
    assert len(patches) >= len(decisions) - 1 and all(r == pytest.approx(1.0, abs=0.05) for p in patches for r in p)
    assert all(d["openings"] == 0 and not d["push"] for d in decisions)
    assert max(p[0] for p in link.setpoints) <= 3.0 - ServoConfig().hold_distance_m + 1e-9


class HalfwayLink(RecordingLink):
    """Each setpoint is flown only half the way (the vehicle still on its way at the frame)."""

    def set_position_target(self, position, yaw) -> None:
        before = self.telemetry.position
        super().set_position_target(position, yaw)
        self.telemetry.position = tuple(b + 0.5 * (p - b) for b, p in zip(before, position, strict=True))


def _wide_hole_right(h: int, w: int) -> tuple[np.ndarray, tuple[float, float]]:
    """A wide opening (14 px in clear radius) 8 px right of the frame's centre: its mask and centre."""
    ys, xs = np.mgrid[0:h, 0:w]
    centre = ((w - 1) / 2 + 8.0, (h - 1) / 2)
    return (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2 <= 14.0 ** 2, centre


class WideHoleRight:
    """A detector that sees :func:`_wide_hole_right`."""

    def __call__(self, flow, textured=None):
        from companion.gap import GapDetection

        mask, centre = _wide_hole_right(*flow.shape[:2])
        return GapDetection(mask, centre, float(mask.sum()), None, None, "fake", centre, 14.0)


class WallWithHoleFlow(WallFlow):
    """:class:`WallFlow`, with a background 2 m behind the wall through :func:`_wide_hole_right`."""

    def estimate(self, a, b):
        flow = super().estimate(a, b)
        mask, _ = _wide_hole_right(*a.shape[:2])
        depth = self.wall_n - self.before
        flow[mask] *= depth / (depth + 2.0)
        return flow


def test_the_push_starts_where_the_vehicle_was_at_the_last_frame_not_at_its_waypoint(tmp_path):
    """The push's correction and distances are measured from where the vehicle was at the frame: a vehicle that
    has not reached its last waypoint pushes from where it is (measured, hard world seed 44: started from the
    waypoint 0.04 m aside, a push through a polygon 0.26 m clear touched its edge)."""
    import math

    link = HalfwayLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    # the still camera's frames are all alike, and the flow made up: no edge can be read from them (edges=None)
    mission = Mission(link, StillCamera(), WallWithHoleFlow(link, 2.5), WideHoleRight(), RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01), edges=None)
    mission.yaw = 0.0
    frames = []
    capture = mission.camera.capture
    mission.camera.capture = lambda: frames.append(link.telemetry.position) or capture()
    start, _, wall_distance, _ = mission._servo((0.0, 0.0, -1.5))
    assert wall_distance is not None                                  # placed by the metric law, then pushed
    assert start == pytest.approx(frames[-1])                         # from where the last frame was taken
    assert math.dist(link.setpoints[-1], frames[-1]) > 0.02           # ... not from the waypoint ahead of it


def test_a_push_square_to_a_turned_wall_logs_the_length_it_flies_besides_its_depth(tmp_path, caplog):
    """The traversal's log line: the push's length along the heading, and for a path that turns square to the wall
    the longer length it flies (it ends as deep past the wall as the straight push would)."""
    class SimulatedTime(_ClockBase):
        """Time that passes only when slept (the push's setpoints are 50 ms apart)."""

        def __init__(self) -> None:
            self.t = 0.0

        def now(self) -> float:
            return self.t

        def sleep_until(self, t: float) -> None:
            self.t = max(self.t, t)

    def line_of(turn):
        link = RecordingLink()
        link.clock = SimulatedTime()
        mission = Mission(link, StillCamera(), None, None, RunLog(tmp_path, images=False))
        mission.yaw = 0.0
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="companion.mission"):
            mission._traverse((0.0, 0.0, -1.5), (0.0, 0.0), 1.2, None, turn)
        mission.record.runlog.close()
        start = (0.0, 0.0, -1.5)
        flown = sum(math.dist(a, b) for a, b in zip([start, *link.setpoints[:-1]], link.setpoints, strict=True))
        return next(r.getMessage() for r in caplog.records if r.getMessage().startswith("traversal:")), \
            mission.result.push_length_m, flown

    square, length, flown = line_of(math.radians(15.0))
    assert flown > length + 0.005
    assert square.startswith(f"traversal: {length:.2f} m ahead along the heading, {flown:.2f} m flown square to the "
                             "wall in ")
    straight, length, flown = line_of(None)
    assert flown == pytest.approx(length, abs=1e-6)
    assert straight.startswith(f"traversal: {length:.2f} m ahead along the heading in ")


def test_a_look_that_sees_nothing_in_front_of_its_placed_opening_steps_back_once(tmp_path, monkeypatch):
    """MissionConfig.unseen_step_back_after: frames in a row that see no opening at all, the tracked one placed and
    the wall within decide_within_m, take the vehicle one step back (a new forward baseline, a wider view), once a
    look; before, it dithered beside the place until its steps ran out (hard seeds 96-102)."""
    import companion.mission as mission_module
    from companion.look import FrameView
    from companion.mission import Refusal
    from companion.opening import Sight
    from companion.servo import ServoStep

    opening = HalfTheFrame()(np.zeros((48, 64, 2), np.float32))
    views = []

    def scripted_view(*_args):      # placed 1.2 m ahead; seen in the first two frames only
        found = [opening] if len(views) < 2 else []
        views.append(bool(found))
        sight = Sight(opening if found else None, (47.5, 23.5), offset_m=(0.0, 0.0), clear_radius_m=0.3)
        return FrameView(sight, opening, found, [], 1.2, 1.2, 1.2, None, 0.0, 0.0, None, 0.1)

    monkeypatch.setattr(mission_module, "see_frame", scripted_view)
    monkeypatch.setattr(mission_module, "next_look_step",
                        lambda *_args: ServoStep((0.0, 0.0, 0.0), None, False, False, offset_m=(0.0, 0.0),
                                                 tolerance_m=0.05))
    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    mission = Mission(link, StillCamera(), ZeroFlow(), HalfTheFrame(), RunLog(tmp_path, images=False),
                      config=MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01, min_baseline_m=0.0))
    mission.yaw = 0.0                                  # heading north: forward is the north coordinate
    with pytest.raises(Refusal, match="could not centre"):
        mission._servo((0.0, 0.0, -1.5))
    north = [p[0] for p in link.setpoints]
    steps = [round(b - a, 6) for a, b in zip(north[:-1], north[1:], strict=True)]
    back = -mission.config.unseen_step_back_m
    assert steps.count(back) == 1 and all(s in (0.0, back) for s in steps)
    # sent after the sixth frame: two that saw it, then unseen_step_back_after that saw nothing
    assert steps.index(back) == 2 + mission.config.unseen_step_back_after - 1
    mission.record.runlog.close()


class WallThenBeyondItsEnd(WallFlow):
    """On the start's axis (within 0.5 m across), the wall's flow for the first ``wall_pairs`` pairs, then that of a
    surface 1.5 m behind it (a look that followed something past the wall's end reads what lies behind the end as
    the wall); off the axis, no flow at all."""

    def __init__(self, link: ScriptedLink, wall_n: float, wall_pairs: int) -> None:
        super().__init__(link, wall_n)
        self.wall_pairs = wall_pairs

    def estimate(self, a, b):
        on_axis = abs(self.link.telemetry.position[1]) < 0.5
        self.wrong_every = 1 if self.pairs >= self.wall_pairs else 0
        flow = super().estimate(a, b)
        return flow if on_axis else np.zeros_like(flow)


def test_a_later_look_starts_short_of_the_nearest_wall_any_sight_of_an_earlier_look_allows(tmp_path):
    """The search bounds a look's start by every sight of the wall the earlier looks took with its turn measured,
    not only by each look's last (Mission._wall_sights): a first look that read the wall, then followed something
    past its end and read what lies behind the end, would start the next look too near the wall (measured, hard
    world seed 105, hard_1719364450: the second look began beside the wall's end, past its face, and backed into
    its corner)."""
    from companion.gap import _no_gap
    from companion.mission import Refusal
    from companion.servo import ServoConfig

    link = RecordingLink()
    link.telemetry.armed, link.telemetry.position = True, (0.0, 0.0, -1.5)
    on_axis = SmallHole()

    def detector(flow, textured=None):
        if abs(link.telemetry.position[1]) < 0.5:
            return on_axis(flow)
        return _no_gap(flow.shape[:2], "nothing", "fake")

    config = MissionConfig(estimate_wait_s=0.01, step_timeout_s=0.01)
    mission = Mission(link, StillCamera(), WallThenBeyondItsEnd(link, 3.0, wall_pairs=4), detector,
                      RunLog(tmp_path, images=False), config=config)
    mission.yaw = 0.0
    with pytest.raises(Refusal, match="looked again"):
        mission._servo_searching((0.0, 0.0, -1.5))
    aside = [p for p in link.setpoints if abs(p[1]) > 1.0]
    assert aside, "the search never looked from aside"
    # by the last sight alone (4.5 m, what lies behind the end) the looks walked to 3.0 and 3.4 m, onto the wall
    # and past it; by every sight with the turn measured each stays further from the wall than the hold distance
    assert max(p[0] for p in aside) < 3.0 - ServoConfig().hold_distance_m
