"""The vehicle's end of lockstep: simulation time advances only as far as the companion releases it.

The release and its answer travel on the simulation-only side channel, beside the ground-truth ODOMETRY
stream, never on the MAVLink API link: a MAVLink ``DEBUG_VECT`` named ``LOCKSTEP`` each way.

- companion → vehicle, a *release*: ``time_usec`` the simulation time the vehicle may run to, ``x`` how many
  MAVLink messages the companion has sent on the API link (mod 2**24), ``y`` the release's sequence number
  (from 1, mod 2**24).  The vehicle reads that many API messages before it steps, so a command or setpoint
  takes effect at the simulation time it was sent.
- vehicle → companion, an *ack*: ``time_usec`` the simulation time reached, ``x`` how many messages the
  vehicle has sent on the API link (mod 2**24), ``y`` the release it answers; a held vehicle repeats it with
  ``y`` 0 a few times a second (a beacon, so that a companion can find it).

The companion's end is :mod:`companion.lockstep`; the two share this definition, not code.
"""

from __future__ import annotations

import logging
import select
import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

NAME = "LOCKSTEP"
COUNT_MODULUS = 1 << 24        # counts and sequence numbers travel as float32, exact below 2**24


@dataclass(frozen=True)
class Release:
    until_s: float
    api_messages: int      # what the companion has sent on the API link so far (mod 2**24)
    sequence: int


def ack_message(time_s: float, api_messages_sent: int, sequence: int) -> mavlink.MAVLink_debug_vect_message:
    return mavlink.MAVLink_debug_vect_message(NAME.encode(), int(round(time_s * 1e6)),
                                              float(api_messages_sent % COUNT_MODULUS),
                                              float(sequence % COUNT_MODULUS), 0.0)


def release_from(msg) -> Release | None:
    """The release a received message carries, or None (another message, or a malformed one)."""
    if msg.get_type() != "DEBUG_VECT":
        return None
    name = msg.name if isinstance(msg.name, str) else msg.name.decode(errors="replace")
    if name.rstrip("\x00") != NAME:
        return None
    values = (msg.x, msg.y)
    if not all(v == v and 0 <= v < COUNT_MODULUS for v in values) or msg.time_usec < 0:
        return None
    return Release(msg.time_usec * 1e-6, int(msg.x), int(msg.y))


def behind(received: int, expected: int) -> bool:
    """Whether ``received`` messages (mod 2**24) fall short of ``expected``."""
    gap = (expected - received) % COUNT_MODULUS
    return 0 < gap < COUNT_MODULUS // 2


class LockstepHold:
    """Waits, with time held, for the companion's next release; meanwhile beacons on the side channel
    (``beacon_s`` wall seconds apart) and keeps ground stations content: a HEARTBEAT each wall second on
    the other links, whose messages are handled (a ground station's commands take effect at the next
    release)."""

    def __init__(self, server, beacon_s: float = 0.2, heartbeat_s: float = 1.0, drain_timeout_s: float = 1.0):
        self.server = server
        self.beacon_s = beacon_s
        self.heartbeat_s = heartbeat_s
        self.drain_timeout_s = drain_timeout_s
        self.answered = 0                 # the last release answered
        self.releases = 0
        self._next_beacon = 0.0
        self._next_heartbeat = time.monotonic() + heartbeat_s

    def wait(self, stop) -> Release | None:
        """The next new release, or None once ``stop`` is set."""
        server = self.server
        truth, api = server.truth_link, server.link("api")
        others = [link for link in server.links if link is not api]
        while not stop.is_set():
            now = time.monotonic()
            if now >= self._next_beacon:
                truth.send(ack_message(server.sim.time_s, api.packets_out, 0))
                self._next_beacon = now + self.beacon_s
            if now >= self._next_heartbeat:
                server.interface.heartbeat(others)
                self._next_heartbeat = now + self.heartbeat_s
            select.select([truth.sock, *(link.sock for link in others)], [], [], 0.05)
            server.interface.poll(others)
            newest = None
            for msg in truth.receive():
                release = release_from(msg)
                if release is None:
                    continue
                if release.sequence == self.answered:      # its ack went missing: say it again
                    self.ack()
                else:
                    newest = release
            if newest is not None:
                return newest
        return None

    def read_api(self, release: Release) -> None:
        """Handle the API messages the companion sent before ``release`` (all of them, or after a wall-time
        timeout, what has come: a lost datagram, logged)."""
        server = self.server
        api = server.link("api")
        deadline = time.monotonic() + self.drain_timeout_s
        server.interface.poll()
        while behind(api.packets_in % COUNT_MODULUS, release.api_messages):
            if time.monotonic() > deadline:
                log.warning("lockstep: %d of the companion's API messages missing after %.1f s; going on",
                            (release.api_messages - api.packets_in) % COUNT_MODULUS, self.drain_timeout_s)
                break
            select.select([api.sock], [], [], 0.005)
            server.interface.poll([api])

    def ack(self, sequence: int | None = None) -> None:
        server = self.server
        if sequence is not None:
            self.answered = sequence
            self.releases += 1
        server.truth_link.send(ack_message(server.sim.time_s, server.link("api").packets_out, self.answered))
