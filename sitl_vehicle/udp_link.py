"""One MAVLink UDP endpoint, the way PX4 SITL opens them.

``UdpLink`` sends first to a default remote (PX4: 127.0.0.1:14550 for the ground station, 127.0.0.1:14540 for
the offboard API) and locks onto the first peer that answers. Each datagram is parsed on its own, so random
bytes or a truncated packet cost that datagram only; they are counted and reported, never raised. Apart from
the protocol (``sitl_vehicle.mavlink_io``) because it is the transport: sockets, packing, signing the bytes
it sends and parsing those it receives, and no idea what a message means.
"""

from __future__ import annotations

import errno
import logging
import socket

from pymavlink.dialects.v20 import common as mavlink

# the logger these lines had before the link had a module of its own: a log configured by name still finds them
log = logging.getLogger("sitl_vehicle.mavlink_io")

SYSTEM_ID = 1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1


class PortInUseError(OSError):
    """A UDP port the vehicle must bind is taken by another process."""


def parse_hostport(text: str) -> tuple[str, int]:
    """'host:port' or ':port' → (host, port); raises ValueError with a usable message."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"address {text!r} must look like HOST:PORT, e.g. 127.0.0.1:14540")
    return host or "0.0.0.0", int(port)


class UdpLink:
    """One MAVLink UDP endpoint with PX4 SITL's send-first, lock-on-first-answer behaviour."""

    def __init__(self, name: str, local: tuple[str, int], remote: tuple[str, int] | None,
                 system_id: int = SYSTEM_ID, component_id: int = COMPONENT_ID):
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(local)
        except OSError as exc:
            self.sock.close()
            if exc.errno == errno.EADDRINUSE:
                raise PortInUseError(
                    f"UDP port {local[1]} ({name} link) is already in use: stop the other vehicle or pass "
                    f"another port (see --help, e.g. --instance N)") from None
            raise
        self.sock.setblocking(False)
        self.local_address = self.sock.getsockname()
        self.remote = remote
        self.peer_locked = False
        self.mav = mavlink.MAVLink(None, system_id, component_id)       # packs (and signs) what we send
        # a parser of its own: with a key set, pymavlink would also check signatures on receipt, which the
        # vehicle does itself (sitl_vehicle.signing: PX4's allowlist, the signature before the timestamp)
        self.parser = mavlink.MAVLink(None, system_id, component_id)
        self.parser.robust_parsing = True
        self._signing_clock = None
        self.malformed_datagrams = 0
        self.packets_in = 0
        self.packets_out = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def sign_outgoing(self, secret: bytes | None, link_id: int, clock) -> None:
        """Sign every message sent from now on with ``secret`` (None: send unsigned) and ``link_id``, never with a
        timestamp behind ``clock()`` (the vehicle's signing clock)."""
        signing = self.mav.signing
        signing.secret_key = secret
        signing.sign_outgoing = secret is not None
        signing.link_id = link_id
        self._signing_clock = clock if secret is not None else None
        if clock is not None:
            signing.timestamp = max(signing.timestamp, clock())

    def signing_timestamp(self) -> int:
        """The timestamp the next signed message will carry."""
        return self.mav.signing.timestamp

    def send(self, msg) -> None:
        if self.remote is None:
            return
        if self._signing_clock is not None:
            self.mav.signing.timestamp = max(self.mav.signing.timestamp, self._signing_clock())
        data = msg.pack(self.mav)
        # a sequence number per link and message, as PX4's: ground stations count link loss from its gaps
        self.mav.seq = (self.mav.seq + 1) % 256
        try:
            self.sock.sendto(data, self.remote)
            self.packets_out += 1
        except OSError as exc:
            # Nobody listening (ECONNREFUSED via ICMP) is normal before a client starts.
            if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENETUNREACH):
                log.debug("%s link: send failed: %s", self.name, exc)

    def receive(self) -> list:
        """All messages waiting on the socket; malformed datagrams are counted and dropped."""
        out = []
        while True:
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError as exc:
                if exc.errno == errno.ECONNREFUSED:
                    continue
                raise
            messages = self._parse_datagram(data)
            if messages and not self.peer_locked:
                self.remote = address
                self.peer_locked = True
                log.info("%s link: peer %s:%d connected", self.name, *address)
            out.extend(messages)

    def _parse_datagram(self, data: bytes) -> list:
        mav = self.parser
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        try:
            parsed = mav.parse_buffer(data) or []
        except Exception as exc:  # noqa: BLE001 — a hostile datagram must never stop the vehicle
            parsed = []
            log.debug("%s link: unparsable datagram (%s)", self.name, exc)
            self._count_malformed(len(data))
            return []
        good = [m for m in parsed if m.get_type() != "BAD_DATA"]
        if len(good) != len(parsed) or mav.buf_len() > 0:
            self._count_malformed(len(data))
        self.packets_in += len(good)
        return good

    def _count_malformed(self, size: int) -> None:
        self.malformed_datagrams += 1
        n = self.malformed_datagrams
        if n & (n - 1) == 0:  # log the 1st, 2nd, 4th, 8th … so a flood cannot flood the log
            log.warning("%s link: dropped malformed or truncated MAVLink datagram (%d bytes); %d so far",
                        self.name, size, n)

    def close(self) -> None:
        self.sock.close()
