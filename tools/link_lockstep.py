"""The link-fault relay in lockstep: a proxy for the lockstep words on the side channel, so that a lossy,
delayed API link neither stalls a lockstep flight nor makes it depend on the machine's load.

Lockstep (see :mod:`sitl_vehicle.lockstep`) trusts two counts: the vehicle, on each *release*, reads as many
API messages as the companion says it has sent; the companion, on each *ack*, reads as many as the vehicle
says it has sent.  With datagrams lost, duplicated or held back those counts no longer match what arrives, so
the relay sits on the side channel too (the vehicle's ``--truth-remote`` points at it) and:

- forwards everything that is not a lockstep word (the ground-truth ODOMETRY) unchanged and at once;
- stamps each companion API datagram with the companion's clock when it was sent (the time of the last ack the
  companion was given: its clock stands still between a release and the ack) and each vehicle API datagram
  sent during a release with the time that release reached (the ack's time), and hands them to the fault
  model (:class:`tools.link_faults.DelayLine`), so delays run on simulated time;
- splits each companion release into releases to the vehicle that end at the due times of the companion's
  datagrams in flight (waiting for each ack before the next), delivering each datagram just before the release
  that starts at its due time: a setpoint sent at ``t`` with a 150 ms delay takes effect at ``t + 0.150``
  of simulated time;
- writes into each release to the vehicle the number of companion messages it has delivered to the vehicle,
  and into the companion's ack the number of vehicle messages it has delivered to the companion: the vehicle's
  datagrams due by the ack's time, delivered just before it (the companion's clock jumps from ack to ack, so
  a vehicle datagram arrives at the first ack at or after its due time).

Every decision is a function of the seed and the two sides' datagram sequences, which lockstep makes
independent of the machine's load: the same seed gives the same flight.  A datagram the relay never gets
(the side channel is loopback: practically never) costs a logged warning after ``drain_timeout_s``, once.
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.lockstep import COUNT_MODULUS, Release, ack_message, behind, release_from
from tools.link_faults import (
    COMPANION_TO_VEHICLE,
    VEHICLE_TO_COMPANION,
    DelayLine,
    count_mavlink_frames,
    mavlink_message_id,
)
from tools.link_relay import RelaySocket

log = logging.getLogger(__name__)

VEHICLE, COMPANION = "vehicle", "companion"


class _Stopped(Exception):
    pass


def decode_lockstep_word(data: bytes) -> tuple[Release, tuple[int, int]] | None:
    """(the word, its sender's system and component ids) if ``data`` is a lockstep DEBUG_VECT, else None.
    A release and an ack share one layout: (time, count, sequence)."""
    if mavlink_message_id(data) != mavlink.MAVLINK_MSG_ID_DEBUG_VECT:
        return None
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    try:
        messages = parser.parse_buffer(data) or []
    except Exception:  # noqa: BLE001 — a mangled datagram is not a word
        return None
    for msg in messages:
        word = release_from(msg) if msg.get_type() != "BAD_DATA" else None
        if word is not None:
            return word, (msg.get_srcSystem(), msg.get_srcComponent())
    return None


class LockstepProxy:
    """The lockstep relay's loop (see the module docstring); runs in :class:`tools.link_relay.LinkRelay`'s
    thread until ``stop`` is set.  ``resend_s``: wall seconds between repeats of an unanswered release;
    ``drain_timeout_s``: how long to wait for API messages a side says it sent."""

    def __init__(self, lines: dict[str, DelayLine], vehicle_api: RelaySocket, companion_api: RelaySocket,
                 vehicle_side: RelaySocket, companion_side: RelaySocket, stop: threading.Event,
                 resend_s: float = 1.0, drain_timeout_s: float = 1.0) -> None:
        self.lines = lines
        self.api = {VEHICLE: vehicle_api, COMPANION: companion_api}
        self.side = {VEHICLE: vehicle_side, COMPANION: companion_side}
        self.stop = stop
        self.resend_s = resend_s
        self.drain_timeout_s = drain_timeout_s
        self._words: deque[tuple[str, Release]] = deque()
        self._unstamped: dict[str, list[tuple[bytes, int]]] = {VEHICLE: [], COMPANION: []}
        self._received = {VEHICLE: 0, COMPANION: 0}      # API messages each side sent that reached the relay
        self._missing = {VEHICLE: 0, COMPANION: 0}       # ... and those it said it sent that never came
        self._delivered = {VEHICLE: 0, COMPANION: 0}     # API messages delivered *to* each side
        self._packers: dict[str, mavlink.MAVLink] = {}   # words to each side, in the other side's name
        self._started = False
        self._companion_time = 0.0     # what the companion's clock reads: the time of its last ack
        self._vehicle_target = 0.0     # how far the vehicle has been released
        self._vehicle_sequence = 0
        self._companion_sequence: int | None = None      # the companion release in hand or last answered
        self._last_ack: bytes | None = None
        self.releases = 0              # companion releases answered
        self.vehicle_releases = 0      # releases sent to the vehicle (more: they end at due times)

    # ------------------------------------------------------------------------------------------ the loop
    def run(self) -> None:
        try:
            while True:
                self._service(0.05)
                while self._words:
                    side, word = self._words.popleft()
                    if side == COMPANION:
                        self._handle_release(word)
                    elif word.sequence == 0:        # a held vehicle's beacon: pass it on, with our count
                        if not self._started:
                            self._companion_time = self._vehicle_target = word.until_s
                        self._send_word(COMPANION, word.until_s, self._delivered[COMPANION], 0)
        except _Stopped:
            pass

    def _handle_release(self, release: Release) -> None:
        if release.sequence == self._companion_sequence:     # a repeat: its ack went missing
            if self._last_ack is not None:
                self.side[COMPANION].send(self._last_ack)
            return
        self._started = True
        self._companion_sequence = release.sequence
        to_vehicle = self.lines[COMPANION_TO_VEHICLE]
        self._drain(COMPANION, release.api_messages)
        self._stamp(COMPANION, self._companion_time)
        target, until = self._vehicle_target, release.until_s
        while True:
            self._deliver(VEHICLE, target)
            due = to_vehicle.next_due()
            end = due if due is not None and target < due < until else until
            reached, vehicle_sent = self._release_vehicle(end)
            self._drain(VEHICLE, vehicle_sent)
            self._stamp(VEHICLE, reached)
            target = max(target, end)
            if end >= until:
                break
        self._vehicle_target = target
        self._companion_time = reached
        self._deliver(COMPANION, reached)
        self._last_ack = self._send_word(COMPANION, reached, self._delivered[COMPANION], release.sequence)
        self.releases += 1

    # ------------------------------------------------------------------------------------------ steps
    def _release_vehicle(self, until_s: float) -> tuple[float, int]:
        """Release the vehicle to ``until_s``; (time reached, API messages it has sent) from its ack."""
        self._vehicle_sequence = self._vehicle_sequence % (COUNT_MODULUS - 1) + 1
        sequence = self._vehicle_sequence
        release = self._send_word(VEHICLE, until_s, self._delivered[VEHICLE], sequence)
        self.vehicle_releases += 1
        next_resend = time.monotonic() + self.resend_s
        while True:
            kept: deque[tuple[str, Release]] = deque()
            while self._words:
                side, word = self._words.popleft()
                if side == VEHICLE:
                    if word.sequence == sequence:
                        self._words.extendleft(reversed(kept))
                        return word.until_s, word.api_messages
                    # beacons and late repeats of earlier acks: nothing the companion needs
                elif word.sequence != self._companion_sequence:
                    kept.append((side, word))       # a new release (the companion gave up on this one): later
            self._words = kept
            if time.monotonic() > next_resend:
                self.side[VEHICLE].send(release)
                next_resend = time.monotonic() + self.resend_s
            self._service(0.05)

    def _drain(self, side: str, expected: int) -> None:
        """Wait until the API messages ``side`` says it sent (``expected``, mod 2**24) have reached the relay."""
        deadline = time.monotonic() + self.drain_timeout_s
        while behind((self._received[side] + self._missing[side]) % COUNT_MODULUS, expected):
            if time.monotonic() > deadline:
                short = (expected - self._received[side] - self._missing[side]) % COUNT_MODULUS
                log.warning("link relay: %d of the %s's API messages never reached the relay after %.1f s; going "
                            "on without them (this flight may not repeat exactly)", short, side, self.drain_timeout_s)
                self._missing[side] += short
                return
            self._service(0.005)

    def _stamp(self, side: str, sent_s: float) -> None:
        """Hand ``side``'s datagrams that came since the last stamp to the fault model, sent at ``sent_s``."""
        line = self.lines[VEHICLE_TO_COMPANION if side == VEHICLE else COMPANION_TO_VEHICLE]
        for data, messages in self._unstamped[side]:
            line.push(data, sent_s, messages)
        self._unstamped[side].clear()

    def _deliver(self, side: str, now_s: float) -> None:
        """Deliver to ``side`` the datagrams due by ``now_s``."""
        line = self.lines[COMPANION_TO_VEHICLE if side == VEHICLE else VEHICLE_TO_COMPANION]
        for datagram in line.pop_due(now_s):
            if self.api[side].send(datagram.payload):      # (what never left cannot be counted on)
                self._delivered[side] += datagram.messages

    def _send_word(self, side: str, time_s: float, count: int, sequence: int) -> bytes:
        """Send a lockstep word to ``side`` (in the other side's system and component ids); its bytes."""
        packer = self._packers.get(side)
        if packer is None:                  # (not yet heard from the other side: any ids will do)
            packer = mavlink.MAVLink(None, 1, 1)
        data = ack_message(time_s, count % COUNT_MODULUS, sequence).pack(packer)
        self.side[side].send(data)
        return data

    # ------------------------------------------------------------------------------------------ sockets
    def _service(self, timeout_s: float) -> None:
        """Take what arrived within ``timeout_s``: API datagrams wait to be stamped, lockstep words queue up,
        everything else on the side channel passes straight through."""
        if self.stop.is_set():
            raise _Stopped
        sockets = [*self.api.values(), *self.side.values()]
        readable, _, _ = select.select(sockets, [], [], timeout_s)
        for side in (VEHICLE, COMPANION):
            other = COMPANION if side == VEHICLE else VEHICLE
            if self.api[side] in readable:
                for data in self.api[side].receive_all():
                    messages = count_mavlink_frames(data)
                    self._unstamped[side].append((data, messages))
                    self._received[side] += messages
            if self.side[side] in readable:
                for data in self.side[side].receive_all():
                    decoded = decode_lockstep_word(data)
                    if decoded is None:
                        self.side[other].send(data)
                        continue
                    word, ids = decoded
                    if other not in self._packers:
                        self._packers[other] = mavlink.MAVLink(None, *ids)
                    self._words.append((side, word))
