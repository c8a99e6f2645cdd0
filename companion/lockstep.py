"""The companion's end of lockstep, on the simulation-only side channel (the ground-truth pose stream).

The side channel carries the vehicle's ODOMETRY truth (what the simulated camera renders from) and, in
lockstep, one more message each way, a MAVLink ``DEBUG_VECT`` named ``LOCKSTEP``:

- companion → vehicle, a *release*: ``time_usec`` the simulation time the vehicle may run to, ``x`` how many
  MAVLink messages the companion has sent on the API link so far (mod 2**24), ``y`` the release's sequence
  number (mod 2**24, from 1).  The vehicle first reads that many API messages, so a setpoint or command sent
  before the release takes effect at the simulation time it was sent, then runs to ``time_usec``.
- vehicle → companion, an *ack*: ``time_usec`` the simulation time reached, ``x`` how many messages the
  vehicle has sent on its API link (mod 2**24), ``y`` the sequence number of the release it answers (0 in
  the beacons a held vehicle repeats a few times a second, so that a companion can find it).

The MAVLink API link stays exactly what PX4 would see.  Lockstep needs both processes on one host (a
datagram lost on the side channel or the API link costs a logged warning and exact repeatability).
"""

from __future__ import annotations

import logging
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.camera import CameraError
from companion.clock import MESSAGE_COUNT_MODULUS, LockstepError
from companion.link.base import parse_endpoint

log = logging.getLogger(__name__)

LOCKSTEP_NAME = "LOCKSTEP"
START_TIMEOUT_S = 30.0      # wall seconds to find a held vehicle (as long as a link's connect)


def lockstep_message(time_s: float, count: int, sequence: int) -> mavlink.MAVLink_debug_vect_message:
    """A release or ack (see the module docstring); shared with the vehicle's end by its definition only."""
    return mavlink.MAVLink_debug_vect_message(LOCKSTEP_NAME.encode(), int(round(time_s * 1e6)),
                                              float(count % MESSAGE_COUNT_MODULUS),
                                              float(sequence % MESSAGE_COUNT_MODULUS), 0.0)


def is_lockstep(msg) -> bool:
    if msg.get_type() != "DEBUG_VECT":
        return False
    name = msg.name if isinstance(msg.name, str) else msg.name.decode(errors="replace")
    return name.rstrip("\x00") == LOCKSTEP_NAME


class LockstepChannel:
    """The side channel read synchronously: the clock's transport and the camera's pose source.

    ``start_timeout_s``: how long to wait for a held vehicle's beacon (default :data:`START_TIMEOUT_S`);
    ``ack_timeout_s``: for the answer to a release (wall seconds; the release is repeated every ``resend_s``
    meanwhile).
    """

    def __init__(self, url: str, start_timeout_s: float | None = None, ack_timeout_s: float = 10.0,
                 resend_s: float = 1.0) -> None:
        endpoint = parse_endpoint(url)
        self._conn = mavutil.mavlink_connection(endpoint.mavutil, dialect="common")
        self.start_timeout_s = START_TIMEOUT_S if start_timeout_s is None else start_timeout_s
        self.ack_timeout_s = ack_timeout_s
        self.resend_s = resend_s
        self._sequence = 0
        self._latest: tuple | None = None
        self.url = url

    # ------------------------------------------------------------------- the clock's transport
    def start(self) -> tuple[float, int]:
        ack = self._await(lambda seq: True, self.start_timeout_s,
                          f"no lockstep word from the vehicle on {self.url} within {self.start_timeout_s:.0f} s: "
                          f"is flowgap-vehicle running with --lockstep and its --truth-remote pointed here?")
        log.info("lockstep: the vehicle is held at t=%.3f s", ack[0])
        return ack

    def advance(self, until_s: float, sent_messages: int) -> tuple[float, int]:
        self._sequence = self._sequence % (MESSAGE_COUNT_MODULUS - 1) + 1
        sequence = self._sequence
        release = lockstep_message(until_s, sent_messages, sequence)
        self._conn.mav.send(release)
        return self._await(lambda seq: seq == sequence, self.ack_timeout_s,
                           f"the vehicle did not answer a lockstep release within {self.ack_timeout_s:.0f} s: "
                           f"it stopped or runs without --lockstep", resend=release)

    def _await(self, wanted, timeout_s: float, error: str, resend=None) -> tuple[float, int]:
        deadline = time.monotonic() + timeout_s
        next_resend = time.monotonic() + self.resend_s
        while True:
            now = time.monotonic()
            if now > deadline:
                raise LockstepError(error)
            if resend is not None and now > next_resend:
                self._conn.mav.send(resend)
                next_resend = now + self.resend_s
            try:
                msg = self._conn.recv_match(blocking=True, timeout=min(0.05, max(0.0, deadline - now)))
            except (OSError, ValueError) as exc:
                raise LockstepError(f"lockstep side channel {self.url}: {exc}") from None
            if msg is None:
                continue
            kind = msg.get_type()
            if kind == "ODOMETRY":
                self._latest = (msg.time_usec * 1e-6, (msg.x, msg.y, msg.z), tuple(msg.q))
            elif is_lockstep(msg) and wanted(int(msg.y)):
                return msg.time_usec * 1e-6, int(msg.x)

    # ------------------------------------------------------------------- the camera's pose source
    def latest(self, timeout_s: float = 5.0) -> tuple[float, tuple, tuple]:
        """The newest true pose the vehicle sent up to the last ack (no waiting: lockstep time is held)."""
        if self._latest is None:
            raise CameraError(f"no ground-truth pose received yet on {self.url}")
        return self._latest

    def close(self) -> None:
        self._conn.close()


def open_clock(truth_url: str, lockstep: bool):
    """(clock, pose source) for a companion: the wall clock with the truth stream listened to in a thread, or
    the lockstep clock with the side channel it reads (which then also gives the camera its poses)."""
    from companion.camera import TruthPoseListener
    from companion.clock import LockstepClock, WallClock

    if not lockstep:
        return WallClock(), TruthPoseListener(truth_url)
    channel = LockstepChannel(truth_url)
    try:
        return LockstepClock(channel), channel
    except LockstepError:
        channel.close()
        raise
