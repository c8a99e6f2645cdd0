"""MAVLink 2 message signing as PX4 v1.18 does it: the key file, the incoming check, SETUP_SIGNING's rules.

- **Key file** (PX4: ``/mavlink/mavlink-signing-key.bin``; here any path, ``flowgap-vehicle --signing-key``): 40
  bytes, the 32-byte secret key then the 64-bit little-endian timestamp (10 µs since 2015-01-01 UTC), mode
  0600.  An all-zero file means signing off.  The file's timestamp is written when a SETUP_SIGNING sets a key
  and again at a graceful shutdown (only if the file still holds the same key and an older timestamp: a
  stale process never restores a replaced key); at start the signing clock is the later of the file's
  timestamp and the system clock, so a restarted vehicle never signs with a timestamp it used before.
- **Incoming**: with a key, a message must carry a valid signature (SHA-256 of the key, the frame and the
  signature's link id and timestamp, first 6 bytes), except HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE and
  COLLISION, which are accepted unsigned (PX4's allowlist).  The signature is checked first, then the
  timestamp, per (system, component, link id) stream as the MAVLink C library does: a known stream's
  timestamp must rise; a new stream is accepted unless its timestamp is more than a minute behind the
  vehicle's signing clock, and at most 16 streams are tracked.  Accepted timestamps advance the clock.
- **SETUP_SIGNING**: accepted unsigned only while no key is set; with a key it must be signed with it (the
  incoming check already drops it otherwise); refused while armed; an all-zero key and timestamp turns
  signing off.

The verifier is a pure class (no sockets, files or clocks): ``sitl_vehicle.mavlink_io`` applies it at the
link edge, and the key file functions here are the only I/O.
"""

from __future__ import annotations

import hashlib
import os
import stat
import struct
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

SECRET_LENGTH = 32
KEY_FILE_LENGTH = SECRET_LENGTH + 8
EPOCH_2015_UNIX_S = 1_420_070_400          # MAVLink signing timestamps count from 2015-01-01 00:00 UTC
TICKS_PER_SECOND = 100_000                 # ... in units of 10 µs
NEW_STREAM_WINDOW = 60 * TICKS_PER_SECOND  # a new stream may be at most a minute behind (MAVLink C library)
MAX_STREAMS = 16                           # MAVLINK_MAX_SIGNING_STREAMS
SIGNATURE_LENGTH = 13                      # link id (1) + timestamp (6) + signature (6)
IFLAG_SIGNED = 0x01
# PX4's allowlist: accepted unsigned even while signing is on (discovery and safety traffic)
UNSIGNED_ALLOWED = frozenset({mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
                              mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE, mavlink.MAVLINK_MSG_ID_COLLISION})

# outcomes of the incoming check, also the keys of the counts
SIGNED = "signed"                  # valid signature, fresh timestamp
UNSIGNED = "unsigned"              # accepted without a valid signature (signing off, or the allowlist)
UNVERIFIED = "signed_unverified"   # signed, accepted while signing is off (no key to check it with)
REJECTED_UNSIGNED = "rejected_unsigned"
REJECTED_BAD_SIGNATURE = "rejected_bad_signature"
REJECTED_REPLAY = "rejected_replay"          # a known stream's timestamp did not rise
REJECTED_OLD_STREAM = "rejected_old_stream"  # a new stream more than a minute behind
REJECTED_STREAMS_FULL = "rejected_streams_full"
OUTCOMES = (SIGNED, UNSIGNED, UNVERIFIED, REJECTED_UNSIGNED, REJECTED_BAD_SIGNATURE, REJECTED_REPLAY,
            REJECTED_OLD_STREAM, REJECTED_STREAMS_FULL)


class SigningKeyError(ValueError):
    """A key file that cannot be used; the message names the file, the problem and the fix."""


def timestamp_from_unix(unix_s: float) -> int:
    """The signing timestamp (10 µs ticks since 2015-01-01 UTC) of a Unix time; 0 before 2015."""
    return max(0, int((unix_s - EPOCH_2015_UNIX_S) * TICKS_PER_SECOND))


@dataclass(frozen=True)
class SigningKey:
    secret: bytes
    timestamp: int = 0

    def __post_init__(self) -> None:
        if len(self.secret) != SECRET_LENGTH:
            raise SigningKeyError(f"a signing key is {SECRET_LENGTH} bytes, got {len(self.secret)}")
        if not 0 <= self.timestamp < 1 << 64:
            raise SigningKeyError(f"a signing timestamp is a 64-bit unsigned number, got {self.timestamp}")

    @property
    def enabled(self) -> bool:
        """PX4's rule: a key or a timestamp that is not all zero turns signing on."""
        return self.timestamp != 0 or any(self.secret)

    def to_bytes(self) -> bytes:
        return self.secret + struct.pack("<Q", self.timestamp)

    @classmethod
    def from_bytes(cls, data: bytes) -> SigningKey:
        return cls(bytes(data[:SECRET_LENGTH]), struct.unpack("<Q", data[SECRET_LENGTH:KEY_FILE_LENGTH])[0])


DISABLED = SigningKey(bytes(SECRET_LENGTH), 0)


def read_key_file(path: str | Path) -> SigningKey:
    """The key in a PX4 key file; :class:`SigningKeyError` (one line: what is wrong, how to fix it) if the
    file is missing, readable by others, or not 40 bytes."""
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise SigningKeyError(f"signing key file {path} does not exist: write 32 bytes of secret key then an "
                              f"8-byte little-endian timestamp, e.g. flowgap-vehicle --new-signing-key {path}"
                              ) from None
    except OSError as exc:
        raise SigningKeyError(f"signing key file {path}: {exc.strerror}") from None
    if not stat.S_ISREG(info.st_mode):
        raise SigningKeyError(f"signing key file {path} is not a regular file")
    mode = stat.S_IMODE(info.st_mode)
    if mode & 0o077:
        raise SigningKeyError(f"signing key file {path} is mode {mode:04o}, readable by others: chmod 600 {path}")
    if info.st_size != KEY_FILE_LENGTH:
        raise SigningKeyError(f"signing key file {path} is {info.st_size} bytes; a PX4 key file is "
                              f"{KEY_FILE_LENGTH}: 32 bytes of secret key, then an 8-byte little-endian timestamp")
    try:
        return SigningKey.from_bytes(path.read_bytes())
    except OSError as exc:
        raise SigningKeyError(f"signing key file {path}: {exc.strerror}") from None


def write_key_file(path: str | Path, key: SigningKey) -> None:
    """Replace the key file atomically (a temporary file, synced, then renamed), created mode 0600."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    fd = os.open(tmp, os.O_CREAT | os.O_WRONLY | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, key.to_bytes())
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def checkpoint_key_file(path: str | Path, key: SigningKey) -> bool:
    """Write ``key``'s newer timestamp back (PX4 does at a graceful shutdown) if the file still holds the same
    secret and an older timestamp; whether it wrote."""
    try:
        stored = read_key_file(path)
    except SigningKeyError:
        return False
    if stored.secret != key.secret or not key.enabled or key.timestamp <= stored.timestamp:
        return False
    write_key_file(path, key)
    return True


def new_key(unix_s: float) -> SigningKey:
    """A random secret with the signing timestamp of ``unix_s``."""
    return SigningKey(os.urandom(SECRET_LENGTH), timestamp_from_unix(unix_s))


def frame_is_signed(frame: bytes) -> bool:
    """Whether a raw MAVLink frame carries a signature (MAVLink 2 with the signed incompatibility flag)."""
    return len(frame) > 2 and frame[0] == mavlink.PROTOCOL_MARKER_V2 and bool(frame[2] & IFLAG_SIGNED)


def signature_of(secret: bytes, frame: bytes) -> bytes:
    """The 6-byte signature of a signed frame (everything before the signature's last 6 bytes, keyed)."""
    return hashlib.sha256(secret + bytes(frame[:-6])).digest()[:6]


def frame_link_and_timestamp(frame: bytes) -> tuple[int, int]:
    """(link id, timestamp) of a signed frame."""
    block = bytes(frame[-SIGNATURE_LENGTH:])
    return block[0], int.from_bytes(block[1:7], "little")


@dataclass
class MessageVerifier:
    """The incoming half of signing for one vehicle (shared by all its links, as PX4 shares its streams).

    ``key`` None (or a disabled key) accepts everything.  :meth:`check` returns the outcome of one received
    frame (one of :data:`OUTCOMES`) and counts it; ``timestamp`` is the vehicle's signing clock, which never
    falls behind an accepted timestamp.
    """

    key: SigningKey | None = None
    timestamp: int = 0
    streams: dict[tuple[int, int, int], int] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)

    @property
    def active(self) -> bool:
        return self.key is not None and self.key.enabled

    def set_key(self, key: SigningKey | None, now_timestamp: int = 0) -> None:
        """Use ``key`` from now on (None or a disabled key: signing off); the clock becomes the latest of the
        key's timestamp, ``now_timestamp`` and, for the same secret, the clock so far."""
        same = key is not None and self.key is not None and key.secret == self.key.secret
        self.timestamp = max(key.timestamp if key else 0, now_timestamp, self.timestamp if same else 0)
        self.key = key if key is not None and key.enabled else None
        if not same:
            self.streams.clear()

    def check(self, frame: bytes, msg_id: int, system: int, component: int) -> str:
        outcome = self._outcome(bytes(frame), msg_id, system, component)
        self.counts[outcome] += 1
        return outcome

    def _outcome(self, frame: bytes, msg_id: int, system: int, component: int) -> str:
        if not self.active:
            return UNVERIFIED if frame_is_signed(frame) else UNSIGNED
        if not frame_is_signed(frame):
            return UNSIGNED if msg_id in UNSIGNED_ALLOWED else REJECTED_UNSIGNED
        rejected = self._verify(frame, system, component)
        if rejected is None:
            return SIGNED
        return UNSIGNED if msg_id in UNSIGNED_ALLOWED else rejected

    def _verify(self, frame: bytes, system: int, component: int) -> str | None:
        """None for a valid, fresh signature; else the reason it is not (signature first, as the C library)."""
        if len(frame) < SIGNATURE_LENGTH + 12 or signature_of(self.key.secret, frame) != frame[-6:]:
            return REJECTED_BAD_SIGNATURE
        link_id, stamp = frame_link_and_timestamp(frame)
        stream = (system, component, link_id)
        last = self.streams.get(stream)
        if last is None:
            if len(self.streams) >= MAX_STREAMS:
                return REJECTED_STREAMS_FULL
            if stamp + NEW_STREAM_WINDOW < self.timestamp:
                return REJECTED_OLD_STREAM
        elif stamp <= last:
            return REJECTED_REPLAY
        self.streams[stream] = stamp
        self.timestamp = max(self.timestamp, stamp)
        return None

    def summary(self) -> dict:
        """Counts of every outcome so far, plus whether signing is on."""
        return {"active": self.active, **{name: int(self.counts.get(name, 0)) for name in OUTCOMES}}


def is_rejection(outcome: str) -> bool:
    return outcome.startswith("rejected")
