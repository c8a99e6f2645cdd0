"""The link-fault injector: the seeded fault model against its probabilities, the real UDP relay in real time
against the loss and delay it was asked for, the lockstep proxy against a scripted vehicle and companion, and
the options' one-line errors."""

from __future__ import annotations

import select
import socket
import statistics
import struct
import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.lockstep import LockstepChannel
from sitl_vehicle.lockstep import ack_message, release_from
from tools import eval_flights, launch
from tools.link_faults import (
    COMPANION_TO_VEHICLE,
    HOLD_LIMIT_S,
    VEHICLE_TO_COMPANION,
    DelayLine,
    Fate,
    FaultModel,
    LinkFaultError,
    LinkFaults,
    count_mavlink_frames,
)
from tools.link_relay import LinkRelay

N = 20_000
TOLERANCE = 0.015        # on a fraction of 20,000 draws: over 4 standard deviations at p = 0.3


def _fates(faults: LinkFaults, direction: str = VEHICLE_TO_COMPANION, n: int = N) -> list[Fate]:
    model = FaultModel(faults, faults.rng(direction))
    return [model.decide() for _ in range(n)]


# ------------------------------------------------------------------------------------------- the pure model
def test_the_fractions_dropped_duplicated_and_held_match_the_probabilities():
    fates = _fates(LinkFaults(loss=0.3, duplicate=0.2, reorder=0.1, seed=11))
    kept = [f for f in fates if not f.dropped]
    assert abs(sum(f.dropped for f in fates) / N - 0.3) <= TOLERANCE
    assert abs(sum(len(f.delays_s) == 2 for f in kept) / len(kept) - 0.2) <= TOLERANCE
    assert abs(sum(f.held for f in kept) / len(kept) - 0.1) <= TOLERANCE


def test_delays_lie_between_the_delay_and_the_delay_plus_jitter_with_the_right_mean():
    delays = [d for f in _fates(LinkFaults(delay_ms=150, jitter_ms=30, duplicate=0.5, seed=3)) for d in f.delays_s]
    assert min(delays) >= 0.150 and max(delays) <= 0.180
    assert abs(statistics.fmean(delays) - 0.165) <= 0.0005          # 30 ms / sqrt(12 * 30,000) = 0.05 ms
    fixed = {d for f in _fates(LinkFaults(delay_ms=40, seed=3), n=100) for d in f.delays_s}
    assert fixed == {0.040}


def test_the_same_seed_gives_the_same_decisions_another_seed_or_direction_others():
    faults = LinkFaults(loss=0.3, delay_ms=10, jitter_ms=5, duplicate=0.1, reorder=0.1, seed=7)
    assert _fates(faults, n=2000) == _fates(faults, n=2000)
    assert _fates(faults, n=2000) != _fates(LinkFaults(**{**faults.settings(), "seed": 8}), n=2000)
    assert _fates(faults, n=2000) != _fates(faults, COMPANION_TO_VEHICLE, n=2000)


def test_each_probability_moves_only_its_own_decisions():
    lossy = _fates(LinkFaults(loss=0.3, seed=5), n=5000)
    also_duplicated = _fates(LinkFaults(loss=0.3, duplicate=0.5, jitter_ms=20, seed=5), n=5000)
    assert [f.dropped for f in lossy] == [f.dropped for f in also_duplicated]


def test_the_delay_line_hands_on_what_is_due_in_order_and_counts_it():
    line = DelayLine(LinkFaults(loss=0.25, delay_ms=50, jitter_ms=50, duplicate=0.1, seed=2), COMPANION_TO_VEHICLE)
    delivered = []
    for k in range(4000):
        now = k * 0.01
        line.push(struct.pack("<I", k), now)
        for d in line.pop_due(now):
            assert d.sent_s + 0.050 - 1e-9 <= now and d.due_s <= now + 1e-9
            delivered.append((d.due_s, now))
    assert [due for due, _ in delivered] == sorted(due for due, _ in delivered)
    s = line.stats
    assert s.delivered + len(line) == s.datagrams_in - s.dropped + s.duplicated
    # delivered on the next 10 ms tick at or after its due time: 75 +- 1.4 ms, plus up to 10 ms
    assert 75 <= s.to_dict()["mean_added_delay_ms"] <= 86


class _Scripted:
    def __init__(self, fates):
        self.fates = list(fates)

    def decide(self):
        return self.fates.pop(0)


def test_a_held_datagram_goes_right_after_the_next_one_or_at_the_hold_limit():
    line = DelayLine(LinkFaults(reorder=0.5, seed=1), VEHICLE_TO_COMPANION)
    line.model = _Scripted([Fate((0.010,), held=True), Fate((0.030,)), Fate((0.0,), held=True)])
    line.push(b"a", 0.0)
    assert line.pop_due(0.02) == []                                    # due, but held for the next one
    line.push(b"b", 0.0)
    assert [d.payload for d in line.pop_due(0.03)] == [b"b", b"a"]
    line.push(b"c", 1.0)                                               # held, and nothing follows
    assert line.pop_due(1.0 + HOLD_LIMIT_S - 0.001) == []
    assert [d.payload for d in line.pop_due(1.0 + HOLD_LIMIT_S)] == [b"c"]
    assert line.stats.reordered == 2 and line.stats.delivered == 3


def test_mavlink_frames_are_counted_by_their_headers():
    mav = mavlink.MAVLink(None, 1, 1)
    heartbeat = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav)
    text = mavlink.MAVLink_statustext_message(6, b"hello").pack(mav)
    assert count_mavlink_frames(heartbeat) == 1
    assert count_mavlink_frames(heartbeat + text + heartbeat) == 3
    assert count_mavlink_frames(b"\x00junk" + text) == 1 and count_mavlink_frames(text[:-3]) == 0
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = bytes(32), True, 1
    assert count_mavlink_frames(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav) + text) == 2


# ------------------------------------------------------------------------------------ the relay in real time
def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def _collect(sock: socket.socket, into: list, stop: threading.Event) -> None:
    while not stop.is_set():
        if select.select([sock], [], [], 0.02)[0]:
            data = sock.recv(2048)
            into.append((struct.unpack("<Id", data[:12]), time.monotonic()))


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_the_real_time_relay_loses_and_delays_what_it_was_asked_to_both_ways(speed):
    """400 datagrams each way through loopback, on a loaded machine: the loss is what the model drew (nothing
    else is lost) and near what was asked; no datagram comes early; the one-way delay's mean, in simulated
    time (wall time times ``speed``), is the asked mean (70 +- 2 ms for 320 draws of U(60, 80)) plus at most
    15 ms of wall-clock scheduling."""
    faults = LinkFaults(loss=0.2, delay_ms=60, jitter_ms=20, seed=4)
    vehicle, companion = _udp(), _udp()
    n = 400
    got = {VEHICLE_TO_COMPANION: [], COMPANION_TO_VEHICLE: []}
    stop = threading.Event()
    listeners = [threading.Thread(target=_collect, args=(companion, got[VEHICLE_TO_COMPANION], stop)),
                 threading.Thread(target=_collect, args=(vehicle, got[COMPANION_TO_VEHICLE], stop))]
    with LinkRelay(faults, companion.getsockname(), speed=speed) as relay:
        for t in listeners:
            t.start()
        for k in range(n):
            vehicle.sendto(struct.pack("<Id", k, time.monotonic()), relay.vehicle_api_address)
            companion.sendto(struct.pack("<Id", k, time.monotonic()), relay.companion_api.address)
            time.sleep(0.002)
        time.sleep(0.5)
        stop.set()
        for t in listeners:
            t.join()
    report = relay.report()
    for direction, received in got.items():
        stats = report[direction]
        assert stats["datagrams_in"] == n and len(received) == n - stats["dropped"] == stats["delivered"]
        assert abs(stats["dropped"] / n - 0.2) <= 0.07                  # 400 draws: 3.5 standard deviations
        delays_ms = [(arrived - sent) * speed * 1e3 for (_, sent), arrived in received]
        assert min(delays_ms) >= 60 - 1
        assert 70 - 2 <= statistics.fmean(delays_ms) <= 70 + 15 * speed
        assert 70 - 2 <= stats["mean_added_delay_ms"] <= 70 + 15 * speed
    vehicle.close()
    companion.close()


# --------------------------------------------------------------------------------- the relay in lockstep
STEP_S = 0.02           # the scripted companion releases 20 ms at a time
SEND_EVERY_S = 0.01     # the scripted vehicle sends every 10 ms of its time


class ScriptedVehicle(threading.Thread):
    """A lockstep vehicle reduced to its protocol: beacons while held; on a release reads the API messages it
    is told of (noting how many were missing), runs exactly to the release's time sending a DEBUG every 10 ms
    and an ODOMETRY at the end, and acks."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.api, self.truth = _udp(), _udp()
        self.relay_api = self.relay_truth = None
        self.mav = mavlink.MAVLink(None, 1, 1)
        self.parser = mavlink.MAVLink(None)
        self.t = self.next_send = 0.0
        self.sent = self.received = self.short = 0
        self.effects: list[tuple[float, int]] = []      # (time it took effect, the companion's send time in ms)
        self.stop = threading.Event()

    def run(self) -> None:
        answered, next_beacon = 0, 0.0
        while not self.stop.is_set():
            if answered == 0 and time.monotonic() > next_beacon:
                self.truth.sendto(ack_message(self.t, self.sent, 0).pack(self.mav), self.relay_truth)
                next_beacon = time.monotonic() + 0.1
            if not select.select([self.truth], [], [], 0.02)[0]:
                continue
            data, source = self.truth.recvfrom(2048)
            release = next(filter(None, map(release_from, self.parser.parse_buffer(data) or [])), None)
            if release is None or release.sequence == answered:
                continue
            self._read_api(release.api_messages)
            while self.next_send <= release.until_s + 1e-9:
                self.api.sendto(mavlink.MAVLink_debug_message(round(self.next_send * 1e3), 0, 0).pack(self.mav),
                                self.relay_api)
                self.sent += 1
                self.next_send = round(self.next_send + SEND_EVERY_S, 6)
            self.t = release.until_s
            odometry = mavlink.MAVLink_odometry_message(round(self.t * 1e6), 1, 12, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0,
                                                        0, 0, 0, [0.0] * 21, [0.0] * 21)
            self.truth.sendto(odometry.pack(self.mav), source)
            answered = release.sequence
            self.truth.sendto(ack_message(self.t, self.sent, answered).pack(self.mav), source)

    def _read_api(self, expected: int) -> None:
        deadline = time.monotonic() + 1.0
        while self.received < expected:
            if not select.select([self.api], [], [], max(0.0, deadline - time.monotonic()))[0]:
                self.short += 1
                self.received = expected
                return
            for msg in self.parser.parse_buffer(self.api.recv(2048)) or []:
                self.received += 1
                self.effects.append((round(self.t, 6), msg.time_boot_ms))


def _fly_scripted(faults: LinkFaults, steps: int = 150) -> dict:
    """The scripted pair through a lockstep relay: the companion sends two DEBUGs per 20 ms step and reads
    what the vehicle sent as each ack says."""
    vehicle, companion_api, probe = ScriptedVehicle(), _udp(), _udp()
    truth_port = probe.getsockname()[1]
    probe.close()
    channel = LockstepChannel(f"udpin://127.0.0.1:{truth_port}", start_timeout_s=10, ack_timeout_s=10)
    relay = LinkRelay(faults, companion_api.getsockname(), vehicle_api=vehicle.api.getsockname(),
                      companion_truth=("127.0.0.1", truth_port), lockstep=True).start()
    vehicle.relay_api, vehicle.relay_truth = relay.vehicle_api_address, relay.vehicle_truth_address
    vehicle.start()
    mav, parser = mavlink.MAVLink(None, 255, 0), mavlink.MAVLink(None)
    sent = received = short = 0
    receipts = []            # (the companion's time when it read it, the vehicle's send time in ms)
    try:
        now, _ = channel.start()
        for _ in range(steps):
            for _ in range(2):
                companion_api.sendto(mavlink.MAVLink_debug_message(round(now * 1e3), 0, 0).pack(mav),
                                     relay.companion_api.address)
                sent += 1
            now, expected = channel.advance(round(now + STEP_S, 6), sent)
            deadline = time.monotonic() + 1.0
            while received < expected:
                if not select.select([companion_api], [], [], max(0.0, deadline - time.monotonic()))[0]:
                    short, received = short + 1, expected
                    break
                for msg in parser.parse_buffer(companion_api.recv(2048)) or []:
                    received += 1
                    receipts.append((round(now, 6), msg.time_boot_ms))
        pose = channel.latest()
    finally:
        vehicle.stop.set()
        vehicle.join(timeout=5)
        relay.stop()
        channel.close()
        for s in (companion_api, vehicle.api, vehicle.truth):
            s.close()
    return {"effects": vehicle.effects, "receipts": receipts, "vehicle_short": vehicle.short,
            "companion_short": short, "report": relay.report(), "pose_time": pose[0], "end": now}


LOCKSTEP_FAULTS = LinkFaults(loss=0.3, delay_ms=150, jitter_ms=50, duplicate=0.1, seed=9)


def test_the_lockstep_proxy_delays_in_simulated_time_and_keeps_both_counts_true():
    flight = _fly_scripted(LOCKSTEP_FAULTS)
    assert flight["vehicle_short"] == 0 and flight["companion_short"] == 0     # nobody ever waited for a count
    assert abs(flight["end"] - 150 * STEP_S) < 1e-6 and abs(flight["pose_time"] - flight["end"]) < 1e-6
    # a companion message takes effect at its due time: sent + 150 ms + U(0, 50 ms), on simulated time
    lags = [effect - sent_ms * 1e-3 for effect, sent_ms in flight["effects"]]
    assert lags and min(lags) >= 0.150 - 1e-6 and max(lags) <= 0.200 + 1e-6
    # a vehicle message counts as sent at its release's end and arrives at the first ack at or after its due time
    lags = [at - sent_ms * 1e-3 for at, sent_ms in flight["receipts"]]
    assert lags and min(lags) >= 0.150 - 1e-6 and max(lags) <= 0.200 + 2 * STEP_S + 1e-6
    report = flight["report"]
    for direction, n in ((COMPANION_TO_VEHICLE, 300), (VEHICLE_TO_COMPANION, 301)):
        stats = report[direction]
        assert stats["datagrams_in"] == n and abs(stats["dropped"] / n - 0.3) <= 0.09
    assert len(flight["effects"]) == report[COMPANION_TO_VEHICLE]["delivered"]
    assert len(flight["receipts"]) == report[VEHICLE_TO_COMPANION]["delivered"]
    assert 175 - 1 <= report[COMPANION_TO_VEHICLE]["mean_added_delay_ms"] <= 175 + 8
    assert report["lockstep_releases"] == 150 < report["vehicle_releases"]


def test_the_same_seed_gives_the_same_lockstep_exchange_twice_another_seed_another():
    first, second = _fly_scripted(LOCKSTEP_FAULTS, 60), _fly_scripted(LOCKSTEP_FAULTS, 60)
    for key in ("effects", "receipts", "report"):
        assert first[key] == second[key]
    other = _fly_scripted(LinkFaults(**{**LOCKSTEP_FAULTS.settings(), "seed": 10}), 60)
    assert other["effects"] != first["effects"]


# ------------------------------------------------------------------------------------------- the options
BAD = [
    (["--link-loss", "1.5"], "--link-loss must be a probability between 0 and 1, got 1.5"),
    (["--link-loss", "nan"], "--link-loss must be a probability"),
    (["--link-loss", "lots"], "--link-loss 'lots' is not a number"),
    (["--link-duplicate", "-0.1"], "--link-duplicate must be a probability"),
    (["--link-reorder", "2"], "--link-reorder must be a probability"),
    (["--link-delay", "-5"], "--link-delay: the delay must be a finite number of milliseconds >= 0"),
    (["--link-delay", "inf"], "--link-delay: the delay must be a finite"),
    (["--link-delay", "150,-1"], "--link-delay: the jitter must be"),
    (["--link-delay", "150ms"], "--link-delay '150ms' must be MS or MS,JITTER_MS"),
    (["--link-delay", "1,2,3"], "must be MS or MS,JITTER_MS"),
    (["--link-loss", "0.1", "--link-seed", "x"], "--link-seed 'x' must be a whole number"),
    (["--link-loss", "0.1", "--link-seed", "-3"], "--link-seed must be a whole number >= 0"),
]


@pytest.mark.parametrize("argv, needle", BAD)
@pytest.mark.parametrize("main", [launch.main, eval_flights.main], ids=["flowgap-sitl", "flowgap-eval-flights"])
def test_a_bad_link_option_is_a_one_line_error_naming_the_fix(main, argv, needle, capsys, tmp_path):
    assert main([*argv, "--scene" if main is launch.main else "-o", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and "e.g." in err[0] and "Traceback" not in err[0]


def test_no_fault_asked_is_no_relay_and_a_seed_is_derived_per_flight():
    assert launch.link_faults_from_args(_args()) is None
    assert launch.link_faults_from_args(_args(link_loss="0", link_delay="0,0", link_seed="4")) is None
    faults = launch.link_faults_from_args(_args(link_loss="0.3", link_delay="150"))
    assert faults == LinkFaults(loss=0.3, delay_ms=150.0) and faults.with_seed(12).seed == 12
    assert eval_flights.flight_link_faults(faults, "window1_brick", 0) is faults     # the flight's seed fills it
    seeded = LinkFaults(loss=0.3, seed=5)
    a, b = (eval_flights.flight_link_faults(seeded, "window1_brick", i) for i in (0, 1))
    assert a.seed != b.seed and a == eval_flights.flight_link_faults(seeded, "window1_brick", 0)
    with pytest.raises(LinkFaultError):
        LinkFaults(loss=0.3).rng(VEHICLE_TO_COMPANION)           # no seed yet: never global state
    assert np.isclose(a.loss, 0.3)


def _args(**given):
    import argparse

    values = {"link_loss": None, "link_delay": None, "link_duplicate": None, "link_reorder": None,
              "link_seed": None}
    return argparse.Namespace(**{**values, **given})
